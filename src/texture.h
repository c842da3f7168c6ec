/* Textures: 8-bit images (sRGB colour or linear data) turned into the linear half-float texels
 * both tracers sample, and the bilinear sampling with wrap modes, the C mirror of
 * sample_texture() in shaders/trace_common.glsl (same arithmetic, so the CPU and the GPU return
 * the same bits). */
#ifndef VKRT_TEXTURE_H
#define VKRT_TEXTURE_H

#include <stdint.h>

#include "../shaders/vkrt_shared.h"

/* Largest texture side, and most texels, accepted: 4096 x 4096 texels are 128 MiB as halves,
 * lavapipe's whole storage buffer range; an image file declaring more is not decoded at all,
 * so a small file cannot make vkrt decode gigabytes. */
#define TEXTURE_MAX_SIDE 16384u
#define TEXTURE_MAX_TEXELS (4096u * 4096u)

/* IEEE half from float, rounding to nearest even (overflow to infinity). */
uint16_t half_from_float(float f);
/* Exact, as GLSL's unpackHalf2x16. */
float half_to_float(uint16_t h);

/* What an image's 8-bit RGB channels hold, which decides how they become linear texels (alpha is
 * always linear): glTF stores colour sRGB-encoded and data such as metallic-roughness as is. */
typedef enum texture_encoding {
    TEXTURE_SRGB = 0, /* colour (base colour, emission): decoded from sRGB */
    TEXTURE_LINEAR    /* data (metallic-roughness): value / 255, no transfer function */
} texture_encoding;

/* texels (2 words per texel: R | G << 16, B | A << 16, as halves) from width * height RGBA8
 * pixels: colour decoded from sRGB to linear, alpha linear. */
void texture_encode_rgba8(const uint8_t *rgba8, uint32_t width, uint32_t height, uint32_t *texels);
/* The same with every channel linear (value / 255), for data textures (TEXTURE_LINEAR). */
void texture_encode_rgba8_linear(const uint8_t *rgba8, uint32_t width, uint32_t height, uint32_t *texels);

/* Bilinear sample of texture t (its texels at t->first of `texels`) at (u, v). */
void texture_sample(const vkrt_gpu_texture *t, const uint32_t *texels, float u, float v, float out[4]);

#endif
