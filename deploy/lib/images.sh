# Shared by build-images.sh and build-service-images.sh (sourced, from the
# repository's root, after they define say()).

# stage_scenes DIR: the scene files as the images hold them, without
# references (runners make or download those), generators or notes.
stage_scenes() {
    mkdir -p "$1"
    (cd scenes && find . -type f ! -name 'reference.*' ! -name 'reference-*' ! -name '*.py' ! -name '*.md' -print0 \
        | xargs -0 cp --parents -t "$1")
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
