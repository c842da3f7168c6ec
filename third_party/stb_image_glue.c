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

static uint32_t be32(const uint8_t *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

/* What this stb_image (Debian's 2.27) trips over in a PNG's chunks, found before it decodes,
 * up to IEND, where it stops reading. Both were found by fuzz_gltf:
 * - An empty IDAT chunk at the start of the data stream makes it compute NULL + 0 before it has
 *   a buffer (undefined behaviour).
 * - An IDAT chunk that claims more bytes than follow it makes it grow its data buffer to hold
 *   them, doubling, before it finds they are not there: a 4 KB file asked for 2 GiB. */
typedef struct png_flaws {
    int empty_idat;
    int idat_past_end;
} png_flaws;

/* The walk over a PNG's chunks, one step: the chunk whose header lies at off (inside the file).
 * Sets *len to its data length and returns the bytes it takes in the file, 12 + *len, or less
 * where the file ends inside its CRC; 0 where its data reaches past the end. */
static size_t png_chunk_bytes(const uint8_t *bytes, size_t size, size_t off, uint32_t *len)
{
    *len = be32(bytes + off);
    if (*len > size - off - 8) return 0;
    return size - off - *len < 12 ? size - off : 12 + (size_t)*len;
}

static png_flaws png_find_flaws(const uint8_t *bytes, size_t size)
{
    static const uint8_t signature[8] = { 0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n' };
    png_flaws flaws = { 0, 0 };
    if (size < 8 || memcmp(bytes, signature, 8) != 0) return flaws;
    for (size_t off = 8; off + 8 <= size;) {
        uint32_t len;
        size_t chunk = png_chunk_bytes(bytes, size, off, &len);
        int idat = memcmp(bytes + off + 4, "IDAT", 4) == 0;
        if (!chunk) {
            flaws.idat_past_end = idat; /* any other chunk cut short: stb_image reports it */
            break;
        }
        if (idat && len == 0) flaws.empty_idat = 1;
        if (memcmp(bytes + off + 4, "IEND", 4) == 0) break;
        off += chunk;
    }
    return flaws;
}

/* An empty IDAT carries no data, so the same image without those chunks decodes identically:
 * the copy (allocated through the decode's allocator; NULL when nothing needs dropping or memory
 * runs out, *out_oom telling which) leaves every other chunk, CRC included, as it was. */
static uint8_t *png_without_empty_idat(const uint8_t *bytes, size_t size, size_t *out_size, int *out_oom)
{
    *out_oom = 0;
    if (!png_find_flaws(bytes, size).empty_idat) return NULL;
    uint8_t *copy = glue_malloc(size);
    if (!copy) {
        *out_oom = 1;
        return NULL;
    }
    memcpy(copy, bytes, 8);
    size_t off = 8, n = 8;
    /* The same walk as png_find_flaws: a last chunk may lack (part of) its CRC, and an empty
     * IDAT there must go too (found by hand: the NULL + 0 again). */
    while (off + 8 <= size) {
        uint32_t len;
        size_t chunk = png_chunk_bytes(bytes, size, off, &len);
        if (!chunk) break;
        if (!(len == 0 && memcmp(bytes + off + 4, "IDAT", 4) == 0)) {
            memcpy(copy + n, bytes + off, chunk);
            n += chunk;
        }
        off += chunk;
    }
    memcpy(copy + n, bytes + off, size - off);
    *out_size = n + (size - off);
    return copy;
}

uint8_t *stb_image_glue_decode_rgba8(const stb_image_glue_allocator *allocator, const void *bytes, size_t size,
                                     uint32_t *out_width, uint32_t *out_height, const char **reason)
{
    *out_width = *out_height = 0;
    *reason = NULL;
    if (size > 0x7FFFFFFF) {
        *reason = "image larger than 2 GiB";
        return NULL;
    }
    if (png_find_flaws(bytes, size).idat_past_end) {
        *reason = "an IDAT chunk reaches past the end of the PNG";
        return NULL;
    }
    current = allocator;
    int w = 0, h = 0, channels = 0, oom = 0;
    size_t clean_size = 0;
    uint8_t *clean = png_without_empty_idat(bytes, size, &clean_size, &oom);
    stbi_uc *pixels = NULL;
    if (oom) {
        *reason = "outofmem";
    } else {
        pixels = stbi_load_from_memory(clean ? clean : bytes, (int)(clean ? clean_size : size), &w, &h, &channels, 4);
        if (!pixels) *reason = stbi_failure_reason();
    }
    glue_free(clean);
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
