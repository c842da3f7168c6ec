/* Wächter, Binder, "A Fast and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems,
 * chapter 6, 2019: the error of a computed hit point grows with the magnitude of its
 * coordinates, so the offset is a fixed number of ulps (an integer added to the float's bits,
 * away from zero in the direction of the normal) rather than a fixed distance; near the origin,
 * where ulps shrink towards denormals, a small fixed distance takes over. */
#include "ray_offset.h"

#include <math.h>
#include <string.h>

static float offset_one(float p, float n)
{
    if (fabsf(p) < (float)VKRT_OFFSET_ORIGIN) return p + (float)VKRT_OFFSET_FLOAT_SCALE * n;
    /* Truncation toward zero, as GLSL's int(); unsigned arithmetic wraps as GLSL's int does. */
    int32_t of_i = (int32_t)((float)VKRT_OFFSET_INT_SCALE * n);
    uint32_t bits;
    memcpy(&bits, &p, sizeof bits);
    bits += (uint32_t)(p < 0.0f ? -of_i : of_i);
    float out;
    memcpy(&out, &bits, sizeof out);
    return out;
}

vkrt_float3 ray_offset(vkrt_float3 p, vkrt_float3 n)
{
    return (vkrt_float3){ offset_one(p.x, n.x), offset_one(p.y, n.y), offset_one(p.z, n.z) };
}
