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
echo "== Cornell box, 512×512, 64 spp =="
./target/release/fbksd-embree bench "$cornell" --spp 64 --out-dir "$out/ours" | tee "$out/ours.txt"
python3 renderers/embree/bench/mitsuba_bench.py "$out/mitsuba-scene" 64 "$out/mitsuba.exr" | tee "$out/mitsuba.txt"
# The all-cores figure is the last "M samples/s" of each line.
all_cores() { grep -o '[0-9.]* M samples/s' "$1" | tail -n 1 | cut -d' ' -f1; }
python3 -c "import sys; print(f'ours / Mitsuba on all cores: {float(sys.argv[1]) / float(sys.argv[2]):.2f}x')" \
    "$(all_cores "$out/ours.txt")" "$(all_cores "$out/mitsuba.txt")"
echo "== Hair, 512×512, 16 spp =="
./target/release/fbksd-embree bench scenes/production/hair/scene.pbrt --spp 16
echo "== Agreement of the two Cornell images (each 64 spp) =="
./target/release/fbksd-embree compare "$out/mitsuba.exr" "$out/ours/cornell-box.exr"
for metric in rMSE PSNR; do
    echo "$metric: $(./target/release/fbksd iqa "$metric" "$out/mitsuba.exr" "$out/ours/cornell-box.exr")"
done
