// FBKSD 2.x's definitions.h: the image window, tile and tile package types,
// with the points they are made of. The renderer's RandomParameter and
// Feature enums are not here but in <fbksd/renderer/samples.h>, as in 2.x,
// so a technique may declare its own DEPTH or COLOR_R.
#pragma once

#include <fbksd/core/Point.h>
#include <fbksd/core/sdk.h>

namespace fbksd {

//! A window of the image: pixels [begin, end).
struct CropWindow {
    CropWindow() = default;
    CropWindow(Point2l begin, Point2l end) : begin(begin), end(end) {}

    int64_t width() const { return end.x - begin.x; }
    int64_t height() const { return end.y - begin.y; }

    Point2l begin; //!< Upper left corner.
    Point2l end;   //!< One past the bottom right corner.
};

//! A window with its place in a request and its number of samples.
struct Tile {
    Tile() = default;
    Tile(const CropWindow& window, int64_t index, int64_t numSamples)
        : window(window), index(index), numSamples(numSamples) {}

    CropWindow window;
    int64_t index = 0;
    int64_t numSamples = 0;
};

//! A tile as handed over, with whether it is valid, whether more follow and
//! whether the technique writes its INPUT parameters.
struct TilePkg {
    TilePkg() = default;
    TilePkg(const Tile& tile, bool hasNext, bool isInputRequest = false)
        : tile(tile), isValid(true), hasNext(hasNext), isInputRequest(isInputRequest) {}

    Tile tile;
    bool isValid = false;
    bool hasNext = false;
    bool isInputRequest = false;
};

} // namespace fbksd
