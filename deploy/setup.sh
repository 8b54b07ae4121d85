#!/usr/bin/env bash
# Installs what a fresh Debian 12 machine lacks to build, run and test FBKSD.
# Idempotent: run it as often as you like.
set -euo pipefail

# Debian packages the build and the tests need (Embree 3 for the path tracer).
APT_PACKAGES=(build-essential pkg-config cmake libembree-dev python3-pip python3-venv
    # OpenCV headers: the thesis metric example A.3 is compiled by the tests.
    libopencv-core-dev libopencv-imgproc-dev libopencv-highgui-dev
    # OpenEXR 3: the 2.x compatibility corpus (sdk/cpp/compat) builds against it.
    libopenexr-dev
    # fbksd-server: TLS for SMTP; PostgreSQL for its tests (and deployments).
    libssl-dev postgresql git
    # A real browser for the page tests (the live job log, the results
    # viewer), driven over WebDriver.
    chromium chromium-driver
    # fbksd-ci's base image is built from Debian packages (no registry).
    mmdebstrap
    # deploy/compose.yaml (server, PostgreSQL and runners) and its check.
    docker-compose
    # Mitsuba 3's vectorised variants (fbksd-mitsuba) compile with LLVM.
    libllvm19)

missing=()
for p in "${APT_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    sudo_cmd=""
    [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
    $sudo_cmd apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq "${missing[@]}"
fi

# fbksd-ci builds and runs techniques in Docker containers (its tests too).
if ! docker info >/dev/null 2>&1; then
    echo "setup: Docker does not answer: install and start the Docker engine (docker.io), then run this again" >&2
    exit 1
fi

if ! command -v cargo >/dev/null; then
    echo "setup: cargo (Rust) is required: install it with rustup, then run this again" >&2
    exit 1
fi
# Independent implementations the metric tests compare against; mypy checks
# the Python SDK's type stubs; Mitsuba 3, the renderer behind
# renderers/mitsuba/fbksd-mitsuba; and the python environment's own
# packages, pinned as in its image (numpy, SciPy, OpenEXR, pyoidn), for the
# baselines' tests.
PIP_PACKAGES=(scikit-image flip-evaluator mypy -r "$(dirname "$0")/images/renderer/requirements.txt"
    -r "$(dirname "$0")/images/python/requirements.txt")
# Mitsuba as pinned for the renderer image: references made here and runs in
# the image must come from the same version (it is in their key).
mitsuba_pin=$(sed -n 's/^mitsuba==//p' "$(dirname "$0")/images/renderer/requirements.txt")
if ! python3 -c "import numpy, scipy, OpenEXR, pyoidn, skimage, flip_evaluator, mypy, mitsuba, sys
sys.exit(mitsuba.__version__ != sys.argv[1])" "$mitsuba_pin" >/dev/null 2>&1; then
    if ! python3 -m pip --version >/dev/null 2>&1; then
        sudo_cmd=""
        [ "$(id -u)" -ne 0 ] && sudo_cmd="sudo"
        $sudo_cmd apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $sudo_cmd apt-get install -y -qq python3-pip
    fi
    # Debian's own Python refuses system-wide pip installs (PEP 668); these
    # are test tools only, so allow it there.
    python3 -m pip install --quiet --disable-pip-version-check "${PIP_PACKAGES[@]}" \
        || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages "${PIP_PACKAGES[@]}"
fi

# The Kubernetes manifests (deploy/k8s) are validated offline, against the
# API schemas this package bundles.
if ! python3 -c "import kubernetes_validate" >/dev/null 2>&1; then
    python3 -m pip install --quiet --disable-pip-version-check kubernetes-validate \
        || python3 -m pip install --quiet --disable-pip-version-check --break-system-packages kubernetes-validate
fi

# The test command checks formatting and lints first.
for tool in fmt clippy; do
    if ! cargo "$tool" --version >/dev/null 2>&1; then
        echo "setup: cargo $tool is missing: rustup component add $( [ $tool = fmt ] && echo rustfmt || echo clippy )" >&2
        exit 1
    fi
done

if ! cargo nextest --version >/dev/null 2>&1; then
    cargo install cargo-nextest --locked
fi

# The procedurally authored parts of the production scene pool (deterministic, a second or two).
python3 "$(dirname "$0")/../scenes/production/generate.py"

# A PostgreSQL server for the fbksd-server tests: 127.0.0.1:54329, trust
# authentication, data in /var/tmp/fbksd-test-postgres (each test creates
# its own database). PostgreSQL refuses to run as root: root runs it as the
# postgres user.
PG_PORT=54329
PG_DIR=${FBKSD_TEST_PG_DIR:-/var/tmp/fbksd-test-postgres}
if ! pg_isready -q -h 127.0.0.1 -p "$PG_PORT"; then
    pg_bin=$(ls -d /usr/lib/postgresql/*/bin | sort -V | tail -1)
    as_pg() { if [ "$(id -u)" -eq 0 ]; then runuser -u postgres -- "$@"; else "$@"; fi; }
    if [ ! -f "$PG_DIR/PG_VERSION" ]; then
        mkdir -p "$PG_DIR"
        [ "$(id -u)" -eq 0 ] && chown postgres: "$PG_DIR"
        as_pg "$pg_bin/initdb" -D "$PG_DIR" -U postgres --auth=trust >/dev/null
    fi
    as_pg "$pg_bin/pg_ctl" -D "$PG_DIR" -l "$PG_DIR/server.log" -w \
        -o "-p $PG_PORT -k $PG_DIR -c listen_addresses=127.0.0.1" start >/dev/null
fi
