#!/usr/bin/env bash
# Installs the FBKSD C/C++ SDK into PREFIX: the library (lib/libfbksd.so,
# lib/libfbksd.a), the headers (include/fbksd/...) and the CMake package
# (lib/cmake/fbksd), so a technique builds with find_package(fbksd).
#
#   bash deploy/install-sdk.sh PREFIX            # builds the release library first
#   bash deploy/install-sdk.sh PREFIX LIB_DIR    # installs an already built one
set -euo pipefail
cd "$(dirname "$0")/.."
prefix=${1:?usage: install-sdk.sh PREFIX [LIB_DIR]}
lib_dir=${2:-}
if [ -z "$lib_dir" ]; then
    cargo build --release --locked -p fbksd-capi
    lib_dir=target/release
fi
mkdir -p "$prefix/lib/cmake/fbksd" "$prefix/include/fbksd"
cp "$lib_dir/libfbksd.so" "$lib_dir/libfbksd.a" "$prefix/lib/"
cp sdk/capi/include/fbksd/fbksd.h "$prefix/include/fbksd/"
cp -r sdk/cpp/include/fbksd/. "$prefix/include/fbksd/"
cp sdk/cpp/cmake/fbksdConfig.cmake sdk/cpp/cmake/fbksdConfigVersion.cmake "$prefix/lib/cmake/fbksd/"
echo "FBKSD SDK installed in $prefix (CMake: -DCMAKE_PREFIX_PATH=$prefix)"
