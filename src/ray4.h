/* Four vkrt_rays as the columns of float4 rows, and the rays among them that must miss: the
 * shared first step of the host's four-ray code (ray_cull.c's box test on the way into the
 * GPU's ray buffer, cpu_trace_packet8.h's packets in two halves), so that both read the rays
 * alike and reject what ray_from_buffer_f rejects. */
#ifndef VKRT_RAY4_H
#define VKRT_RAY4_H

#include <math.h>
#include <stddef.h>

#include "float4.h"
#include "vkrt.h"

_Static_assert(sizeof(vkrt_ray) == 8 * sizeof(float) && offsetof(vkrt_ray, tmin) == 3 * sizeof(float) &&
                   offsetof(vkrt_ray, dir) == 4 * sizeof(float) && offsetof(vkrt_ray, tmax) == 7 * sizeof(float),
               "vkrt_ray is read as two rows of four floats");

/* o[a] and d[a]: axis a of the four origins and directions; o[3] the tmins, d[3] the tmaxes
 * as given (0 meaning infinity). Two rows a ray, four columns once transposed. */
static inline void ray4_load(const vkrt_ray rays[4], float4 o[4], float4 d[4])
{
    const float *f = (const float *)(const void *)rays;
    o[0] = f4_load(f), o[1] = f4_load(f + 8), o[2] = f4_load(f + 16), o[3] = f4_load(f + 24);
    d[0] = f4_load(f + 4), d[1] = f4_load(f + 12), d[2] = f4_load(f + 20), d[3] = f4_load(f + 28);
    f4_transpose(o);
    f4_transpose(d);
}

/* The lanes ray_from_buffer_f accepts: finite origin and direction, a direction not zero. */
static inline float4 ray4_valid(const float4 o[4], const float4 d[4])
{
    const float4 inf = f4_set1(INFINITY), zero = f4_set1(0.0f);
    float4 valid = f4_mask(0xFu);
    for (int a = 0; a < 3; a++) valid = f4_and(valid, f4_and(f4_lt(f4_abs(o[a]), inf), f4_lt(f4_abs(d[a]), inf)));
    return f4_andnot(f4_and(f4_and(f4_eq(d[0], zero), f4_eq(d[1], zero)), f4_eq(d[2], zero)), valid);
}

#endif
