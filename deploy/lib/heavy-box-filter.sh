# The C++ box filter made heavier, for the equal-time checks of the service
# (bench-runner-classes.sh, bench-service-ties.sh; sourced from the
# repository's root).

# heavy_box_filter DIR ROUNDS: a copy of sdk/techniques/box-filter-cpp in DIR
# that sums every sample ROUNDS times, each time weighted 1/ROUNDS: the same
# image for ROUNDS times the arithmetic.
heavy_box_filter() {
    cp -r sdk/techniques/box-filter-cpp "$1"
    sed -i -e "s|pixel\[0\] += sample\[0\];|for (int r = 0; r < $2; ++r) { pixel[0] += sample[0] * (1.0 / $2); pixel[1] += sample[1] * (1.0 / $2); pixel[2] += sample[2] * (1.0 / $2); }|" \
        -e '/pixel\[1\] += sample\[1\];/d' -e '/pixel\[2\] += sample\[2\];/d' "$1/main.cpp"
    grep -q "r < $2" "$1/main.cpp" || { echo "heavy_box_filter: could not make $1 (has box-filter-cpp/main.cpp changed?)" >&2; exit 1; }
}
