#!/usr/bin/env bash
# Every baseline of sdk/techniques/baselines.txt on the service's default
# scene pool (the nine experimental scenes and the small Cornell box) at
# 4, 16 and 64 spp, through `fbksd run` with release binaries, as the
# service would benchmark them; then the metrics, and a table in the form
# of the thesis's figure 6.6: rMSE, PSNR, SSIM, FLIP, technique time and
# render time per technique, scene and budget (markdown, on stdout); then
# the equal-time comparison: each technique's rMSE at the cheapest
# technique's cost at each budget (sdk/exchange/src/cost.rs), and the mean ranks at equal
# samples and at equal time. References are made once and cached beside
# the scenes. REPEATS=N makes each run N times with other sample seeds.
#
#   [REPEATS=N] bash deploy/bench-baselines.sh [SPP] [SCENE...]   # default 4,16,64 and the pool
set -euo pipefail
cd "$(dirname "$0")/.."
spp=${1:-4,16,64}
shift || true
scenes=("$@")
if [ ${#scenes[@]} -eq 0 ]; then
    scenes=(scenes/experimental/* scenes/production-small/cornell-box)
fi
work=$PWD/target/bench-baselines
source deploy/bench-env.sh
bench_env "$work"

make_references "${scenes[@]}"

# Each baseline built as the service builds it (CMake, Release) or run as it is.
techniques=()
while read -r name; do
    repo=sdk/techniques/$name
    if [ -f "$repo/CMakeLists.txt" ]; then
        dir=$(build_technique "$name")
    else
        dir=$repo
    fi
    while IFS=$'\t' read -r version executable; do
        techniques+=(-t "$version=$dir/$executable")
    done < <(python3 -c '
import json, sys
info = json.load(open(sys.argv[1]))
for v in info["versions"]:
    name = sys.argv[2] if len(info["versions"]) == 1 else sys.argv[2] + "-" + v["name"]
    print(name + "\t" + v["executable"])' "$repo/info.json" "$name")
done < <(sed -e 's/#.*//' -e '/^[[:space:]]*$/d' sdk/techniques/baselines.txt)

scene_args=()
for scene in "${scenes[@]}"; do scene_args+=(-s "$scene"); done
target/release/fbksd run "${techniques[@]}" "${scene_args[@]}" --spp "$spp" --results "$work/results" \
    --time-limit 20m --repeats "${REPEATS:-1}" >&2 || echo "bench-baselines: some runs failed (see the table's status)" >&2
target/release/fbksd results compute --results "$work/results" --scenes scenes >&2

python3 - "$work/results/index.json" <<'PY'
import json, sys
runs = json.load(open(sys.argv[1]))["runs"]
print("| scene | spp | technique | rMSE | PSNR | SSIM | FLIP | technique s | render s | status |")
print("|---|---|---|---|---|---|---|---|---|---|")
for r in sorted(runs, key=lambda r: (r["scene"], r["spp"], r["technique"])):
    m = r.get("metrics", {})
    def value(key, digits):
        return f"{m[key]:.{digits}f}" if key in m else "—"
    print(f"| {r['scene']} | {r['spp']} | {r['technique']} | {value('rMSE', 4)} | {value('PSNR', 2)} | "
          f"{value('SSIM', 4)} | {value('FLIP', 4)} | {r['technique_ms'] / 1000:.2f} | "
          f"{r['render_ms'] / 1000:.2f} | {r['status']} |")

rankings = json.load(open(sys.argv[1])).get("rankings")
if rankings:
    print("\n**Equal time** (rMSE at the cheapest technique's cost at each budget; — : costs more)\n")
    cells = [c for c in rankings["equal_time"]["cells"] if c["metric"] == "rMSE"]
    techniques = sorted({p["technique"] for c in cells for p in c["places"]} | {t for c in cells for t in c["missing"]})
    print("| scene | cost s | cheapest | " + " | ".join(techniques) + " |")
    print("|---|---|---|" + "---|" * len(techniques))
    for c in cells:
        at = c["at"]
        values = {p["technique"]: f"{p['mean']:.4f} (#{p['place']:g})" for p in c["places"]}
        print(f"| {c['scene']} | {at['ms'] / 1000:.2f} | {at['fastest']} at {at['spp']} | "
              + " | ".join(values.get(t, "—") for t in techniques) + " |")
    time_rank = {s["technique"]: s["mean_rank"] for s in rankings["equal_time"]["standings"]}
    print("\n| technique | mean rank, equal spp | mean rank, equal time | ties |")
    print("|---|---|---|---|")
    for s in rankings["equal_spp"]["standings"]:
        print(f"| {s['technique']} | {s['mean_rank']:.2f} | {time_rank.get(s['technique'], float('nan')):.2f} | {s['tied']} |")
PY
echo "bench-baselines: results in $work/results (\`target/release/fbksd results page --results $work/results --scenes scenes\` for the viewer)" >&2
