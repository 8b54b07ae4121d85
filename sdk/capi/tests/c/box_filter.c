/* Box filter in C against the FBKSD C API: each pixel is the mean of its
 * samples. The conformance test runs it beside the Rust box filter and
 * expects bit-identical images. */
#include <fbksd/fbksd.h>
#include <stdio.h>
#include <stdlib.h>

#define CHECK(call)                                                      \
    do {                                                                 \
        if ((call) != FBKSD_STATUS_OK) {                                 \
            fprintf(stderr, "%s failed: %s\n", #call, fbksd_last_error()); \
            return 1;                                                    \
        }                                                                \
    } while (0)

typedef struct {
    double *sums;
    int64_t width;
} Sums;

static void consume(void *user, const FbksdTile *tile) {
    Sums *sums = (Sums *)user;
    size_t tile_width = tile->end_x - tile->begin_x;
    for (uint32_t y = tile->begin_y; y < tile->end_y; ++y)
        for (uint32_t x = tile->begin_x; x < tile->end_x; ++x)
            for (uint32_t s = 0; s < tile->spp; ++s) {
                size_t index = ((size_t)(y - tile->begin_y) * tile_width + (x - tile->begin_x)) * tile->spp + s;
                const float *sample = tile->data + index * tile->sample_size;
                double *pixel = sums->sums + ((size_t)y * sums->width + x) * 3;
                pixel[0] += sample[0];
                pixel[1] += sample[1];
                pixel[2] += sample[2];
            }
}

int main(int argc, char **argv) {
    FbksdClient *client = NULL;
    CHECK(fbksd_client_new(argc, (const char *const *)argv, &client));
    int64_t width, height, spp;
    const FbksdSceneInfo *info = fbksd_client_scene_info(client);
    CHECK(fbksd_scene_info_int(info, "width", &width));
    CHECK(fbksd_scene_info_int(info, "height", &height));
    CHECK(fbksd_scene_info_int(info, "max_spp", &spp));

    FbksdLayout *layout = fbksd_layout_new();
    CHECK(fbksd_layout_add(layout, "COLOR_R", false, 0));
    CHECK(fbksd_layout_add(layout, "COLOR_G", false, 0));
    CHECK(fbksd_layout_add(layout, "COLOR_B", false, 0));
    CHECK(fbksd_client_set_layout(client, layout));
    fbksd_layout_free(layout);

    Sums sums = {(double *)calloc((size_t)(width * height * 3), sizeof(double)), width};
    CHECK(fbksd_client_evaluate_samples(client, (uint64_t)spp, consume, &sums));

    size_t len = 0;
    float *result = fbksd_client_result_buffer(client, &len);
    double inv = 1.0 / (double)spp;
    for (size_t i = 0; i < len; ++i)
        result[i] = (float)(sums.sums[i] * inv);
    CHECK(fbksd_client_send_result(client));
    fbksd_client_free(client);
    free(sums.sums);
    return 0;
}
