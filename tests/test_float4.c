/* Every operation of src/float4.h against the scalar expression it is defined as, lane for
 * lane and bit for bit, on hostile floats (+-0, +-inf, NaN, denormals, the extremes). The
 * build compiles this file twice: as the library is (SSE2 on x86-64) and with
 * VKRT_FLOAT4_PORTABLE (the plain-C twin), so both implementations are held to the same
 * expressions and therefore give the BVH builder and the CPU tracer the same bits. */
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "check.h"
#include "float4.h"

static const float values[] = { 0.0f, -0.0f, 1.0f, -1.0f, 0.5f, -3.25f, 1e-40f, -1e-40f, FLT_MIN, FLT_MAX, -FLT_MAX,
                                INFINITY, -INFINITY, NAN, 7e-8f, 3e38f };
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

static void check_binary(const char *name, float4 (*op)(float4, float4), float (*expect)(float, float))
{
    int wrong = 0;
    for (int i = 0; i < VALUES; i++)
        for (int j = 0; j < VALUES; j++) {
            float4 a = quad(i, j), b = quad(j, i);
            float x[4], y[4], r[4];
            lanes(a, x), lanes(b, y), lanes(op(a, b), r);
            for (int l = 0; l < 4; l++)
                if (!same(r[l], expect(x[l], y[l])) && wrong++ < 3)
                    fprintf(stderr, "  %s(%a, %a) = %a, not %a\n", name, x[l], y[l], r[l], expect(x[l], y[l]));
        }
    CHECK_MSG(wrong == 0, "%s: %d lanes differ from the scalar expression", name, wrong);
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
        float4 (*op)(float4, float4);
        float (*expect)(float, float);
    } ops[] = {
        { "f4_add", f4_add, e_add }, { "f4_sub", f4_sub, e_sub }, { "f4_mul", f4_mul, e_mul },
        { "f4_div", f4_div, e_div }, { "f4_min", f4_min, e_min }, { "f4_max", f4_max, e_max },
        { "f4_lt", f4_lt, e_lt },    { "f4_le", f4_le, e_le },    { "f4_gt", f4_gt, e_gt },
        { "f4_ge", f4_ge, e_ge },    { "f4_eq", f4_eq, e_eq },    { "f4_and", f4_and, e_and },
        { "f4_or", f4_or, e_or },    { "f4_andnot", f4_andnot, e_andnot },
    };
    for (size_t i = 0; i < sizeof ops / sizeof ops[0]; i++) check_binary(ops[i].name, ops[i].op, ops[i].expect);
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

int main(void)
{
#if defined(__SSE2__) && !defined(VKRT_FLOAT4_PORTABLE)
    fprintf(stderr, "float4.h: the SSE2 implementation\n");
#else
    fprintf(stderr, "float4.h: the plain-C implementation\n");
#endif
    RUN(arithmetic_comparisons_and_bit_operations_are_their_expressions);
    RUN(masks_selects_and_lane_operations_are_their_expressions);
    return check_exit();
}
