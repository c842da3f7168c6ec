/* vkrt_image_save: raw render values -> display colours -> PNG or PPM on disk, or the raw
 * values themselves -> PFM (exact floats) or Radiance HDR (RGBE, 8-bit shared-exponent).
 * Every format is written to a temporary file beside the target and renamed over it, so a
 * failed or interrupted save never leaves a half-written image under the requested name. */
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include <strings.h>

#include <stb_image_write.h>

#include "context.h"

typedef enum image_format { FORMAT_UNKNOWN, FORMAT_PNG, FORMAT_PPM, FORMAT_PFM, FORMAT_HDR } image_format;

static image_format format_of(const char *path)
{
    const char *dot = strrchr(path, '.');
    if (!dot || strchr(dot, '/')) return FORMAT_UNKNOWN;
    if (strcasecmp(dot, ".png") == 0) return FORMAT_PNG;
    if (strcasecmp(dot, ".ppm") == 0) return FORMAT_PPM;
    if (strcasecmp(dot, ".pfm") == 0) return FORMAT_PFM;
    if (strcasecmp(dot, ".hdr") == 0) return FORMAT_HDR;
    return FORMAT_UNKNOWN;
}

static uint8_t to_byte(float v)
{
    if (!(v > 0.0f)) return 0;
    if (v >= 1.0f) return 255;
    return (uint8_t)(v * 255.0f + 0.5f);
}

/* A perceptually ordered ramp (dark blue -> cyan -> yellow -> red -> white) for heat maps. */
static void heat_ramp(float x, float rgb[3])
{
    static const float stops[][3] = {
        { 0.02f, 0.02f, 0.10f }, { 0.10f, 0.20f, 0.65f }, { 0.05f, 0.70f, 0.80f },
        { 0.95f, 0.90f, 0.15f }, { 0.90f, 0.25f, 0.05f }, { 1.00f, 1.00f, 1.00f },
    };
    const int n = (int)(sizeof stops / sizeof stops[0]);
    if (!(x > 0.0f)) x = 0.0f;
    if (x > 1.0f) x = 1.0f;
    float f = x * (float)(n - 1);
    int i = (int)f;
    if (i >= n - 1) i = n - 2;
    float w = f - (float)i;
    for (int k = 0; k < 3; k++) rgb[k] = stops[i][k] * (1.0f - w) + stops[i + 1][k] * w;
}

/* Distinct, stable colours for triangle ids (a 32-bit integer hash). */
static void id_colour(uint32_t id, float rgb[3])
{
    uint32_t h = id * 0x9E3779B1u;
    h ^= h >> 15;
    h *= 0x85EBCA77u;
    h ^= h >> 13;
    rgb[0] = 0.25f + 0.75f * (float)(h & 0xFF) / 255.0f;
    rgb[1] = 0.25f + 0.75f * (float)((h >> 8) & 0xFF) / 255.0f;
    rgb[2] = 0.25f + 0.75f * (float)((h >> 16) & 0xFF) / 255.0f;
}

/* The sRGB transfer function (IEC 61966-2-1) of a linear value in [0, 1]. */
static float srgb_encode(float v)
{
    if (!(v > 0.0f)) return 0.0f;
    if (v >= 1.0f) return 1.0f;
    return v <= 0.0031308f ? 12.92f * v : 1.055f * powf(v, 1.0f / 2.4f) - 0.055f;
}

static void encode_rgb8(const vkrt_image_view *im, uint8_t *out)
{
    const size_t pixels = (size_t)im->width * im->height;
    const float *px = im->rgba;
    float lo = INFINITY, hi = -INFINITY, heat_max = im->heat_max;
    for (size_t i = 0; i < pixels; i++) {
        float v = px[i * 4];
        if (im->mode == VKRT_MODE_DEPTH && px[i * 4 + 3] > 0.0f) {
            if (v < lo) lo = v;
            if (v > hi) hi = v;
        }
        if (im->mode == VKRT_MODE_HEATMAP && im->heat_max <= 0.0f && v > heat_max) heat_max = v;
    }
    if (heat_max <= 0.0f) heat_max = 1.0f;
    for (size_t i = 0; i < pixels; i++) {
        const float *p = px + i * 4;
        bool hit = p[3] > 0.0f;
        float rgb[3] = { 0.0f, 0.0f, 0.0f };
        switch (im->mode) {
        case VKRT_MODE_DEPTH:
            /* Near is bright; the nearest hit is white and the farthest a dark grey. */
            if (hit) rgb[0] = rgb[1] = rgb[2] = hi > lo ? 1.0f - 0.8f * (p[0] - lo) / (hi - lo) : 1.0f;
            break;
        case VKRT_MODE_ID:
            if (hit) id_colour((uint32_t)p[0], rgb);
            break;
        case VKRT_MODE_HEATMAP:
            heat_ramp(p[0] / heat_max, rgb);
            break;
        case VKRT_MODE_ALBEDO:
        case VKRT_MODE_SHADED:
        case VKRT_MODE_AO:
        case VKRT_MODE_PATH:
            /* Linear reflectance or radiance, shown as an sRGB image shows colour (radiance
             * above 1 clips to white). */
            for (int k = 0; k < 3; k++) rgb[k] = srgb_encode(p[k]);
            break;
        case VKRT_MODE_UV:
            /* The fractional part: a texture's repeat wraps the same way. */
            if (hit) rgb[0] = p[0] - floorf(p[0]), rgb[1] = p[1] - floorf(p[1]);
            break;
        default:
            if (hit) memcpy(rgb, p, sizeof rgb);
            break;
        }
        for (int k = 0; k < 3; k++) out[i * 3 + k] = to_byte(rgb[k]);
    }
}

static void write_to_file(void *context, void *data, int size)
{
    FILE *f = context;
    fwrite(data, 1, (size_t)size, f);
}

static bool write_pfm(FILE *f, const vkrt_image_view *im)
{
    /* PFM stores rows bottom to top; a negative scale says little-endian. */
    if (fprintf(f, "PF\n%u %u\n-1.0\n", im->width, im->height) < 0) return false;
    for (uint32_t y = im->height; y-- > 0;) {
        for (uint32_t x = 0; x < im->width; x++) {
            const float *p = im->rgba + ((size_t)y * im->width + x) * 4;
            if (fwrite(p, sizeof(float), 3, f) != 3) return false;
        }
    }
    return true;
}

/* Greg Ward's shared-exponent pixel (Graphics Gems II, "Real Pixels"): the largest component
 * keeps 8 bits of mantissa. RGBE has no sign, so negative values (a miss's -1) and NaN become 0;
 * values beyond 1e38 are clamped so the exponent byte cannot wrap. */
static void rgbe_from_float(const float *p, uint8_t out[4])
{
    float c[3];
    for (int k = 0; k < 3; k++) c[k] = p[k] > 0.0f ? fminf(p[k], 1e38f) : 0.0f;
    float v = fmaxf(c[0], fmaxf(c[1], c[2]));
    if (v < 1e-32f) {
        memset(out, 0, 4);
        return;
    }
    int e;
    float scale = frexpf(v, &e) * 256.0f / v;
    for (int k = 0; k < 3; k++) out[k] = (uint8_t)fminf(c[k] * scale, 255.0f);
    out[3] = (uint8_t)(e + 128);
}

/* Radiance HDR, rows top to bottom ("-Y H +X W"). Readers take a scanline of width 8..32767
 * that starts 2, 2 for run-length encoded, so such rows are always written in that encoding
 * (literal chunks of at most 128 bytes per component); other widths are flat pixels. */
static bool write_hdr(FILE *f, const vkrt_image_view *im, uint8_t *row)
{
    if (fprintf(f, "#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y %u +X %u\n", im->height, im->width) < 0) return false;
    const uint32_t w = im->width;
    const bool rle = w >= 8 && w <= 32767;
    for (uint32_t y = 0; y < im->height; y++) {
        for (uint32_t x = 0; x < w; x++) rgbe_from_float(im->rgba + ((size_t)y * w + x) * 4, row + (size_t)x * 4);
        if (!rle) {
            if (fwrite(row, 4, w, f) != w) return false;
            continue;
        }
        const uint8_t head[4] = { 2, 2, (uint8_t)(w >> 8), (uint8_t)(w & 0xFF) };
        if (fwrite(head, 1, 4, f) != 4) return false;
        for (int k = 0; k < 4; k++) {
            for (uint32_t x = 0; x < w; x += 128) {
                uint8_t chunk[129];
                uint32_t n = w - x < 128 ? w - x : 128;
                chunk[0] = (uint8_t)n;
                for (uint32_t i = 0; i < n; i++) chunk[1 + i] = row[(size_t)(x + i) * 4 + (size_t)k];
                if (fwrite(chunk, 1, n + 1, f) != n + 1) return false;
            }
        }
    }
    return true;
}

vkrt_result vkrt_image_save(vkrt_context *ctx, const char *path, const vkrt_image_view *image)
{
    if (!ctx) return VKRT_ERROR_INVALID_ARGUMENT;
    core *c = &ctx->core;
    core_clear_error(c);
    if (!path || !image || !image->rgba)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_image_save needs a path and an image with pixels");
    if (!image->width || !image->height || !vkrt_render_floats(image->width, image->height) ||
        image->width > (uint32_t)INT32_MAX / 3)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "%s: image size %ux%u is not valid", path, image->width,
                         image->height);
    image_format format = format_of(path);
    if (format == FORMAT_UNKNOWN)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "%s: unknown image format (use .png, .ppm, .pfm or .hdr)", path);

    size_t tmp_size = strlen(path) + 16;
    char *tmp = core_alloc(c, tmp_size);
    uint8_t *rgb = NULL;
    if (!tmp) return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory saving %s", path);
    snprintf(tmp, tmp_size, "%s.tmp-vkrt", path);
    if (format != FORMAT_PFM) {
        /* PNG and PPM: the whole image as 8-bit RGB; HDR: one RGBE row at a time. */
        rgb = format == FORMAT_HDR ? core_alloc_array(c, image->width, 4)
                                   : core_alloc_array(c, (size_t)image->width * image->height, 3);
        if (!rgb) {
            core_free(c, tmp);
            return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory encoding %s", path);
        }
        if (format != FORMAT_HDR) encode_rgb8(image, rgb);
    }
    vkrt_result r = VKRT_OK;
    FILE *f = fopen(tmp, "wb");
    if (!f) {
        r = core_fail(c, VKRT_ERROR_IO, "%s: cannot create the file: %s", path, strerror(errno));
    } else {
        bool ok = true;
        if (format == FORMAT_PFM) {
            ok = write_pfm(f, image);
        } else if (format == FORMAT_HDR) {
            ok = write_hdr(f, image, rgb);
        } else if (format == FORMAT_PPM) {
            ok = fprintf(f, "P6\n%u %u\n255\n", image->width, image->height) > 0 &&
                 fwrite(rgb, 3, (size_t)image->width * image->height, f) == (size_t)image->width * image->height;
        } else {
            ok = stbi_write_png_to_func(write_to_file, f, (int)image->width, (int)image->height, 3, rgb,
                                        (int)image->width * 3) != 0;
        }
        ok = !ferror(f) && ok;
        int saved_errno = errno;
        if (fclose(f) != 0) ok = false;
        if (!ok) {
            remove(tmp);
            r = core_fail(c, VKRT_ERROR_IO, "%s: writing failed: %s", path, strerror(saved_errno ? saved_errno : EIO));
        } else if (rename(tmp, path) != 0) {
            r = core_fail(c, VKRT_ERROR_IO, "%s: cannot replace the file: %s", path, strerror(errno));
            remove(tmp);
        }
    }
    core_free(c, rgb);
    core_free(c, tmp);
    return r;
}
