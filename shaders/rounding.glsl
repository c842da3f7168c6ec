/* Correctly rounded float division and square root, for the arithmetic the GPU must do exactly
 * as the CPU backend's C does it (ray generation and setup, the triangle tests, normals).
 *
 * Why: Vulkan requires +, - and * to round correctly, but lets a device's division be 2.5 ulps
 * off and its square root more (the precision table of the SPIR-V environment appendix). C's
 * are correctly rounded. lavapipe's are too, so on it the shaders use the operators as they
 * are; on an NVIDIA H200 (driver 580) the images of the stacked-leaf, uv, albedo and
 * alpha-tested cases differed from the CPU's on up to a fifth of their pixels by an ulp of u, v
 * or the ray, which decides which of two nearly coincident triangles is hit.
 *
 * How: with VKRT_EXACT_ROUNDING (vk_pipeline.c defines it on a device with shaderFloat64 whose
 * driver is not lavapipe), the device's double quotient or root rounded to float is within one
 * float ulp of the right answer; the right one is then chosen between it and its neighbour by
 * comparing the operand with the midpoint between them, which double holds exactly (a float
 * midpoint has 25 significant bits: a midpoint times a float 49, a midpoint squared 50, both
 * under double's 53). Only double +, * and comparisons and the conversion to float are relied
 * on, which Vulkan requires to be exact or correctly rounded. Results outside the normal float range
 * (and zero, infinite or NaN operands) are settled by the rules of IEEE 754 directly or left to
 * the double result, exact in all but a vanishing share of cases there. Without
 * VKRT_EXACT_ROUNDING, div_rn and sqrt_rn are the operators themselves. */
#ifndef VKRT_ROUNDING_GLSL
#define VKRT_ROUNDING_GLSL

#if defined(VKRT_EXACT_ROUNDING) && defined(VKRT_HAS_FLOAT64)

const float ROUNDING_MIN_NORMAL = 1.17549435e-38; /* 2^-126 */
const float ROUNDING_MAX_NORMAL = 1.70141183e+38; /* 2^127: its upper neighbour is finite */

const double ROUNDING_DENORMAL_ULP = 1.4012984643248171e-45LF; /* 2^-149, exact in double */

/* The value of a float that is not negative, denormals included, as a double. A device may flush
 * float denormals to zero wherever they are an operand, conversions and comparisons included
 * (NVIDIA's driver 580 on an H100 compared a guess an ulp below 2^-126 as zero), but not in a
 * bit cast: a denormal's bits are its value in units of 2^-149. */
double value_of(float x)
{
    uint bits = floatBitsToUint(x);
    return bits < 0x00800000u ? double(bits) * ROUNDING_DENORMAL_ULP : double(x);
}

/* The nearest float to a / b (a, b positive and finite) given q, a float at most one ulp from
 * it: q or the neighbour on the side of the midpoint that a / b lies beyond. A quotient of
 * floats is never exactly a midpoint in the normal range, so there are no ties. */
float round_quotient(float a, float b, float q)
{
    /* A guess may be a denormal below 2^-126: the midpoints of denormals are exact too. Its
     * range is tested on its bits (positive, not zero, at most 2^127), its value taken by
     * value_of, so that a device that flushes denormals still corrects it. */
    uint bits = floatBitsToUint(q);
    if (bits == 0u || bits > floatBitsToUint(ROUNDING_MAX_NORMAL)) return q;
    float up = uintBitsToFloat(bits + 1u), down = uintBitsToFloat(bits - 1u);
    precise double da = double(a), db = double(b);
    precise double at_up = ((value_of(q) + value_of(up)) * 0.5LF) * db;
    precise double at_down = ((value_of(q) + value_of(down)) * 0.5LF) * db;
    return da > at_up ? up : (da < at_down ? down : q);
}

/* The nearest float to sqrt(x) (x positive and finite) given s, a float at most one ulp from
 * it. No ties either: a midpoint squared has a lower set bit than any float. */
float round_root(float x, float s)
{
    if (!(s >= ROUNDING_MIN_NORMAL && s <= ROUNDING_MAX_NORMAL)) return s;
    uint bits = floatBitsToUint(s);
    float up = uintBitsToFloat(bits + 1u), down = uintBitsToFloat(bits - 1u);
    precise double mid_up = (double(s) + double(up)) * 0.5LF;
    precise double mid_down = (double(s) + double(down)) * 0.5LF;
    precise double dx = double(x);
    return dx > mid_up * mid_up ? up : (dx < mid_down * mid_down ? down : s);
}

float div_rn(float a, float b)
{
    uint sign = (floatBitsToUint(a) ^ floatBitsToUint(b)) & 0x80000000u;
    float x = abs(a), y = abs(b);
    if (isnan(a) || isnan(b) || (x == 0.0 && y == 0.0) || (isinf(x) && isinf(y)))
        return uintBitsToFloat(0x7FC00000u);
    if (isinf(x) || y == 0.0) return uintBitsToFloat(sign | 0x7F800000u);
    if (x == 0.0 || isinf(y)) return uintBitsToFloat(sign);
    return uintBitsToFloat(sign | floatBitsToUint(round_quotient(x, y, float(double(x) / double(y)))));
}

float sqrt_rn(float x)
{
    if (!(x > 0.0) || isinf(x)) return x < 0.0 ? uintBitsToFloat(0x7FC00000u) : x; /* -0, 0, NaN, inf */
    return round_root(x, float(sqrt(double(x))));
}

#else

float div_rn(float a, float b)
{
    precise float q = a / b;
    return q;
}

float sqrt_rn(float x)
{
    return sqrt(x);
}

#endif

vec3 div_rn(vec3 a, vec3 b)
{
    return vec3(div_rn(a.x, b.x), div_rn(a.y, b.y), div_rn(a.z, b.z));
}

#endif
