# Sourced by the benchmark scripts (deploy/bench-*.sh): the release build,
# the C/C++ SDK and the Python package as pip would install them, under a
# work directory, and builds of C++ techniques as the service builds them.
#
#   source deploy/bench-env.sh; bench_env WORK; build_technique NAME   # prints its build directory

# Builds the release binaries, installs the SDK into WORK/sdk and the Python
# package (sources and the release native module) into WORK/python, which
# PYTHONPATH then names; puts the renderers on PATH (make_references);
# WORK/results starts empty.
bench_env() {
    local work=$1
    rm -rf "$work/results" && mkdir -p "$work"
    cargo build --release --locked --workspace --bins --lib >&2
    bash deploy/install-sdk.sh "$work/sdk" target/release >&2
    say() { echo "bench: $*" >&2; }
    . deploy/lib/images.sh
    . deploy/lib/renderers.sh
    renderers_on_path "$(pwd)/target/release" "$work/python"
    bench_work=$work
}

# Builds sdk/techniques/NAME with CMake (Release) against the installed SDK;
# prints the build directory.
build_technique() {
    local name=$1
    cmake -S "sdk/techniques/$name" -B "$bench_work/build/$name" -DCMAKE_BUILD_TYPE=Release \
        -DCMAKE_PREFIX_PATH="$bench_work/sdk" >&2
    cmake --build "$bench_work/build/$name" -j2 >&2
    echo "$bench_work/build/$name"
}
