# Image staging shared by build-images.sh and build-service-images.sh, and
# the Python SDK staging that serve.sh and the bench scripts use too
# (sourced, from the repository's root, after the caller defines say()).

# stage_scenes DIR: the scene files as the images hold them, without
# references (runners make or download those), generators or notes.
stage_scenes() {
    mkdir -p "$1"
    (cd scenes && find . -type f ! -name 'reference.*' ! -name 'reference-*' ! -name '*.py' ! -name '*.md' -print0 \
        | xargs -0 cp --parents -t "$1")
}

# stage_wheels DIR REQUIREMENTS: the wheels REQUIREMENTS pins (CPython 3.11,
# manylinux), downloaded on the host into ~/.cache/fbksd/wheels, copied into
# DIR with the file itself, for an image to install with no registry. Only
# what the file names, so a stale cached wheel never changes the image.
stage_wheels() {
    local dir=$1 requirements=$2 wheels=${XDG_CACHE_HOME:-$HOME/.cache}/fbksd/wheels name version file
    mkdir -p "$dir" "$wheels"
    cp "$requirements" "$dir/requirements.txt"
    python3 -m pip download --quiet --disable-pip-version-check --only-binary=:all: \
        --dest "$wheels" -r "$requirements" >&2
    grep -E '^[A-Za-z]' "$requirements" | while IFS='=' read -r name _ version; do
        file=$(ls "$wheels" | grep -i "^$(echo "$name" | tr '-' '_')-$version-" | head -1 || true)
        [ -n "$file" ] || { say "no wheel for $name $version in $wheels"; exit 1; }
        cp "$wheels/$file" "$dir/"
    done
}

# stage_python_sdk DIR BIN_DIR: the FBKSD Python package as DIR/fbksd (its
# sources and the native module BIN_DIR/lib_native.so), importable with
# PYTHONPATH=DIR.
stage_python_sdk() {
    mkdir -p "$1/fbksd"
    cp sdk/python/python/fbksd/*.py sdk/python/python/fbksd/*.pyi sdk/python/python/fbksd/py.typed "$1/fbksd/"
    cp "$2/lib_native.so" "$1/fbksd/_native.so"
}

# stage_mitsuba DIR BIN_DIR: what fbksd-mitsuba needs beside Debian's
# python3 and libllvm19: its program (DIR/bin), the Python SDK (DIR/python)
# and the wheels of deploy/images/renderer/requirements.txt (DIR/wheels).
stage_mitsuba() {
    mkdir -p "$1/bin"
    cp renderers/mitsuba/fbksd-mitsuba "$1/bin/"
    stage_python_sdk "$1/python" "$2"
    stage_wheels "$1/wheels" deploy/images/renderer/requirements.txt
}

# build_image NAME CONTEXT BASE: the image of CONTEXT's Dockerfile FROM
# BASE, tagged fbksd-NAME:<hash of its content: files, their modes, the
# base's id>, built only when no image has that tag; prints the tag.
build_image() {
    local name=$1 ctx=$2 base=$3 hash tag started
    hash=$( (docker image inspect --format '{{.Id}}' "$base"; cd "$ctx" && find . -type f -print0 | sort -z \
        | xargs -0 sha256sum && find . -type f -printf '%m %p\n' | sort) | sha256sum | cut -c1-16)
    tag=fbksd-$name:$hash
    if ! docker image inspect "$tag" >/dev/null 2>&1; then
        say "building $tag"
        started=$SECONDS
        if ! docker build --quiet --network host --build-arg "BASE=$base" -t "$tag" "$ctx" >"$ctx.log" 2>&1; then
            cat "$ctx.log" >&2
            say "building $tag failed"
            return 1
        fi
        say "built $tag in $((SECONDS - started)) s ($(docker image inspect --format '{{.Size}}' "$tag" \
            | awk '{printf "%.0f MB", $1 / 1e6}'))"
    fi
    echo "$tag"
}

# build_images BASE NAME...: for each NAME, its Dockerfile
# (deploy/images/NAME) and what stage_NAME puts beside it, in $stage/NAME,
# built by build_image; the tags go into the caller's array `tags`.
build_images() {
    local base=$1 name
    shift
    for name in "$@"; do
        mkdir -p "$stage/$name"
        cp "deploy/images/$name/Dockerfile" "$stage/$name/"
        "stage_$name" "$stage/$name"
        tags[$name]=$(build_image "$name" "$stage/$name" "$base")
    done
}
