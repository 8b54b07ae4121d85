// fbksd::TPoint2 and fbksd::TPoint3 (FBKSD 2.x's Point.h): small points with
// public coordinates, indexable, and compared the way 2.x compared them.
#pragma once

#include <fbksd/core/sdk.h>

namespace fbksd {

//! A 2D point.
template<class T> struct TPoint2 {
    TPoint2() = default;
    TPoint2(T x, T y) : x(x), y(y) {}

    //! Coordinate i (0: x, 1: y).
    T& operator[](int i) { return i == 0 ? x : y; }
    T operator[](int i) const { return i == 0 ? x : y; }

    bool operator==(const TPoint2& p) const { return x == p.x && y == p.y; }
    bool operator!=(const TPoint2& p) const { return !(*this == p); }
    //! Whether both coordinates are smaller (2.x's meaning: a point inside a window's end).
    bool operator<(const TPoint2& p) const { return x < p.x && y < p.y; }

    T x = 0;
    T y = 0;
};

//! A 3D point.
template<class T> struct TPoint3 {
    TPoint3() = default;
    TPoint3(T x, T y, T z) : x(x), y(y), z(z) {}

    //! Coordinate i (0: x, 1: y, 2: z).
    T& operator[](int i) { return i == 0 ? x : i == 1 ? y : z; }
    T operator[](int i) const { return i == 0 ? x : i == 1 ? y : z; }

    bool operator==(const TPoint3& p) const { return x == p.x && y == p.y && z == p.z; }
    bool operator!=(const TPoint3& p) const { return !(*this == p); }
    //! Whether every coordinate is smaller.
    bool operator<(const TPoint3& p) const { return x < p.x && y < p.y && z < p.z; }

    T x = 0;
    T y = 0;
    T z = 0;
};

//! Integer pixel positions and image windows.
using Point2l = TPoint2<int64_t>;

} // namespace fbksd
