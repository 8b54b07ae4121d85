#!/usr/bin/env bash
# Equal time against noise, through the service: the check of
# deploy/bench-equal-time.sh (20 repetitions of `fbksd run`) made the way
# the board makes it. One runner and the whole service (deploy/serve.sh, a
# fresh data directory) publish three techniques on the experimental sphere
# and sin-bands at 4 and 16 spp, 3 seeds each:
#   box-copy-a, box-copy-b  the C++ box filter summing every sample ROUNDS
#                           times (default 30), twice under two names
#   box-doubled             the same, 2 × ROUNDS times: the same image for
#                           twice the work
# Each repetition is one season: the administrator starts a new season
# (POST /api/v1/admin/seasons), which benchmarks every published technique
# again and publishes it, and the board is read once nothing is left to do
# (the season's benchmarks and the seeds jobs the planner queued for close
# ties, max_seeds 12 by default: MAX_SEEDS=0 turns them off). It prints,
# per repetition, the three techniques' mean ranks at equal spp and at
# equal time, whether the copies tied at both and the doubled one ranked
# below them at equal time ("–": a set left out of equal time for its
# calibration), the seeds jobs of the season (whose runs and
# what they cost), the scenes the runner measured again because the
# machine was slow during them and the sets the service measured again for
# their runner's calibration, the minutes it took, and whether the two
# copies' runs had the same seeds (a seeds job given to one copy's run and
# not the other's judges third techniques against them on different
# seeds); then the counts.
#
#   [ROUNDS=N | COPIES=a,b] [MAX_SEEDS=M] [SCENES=a,b] [SPP=x,y] bash deploy/bench-service-ties.sh [REPETITIONS]   # default 20
#
# COPIES=nlm,nfor,… publishes each listed baseline (sdk/techniques/<name>)
# twice instead, as <name>-a and <name>-b, with no doubled copy (its
# column reads "–"): the between-job noise of real techniques, one row per
# baseline and season, which deploy/job-noise.py reads off the kept sets.
# SCENES and SPP replace the sphere and sin-bands at 4 and 16 spp (SPP=
# empty: each scene's own budgets); ROUNDS=1 is the plain box filter's
# arithmetic, the walk of README's service (ci-runner/README) on
# SCENES=experimental/black-ring,…  SPP= ROUNDS=1 (there the doubled copy's
# second sum is lost in its memory traffic: it costs about what the copies
# do, and "doubled below" reads NO). Each set's results (its runs' times by
# seed) are kept in target/bench-service-ties/sets/, which
# deploy/replay-service-ties.py ranks again with another `fbksd`.
#
# About 3 min per repetition on 2 cores, after the release build, the
# images and the two references (serve.sh caches them). Run it on an
# otherwise idle machine: it measures noise.
set -euo pipefail
cd "$(dirname "$0")/.."
repetitions=${1:-20}
rounds=${ROUNDS:-30}
work=$(pwd)/target/bench-service-ties
bind=127.0.0.1:8197
rm -rf "$work"
mkdir -p "$work/techniques" "$work/sets"

# The techniques, as submission repositories; groups.txt lists each group:
# its name, its two copies and its doubled copy, if any.
list="$work/techniques/list.txt"
if [ -n "${COPIES:-}" ]; then
    : >"$work/techniques/groups.txt"
    for name in ${COPIES//,/ }; do
        [ -f "sdk/techniques/$name/info.json" ] || { echo "COPIES: sdk/techniques/$name is not a technique" >&2; exit 1; }
        cp -r "sdk/techniques/$name" "$work/techniques/$name-a"
        cp -r "sdk/techniques/$name" "$work/techniques/$name-b"
        printf '%s\n' "$name-a" "$name-b" >>"$list"
        echo "$name $name-a $name-b" >>"$work/techniques/groups.txt"
    done
else
    . deploy/lib/heavy-box-filter.sh
    heavy_box_filter "$work/techniques/box-copy-a" "$rounds"
    heavy_box_filter "$work/techniques/box-copy-b" "$rounds"
    heavy_box_filter "$work/techniques/box-doubled" $((2 * rounds))
    printf '%s\n' box-copy-a box-copy-b box-doubled >"$list"
    echo "box box-copy-a box-copy-b box-doubled" >"$work/techniques/groups.txt"
fi

server_env=()
[ -n "${MAX_SEEDS:-}" ] && server_env=(FBKSD_SERVER_MAX_SEEDS="$MAX_SEEDS")
spp=${SPP-4,16}
[ -n "$spp" ] && server_env+=(FBKSD_CI_SPP="$spp")
# setsid: the service gets a process group of its own, stopped as one.
env "${server_env[@]}" FBKSD_DATA_DIR="$work/data" FBKSD_RUNNER_DIR="$work/runner" \
    FBKSD_SERVER_BIND="$bind" FBKSD_BASELINES="$list" \
    FBKSD_CI_SCENES="${SCENES:-experimental/sphere,experimental/sin-bands}" \
    setsid bash deploy/serve.sh >"$work/serve.log" 2>&1 &
serve=$!
trap 'kill -INT -- -$serve 2>/dev/null; wait $serve 2>/dev/null || true' EXIT

echo "CPU: $(sed -n 's/^model name\s*: //p' /proc/cpuinfo | head -1), $(nproc) cores; ${repetitions} repetitions (seasons), ${COPIES:-${rounds} rounds per sample}, max_seeds ${MAX_SEEDS:-12 (default)}"
echo
python3 - "$bind" "$repetitions" "$work" "$serve" <<'EOF' | tee "$work/table.md"
import json, os, re, statistics, sys, time, urllib.error, urllib.request
bind, repetitions, work, serve = sys.argv[1], int(sys.argv[2]), sys.argv[3], int(sys.argv[4])
url = f"http://{bind}"
groups = {line.split()[0]: line.split()[1:] for line in open(f"{work}/techniques/groups.txt")}
names = [name for group in groups.values() for name in group]
show = lambda r: " / ".join("–" if v is None else f"{v:.2f}" for v in r)

def call(method, path, body=None, token=None, session=None):
    headers = {"Content-Type": "application/json"}
    if token:
        headers["Authorization"] = f"Bearer {token}"
    if session:
        headers["Cookie"], headers["X-CSRF-Token"] = session
    data = json.dumps(body).encode() if body is not None else None
    request = urllib.request.Request(url + path, data=data, method=method, headers=headers)
    with urllib.request.urlopen(request, timeout=30) as answer:
        text = answer.read()
        return json.loads(text) if text else None, answer.headers

def alive():
    try:
        os.kill(serve, 0)
    except OSError:
        sys.exit(f"serve.sh stopped: see {work}/serve.log")

def wait_for(what, ready, limit_s=3 * 3600):
    start = time.time()
    while True:
        alive()
        try:
            value = ready()
            if value:
                return value
        except (OSError, urllib.error.URLError):
            pass
        if time.time() - start > limit_s:
            sys.exit(f"bench-service-ties: {what}: not within {limit_s / 60:.0f} min")
        time.sleep(2)

# The administrator's one-time password, from serve.sh's log; replaced, then a token.
def credentials():
    found = re.search(r"administrator created: (\S+) / (\S+)", open(f"{work}/serve.log").read())
    return found.groups() if found else None
email, once = wait_for("the administrator's password in serve.log", credentials, 1800)
def log_in(password):
    answer, headers = call("POST", "/api/v1/sessions", {"email": email, "password": password})
    return headers["Set-Cookie"].split(";")[0], answer["csrf_token"]
password = "bench-service-ties-" + os.urandom(8).hex()
call("PATCH", "/api/v1/me", {"current_password": once, "new_password": password}, session=log_in(once))
token = call("POST", "/api/v1/tokens", {"name": "bench-service-ties"}, session=log_in(password))[0]["token"]

def jobs():
    return call("GET", "/api/v1/admin/jobs", token=token)[0]

def settled(season):
    """The season's board once all three are on it and nothing is queued or
    running. The planner looks at a changed board every 2 s, so "nothing"
    must hold for 10 s (five looks) before the board is read."""
    board = call("GET", "/api/v1/leaderboard")[0]
    if board["season"] != season or len(board["standings"]) < len(names):
        return None
    if any(j["state"] in ("queued", "running") for j in jobs()):
        settled.quiet_since = None
        return None
    settled.quiet_since = settled.quiet_since or time.time()
    return board if time.time() - settled.quiet_since >= 10 else None
settled.quiet_since = None

def what(job):
    # "… rests on N of its runs (…)" while it waits, "N repeats added to result set …" once it succeeded.
    found = re.search(r"rests on \d+ of its runs|\d+ repeats added", job["message"])
    return found.group(0) if found else job["state"]

def seeds_jobs(season):
    return ", ".join(f"{j['project']} ({what(j)})" for j in jobs() if j["kind"] == "seeds" and j["season"] == season) or "none"

def disturbance(board):
    """How much faster the machine ran in one set's job than in another's,
    read off the renderer: it does the same work for every technique (the
    same scene, the same samples), so its CPU per sample is the machine's
    speed during that job. The largest ratio of two sets' medians over the
    scenes."""
    rates = {}
    for set_id in {e["result_id"] for g in board["groups"] for e in g["entries"]}:
        result = call("GET", f"/api/v1/results/{set_id}")[0]
        json.dump(result, open(f"{work}/sets/{set_id}.json", "w"))
        for run in result["runs"]:
            per_sample = [r["render_cpu_ms"] / r["used_samples"] for r in run["repeats"] if r.get("used_samples")]
            if per_sample:
                rates.setdefault(run["scene"], {}).setdefault(set_id, []).extend(per_sample)
    worst = max((max(m) / min(m) for m in ([statistics.median(v) for v in by_set.values()] for by_set in rates.values())), default=1.0)
    return f"{worst:.2f}×"

def measured_again(season):
    """The scenes the runner measured again because its renderer ran
    markedly slower than its usual there (ci-runner/src/renderer_rates.rs),
    in the season's jobs, with the slowdown that set each off."""
    found = []
    for j in jobs():
        if j["season"] == season and j["kind"] in ("benchmark", "seeds"):
            log = "".join(c["text"] for c in call("GET", f"/api/v1/jobs/{j['id']}/log", token=token)[0]["chunks"])
            found += [f"{j['project']} {m.group(1)} {m.group(2)}×" for m in re.finditer(r"\] (\S+): the renderer ran at ([0-9.]+)×", log)]
        if j["season"] == season and j.get("measures_again"):
            # A set the service measured again for its runner's calibration (server/src/measure_again.rs).
            drift = re.search(r"class's \(([^)]*)\)", j["message"])
            found.append(f"{j['project']}'s set ({drift.group(1) if drift else 'calibration'}: {j['state']})")
    return ", ".join(found) or "none"

def seeds_by_run(set_id):
    result = json.load(open(f"{work}/sets/{set_id}.json"))
    return {(run["scene"], run["spp"]): sorted(r["seed"] for r in run["repeats"]) for run in result["runs"]}

print("| repetition | technique | copy a, copy b(, doubled) at equal spp | at equal time | copies tie at both | doubled below at equal time | renderer rate, slowest set / fastest | seeds jobs | measured again | min | copies' seeds alike |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
season = 1
for repetition in range(1, repetitions + 1):
    started = time.time()
    if repetition > 1:
        season = call("POST", "/api/v1/admin/seasons", {"note": f"bench-service-ties repetition {repetition}"}, token=token)[0]["season"]
    settled.quiet_since = None
    board = wait_for(f"season {season}'s board", lambda: settled(season))
    json.dump(board, open(f"{work}/board-{repetition}.json", "w"))
    ranks = {s["technique"]: (s["mean_rank"], s["mean_rank_time"]) for s in board["standings"]}
    set_of = {s["technique"]: s["result_id"] for s in board["standings"]}
    rate, seeds, again = disturbance(board), seeds_jobs(season), measured_again(season)
    minutes = (time.time() - started) / 60
    for label, group in groups.items():
        spp = [ranks[n][0] for n in group]
        at_time = [ranks[n][1] for n in group]
        # A set measured while its runner's calibration lay off its class's is
        # ranked at equal spp only (no rank at equal time, shown "–"): a miss.
        timed = None not in at_time
        tie = spp[0] == spp[1] and timed and at_time[0] == at_time[1]
        below = "–" if len(group) < 3 else "yes" if timed and at_time[2] > max(at_time[0], at_time[1]) else "NO"
        a, b = seeds_by_run(set_of[group[0]]), seeds_by_run(set_of[group[1]])
        unlike = [f"{scene} {spp} spp: {len(a.get((scene, spp), []))} / {len(b.get((scene, spp), []))}" for scene, spp in sorted(set(a) | set(b)) if a.get((scene, spp)) != b.get((scene, spp))]
        alike = "yes" if not unlike else "NO (" + "; ".join(unlike) + ")"
        print(f"| {repetition} | {label} | {show(spp)} | {show(at_time)} | {'yes' if tie else 'NO'} | {below} | {rate} | {seeds} | {again} | {minutes:.1f} | {alike} |", flush=True)
EOF
echo
awk -F'|' '/^\| [0-9]/ { n++; if ($6 ~ /yes/) tie++; if ($7 !~ /–/) { d++; if ($7 ~ /yes/) below++ }
        if ($12 ~ /yes/) alike++
        if (!($2 in seen)) { seen[$2]; seasons++; if ($9 !~ /none/) seeds++; if ($10 !~ /none/) again++; minutes += $11 } }
    END { printf "copies tied at equal spp and at equal time in %d of %d; doubled ranked below them at equal time in %d of %d; copies given the same seeds in %d of %d; seeds jobs in %d of %d seasons; scenes or sets measured again in %d of %d; %.1f min per season\n", tie, n, below, d, alike, n, seeds, seasons, again, seasons, minutes / seasons }' "$work/table.md"
