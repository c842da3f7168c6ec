/* Traversal counters of a render, summed over its primary rays (vkrt_render_stats): what the
 * heat map shows per pixel, in total. Both backends fill one; the GPU's vkrt_trace_rays fills
 * its submissions and culled rays (vkrt_trace_stats). */
#ifndef VKRT_TRACE_COUNTS_H
#define VKRT_TRACE_COUNTS_H

#include <stdint.h>

typedef struct trace_counts {
    uint64_t nodes;  /* BVH boxes entered, the root's included */
    uint64_t leaves; /* of those, leaves */
    uint64_t tris;   /* ray-triangle tests (naive traversal: every triangle, every ray) */
    uint64_t samples;     /* lighting modes: samples taken */
    uint64_t shadow_rays; /* lighting modes: any-hit rays traced */
    uint64_t bounce_rays; /* lighting modes: closest-hit rays after the primary ones */
    uint32_t submissions; /* GPU: device submissions (gpu_pace.h sizes them) */
    double longest_submission_ms; /* GPU: wall-clock time of the longest */
    uint64_t rays_culled; /* vkrt_trace_rays on a CPU device: rays the host answered as missing
                             the scene's box (binned: those whose list is empty) */
    uint64_t rays_binned; /* GPU backend on a CPU device: rays (vkrt_trace_rays) or camera rays
                             (vkrt_render) traced through the lists of the binned traversal
                             (src/ray_bin.h) */
    uint64_t binned_tests; /* of those rays' lists, the entries: a triangle test each, and no box */
} trace_counts;

#endif
