/* Image decoding through stb_image (PNG, JPEG, TGA and BMP; its other decoders are not built),
 * with every allocation going to the caller's allocator so vkrt's out-of-memory tests reach it
 * too, and files this stb_image would mishandle refused before it reads them. */
#ifndef STB_IMAGE_GLUE_H
#define STB_IMAGE_GLUE_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

typedef struct stb_image_glue_allocator {
    void *(*alloc)(void *user, size_t size);
    void (*free)(void *user, void *pointer);
    void *user;
} stb_image_glue_allocator;

/* Decodes `size` bytes to 8-bit RGBA rows, top row first. Returns the pixels, allocated with
 * `allocator` (release them with stb_image_glue_free), or NULL with *reason saying why (stb's
 * own words, e.g. "outofmem" or "unknown image type"). */
uint8_t *stb_image_glue_decode_rgba8(const stb_image_glue_allocator *allocator, const void *bytes, size_t size,
                                     uint32_t *out_width, uint32_t *out_height, const char **reason);
void stb_image_glue_free(const stb_image_glue_allocator *allocator, uint8_t *pixels);

/* The size an image declares, read from its header without decoding its pixels (a JPEG's header
 * still needs a little memory, from `allocator`); 0 when it is no image stb_image reads. */
int stb_image_glue_info(const stb_image_glue_allocator *allocator, const void *bytes, size_t size,
                        uint32_t *out_width, uint32_t *out_height);

#ifdef __cplusplus
}
#endif

#endif
