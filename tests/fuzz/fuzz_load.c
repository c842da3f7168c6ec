/* libFuzzer target: the bytes as a mesh file through vkrt's whole load path (parse, validate,
 * triangulate, compute normals, normalise, build the BVH (binned SAH, then spatial splits), pack)
 * on the CPU backend. Built twice, as fuzz_obj and fuzz_gltf, with FUZZ_EXTENSION ".obj" or
 * ".gltf" (a GLB is recognised by its magic whatever the name). Any result is fine; a crash, a
 * hang, a leak or a sanitizer report is not. scripts/fuzz builds and runs them. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <unistd.h>

#include "vkrt.h"

#ifndef FUZZ_EXTENSION
#error "define FUZZ_EXTENSION"
#endif

static vkrt_context *ctx;
static char path[64];

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!ctx) {
        /* One thread: libFuzzer's own timing and leak checks see all the work. */
        if (vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU, .cpu_threads = 1 }, &ctx) != VKRT_OK)
            abort();
        snprintf(path, sizeof path, "/tmp/vkrt-fuzz-%ld%s", (long)getpid(), FUZZ_EXTENSION);
    }
    FILE *f = fopen(path, "wb");
    if (!f) abort();
    if (size && fwrite(data, 1, size, f) != size) abort();
    fclose(f);
    /* What loads is built twice: with the default BVH and with spatial splits, whose clipping
     * sees every triangle the parsers let through. */
    const vkrt_bvh_builder builders[2] = { VKRT_BVH_BUILDER_DEFAULT, VKRT_BVH_BUILDER_SPATIAL_SAH };
    for (int b = 0; b < 2; b++) {
        vkrt_scene *scene = NULL;
        vkrt_result r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = path, .builder = builders[b] }, &scene);
        if (r == VKRT_OK) {
            /* A few rays through what loaded: traversal of whatever BVH the input produced. */
            float rgba[8 * 8 * 4];
            vkrt_render(ctx, scene, &(vkrt_render_desc){ .width = 8, .height = 8, .mode = VKRT_MODE_ALBEDO }, rgba,
                        sizeof rgba / sizeof rgba[0], NULL);
        }
        vkrt_scene_destroy(scene);
        if (r != VKRT_OK) break;
    }
    return 0;
}
