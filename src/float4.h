/* Four-lane float arithmetic for the inner loops of the BVH builder and the CPU tracer's
 * four-box, four-triangle and packet tests: SSE2 where the compiler targets it (every x86-64
 * compiler does) and VKRT_FLOAT4_PORTABLE is not defined, plain C otherwise. Each operation is
 * defined as the scalar expression it replaces, lane for lane, and SSE2 rounds each lane
 * exactly like that expression, so both implementations give the same bits, the same BVH and
 * the same hits (tests/test_float4.c holds both to those expressions). A mask is a float4
 * whose lanes are all ones (true) or all zeros (false), as SSE2 comparisons make them. The
 * compiler does not vectorise these loops by itself at -O2: the box updates go through memory
 * that may alias. The layout follows meshoptimizer src/vertexcodec.cpp (an SSE path chosen by
 * the compiler's target, a portable path beside it). */
#ifndef VKRT_FLOAT4_H
#define VKRT_FLOAT4_H

#include <stdint.h>

#if defined(__SSE2__) && !defined(VKRT_FLOAT4_PORTABLE)
#include <emmintrin.h>

typedef __m128 float4;

static inline float4 f4_load(const float *p) { return _mm_loadu_ps(p); }
static inline void f4_store(float *p, float4 a) { _mm_storeu_ps(p, a); }
static inline float4 f4_set(float x, float y, float z, float w) { return _mm_setr_ps(x, y, z, w); }
static inline float4 f4_add(float4 a, float4 b) { return _mm_add_ps(a, b); }
static inline float4 f4_sub(float4 a, float4 b) { return _mm_sub_ps(a, b); }
static inline float4 f4_mul(float4 a, float4 b) { return _mm_mul_ps(a, b); }
/* a < b ? a : b and a > b ? a : b per lane: MINPS and MAXPS return the second operand for
 * NaN and for equal values, as the conditional expression does. */
static inline float4 f4_min(float4 a, float4 b) { return _mm_min_ps(a, b); }
static inline float4 f4_max(float4 a, float4 b) { return _mm_max_ps(a, b); }
/* Lanes 0-2 of a, lane 3 zero. */
static inline float4 f4_xyz(float4 a)
{
    return _mm_and_ps(a, _mm_castsi128_ps(_mm_setr_epi32(-1, -1, -1, 0)));
}
/* (int32_t)a per lane; a must be in int32_t range (and not NaN). */
static inline void f4_truncate(float4 a, int32_t *out) { _mm_storeu_si128((__m128i *)(void *)out, _mm_cvttps_epi32(a)); }
/* Each lane rounded toward zero, as a float; lanes within +-2^31 only. */
static inline float4 f4_trunc(float4 a) { return _mm_cvtepi32_ps(_mm_cvttps_epi32(a)); }
/* Lanes (y, z, x, w) of a. */
static inline float4 f4_yzxw(float4 a) { return _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 0, 2, 1)); }
static inline float f4_x(float4 a) { return _mm_cvtss_f32(a); }
static inline float f4_y(float4 a) { return _mm_cvtss_f32(_mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 1, 1, 1))); }
static inline float f4_z(float4 a) { return _mm_cvtss_f32(_mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 2, 2, 2))); }
static inline float4 f4_set1(float x) { return _mm_set1_ps(x); }
static inline float4 f4_div(float4 a, float4 b) { return _mm_div_ps(a, b); }
/* Masks of a < b, a <= b, a > b, a >= b, a == b (false where either is NaN). */
static inline float4 f4_lt(float4 a, float4 b) { return _mm_cmplt_ps(a, b); }
static inline float4 f4_le(float4 a, float4 b) { return _mm_cmple_ps(a, b); }
static inline float4 f4_gt(float4 a, float4 b) { return _mm_cmpgt_ps(a, b); }
static inline float4 f4_ge(float4 a, float4 b) { return _mm_cmpge_ps(a, b); }
static inline float4 f4_eq(float4 a, float4 b) { return _mm_cmpeq_ps(a, b); }
/* Bitwise a & b, a | b and ~a & b. */
static inline float4 f4_and(float4 a, float4 b) { return _mm_and_ps(a, b); }
static inline float4 f4_or(float4 a, float4 b) { return _mm_or_ps(a, b); }
static inline float4 f4_andnot(float4 a, float4 b) { return _mm_andnot_ps(a, b); }
/* mask ? a : b per lane, as (mask & a) | (~mask & b). */
static inline float4 f4_select(float4 mask, float4 a, float4 b) { return _mm_or_ps(_mm_and_ps(mask, a), _mm_andnot_ps(mask, b)); }
/* |a| per lane: the sign bit cleared. */
static inline float4 f4_abs(float4 a) { return _mm_andnot_ps(_mm_set1_ps(-0.0f), a); }
/* Bit l set where lane l's sign bit is (every true lane of a mask). */
static inline unsigned f4_bits(float4 mask) { return (unsigned)_mm_movemask_ps(mask); }
/* The mask whose lane l is bit l of bits. */
static inline float4 f4_mask(unsigned bits)
{
    return _mm_castsi128_ps(_mm_set_epi32(bits & 8u ? -1 : 0, bits & 4u ? -1 : 0, bits & 2u ? -1 : 0, bits & 1u ? -1 : 0));
}
/* Bit l set where p[l] == v. */
static inline unsigned f4_equal_u32(const uint32_t *p, uint32_t v)
{
    __m128i eq = _mm_cmpeq_epi32(_mm_loadu_si128((const __m128i *)(const void *)p), _mm_set1_epi32((int)v));
    return (unsigned)_mm_movemask_ps(_mm_castsi128_ps(eq));
}
/* Rows to columns: r[i] lane j becomes r[j] lane i. */
static inline void f4_transpose(float4 r[4]) { _MM_TRANSPOSE4_PS(r[0], r[1], r[2], r[3]); }
/* The lanes' minimum as f4_min(f4_min(x, z), f4_min(y, w)) gives it. */
static inline float f4_min_lane(float4 a)
{
    a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 0, 3, 2)));
    a = _mm_min_ps(a, _mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 3, 0, 1)));
    return _mm_cvtss_f32(a);
}

#else

#include <string.h>

typedef struct float4 {
    float v[4];
} float4;

static inline float4 f4_load(const float *p) { return (float4){ { p[0], p[1], p[2], p[3] } }; }
static inline void f4_store(float *p, float4 a)
{
    for (int k = 0; k < 4; k++) p[k] = a.v[k];
}
static inline float4 f4_set(float x, float y, float z, float w) { return (float4){ { x, y, z, w } }; }
static inline float4 f4_add(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] += b.v[k];
    return a;
}
static inline float4 f4_sub(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] -= b.v[k];
    return a;
}
static inline float4 f4_mul(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] *= b.v[k];
    return a;
}
static inline float4 f4_min(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = a.v[k] < b.v[k] ? a.v[k] : b.v[k];
    return a;
}
static inline float4 f4_max(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = a.v[k] > b.v[k] ? a.v[k] : b.v[k];
    return a;
}
static inline float4 f4_xyz(float4 a)
{
    a.v[3] = 0.0f;
    return a;
}
static inline void f4_truncate(float4 a, int32_t *out)
{
    for (int k = 0; k < 4; k++) out[k] = (int32_t)a.v[k];
}
static inline float4 f4_trunc(float4 a)
{
    for (int k = 0; k < 4; k++) a.v[k] = (float)(int32_t)a.v[k];
    return a;
}
static inline float4 f4_yzxw(float4 a) { return (float4){ { a.v[1], a.v[2], a.v[0], a.v[3] } }; }
static inline float f4_x(float4 a) { return a.v[0]; }
static inline float f4_y(float4 a) { return a.v[1]; }
static inline float f4_z(float4 a) { return a.v[2]; }
static inline float4 f4_set1(float x) { return (float4){ { x, x, x, x } }; }
static inline float4 f4_div(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] /= b.v[k];
    return a;
}

static inline uint32_t f4_lane_bits(float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    return u;
}
static inline float f4_bits_lane(uint32_t u)
{
    float x;
    memcpy(&x, &u, sizeof x);
    return x;
}
static inline float f4_truth(int c) { return f4_bits_lane(c ? 0xFFFFFFFFu : 0u); }
static inline float4 f4_lt(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_truth(a.v[k] < b.v[k]);
    return a;
}
static inline float4 f4_le(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_truth(a.v[k] <= b.v[k]);
    return a;
}
static inline float4 f4_gt(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_truth(a.v[k] > b.v[k]);
    return a;
}
static inline float4 f4_ge(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_truth(a.v[k] >= b.v[k]);
    return a;
}
static inline float4 f4_eq(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_truth(a.v[k] == b.v[k]);
    return a;
}
static inline float4 f4_and(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_bits_lane(f4_lane_bits(a.v[k]) & f4_lane_bits(b.v[k]));
    return a;
}
static inline float4 f4_or(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_bits_lane(f4_lane_bits(a.v[k]) | f4_lane_bits(b.v[k]));
    return a;
}
static inline float4 f4_andnot(float4 a, float4 b)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_bits_lane(~f4_lane_bits(a.v[k]) & f4_lane_bits(b.v[k]));
    return a;
}
static inline float4 f4_select(float4 mask, float4 a, float4 b) { return f4_or(f4_and(mask, a), f4_andnot(mask, b)); }
static inline float4 f4_abs(float4 a)
{
    for (int k = 0; k < 4; k++) a.v[k] = f4_bits_lane(f4_lane_bits(a.v[k]) & 0x7FFFFFFFu);
    return a;
}
static inline unsigned f4_bits(float4 mask)
{
    unsigned bits = 0;
    for (int k = 0; k < 4; k++) bits |= (f4_lane_bits(mask.v[k]) >> 31) << k;
    return bits;
}
static inline float4 f4_mask(unsigned bits)
{
    float4 m;
    for (int k = 0; k < 4; k++) m.v[k] = f4_truth((bits >> k) & 1u);
    return m;
}
static inline unsigned f4_equal_u32(const uint32_t *p, uint32_t v)
{
    unsigned bits = 0;
    for (int k = 0; k < 4; k++) bits |= (unsigned)(p[k] == v) << k;
    return bits;
}
static inline void f4_transpose(float4 r[4])
{
    for (int i = 0; i < 4; i++)
        for (int j = i + 1; j < 4; j++) {
            float t = r[i].v[j];
            r[i].v[j] = r[j].v[i];
            r[j].v[i] = t;
        }
}
static inline float f4_min_lane(float4 a)
{
    float xz = a.v[0] < a.v[2] ? a.v[0] : a.v[2], yw = a.v[1] < a.v[3] ? a.v[1] : a.v[3];
    return xz < yw ? xz : yw;
}

#endif

#endif
