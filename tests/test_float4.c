/* Every operation of src/float4.h and src/float8.h against the scalar expression it is defined
 * as, lane for lane and bit for bit, on hostile floats (+-0, +-inf, NaN, denormals, the
 * extremes). The build compiles this file as the library is (SSE2 on x86-64; float8 two
 * halves), with VKRT_FLOAT4_PORTABLE (the plain-C twin) and, where the compiler and this
 * machine have it, for x86-64-v3 as the CPU tracer's second build is (float8 one AVX
 * register), so every implementation is held to the same expressions and therefore gives the
 * BVH builder and both builds of the CPU tracer the same bits. */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "check.h"
#include "float4.h"
#include "float8.h"

static const float values[] = { 0.0f, -0.0f, 1.0f, -1.0f, 0.5f, -3.25f, 1e-40f, -1e-40f, FLT_MIN, FLT_MAX, -FLT_MAX,
                                INFINITY, -INFINITY, NAN, 7e-8f, 3e38f, 1.75f };
enum { VALUES = sizeof values / sizeof values[0] };

static uint32_t bits_of(float x)
{
    uint32_t u;
    memcpy(&u, &x, sizeof u);
    return u;
}

static float float_of(uint32_t u)
{
    float x;
    memcpy(&x, &u, sizeof x);
    return x;
}

/* The same bits; any NaN matches any NaN (no scalar expression promises a NaN's payload). */
static bool same(float a, float b) { return bits_of(a) == bits_of(b) || (isnan(a) && isnan(b)); }

static float mask_of(bool c) { return float_of(c ? 0xFFFFFFFFu : 0u); }

static void lanes(float4 a, float out[4]) { f4_store(out, a); }

/* Four-lane inputs that walk the table so every pair of values meets in some lane. */
static float4 quad(int i, int j) { return f4_set(values[i], values[j], values[(i + j) % VALUES], values[(i * 7 + j) % VALUES]); }

/* Eight lanes: quad(i, j) and four more pairings. */
static float8 oct(int i, int j)
{
    return f8_join(quad(i, j), f4_set(values[(i * 3 + j) % VALUES], values[(i + j * 5) % VALUES],
                                      values[(i * 11 + j * 2) % VALUES], values[(i + 9) % VALUES]));
}

typedef float (*scalar_op)(float, float);

/* Lanes of r against expect(x, y), lane for lane; the number that differ. */
static int count_wrong(const char *name, int n, const float *x, const float *y, const float *r, scalar_op expect)
{
    int wrong = 0;
    for (int l = 0; l < n; l++)
        if (!same(r[l], expect(x[l], y[l])) && wrong++ < 3)
            fprintf(stderr, "  %s(%a, %a) = %a, not %a\n", name, x[l], y[l], r[l], expect(x[l], y[l]));
    return wrong;
}

/* op4 on four lanes and op8 on eight, each against expect on every pair of the table. */
static void check_binary(const char *name, float4 (*op4)(float4, float4), float8 (*op8)(float8, float8),
                         scalar_op expect)
{
    int wrong4 = 0, wrong8 = 0;
    for (int i = 0; i < VALUES; i++)
        for (int j = 0; j < VALUES; j++) {
            float4 a = quad(i, j), b = quad(j, i);
            float x[8], y[8], r[8];
            lanes(a, x), lanes(b, y), lanes(op4(a, b), r);
            wrong4 += count_wrong(name, 4, x, y, r, expect);
            float8 a8 = oct(i, j), b8 = oct(j, i);
            f8_store(x, a8), f8_store(y, b8), f8_store(r, op8(a8, b8));
            wrong8 += count_wrong(name, 8, x, y, r, expect);
        }
    CHECK_MSG(wrong4 == 0 && wrong8 == 0, "%s: %d of four lanes and %d of eight differ from the scalar expression", name,
              wrong4, wrong8);
}

static float e_add(float a, float b) { return a + b; }
static float e_sub(float a, float b) { return a - b; }
static float e_mul(float a, float b) { return a * b; }
static float e_div(float a, float b) { return a / b; }
static float e_min(float a, float b) { return a < b ? a : b; }
static float e_max(float a, float b) { return a > b ? a : b; }
static float e_lt(float a, float b) { return mask_of(a < b); }
static float e_le(float a, float b) { return mask_of(a <= b); }
static float e_gt(float a, float b) { return mask_of(a > b); }
static float e_ge(float a, float b) { return mask_of(a >= b); }
static float e_eq(float a, float b) { return mask_of(a == b); }
static float e_and(float a, float b) { return float_of(bits_of(a) & bits_of(b)); }
static float e_or(float a, float b) { return float_of(bits_of(a) | bits_of(b)); }
static float e_andnot(float a, float b) { return float_of(~bits_of(a) & bits_of(b)); }

static void arithmetic_comparisons_and_bit_operations_are_their_expressions(void)
{
    static const struct {
        const char *name;
        float4 (*op4)(float4, float4);
        float8 (*op8)(float8, float8);
        scalar_op expect;
    } ops[] = {
        { "add", f4_add, f8_add, e_add }, { "sub", f4_sub, f8_sub, e_sub },          { "mul", f4_mul, f8_mul, e_mul },
        { "div", f4_div, f8_div, e_div }, { "min", f4_min, f8_min, e_min },          { "max", f4_max, f8_max, e_max },
        { "lt", f4_lt, f8_lt, e_lt },     { "le", f4_le, f8_le, e_le },              { "gt", f4_gt, f8_gt, e_gt },
        { "ge", f4_ge, f8_ge, e_ge },     { "eq", f4_eq, f8_eq, e_eq },              { "and", f4_and, f8_and, e_and },
        { "or", f4_or, f8_or, e_or },     { "andnot", f4_andnot, f8_andnot, e_andnot },
    };
    for (size_t i = 0; i < sizeof ops / sizeof ops[0]; i++) check_binary(ops[i].name, ops[i].op4, ops[i].op8, ops[i].expect);
}

static void masks_selects_and_lane_operations_are_their_expressions(void)
{
    for (unsigned bits = 0; bits < 16; bits++) {
        float m[4];
        lanes(f4_mask(bits), m);
        for (int l = 0; l < 4; l++) CHECK(bits_of(m[l]) == ((bits >> l) & 1u ? 0xFFFFFFFFu : 0u));
        CHECK_EQ_U64(f4_bits(f4_mask(bits)), bits);
        for (int i = 0; i < VALUES; i++) {
            float4 a = quad(i, 3), b = quad(5, i);
            float x[4], y[4], r[4];
            lanes(a, x), lanes(b, y), lanes(f4_select(f4_mask(bits), a, b), r);
            for (int l = 0; l < 4; l++) CHECK(bits_of(r[l]) == bits_of((bits >> l) & 1u ? x[l] : y[l]));
        }
        const uint32_t words[4] = { bits & 1u ? 7u : 0xFFFFFFFFu, bits & 2u ? 7u : 1u, bits & 4u ? 7u : 8u,
                                    bits & 8u ? 7u : 0x80000007u };
        CHECK_EQ_U64(f4_equal_u32(words, 7u), bits);
    }
    for (int i = 0; i < VALUES; i++)
        for (int j = 0; j < VALUES; j++) {
            float4 a = quad(i, j);
            float x[4], r[4];
            lanes(a, x), lanes(f4_abs(a), r);
            for (int l = 0; l < 4; l++) CHECK(bits_of(r[l]) == (bits_of(x[l]) & 0x7FFFFFFFu));
            /* f4_trunc within its domain (|x| < 2^31): toward zero, as a float. */
            lanes(f4_trunc(a), r);
            for (int l = 0; l < 4; l++)
                if (fabsf(x[l]) < 0x1p31f) CHECK_MSG(same(r[l], (float)(int32_t)x[l]), "f4_trunc(%a)", x[l]);
            /* f4_min(f4_min(x, z), f4_min(y, w)), the order deciding which zero is returned. */
            float xz = e_min(x[0], x[2]), yw = e_min(x[1], x[3]);
            CHECK_MSG(same(f4_min_lane(a), e_min(xz, yw)), "f4_min_lane(%a %a %a %a)", x[0], x[1], x[2], x[3]);
            float s[4];
            lanes(f4_set1(values[i]), s);
            for (int l = 0; l < 4; l++) CHECK(same(s[l], values[i]));
        }
    float4 rows[4];
    for (int r = 0; r < 4; r++) rows[r] = f4_set(values[r * 4], values[r * 4 + 1], values[r * 4 + 2], values[r * 4 + 3]);
    f4_transpose(rows);
    for (int r = 0; r < 4; r++) {
        float got[4];
        lanes(rows[r], got);
        for (int c = 0; c < 4; c++) CHECK(same(got[c], values[c * 4 + r]));
    }
}

/* float8's masks, selects and lane operations, as float4's above. */
static void eight_lane_masks_selects_and_lane_operations_are_their_expressions(void)
{
    for (unsigned bits = 0; bits < 256; bits++) {
        float m[8];
        f8_store(m, f8_mask(bits));
        for (int l = 0; l < 8; l++) CHECK(bits_of(m[l]) == ((bits >> l) & 1u ? 0xFFFFFFFFu : 0u));
        CHECK_EQ_U64(f8_bits(f8_mask(bits)), bits);
        for (int i = 0; i < VALUES; i++) {
            float8 a = oct(i, 3), b = oct(5, i);
            float x[8], y[8], r[8];
            f8_store(x, a), f8_store(y, b), f8_store(r, f8_select(f8_mask(bits), a, b));
            for (int l = 0; l < 8; l++) CHECK(bits_of(r[l]) == bits_of((bits >> l) & 1u ? x[l] : y[l]));
        }
    }
    for (int i = 0; i < VALUES; i++)
        for (int j = 0; j < VALUES; j++) {
            float8 a = oct(i, j);
            float x[8], r[8];
            f8_store(x, a), f8_store(r, f8_abs(a));
            for (int l = 0; l < 8; l++) CHECK(bits_of(r[l]) == (bits_of(x[l]) & 0x7FFFFFFFu));
            /* Each half's f4_min_lane, then the lesser of the two. */
            float lo = e_min(e_min(x[0], x[2]), e_min(x[1], x[3])), hi = e_min(e_min(x[4], x[6]), e_min(x[5], x[7]));
            CHECK_MSG(same(f8_min_lane(a), e_min(lo, hi)), "f8_min_lane(%a %a %a %a %a %a %a %a)", x[0], x[1], x[2], x[3],
                      x[4], x[5], x[6], x[7]);
            f8_store(r, f8_set(x[7], x[6], x[5], x[4], x[3], x[2], x[1], x[0]));
            for (int l = 0; l < 8; l++) CHECK(same(r[l], x[7 - l]));
            f8_store(r, f8_join(f4_set(x[4], x[5], x[6], x[7]), f4_set(x[0], x[1], x[2], x[3])));
            for (int l = 0; l < 8; l++) CHECK(same(r[l], x[(l + 4) % 8]));
            f8_store(r, f8_set1(values[i]));
            for (int l = 0; l < 8; l++) CHECK(same(r[l], values[i]));
            f8_store(r, f8_load(x));
            for (int l = 0; l < 8; l++) CHECK(same(r[l], x[l]));
            /* f8_trunc and f8_truncate within their domain (|x| < 2^31): toward zero, as a float
             * and as an int32. */
            int32_t whole[8];
            f8_store(r, f8_trunc(a));
            f8_truncate(a, whole);
            for (int l = 0; l < 8; l++)
                if (fabsf(x[l]) < 0x1p31f) {
                    CHECK_MSG(same(r[l], (float)(int32_t)x[l]), "f8_trunc(%a)", x[l]);
                    CHECK_MSG(whole[l] == (int32_t)x[l], "f8_truncate(%a)", x[l]);
                }
        }
}

int main(void)
{
#if defined(__SSE2__) && !defined(VKRT_FLOAT4_PORTABLE)
    fprintf(stderr, "float4.h: the SSE2 implementation\n");
#else
    fprintf(stderr, "float4.h: the plain-C implementation\n");
#endif
#if defined(__AVX2__) && !defined(VKRT_FLOAT4_PORTABLE)
    fprintf(stderr, "float8.h: the AVX implementation\n");
#else
    fprintf(stderr, "float8.h: two float4 halves\n");
#endif
    RUN(arithmetic_comparisons_and_bit_operations_are_their_expressions);
    RUN(masks_selects_and_lane_operations_are_their_expressions);
    RUN(eight_lane_masks_selects_and_lane_operations_are_their_expressions);
    return check_exit();
}
