#!/usr/bin/env bash
# Builds the images of the service itself, with no registry, on top of the
# job images of deploy/build-images.sh (run first, with the same binaries):
#   server    fbksd-server, git, the PostgreSQL client (backups), curl
#   runner    the renderer image (the renderers, the scene files without
#             references) + fbksd-ci and git
#             and the job images' manifest
#   postgres  PostgreSQL from Debian's packages
# all FROM the same Debian base. Each tag is a hash of the image's content
# (its Dockerfile, the files it copies and its base), so an unchanged image
# is never rebuilt. The tags are printed, and written as variables for
# `docker-compose --env-file` (FBKSD_IMAGE_SERVER, FBKSD_IMAGE_RUNNER,
# FBKSD_IMAGE_POSTGRES; see deploy/compose.yaml).
#
#   bash deploy/build-service-images.sh [--bin-dir DIR] [--manifest FILE] [--env-file FILE]
#
# --bin-dir and --manifest are build-images.sh's (the job images' manifest,
# baked into the runner image). Without --bin-dir the release binaries are
# built first (target/release).
set -euo pipefail
caller=$(pwd)
absolute() { case "$1" in /*) echo "$1" ;; *) echo "$caller/$1" ;; esac; }
cd "$(dirname "$0")/.."
bin_dir=""
manifest=$(pwd)/fbksd-data/images.json
env_file=""
while [ $# -gt 0 ]; do
    case "$1" in
        --bin-dir) bin_dir=$(absolute "$2"); shift 2 ;;
        --manifest) manifest=$(absolute "$2"); shift 2 ;;
        --env-file) env_file=$(absolute "$2"); shift 2 ;;
        *) echo "usage: build-service-images.sh [--bin-dir DIR] [--manifest FILE] [--env-file FILE]" >&2; exit 2 ;;
    esac
done
say() { echo "build-service-images: $*" >&2; }
. deploy/lib/images.sh
if [ -z "$bin_dir" ]; then
    cargo build --release --locked -p fbksd-server -p fbksd-ci -p fbksd-capi -p fbksd-python \
        -p fbksd-procedural -p fbksd-embree
    bin_dir=$(pwd)/target/release
fi
for f in fbksd-server fbksd-ci fbksd-procedural fbksd-embree; do
    [ -f "$bin_dir/$f" ] || { say "$bin_dir/$f is missing: build the workspace first (cargo build)"; exit 1; }
done

# The job images and the base, from the same binaries.
bash deploy/build-images.sh --bin-dir "$bin_dir" --manifest "$manifest"
base=$(sed -n 's/.*"base": *"\([^"]*\)".*/\1/p' "$manifest")
renderer=$(sed -n 's/.*"renderer": *"\([^"]*\)".*/\1/p' "$manifest")
[ -n "$base" ] && [ -n "$renderer" ] || { say "no base or renderer image in $manifest"; exit 1; }

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT

stage_server() {
    mkdir -p "$1/bin"
    cp "$bin_dir/fbksd-server" "$1/bin/"
    cp deploy/images/server/entrypoint.sh deploy/images/secrets.sh "$1/"
}
stage_runner() {
    mkdir -p "$1/bin"
    cp "$bin_dir/fbksd-ci" "$1/bin/"
    cp deploy/images/runner/entrypoint.sh deploy/images/secrets.sh "$1/"
    cp "$manifest" "$1/images.json"
}
stage_postgres() {
    cp deploy/images/postgres/entrypoint.sh "$1/"
}

declare -A tags
build_images "$base" server postgres
# The runner is the renderer image and fbksd-ci: the renderers and scene
# files it makes references with are those its jobs run.
build_images "$renderer" runner

variables="FBKSD_IMAGE_SERVER=${tags[server]}
FBKSD_IMAGE_RUNNER=${tags[runner]}
FBKSD_IMAGE_POSTGRES=${tags[postgres]}"
if [ -n "$env_file" ]; then
    mkdir -p "$(dirname "$env_file")"
    echo "$variables" >"$env_file.tmp"
    mv "$env_file.tmp" "$env_file"
fi
echo "$variables"
say "service images ready: ${tags[server]} ${tags[runner]} ${tags[postgres]}${env_file:+ (written to $env_file)}"
