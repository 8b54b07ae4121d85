#!/usr/bin/env bash
# Speed of the Embree path tracer beside Mitsuba 3 (llvm_ad_rgb) in one run:
# the Cornell box at 512×512, 64 spp, same maximum path depth, one thread and
# all cores; then the hair scene; then how far the two Cornell images agree.
# Mitsuba (PyPI) and LLVM 19 (Debian) come with deploy/setup.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
bash deploy/setup.sh
cargo build --release --locked -p fbksd-embree -p fbksd
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
cornell=scenes/production/cornell-box/scene.pbrt
./target/release/fbksd-embree export-mitsuba "$cornell" "$out/mitsuba-scene"
# The all-cores figure is the last "M samples/s" of each line.
all_cores() { grep -o '[0-9.]* M samples/s' "$1" | tail -n 1 | cut -d' ' -f1; }
# Rounds of one run each, alternating, so that a machine whose speed
# drifts over minutes (a shared host) slows both alike; the ratio given is
# the median of the rounds' ratios.
rounds=${FBKSD_BENCH_ROUNDS:-3}
echo "== Cornell box, 512×512, 64 spp, $rounds rounds of ours then Mitsuba =="
ratios=()
for round in $(seq "$rounds"); do
    ./target/release/fbksd-embree bench "$cornell" --spp 64 --out-dir "$out/ours" | tee "$out/ours.txt"
    python3 renderers/embree/bench/mitsuba_bench.py "$out/mitsuba-scene" 64 "$out/mitsuba.exr" | tee "$out/mitsuba.txt"
    ratios+=("$(all_cores "$out/ours.txt")/$(all_cores "$out/mitsuba.txt")")
done
python3 - "${ratios[@]}" <<'PY'
import statistics, sys
pairs = [tuple(map(float, r.split("/"))) for r in sys.argv[1:]]
each = ", ".join(f"{o:.2f}/{m:.2f} = {o / m:.2f}x" for o, m in pairs)
print(f"ours / Mitsuba on all cores, by round: {each}")
print(f"ours / Mitsuba on all cores: {statistics.median(o / m for o, m in pairs):.2f}x (median of {len(pairs)} rounds)")
PY
echo "== Hair, 512×512, 16 spp =="
./target/release/fbksd-embree bench scenes/production/hair/scene.pbrt --spp 16
echo "== Agreement of the two Cornell images (each 64 spp) =="
./target/release/fbksd-embree compare "$out/mitsuba.exr" "$out/ours/cornell-box.exr"
for metric in rMSE PSNR; do
    echo "$metric: $(./target/release/fbksd iqa "$metric" "$out/mitsuba.exr" "$out/ours/cornell-box.exr")"
done
# Where the time goes, when perf (Debian's linux-perf) is installed: the
# share each renderer spends inside Embree, and so its Embree time per
# sample. Both call the same kind of Embree packet queries, so the part
# left is shading and bookkeeping; the bound printed last is how fast ours
# could be beside Mitsuba with that part free.
if command -v perf > /dev/null; then
    echo "== Time inside Embree (perf) =="
    embree_share() {
        perf report -i "$1" --no-children --sort dso --stdio 2> /dev/null \
            | awk '/libembree/ { gsub("%", "", $1); s += $1 } END { print s + 0 }'
    }
    perf record -q -o "$out/ours.perf" ./target/release/fbksd-embree bench "$cornell" --spp 64 > "$out/ours-perf.txt" 2> /dev/null
    perf record -q -o "$out/mitsuba.perf" python3 renderers/embree/bench/mitsuba_bench.py "$out/mitsuba-scene" 64 \
        > "$out/mitsuba-perf.txt" 2> /dev/null
    python3 - "$(nproc)" "$(all_cores "$out/ours.txt")" "$(all_cores "$out/mitsuba.txt")" \
        "$(embree_share "$out/ours.perf")" "$(embree_share "$out/mitsuba.perf")" <<'PY'
import sys
cores, ours, mitsuba, share_ours, share_mitsuba = map(float, sys.argv[1:])
# Nanoseconds of one core per sample, and the part of it inside Embree.
ns_ours, ns_mitsuba = cores * 1e3 / ours, cores * 1e3 / mitsuba
embree_ours, embree_mitsuba = ns_ours * share_ours / 100, ns_mitsuba * share_mitsuba / 100
print(f"ours:    {ns_ours:.0f} ns per sample, {embree_ours:.0f} in Embree ({share_ours:.0f} %), {ns_ours - embree_ours:.0f} the rest")
print(f"Mitsuba: {ns_mitsuba:.0f} ns per sample, {embree_mitsuba:.0f} in Embree ({share_mitsuba:.0f} %), {ns_mitsuba - embree_mitsuba:.0f} the rest")
print(f"ours / Mitsuba with the rest of ours free: at most {ns_mitsuba / embree_ours:.2f}x")
PY
else
    echo "(install linux-perf to see the time each renderer spends inside Embree)"
fi
