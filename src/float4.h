/* Four-lane float arithmetic for the inner loops of the BVH builder: SSE2 where the compiler
 * targets it (every x86-64 compiler does), plain C otherwise. Each operation is defined as the
 * scalar expression it replaces, lane for lane, and SSE2 rounds each lane exactly like that
 * expression, so both implementations give the same bits and the same BVH. The compiler does
 * not vectorise these loops by itself at -O2: the box updates go through memory that may alias.
 * The layout follows meshoptimizer src/vertexcodec.cpp (an SSE path chosen by the compiler's
 * target, a portable path beside it). */
#ifndef VKRT_FLOAT4_H
#define VKRT_FLOAT4_H

#include <stdint.h>

#if defined(__SSE2__)
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
/* Lanes (y, z, x, w) of a. */
static inline float4 f4_yzxw(float4 a) { return _mm_shuffle_ps(a, a, _MM_SHUFFLE(3, 0, 2, 1)); }
static inline float f4_x(float4 a) { return _mm_cvtss_f32(a); }
static inline float f4_y(float4 a) { return _mm_cvtss_f32(_mm_shuffle_ps(a, a, _MM_SHUFFLE(1, 1, 1, 1))); }
static inline float f4_z(float4 a) { return _mm_cvtss_f32(_mm_shuffle_ps(a, a, _MM_SHUFFLE(2, 2, 2, 2))); }

#else

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
static inline float4 f4_yzxw(float4 a) { return (float4){ { a.v[1], a.v[2], a.v[0], a.v[3] } }; }
static inline float f4_x(float4 a) { return a.v[0]; }
static inline float f4_y(float4 a) { return a.v[1]; }
static inline float f4_z(float4 a) { return a.v[2]; }

#endif

#endif
