#include "ray_cull.h"

#include <math.h>
#include <stddef.h>
#include <string.h>

#include "cpu_trace.h"
#include "float4.h"
#include "ray4.h"

/* intersect_box_f of src/cpu_trace_real.h on four rays against one box, operation for
 * operation (f_min_f(x, y) is f4_min(y, x), f_max_f(x, y) is f4_max(y, x): see
 * cpu_trace_simd4.h), after ray_from_buffer_f's checks: a lane's answer is the scalar
 * test's, NaN, infinities and +-0 included. */
unsigned ray_cull_test4(const vkrt_ray rays[4], const vkrt_gpu_node *box)
{
    float4 o[4], d[4];
    ray4_load(rays, o, d);
    const float4 valid = ray4_valid(o, d);
    const float4 inf = f4_set1(INFINITY), minus_inf = f4_set1(-INFINITY), zero = f4_set1(0.0f);
    const float lo[3] = { box->bmin.x, box->bmin.y, box->bmin.z }, hi[3] = { box->bmax.x, box->bmax.y, box->bmax.z };
    float4 near[3], far[3];
    for (int a = 0; a < 3; a++) {
        const float4 inv = f4_div(f4_set1(1.0f), d[a]), blo = f4_set1(lo[a]), bhi = f4_set1(hi[a]);
        const float4 t0 = f4_mul(f4_sub(blo, o[a]), inv), t1 = f4_mul(f4_sub(bhi, o[a]), inv);
        /* slab_f: a +-0 direction component makes the slab everything or nothing. */
        const float4 parallel = f4_eq(f4_abs(inv), inf);
        const float4 inside = f4_and(f4_ge(o[a], blo), f4_le(o[a], bhi));
        near[a] = f4_select(parallel, f4_select(inside, minus_inf, inf), f4_min(t1, t0));
        far[a] = f4_select(parallel, f4_select(inside, inf, minus_inf), f4_max(t1, t0));
    }
    const float4 tnear = f4_max(f4_max(o[3], near[2]), f4_max(near[1], near[0]));
    float4 tfar = f4_mul(f4_min(far[2], f4_min(far[1], far[0])), f4_set1((float)VKRT_TFAR_WIDEN_FLOAT));
    /* prune_bound_f(tmax), tmax = 0 meaning infinity. */
    const float4 tmax = f4_select(f4_eq(d[3], zero), inf, d[3]);
    tfar = f4_min(f4_add(tmax, f4_mul(f4_abs(tmax), f4_set1((float)VKRT_PRUNE_SLACK))), tfar);
    return f4_bits(f4_and(valid, f4_le(tnear, tfar)));
}

size_t ray_cull_compact(const vkrt_ray *rays, size_t count, const vkrt_gpu_node *box, size_t room, vkrt_ray *out_rays,
                        uint32_t *out_index, vkrt_hit *out_hits, size_t *out_read)
{
    const vkrt_hit miss = cpu_trace_miss();
    size_t copied = 0, i = 0;
    for (; i < count; i += 4) {
        unsigned mask = 0;
        const size_t lanes = count - i < 4 ? count - i : 4;
        if (box && lanes == 4) {
            mask = ray_cull_test4(&rays[i], box);
        } else if (box) {
            /* The last rays, with zero rays (which must miss) in the lanes past the end. */
            vkrt_ray four[4] = { 0 };
            memcpy(four, &rays[i], lanes * sizeof *rays);
            mask = ray_cull_test4(four, box);
        }
        for (size_t l = 0; l < lanes; l++) {
            if (!(mask >> l & 1u)) {
                out_hits[i + l] = miss;
                continue;
            }
            if (copied == room) {
                *out_read = i + l;
                return copied;
            }
            out_rays[copied] = rays[i + l];
            out_index[copied++] = (uint32_t)(i + l);
        }
    }
    *out_read = count;
    return copied;
}
