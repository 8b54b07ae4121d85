#!/usr/bin/env bash
# Times what references built once save: a server (SQLite, a temporary data
# directory) and two runners, each with its own copy of the scene files and
# no reference. The first runner makes every reference of the pool as the
# service's reference jobs; the second, started once the first is ready,
# downloads and checks them. Prints both times to ready and their ratio.
#
#   bash deploy/bench-references.sh [--bin-dir DIR] [SCENE,SCENE,...]
#
# The binaries are target/release's unless --bin-dir names others (the
# tests' debug build is optimised too); the job images must exist
# (deploy/build-images.sh, whose manifest is read from the bin directory or
# fbksd-data/images.json). The default pool is serve.sh's scenes but the two
# Mitsuba ones.
set -euo pipefail
cd "$(dirname "$0")/.."
bin=$(pwd)/target/release
if [ "${1:-}" = --bin-dir ]; then bin=$(cd "$2" && pwd); shift 2; fi
scenes=${1:-experimental/black-ring,experimental/defocus-checkerboard,experimental/fireflies,experimental/mandelbrot,experimental/moving-bars,experimental/sin-bands,experimental/sphere,production-small/cornell-box}
manifest=$bin/fbksd-test-images.json
[ -f "$manifest" ] || manifest=$(pwd)/fbksd-data/images.json
[ -f "$manifest" ] || { echo "bench-references: no image manifest: run deploy/build-images.sh first" >&2; exit 1; }
for f in fbksd-server fbksd-ci lib_native.so; do
    [ -x "$bin/$f" ] || { echo "bench-references: $bin/$f is missing: cargo build --release" >&2; exit 1; }
done
work=$(mktemp -d)
# A Mitsuba scene in the pool needs fbksd-mitsuba and the Python SDK on the runners' paths.
say() { echo "bench-references: $*" >&2; }
. deploy/lib/images.sh
. deploy/lib/renderers.sh
renderers_on_path "$bin" "$work/python"
port=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
url=http://127.0.0.1:$port
FBKSD_SERVER_DATA_DIR=$work/data FBKSD_SERVER_BIND=127.0.0.1:$port FBKSD_SERVER_RUNNER_REGISTRATION_TOKEN=bench \
    "$bin/fbksd-server" >"$work/server.log" 2>&1 &
pids=($!)
trap 'kill "${pids[@]}" 2>/dev/null; wait 2>/dev/null; rm -rf "$work"' EXIT
for _ in $(seq 300); do curl -sf "$url/healthz" >/dev/null && break; sleep 0.2; done
now() { date +%s.%N; }
runner() { # NAME: a runner with its own scene files, none of their references
    cp -r scenes "$work/scenes-$1"
    find "$work/scenes-$1" -name 'reference*' -delete
    "$bin/fbksd-ci" --server "$url" --registration-token bench --name "$1" --work-dir "$work/runner-$1" \
        --images "$manifest" --scene-root "$work/scenes-$1" --scene "$scenes" --poll-seconds 1 >"$work/$1.log" 2>&1 &
    pids+=($!)
}
ready() { # NAME: waits until the runner is ready
    until grep -q " ready: " "$work/$1.log"; do
        kill -0 "${pids[-1]}" 2>/dev/null || { cat "$work/$1.log" >&2; exit 1; }
        sleep 0.1
    done
}
t0=$(now); runner first; ready first; t1=$(now)
runner second; ready second; t2=$(now)
# The job log repeats each "making reference" line after "[fbksd-ci]".
count_made() { grep -v '\[fbksd-ci\]' "$1" | grep -c 'making reference' || true; }
made=$(count_made "$work/first.log")
downloaded=$(grep -c 'reference of .* downloaded' "$work/second.log" || true)
remade=$(count_made "$work/second.log")
echo "bench-references: first runner to ready, making the $made references: $(echo "$t1 - $t0" | bc) s"
echo "bench-references: second runner to ready, downloading $downloaded and making $remade: $(echo "$t2 - $t1" | bc) s"
echo "bench-references: ratio $(echo "scale=1; ($t1 - $t0) / ($t2 - $t1)" | bc)x; stored: $(du -sh "$work/data/scene-references" | cut -f1)"
