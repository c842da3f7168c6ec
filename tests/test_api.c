/* The public API under misuse and under memory exhaustion: an allocator that fails its Nth
 * allocation, for N = 1, 2, ... until the call succeeds, makes every create, render and save
 * path return VKRT_ERROR_OUT_OF_MEMORY, leave its out pointer NULL and leak nothing; every
 * misuse answers the exact result code. The GPU part runs where a Vulkan device exists. */
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "check.h"
#include "failing_alloc.h"
#include "vkrt.h"

/* ---- an allocator that counts live blocks and fails one chosen allocation ---- */

static failing_allocator fa;

static void arm(long n)
{
    fa.calls = 0;
    fa.fail_at = n;
}

static void disarm(void)
{
    fa.fail_at = 0;
}

static vkrt_context_desc context_desc(vkrt_backend backend)
{
    return (vkrt_context_desc){
        .backend = backend,
        .cpu_threads = 2,
        .allocator = failing_allocator_use(&fa),
    };
}

/* Creating a context whose Nth allocation fails. */
static void context_create_oom(vkrt_backend backend)
{
    vkrt_context_desc d = context_desc(backend);
    for (long n = 1; n < 100000; n++) {
        fa = (failing_allocator){ 0 };
        arm(n);
        vkrt_context *ctx = (vkrt_context *)&fa; /* must come back NULL on failure */
        vkrt_result r = vkrt_context_create(&d, &ctx);
        disarm();
        if (r == VKRT_OK) {
            CHECK(fa.calls >= 1);
            vkrt_context_destroy(ctx);
            CHECK_EQ_U64(fa.live, 0);
            return;
        }
        CHECK_MSG(r == VKRT_ERROR_OUT_OF_MEMORY, "context_create, allocation %ld of backend %d failed: %s", n,
                  (int)backend, vkrt_result_string(r));
        CHECK(ctx == NULL);
        CHECK_MSG(fa.live == 0, "context_create, allocation %ld failed: %ld blocks leaked", n, fa.live);
        if (r != VKRT_ERROR_OUT_OF_MEMORY) return;
    }
    CHECK_MSG(0, "context_create never succeeded");
}

/* An operation on a fresh context; it calls arm(n) right before the call under test and
 * destroys everything it made. */
typedef vkrt_result (*oom_op)(vkrt_context *ctx, long n);

static void oom_every_allocation(const char *name, vkrt_backend backend, oom_op op)
{
    vkrt_context_desc d = context_desc(backend);
    for (long n = 1; n < 100000; n++) {
        fa = (failing_allocator){ 0 };
        vkrt_context *ctx = NULL;
        vkrt_result r = vkrt_context_create(&d, &ctx);
        CHECK_MSG(r == VKRT_OK, "%s: %s", name, vkrt_result_string(r));
        if (r != VKRT_OK) return;
        long live_before = fa.live;
        r = op(ctx, n);
        disarm();
        long live_after = fa.live;
        vkrt_context_destroy(ctx);
        CHECK_MSG(fa.live == 0, "%s: %ld blocks live after destroying the context", name, fa.live);
        if (r == VKRT_OK) {
            CHECK_MSG(n > 1, "%s made no allocation", name);
            return;
        }
        CHECK_MSG(r == VKRT_ERROR_OUT_OF_MEMORY, "%s, allocation %ld failed: %s", name, n, vkrt_result_string(r));
        CHECK_MSG(live_after == live_before, "%s, allocation %ld failed: %ld blocks leaked", name, n,
                  live_after - live_before);
        if (r != VKRT_ERROR_OUT_OF_MEMORY || live_after != live_before) return;
    }
    CHECK_MSG(0, "%s never succeeded", name);
}

static vkrt_result scene_op(vkrt_context *ctx, long n, const vkrt_scene_desc *desc)
{
    vkrt_scene *s = (vkrt_scene *)ctx;
    arm(n);
    vkrt_result r = vkrt_scene_create(ctx, desc, &s);
    disarm();
    if (r != VKRT_OK) CHECK(s == NULL);
    vkrt_scene_destroy(s);
    return r;
}

static vkrt_result op_scene_builtin(vkrt_context *ctx, long n)
{
    return scene_op(ctx, n, &(vkrt_scene_desc){ 0 });
}

static vkrt_result op_scene_obj(vkrt_context *ctx, long n)
{
    return scene_op(ctx, n, &(vkrt_scene_desc){ .path = VKRT_TEST_DATA_DIR "/groups.obj" });
}

/* A lattice of small triangles at several heights and two large ones across it: the
 * spatial-split builder cuts the large ones, so its BVH holds copies of them. */
#define ROOM_SMALL 64
static float room_positions[(ROOM_SMALL + 2) * 9];

static vkrt_mesh_desc room_mesh(void)
{
    for (int i = 0; i < ROOM_SMALL; i++) {
        float x = (float)(i % 8), y = (float)(i / 8), z = 0.1f * (float)(i * 37 % 11);
        const float t[9] = { x, y, z, x + 0.5f, y, z, x, y + 0.5f, z + 0.2f };
        memcpy(room_positions + 9 * i, t, sizeof t);
    }
    const float large[18] = { 0, 0, 0, 8, 0, 1, 8, 8, 0.5f, 0, 8, 1, 0, 0, 0.2f, 8, 8, 0.3f };
    memcpy(room_positions + 9 * ROOM_SMALL, large, sizeof large);
    return (vkrt_mesh_desc){ .positions = room_positions, .vertex_count = (ROOM_SMALL + 2) * 3 };
}

static vkrt_result op_scene_sbvh(vkrt_context *ctx, long n)
{
    vkrt_mesh_desc room = room_mesh();
    return scene_op(ctx, n, &(vkrt_scene_desc){ .meshes = &room, .mesh_count = 1, .builder = VKRT_BVH_BUILDER_SPATIAL_SAH });
}

static vkrt_result op_scene_gltf(vkrt_context *ctx, long n)
{
    return scene_op(ctx, n, &(vkrt_scene_desc){ .path = VKRT_TEST_DATA_DIR "/instanced.gltf" });
}

/* An OBJ with an .mtl file and a PNG texture. */
static vkrt_result op_scene_obj_materials(vkrt_context *ctx, long n)
{
    return scene_op(ctx, n, &(vkrt_scene_desc){ .path = VKRT_TEST_DATA_DIR "/materials.obj" });
}

/* KHR_lights_punctual lights on transformed nodes, normalised with the scene. */
static vkrt_result op_scene_lights_gltf(vkrt_context *ctx, long n)
{
    return scene_op(ctx, n, &(vkrt_scene_desc){ .path = VKRT_TEST_DATA_DIR "/lights.gltf" });
}

/* One embedded PNG decoded twice: as linear metallic-roughness data and as sRGB emission. */
static vkrt_result op_scene_pbr_gltf(vkrt_context *ctx, long n)
{
    return scene_op(ctx, n, &(vkrt_scene_desc){ .path = VKRT_TEST_DATA_DIR "/pbr_textures.gltf" });
}

/* Two PNG base colour textures, decoded by stb_image through the context's allocator. */
static vkrt_result op_scene_textured_gltf(vkrt_context *ctx, long n)
{
    return scene_op(ctx, n,
                    &(vkrt_scene_desc){ .path = VKRT_MODELS_DIR "/gltf/draco/three_meshes_two_materials_one_no_material/"
                                                                "three_meshes_two_materials_one_no_material.gltf" });
}

/* Two in-memory meshes: an indexed quad with a transform, and a non-indexed triangle. */
static const float quad_positions[] = { 0, 0, 0, 1, 0, 0, 1, 1, 0, 0, 1, 0 };
static const uint32_t quad_indices[] = { 0, 1, 2, 0, 2, 3 };
static const float shift[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 2, 1 };
static const float tri_positions[] = { 0, 0, 1, 1, 0, 1, 0, 1, 1 };

static const float quad_texcoords[] = { 0, 0, 1, 0, 1, 1, 0, 1 };

static vkrt_result op_scene_memory(vkrt_context *ctx, long n)
{
    static const uint8_t checker[16] = { 255, 255, 255, 255, 0, 0, 0, 255, 0, 0, 0, 255, 255, 255, 255, 255 };
    const vkrt_texture_desc tex = { .rgba8 = checker, .width = 2, .height = 2 };
    const vkrt_material gold = { .base_color = { 1.0f, 0.78f, 0.34f, 1.0f }, .metallic = 1.0f, .roughness = 0.3f,
                                 .base_color_texture = &tex, .metallic_roughness_texture = &tex,
                                 .emissive_texture = &tex };
    vkrt_mesh_desc meshes[2] = {
        { .positions = quad_positions, .vertex_count = 4, .indices = quad_indices, .index_count = 6, .transform = shift,
          .texcoords = quad_texcoords, .material = &gold },
        { .positions = tri_positions, .vertex_count = 3 },
    };
    return scene_op(ctx, n, &(vkrt_scene_desc){ .meshes = meshes, .mesh_count = 2 });
}

static vkrt_result render_op_with(vkrt_context *ctx, long n, vkrt_mode mode, const char *save_path,
                                  const vkrt_scene_desc *scene)
{
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(ctx, scene, &s);
    CHECK_MSG(r == VKRT_OK, "%s", vkrt_context_last_error(ctx));
    if (r != VKRT_OK) return VKRT_OK; /* reported; ends the loop */
    float rgba[24 * 16 * 4];
    vkrt_render_desc d = { .width = 24, .height = 16, .mode = mode };
    if (save_path) {
        r = vkrt_render(ctx, s, &d, rgba, sizeof rgba / sizeof rgba[0], NULL);
        CHECK(r == VKRT_OK);
        arm(n);
        r = vkrt_image_save(ctx, save_path, &(vkrt_image_view){ .rgba = rgba, .width = 24, .height = 16, .mode = mode });
    } else {
        arm(n);
        r = vkrt_render(ctx, s, &d, rgba, sizeof rgba / sizeof rgba[0], NULL);
    }
    disarm();
    vkrt_scene_destroy(s);
    return r;
}

static vkrt_result render_op(vkrt_context *ctx, long n, vkrt_mode mode, const char *save_path)
{
    return render_op_with(ctx, n, mode, save_path, &(vkrt_scene_desc){ 0 });
}

static vkrt_result op_render(vkrt_context *ctx, long n)
{
    return render_op(ctx, n, VKRT_MODE_NORMAL, NULL);
}

/* Albedo: on the GPU the first such render uploads the surfaces. */
static vkrt_result op_render_albedo(vkrt_context *ctx, long n)
{
    return render_op(ctx, n, VKRT_MODE_ALBEDO, NULL);
}

static vkrt_result op_render_path(vkrt_context *ctx, long n)
{
    return render_op(ctx, n, VKRT_MODE_PATH, NULL);
}

static vkrt_result op_render_shaded(vkrt_context *ctx, long n)
{
    return render_op(ctx, n, VKRT_MODE_SHADED, NULL);
}

/* Shading lists the scene's emitters, each triangle once however many leaves hold it. */
static vkrt_result op_render_shaded_sbvh(vkrt_context *ctx, long n)
{
    vkrt_mesh_desc room = room_mesh();
    return render_op_with(ctx, n, VKRT_MODE_SHADED, NULL,
                          &(vkrt_scene_desc){ .meshes = &room, .mesh_count = 1, .builder = VKRT_BVH_BUILDER_SPATIAL_SAH });
}

static char save_dir[] = "/tmp/vkrt_test_api_XXXXXX";

/* Saves a render as `name`; a failed save leaves no file. */
static vkrt_result save_op(vkrt_context *ctx, long n, const char *name, vkrt_mode mode)
{
    char path[64];
    snprintf(path, sizeof path, "%s/%s", save_dir, name);
    vkrt_result r = render_op(ctx, n, mode, path);
    CHECK_MSG(r == VKRT_OK ? access(path, F_OK) == 0 : access(path, F_OK) != 0, "%s after %s", name,
              vkrt_result_string(r));
    remove(path);
    return r;
}

static vkrt_result op_save_png(vkrt_context *ctx, long n)
{
    return save_op(ctx, n, "oom.png", VKRT_MODE_DEPTH);
}

static vkrt_result op_save_pfm(vkrt_context *ctx, long n)
{
    return save_op(ctx, n, "oom.pfm", VKRT_MODE_ID);
}

static vkrt_result op_save_hdr(vkrt_context *ctx, long n)
{
    return save_op(ctx, n, "oom.hdr", VKRT_MODE_DEPTH);
}

static void out_of_memory_at_every_cpu_allocation(void)
{
    context_create_oom(VKRT_BACKEND_CPU);
    oom_every_allocation("scene_create (built-in)", VKRT_BACKEND_CPU, op_scene_builtin);
    oom_every_allocation("scene_create (groups.obj)", VKRT_BACKEND_CPU, op_scene_obj);
    oom_every_allocation("scene_create (instanced.gltf)", VKRT_BACKEND_CPU, op_scene_gltf);
    oom_every_allocation("scene_create (spatial splits)", VKRT_BACKEND_CPU, op_scene_sbvh);
    oom_every_allocation("scene_create (in-memory meshes)", VKRT_BACKEND_CPU, op_scene_memory);
    oom_every_allocation("scene_create (glTF with PNG textures)", VKRT_BACKEND_CPU, op_scene_textured_gltf);
    oom_every_allocation("scene_create (OBJ with .mtl and a PNG texture)", VKRT_BACKEND_CPU, op_scene_obj_materials);
    oom_every_allocation("scene_create (glTF with punctual lights)", VKRT_BACKEND_CPU, op_scene_lights_gltf);
    oom_every_allocation("scene_create (glTF with PBR textures)", VKRT_BACKEND_CPU, op_scene_pbr_gltf);
    oom_every_allocation("render (CPU)", VKRT_BACKEND_CPU, op_render);
    oom_every_allocation("render albedo (CPU)", VKRT_BACKEND_CPU, op_render_albedo);
    oom_every_allocation("render path (CPU)", VKRT_BACKEND_CPU, op_render_path);
    oom_every_allocation("render shaded (CPU)", VKRT_BACKEND_CPU, op_render_shaded);
    oom_every_allocation("render shaded (CPU, spatial splits)", VKRT_BACKEND_CPU, op_render_shaded_sbvh);
    oom_every_allocation("image_save (.png)", VKRT_BACKEND_CPU, op_save_png);
    oom_every_allocation("image_save (.pfm)", VKRT_BACKEND_CPU, op_save_pfm);
    oom_every_allocation("image_save (.hdr)", VKRT_BACKEND_CPU, op_save_hdr);
}

static void out_of_memory_at_every_gpu_allocation(void)
{
    context_create_oom(VKRT_BACKEND_GPU);
    oom_every_allocation("scene_create (built-in, GPU)", VKRT_BACKEND_GPU, op_scene_builtin);
    oom_every_allocation("render (GPU)", VKRT_BACKEND_GPU, op_render);
    oom_every_allocation("render albedo (GPU, surfaces uploaded)", VKRT_BACKEND_GPU, op_render_albedo);
    oom_every_allocation("render path (GPU, wavefront)", VKRT_BACKEND_GPU, op_render_path);
}

/* ---- misuse ---- */

static void result_strings_name_every_code(void)
{
#define CHECK_RESULT_STRING_(name, message) \
    CHECK(strcmp(vkrt_result_string(name), #name ": " message) == 0);
    VKRT_RESULT_LIST(CHECK_RESULT_STRING_)
#undef CHECK_RESULT_STRING_
    CHECK(vkrt_result_string(VKRT_RESULT_COUNT_) != NULL);
    CHECK(vkrt_result_string((vkrt_result)-1) != NULL);
    CHECK(strstr(vkrt_result_string((vkrt_result)12345), "UNKNOWN") != NULL);
}

static void version_matches_header(void)
{
    CHECK_EQ_U64(vkrt_version(), VKRT_VERSION);
    CHECK_EQ_U64(VKRT_VERSION >> 22, VKRT_VERSION_MAJOR);
    CHECK_EQ_U64((VKRT_VERSION >> 12) & 0x3ff, VKRT_VERSION_MINOR);
    CHECK_EQ_U64(VKRT_VERSION & 0xfff, VKRT_VERSION_PATCH);
}

static void context_misuse_returns_invalid_argument(void)
{
    CHECK(vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU }, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    vkrt_context *ctx = (vkrt_context *)&fa;
    CHECK(vkrt_context_create(&(vkrt_context_desc){ .backend = (vkrt_backend)99 }, &ctx) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(ctx == NULL);
    ctx = (vkrt_context *)&fa;
    vkrt_context_desc half = { .backend = VKRT_BACKEND_CPU, .allocator = { .alloc = failing_alloc } };
    CHECK(vkrt_context_create(&half, &ctx) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(ctx == NULL);
    /* NULL desc means every default, like (desc){ 0 }: documented in vkrt.h's conventions. */
    vkrt_context_destroy(NULL);
    CHECK(vkrt_context_last_error(NULL) != NULL);
    CHECK_EQ_U64(vkrt_context_validation_messages(NULL), 0);
    CHECK(vkrt_context_device_name(NULL) != NULL);
    CHECK(strcmp(vkrt_cpu_code(), "x86-64-v3") == 0 || strcmp(vkrt_cpu_code(), "baseline") == 0);
    CHECK(vkrt_devices_list(NULL, NULL, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
}

static vkrt_result make_memory_scene(vkrt_context *ctx, const vkrt_mesh_desc *m, vkrt_scene **out)
{
    *out = (vkrt_scene *)ctx;
    return vkrt_scene_create(ctx, &(vkrt_scene_desc){ .meshes = m, .mesh_count = 1 }, out);
}

static void scene_misuse_returns_the_exact_code(void)
{
    vkrt_context *ctx = NULL;
    CHECK(vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU }, &ctx) == VKRT_OK);
    if (!ctx) return;
    vkrt_scene *s = (vkrt_scene *)ctx;
    CHECK(vkrt_scene_create(NULL, &(vkrt_scene_desc){ 0 }, &s) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_scene_create(ctx, &(vkrt_scene_desc){ 0 }, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(vkrt_context_last_error(ctx), "out_scene") != NULL);
    s = (vkrt_scene *)ctx;
    CHECK(vkrt_scene_create(ctx, &(vkrt_scene_desc){ .builder = (vkrt_bvh_builder)7 }, &s) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(s == NULL);
    CHECK(strstr(vkrt_context_last_error(ctx), "builder") != NULL);
    CHECK(vkrt_scene_create(ctx, &(vkrt_scene_desc){ .mesh_count = 1 }, &s) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = "/nonexistent/vkrt.obj" }, &s) == VKRT_ERROR_IO);
    CHECK(s == NULL);

    float nan_positions[] = { 0, 0, 0, 1, 0, 0, 0, NAN, 0 };
    float inf_positions[] = { 0, 0, 0, INFINITY, 0, 0, 0, 1, 0 };
    float nan_normals[] = { 0, 0, 1, 0, 0, 1, NAN, 0, 1 };
    float nan_transform[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, NAN, 0, 0, 1 };
    uint32_t bad_index[] = { 0, 1, 3 };
    uint32_t two_indices[] = { 0, 1 };
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = nan_positions, .vertex_count = 3 }, &s) ==
          VKRT_ERROR_INVALID_GEOMETRY);
    CHECK(s == NULL);
    CHECK(strstr(vkrt_context_last_error(ctx), "meshes[0]") != NULL);
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = inf_positions, .vertex_count = 3 }, &s) ==
          VKRT_ERROR_INVALID_GEOMETRY);
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = tri_positions, .vertex_count = 3, .normals = nan_normals }, &s) ==
          VKRT_ERROR_INVALID_GEOMETRY);
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = tri_positions, .vertex_count = 3, .transform = nan_transform }, &s) ==
          VKRT_ERROR_INVALID_GEOMETRY);
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = tri_positions, .vertex_count = 3, .indices = bad_index, .index_count = 3 }, &s) ==
          VKRT_ERROR_INVALID_GEOMETRY);
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = tri_positions, .vertex_count = 3, .indices = two_indices, .index_count = 2 }, &s) ==
          VKRT_ERROR_INVALID_GEOMETRY);
    float nan_uv[] = { 0, 0, 1, NAN, 0, 1 };
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = tri_positions, .vertex_count = 3, .texcoords = nan_uv }, &s) ==
          VKRT_ERROR_INVALID_GEOMETRY);
    CHECK(strstr(vkrt_context_last_error(ctx), "texture coordinates") != NULL);
    /* Materials out of their ranges (vkrt_material) name the field. */
    const struct {
        vkrt_material material;
        const char *field;
    } bad_materials[] = {
        { { .base_color = { 0.5f, 0.5f, 1.5f, 1.0f } }, "base_color[2]" },
        { { .base_color = { 0.5f, 0.5f, 0.5f, NAN } }, "base_color[3]" },
        { { .base_color = { 0.5f, 0.5f, 0.5f, 1.0f }, .metallic = -0.25f }, "metallic" },
        { { .base_color = { 0.5f, 0.5f, 0.5f, 1.0f }, .roughness = INFINITY }, "roughness" },
        { { .base_color = { 0.5f, 0.5f, 0.5f, 1.0f }, .emissive = { 0, -1, 0 } }, "emissive[1]" },
    };
    /* Textures without pixels, of no size or beyond the limit, or with an unknown wrap mode. */
    static const uint8_t pixel[4] = { 1, 2, 3, 4 };
    const vkrt_texture_desc bad_textures[] = {
        { .rgba8 = NULL, .width = 1, .height = 1 },
        { .rgba8 = pixel, .width = 0, .height = 1 },
        { .rgba8 = pixel, .width = 1, .height = 20000 },
        { .rgba8 = pixel, .width = 1, .height = 1, .wrap_v = (vkrt_wrap)7 },
    };
    /* Each texture field of the material is checked, and the message names it. */
    static const char *const texture_fields[] = { "base_color_texture", "metallic_roughness_texture",
                                                  "emissive_texture" };
    for (size_t i = 0; i < sizeof bad_textures / sizeof bad_textures[0]; i++)
        for (size_t f = 0; f < sizeof texture_fields / sizeof texture_fields[0]; f++) {
            vkrt_material mat = vkrt_material_default();
            const vkrt_texture_desc **field = f == 0   ? &mat.base_color_texture
                                              : f == 1 ? &mat.metallic_roughness_texture
                                                       : &mat.emissive_texture;
            *field = &bad_textures[i];
            vkrt_mesh_desc md = { .positions = tri_positions, .vertex_count = 3, .material = &mat };
            CHECK_MSG(make_memory_scene(ctx, &md, &s) == VKRT_ERROR_INVALID_ARGUMENT && s == NULL, "bad texture %zu",
                      i);
            CHECK_MSG(strstr(vkrt_context_last_error(ctx), texture_fields[f]), "bad texture %zu: '%s'", i,
                      vkrt_context_last_error(ctx));
        }
    for (size_t i = 0; i < sizeof bad_materials / sizeof bad_materials[0]; i++) {
        vkrt_mesh_desc md = { .positions = tri_positions, .vertex_count = 3, .material = &bad_materials[i].material };
        CHECK_MSG(make_memory_scene(ctx, &md, &s) == VKRT_ERROR_INVALID_ARGUMENT && s == NULL, "bad material %zu", i);
        CHECK_MSG(strstr(vkrt_context_last_error(ctx), bad_materials[i].field) &&
                      strstr(vkrt_context_last_error(ctx), "meshes[0]"),
                  "bad material %zu: '%s'", i, vkrt_context_last_error(ctx));
    }
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = NULL, .vertex_count = 3 }, &s) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = tri_positions, .vertex_count = 0 }, &s) == VKRT_ERROR_EMPTY_SCENE);
    CHECK(s == NULL);
    CHECK(make_memory_scene(ctx, &(vkrt_mesh_desc){ .positions = tri_positions, .vertex_count = 3 }, &s) == VKRT_OK);
    vkrt_scene_stats st;
    CHECK(vkrt_scene_stats_get(s, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_scene_stats_get(NULL, &st) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_scene_stats_get(s, &st) == VKRT_OK && st.triangles == 1);
    vkrt_scene_destroy(s);
    /* Every texture of a material is read, and counted whatever its kind. */
    static const uint8_t texel[4] = { 255, 128, 64, 255 };
    const vkrt_texture_desc one = { .rgba8 = texel, .width = 1, .height = 1 };
    vkrt_material textured = vkrt_material_default();
    textured.base_color_texture = textured.metallic_roughness_texture = textured.emissive_texture = &one;
    vkrt_mesh_desc textured_mesh = { .positions = tri_positions, .vertex_count = 3, .material = &textured };
    CHECK(make_memory_scene(ctx, &textured_mesh, &s) == VKRT_OK);
    CHECK(vkrt_scene_stats_get(s, &st) == VKRT_OK && st.textures == 3 && st.materials == 1);
    vkrt_scene_destroy(s);
    vkrt_scene_destroy(NULL);
    vkrt_context_destroy(ctx);
}

static void render_and_save_misuse_return_invalid_argument(void)
{
    vkrt_context *ctx = NULL, *other = NULL;
    CHECK(vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU }, &ctx) == VKRT_OK);
    CHECK(vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU }, &other) == VKRT_OK);
    vkrt_scene *s = NULL;
    if (ctx) CHECK(vkrt_scene_create(ctx, NULL, &s) == VKRT_OK); /* NULL desc: the built-in scene */
    if (!s) goto done;
    float rgba[8 * 8 * 4];
    const size_t n = sizeof rgba / sizeof rgba[0];
    const vkrt_render_desc ok = { .width = 8, .height = 8 };
    CHECK(vkrt_render(ctx, s, &ok, rgba, n, NULL) == VKRT_OK);
    CHECK(vkrt_render(NULL, s, &ok, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_render(ctx, NULL, &ok, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_render(other, s, &ok, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_render(ctx, s, &ok, NULL, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_render(ctx, s, &ok, rgba, n - 1, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_render(ctx, s, NULL, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT); /* default 1024x1024 > n */
    vkrt_render_desc d = ok;
    d.mode = (vkrt_mode)99;
    CHECK(vkrt_render(ctx, s, &d, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(vkrt_context_last_error(ctx), "mode") != NULL);
    d = ok;
    d.traversal = (vkrt_traversal)99;
    CHECK(vkrt_render(ctx, s, &d, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    d = ok;
    d.heat = (vkrt_heat)99;
    CHECK(vkrt_render(ctx, s, &d, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    d = ok;
    d.camera.fov_y_degrees = 180;
    CHECK(vkrt_render(ctx, s, &d, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    d = ok;
    d.camera.eye[0] = NAN;
    CHECK(vkrt_render(ctx, s, &d, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    d = ok;
    d.width = 100000;
    CHECK(vkrt_render(ctx, s, &d, rgba, n, NULL) == VKRT_ERROR_INVALID_ARGUMENT);

    char path[64];
    snprintf(path, sizeof path, "%s/misuse.png", save_dir);
    vkrt_image_view view = { .rgba = rgba, .width = 8, .height = 8 };
    CHECK(vkrt_image_save(NULL, path, &view) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_image_save(ctx, NULL, &view) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_image_save(ctx, path, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_image_save(ctx, path, &(vkrt_image_view){ .width = 8, .height = 8 }) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_image_save(ctx, path, &(vkrt_image_view){ .rgba = rgba, .width = 0, .height = 8 }) == VKRT_ERROR_INVALID_ARGUMENT);
    snprintf(path, sizeof path, "%s/misuse.bmp", save_dir);
    CHECK(vkrt_image_save(ctx, path, &view) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_image_save(ctx, "/nonexistent/dir/misuse.png", &view) == VKRT_ERROR_IO);
    CHECK(access(path, F_OK) != 0);
done:
    vkrt_scene_destroy(s);
    vkrt_context_destroy(other);
    vkrt_context_destroy(ctx);
}

/* The helpers that hand vkrt's rays and triangles to another tracer check their buffers. */
static void export_misuse_returns_invalid_argument(void)
{
    vkrt_context *ctx = NULL;
    CHECK(vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU }, &ctx) == VKRT_OK);
    vkrt_scene *s = NULL;
    if (ctx) CHECK(vkrt_scene_create(ctx, NULL, &s) == VKRT_OK);
    if (!s) goto done;
    vkrt_scene_stats st;
    vkrt_scene_stats_get(s, &st);
    size_t n = st.triangles * 9;
    float *tris = malloc(n * sizeof *tris);
    if (!tris) abort();
    CHECK(vkrt_scene_triangles_get(s, tris, n) == VKRT_OK);
    CHECK(vkrt_scene_triangles_get(NULL, tris, n) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_scene_triangles_get(s, NULL, n) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_scene_triangles_get(s, tris, n - 1) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(vkrt_context_last_error(ctx), "out_positions") != NULL);
    free(tris);
    /* With spatial splits the BVH holds copies of some triangles; the export still gives each
     * once, in prim_id order, as from the SAH BVH. */
    vkrt_mesh_desc room = room_mesh();
    vkrt_scene *split[2] = { NULL, NULL };
    vkrt_scene_stats sst[2] = { { 0 } };
    float *room_tris[2] = { NULL, NULL };
    const size_t room_floats = (ROOM_SMALL + 2) * 9;
    for (int k = 0; k < 2; k++) {
        const vkrt_scene_desc sd = { .meshes = &room, .mesh_count = 1,
                                     .builder = k ? VKRT_BVH_BUILDER_SPATIAL_SAH : VKRT_BVH_BUILDER_BINNED_SAH };
        CHECK(vkrt_scene_create(ctx, &sd, &split[k]) == VKRT_OK);
        if (split[k]) vkrt_scene_stats_get(split[k], &sst[k]);
        room_tris[k] = calloc(room_floats, sizeof *room_tris[k]);
        if (!room_tris[k]) abort();
        CHECK(split[k] && vkrt_scene_triangles_get(split[k], room_tris[k], room_floats) == VKRT_OK);
    }
    CHECK_MSG(sst[0].triangles == ROOM_SMALL + 2 && sst[1].triangles == ROOM_SMALL + 2 &&
                  sst[0].bvh_references == sst[0].triangles && sst[1].bvh_references > sst[1].triangles,
              "triangles %llu and %llu, references %llu and %llu", (unsigned long long)sst[0].triangles,
              (unsigned long long)sst[1].triangles, (unsigned long long)sst[0].bvh_references,
              (unsigned long long)sst[1].bvh_references);
    CHECK(memcmp(room_tris[0], room_tris[1], room_floats * sizeof(float)) == 0);
    for (int k = 0; k < 2; k++) {
        free(room_tris[k]);
        vkrt_scene_destroy(split[k]);
    }
    vkrt_ray rays[6];
    CHECK(vkrt_camera_rays(ctx, NULL, 3, 2, rays, 6) == VKRT_OK);
    CHECK(rays[0].tmin == 0.0f && rays[0].tmax == 0.0f && rays[0].origin[2] == 1.5f); /* the default eye */
    CHECK(vkrt_camera_rays(NULL, NULL, 3, 2, rays, 6) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_camera_rays(ctx, NULL, 3, 2, NULL, 6) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_camera_rays(ctx, NULL, 3, 2, rays, 5) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_camera_rays(ctx, NULL, 0, 2, rays, 6) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_camera_rays(ctx, NULL, 70000, 1, rays, 6) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_camera_rays(ctx, &(vkrt_camera){ .fov_y_degrees = 180 }, 3, 2, rays, 6) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(vkrt_context_last_error(ctx), "fov") != NULL);
    /* The offset moves a point off its surface along the normal, and only along it. */
    float o[3];
    vkrt_ray_offset((const float[3]){ 1.0f, 0.0f, -2.0f }, (const float[3]){ 0.0f, 1.0f, 0.0f }, o);
    CHECK(o[0] == 1.0f && o[1] > 0.0f && o[2] == -2.0f);
done:
    vkrt_scene_destroy(s);
    vkrt_context_destroy(ctx);
}

static bool gpu_available(void)
{
    vkrt_context *ctx = NULL;
    vkrt_result r = vkrt_context_create(&(vkrt_context_desc){ 0 }, &ctx);
    vkrt_context_destroy(ctx);
    if (r == VKRT_OK) return true;
    CHECK_MSG(r == VKRT_ERROR_NO_DEVICE, "GPU context: %s", vkrt_result_string(r));
    /* In CI a missing device is a failure, so a broken lavapipe cannot pass as green. */
    if (getenv("CI")) CHECK_MSG(0, "no Vulkan device, and CI is set");
    else fprintf(stderr, "skip the GPU backend: no Vulkan device\n");
    return false;
}

int main(void)
{
    if (!mkdtemp(save_dir)) {
        perror("mkdtemp");
        return 1;
    }
    RUN(result_strings_name_every_code);
    RUN(version_matches_header);
    RUN(context_misuse_returns_invalid_argument);
    RUN(scene_misuse_returns_the_exact_code);
    RUN(render_and_save_misuse_return_invalid_argument);
    RUN(export_misuse_returns_invalid_argument);
    RUN(out_of_memory_at_every_cpu_allocation);
    if (gpu_available()) RUN(out_of_memory_at_every_gpu_allocation);
    rmdir(save_dir);
    return check_exit();
}
