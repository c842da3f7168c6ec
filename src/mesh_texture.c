/* Texture images for the loaders: decoded by stb_image (third_party/stb_image_glue.h), every
 * allocation through the context's allocator. A texture that cannot be read is a warning and
 * no texture, so a model with a missing image still renders; only running out of memory fails. */
#include "mesh.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

#include "file_read.h"
#include "stb_image_glue.h"
#include "texture.h"

static void *glue_alloc(void *user, size_t size)
{
    return core_alloc(user, size);
}

static void glue_free(void *user, void *pointer)
{
    core_free(user, pointer);
}

static void unreadable(core *c, const char *source, const char *what, const char *name, const char *reason)
{
    /* stb_image names an unknown PNG chunk by its four raw bytes, which a hostile file makes
     * anything: the message keeps only printable ASCII. */
    char clean[128];
    size_t n = 0;
    for (; reason[n] && n + 1 < sizeof clean; n++) clean[n] = reason[n] >= 0x20 && reason[n] < 0x7f ? reason[n] : '?';
    clean[n] = '\0';
    core_log(c, VKRT_LOG_WARN, "%s: %s: texture %s cannot be read (%s); the material has no texture", source, what,
             name, clean);
}

vkrt_result mesh_add_texture_image(core *c, mesh *m, const void *bytes, size_t size, vkrt_wrap wrap_u, vkrt_wrap wrap_v,
                                   texture_encoding encoding, const char *name, const char *source, const char *what,
                                   uint32_t *out_index)
{
    *out_index = VKRT_NO_TEXTURE;
    stb_image_glue_allocator allocator = { glue_alloc, glue_free, c };
    uint32_t width = 0, height = 0;
    if (stb_image_glue_info(&allocator, bytes, size, &width, &height) &&
        (width > TEXTURE_MAX_SIDE || height > TEXTURE_MAX_SIDE || (uint64_t)width * height > TEXTURE_MAX_TEXELS)) {
        char reason_text[96];
        snprintf(reason_text, sizeof reason_text, "%ux%u texels, more than %u on a side or %u in all", width, height,
                 TEXTURE_MAX_SIDE, TEXTURE_MAX_TEXELS);
        unreadable(c, source, what, name, reason_text);
        return VKRT_OK;
    }
    const char *reason = NULL;
    uint8_t *pixels = stb_image_glue_decode_rgba8(&allocator, bytes, size, &width, &height, &reason);
    if (!pixels) {
        if (reason && !strcmp(reason, "outofmem"))
            return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory decoding texture %s", source, what,
                             name);
        unreadable(c, source, what, name, reason ? reason : "unknown image format");
        return VKRT_OK;
    }
    vkrt_result r = VKRT_OK;
    if (width > TEXTURE_MAX_SIDE || height > TEXTURE_MAX_SIDE || (uint64_t)width * height > TEXTURE_MAX_TEXELS) {
        unreadable(c, source, what, name, "more texels than vkrt's limit");
    } else {
        const vkrt_texture_desc desc = { .rgba8 = pixels, .width = width, .height = height, .wrap_u = wrap_u,
                                         .wrap_v = wrap_v };
        r = mesh_add_texture(c, m, &desc, encoding, VKRT_ERROR_UNSUPPORTED, source, what, out_index);
    }
    stb_image_glue_free(&allocator, pixels);
    return r;
}

vkrt_result mesh_add_texture_file(core *c, mesh *m, const char *path, vkrt_wrap wrap_u, vkrt_wrap wrap_v,
                                  texture_encoding encoding, const char *source, const char *what,
                                  uint32_t *out_index)
{
    *out_index = VKRT_NO_TEXTURE;
    void *bytes = NULL;
    size_t length = 0;
    file_read_status status = file_read(c, path, 0, &bytes, &length);
    if (status == FILE_READ_OUT_OF_MEMORY)
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory reading texture %s", source, what, path);
    if (status != FILE_READ_OK) {
        unreadable(c, source, what, path, file_read_status_text(status, errno));
        return VKRT_OK;
    }
    vkrt_result r =
        mesh_add_texture_image(c, m, bytes, length, wrap_u, wrap_v, encoding, path, source, what, out_index);
    core_free(c, bytes);
    return r;
}
