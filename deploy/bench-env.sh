# Sourced by the benchmark scripts (deploy/bench-*.sh): the release build,
# the C/C++ SDK and the Python package as pip would install them, under a
# work directory, and builds of C++ techniques as the service builds them.
#
#   source deploy/bench-env.sh; bench_env WORK; build_technique NAME   # prints its build directory

# Builds the release binaries, installs the SDK into WORK/sdk and the Python
# package (sources and the release native module) into WORK/python, which
# PYTHONPATH then names; WORK/results starts empty.
bench_env() {
    local work=$1
    rm -rf "$work/results" && mkdir -p "$work/python/fbksd"
    cargo build --release --locked --workspace --bins --lib >&2
    bash deploy/install-sdk.sh "$work/sdk" target/release >&2
    cp sdk/python/python/fbksd/*.py "$work/python/fbksd/"
    cp target/release/lib_native.so "$work/python/fbksd/_native.so"
    export PYTHONPATH=$work/python
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
