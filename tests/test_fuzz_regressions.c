/* Hostile inputs (tests/fuzz/regressions/): files the fuzzers found, or written by hand to
 * claim absurd sizes, that must load cleanly or fail with an input error naming the file, never
 * crash, hang or leak (the sanitizer build runs this too). Every file there is loaded; those
 * listed below must also give their expected outcome. */
#include <dirent.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "vkrt.h"

#define DIR_PATH VKRT_TEST_SOURCE_DIR "/fuzz/regressions"

static const struct {
    const char *name;
    vkrt_result result;
    uint64_t triangles;  /* when it loads */
    const char *message; /* when it fails: part of the message */
} expected[] = {
    { "huge_accessor_count.gltf", VKRT_ERROR_PARSE, 0, "reaches past the end" },
    { "offset_past_the_buffer.gltf", VKRT_ERROR_PARSE, 0, "reaches past the end" },
    { "absurd_stride.gltf", VKRT_ERROR_PARSE, 0, "reaches past the end" },
    { "face_of_5000_corners.obj", VKRT_OK, 4998, NULL },
    { "long_line_and_non_utf8.obj", VKRT_OK, 1, NULL },
    /* Found by fuzz_gltf: a GLB whose TEXCOORD_0 data lies at an odd address (cgltf read it
     * through a float pointer: undefined behaviour). */
    { "misaligned_glb_chunk.glb", VKRT_ERROR_PARSE, 0, "not aligned" },
    /* Found by fuzz_gltf: 16-bit indices at an odd address, read by cgltf_validate itself. */
    { "misaligned_indices.glb", VKRT_ERROR_PARSE, 0, "indices are not aligned" },
    /* Found by fuzz_gltf: a 2 KB JPEG declaring 8224x8224 texels (decoding and encoding it took
     * over 10 s in the fuzz build, and 800 MB); now not decoded, and the material has no texture. */
    { "huge_texture_bomb.glb", VKRT_OK, 12, NULL },
    /* Found by fuzz_gltf: a PNG texture whose data starts with an empty IDAT chunk, on which
     * stb_image computed NULL + 0 (undefined behaviour); the empty chunks are now dropped before
     * decoding (third_party/stb_image_glue.c). This one is corrupt further on: a warning, and
     * the material keeps its factors. */
    { "empty_idat_png.gltf", VKRT_OK, 12, NULL },
    /* Written by hand: the same empty IDAT as the last chunk, its CRC missing, which the
     * dropping walk had left in place (UBSan: NULL + 0 again). */
    { "empty_idat_no_crc.gltf", VKRT_OK, 1, NULL },
    /* Found by fuzz_gltf: the embedded PNG's IDAT chunk claims more bytes than follow it, and
     * stb_image grew its buffer to 2 GiB before reading them; now refused first (a warning). */
    { "idat_past_the_end.glb", VKRT_OK, 12, NULL },
    /* Found by fuzz_gltf: the index buffer view at byteOffset -68 (length 72), which wraps in
     * size_t: cgltf_validate's own range checks passed, and it read the index bound 68 bytes
     * before the buffer (undefined behaviour). */
    { "negative_view_offset.glb", VKRT_ERROR_PARSE, 0, "buffer view 0 reaches past the end of its buffer" },
    /* Found by fuzz_gltf (written here by hand, as CI's artifact stayed on its machine): a data:
     * URI buffer of byteLength -20, which cgltf reads as 2^64 - 20 and asked the allocator for
     * before decoding a character (AddressSanitizer aborts on such a request). */
    { "negative_data_uri_length.gltf", VKRT_ERROR_PARSE, 0, "is more than its data: URI holds" },
    /* The same byteLength for a buffer file (this file itself), and a buffer and a texture whose
     * URI "." names the directory they lie in, whose end ftell() puts at LLONG_MAX: cgltf's file
     * reader and the texture reader asked the allocator for that much (src/file_read.c now
     * learns a file's length first). A texture that cannot be read only loses the texture. */
    { "negative_file_length.gltf", VKRT_ERROR_IO, 0, "not a file, or shorter than its byteLength" },
    { "buffer_is_a_directory.gltf", VKRT_ERROR_IO, 0, "not a file, or shorter than its byteLength" },
    { "texture_is_a_directory.gltf", VKRT_OK, 1, NULL },
    /* Found by fuzz_gltf seeded with JPEG textures (written here by hand): a JPEG Huffman table
     * of 272 codes, which stb_image 2.27 wrote past its 257- and 256-entry arrays (UBSan: index
     * out of bounds); now refused before stb_image reads the image (a warning, no texture). */
    { "jpeg_huffman_272_codes.glb", VKRT_OK, 1, NULL },
    /* Found by the same run (written here by hand): a 16-bit PGM texture, which stb_image 2.27
     * converted to four channels as if 8-bit and then read past that buffer as 16-bit
     * (AddressSanitizer: heap-buffer-overflow); its PNM decoder is no longer built. */
    { "pgm_16_bit.glb", VKRT_OK, 1, NULL },
    /* Written by hand after reading stb_image's decoder: a JPEG whose 16-bit quantiser (65535)
     * times its DC term (65534 after two blocks) overflows an int, undefined behaviour that
     * clang's UBSan reports (the third-party code is now built with -fwrapv). */
    { "jpeg_dc_overflow.glb", VKRT_OK, 1, NULL },
    /* Found by fuzz_gltf seeded with every format (written here by hand: the scan of
     * test_mesh's jpeg_scan_with_an_undefined_huffman_table_decodes_alike_from_any_memory): a
     * progressive JPEG whose AC scan names a Huffman table no DHT defined, which stb_image read
     * from memory it had not cleared (UBSan: a shift by 32); the glue now clears its blocks. */
    { "jpeg_undefined_huffman_table.glb", VKRT_OK, 1, NULL },
};

static bool input_error(vkrt_result r)
{
    return r == VKRT_ERROR_IO || r == VKRT_ERROR_PARSE || r == VKRT_ERROR_INVALID_GEOMETRY ||
           r == VKRT_ERROR_EMPTY_SCENE || r == VKRT_ERROR_UNSUPPORTED || r == VKRT_ERROR_LIMIT;
}

/* No input here is larger than 64 KiB, and none loads into more than a few thousand triangles
 * or a texture past a few hundred texels: a larger single request means a size the file claims
 * went to the allocator unchecked (an IDAT chunk's length made stb_image ask for 2 GiB), which
 * plain malloc may even grant before the decoder finds the bytes are not there. */
#define LARGEST_REQUEST ((size_t)16 << 20)

static size_t largest_request;

static void *measuring_alloc(void *user, size_t size)
{
    (void)user;
    if (size > largest_request) largest_request = size;
    return malloc(size);
}

static void measuring_free(void *user, void *pointer)
{
    (void)user;
    free(pointer);
}

static void every_regression_input_loads_or_fails_cleanly(void)
{
    vkrt_context *ctx = NULL;
    const vkrt_context_desc desc = { .backend = VKRT_BACKEND_CPU,
                                     .allocator = { .alloc = measuring_alloc, .free = measuring_free } };
    CHECK(vkrt_context_create(&desc, &ctx) == VKRT_OK);
    DIR *d = opendir(DIR_PATH);
    CHECK_MSG(d != NULL, "cannot open %s", DIR_PATH);
    size_t files = 0, listed = 0;
    struct dirent *e;
    while (ctx && d && (e = readdir(d)) != NULL) {
        if (e->d_name[0] == '.') continue;
        /* SOURCES.md says where the inputs come from. */
        const size_t len = strlen(e->d_name);
        if (len > 3 && strcmp(e->d_name + len - 3, ".md") == 0) continue;
        char path[1024];
        snprintf(path, sizeof path, "%s/%s", DIR_PATH, e->d_name);
        vkrt_scene *s = NULL;
        largest_request = 0;
        vkrt_result r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = path }, &s);
        files++;
        CHECK_MSG(largest_request <= LARGEST_REQUEST, "%s: asked the allocator for %zu bytes at once", e->d_name,
                  largest_request);
        CHECK_MSG(r == VKRT_OK || input_error(r), "%s: %s", e->d_name, vkrt_result_string(r));
        if (r != VKRT_OK) CHECK_MSG(strstr(vkrt_context_last_error(ctx), e->d_name), "%s: message '%s' does not name it",
                                    e->d_name, vkrt_context_last_error(ctx));
        vkrt_scene_stats st = { 0 };
        if (s) vkrt_scene_stats_get(s, &st);
        for (size_t i = 0; i < sizeof expected / sizeof expected[0]; i++) {
            if (strcmp(expected[i].name, e->d_name)) continue;
            listed++;
            CHECK_MSG(r == expected[i].result, "%s: %s, expected %s", e->d_name, vkrt_result_string(r),
                      vkrt_result_string(expected[i].result));
            if (r == VKRT_OK) CHECK_EQ_U64(st.triangles, expected[i].triangles);
            if (r != VKRT_OK && expected[i].message)
                CHECK_MSG(strstr(vkrt_context_last_error(ctx), expected[i].message), "%s: '%s'", e->d_name,
                          vkrt_context_last_error(ctx));
        }
        printf("%-40s %8zu bytes at most  %s\n", e->d_name, largest_request,
               r == VKRT_OK ? "loads" : vkrt_context_last_error(ctx));
        vkrt_scene_destroy(s);
    }
    if (d) closedir(d);
    CHECK_EQ_U64(listed, sizeof expected / sizeof expected[0]);
    CHECK(files >= listed);
    vkrt_context_destroy(ctx);
}

int main(void)
{
    RUN(every_regression_input_loads_or_fails_cleanly);
    return check_exit();
}
