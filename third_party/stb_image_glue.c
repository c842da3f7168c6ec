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

/* Zeroed: this stb_image reads a JPEG scan's Huffman table whether or not a DHT defined it, from
 * a decoder struct it allocates without clearing, so a file that never defines the table made it
 * decode from whatever the allocator left there (found by fuzz_gltf: a shift by 32, undefined
 * behaviour, from such a table's code length). Cleared, an undefined table is all zero: a wrong
 * pixel in a broken file, the same on every run. */
static void *glue_malloc_uncleared(size_t size)
{
    block_header *b = current->alloc(current->user, sizeof *b + size);
    if (!b) return NULL;
    b->size = size;
    return b + 1;
}

static void *glue_malloc(size_t size)
{
    void *p = glue_malloc_uncleared(size);
    if (p) memset(p, 0, size);
    return p;
}

static void glue_free(void *p)
{
    if (p) current->free(current->user, (block_header *)p - 1);
}

static void *glue_realloc(void *p, size_t size)
{
    if (!p) return glue_malloc(size);
    void *fresh = glue_malloc_uncleared(size);
    if (!fresh) return NULL;
    size_t old = ((block_header *)p - 1)->size, kept = old < size ? old : size;
    memcpy(fresh, p, kept);
    memset((char *)fresh + kept, 0, size - kept); /* cleared past what was kept, as glue_malloc */
    glue_free(p);
    return fresh;
}

#define STBI_MALLOC(size) glue_malloc(size)
#define STBI_REALLOC(p, size) glue_realloc(p, size)
#define STBI_FREE(p) glue_free(p)
#define STBI_NO_STDIO /* vkrt reads files itself and hands over bytes */
/* The formats textures come in: glTF allows PNG and JPEG, and OBJ exporters write those, TGA and
 * BMP. This stb_image's other decoders are left out, so a hostile model cannot reach them: its
 * 16-bit PNM path reads past its buffer (found by fuzz_gltf seeded with every format), and its GIF
 * decoder has published memory-safety bugs (CVE-2023-45661, -45664, -45666, -45667). */
#define STBI_NO_GIF
#define STBI_NO_PSD
#define STBI_NO_PIC
#define STBI_NO_PNM
#define STBI_NO_HDR
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

/* A JPEG's bytes as stb_image's reader gives them: 0 past the end. */
static unsigned jpeg_byte(const uint8_t *bytes, size_t size, size_t at)
{
    return at < size ? bytes[at] : 0u;
}

static unsigned jpeg_be16(const uint8_t *bytes, size_t size, size_t at)
{
    return jpeg_byte(bytes, size, at) << 8 | jpeg_byte(bytes, size, at + 1);
}

/* stb_image's marker read (stbi__get_marker): a byte other than 0xFF is no marker (returned as
 * 0xFF, its "none"); else the fill bytes 0xFF are skipped and the next byte is the marker. */
static unsigned jpeg_marker(const uint8_t *bytes, size_t size, size_t *at)
{
    unsigned x = jpeg_byte(bytes, size, (*at)++);
    if (x != 0xFF) return 0xFF;
    while (x == 0xFF && *at <= size) x = jpeg_byte(bytes, size, (*at)++);
    return x;
}

/* The DHT segment whose length field lies at `at`, read as stb_image's stbi__process_marker
 * reads it: 1 where one of its tables lists more than 256 codes. This stb_image (Debian's 2.27)
 * writes each code's length into a 257-entry array and its symbol into a 256-entry one without
 * checking the 16 counts' total, so a larger total writes past both (found by fuzz_gltf; later
 * stb_image versions refuse it). *end is set past the segment. */
static int jpeg_dht_overflows(const uint8_t *bytes, size_t size, size_t at, size_t *end)
{
    long left = (long)jpeg_be16(bytes, size, at) - 2;
    at += 2;
    while (left > 0 && at <= size) {
        unsigned q = jpeg_byte(bytes, size, at++), codes = 0;
        if ((q >> 4) > 1 || (q & 15) > 3) break; /* stb_image refuses the table */
        for (int i = 0; i < 16; i++) codes += jpeg_byte(bytes, size, at++);
        if (codes > 256) return 1;
        at += codes;
        left -= 17 + (long)codes;
    }
    *end = at;
    return 0;
}

/* Whether stb_image would overflow a Huffman table of this JPEG (jpeg_dht_overflows). Up to the
 * frame header the walk is stb_image's own (stbi__decode_jpeg_header: SOI, then markers, each
 * segment by its length, stray bytes between them skipped one at a time), so the bytes it skips
 * (an APPn's ICC profile or EXIF thumbnail) are not read as tables. From there on, where tables
 * may follow scans whose entropy-coded data only a decoder can walk exactly, every FF C4 (a DHT
 * marker, the last of its fill bytes) is read as a DHT: stb_image can reach no table that does
 * not start there, and a valid file holds those bytes nowhere else after its first scan. */
static int jpeg_huffman_overflows(const uint8_t *bytes, size_t size)
{
    size_t at = 0, end;
    if (jpeg_marker(bytes, size, &at) != 0xD8) return 0; /* no SOI: stb_image does not read it as a JPEG */
    unsigned m = jpeg_marker(bytes, size, &at);
    while (!(m >= 0xC0 && m <= 0xC2)) { /* SOF0-2 end the header */
        if (m == 0xC4) {
            if (jpeg_dht_overflows(bytes, size, at, &end)) return 1;
            at = end;
        } else if (m == 0xDD) {
            at += 4;
        } else if (m == 0xDB || (m >= 0xE0 && m <= 0xEF) || m == 0xFE) {
            unsigned length = jpeg_be16(bytes, size, at);
            if (length < 2) return 0; /* stb_image stops at a bad length */
            at += length;
        } else {
            return 0; /* no marker, or one stb_image stops at */
        }
        m = jpeg_marker(bytes, size, &at);
        while (m == 0xFF) {
            if (at >= size) return 0;
            m = jpeg_marker(bytes, size, &at);
        }
    }
    for (; at + 1 < size; at++)
        if (bytes[at] == 0xFF && bytes[at + 1] == 0xC4 && jpeg_dht_overflows(bytes, size, at + 2, &end)) return 1;
    return 0;
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

/* Why stb_image must not be handed these bytes (NULL: they are safe to decode). */
static const char *image_flaw(const uint8_t *bytes, size_t size)
{
    if (png_find_flaws(bytes, size).idat_past_end) return "an IDAT chunk reaches past the end of the PNG";
    if (jpeg_huffman_overflows(bytes, size)) return "a JPEG Huffman table lists more than 256 codes";
    return NULL;
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
    if ((*reason = image_flaw(bytes, size))) return NULL;
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
        /* stb_image's words for bytes no decoder it was built with takes. */
        if (!pixels && *reason && !strcmp(*reason, "unknown image type")) *reason = "not a PNG, JPEG, TGA or BMP image";
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
    if (size > 0x7FFFFFFF || image_flaw(bytes, size)) return 0;
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
