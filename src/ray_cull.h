/* Rays that cannot reach a scene, answered on the host: vkrt_trace_rays on a CPU device
 * (gpu_trace_rays) sends the BVH traversal only the rays that may enter the scene's bounding box
 * (the binary BVH's root) and writes a miss for the others. On lavapipe a ray that misses
 * everything still costs a whole iteration of the wide traversal's loop (a root visit, the
 * refill, an idle second step) for all eight lanes of a SIMD group; here it costs a four-ray box
 * test on the way into the ray buffer, which the rays are copied into anyway. */
#ifndef VKRT_RAY_CULL_H
#define VKRT_RAY_CULL_H

#include <stddef.h>
#include <stdint.h>

#include "vkrt.h"
#include "../shaders/vkrt_shared.h"

/* Bit l set where rays[l] may enter box: exactly where the C reference's first step, its
 * conservative box test of the root (intersect_box_f on the float ray of ray_from_buffer_f,
 * against the ray's tmax), enters it; clear for a ray that must miss (a non-finite origin or
 * direction, a zero direction). Four lanes of float4.h. */
unsigned ray_cull_test4(const vkrt_ray rays[4], const vkrt_gpu_node *box);

/* Reads rays from rays[0] on until `room` of them may enter box or all `count` are read: those
 * are copied to out_rays[0..] with their positions in out_index, and every ray read that cannot
 * enter box gets a miss in out_hits at its position (t = -1, prim_id VKRT_NO_HIT, u = v = 0,
 * what the device writes for a miss). box NULL: the scene is empty, and every ray misses.
 * Returns the rays copied; *out_read is the rays read. */
size_t ray_cull_compact(const vkrt_ray *rays, size_t count, const vkrt_gpu_node *box, size_t room, vkrt_ray *out_rays,
                        uint32_t *out_index, vkrt_hit *out_hits, size_t *out_read);

#endif
