#!/usr/bin/env bash
# Timing noise: the C++ box filter, NFOR (C++, OpenMP) and NL-means (Python)
# on the procedural sphere and the Embree Cornell box at 16 spp, each run
# REPEATS times (default 5) with other sample seeds through `fbksd run`
# with release binaries; prints, per technique and scene, the median
# technique time and time to result with their coefficients of variation
# (markdown, on stdout). The C++ techniques are built as the service
# builds them (deploy/bench-env.sh).
#
#   [REPEATS=N] bash deploy/bench-timing.sh
set -euo pipefail
cd "$(dirname "$0")/.."
work=$PWD/target/bench-timing
source deploy/bench-env.sh
bench_env "$work"
target/release/fbksd-procedural reference scenes/experimental/sphere >&2
target/release/fbksd-embree reference scenes/production-small/cornell-box >&2
box=$(build_technique box-filter-cpp)
nfor=$(build_technique nfor)
target/release/fbksd run -t "box-filter-cpp=$box/box-filter-cpp" -t "nfor=$nfor/nfor" \
    -t "nlm=sdk/techniques/nlm/nlm.py" -s scenes/experimental/sphere -s scenes/production-small/cornell-box \
    --spp 16 --repeats "${REPEATS:-5}" --results "$work/results" >&2
python3 - "$work/results/index.json" <<'PY'
import json, sys
runs = json.load(open(sys.argv[1]))["runs"]
print("| technique | scene | seeds | technique time (median) | CV | time to result (median) | CV | CPU time CV |")
print("|---|---|---|---|---|---|---|---|")
for r in sorted(runs, key=lambda r: (r["technique"], r["scene"])):
    t = r["timing"]
    print(f"| {r['technique']} | {r['scene']} | {len(r['repeats'])} | {t['technique']['median']:.1f} ms | "
          f"{t['technique']['cv'] * 100:.1f} % | {t['time']['median']:.1f} ms | {t['time']['cv'] * 100:.1f} % | "
          f"{t['cpu']['cv'] * 100:.1f} % |")
PY
