/* Eight float lanes for the CPU tracer's packets (cpu_trace_packet8.h) and the binned lists'
 * triangles (ray_bin.c): one AVX register where the file is compiled for AVX2 (the x86-64-v3
 * builds of src/cpu_trace.c and src/ray_bin.c), else two float4
 * halves (SSE2, or float4.h's plain-C twin). Every operation is float4.h's, lane for lane, so
 * both forms give the same bits and the two builds of the tracer the same hits
 * (tests/test_float4.c holds each form to the scalar expressions). */
#ifndef VKRT_FLOAT8_H
#define VKRT_FLOAT8_H

#include "float4.h"

#if defined(__AVX2__) && !defined(VKRT_FLOAT4_PORTABLE)
#include <immintrin.h>

typedef __m256 float8;

static inline float8 f8_set(float a, float b, float c, float d, float e, float f, float g, float h)
{
    return _mm256_setr_ps(a, b, c, d, e, f, g, h);
}
static inline float8 f8_join(float4 lo, float4 hi) { return _mm256_set_m128(hi, lo); }
static inline float8 f8_load(const float *p) { return _mm256_loadu_ps(p); }
/* As f4_truncate and f4_trunc: each lane toward zero, as int32 (0x80000000 outside their range)
 * and as a float (lanes within +-2^31 only). */
static inline void f8_truncate(float8 a, int32_t *out) { _mm256_storeu_si256((__m256i *)(void *)out, _mm256_cvttps_epi32(a)); }
static inline float8 f8_trunc(float8 a) { return _mm256_cvtepi32_ps(_mm256_cvttps_epi32(a)); }
static inline void f8_store(float *p, float8 a) { _mm256_storeu_ps(p, a); }
static inline float8 f8_set1(float x) { return _mm256_set1_ps(x); }

#define F8_BINARY(name, intrinsic) \
    static inline float8 name(float8 a, float8 b) { return intrinsic(a, b); }
F8_BINARY(f8_add, _mm256_add_ps)
F8_BINARY(f8_sub, _mm256_sub_ps)
F8_BINARY(f8_mul, _mm256_mul_ps)
F8_BINARY(f8_div, _mm256_div_ps)
/* As _mm_min_ps and _mm_max_ps: b where either is NaN or both are zeros. */
F8_BINARY(f8_min, _mm256_min_ps)
F8_BINARY(f8_max, _mm256_max_ps)
F8_BINARY(f8_and, _mm256_and_ps)
F8_BINARY(f8_or, _mm256_or_ps)
F8_BINARY(f8_andnot, _mm256_andnot_ps)
#undef F8_BINARY

/* The predicates of _mm_cmplt_ps, _mm_cmple_ps, _mm_cmpgt_ps, _mm_cmpge_ps and _mm_cmpeq_ps. */
#define F8_COMPARE(name, predicate) \
    static inline float8 name(float8 a, float8 b) { return _mm256_cmp_ps(a, b, predicate); }
F8_COMPARE(f8_lt, _CMP_LT_OS)
F8_COMPARE(f8_le, _CMP_LE_OS)
F8_COMPARE(f8_gt, _CMP_GT_OS)
F8_COMPARE(f8_ge, _CMP_GE_OS)
F8_COMPARE(f8_eq, _CMP_EQ_OQ)
#undef F8_COMPARE

/* a where mask (all ones or all zeros a lane), else b: f4_select's and/or, not a blend, so a
 * lane that is neither gives the same bits in both forms. */
static inline float8 f8_select(float8 mask, float8 a, float8 b)
{
    return _mm256_or_ps(_mm256_and_ps(mask, a), _mm256_andnot_ps(mask, b));
}
static inline float8 f8_abs(float8 a) { return _mm256_andnot_ps(_mm256_set1_ps(-0.0f), a); }
static inline unsigned f8_bits(float8 mask) { return (unsigned)_mm256_movemask_ps(mask); }
static inline float8 f8_mask(unsigned bits)
{
    const __m256i lane = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
    return _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32((int)bits), lane), lane));
}
/* The halves' f4_min_lane, then the lesser: the same order of minima as the two-half form. */
static inline float f8_min_lane(float8 a)
{
    const float lo = f4_min_lane(_mm256_castps256_ps128(a)), hi = f4_min_lane(_mm256_extractf128_ps(a, 1));
    return _mm_cvtss_f32(_mm_min_ss(_mm_set_ss(lo), _mm_set_ss(hi)));
}

#else

typedef struct float8 {
    float4 lo, hi; /* lanes 0-3 and 4-7 */
} float8;

static inline float8 f8_set(float a, float b, float c, float d, float e, float f, float g, float h)
{
    return (float8){ f4_set(a, b, c, d), f4_set(e, f, g, h) };
}
static inline float8 f8_join(float4 lo, float4 hi) { return (float8){ lo, hi }; }
static inline float8 f8_load(const float *p) { return (float8){ f4_load(p), f4_load(p + 4) }; }
static inline void f8_truncate(float8 a, int32_t *out)
{
    f4_truncate(a.lo, out);
    f4_truncate(a.hi, out + 4);
}
static inline float8 f8_trunc(float8 a) { return (float8){ f4_trunc(a.lo), f4_trunc(a.hi) }; }
static inline void f8_store(float *p, float8 a)
{
    f4_store(p, a.lo);
    f4_store(p + 4, a.hi);
}
static inline float8 f8_set1(float x) { return (float8){ f4_set1(x), f4_set1(x) }; }

/* name on each half with float4's operation. */
#define F8_HALVES(name, f4_op) \
    static inline float8 name(float8 a, float8 b) { return (float8){ f4_op(a.lo, b.lo), f4_op(a.hi, b.hi) }; }
F8_HALVES(f8_add, f4_add)
F8_HALVES(f8_sub, f4_sub)
F8_HALVES(f8_mul, f4_mul)
F8_HALVES(f8_div, f4_div)
F8_HALVES(f8_min, f4_min)
F8_HALVES(f8_max, f4_max)
F8_HALVES(f8_and, f4_and)
F8_HALVES(f8_or, f4_or)
F8_HALVES(f8_andnot, f4_andnot)
F8_HALVES(f8_lt, f4_lt)
F8_HALVES(f8_le, f4_le)
F8_HALVES(f8_gt, f4_gt)
F8_HALVES(f8_ge, f4_ge)
F8_HALVES(f8_eq, f4_eq)
#undef F8_HALVES

static inline float8 f8_select(float8 mask, float8 a, float8 b)
{
    return (float8){ f4_select(mask.lo, a.lo, b.lo), f4_select(mask.hi, a.hi, b.hi) };
}
static inline float8 f8_abs(float8 a) { return (float8){ f4_abs(a.lo), f4_abs(a.hi) }; }
static inline unsigned f8_bits(float8 mask) { return f4_bits(mask.lo) | f4_bits(mask.hi) << 4; }
static inline float8 f8_mask(unsigned bits) { return (float8){ f4_mask(bits & 0xFu), f4_mask(bits >> 4 & 0xFu) }; }
static inline float f8_min_lane(float8 a)
{
    const float lo = f4_min_lane(a.lo), hi = f4_min_lane(a.hi);
    return f4_x(f4_min(f4_set1(lo), f4_set1(hi)));
}

#endif

#endif
