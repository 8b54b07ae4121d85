// What this SDK's C++ headers add to the FBKSD 2.x surface, kept out of the
// names a technique sees with `using namespace fbksd;` (they live in
// fbksd::sdk): the exception every failed call throws, and the standard
// headers 2.x brought in through its own includes.
//
// 2.x's core headers included msgpack-c, which pulls in most of the
// standard library; techniques written for 2.x use std::numeric_limits,
// std::sort, std::sqrt, std::memcpy, std::cout, … without including their
// headers, so every FBKSD header includes them here.
#pragma once

#include <fbksd/fbksd.h>

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <exception>
#include <functional>
#include <iostream>
#include <iterator>
#include <limits>
#include <list>
#include <map>
#include <memory>
#include <numeric>
#include <ostream>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>
#include <unordered_map>
#include <utility>
#include <vector>

namespace fbksd {
namespace sdk {

//! A failed call: the C API's status and its message. The original aborted instead.
class Error : public std::runtime_error {
public:
    Error(FbksdStatus status, const std::string& message) : std::runtime_error(message), status(status) {}
    FbksdStatus status;
};

//! Throws Error for a failed C API call.
inline void check(FbksdStatus status) {
    if (status != FBKSD_STATUS_OK)
        throw Error(status, fbksd_last_error());
}

} // namespace sdk
} // namespace fbksd
