/* The lighting modes on the GPU as a wavefront (Laine, Karras, Aila, "Megakernels Considered
 * Harmful", HPG 2013): per tile and sample, shaders/shade.comp's stages and trace.comp's
 * wavefront traversal (closest-hit for extension rays, any-hit for shadow and AO rays) take
 * turns over per-pixel buffers that stay on the device. Each traversal is a budgeted,
 * resumable pass, so no dispatch ever reaches lavapipe's loop limit; the stages have no
 * unbounded loop. */
#ifndef VKRT_GPU_INTEGRATE_H
#define VKRT_GPU_INTEGRATE_H

#include "gpu_trace.h"
#include "lights.h"

typedef struct gpu_integrate_params {
    vkrt_gpu_push camera;          /* eye/right/up/forward/width/height */
    vkrt_mode mode;                /* shaded, ao or path */
    vkrt_traversal traversal;      /* resolved */
    vkrt_intersector intersector;
    bool alpha_tested;
    bool textured;                 /* some material has a texture (the alpha test samples them) */
    const light_table *lights;
    vkrt_gpu_lighting lighting;    /* with the mode's fields filled */
    uint32_t features;             /* VKRT_GPU_FEATURE_* */
    float *out_error;              /* NULL, or a float per pixel */
    vkrt_progress_fn progress;
    void *progress_user;
} gpu_integrate_params;

/* Writes width * height * 4 floats (mean radiance and coverage) to out_rgba, the device time
 * of every dispatch to *out_device_ms, and the samples and rays to *out_counts. The surfaces,
 * the triangles and what the traversal reads (gpu_trace_rays_arrays) must be uploaded. */
vkrt_result gpu_integrate_render(vk_context *vk, const gpu_scene *scene, const gpu_integrate_params *params,
                                 float *out_rgba, double *out_device_ms, trace_counts *out_counts);

#endif
