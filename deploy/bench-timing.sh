#!/usr/bin/env bash
# Timing noise: the C++ box filter, NFOR (C++, OpenMP) and NL-means (Python)
# on the procedural sphere and the Embree Cornell box at 16 spp, each run
# REPEATS times (default 5) with other sample seeds through `fbksd run`
# with release binaries; prints, per technique and scene, the median
# technique time and time to result with their coefficients of variation
# (markdown, on stdout). The C++ techniques are built as
# deploy/bench-baselines.sh builds them.
#
#   [REPEATS=N] bash deploy/bench-timing.sh
set -euo pipefail
cd "$(dirname "$0")/.."
work=$PWD/target/bench-timing
rm -rf "$work/results" && mkdir -p "$work/python/fbksd"
cargo build --release --locked --workspace --bins --lib >&2
bash deploy/install-sdk.sh "$work/sdk" target/release >&2
cp sdk/python/python/fbksd/*.py "$work/python/fbksd/"
cp target/release/lib_native.so "$work/python/fbksd/_native.so"
export PYTHONPATH=$work/python
target/release/fbksd-procedural reference scenes/experimental/sphere >&2
target/release/fbksd-embree reference scenes/production-small/cornell-box >&2
for name in box-filter-cpp nfor; do
    cmake -S "sdk/techniques/$name" -B "$work/build/$name" -DCMAKE_BUILD_TYPE=Release -DCMAKE_PREFIX_PATH="$work/sdk" >&2
    cmake --build "$work/build/$name" -j2 >&2
done
target/release/fbksd run -t "box-filter-cpp=$work/build/box-filter-cpp/box-filter-cpp" -t "nfor=$work/build/nfor/nfor" \
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
