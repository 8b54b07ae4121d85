/* The FBKSD C API (techniques, renderers, metrics). Generated from sdk/capi/src by cbindgen: do not edit. */

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
 * Which input image.
 */
typedef enum FbksdIqaImage {
  /**
   * The reference image.
   */
  FBKSD_IQA_IMAGE_REFERENCE = 0,
  /**
   * The image under test.
   */
  FBKSD_IQA_IMAGE_TEST = 1,
} FbksdIqaImage;

/**
 * A connection to the benchmark manager (opaque).
 */
typedef struct FbksdClient FbksdClient;

/**
 * A metric program's state: its description, options and input images (opaque).
 */
typedef struct FbksdIqa FbksdIqa;

/**
 * A sample layout: under construction (techniques) or as set by the
 * technique (renderers) (opaque).
 */
typedef struct FbksdLayout FbksdLayout;

/**
 * A pipe: one slot of the shared ring, owned by the renderer until closed (opaque).
 */
typedef struct FbksdPipe FbksdPipe;

/**
 * Scene information: keys with integer, number, boolean or string values (opaque).
 */
typedef struct FbksdSceneInfo FbksdSceneInfo;

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

/**
 * One element of a layout, as [`fbksd_layout_element`] reports it.
 */
typedef struct FbksdElement {
  /**
   * The name (e.g. "COLOR_R"), valid as long as the layout.
   */
  const char *name;
  /**
   * Intersection number of a numbered feature (0 or 1), else 0.
   */
  uint32_t number;
  /**
   * Whether the technique writes it (INPUT random parameters).
   */
  bool input;
} FbksdElement;

/**
 * Returns the preferred tile side in pixels.
 */
typedef uint32_t (*FbksdTileSizeCallback)(void *user);

/**
 * Fills `info` (at least "width" and "height").
 */
typedef enum FbksdStatus (*FbksdSceneInfoCallback)(void *user, struct FbksdSceneInfo *info);

/**
 * Accepts (OK) or rejects the technique's layout (with [`crate::fbksd_set_last_error`]).
 */
typedef enum FbksdStatus (*FbksdSetParametersCallback)(void *user, const struct FbksdLayout *layout);

/**
 * One request for samples, as the evaluate callback sees it.
 */
typedef struct FbksdRequest {
  /**
   * Samples per pixel (may be 0).
   */
  uint64_t spp;
  /**
   * Samples not tied to pixels, fewer than one per pixel (may be 0).
   */
  uint64_t remaining;
  /**
   * The most samples one pipe may hold.
   */
  uint64_t pipe_size;
  /**
   * Whether the technique writes INPUT random parameters.
   */
  bool input;
  /**
   * Index of the request within the technique's session (for seeding).
   */
  uint64_t index;
  /**
   * Image width.
   */
  uint32_t width;
  /**
   * Image height.
   */
  uint32_t height;
} FbksdRequest;

/**
 * Starts producing a request's samples; may return before they are all produced.
 */
typedef enum FbksdStatus (*FbksdEvaluateCallback)(void *user, const struct FbksdRequest *request);

/**
 * A notification.
 */
typedef void (*FbksdEventCallback)(void *user);

/**
 * A renderer's callbacks; `user` is passed to each. Only `scene_info` and
 * `evaluate_samples` are required.
 */
typedef struct FbksdServerCallbacks {
  /**
   * Passed through to every callback.
   */
  void *user;
  /**
   * Preferred tile side (16 if null); called once at start.
   */
  FbksdTileSizeCallback tile_size;
  /**
   * The scene's info; called once at start.
   */
  FbksdSceneInfoCallback scene_info;
  /**
   * Called with each technique's layout (any layout accepted if null).
   */
  FbksdSetParametersCallback set_parameters;
  /**
   * Called for each request, on a thread of the library's.
   */
  FbksdEvaluateCallback evaluate_samples;
  /**
   * Called when a request's last pipe is closed (may be null).
   */
  FbksdEventCallback last_tile_consumed;
  /**
   * Called when the manager has no more work, before `fbksd_server_run` returns (may be null).
   */
  FbksdEventCallback finish;
} FbksdServerCallbacks;

/**
 * Where each layout element sits in a sample, for writing samples fast.
 */
typedef struct FbksdSampleMap {
  /**
   * Floats per sample.
   */
  uint32_t sample_size;
  /**
   * Offset of each random parameter (IMAGE_X … LIGHT_Y), −1 if absent.
   */
  int32_t parameter[7];
  /**
   * Whether each random parameter is INPUT (written by the technique).
   */
  bool parameter_is_input[7];
  /**
   * Offset of feature `f` (COLOR_R … DIFFUSE_COLOR_B, numbered 0–27)
   * with intersection number `n` at index `2f + n`, −1 if absent.
   */
  int32_t feature[56];
} FbksdSampleMap;

#ifdef __cplusplus
extern "C" {
#endif // __cplusplus

/**
 * The message of the last failed call on this thread ("" if none).
 */
const char *fbksd_last_error(void);

/**
 * Sets this thread's last-error message, for callbacks (a renderer's or
 * a technique's) that report a failure with a status: the library passes
 * the message on with it.
 */
void fbksd_set_last_error(const char *message);

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
 * The scene's information (width, height, max_spp, …), owned by the
 * client and valid until it is freed; null for a null client.
 */
const struct FbksdSceneInfo *fbksd_client_scene_info(const struct FbksdClient *client);

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

/**
 * Parses the metric's command line and loads its two images. `--help` and
 * `--info` print and exit the process with status 0, as in the original.
 * A wrong command line, a missing image or images of different sizes are
 * errors whose message says which.
 */
enum FbksdStatus fbksd_iqa_new(int argc,
                               const char *const *argv,
                               const char *acronym,
                               const char *full_name,
                               const char *reference,
                               bool lower_is_better,
                               bool has_error_map,
                               struct FbksdIqa **out);

/**
 * Frees the metric's state (null is ignored).
 */
void fbksd_iqa_free(struct FbksdIqa *iqa);

/**
 * An input image: `*width × *height` RGB pixels, scanline order, owned by
 * `iqa` (null on error).
 */
const float *fbksd_iqa_image(const struct FbksdIqa *iqa,
                             enum FbksdIqaImage which,
                             uint32_t *width,
                             uint32_t *height);

/**
 * Reports the metric's value, and its error map when `map` is not null:
 * `width × height` RGB values in [0, 1) (clamped; a pixel's error is the
 * mean of its three), written as a PNG if `--map-file` was given and the
 * metric declared an error map. A non-finite value is refused.
 */
enum FbksdStatus fbksd_iqa_report(const struct FbksdIqa *iqa,
                                  float value,
                                  const float *map,
                                  uint32_t width,
                                  uint32_t height);

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
 * Number of elements (0 for null).
 */
size_t fbksd_layout_len(const struct FbksdLayout *layout);

/**
 * Element `index` (0-based, in memory order) into `*out`.
 */
enum FbksdStatus fbksd_layout_element(const struct FbksdLayout *layout,
                                      size_t index,
                                      struct FbksdElement *out);

/**
 * The Beckmann roughness threshold of the DIFFUSE_COLOR features (0.1 unless set; 0 for null).
 */
float fbksd_layout_roughness_threshold(const struct FbksdLayout *layout);

/**
 * Serves the manager that started this process (`FBKSD_RENDEZVOUS`)
 * until it says finish, calling `callbacks`. Blocks; returns OK when the
 * manager is done, an error status and message otherwise.
 */
enum FbksdStatus fbksd_server_run(const struct FbksdServerCallbacks *callbacks);

/**
 * Opens a pipe for `num_samples` samples in the window
 * `[begin_x, end_x) × [begin_y, end_y)` of the request in progress
 * (see the module notes for how the window is read), blocking until a slot
 * is free. Any thread may open pipes, concurrently; each must be closed
 * with [`fbksd_pipe_close`].
 */
enum FbksdStatus fbksd_pipe_open(int64_t begin_x,
                                 int64_t begin_y,
                                 int64_t end_x,
                                 int64_t end_y,
                                 int64_t num_samples,
                                 struct FbksdPipe **out);

/**
 * The pipe's tile: its window, spp, sample size, count and the samples to write.
 */
enum FbksdStatus fbksd_pipe_tile(const struct FbksdPipe *pipe, struct FbksdTile *out);

/**
 * Where each element sits in the pipe's samples.
 */
enum FbksdStatus fbksd_pipe_sample_map(const struct FbksdPipe *pipe, struct FbksdSampleMap *out);

/**
 * Hands the pipe's samples to the technique and frees the pipe (null is ignored).
 */
enum FbksdStatus fbksd_pipe_close(struct FbksdPipe *pipe);

/**
 * A new, empty scene info. Free it with [`fbksd_scene_info_free`].
 */
struct FbksdSceneInfo *fbksd_scene_info_new(void);

/**
 * A copy of `info` (null for null). Free it with [`fbksd_scene_info_free`].
 */
struct FbksdSceneInfo *fbksd_scene_info_clone(const struct FbksdSceneInfo *info);

/**
 * Replaces everything in `dst` by a copy of `src`.
 */
enum FbksdStatus fbksd_scene_info_copy(struct FbksdSceneInfo *dst,
                                       const struct FbksdSceneInfo *src);

/**
 * Adds every item of `src` to `dst`, replacing those with the same key
 * (`SceneInfo::merged` of the C++ API).
 */
enum FbksdStatus fbksd_scene_info_merge(struct FbksdSceneInfo *dst,
                                        const struct FbksdSceneInfo *src);

/**
 * Frees a scene info made by [`fbksd_scene_info_new`] or
 * [`fbksd_scene_info_clone`] (null is ignored; never a client's).
 */
void fbksd_scene_info_free(struct FbksdSceneInfo *info);

/**
 * Integer `key` (e.g. "width", "height", "max_spp").
 */
enum FbksdStatus fbksd_scene_info_int(const struct FbksdSceneInfo *info,
                                      const char *key,
                                      int64_t *out);

/**
 * Number `key`.
 */
enum FbksdStatus fbksd_scene_info_float(const struct FbksdSceneInfo *info,
                                        const char *key,
                                        double *out);

/**
 * Boolean `key`.
 */
enum FbksdStatus fbksd_scene_info_bool(const struct FbksdSceneInfo *info,
                                       const char *key,
                                       bool *out);

/**
 * String `key`, copied NUL-terminated into `buf` (`len` bytes).
 * `*needed` (if not null) receives the size the string needs, NUL
 * included; a too-small buffer is [`FbksdStatus::InvalidArgument`].
 */
enum FbksdStatus fbksd_scene_info_string(const struct FbksdSceneInfo *info,
                                         const char *key,
                                         char *buf,
                                         size_t len,
                                         size_t *needed);

/**
 * Whether `key` exists (false for a null info or key).
 */
bool fbksd_scene_info_has(const struct FbksdSceneInfo *info, const char *key);

/**
 * Sets integer `key`.
 */
enum FbksdStatus fbksd_scene_info_set_int(struct FbksdSceneInfo *info,
                                          const char *key,
                                          int64_t value);

/**
 * Sets number `key`.
 */
enum FbksdStatus fbksd_scene_info_set_float(struct FbksdSceneInfo *info,
                                            const char *key,
                                            double value);

/**
 * Sets boolean `key`.
 */
enum FbksdStatus fbksd_scene_info_set_bool(struct FbksdSceneInfo *info,
                                           const char *key,
                                           bool value);

/**
 * Sets string `key` to the NUL-terminated UTF-8 `value`.
 */
enum FbksdStatus fbksd_scene_info_set_string(struct FbksdSceneInfo *info,
                                             const char *key,
                                             const char *value);

#ifdef __cplusplus
}  // extern "C"
#endif  // __cplusplus

#endif  /* FBKSD_H */
