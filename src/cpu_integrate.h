/* The lighting modes on the CPU: shaded, ao and path, one pixel at a time, with the estimators,
 * sampler dimensions and stopping rules of shaders/shade.comp's wavefront stages, so both
 * backends compute the same image up to the rounding of the device. */
#ifndef VKRT_CPU_INTEGRATE_H
#define VKRT_CPU_INTEGRATE_H

#include "cpu_trace.h"

typedef struct cpu_lighting {
    const vkrt_gpu_light *lights;
    vkrt_gpu_lighting lighting; /* sky, counts and the mode's settings */
    uint32_t features;          /* VKRT_GPU_FEATURE_* */
    float *out_error;           /* NULL, or a float per pixel: standard error of the mean luminance */
} cpu_lighting;

/* Samples pixel (x, y) (params->lighting set; mode shaded, ao or path) and writes its mean
 * radiance and coverage to out; adds its samples and rays to *counts. */
void cpu_integrate_pixel(const cpu_trace_scene *s, const cpu_trace_params *p, uint32_t x, uint32_t y, float out[4],
                         trace_counts *counts);

#endif
