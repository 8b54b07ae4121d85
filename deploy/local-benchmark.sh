#!/usr/bin/env bash
# Builds FBKSD and runs a local benchmark: the Rust box filter on the
# experimental scenes (procedural renderer) at 1, 4 and 16 spp.
# Results go to ./fbksd-results.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked --workspace --bins
bin=target/release
scenes=()
for dir in scenes/experimental/*/; do
    scenes+=(--scene "$dir")
done
"$bin/fbksd" run --technique "$bin/box-filter" "${scenes[@]}" --spp 1,4,16 --results fbksd-results
