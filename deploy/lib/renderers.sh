# The renderers on the host, for the scripts that make references or run
# benchmarks outside the images (sourced, from the repository's root, after
# deploy/lib/images.sh).

# renderers_on_path BIN_DIR STAGE: the built-in renderers of BIN_DIR and
# fbksd-mitsuba on PATH, with the Python SDK it imports staged in STAGE
# (Mitsuba itself is installed by deploy/setup.sh).
renderers_on_path() {
    stage_python_sdk "$2" "$1"
    export PYTHONPATH="$2${PYTHONPATH:+:$PYTHONPATH}" PATH="$1:$(pwd)/renderers/mitsuba:$PATH"
}

# make_references DIR...: each scene directory's reference, made (or kept)
# by the renderer its fbksd-scene.json names.
make_references() {
    local dir renderer
    for dir in "$@"; do
        renderer=$(sed -n 's/.*"renderer": *"\([a-z0-9-]*\)".*/\1/p' "$dir/fbksd-scene.json")
        [ -n "$renderer" ] || { echo "$dir/fbksd-scene.json names no renderer" >&2; return 1; }
        "fbksd-$renderer" reference "$dir" >&2
    done
}
