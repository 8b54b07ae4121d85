/* The FBKSD C API (technique side). Generated from sdk/capi/src/lib.rs by cbindgen: do not edit. */

#ifndef FBKSD_H
#define FBKSD_H

#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>

/**
 * The outcome of a call.
 */
typedef enum FbksdStatus {
  /**
   * Success.
   */
  FBKSD_STATUS_OK = 0,
  /**
   * A null pointer, bad UTF-8, or a value out of range.
   */
  FBKSD_STATUS_INVALID_ARGUMENT = 1,
  /**
   * Not started by a manager (and not in debug mode), or the connection failed.
   */
  FBKSD_STATUS_CONNECTION = 2,
  /**
   * The sample layout is invalid.
   */
  FBKSD_STATUS_LAYOUT = 3,
  /**
   * The manager refused a request (budget, order of calls, …); the run is over.
   */
  FBKSD_STATUS_REFUSED = 4,
  /**
   * A scene-info key is missing or has another type.
   */
  FBKSD_STATUS_SCENE_INFO = 5,
  /**
   * A call out of order (e.g. samples before a layout, or after the result).
   */
  FBKSD_STATUS_USAGE = 6,
  /**
   * Anything else (protocol, shared memory).
   */
  FBKSD_STATUS_FAILED = 7,
  /**
   * A bug: the library panicked (the message says where).
   */
  FBKSD_STATUS_PANIC = 8,
} FbksdStatus;

/**
 * A connection to the benchmark manager (opaque).
 */
typedef struct FbksdClient FbksdClient;

/**
 * A sample layout under construction (opaque).
 */
typedef struct FbksdLayout FbksdLayout;

/**
 * One tile of samples, as callbacks see it. Pixel tiles cover
 * `[begin_x, end_x) × [begin_y, end_y)` with `spp` samples per pixel,
 * stored pixel by pixel (row-major), each pixel's samples together, each
 * sample `sample_size` floats: sample `s` of pixel `(x, y)` starts at
 * `((((y − begin_y) · (end_x − begin_x)) + (x − begin_x)) · spp + s) · sample_size`.
 * Count-request tiles have no pixels (`spp` 0, empty rectangle).
 */
typedef struct FbksdTile {
  /**
   * First column.
   */
  uint32_t begin_x;
  /**
   * One past the last column.
   */
  uint32_t end_x;
  /**
   * First row.
   */
  uint32_t begin_y;
  /**
   * One past the last row.
   */
  uint32_t end_y;
  /**
   * Samples per pixel (0 for count tiles).
   */
  uint32_t spp;
  /**
   * Floats per sample.
   */
  size_t sample_size;
  /**
   * Number of samples.
   */
  uint64_t count;
  /**
   * The samples (writable only in producer callbacks).
   */
  float *data;
} FbksdTile;

/**
 * A callback receiving a tile; `user` is passed through.
 */
typedef void (*FbksdTileCallback)(void *user, const struct FbksdTile *tile);

#ifdef __cplusplus
extern "C" {
#endif // __cplusplus

/**
 * The message of the last failed call on this thread ("" if none).
 */
const char *fbksd_last_error(void);

/**
 * Connects to the manager that started this process; with the debug
 * arguments in `argv` (`--fbksd-renderer`, `--fbksd-spp`, …) it starts
 * its own manager instead. On success `*out` owns the connection.
 */
enum FbksdStatus fbksd_client_new(int argc, const char *const *argv, struct FbksdClient **out);

/**
 * Closes the connection and frees the handle (null is ignored).
 */
void fbksd_client_free(struct FbksdClient *client);

/**
 * Scene-info integer (e.g. "width", "height", "max_spp").
 */
enum FbksdStatus fbksd_scene_info_int(struct FbksdClient *client, const char *key, int64_t *out);

/**
 * Scene-info number.
 */
enum FbksdStatus fbksd_scene_info_float(struct FbksdClient *client, const char *key, double *out);

/**
 * Scene-info boolean.
 */
enum FbksdStatus fbksd_scene_info_bool(struct FbksdClient *client, const char *key, bool *out);

/**
 * Scene-info string, copied NUL-terminated into `buf` (`len` bytes).
 * `*needed` (if not null) receives the size the string needs, NUL
 * included; a too-small buffer is [`FbksdStatus::InvalidArgument`].
 */
enum FbksdStatus fbksd_scene_info_string(struct FbksdClient *client,
                                         const char *key,
                                         char *buf,
                                         size_t len,
                                         size_t *needed);

/**
 * Whether scene info has `key` (false for a null client or key).
 */
bool fbksd_scene_info_has(struct FbksdClient *client, const char *key);

/**
 * A new, empty layout (roughness threshold 0.1). Free it with [`fbksd_layout_free`].
 */
struct FbksdLayout *fbksd_layout_new(void);

/**
 * Frees a layout (null is ignored).
 */
void fbksd_layout_free(struct FbksdLayout *layout);

/**
 * Appends element `name` (e.g. "COLOR_R", "IMAGE_X"); `input` marks a
 * random parameter the technique gives; `number` picks the intersection
 * of a numbered feature (0 or 1). Checked when the layout is set.
 */
enum FbksdStatus fbksd_layout_add(struct FbksdLayout *layout,
                                  const char *name,
                                  bool input,
                                  uint32_t number);

/**
 * Sets the Beckmann roughness threshold of the DIFFUSE_COLOR features.
 */
enum FbksdStatus fbksd_layout_set_roughness_threshold(struct FbksdLayout *layout, float threshold);

/**
 * Sends the layout to the manager (validated first: the message names the bad element).
 */
enum FbksdStatus fbksd_client_set_layout(struct FbksdClient *client,
                                         const struct FbksdLayout *layout);

/**
 * Floats per sample of the current layout (0 before one is set).
 */
size_t fbksd_client_sample_size(struct FbksdClient *client);

/**
 * The result image the technique fills: `width × height × 3` floats,
 * row-major RGB; `*len` receives the number of floats. Null on failure.
 */
float *fbksd_client_result_buffer(struct FbksdClient *client, size_t *len);

/**
 * Requests `spp` samples for every pixel; `consumer` receives each tile.
 */
enum FbksdStatus fbksd_client_evaluate_samples(struct FbksdClient *client,
                                               uint64_t spp,
                                               FbksdTileCallback consumer,
                                               void *user);

/**
 * Requests `count` samples anywhere on the image (the renderer places
 * them; IMAGE_X/IMAGE_Y say where); `consumer` receives them in chunks.
 */
enum FbksdStatus fbksd_client_evaluate_sample_count(struct FbksdClient *client,
                                                    uint64_t count,
                                                    FbksdTileCallback consumer,
                                                    void *user);

/**
 * Like [`fbksd_client_evaluate_samples`], but `producer` first writes the
 * INPUT parameters of each tile (adaptive sampling).
 */
enum FbksdStatus fbksd_client_evaluate_input_samples(struct FbksdClient *client,
                                                     uint64_t spp,
                                                     FbksdTileCallback producer,
                                                     FbksdTileCallback consumer,
                                                     void *user);

/**
 * Like [`fbksd_client_evaluate_sample_count`], but `producer` first
 * writes the INPUT parameters of each chunk.
 */
enum FbksdStatus fbksd_client_evaluate_input_sample_count(struct FbksdClient *client,
                                                          uint64_t count,
                                                          FbksdTileCallback producer,
                                                          FbksdTileCallback consumer,
                                                          void *user);

/**
 * Sends the result buffer to the manager. The client can do nothing
 * more afterwards but be freed.
 */
enum FbksdStatus fbksd_client_send_result(struct FbksdClient *client);

#ifdef __cplusplus
}  // extern "C"
#endif  // __cplusplus

#endif  /* FBKSD_H */
