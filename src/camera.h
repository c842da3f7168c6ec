/* Turns the public camera description into the ray-generation basis both tracers use. */
#ifndef VKRT_CAMERA_H
#define VKRT_CAMERA_H

#include "../shaders/vkrt_shared.h"
#include "core.h"

/* The eye of the default view (vkrt_camera: eye == target), looking at the origin. */
#define CAMERA_DEFAULT_EYE_Z 1.5

/* The ray-generation basis as doubles holding the push constants' float values: what the CPU
 * double-precision reference generates its rays from, in double (same fields and meaning as in
 * vkrt_gpu_push). */
typedef struct camera_basis {
    double eye[3], right[3], up[3], forward[3];
    uint32_t width, height;
} camera_basis;

/* Resolves defaults (see vkrt_camera) and fills eye, right, up, forward, width and height of
 * *push. Fails with VKRT_ERROR_INVALID_ARGUMENT (message naming the field) for a non-finite
 * value, a field of view outside (0, 180), or an up vector parallel to the view direction. */
vkrt_result camera_setup(core *c, const vkrt_camera *camera, uint32_t width, uint32_t height,
                         vkrt_gpu_push *push);
/* The same checks and basis as camera_setup, as doubles (each value the push constant's). */
vkrt_result camera_setup_double(core *c, const vkrt_camera *camera, uint32_t width, uint32_t height,
                                camera_basis *out);

#endif
