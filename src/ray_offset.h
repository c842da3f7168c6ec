/* Origins of secondary rays that cannot re-hit the surface they leave. */
#ifndef VKRT_RAY_OFFSET_H
#define VKRT_RAY_OFFSET_H

#include "../shaders/vkrt_shared.h"

/* p moved off its surface along n: n is the unit geometric normal turned to the side the new
 * ray leaves from (for a reflection the side of the incoming ray, for a transmission the
 * other). Each coordinate moves by VKRT_OFFSET_INT_SCALE * n ulps (in integer steps of its
 * float representation), or, where |p| < VKRT_OFFSET_ORIGIN, by VKRT_OFFSET_FLOAT_SCALE * n.
 * Mirrors ray_offset() in shaders/trace_common.glsl bit for bit. */
vkrt_float3 ray_offset(vkrt_float3 p, vkrt_float3 n);

#endif
