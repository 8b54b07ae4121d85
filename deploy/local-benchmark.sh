#!/usr/bin/env bash
# Builds FBKSD and runs a local benchmark: the Rust box filter on the
# analytic scenes at 1, 4 and 16 spp. Results go to ./fbksd-results.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build --release --locked --workspace --bins
bin=target/release
"$bin/fbksd" run \
    --technique "$bin/box-filter" \
    --renderer "$bin/fbksd-analytic-renderer" \
    --scene scenes/analytic/gradient.json \
    --scene scenes/analytic/small.json \
    --spp 1,4,16 \
    --results fbksd-results
