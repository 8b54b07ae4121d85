#!/usr/bin/env bash
# Builds the images fbksd-ci runs jobs in, with no registry:
#   base      Debian 12 (minbase) from this machine's Debian apt sources:
#             mmdebstrap, then docker import (only when it is not there yet)
#   cpp       base + gcc, CMake, the FBKSD C/C++ SDK and research libraries
#             (OpenEXR, Eigen, OpenCV, FFTW, Boost, TBB; OpenMP with gcc)
#   python    base + Python 3, the FBKSD Python SDK, numpy, scipy, OpenEXR
#             and pyoidn (wheels pinned in deploy/images/python/requirements.txt,
#             downloaded here on the host and cached in ~/.cache/fbksd/wheels)
#   renderer  base + the built-in renderers (procedural, Embree, and Mitsuba 3
#             behind fbksd-mitsuba, its wheels pinned in
#             deploy/images/renderer/requirements.txt) and the scene files
#             (no references)
# Each tag is a hash of the image's content (its Dockerfile, the files it
# copies and its base; deploy/lib/images.sh), so an unchanged image is never rebuilt. The
# manifest (JSON) names the four tags; fbksd-ci reads it (--images).
#
#   bash deploy/build-images.sh [--bin-dir DIR] [--manifest FILE]
#
# Without --bin-dir the release binaries are built first (target/release).
set -euo pipefail
# Paths given are the caller's; the script works from the repository's root.
caller=$(pwd)
absolute() { case "$1" in /*) echo "$1" ;; *) echo "$caller/$1" ;; esac; }
cd "$(dirname "$0")/.."
bin_dir=""
manifest=$(pwd)/fbksd-data/images.json
while [ $# -gt 0 ]; do
    case "$1" in
        --bin-dir) bin_dir=$(absolute "$2"); shift 2 ;;
        --manifest) manifest=$(absolute "$2"); shift 2 ;;
        *) echo "usage: build-images.sh [--bin-dir DIR] [--manifest FILE]" >&2; exit 2 ;;
    esac
done
say() { echo "build-images: $*" >&2; }
. deploy/lib/images.sh
if [ -z "$bin_dir" ]; then
    cargo build --release --locked -p fbksd-capi -p fbksd-python -p fbksd-procedural -p fbksd-embree
    bin_dir=$(pwd)/target/release
fi
for f in libfbksd.so libfbksd.a lib_native.so fbksd-procedural fbksd-embree; do
    [ -f "$bin_dir/$f" ] || { say "$bin_dir/$f is missing: build the workspace first (cargo build)"; exit 1; }
done
docker info >/dev/null 2>&1 || { say "Docker does not answer: start it (and run this as a user who may use it)"; exit 1; }

# --- base: Debian's own apt sources of this machine (not third-party ones) --------------
sources=()
for f in /etc/apt/sources.list /etc/apt/sources.list.d/*.list /etc/apt/sources.list.d/*.sources; do
    [ -s "$f" ] && grep -qE '^[^#]*/debian(-security)?/?([[:space:]]|$)' "$f" && sources+=("$f")
done
[ ${#sources[@]} -gt 0 ] || { say "no Debian apt source found in /etc/apt"; exit 1; }
base_hash=$(cat "${sources[@]}" | sha256sum | cut -c1-16)
base=fbksd-base:bookworm-$base_hash
if ! docker image inspect "$base" >/dev/null 2>&1; then
    command -v mmdebstrap >/dev/null || { say "mmdebstrap is missing: apt-get install mmdebstrap (deploy/setup.sh does)"; exit 1; }
    say "building $base with mmdebstrap from ${sources[*]}"
    mmdebstrap --quiet --variant=minbase --mode=root bookworm - "${sources[@]}" | docker import - "$base" >/dev/null
fi

# --- the images on top of it ---------------------------------------------------------------
stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT

stage_cpp() {
    bash deploy/install-sdk.sh "$1/sdk" "$bin_dir" >/dev/null
}
stage_python() {
    stage_wheels "$1/wheels" deploy/images/python/requirements.txt
    stage_python_sdk "$1" "$bin_dir"
}
stage_renderer() {
    mkdir -p "$1/bin" "$1/scenes"
    cp "$bin_dir/fbksd-procedural" "$bin_dir/fbksd-embree" "$1/bin/"
    stage_mitsuba "$1/mitsuba" "$bin_dir"
    stage_scenes "$1/scenes"
}

declare -A tags
build_images "$base" cpp python renderer

mkdir -p "$(dirname "$manifest")"
cat > "$manifest.tmp" <<JSON
{"base": "$base", "cpp": "${tags[cpp]}", "python": "${tags[python]}", "renderer": "${tags[renderer]}"}
JSON
mv "$manifest.tmp" "$manifest"
say "images ready: $base ${tags[cpp]} ${tags[python]} ${tags[renderer]} (manifest: $manifest)"
