/* stb_image's implementation, its allocations routed to the allocator of the decode call in
 * progress on this thread (stb_image takes no allocator argument). Built with warnings
 * relaxed, like the other stb unit. */
#include "stb_image_glue.h"

#include <string.h>

static _Thread_local const stb_image_glue_allocator *current;

/* Each block carries its size ahead of the pointer stb gets, for STBI_REALLOC. */
typedef struct block_header {
    size_t size;
    size_t pad; /* keeps the payload 16-byte aligned */
} block_header;

static void *glue_malloc(size_t size)
{
    block_header *b = current->alloc(current->user, sizeof *b + size);
    if (!b) return NULL;
    b->size = size;
    return b + 1;
}

static void glue_free(void *p)
{
    if (p) current->free(current->user, (block_header *)p - 1);
}

static void *glue_realloc(void *p, size_t size)
{
    if (!p) return glue_malloc(size);
    void *fresh = glue_malloc(size);
    if (!fresh) return NULL;
    size_t old = ((block_header *)p - 1)->size;
    memcpy(fresh, p, old < size ? old : size);
    glue_free(p);
    return fresh;
}

#define STBI_MALLOC(size) glue_malloc(size)
#define STBI_REALLOC(p, size) glue_realloc(p, size)
#define STBI_FREE(p) glue_free(p)
#define STBI_NO_STDIO /* vkrt reads files itself and hands over bytes */
#define STB_IMAGE_STATIC
#define STB_IMAGE_IMPLEMENTATION
#include <stb_image.h>

uint8_t *stb_image_glue_decode_rgba8(const stb_image_glue_allocator *allocator, const void *bytes, size_t size,
                                     uint32_t *out_width, uint32_t *out_height, const char **reason)
{
    *out_width = *out_height = 0;
    *reason = NULL;
    if (size > 0x7FFFFFFF) {
        *reason = "image larger than 2 GiB";
        return NULL;
    }
    current = allocator;
    int w = 0, h = 0, channels = 0;
    stbi_uc *pixels = stbi_load_from_memory(bytes, (int)size, &w, &h, &channels, 4);
    if (!pixels) *reason = stbi_failure_reason();
    current = NULL;
    if (!pixels) return NULL;
    *out_width = (uint32_t)w;
    *out_height = (uint32_t)h;
    return pixels;
}

int stb_image_glue_info(const stb_image_glue_allocator *allocator, const void *bytes, size_t size,
                        uint32_t *out_width, uint32_t *out_height)
{
    int w = 0, h = 0, channels = 0;
    *out_width = *out_height = 0;
    if (size > 0x7FFFFFFF) return 0;
    current = allocator;
    int ok = stbi_info_from_memory(bytes, (int)size, &w, &h, &channels);
    current = NULL;
    if (!ok) return 0;
    *out_width = (uint32_t)w;
    *out_height = (uint32_t)h;
    return 1;
}

void stb_image_glue_free(const stb_image_glue_allocator *allocator, uint8_t *pixels)
{
    if (!pixels) return;
    current = allocator;
    stbi_image_free(pixels);
    current = NULL;
}
