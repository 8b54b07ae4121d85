#!/usr/bin/env bash
# The whole service on this machine: fbksd-server on http://127.0.0.1:8096
# (SQLite and data in ./fbksd-data) with an fbksd-ci runner beside it, so a
# pushed technique is built and benchmarked with nothing else but Docker.
#
#   bash deploy/serve.sh
#
# The server starts first, as soon as it is built: registration, projects
# and pushes work at once, and jobs wait in the queue while the rest is
# prepared (the runner's binaries and images, then the references of its
# scene pool, which the runner makes itself and reports on the home page).
# Everything is cached for the next start. Ctrl-C stops both.
#
# Options, as environment variables:
#   FBKSD_DATA_DIR   the data directory (default fbksd-data, relative to the repository)
#   FBKSD_RUNNER_DIR the runner's work directory (default fbksd-runner): apart from the
#                    server's data, so a job filling it cannot fill the server's disk quota
#   FBKSD_PROFILE    release (default), or debug: the binaries of `cargo build --workspace`, as they are (CI)
#   FBKSD_SERVER_*   the server's settings, e.g. FBKSD_SERVER_BIND=127.0.0.1:9000
#   FBKSD_CI_*       the runner's flags, e.g. FBKSD_CI_SCENES=experimental/sphere FBKSD_CI_SPP=1,4
#   FBKSD_BASELINES  the baselines published on the board's first start (default
#                    sdk/techniques/baselines.txt; empty for none)
set -euo pipefail
cd "$(dirname "$0")/.."
data=${FBKSD_DATA_DIR:-fbksd-data}
mkdir -p "$data"
# Absolute, for everything started below (the server resolves it too).
data=$(cd "$data" && pwd)
runner_dir=${FBKSD_RUNNER_DIR:-fbksd-runner}
mkdir -p "$runner_dir"
runner_dir=$(cd "$runner_dir" && pwd)

case "${FBKSD_PROFILE:-release}" in
    release) build() { cargo build --release --locked "$@"; }; bin=target/release ;;
    # The binaries the test build made, as they are: no cargo here, since a
    # rebuild would re-link libraries other tests are using at that moment.
    debug)
        build() {
            for program in fbksd-server fbksd-ci fbksd-procedural fbksd-embree libfbksd.so lib_native.so; do
                [ -f "target/debug/$program" ] || { echo "serve: target/debug/$program is missing: cargo build --workspace first" >&2; exit 1; }
            done
        }
        bin=target/debug ;;
    *) echo "serve: FBKSD_PROFILE must be release or debug, not '$FBKSD_PROFILE'" >&2; exit 1 ;;
esac
bin=$(pwd)/$bin

# One registration token shared by the server and its runner, kept private.
token_file="$data/runner-registration-token"
if [ ! -s "$token_file" ]; then
    (umask 077 && echo "fbksdreg_$(od -An -N16 -tx1 /dev/urandom | tr -d ' \n')" >"$token_file")
fi
token=$(cat "$token_file")

server="" runner="" baselines=""
# The runner first (it removes its containers), then the server. No `set -e`
# here: a process that has already ended must not stop the stopping.
stop() {
    trap - EXIT INT TERM
    set +e
    if [ -n "$baselines" ]; then kill -TERM "$baselines" 2>/dev/null; wait "$baselines" 2>/dev/null; fi
    if [ -n "$runner" ]; then kill -TERM "$runner" 2>/dev/null; wait "$runner" 2>/dev/null; fi
    if [ -n "$server" ]; then kill -TERM "$server" 2>/dev/null; wait "$server" 2>/dev/null; fi
}
trap 'stop; exit 130' INT
trap 'stop; exit 143' TERM
trap stop EXIT

bind=${FBKSD_SERVER_BIND:-127.0.0.1:8096}
answers() { python3 -c 'import socket,sys; h,p=sys.argv[1].rsplit(":",1); socket.create_connection((h.strip("[]"),int(p)),1)' "$bind" 2>/dev/null; }
# Another service on the address would answer for ours, which cannot bind.
if answers; then
    echo "serve: something already answers at $bind (another serve.sh?): stop it, or set FBKSD_SERVER_BIND" >&2
    exit 1
fi

echo "serve: building the server" >&2
build -p fbksd-server
FBKSD_SERVER_DATA_DIR="$data" FBKSD_SERVER_RUNNER_REGISTRATION_TOKEN="$token" "$bin/fbksd-server" &
server=$!
for attempt in $(seq 150); do
    answers && break
    kill -0 "$server" 2>/dev/null || { echo "serve: the server stopped" >&2; exit 1; }
    [ "$attempt" -lt 150 ] || { echo "serve: the server does not answer at $bind after 30 s" >&2; exit 1; }
    sleep 0.2
done

echo "serve: the service answers; building the runner and its images (jobs wait in the queue meanwhile)" >&2
build -p fbksd-ci -p fbksd-capi -p fbksd-python -p fbksd-procedural -p fbksd-embree
bash deploy/build-images.sh --bin-dir "$bin" --manifest "$data/images.json"
# The runner makes the Mitsuba scenes' references here with fbksd-mitsuba,
# which imports the Python SDK just built (Mitsuba itself: deploy/setup.sh).
say() { echo "serve: $*" >&2; }
. deploy/lib/images.sh
. deploy/lib/renderers.sh
renderers_on_path "$bin" "$data/python-sdk"

# The runner's scene pool (default: the experimental scenes, two of them
# Mitsuba's, and the small Cornell box); it makes the missing references before it takes jobs.
: "${FBKSD_CI_SCENES:=experimental/black-ring,experimental/defocus-checkerboard,experimental/fireflies,experimental/glass-floor,experimental/mandelbrot,experimental/moving-bars,experimental/sin-bands,experimental/sphere,experimental/spheres-sky,production-small/cornell-box}"
export FBKSD_CI_SCENES
export FBKSD_CI_SCENE_ROOT=${FBKSD_CI_SCENE_ROOT:-$(pwd)/scenes}
# The token through the environment: a command line is readable by every user of the machine.
FBKSD_REGISTRATION_TOKEN="$token" "$bin/fbksd-ci" --server "http://$bind" --work-dir "$runner_dir" \
    --images "$data/images.json" &
runner=$!
echo "serve: runner started; it makes the references its scenes lack before it takes jobs (see the home page)" >&2

# The state of the art on the board: each baseline is pushed, benchmarked
# and published under the `baselines` account, the first time only (those
# on the current board are skipped). Users' jobs go first.
baseline_list=${FBKSD_BASELINES-sdk/techniques/baselines.txt}
if [ -n "$baseline_list" ]; then
    FBKSD_SERVER_DATA_DIR="$data" "$bin/fbksd-server" baselines "$baseline_list" --url "http://$bind" &
    baselines=$!
fi
wait -n "$server" "$runner"
