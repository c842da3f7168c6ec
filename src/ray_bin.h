/* Lists of the triangles each ray may hit, for a set of rays that share one origin (the
 * camera rays of vkrt_camera_rays, or any pinhole's): the GPU path on a CPU device (lavapipe)
 * traces such rays by testing each one's list instead of walking the BVH.
 *
 * Seen from the shared origin o, a triangle whose corners all lie in front of a plane through o
 * projects (x -> the direction of x - o) to the triangle of its projected corners, and a ray
 * hits it only where the ray's own projected direction lies inside that. So every triangle is
 * listed for the rays whose projected directions fall in its projected bounding box (widened
 * far beyond the rounding of the projection and of the intersection test), found through a grid
 * of about one cell a ray. A ray's list then holds every triangle the BVH's leaves could give it
 * a hit on, and the device tests them with the same test and tie rule (closest distance, then
 * lowest prim_id): the same hits, bit for bit. Ray classification (Arvo and Kirk 1987) with the
 * origin fixed; a rasteriser whose coverage test is the ray's own intersection test. Where the
 * rays lie on a camera's lattice and start at the origin, a list leaves out the triangles wholly
 * behind one that the ray surely hits (occlusion culling, its test the coverage test with the
 * edges moved inwards): none of those can be its closest hit.
 *
 * Internal; the library's allocator, no printing. */
#ifndef VKRT_RAY_BIN_H
#define VKRT_RAY_BIN_H

#include <stdbool.h>
#include <stdint.h>

#include "../shaders/vkrt_shared.h"
#include "core.h"
#include "vkrt.h"

/* A ray's cell where it cannot enter the scene's box (or is not valid: non-finite, or a zero
 * direction): its list is empty. */
#define RAY_BIN_NO_CELL UINT32_MAX

typedef struct ray_bin_job ray_bin_job;

typedef struct ray_bins {
    const uint32_t *ray_cell;   /* each ray's cell (RAY_BIN_NO_CELL: none) */
    const uint32_t *cell_start; /* each cell's room in the entries, from its first, then one past
                                   the last cell's: a cell without room has an empty list */
    const uint32_t *cell_first, *cell_end; /* once filled: each cell's list (within its room) */
    uint32_t entry_count;       /* the room of all lists together (they may leave some unwritten) */
    uint32_t longest;           /* the longest list's room */
    bool culled;                /* lists leave out triangles hidden behind others */
    bool on_lattice;            /* the rays' projections lie on a regular lattice (a camera's
                                   pixel centres), a cell each: a triangle between them is in
                                   no list without a test */
    ray_bin_job *job;           /* the plan's state, for ray_bin_fill */
} ray_bins;

/* What a set of rays must keep within for the lists to be built: past them the caller traces
 * the rays through the BVH instead. */
typedef struct ray_bin_limits {
    uint32_t max_entries; /* all lists together */
    uint32_t max_list;    /* one ray's list (lavapipe's loops end silently after 65,535 turns) */
} ray_bin_limits;

typedef enum ray_bin_outcome {
    RAY_BIN_BUILT,          /* *out holds the lists */
    RAY_BIN_ORIGINS_DIFFER, /* two valid rays start at different points, or none is valid */
    RAY_BIN_WIDE_ANGLE,     /* some direction lies more than RAY_BIN_MAX_ANGLE_DEG off the axis */
    RAY_BIN_BEHIND,         /* the scene's box reaches behind (or too near) the origin's plane */
    RAY_BIN_TOO_LONG,       /* the lists would pass `limits` */
    RAY_BIN_NONE_ENTER      /* no ray may enter the scene's box: every one misses */
} ray_bin_outcome;

/* The widest angle between a ray and the axis, the mean direction of up to RAY_BIN_AXIS_SAMPLES
 * of the rays (a projection onto the plane at distance 1 along it stays within tan of this). */
#define RAY_BIN_AXIS_SAMPLES 4096u
#define RAY_BIN_MAX_ANGLE_DEG 75.0

/* The host memory of a plan, kept between calls by a caller that wants later plans to reuse it
 * (ray_bin_plan's `keep`): up to 192 MiB. */
typedef struct ray_bin_scratch ray_bin_scratch;
void ray_bin_scratch_destroy(core *c, ray_bin_scratch *s);

/* Plans the lists of rays[0 .. ray_count) for triangles tris[0 .. tri_count), which lie in
 * `box` (the BVH's root), on `threads` threads (0 counts as 1): each ray's cell and each cell's
 * place in the lists, which ray_bin_fill then writes. A ray that cannot enter the box by
 * ray_cull_test4 (the test that keeps rays from the device) gets an empty list. *out_outcome says whether the rays suit
 * (anything but RAY_BIN_BUILT leaves *out empty). keep (may be NULL): scratch a previous plan
 * left, taken and handed back by ray_bins_destroy (or a failed plan). Fails only with
 * VKRT_ERROR_OUT_OF_MEMORY. Ownership: free *out with ray_bins_destroy. */
vkrt_result ray_bin_plan(core *c, ray_bin_scratch **keep, const vkrt_ray *rays, uint32_t ray_count,
                         const vkrt_gpu_tri *tris, uint32_t tri_count, const vkrt_gpu_node *box,
                         ray_bin_limits limits, uint32_t threads, ray_bins *out, ray_bin_outcome *out_outcome);
/* As ray_bin_plan for the primary rays of `camera` (its eye, basis and image size, as
 * camera_setup fills them; width * height of at most 2^32 - 1) through every pixel centre, ray
 * y * width + x pixel (x, y): cpu_trace_camera_ray's rays, which vkrt_camera_rays makes and the
 * shaders' camera_ray traces, made as the plan reads them. The camera is borrowed for the plan. */
vkrt_result ray_bin_plan_camera(core *c, ray_bin_scratch **keep, const vkrt_gpu_push *camera,
                                const vkrt_gpu_tri *tris, uint32_t tri_count, const vkrt_gpu_node *box,
                                ray_bin_limits limits, uint32_t threads, ray_bins *out, ray_bin_outcome *out_outcome);
/* Writes the lists into `entries` (b->entry_count words, of which the culled triangles' room
 * stays unwritten), each cell's in the triangles' order. */
void ray_bin_fill(ray_bins *b, uint32_t *entries);

/* Ray i's list, once ray_bin_fill has written them: its first entry and its entry count. */
static inline void ray_bin_list(const ray_bins *b, uint32_t i, uint32_t out[2])
{
    const uint32_t cell = b->ray_cell[i];
    const bool none = cell == RAY_BIN_NO_CELL || b->cell_start[cell] == b->cell_start[cell + 1];
    out[0] = none ? 0 : b->cell_first[cell];
    out[1] = none ? 0 : b->cell_end[cell] - out[0];
}

/* As ray_cull_compact (ray_cull.h) for rays the lists were planned for: reads rays first ..
 * first + count - 1 of the plan's (rays[0] is ray `first`) until `room` of them have a list
 * that is not empty or all are read; those are copied to out_rays[0..] with their positions
 * (from rays[0]) in out_index, and every other ray read gets a miss in out_hits at its
 * position. A ray whose list is empty misses every triangle: the lists hold every triangle a
 * ray may hit first (culling leaves in the nearest triangle a cell's rays surely hit), and a ray
 * that cannot enter the scene's box has none. Three in four of the
 * standard view's rays of the dragons do, each a SIMD lane's work on a CPU device. Returns the
 * rays copied; *out_read is the rays read. */
size_t ray_bin_compact(const ray_bins *b, const vkrt_ray *rays, size_t first, size_t count, size_t room,
                       vkrt_ray *out_rays, uint32_t *out_index, vkrt_hit *out_hits, size_t *out_read);

void ray_bins_destroy(core *c, ray_bins *b);

#endif
