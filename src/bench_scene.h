/* The scene a `vkrt bench` run loads: a mesh file, the built-in scene, or (options->procedural)
 * a tessellated surface of a chosen size for the scaling series, made here in memory and handed
 * to vkrt_scene_create as a vkrt_mesh_desc. */
#ifndef VKRT_BENCH_SCENE_H
#define VKRT_BENCH_SCENE_H

#include "bench.h"

typedef struct bench_scene {
    const bench_options *o;
    float *positions;       /* procedural: the vertices ... */
    uint32_t *indices;      /* ... and triangles */
    vkrt_mesh_desc mesh;
    char label[64];         /* "built-in", "procedural-N", or (label empty) the file's path */
} bench_scene;

/* Makes the procedural mesh where options ask for one: about options->procedural triangles
 * (its label says exactly how many). Returns VKRT_OK, or VKRT_ERROR_OUT_OF_MEMORY
 * with error saying so. */
vkrt_result bench_scene_init(bench_scene *s, const bench_options *o, char *error, size_t error_size);
/* What vkrt_scene_create needs for it, with the options' builder. */
vkrt_scene_desc bench_scene_desc(const bench_scene *s);
/* The scene's name in tables and CSV files. */
const char *bench_scene_name(const bench_scene *s);
void bench_scene_free(bench_scene *s);

/* vkrt_scene_create of desc on ctx. For a GPU scene (gpu_rows: what the run skips without it,
 * "the GPU backend"; NULL for a CPU scene), one beyond the device (VKRT_ERROR_LIMIT: lavapipe's
 * storage buffers hold 128 MiB, about two million triangles; VKRT_ERROR_OUT_OF_DEVICE_MEMORY)
 * is not a failure of the run: *out_scene is then NULL, the call returns VKRT_OK and skipped
 * (skipped_size bytes) says "<gpu_rows> not run: why", and the run goes on without those rows.
 * Any other failure returns its code with error saying what failed. */
#define BENCH_GPU_BACKEND_ROWS "the GPU backend was" /* gpu_rows where a run has one GPU scene */
vkrt_result bench_scene_create(vkrt_context *ctx, const char *gpu_rows, const vkrt_scene_desc *desc,
                               vkrt_scene **out_scene, char *skipped, size_t skipped_size, char *error,
                               size_t error_size);

#endif
