/* The C reference tracer: the same camera, traversal, triangle tests and per-mode outputs as
 * shaders/trace.comp, over the same packed node and triangle arrays, multi-threaded over
 * tiles (or blocks of rays), in float (as the GPU) or double (the reference for every error
 * figure). Everything the GPU is checked against comes from here. */
#ifndef VKRT_CPU_TRACE_H
#define VKRT_CPU_TRACE_H

#include "../shaders/vkrt_shared.h"
#include "bvh_wide.h"
#include "camera.h"
#include "core.h"
#include "trace_counts.h"

typedef struct cpu_trace_scene {
    const vkrt_gpu_node *nodes;
    uint32_t node_count;
    const vkrt_gpu_tri *tris;
    uint32_t tri_count;
    const vkrt_gpu_surface *surfaces;   /* by prim_id (albedo and uv modes) */
    const vkrt_gpu_material *materials;
    const vkrt_gpu_texture *textures;
    const uint32_t *texels;
    bool alpha_tested;                  /* some material is alpha-masked: hits are alpha tested */
    const bvh4 *wide;                   /* NULL, or the same tree collapsed 4-wide over the same
                                           triangles: float BVH traces that keep no counters go
                                           through it instead (cpu_trace_bvh4.h), with the same
                                           closest hits */
} cpu_trace_scene;

typedef struct cpu_trace_params {
    vkrt_gpu_push camera;       /* eye/right/up/forward/width/height as for the GPU; tile
                                   fields ignored */
    vkrt_mode mode;             /* resolved: never _DEFAULT */
    vkrt_traversal traversal;   /* resolved */
    vkrt_heat heat;             /* resolved */
    vkrt_intersector intersector; /* _DEFAULT: watertight */
    vkrt_precision precision;   /* _DEFAULT: float */
    camera_basis camera_d;      /* camera_setup_double: double traces from it; float refines its
                                   hit distances with it */
    bool counters;              /* fill *out_counts */
    const struct cpu_lighting *lighting; /* lighting modes (cpu_integrate.h); NULL for the others */
    uint32_t threads;           /* >= 1 */
    vkrt_progress_fn progress;  /* may be NULL; called from the calling thread */
    void *progress_user;
} cpu_trace_params;

/* Writes width * height * 4 floats to out_rgba, and the traversal counters to *out_counts
 * (zero unless params->counters). Returns VKRT_OK, VKRT_ERROR_CANCELLED, or
 * VKRT_ERROR_OUT_OF_MEMORY / a thread-creation failure as VKRT_ERROR_LIMIT. */
vkrt_result cpu_trace_render(core *c, const cpu_trace_scene *scene, const cpu_trace_params *params,
                             float *out_rgba, trace_counts *out_counts);

#define CPU_TRACE_PACKET_LANES 8 /* rays a packet (src/cpu_trace_packet8.h) */

typedef struct cpu_trace_rays_params {
    vkrt_traversal traversal;     /* resolved */
    bool any_hit;                 /* the first hit found, not the closest */
    vkrt_intersector intersector; /* _DEFAULT: watertight */
    vkrt_precision precision;     /* _DEFAULT: float */
    uint32_t threads;             /* >= 1 */
    vkrt_progress_fn progress;    /* may be NULL; called from the calling thread */
    void *progress_user;
} cpu_trace_rays_params;

/* The closest hit of each ray (see vkrt_trace_rays), threads over blocks of rays. Returns as
 * cpu_trace_render. Float rays through the 4-wide BVH go CPU_TRACE_PACKET_LANES at a time as
 * one packet where those rays, in buffer order, are valid and share an origin and nearly a
 * direction (a camera's); the answers are the single rays' either way. */
vkrt_result cpu_trace_rays(core *c, const cpu_trace_scene *scene, const cpu_trace_rays_params *params,
                           const vkrt_ray *rays, size_t count, vkrt_hit *out_hits);

/* A miss as vkrt_trace_rays writes it (vkrt.h): t = -1, prim_id VKRT_NO_HIT, u = v = 0. */
static inline vkrt_hit cpu_trace_miss(void)
{
    return (vkrt_hit){ .t = -1.0f, .prim_id = VKRT_NO_HIT };
}

/* Whether the reference's first step enters box for this ray: the float ray of a ray buffer
 * (false for one that must miss), box-tested against its tmax. What ray_cull_test4 is held
 * to by test_cpu_trace. */
bool cpu_trace_ray_enters_box(const vkrt_ray *ray, const vkrt_gpu_node *box);

/* The machine code cpu_trace_render and cpu_trace_rays run (and ray_bin.c's plan): the baseline
 * build (SSE2), or the same source built for x86-64-v3 (AVX2, BMI2, FMA unused: the same bits),
 * where the library was built with it and the host has it, unless c->test_cpu_baseline asks for
 * the baseline. */
typedef enum cpu_trace_code { CPU_TRACE_BASELINE, CPU_TRACE_X86_64_V3 } cpu_trace_code;
cpu_trace_code cpu_trace_isa(const core *c);
const char *cpu_trace_isa_name(cpu_trace_code code);

/* The primary ray of pixel (x, y) in float, as shaders/trace_common.glsl's camera_ray makes it
 * (tmax = 0: infinity). */
vkrt_gpu_ray cpu_trace_camera_ray(const vkrt_gpu_push *camera, uint32_t x, uint32_t y);

/* One ray as trace.comp's wavefront variant traces it: the closest hit (or with any_hit the
 * first found) with out_hit->tri the triangle array index and t unrefined; t = -1 and tri =
 * 0xFFFFFFFF on a miss. Adds the binary traversal's counts to *counts; with s->wide (and
 * traversal BVH) the ray goes through the 4-wide tree, which keeps no counts, and *counts is
 * left as it was. Returns whether it hit. */
bool cpu_trace_one(const cpu_trace_scene *s, vkrt_traversal traversal, vkrt_intersector isect, const vkrt_gpu_ray *ray,
                   bool any_hit, vkrt_gpu_hit *out_hit, trace_counts *counts);

/* The four-box test of the 4-wide traversal on node n's slots, for the tests that hold it to
 * the binary one: the float ray made from ray's origin, dir and tmin as every traversal makes
 * it (no checks: zero, denormal and infinite components pass), tested against best_t. simd:
 * the four-lane test the traversal uses (float4.h: SSE2, or its plain-C twin); false:
 * intersect_box_f per slot. Returns the mask of hit slots (bit i: slot i) and writes each
 * used slot's entry distance to out_tnear[i]. */
unsigned cpu_trace_box4_test(const vkrt_gpu_ray *ray, const bvh4_node *n, float best_t, bool simd,
                             float out_tnear[BVH4_WIDTH]);
/* The watertight test of the 4-wide traversal's leaves on four triangles, for the tests that
 * hold it to the scalar one: the float ray made from ray (tmin, tmax as given; no checks).
 * simd: the four-lane test (float4.h); false: intersect_triangle_watertight_f per triangle.
 * Returns the mask of hit triangles and writes each hit's t, u, v. */
unsigned cpu_trace_watertight4_test(const vkrt_gpu_ray *ray, const vkrt_gpu_tri *const tris[4], bool simd,
                                    float out_t[4], float out_u[4], float out_v[4]);

#endif
