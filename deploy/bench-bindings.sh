#!/usr/bin/env bash
# The box filter in Rust, C++ and Python (the tuned one of
# sdk/techniques/box-filter-python, and the thesis's B.1 as printed) at
# 16, 64 and 256 spp on 1024×1024 images, through `fbksd run`, each run
# repeated; prints the median wall, technique and CPU time per technique
# and budget, and each one's ratio to Rust.
#
# Two renderers: the analytic renderer's "constant" pattern (it costs only
# the memory it writes, so the table shows the bindings' own cost) and the
# procedural renderer on listing C.1's sphere (a renderer that works).
#
#   bash deploy/bench-bindings.sh [REPEATS]     # default 3
set -euo pipefail
cd "$(dirname "$0")/.."
repeats=${1:-3}
root=$PWD
work=$root/target/bench-bindings
rm -rf "$work" && mkdir -p "$work"

cargo build --release --locked --workspace >&2
bash deploy/install-sdk.sh "$work/sdk" target/release >&2
cmake -S sdk/techniques/box-filter-cpp -B "$work/build" -DCMAKE_BUILD_TYPE=Release \
    -DCMAKE_PREFIX_PATH="$work/sdk" >&2
cmake --build "$work/build" >&2
# The Python package as pip would install it: sources and the release native module.
say() { echo "bench-bindings: $*" >&2; }
. deploy/lib/images.sh
stage_python_sdk "$work/python" target/release
export PYTHONPATH=$work/python
# The techniques' `#!/usr/bin/env python3` finds the interpreter itself, as in
# a sandbox, not a version manager's shim before it (pyenv's costs 70 ms a
# start on the development machine, none of it ours).
PATH="$(dirname "$(python3 -c 'import sys; print(sys.executable)')"):$PATH"

echo '{"width": 1024, "height": 1024, "pattern": "constant"}' > "$work/constant.json"
sed -e 's/^width := .*/width := 1024;/' -e 's/^height := .*/height := 1024;/' \
    scenes/experimental/sphere/sphere.expr > "$work/sphere.expr"

run() { # renderer scene results-dir
    target/release/fbksd run \
        -t rust=target/release/box-filter \
        -t cpp="$work/build/box-filter-cpp" \
        -t python=sdk/techniques/box-filter-python/box_filter.py \
        -t python-b1=sdk/python/examples/b1_box_filter.py \
        -r "$1" -s "$2" --spp 16,64,256 --results "$3" >&2
}
for i in $(seq "$repeats"); do
    run target/release/fbksd-analytic-renderer "$work/constant.json" "$work/results-$i"
    run target/release/fbksd-procedural "$work/sphere.expr" "$work/results-$i"
done

python3 - "$work" "$repeats" <<'PY'
import json, statistics, sys
work, repeats = sys.argv[1], int(sys.argv[2])
times = {}
for i in range(1, repeats + 1):
    for run in json.load(open(f"{work}/results-{i}/index.json"))["runs"]:
        log = json.load(open(f"{work}/results-{i}/{run['technique']}/{run['scene']}/{run['spp']}_0_log.json"))
        key = (run["scene"], run["spp"], run["technique"])
        times.setdefault(key, []).append(log["times"])
print(f"box filter on 1024x1024, median of {repeats} runs (ms); ratio = wall / Rust's wall")
print(f"{'scene':9} {'spp':>4} {'technique':10} {'wall':>8} {'technique':>10} {'cpu':>8} {'ratio':>6}")
for scene in sorted({k[0] for k in times}):
    for spp in sorted({k[1] for k in times if k[0] == scene}):
        rust = statistics.median(t["wall_ms"] for t in times[(scene, spp, "rust")])
        for technique in ["rust", "cpp", "python", "python-b1"]:
            ts = times.get((scene, spp, technique))
            if not ts:
                continue
            m = {k: statistics.median(t[k] for t in ts) for k in ("wall_ms", "technique_ms", "cpu_ms")}
            print(f"{scene:9} {spp:>4} {technique:10} {m['wall_ms']:8.0f} {m['technique_ms']:10.0f} "
                  f"{m['cpu_ms']:8.0f} {m['wall_ms'] / rust:6.2f}")
PY
