#!/usr/bin/env bash
# Runner classes: does a CPU quota change the equal-time ranking?
#
#   bash deploy/bench-runner-classes.sh [QUOTA]     (default 0.5 cores)
#
# Runs the whole service (deploy/serve.sh) twice on this machine, each time
# in a fresh data directory with one runner: first as it is, then with
# every container under a Docker CPU quota of QUOTA cores
# (FBKSD_CI_CPU_QUOTA). Each time the same techniques are published as
# baselines on two experimental scenes at 4 and 16 spp, 3 seeds:
#   box-copy-a, box-copy-b   the C++ box filter twice under two names (must tie)
#   box-heavy                the box filter summing every sample 30 times
#   box-heavy-doubled        the same, 60 times: the same image for twice the work
#   gaussian-filter, nlm     two baselines
# and prints, for each technique, its mean ranks at equal spp and at equal
# time on both runners, its cost and wall time to result per run on both,
# and each runner's class and calibration. Takes about 30 min on 2 cores
# (after the release build and the images, which serve.sh caches).
set -euo pipefail
cd "$(dirname "$0")/.."
quota=${1:-0.5}
work=$(pwd)/target/bench-runner-classes
bind=127.0.0.1:8196
rm -rf "$work"
mkdir -p "$work/techniques"

# The techniques, as submission repositories.
. deploy/lib/heavy-box-filter.sh
for name in box-copy-a box-copy-b; do
    cp -r sdk/techniques/box-filter-cpp "$work/techniques/$name"
done
heavy_box_filter "$work/techniques/box-heavy" 30
heavy_box_filter "$work/techniques/box-heavy-doubled" 60
cp -r sdk/techniques/gaussian-filter sdk/techniques/nlm "$work/techniques/"
list="$work/techniques/list.txt"
printf '%s\n' box-copy-a box-copy-b box-heavy box-heavy-doubled gaussian-filter nlm >"$list"
expected=$(wc -l <"$list")

for runner in plain throttled; do
    extra=()
    [ "$runner" = throttled ] && extra=(FBKSD_CI_CPU_QUOTA="$quota")
    echo "bench-runner-classes: $runner runner ${extra[*]:-}" >&2
    env "${extra[@]}" FBKSD_DATA_DIR="$work/$runner" FBKSD_RUNNER_DIR="$work/$runner-runner" \
        FBKSD_SERVER_BIND="$bind" FBKSD_BASELINES="$list" \
        FBKSD_CI_SCENES=experimental/sphere,experimental/sin-bands FBKSD_CI_SPP=4,16 \
        bash deploy/serve.sh >"$work/$runner.log" 2>&1 &
    serve=$!
    # Until every technique is on the board (the baselines command waits for each).
    python3 - "$bind" "$expected" "$work/$runner.json" "$serve" <<'EOF'
import json, os, sys, time, urllib.request
bind, expected, out, serve = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
start = time.time()
while True:
    try:
        os.kill(serve, 0)
    except OSError:
        sys.exit("serve.sh stopped: see its log")
    try:
        board = json.load(urllib.request.urlopen(f"http://{bind}/api/v1/leaderboard", timeout=10))
        if len(board["standings"]) >= expected:
            sets = {}
            for s in board["standings"]:
                with urllib.request.urlopen(f"http://{bind}/api/v1/results/{s['result_id']}", timeout=10) as r:
                    sets[s["technique"]] = json.load(r)
            json.dump({"board": board, "sets": sets, "minutes": (time.time() - start) / 60}, open(out, "w"))
            break
    except OSError:
        pass
    if time.time() - start > 3 * 3600:
        sys.exit("not every technique was published within 3 hours")
    time.sleep(10)
EOF
    kill -TERM "$serve"
    wait "$serve" || true
done

python3 - "$work/plain.json" "$work/throttled.json" "$quota" <<'EOF'
import json, statistics, sys
plain, throttled = (json.load(open(p)) for p in sys.argv[1:3])
quota = sys.argv[3]
def machine(doc):
    any_set = next(iter(doc["sets"].values()))
    return any_set["result"]["provenance"]["machine"]
for name, doc in (("plain", plain), (f"quota {quota}", throttled)):
    m, c = machine(doc), machine(doc)["calibration"]
    print(f"{name}: class {m['class']}, quota {m.get('cpu_quota')}, calibration {c['cpu_ms']:.1f} ms CPU "
          f"(CV {c['cpu_cv_percent']:.1f} %), {c['wall_ms']:.1f} ms wall; board in {doc['minutes']:.0f} min")
def ranks(doc):
    return {s["technique"]: (s["mean_rank"], s["mean_rank_time"]) for s in doc["board"]["standings"]}
def runs(doc):
    out = {}
    for g in doc["board"]["groups"]:
        for e in g["entries"]:
            out[(e["technique"], g["scene"], g["spp"])] = (e["cost_ms"], e["technique_ms"])
    return out
rp, rt = ranks(plain), ranks(throttled)
print()
print(f"{'technique':20} {'equal spp':>19} {'equal time':>19}")
print(f"{'':20} {'plain':>9} {'quota':>9} {'plain':>9} {'quota':>9}")
for t in sorted(rp, key=lambda t: rp[t][1]):
    a, b = rp[t], rt.get(t, (float('nan'),) * 2)
    print(f"{t:20} {a[0]:9.2f} {b[0]:9.2f} {a[1]:9.2f} {b[1]:9.2f}")
up, ut = runs(plain), runs(throttled)
print()
print(f"{'technique':20} {'scene':12} {'spp':>4} {'cost plain':>11} {'cost quota':>11} {'ratio':>6} {'time plain':>11} {'time quota':>11} {'ratio':>6}")
cost_ratios, time_ratios = [], []
for key in sorted(up):
    if key not in ut:
        continue
    (cp, tp), (cq, tq) = up[key], ut[key]
    cr, tr = cq / cp, tq / tp
    cost_ratios.append(cr)
    time_ratios.append(tr)
    print(f"{key[0]:20} {key[1]:12} {key[2]:4} {cp:11.1f} {cq:11.1f} {cr:6.3f} {tp:11.1f} {tq:11.1f} {tr:6.3f}")
print()
print(f"cost ratio quota/plain: median {statistics.median(cost_ratios):.3f}, {min(cost_ratios):.3f}-{max(cost_ratios):.3f}")
print(f"wall time ratio quota/plain: median {statistics.median(time_ratios):.3f}, {min(time_ratios):.3f}-{max(time_ratios):.3f}")
EOF
