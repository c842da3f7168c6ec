/* Embree 3 behind the interface `vkrt bench --compare embree` times: a scene of the triangles
 * vkrt traces and the two queries vkrt_trace_rays answers (the closest hit, rtcIntersect1; any
 * hit, rtcOccluded1) over an array of vkrt_ray, on as many threads as vkrt's CPU backend uses.
 * Built only where Debian's libembree-dev (Embree 3) is installed (VKRT_HAVE_EMBREE); the rest
 * of the command line never includes Embree's headers. */
#ifndef VKRT_BENCH_EMBREE_H
#define VKRT_BENCH_EMBREE_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "vkrt.h"

typedef struct bench_embree bench_embree;

/* "3.13.5": the Embree the program was built against. */
const char *bench_embree_version(void);

/* Builds an Embree scene (RTC_SCENE_FLAG_NONE, build quality medium) of `count` triangles,
 * 9 floats each in vkrt_scene_triangles_get() order, so Embree's primID is vkrt's prim_id, on a
 * device of `threads` threads. *out_build_ms: the wall-clock time of rtcCommitScene alone;
 * *out_bytes: the most memory Embree held for it (its memory monitor). On failure error says
 * what Embree reported. */
vkrt_result bench_embree_create(const float *triangles, size_t count, uint32_t threads, bench_embree **out,
                                double *out_build_ms, uint64_t *out_bytes, char *error, size_t error_size);
void bench_embree_destroy(bench_embree *e);

/* Traces `count` rays (vkrt's conventions: hits in (tmin, tmax), tmax 0 infinite, t in units of
 * |dir|) into out_hits as vkrt_trace_rays() would write them: closest, or with any_hit the
 * first hit found (rtcOccluded1 reports no distance: t is then 0 on a hit, -1 on a miss).
 * *out_ms: the wall-clock time of the whole call, threads started and joined. */
vkrt_result bench_embree_trace(bench_embree *e, const vkrt_ray *rays, size_t count, bool any_hit, vkrt_hit *out_hits,
                               double *out_ms, char *error, size_t error_size);

#endif
