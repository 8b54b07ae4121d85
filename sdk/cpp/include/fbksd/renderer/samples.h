// fbksd::SamplesPipe and fbksd::SampleBuffer (thesis appendix A.5.7–A.5.8):
// how a renderer hands samples to the technique. Header-only over the C ABI.
//
// A rendering thread opens a SamplesPipe for an image window and a number
// of samples (blocking until a slot of the shared ring is free), positions
// it with seek(x, y), takes a SampleBuffer per sample with getBuffer(),
// writes the sample's values with set(), and inserts it with operator<<.
// The destructor hands the samples to the technique. Any number of threads
// may fill pipes at once, each its own.
#pragma once

#include <fbksd/core/definitions.h>
#include <fbksd/core/sdk.h>

namespace fbksd {

//! Random parameters; with them first in the layout, in this order, they
//! also index a sample (`sample[IMAGE_X]`), as in the original examples.
//! Renderer-side only, as in 2.x: techniques declare their own.
enum RandomParameter { IMAGE_X = 0, IMAGE_Y, LENS_U, LENS_V, TIME, LIGHT_X, LIGHT_Y, NUM_RANDOM_PARAMETERS };

//! Features a renderer computes. Numbered ones (WORLD, NORMAL,
//! TEXTURE_COLOR) also exist for the second intersection (number 1).
enum Feature {
    COLOR_R = 0, COLOR_G, COLOR_B,
    DIRECT_LIGHT_R, DIRECT_LIGHT_G, DIRECT_LIGHT_B,
    DEPTH,
    WORLD_X, WORLD_Y, WORLD_Z,
    NORMAL_X, NORMAL_Y, NORMAL_Z,
    TEXTURE_COLOR_R, TEXTURE_COLOR_G, TEXTURE_COLOR_B,
    WORLD_X_NS, WORLD_Y_NS, WORLD_Z_NS,
    NORMAL_X_NS, NORMAL_Y_NS, NORMAL_Z_NS,
    TEXTURE_COLOR_R_NS, TEXTURE_COLOR_G_NS, TEXTURE_COLOR_B_NS,
    DIFFUSE_COLOR_R, DIFFUSE_COLOR_G, DIFFUSE_COLOR_B,
    NUM_FEATURES
};

//! One sample: writes go straight into the pipe's shared memory.
class SampleBuffer {
public:
    //! A buffer bound to no sample: set() has no effect, get() returns 0.
    SampleBuffer() = default;
    SampleBuffer(float* data, const FbksdSampleMap* map) : m_data(data), m_map(map) {}

    //! Writes an OUTPUT random parameter and returns `v`; for an INPUT one
    //! writes nothing and returns the technique's value.
    float set(RandomParameter i, float v) {
        int at = offset(i);
        if (at < 0)
            return v;
        if (m_map->parameter_is_input[i])
            return m_data[at];
        m_data[at] = v;
        return v;
    }
    //! A random parameter's value in the sample (0 if not in the layout).
    float get(RandomParameter i) const {
        int at = offset(i);
        return at < 0 ? 0.f : m_data[at];
    }
    //! Writes a feature (first intersection) if the layout has it; returns `v`.
    float set(Feature f, float v) { return set(f, 0, v); }
    //! Writes feature `f` of intersection `number` (0 or 1) if the layout has it; returns `v`.
    float set(Feature f, int number, float v) {
        int at = offset(f, number);
        if (at >= 0)
            m_data[at] = v;
        return v;
    }
    //! A feature's value in the sample (0 if not in the layout).
    float get(Feature f, int number = 0) const {
        int at = offset(f, number);
        return at < 0 ? 0.f : m_data[at];
    }

    //! The sample's floats, in layout order (null when unbound).
    float* data() const { return m_data; }

private:
    int offset(RandomParameter i) const {
        return (m_data && i >= 0 && i < NUM_RANDOM_PARAMETERS) ? m_map->parameter[i] : -1;
    }
    int offset(Feature f, int number) const {
        return (m_data && f >= 0 && f < NUM_FEATURES && number >= 0 && number <= 1) ? m_map->feature[2 * f + number]
                                                                                  : -1;
    }

    float* m_data = nullptr;
    const FbksdSampleMap* m_map = nullptr;
};

//! A slot of samples for an image window; see the file comment.
class SamplesPipe {
public:
    //! Acquires a pipe for `numSamples` samples of the window [begin, end):
    //! `area × spp` samples make a pixel tile, anything else pixel-free
    //! samples (the original passed the whole image for those). Blocks until
    //! a slot is free; throws fbksd::sdk::Error when no request is in progress.
    SamplesPipe(const Point2l& begin, const Point2l& end, int64_t numSamples) {
        sdk::check(fbksd_pipe_open(begin.x, begin.y, end.x, end.y, numSamples, &m_pipe));
        sdk::check(fbksd_pipe_tile(m_pipe, &m_tile));
        sdk::check(fbksd_pipe_sample_map(m_pipe, &m_map));
    }
    SamplesPipe(const SamplesPipe&) = delete;
    SamplesPipe& operator=(const SamplesPipe&) = delete;
    //! Releases the pipe: its samples go to the technique.
    ~SamplesPipe() { fbksd_pipe_close(m_pipe); }

    //! Positions the pipe at the first sample of pixel (x, y) (pixel tiles).
    void seek(int x, int y) {
        size_t width = m_tile.end_x - m_tile.begin_x;
        m_position = ((size_t)(y - (int64_t)m_tile.begin_y) * width + (size_t)(x - (int64_t)m_tile.begin_x)) * m_tile.spp;
    }
    //! Positions the pipe at sample `position` (storage order).
    void seek(size_t position) { m_position = position; }
    //! The current position.
    size_t getPosition() const { return m_position; }
    //! The number of samples inserted so far.
    size_t getNumSamples() const { return m_inserted; }
    //! The pipe's capacity in samples.
    size_t getSize() const { return (size_t)m_tile.count; }

    //! A buffer for the sample at the current position; with INPUT random
    //! parameters it already holds the technique's values.
    SampleBuffer getBuffer() {
        if (m_position >= m_tile.count)
            return SampleBuffer();
        return SampleBuffer(m_tile.data + m_position * m_tile.sample_size, &m_map);
    }

    //! Inserts a sample at the current position and advances. A buffer
    //! from getBuffer() is already in place; another one is copied.
    SamplesPipe& operator<<(const SampleBuffer& buffer) {
        if (m_position < m_tile.count) {
            float* at = m_tile.data + m_position * m_tile.sample_size;
            if (buffer.data() && buffer.data() != at)
                std::memcpy(at, buffer.data(), m_tile.sample_size * sizeof(float));
            ++m_position;
            ++m_inserted;
        }
        return *this;
    }

private:
    FbksdPipe* m_pipe = nullptr;
    FbksdTile m_tile{};
    FbksdSampleMap m_map{};
    size_t m_position = 0;
    size_t m_inserted = 0;
};

} // namespace fbksd
