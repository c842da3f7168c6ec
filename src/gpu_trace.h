/* Drives shaders/trace.comp: scene buffers on the device, a render as a sequence of
 * rectangles of its tiles and arbitrary rays as a sequence of ray chunks, each its own
 * submission sized by a pacer to about GPU_SUBMIT_TARGET_MS (progress and cancellation happen
 * between them). */
#ifndef VKRT_GPU_TRACE_H
#define VKRT_GPU_TRACE_H

#include "../shaders/vkrt_shared.h"
#include "gpu_pace.h"
#include "gpu_scene.h"
#include "trace_counts.h"

typedef struct gpu_trace_params {
    vkrt_gpu_push camera;      /* eye/right/up/forward/width/height filled by camera_setup */
    vkrt_mode mode;            /* resolved */
    vkrt_traversal traversal;  /* resolved */
    vkrt_heat heat;            /* resolved */
    vkrt_intersector intersector; /* _DEFAULT: watertight */
    bool counters;             /* fill *out_counts (a pipeline variant that writes them) */
    bool alpha_tested;         /* alpha-test every hit (the surfaces must be uploaded) */
    bool textured;             /* some material has a texture (albedo, alpha test) */
    vkrt_progress_fn progress; /* may be NULL */
    void *progress_user;
    const vkrt_gpu_tri *tris;  /* the scene's triangles in BVH order, whose lists the binned
                                  traversal builds for the camera rays on a CPU device (NULL: the
                                  BVH); see gpu_trace_rays_params */
    uint32_t threads;          /* host threads that build them (0 counts as 1) */
} gpu_trace_params;

/* The binary arrays (GPU_ARRAY_*) gpu_trace_render reads for `params`; the caller uploads them
 * first. */
uint32_t gpu_trace_render_arrays(const gpu_scene *scene, const gpu_trace_params *params);

/* Writes width * height * 4 floats (rows top to bottom) to out_rgba; *out_device_ms gets the
 * summed device time of the trace dispatches (0 where the queue has no timestamps), with the
 * binned traversal's listing on the host added where it took the camera rays, and *out_counts
 * the traversal counters (zero unless params->counters). */
vkrt_result gpu_trace_render(vk_context *vk, const gpu_scene *scene, const gpu_trace_params *params,
                             float *out_rgba, double *out_device_ms, trace_counts *out_counts);

typedef struct gpu_trace_rays_params {
    vkrt_traversal traversal;     /* resolved */
    bool any_hit;                 /* the first hit found, not the closest */
    vkrt_intersector intersector; /* _DEFAULT: watertight */
    bool alpha_tested;            /* as in gpu_trace_params */
    bool textured;                /* as in gpu_trace_params */
    vkrt_progress_fn progress;    /* may be NULL; called between submissions */
    void *progress_user;
    const vkrt_gpu_tri *tris;     /* gpu_trace_rays: the scene's triangles in BVH order, whose lists
                                     the binned traversal builds on a CPU device (NULL: none) */
    uint32_t threads;             /* host threads that build them (0 counts as 1) */
} gpu_trace_rays_params;

/* The binary arrays a traversal of rays reads (gpu_trace_rays and the wavefront's tracers; the
 * wavefront's shade stage reads the triangles besides). */
uint32_t gpu_trace_rays_arrays(const gpu_scene *scene, vkrt_traversal traversal);

/* The closest hit of each ray (see vkrt_trace_rays), VKRT_RAY_CHUNK rays per submission
 * (VKRT_RESUME_RAY_CHUNK with a loop budget, plus resume submissions while any is unfinished);
 * the passes' device time into *out_device_ms, the submissions and culled rays into *out_counts,
 * as gpu_trace_render reports a render's. */
vkrt_result gpu_trace_rays(vk_context *vk, const gpu_scene *scene, const gpu_trace_rays_params *params,
                           const vkrt_ray *rays, size_t count, vkrt_hit *out_hits, double *out_device_ms,
                           trace_counts *out_counts);

/* The wavefront's traversal passes (the lighting modes): a ray buffer on the device that
 * shade.comp fills and trace.comp's wavefront variant traces, closest-hit or (params->any_hit)
 * any-hit, its hits left on the device for the next stage (tri = triangle array index). */
typedef struct gpu_wavefront_tracer gpu_wavefront_tracer;

/* The host memory first (NULL when out of it), the device objects next: a caller allocates
 * everything it needs before anything creates the context's pipelines, so a failed
 * allocation leaves nothing behind. */
gpu_wavefront_tracer *gpu_wavefront_tracer_alloc(vk_context *vk);
/* On failure the caller still destroys t. */
vkrt_result gpu_wavefront_tracer_init(vk_context *vk, gpu_wavefront_tracer *t, const gpu_scene *scene,
                                      const gpu_trace_rays_params *params, uint32_t capacity);
VkBuffer gpu_wavefront_rays(const gpu_wavefront_tracer *t);
VkBuffer gpu_wavefront_hits(const gpu_wavefront_tracer *t);
/* A pacer for a wavefront of up to `capacity` rays (gpu_pace.h): its units are rays times
 * naive-traversal chunks, and it grows only after the stages and the traversals have all been
 * fast. */
void gpu_wavefront_pacer(const vk_context *vk, const gpu_scene *scene, bool naive, uint32_t capacity, gpu_pacer *out);

/* Progress and cancellation between a wavefront traversal's submissions. */
typedef struct gpu_wave_progress {
    vkrt_progress_fn progress;  /* may be NULL */
    void *user;
    float fraction;
} gpu_wave_progress;

/* Traces the first `count` rays: one submission, and more while the loop budget leaves any
 * unfinished or naive traversal has triangle chunks left (as many per submission as the pacer
 * allows); the pacer learns every submission's time. Adds the device time to *device_ms. */
vkrt_result gpu_wavefront_trace(vk_context *vk, gpu_wavefront_tracer *t, const gpu_scene *scene, uint32_t count,
                                gpu_pacer *pacer, const gpu_wave_progress *progress, double *device_ms);
void gpu_wavefront_tracer_destroy(vk_context *vk, gpu_wavefront_tracer *t); /* NULL: no-op */

#endif
