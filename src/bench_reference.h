/* Converged references for `vkrt bench --modes`: a lighting-mode render at many samples per
 * pixel on the CPU backend, with a seed of its own (so its noise is independent of the renders
 * measured against it), kept on disk under a key of everything that decides the image, so
 * later runs read it back instead of spending minutes on it again. */
#ifndef VKRT_BENCH_REFERENCE_H
#define VKRT_BENCH_REFERENCE_H

#include <stdbool.h>
#include <stddef.h>

#include "vkrt.h"

typedef struct bench_reference_desc {
    vkrt_context *cpu;          /* a CPU-backend context ... */
    vkrt_scene *scene;          /* ... and its scene */
    const char *scene_path;     /* the file the scene came from (its size and modification time
                                   join the key); NULL: scene_name alone names it */
    const char *scene_name;     /* "built-in", "procedural-N" */
    bool keep_world_coordinates;
    const vkrt_render_desc *render; /* the render to converge: mode, size, camera, lights, sky,
                                       ao and path settings; spp and seed are the reference's */
    const char *cache_dir;      /* NULL: render every time, keep nothing; else read and write
                                   ref-<key hash>.bin here (made where missing) */
} bench_reference_desc;

typedef struct bench_reference_info {
    bool cached;                /* read from the cache rather than rendered */
    double ms;                  /* the render's (or the read's) wall-clock time */
    double noise;               /* the reference's own error: the root mean square over pixels of
                                   vkrt's estimated standard error of each pixel's mean luminance */
} bench_reference_info;

/* Fills out_rgba (vkrt_render_floats(width, height)) with the reference image. A cache file
 * that does not hold exactly this key is rendered anew and replaced (atomically). Returns a
 * vkrt_result, with error saying what failed. */
vkrt_result bench_reference_get(const bench_reference_desc *desc, float *out_rgba, bench_reference_info *out_info,
                                char *error, size_t error_size);

#endif
