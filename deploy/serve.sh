#!/usr/bin/env bash
# The whole service on this machine: fbksd-server on http://127.0.0.1:8096
# (SQLite and data in ./fbksd-data) with an fbksd-ci runner beside it, so a
# pushed technique is built and benchmarked with nothing else but Docker.
#
# First start: builds the release binaries and the images (a few minutes),
# and the references of the runner's scene pool (cached beside each scene).
# The server prints the administrator's one-time password. Ctrl-C stops both.
#
#   bash deploy/serve.sh
#
# The runner's settings are fbksd-ci's flags as FBKSD_CI_* variables, e.g.
# FBKSD_CI_SCENES=experimental/sphere,experimental/fireflies FBKSD_CI_SPP=1,4.
set -euo pipefail
cd "$(dirname "$0")/.."
data=${FBKSD_DATA_DIR:-fbksd-data}
mkdir -p "$data"
cargo build --release --locked -p fbksd-server -p fbksd-ci -p fbksd-capi -p fbksd-python -p fbksd-procedural -p fbksd-embree
bin=target/release
bash deploy/build-images.sh --bin-dir "$bin" --manifest "$data/images.json"

# The runner's scene pool (default: the experimental scenes and the small
# Cornell box: about five minutes of references on two cores) and its references.
: "${FBKSD_CI_SCENES:=experimental/black-ring,experimental/defocus-checkerboard,experimental/fireflies,experimental/mandelbrot,experimental/moving-bars,experimental/sin-bands,experimental/sphere,production-small/cornell-box}"
export FBKSD_CI_SCENES
IFS=, read -ra pool <<<"$FBKSD_CI_SCENES"
for scene in "${pool[@]}"; do
    if [ ! -f "scenes/$scene/reference.exr" ]; then
        renderer=$(python3 -c 'import json,sys; print(json.load(open(sys.argv[1]))["renderer"])' "scenes/$scene/fbksd-scene.json")
        "$bin/fbksd-$renderer" reference "scenes/$scene"
    fi
done

# One registration token shared by the server and its runner, kept private.
token_file="$data/runner-registration-token"
if [ ! -s "$token_file" ]; then
    (umask 077 && echo "fbksdreg_$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')" >"$token_file")
fi
token=$(cat "$token_file")

export FBKSD_SERVER_DATA_DIR="$data"
export FBKSD_SERVER_RUNNER_REGISTRATION_TOKEN="$token"
"$bin/fbksd-server" &
server=$!
trap 'kill $server $runner 2>/dev/null; wait' EXIT INT TERM
runner=""
bind=${FBKSD_SERVER_BIND:-127.0.0.1:8096}
for _ in $(seq 100); do
    python3 -c 'import socket,sys; h,p=sys.argv[1].rsplit(":",1); socket.create_connection((h,int(p)),1)' "$bind" 2>/dev/null && break
    sleep 0.2
done
"$bin/fbksd-ci" --server "http://$bind" --registration-token "$token" --work-dir "$data/ci" \
    --images "$data/images.json" --scene-root scenes &
runner=$!
wait -n "$server" "$runner"
