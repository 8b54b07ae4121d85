#!/usr/bin/env bash
# Builds FBKSD and runs a local benchmark end to end: references of the
# experimental scenes and of the small production scenes (built once, then
# cached beside each scene), the Rust
# box filter on every scene at 1, 4 and 16 spp, metric values and error
# maps, and the ranking. Results go to ./fbksd-results.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked --workspace --bins --lib
bin=target/release
say() { echo "local-benchmark: $*" >&2; }
. deploy/lib/images.sh
. deploy/lib/renderers.sh
renderers_on_path "$(pwd)/$bin" "$(pwd)/target/local-benchmark/python"
make_references scenes/experimental/* scenes/production-small/*
scenes=()
for dir in scenes/experimental/*/ scenes/production-small/*/; do
    scenes+=(--scene "$dir")
done
status=0
"$bin/fbksd" run --technique "$bin/box-filter" "${scenes[@]}" --spp 1,4,16 --results fbksd-results || status=$?
"$bin/fbksd" results compute --results fbksd-results --scenes scenes
"$bin/fbksd" results show --results fbksd-results
exit "$status"
