/* `vkrt bench`: run time against error for one scene, through vkrt.h only (like main.c). Every
 * configuration (backend, BVH builder, traversal, intersector, CPU precision) renders the same
 * view; each is timed (median of several renders after a warm-up), its traversal work counted,
 * and its `id` and `depth` images compared with the CPU double-precision reference. One row per
 * configuration, as a markdown table and optionally as CSV. */
#ifndef VKRT_BENCH_H
#define VKRT_BENCH_H

#include <stdbool.h>
#include <stdint.h>
#include <stdio.h>

#include "vkrt.h"

typedef struct bench_options {
    vkrt_context_desc context; /* log, validation, device, threads, pipeline cache; its backend
                                  is ignored (see backend below) */
    vkrt_backend backend;      /* _DEFAULT: both GPU and CPU; else that one only */
    const char *input;         /* mesh file; NULL: the built-in scene */
    uint32_t procedural;       /* > 0: instead, a procedural scene of about this many triangles
                                  (bench_scene.h) */
    bool keep_world_coordinates;
    vkrt_bvh_builder builder;  /* --compare and --modes: the scene's BVH builder (_DEFAULT: binned
                                  SAH); the configuration table builds every builder's */
    vkrt_camera camera;        /* zero: the default view */
    uint32_t width, height;    /* 0: 512x512 (quick: 64x64) */
    uint32_t repeat;           /* timed renders after the warm-up; 0: 5 (quick: 1) */
    bool quick;                /* small image, one timed render: the test suite's run */
    FILE *out;                 /* the markdown table; NULL: stdout */
    const char *csv_path;      /* also write the rows as CSV here (atomically); NULL: no CSV */
    bool progress;             /* a progress line on stderr (a terminal) */
    /* bench_modes_run only: */
    uint32_t max_spp;          /* bench --modes: the spp ladder 1, 4, 16, ... up to this; 0: 64
                                  (quick: 4) */
    uint32_t reference_spp;    /* samples per pixel of the converged references; 0: 1024
                                  (quick: 256) */
    const char *cache_dir;     /* where references are kept between runs; NULL: nowhere */
} bench_options;

typedef struct bench_report {
    unsigned rows;
    unsigned validation_messages; /* summed over the contexts */
    char error[1024];             /* what failed when bench_run returns an error */
} bench_report;

/* The median of n > 0 values (sorted in place): what every timing of the command line reports. */
double bench_median(double *values, uint32_t n);

/* Runs every configuration and prints the table. Returns VKRT_OK, or the vkrt_result of the
 * call that failed, with out->error naming it. */
vkrt_result bench_run(const bench_options *options, bench_report *out);

#endif
