/* Paces a sequence of device submissions so that each takes about a target time: real GPUs
 * reset a device whose submission runs past a watchdog's second or two, and the progress
 * callback can only cancel between submissions. A caller asks how many units of work (pixels,
 * rays, or pixels times naive-traversal chunks) the next submission may take, submits that,
 * and reports how long it took; the pacer shrinks the amount in proportion after a submission
 * that ran long, and doubles it after a run of submissions that would all have stayed under
 * the target at twice the amount. */
#ifndef VKRT_GPU_PACE_H
#define VKRT_GPU_PACE_H

#include <stdint.h>

/* Each submission's aim: a tenth of a second stays well inside the watchdogs of desktop GPUs
 * (about two seconds) and keeps cancellation from the progress callback prompt. */
#define GPU_SUBMIT_TARGET_MS 100.0
/* The first submission of a call: a 128x128 rectangle, a few milliseconds of BVH traversal on
 * lavapipe, so a render starts under the target on any device and doubles from there. */
#define GPU_PACE_START_UNITS 16384u
/* Naive traversal's first submission: 128 rays times one chunk of 8,192 triangles, about the
 * time of 16,384 BVH traversals on lavapipe (where one naive chunk costs some 150 of them). */
#define GPU_PACE_START_NAIVE_UNITS 128u

typedef struct gpu_pacer {
    double target_ms;     /* each submission's aim */
    uint64_t units;       /* what the next submission may take, a power of two */
    uint64_t min_units, max_units;
    uint32_t grow_after;  /* fast reports in a row before the amount doubles */
    uint32_t fast;        /* fast reports in a row so far */
    uint32_t submissions; /* reported so far */
    double longest_ms;    /* the longest submission reported */
} gpu_pacer;

/* min_units and max_units are powers of two (max_units >= min_units); the first submission
 * takes `start` units, clamped to them and rounded down to a power of two. Submissions of
 * different kinds in one sequence (the wavefront's stages and traversals) want grow_after
 * above 1, so that every kind has been fast before the amount doubles. */
void gpu_pacer_init(gpu_pacer *p, double target_ms, uint64_t min_units, uint64_t max_units, uint64_t start,
                    uint32_t grow_after);

/* One submission of `units` units (at most p->units; fewer at the end of a tile) took `ms`. */
void gpu_pacer_report(gpu_pacer *p, uint64_t units, double ms);

/* Pixels or rays the next submission may take when each must meet `chunks` naive-traversal
 * chunks (1: BVH traversal): p->units / chunks rounded up, at least 1. */
uint64_t gpu_pacer_items(const gpu_pacer *p, uint32_t chunks);

/* The next rectangle of a tile (tile_w x tile_h) from the cursor (x, y) of the rectangles
 * before it, of about `pixels` pixels and at least one workgroup: whole 8-row bands of the
 * tile's width where that many fit and the cursor is at a band's start, else part of one band.
 * The caller advances the cursor by the width, and to the next band at the tile's edge. */
void gpu_pacer_rect(uint32_t tile_w, uint32_t tile_h, uint32_t x, uint32_t y, uint64_t pixels, uint32_t *out_w,
                    uint32_t *out_h);

#endif
