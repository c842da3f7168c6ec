/* Texture encoding and sampling. Texels are linear RGBA in half floats: 8 bytes a texel, exact
 * to decode on both sides (GLSL unpackHalf2x16), and enough precision for 8-bit sRGB sources
 * (the smallest non-zero linear value, 1/255/12.92, is a normal half). */
#include "texture.h"

#include <math.h>
#include <string.h>

uint16_t half_from_float(float f)
{
    uint32_t x;
    memcpy(&x, &f, sizeof x);
    uint32_t sign = (x >> 16) & 0x8000u;
    uint32_t abs = x & 0x7FFFFFFFu;
    if (abs >= 0x7F800000u) return (uint16_t)(sign | 0x7C00u | (abs > 0x7F800000u ? 0x200u : 0u)); /* inf, NaN */
    if (abs >= 0x477FF000u) return (uint16_t)(sign | 0x7C00u); /* rounds past 65504: infinity */
    if (abs < 0x38800000u) {                                    /* below 2^-14: a subnormal half, or 0 */
        if (abs < 0x33000000u) return (uint16_t)sign;            /* below half the smallest subnormal */
        uint32_t mant = (abs & 0x7FFFFFu) | 0x800000u;
        uint32_t shift = 113u - (abs >> 23) + 13u;
        uint32_t h = mant >> shift;
        uint32_t rest = mant & ((1u << shift) - 1u), halfway = 1u << (shift - 1u);
        if (rest > halfway || (rest == halfway && (h & 1u))) h++;
        return (uint16_t)(sign | h);
    }
    uint32_t h = ((abs - 0x38000000u) >> 13);
    uint32_t rest = abs & 0x1FFFu;
    if (rest > 0x1000u || (rest == 0x1000u && (h & 1u))) h++;
    return (uint16_t)(sign | h);
}

float half_to_float(uint16_t h)
{
    uint32_t sign = (uint32_t)(h & 0x8000u) << 16, exp = (h >> 10) & 0x1Fu, mant = h & 0x3FFu, x;
    if (exp == 0) {
        float f = ldexpf((float)mant, -24); /* subnormal (or zero): exact */
        return sign ? -f : f;
    }
    if (exp == 31) x = sign | 0x7F800000u | (mant << 13);
    else x = sign | ((exp + 112u) << 23) | (mant << 13);
    float f;
    memcpy(&f, &x, sizeof f);
    return f;
}

/* IEC 61966-2-1, evaluated in double and rounded once. */
static float srgb_decode(uint8_t v)
{
    double c = v / 255.0;
    return (float)(c <= 0.04045 ? c / 12.92 : pow((c + 0.055) / 1.055, 2.4));
}

/* lut: the linear value of each 8-bit RGB level; alpha is always level / 255. */
static void encode(const uint8_t *rgba8, uint32_t width, uint32_t height, const float lut[256], uint32_t *texels)
{
    size_t n = (size_t)width * height;
    for (size_t i = 0; i < n; i++) {
        const uint8_t *p = rgba8 + 4 * i;
        uint16_t r = half_from_float(lut[p[0]]), g = half_from_float(lut[p[1]]), b = half_from_float(lut[p[2]]);
        uint16_t a = half_from_float((float)(p[3] / 255.0));
        texels[2 * i] = (uint32_t)r | (uint32_t)g << 16;
        texels[2 * i + 1] = (uint32_t)b | (uint32_t)a << 16;
    }
}

void texture_encode_rgba8(const uint8_t *rgba8, uint32_t width, uint32_t height, uint32_t *texels)
{
    float lut[256];
    for (int i = 0; i < 256; i++) lut[i] = srgb_decode((uint8_t)i);
    encode(rgba8, width, height, lut, texels);
}

void texture_encode_rgba8_linear(const uint8_t *rgba8, uint32_t width, uint32_t height, uint32_t *texels)
{
    float lut[256];
    for (int i = 0; i < 256; i++) lut[i] = (float)(i / 255.0); /* rounded once, as alpha */
    encode(rgba8, width, height, lut, texels);
}

/* A texture coordinate brought into one period of its wrap mode (mirrors wrap_coordinate in
 * the shader): repeat [0, 1), mirror [0, 2), clamp [-1, 2]; a huge or non-finite one is 0. */
static float wrap_coordinate(float u, uint32_t mode)
{
    if (!(fabsf(u) < 1e30f)) return 0.0f;
    if (mode == VKRT_GPU_WRAP_CLAMP) return u < -1.0f ? -1.0f : (u > 2.0f ? 2.0f : u);
    if (mode == VKRT_GPU_WRAP_MIRROR) return u - 2.0f * floorf(u * 0.5f);
    return u - floorf(u);
}

/* A texel index of one period (see wrap_coordinate: i in [-n - 1, 2n]) to [0, n). */
static int32_t wrap_index(int32_t i, int32_t n, uint32_t mode)
{
    if (mode == VKRT_GPU_WRAP_CLAMP) return i < 0 ? 0 : (i >= n ? n - 1 : i);
    if (mode == VKRT_GPU_WRAP_MIRROR) {
        int32_t k = i < 0 ? i + 2 * n : (i >= 2 * n ? i - 2 * n : i);
        return k < n ? k : 2 * n - 1 - k;
    }
    return i < 0 ? i + n : (i >= n ? i - n : i);
}

static void fetch(const vkrt_gpu_texture *t, const uint32_t *texels, int32_t x, int32_t y, float out[4])
{
    const uint32_t *p = texels + 2 * ((size_t)t->first + (size_t)y * t->width + (size_t)x);
    out[0] = half_to_float((uint16_t)(p[0] & 0xFFFFu));
    out[1] = half_to_float((uint16_t)(p[0] >> 16));
    out[2] = half_to_float((uint16_t)(p[1] & 0xFFFFu));
    out[3] = half_to_float((uint16_t)(p[1] >> 16));
}

void texture_sample(const vkrt_gpu_texture *t, const uint32_t *texels, float u, float v, float out[4])
{
    const int32_t w = (int32_t)t->width, h = (int32_t)t->height;
    const uint32_t wrap_u = t->wrap & 0xFFu, wrap_v = t->wrap >> 8;
    float x = wrap_coordinate(u, wrap_u) * (float)w - 0.5f;
    float y = wrap_coordinate(v, wrap_v) * (float)h - 0.5f;
    float x0 = floorf(x), y0 = floorf(y);
    float fx = x - x0, fy = y - y0;
    int32_t ix = (int32_t)x0, iy = (int32_t)y0;
    int32_t xa = wrap_index(ix, w, wrap_u), xb = wrap_index(ix + 1, w, wrap_u);
    int32_t ya = wrap_index(iy, h, wrap_v), yb = wrap_index(iy + 1, h, wrap_v);
    float c00[4], c10[4], c01[4], c11[4];
    fetch(t, texels, xa, ya, c00);
    fetch(t, texels, xb, ya, c10);
    fetch(t, texels, xa, yb, c01);
    fetch(t, texels, xb, yb, c11);
    for (int k = 0; k < 4; k++) {
        float top = c00[k] * (1.0f - fx) + c10[k] * fx;
        float bottom = c01[k] * (1.0f - fx) + c11[k] * fx;
        out[k] = top * (1.0f - fy) + bottom * fy;
    }
}
