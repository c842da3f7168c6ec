/* vkrt at scale on the device (lavapipe in CI), validation layer on: scenes split across
 * storage buffers render exactly as the same scenes in one buffer each, and a procedurally
 * generated scene of ten million triangles (beyond lavapipe's 128 MiB maxStorageBufferRange)
 * matches the CPU reference; submissions stay near their target time, the smallest ones give
 * the same images, and the progress callback cancels promptly, leaving nothing behind; out of
 * device memory, a lost device and a failed host allocation each return their own code with a
 * message, leak nothing and never hang (injected through the test knobs of vk_context). Any
 * validation message fails the test. */
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "check.h"
#include "context.h"
#include "cpu_trace.h"
#include "vkrt.h"

static vkrt_context *gpu;
static unsigned log_errors;
static unsigned binary_fallbacks; /* warnings that a scene keeps to its binary BVH */

static void on_log(void *user, vkrt_log_level level, const char *message)
{
    (void)user;
    if (level <= VKRT_LOG_WARN) {
        fprintf(stderr, "  [vkrt %s] %s\n", level == VKRT_LOG_ERROR ? "error" : "warning", message);
        if (strstr(message, "validation")) log_errors++;
        if (strstr(message, "traced through its binary BVH")) binary_fallbacks++;
    }
}

/* Host memory of a context made for a leak check: blocks live, and an allocation to refuse. */
static long live_blocks;
static long alloc_calls, alloc_fail_at; /* 1-based; 0: refuse none */

static void *counting_alloc(void *user, size_t size)
{
    (void)user;
    if (alloc_fail_at && ++alloc_calls == alloc_fail_at) return NULL;
    void *p = malloc(size);
    if (p) live_blocks++;
    return p;
}

static void counting_free(void *user, void *p)
{
    (void)user;
    live_blocks--;
    free(p);
}

/* A second GPU context (validation on, the shared pipeline cache) whose host memory is
 * counted; NULL on failure. Its validation messages reach on_log, so Vulkan objects left
 * behind count when it is destroyed (the layer names each one then). */
static vkrt_context *counted_context(void)
{
    vkrt_context_desc desc = { .backend = VKRT_BACKEND_GPU, .log = on_log, .validation = true,
                               .allocator = { .alloc = counting_alloc, .free = counting_free } };
    desc.pipeline_cache_path = getenv("VKRT_PIPELINE_CACHE");
    vkrt_context *ctx = NULL;
    vkrt_result r = vkrt_context_create(&desc, &ctx);
    CHECK_MSG(r == VKRT_OK, "counted context: %s", vkrt_result_string(r));
    return ctx;
}

static vkrt_scene *make_scene(vkrt_context *ctx, const char *path)
{
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = path }, &s);
    CHECK_MSG(r == VKRT_OK, "%s: %s", path ? path : "built-in", vkrt_context_last_error(ctx));
    return s;
}

/* Creates a scene of `path` on the GPU through `builder`, with every array split into buffers
 * of at most `limit` bytes (0: the device's limits). */
static vkrt_scene *scene_built_with_limit(const char *path, vkrt_bvh_builder builder, VkDeviceSize limit)
{
    gpu->vk->scene_buffer_limit = limit;
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(gpu, &(vkrt_scene_desc){ .path = path, .builder = builder }, &s);
    gpu->vk->scene_buffer_limit = 0;
    CHECK_MSG(r == VKRT_OK, "%s: %s", path, vkrt_context_last_error(gpu));
    return s;
}

static vkrt_scene *scene_with_limit(const char *path, VkDeviceSize limit)
{
    return scene_built_with_limit(path, VKRT_BVH_BUILDER_DEFAULT, limit);
}

/* Renders d (stats may be NULL); NULL on failure, which is a failed check. */
static float *render_stats(vkrt_context *ctx, vkrt_scene *s, const vkrt_render_desc *d, vkrt_render_stats *st)
{
    size_t n = vkrt_render_floats(d->width, d->height);
    float *rgba = malloc(n * sizeof *rgba);
    vkrt_result r = rgba ? vkrt_render(ctx, s, d, rgba, n, st) : VKRT_ERROR_OUT_OF_MEMORY;
    CHECK_MSG(r == VKRT_OK, "render (mode %d): %s", (int)d->mode, vkrt_context_last_error(ctx));
    if (r != VKRT_OK) {
        free(rgba);
        return NULL;
    }
    return rgba;
}

static float *render(vkrt_context *ctx, vkrt_scene *s, const vkrt_render_desc *d)
{
    return render_stats(ctx, s, d, NULL);
}

/* `count` rays from a ring about the y axis (radius 1.5, 37 turns as the height climbs from
 * -0.8 to 0.8), each aimed back across the axis with a wobble: rays from all around through
 * the bunny's bounding box, most of them hitting it. NULL when out of memory. */
static vkrt_ray *ring_rays(int count)
{
    vkrt_ray *rays = malloc((size_t)count * sizeof *rays);
    for (int i = 0; rays && i < count; i++) {
        float u = (float)i / (float)count, ang = 6.2831853f * u * 37.0f;
        rays[i] = (vkrt_ray){ .origin = { 1.5f * cosf(ang), 0.8f * (2.0f * u - 1.0f), 1.5f * sinf(ang) },
                              .dir = { -cosf(ang) + 0.2f * sinf(11 * ang), -0.8f * (2.0f * u - 1.0f) * 0.5f,
                                       -sinf(ang) } };
    }
    return rays;
}

/* The same render of the split and the one-buffer scene, bit for bit. */
static void check_identical(vkrt_scene *split, vkrt_scene *whole, const vkrt_render_desc *d, const char *what)
{
    float *a = render(gpu, split, d), *b = render(gpu, whole, d);
    size_t n = vkrt_render_floats(d->width, d->height), differ = 0;
    for (size_t i = 0; a && b && i < n; i++) differ += memcmp(&a[i], &b[i], sizeof *a) != 0;
    CHECK_MSG(a && b && differ == 0, "%s, mode %d, traversal %d: %zu of %zu floats differ from the one-buffer scene",
              what, (int)d->mode, (int)d->traversal, differ, n);
    free(a);
    free(b);
}

/* A 64 KiB limit cuts the bunny's 3,674 triangles into four buffers of 1,024 (and its nodes
 * and surfaces into as many halves): every primary mode, both traversals, the traversal
 * counters and vkrt_trace_rays give the one-buffer scene's results exactly. The binary arrays
 * reach the device (and the piece table) only when a call reads them: rays through the wide
 * BVH none, naive traversal the triangles, the heat map the nodes too. */
static void split_scene_renders_as_one_buffer(void)
{
    const char *path = VKRT_MODELS_DIR "/meshes/bunny.obj";
    vkrt_scene *split = scene_with_limit(path, 64 << 10), *whole = scene_with_limit(path, 0);
    if (!split || !whole) goto done;
    vkrt_scene_stats ss, ws;
    vkrt_scene_stats_get(split, &ss);
    vkrt_scene_stats_get(whole, &ws);
    CHECK_MSG(ss.device_buffers == 0 && ws.device_buffers == 0, "binary arrays' buffers at first: split %u, whole %u",
              ss.device_buffers, ws.device_buffers);
    CHECK_MSG(ws.device_bytes < ws.node_bytes + ws.triangle_bytes,
              "device bytes %" PRIu64 " at first (binary arrays %" PRIu64 ")", ws.device_bytes,
              ws.node_bytes + ws.triangle_bytes);
    /* The split scene is traced through the wide BVH as the whole one is (its arrays are texel
     * buffers, which the storage buffer range does not bound). */
    CHECK_MSG(ss.traversal_bytes == ws.traversal_bytes && ws.traversal_bytes < ws.node_bytes + ws.triangle_bytes,
              "traversal bytes: split %" PRIu64 ", one buffer %" PRIu64 " (binary arrays %" PRIu64 ")",
              ss.traversal_bytes, ws.traversal_bytes, ws.node_bytes + ws.triangle_bytes);
    /* Rays from all around, through the bunny's bounding box: closest and any hit. */
    enum { RAYS = 5000 };
    vkrt_ray *rays = ring_rays(RAYS);
    vkrt_hit *ha = malloc(RAYS * sizeof *ha), *hb = malloc(RAYS * sizeof *hb);
    CHECK(rays && ha && hb);
    const uint32_t tri_pieces = (uint32_t)((ss.bvh_references + 1023) / 1024);
    for (vkrt_traversal t = VKRT_TRAVERSAL_BVH; rays && ha && hb && t <= VKRT_TRAVERSAL_NAIVE; t++) {
        for (int any = 0; any < 2; any++) {
            vkrt_trace_desc td = { .traversal = t, .any_hit = any };
            CHECK(vkrt_trace_rays(gpu, split, &td, rays, RAYS, ha) == VKRT_OK);
            CHECK(vkrt_trace_rays(gpu, whole, &td, rays, RAYS, hb) == VKRT_OK);
            /* The same bits, any hits too: both scenes go through the same wide BVH (or, naive,
             * the same triangles in the same order). */
            size_t differ = 0;
            for (int i = 0; i < RAYS; i++) differ += memcmp(&ha[i], &hb[i], sizeof ha[i]) != 0;
            CHECK_MSG(differ == 0, "trace_rays (any hit %d, traversal %d): %zu rays differ", any, (int)t, differ);
        }
        vkrt_scene_stats_get(split, &ss);
        vkrt_scene_stats_get(whole, &ws);
        const uint32_t want_split = t == VKRT_TRAVERSAL_BVH ? 0 : tri_pieces, want_whole = t == VKRT_TRAVERSAL_BVH ? 0 : 1;
        CHECK_MSG(ss.device_buffers == want_split && ws.device_buffers == want_whole,
                  "after traversal %d: split %u buffers (want %u), whole %u (want %u)", (int)t, ss.device_buffers,
                  want_split, ws.device_buffers, want_whole);
    }
    free(rays);
    free(ha);
    free(hb);
    for (vkrt_traversal t = VKRT_TRAVERSAL_BVH; t <= VKRT_TRAVERSAL_NAIVE; t++) {
        for (vkrt_mode m = VKRT_MODE_NORMAL; m <= VKRT_MODE_UV; m++) {
            vkrt_render_desc d = { .width = 48, .height = 40, .mode = m, .traversal = t };
            if (t == VKRT_TRAVERSAL_NAIVE && m == VKRT_MODE_HEATMAP) continue; /* no traversal to see */
            check_identical(split, whole, &d, "bunny");
        }
    }
    vkrt_scene_stats_get(split, &ss);
    vkrt_scene_stats_get(whole, &ws);
    CHECK_EQ_U64(ws.device_buffers, 2);
    CHECK_EQ_U64(ss.device_buffers, tri_pieces + (ss.nodes + 1023) / 1024);
    CHECK_MSG(ss.device_bytes >= ss.node_bytes + ss.triangle_bytes && ss.device_bytes < ws.device_bytes + (64 << 10),
              "split device bytes %" PRIu64 " (one buffer: %" PRIu64 ")", ss.device_bytes, ws.device_bytes);
    vkrt_render_stats a, b;
    vkrt_render_desc counted = { .width = 32, .height = 32, .traversal_counters = true };
    size_t n = vkrt_render_floats(32, 32);
    float *img = malloc(n * sizeof *img);
    CHECK(vkrt_render(gpu, split, &counted, img, n, &a) == VKRT_OK);
    CHECK(vkrt_render(gpu, whole, &counted, img, n, &b) == VKRT_OK);
    CHECK_EQ_U64(a.nodes_visited, b.nodes_visited);
    CHECK_EQ_U64(a.tris_tested, b.tris_tested);
    free(img);
done:
    vkrt_scene_destroy(split);
    vkrt_scene_destroy(whole);
}

/* A spatial-split scene split across buffers: its triangle copies set the triangles' pieces
 * (homer_10k: 12,076 of them in buffers of 1,024), its surfaces stay one per prim_id (9,856,
 * fewer pieces). The primary modes and a shaded render (surfaces and the light table) give the
 * one-buffer SBVH scene's images exactly. */
static void split_spatial_split_scene_renders_as_one_buffer(void)
{
    const char *path = VKRT_MODELS_DIR "/meshes/homer_10k.obj";
    vkrt_scene *split = scene_built_with_limit(path, VKRT_BVH_BUILDER_SPATIAL_SAH, 64 << 10),
               *whole = scene_built_with_limit(path, VKRT_BVH_BUILDER_SPATIAL_SAH, 0);
    if (!split || !whole) goto done;
    for (vkrt_mode m = VKRT_MODE_NORMAL; m <= VKRT_MODE_SHADED; m++) {
        vkrt_render_desc d = { .width = 40, .height = 40, .mode = m };
        check_identical(split, whole, &d, "homer_10k sbvh");
    }
    /* The heat map has read the binary nodes and triangles: pieces of 1,024 of each (the
     * triangles' shift is every array's). */
    vkrt_scene_stats ss;
    vkrt_scene_stats_get(split, &ss);
    CHECK_MSG(ss.bvh_references > ss.triangles &&
                  ss.device_buffers == (ss.bvh_references + 1023) / 1024 + (ss.nodes + 1023) / 1024,
              "%" PRIu64 " references, %" PRIu64 " nodes, %u buffers", ss.bvh_references, ss.nodes, ss.device_buffers);
done:
    vkrt_scene_destroy(split);
    vkrt_scene_destroy(whole);
}

/* The lighting modes read triangles and surfaces in shade.comp too: a Cornell box (emissive
 * ceiling) and a textured OBJ, split into buffers of two triangles, give the one-buffer
 * scene's images exactly. */
static void split_scene_lights_as_one_buffer(void)
{
    const char *paths[] = { VKRT_TEST_DATA_DIR "/cornell.obj", VKRT_TEST_DATA_DIR "/pbr.obj" };
    for (size_t f = 0; f < sizeof paths / sizeof paths[0]; f++) {
        vkrt_scene *split = scene_with_limit(paths[f], 128), *whole = scene_with_limit(paths[f], 0);
        if (split && whole) {
            for (vkrt_mode m = VKRT_MODE_ALBEDO; m <= VKRT_MODE_PATH; m++) {
                vkrt_render_desc d = { .width = 24, .height = 20, .mode = m, .spp = 2, .seed = 5 };
                check_identical(split, whole, &d, paths[f]);
            }
            /* shade.comp read the triangles, in pieces of two. */
            vkrt_scene_stats ss;
            vkrt_scene_stats_get(split, &ss);
            CHECK_MSG(ss.device_buffers >= (ss.bvh_references + 1) / 2, "%s: %u buffers", paths[f], ss.device_buffers);
        }
        vkrt_scene_destroy(split);
        vkrt_scene_destroy(whole);
    }
}

/* A height field of (n - 1)^2 quads over [-1, 1]^2, two triangles each, with analytic normals:
 * ripples of several frequencies, so neighbouring triangles are never coplanar and depth
 * varies across the image. */
typedef struct terrain {
    float *positions, *normals;
    uint32_t *indices;
    uint32_t vertex_count, index_count;
} terrain;

static float height(float x, float y)
{
    return 0.08f * sinf(7.0f * x) * cosf(5.0f * y) + 0.01f * sinf(61.0f * x + 37.0f * y);
}

static terrain make_terrain(uint32_t n)
{
    terrain t = { 0 };
    t.vertex_count = n * n;
    t.index_count = (n - 1) * (n - 1) * 6;
    t.positions = malloc((size_t)t.vertex_count * 3 * sizeof(float));
    t.normals = malloc((size_t)t.vertex_count * 3 * sizeof(float));
    t.indices = malloc((size_t)t.index_count * sizeof(uint32_t));
    if (!t.positions || !t.normals || !t.indices) return t;
    const float step = 2.0f / (float)(n - 1), e = 1e-3f;
    for (uint32_t y = 0; y < n; y++) {
        for (uint32_t x = 0; x < n; x++) {
            float u = -1.0f + step * (float)x, v = -1.0f + step * (float)y;
            float *p = t.positions + ((size_t)y * n + x) * 3, *q = t.normals + ((size_t)y * n + x) * 3;
            p[0] = u, p[1] = v, p[2] = height(u, v);
            float dx = (height(u + e, v) - height(u - e, v)) / (2 * e), dy = (height(u, v + e) - height(u, v - e)) / (2 * e);
            float len = sqrtf(dx * dx + dy * dy + 1.0f);
            q[0] = -dx / len, q[1] = -dy / len, q[2] = 1.0f / len;
        }
    }
    size_t k = 0;
    for (uint32_t y = 0; y + 1 < n; y++) {
        for (uint32_t x = 0; x + 1 < n; x++) {
            uint32_t a = y * n + x, b = a + 1, c = a + n, d = c + 1;
            const uint32_t quad[6] = { a, b, d, a, d, c };
            memcpy(t.indices + k, quad, sizeof quad);
            k += 6;
        }
    }
    return t;
}

static void terrain_free(terrain *t)
{
    free(t->positions);
    free(t->normals);
    free(t->indices);
}

/* The CPU double-precision reference of one primary mode, traced over the scene's own host
 * arrays (the ones its device buffers were filled from), which spares building the BVH of ten
 * million triangles a second time in a CPU context. */
static float *cpu_reference(const vkrt_scene *s, const vkrt_render_desc *d)
{
    core *c = &gpu->core;
    vkrt_gpu_push camera = { 0 };
    camera_basis basis = { 0 };
    size_t n = vkrt_render_floats(d->width, d->height);
    float *rgba = malloc(n * sizeof *rgba);
    bool ok = rgba && camera_setup(c, &d->camera, d->width, d->height, &camera) == VKRT_OK &&
              camera_setup_double(c, &d->camera, d->width, d->height, &basis) == VKRT_OK;
    const cpu_trace_scene scene = { .nodes = s->bvh.nodes, .node_count = s->bvh.node_count, .tris = s->tris,
                                    .tri_count = s->bvh.tri_count };
    const cpu_trace_params p = { .camera = camera, .mode = d->mode, .traversal = VKRT_TRAVERSAL_BVH,
                                 .heat = VKRT_HEAT_NODES, .precision = VKRT_PRECISION_DOUBLE, .camera_d = basis,
                                 .threads = 2 };
    trace_counts counts;
    ok = ok && cpu_trace_render(c, &scene, &p, rgba, &counts) == VKRT_OK;
    CHECK_MSG(ok, "CPU reference: %s", vkrt_context_last_error(gpu));
    if (!ok) {
        free(rgba);
        return NULL;
    }
    return rgba;
}

/* 2,238^2 vertices: 10,008,338 triangles, 640 MB of them, five times lavapipe's 128 MiB
 * storage buffer range. The GPU's id and depth images at 64x64, seen from above at a slant,
 * agree with the CPU double-precision reference as in test_reference: the same triangle (or
 * another at the same depth) and depths within 1e-6 relative on at least 99.9% of the pixels. */
static void ten_million_triangles_match_the_cpu_reference(void)
{
    enum { N = 2238, SIZE = 64 };
    double t0 = core_now_ms();
    terrain t = make_terrain(N);
    CHECK(t.positions && t.normals && t.indices);
    if (!t.positions || !t.normals || !t.indices) {
        terrain_free(&t);
        return;
    }
    const vkrt_mesh_desc md = { .positions = t.positions, .vertex_count = t.vertex_count, .indices = t.indices,
                                .index_count = t.index_count, .normals = t.normals };
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(gpu, &(vkrt_scene_desc){ .meshes = &md, .mesh_count = 1 }, &s);
    CHECK_MSG(r == VKRT_OK, "scene: %s", vkrt_context_last_error(gpu));
    terrain_free(&t);
    if (!s) return;
    double t1 = core_now_ms();
    vkrt_scene_stats st;
    vkrt_scene_stats_get(s, &st);
    CHECK_EQ_U64(st.triangles, (uint64_t)2 * (N - 1) * (N - 1));
    const vkrt_camera cam = { .eye = { 0.0f, -0.9f, 1.0f }, .target = { 0.0f, 0.1f, 0.0f }, .fov_y_degrees = 40.0f };
    vkrt_render_desc d = { .width = SIZE, .height = SIZE, .camera = cam, .mode = VKRT_MODE_ID };
    vkrt_render_desc dd = d;
    dd.mode = VKRT_MODE_DEPTH;
    float *gid = render(gpu, s, &d);
    /* Through the wide BVH the id render reads none of the binary arrays: the scene is within
     * issue 7's 64 bytes a triangle. Depth refines its hits from the shading triangles, which
     * then reach the device, in pieces. */
    vkrt_scene_stats_get(s, &st);
    const double id_bytes = (double)st.device_bytes / (double)st.triangles;
    CHECK_MSG(st.device_buffers == 0 && id_bytes <= 64.0, "after the id render: %u buffers, %.1f bytes a triangle",
              st.device_buffers, id_bytes);
    float *gdepth = render(gpu, s, &dd);
    vkrt_scene_stats_get(s, &st);
    /* At least one buffer per storage-buffer range the triangles span: five on lavapipe's 128
     * MiB, one on a GPU whose range holds them all (4 GiB on NVIDIA's). */
    const uint64_t range = gpu->vk->properties.limits.maxStorageBufferRange;
    const uint64_t pieces = (st.triangle_bytes + range - 1) / range;
    CHECK_MSG(st.device_buffers >= pieces && pieces >= 1,
              "a scene of %" PRIu64 " triangle bytes in %u buffers of %" PRIu64 " bytes at most", st.triangle_bytes,
              st.device_buffers, range);
    fprintf(stderr, "  device memory: %.1f bytes a triangle after the id render, %.1f after depth\n", id_bytes,
            (double)st.device_bytes / (double)st.triangles);
    double t2 = core_now_ms();
    float *cid = cpu_reference(s, &d), *cdepth = cpu_reference(s, &dd);
    if (gid && gdepth && cid && cdepth) {
        size_t agree = 0, same_id = 0, hits = 0;
        double max_rel = 0.0;
        for (size_t p = 0; p < (size_t)SIZE * SIZE; p++) {
            float gd = gdepth[4 * p], cd = cdepth[4 * p];
            bool both = gd >= 0 && cd >= 0, depth_ok = (gd >= 0) == (cd >= 0);
            if (both) {
                double rel = fabs((double)gd - cd) / cd;
                if (rel > max_rel) max_rel = rel;
                depth_ok = rel < 1e-6;
                hits++;
            }
            bool id_ok = gid[4 * p] == cid[4 * p];
            same_id += id_ok;
            agree += depth_ok && (id_ok || both);
        }
        fprintf(stderr, "  %" PRIu64 " triangles in %u device buffers, %.1f host and %.1f device bytes per triangle\n",
                st.triangles, st.device_buffers, (double)st.host_bytes / (double)st.triangles,
                (double)st.device_bytes / (double)st.triangles);
        fprintf(stderr, "  %zu of %d pixels hit, %zu agree (%zu same id), max relative depth error %.2e\n", hits,
                SIZE * SIZE, agree, same_id, max_rel);
        fprintf(stderr, "  mesh and scene %.1f s, GPU id + depth %.1f s, CPU double reference %.1f s\n",
                (t1 - t0) * 1e-3, (t2 - t1) * 1e-3, (core_now_ms() - t2) * 1e-3);
        CHECK_MSG(hits > SIZE * SIZE / 2, "only %zu pixels hit", hits);
        CHECK_MSG(agree >= (size_t)(0.999 * SIZE * SIZE), "GPU and CPU agree on %zu of %d pixels", agree, SIZE * SIZE);
    }
    free(gid);
    free(gdepth);
    free(cid);
    free(cdepth);
    vkrt_scene_destroy(s);
}

/* ---- bounded submissions ---- */

/* With a target of a nanosecond every submission shrinks to one 8x8 workgroup (and naive
 * traversal to one chunk of triangles per submission): primary modes with both traversals
 * (the dragon's 47,794 triangles are six naive chunks), a lighting mode and vkrt_trace_rays
 * give the images and hits of the normal pacing, bit for bit, in many more submissions. So do
 * the many passes of a wide ray trace without the loop budget, the way a real GPU runs it:
 * each pass's ray slots are taken from a counter its dispatch must find cleared (lavapipe's
 * loops stay within their limit on these short rays). */
static void smallest_submissions_give_identical_results(void)
{
    vkrt_scene *dragon = make_scene(gpu, VKRT_MODELS_DIR "/meshes/dragon_48k.obj"), *builtin = make_scene(gpu, NULL);
    if (!dragon || !builtin) goto done;
    const struct {
        vkrt_scene *scene;
        vkrt_render_desc d;
    } cases[] = {
        { dragon, { .width = 72, .height = 40, .mode = VKRT_MODE_ID } },
        { dragon, { .width = 72, .height = 40, .mode = VKRT_MODE_DEPTH, .traversal = VKRT_TRAVERSAL_NAIVE } },
        { dragon, { .width = 40, .height = 40, .mode = VKRT_MODE_HEATMAP, .heat = VKRT_HEAT_TRIS,
                    .traversal_counters = true } },
        { builtin, { .width = 40, .height = 24, .mode = VKRT_MODE_PATH, .spp = 3, .seed = 7 } },
        { builtin, { .width = 40, .height = 24, .mode = VKRT_MODE_AO, .spp = 2, .traversal = VKRT_TRAVERSAL_NAIVE } },
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        vkrt_render_stats normal_stats, tiny_stats;
        float *normal = render_stats(gpu, cases[k].scene, &cases[k].d, &normal_stats);
        gpu->vk->submit_target_ms = 1e-6;
        float *tiny = render_stats(gpu, cases[k].scene, &cases[k].d, &tiny_stats);
        gpu->vk->submit_target_ms = 0.0;
        size_t n = vkrt_render_floats(cases[k].d.width, cases[k].d.height), differ = 0;
        for (size_t i = 0; normal && tiny && i < n; i++) differ += memcmp(&normal[i], &tiny[i], sizeof *tiny) != 0;
        fprintf(stderr, "  case %zu: %u submissions (longest %.1f ms); smallest: %u\n", k, normal_stats.submissions,
                normal_stats.longest_submission_ms, tiny_stats.submissions);
        CHECK_MSG(normal && tiny && differ == 0, "case %zu: %zu of %zu floats differ with the smallest submissions", k,
                  differ, n);
        /* At the smallest a submission holds one workgroup and, naive, one chunk of triangles;
         * how many the normal pacing needs depends on the machine's speed (a naive chunk of
         * 8,192 triangles for 64 pixels took 45 ms on one host, so that two filled a
         * submission there), so it is bounded only by the smallest's count. */
        const uint64_t groups = (uint64_t)((cases[k].d.width + 7) / 8) * ((cases[k].d.height + 7) / 8);
        vkrt_scene_stats st;
        vkrt_scene_stats_get(cases[k].scene, &st);
        const uint64_t chunks = cases[k].d.traversal == VKRT_TRAVERSAL_NAIVE
                                    ? (st.bvh_references + VKRT_NAIVE_CHUNK_TRIS - 1) / VKRT_NAIVE_CHUNK_TRIS
                                    : 1;
        CHECK_MSG(tiny_stats.submissions >= groups * chunks && tiny_stats.submissions >= normal_stats.submissions,
                  "case %zu: %u submissions at the smallest, %u normally, %" PRIu64 " workgroups, %" PRIu64
                  " naive chunks", k, tiny_stats.submissions, normal_stats.submissions, groups, chunks);
        CHECK_EQ_U64(tiny_stats.nodes_visited, normal_stats.nodes_visited);
        CHECK_EQ_U64(tiny_stats.samples, normal_stats.samples);
        free(normal);
        free(tiny);
    }
    enum { RAYS = 3000 };
    vkrt_ray *rays = malloc(RAYS * sizeof *rays);
    vkrt_hit *ha = malloc(RAYS * sizeof *ha), *hb = malloc(RAYS * sizeof *hb);
    for (int i = 0; i < RAYS; i++) {
        float a = 6.2831853f * (float)i / RAYS * 17.0f;
        rays[i] = (vkrt_ray){ .origin = { 0.1f * cosf(a), 0.1f * sinf(a), 2.0f }, .dir = { 0.3f * sinf(3 * a), 0.2f * cosf(a), -1.0f } };
    }
    for (vkrt_traversal t = VKRT_TRAVERSAL_BVH; t <= VKRT_TRAVERSAL_NAIVE; t++) {
        vkrt_trace_desc td = { .traversal = t };
        CHECK(vkrt_trace_rays(gpu, dragon, &td, rays, RAYS, ha) == VKRT_OK);
        gpu->vk->submit_target_ms = 1e-6;
        CHECK(vkrt_trace_rays(gpu, dragon, &td, rays, RAYS, hb) == VKRT_OK);
        gpu->vk->submit_target_ms = 0.0;
        CHECK_MSG(memcmp(ha, hb, RAYS * sizeof *ha) == 0, "trace_rays (traversal %d) differ with the smallest submissions",
                  (int)t);
    }
    {
        const uint32_t budget = gpu->vk->trace_budget;
        gpu->vk->trace_budget = 0;
        gpu->vk->submit_target_ms = 1e-6;
        memset(hb, 0xAB, RAYS * sizeof *hb);
        CHECK(vkrt_trace_rays(gpu, dragon, NULL, rays, RAYS, hb) == VKRT_OK);
        gpu->vk->submit_target_ms = 0.0;
        gpu->vk->trace_budget = budget;
        vkrt_trace_rays(gpu, dragon, NULL, rays, RAYS, ha);
        size_t differ = 0;
        for (int i = 0; i < RAYS; i++) differ += memcmp(&ha[i], &hb[i], sizeof *ha) != 0;
        CHECK_MSG(differ == 0, "trace_rays without the loop budget: %zu of %d hits differ", differ, RAYS);
    }
    free(rays);
    free(ha);
    free(hb);
done:
    vkrt_scene_destroy(dragon);
    vkrt_scene_destroy(builtin);
}

/* Progress callbacks of a render that cancels at the `cancel_at`-th: when each came, and when
 * the cancelling one returned. */
typedef struct progress_log {
    uint32_t calls, cancel_at;
    double last_ms, longest_gap_ms, cancelled_ms;
} progress_log;

static bool log_progress(void *user, const char *stage, float fraction)
{
    (void)stage;
    (void)fraction;
    progress_log *p = user;
    double now = core_now_ms();
    /* The first gap holds the pipeline's compilation on lavapipe, not a submission. */
    if (p->calls >= 2 && now - p->last_ms > p->longest_gap_ms) p->longest_gap_ms = now - p->last_ms;
    p->last_ms = now;
    if (++p->calls < p->cancel_at) return true;
    p->cancelled_ms = core_now_ms();
    return false;
}

/* Long renders (naive traversal over the 200k dragon: 25 triangle chunks per pixel; BVH path
 * tracing; many rays) cancelled from their progress callback: the callback is called at least
 * every few submissions' time, the call returns VKRT_ERROR_CANCELLED within a moment of the
 * callback saying so, and the context and scene are left usable and leak nothing. */

/* The end of a failure-injection test: the scene and context destroyed, and neither a Vulkan
 * object (the validation layer reports those at vkDestroyDevice) nor a host block left. */
static void destroy_and_check_nothing_left(vkrt_context *ctx, vkrt_scene *s)
{
    vkrt_scene_destroy(s);
    const unsigned before = log_errors;
    vkrt_context_destroy(ctx);
    CHECK_MSG(log_errors == before, "Vulkan objects left behind at vkDestroyDevice");
    CHECK_MSG(live_blocks == 0, "%ld host blocks leaked", live_blocks);
}

static void progress_cancels_within_one_submission(void)
{
    vkrt_context *ctx = counted_context();
    vkrt_scene *s = ctx ? make_scene(ctx, VKRT_MODELS_DIR "/meshes/dragon_200k.obj") : NULL;
    if (!s) {
        vkrt_context_destroy(ctx);
        return;
    }
    const vkrt_render_desc cases[] = {
        { .width = 256, .height = 256, .mode = VKRT_MODE_DEPTH, .traversal = VKRT_TRAVERSAL_NAIVE },
        { .width = 512, .height = 512, .mode = VKRT_MODE_PATH, .spp = 64 },
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        /* A small render of the same pipelines first: their compilation is not a submission. */
        vkrt_render_desc warm = cases[k];
        warm.width = warm.height = 8;
        warm.spp = 1;
        free(render_stats(ctx, s, &warm, NULL));
        progress_log log = { .cancel_at = 12 };
        vkrt_render_desc d = cases[k];
        d.progress = log_progress;
        d.progress_user = &log;
        size_t n = vkrt_render_floats(d.width, d.height);
        float *rgba = malloc(n * sizeof *rgba);
        double t0 = core_now_ms();
        vkrt_result r = vkrt_render(ctx, s, &d, rgba, n, NULL);
        double end = core_now_ms();
        free(rgba);
        fprintf(stderr, "  case %zu: cancelled after %.0f ms at progress call %u; longest gap between calls %.1f ms, "
                        "returned %.1f ms after the callback said so\n",
                k, end - t0, log.calls, log.longest_gap_ms, end - log.cancelled_ms);
        CHECK_MSG(r == VKRT_ERROR_CANCELLED, "case %zu: %s", k, vkrt_result_string(r));
        CHECK(strstr(vkrt_context_last_error(ctx), "cancelled") != NULL);
        CHECK_EQ_U64(log.calls, log.cancel_at);
        /* 100 ms per submission; generous for a shared 2-core machine with validation on. */
        CHECK_MSG(log.longest_gap_ms < 1000.0, "case %zu: %.1f ms between progress calls", k, log.longest_gap_ms);
        CHECK_MSG(end - log.cancelled_ms < 250.0, "case %zu: returned %.1f ms after cancelling", k, end - log.cancelled_ms);
    }
    /* vkrt_trace_rays too: a million rays, cancelled at the fourth call. */
    enum { RAYS = 1 << 20 };
    vkrt_ray *rays = calloc(RAYS, sizeof *rays);
    vkrt_hit *hits = malloc(RAYS * sizeof *hits);
    for (int i = 0; rays && i < RAYS; i++)
        rays[i] = (vkrt_ray){ .origin = { 0.0f, 0.0f, 2.0f }, .dir = { (float)(i % 1024) / 2048.0f - 0.25f,
                                                                      (float)(i / 1024) / 2048.0f - 0.25f, -1.0f } };
    progress_log log = { .cancel_at = 4 };
    vkrt_trace_desc td = { .traversal = VKRT_TRAVERSAL_NAIVE, .progress = log_progress, .progress_user = &log };
    vkrt_result r = vkrt_trace_rays(ctx, s, &td, rays, RAYS, hits);
    double end = core_now_ms();
    CHECK_MSG(r == VKRT_ERROR_CANCELLED, "trace_rays: %s", vkrt_result_string(r));
    CHECK_MSG(end - log.cancelled_ms < 250.0, "trace_rays returned %.1f ms after cancelling", end - log.cancelled_ms);
    /* Through the BVH the next chunk's rays are read while the device traces one: cancelled as
     * the second and the third chunk are read (a chunk on the device each time), the call waits
     * for that chunk before freeing its buffers (the validation layer, checked below, reports a
     * buffer destroyed in use) and returns within a chunk's time. */
    for (uint32_t at = 2; at <= 3; at++) {
        progress_log chunk_log = { .cancel_at = at };
        vkrt_trace_desc bd = { .progress = log_progress, .progress_user = &chunk_log };
        r = vkrt_trace_rays(ctx, s, &bd, rays, RAYS, hits);
        end = core_now_ms();
        CHECK_MSG(r == VKRT_ERROR_CANCELLED, "trace_rays through the BVH, cancelled at call %u: %s", at,
                  vkrt_result_string(r));
        CHECK_EQ_U64(chunk_log.calls, at);
        CHECK_MSG(end - chunk_log.cancelled_ms < 250.0, "trace_rays through the BVH returned %.1f ms after cancelling",
                  end - chunk_log.cancelled_ms);
    }
    free(rays);
    free(hits);
    /* Still usable. */
    free(render_stats(ctx, s, &(vkrt_render_desc){ .width = 16, .height = 16 }, NULL));
    CHECK_EQ_U64(vkrt_context_validation_messages(ctx), 0);
    destroy_and_check_nothing_left(ctx, s);
}

/* ---- device failures ---- */

/* One operation on a context's scene whose failures are checked. */
typedef vkrt_result (*scene_op)(vkrt_context *ctx, vkrt_scene *s);

static vkrt_result op_render(vkrt_context *ctx, vkrt_scene *s)
{
    float rgba[24 * 16 * 4];
    return vkrt_render(ctx, s, &(vkrt_render_desc){ .width = 24, .height = 16, .mode = VKRT_MODE_DEPTH }, rgba,
                       sizeof rgba / sizeof rgba[0], NULL);
}

/* The first albedo render uploads the surfaces (split, in a split scene). */
static vkrt_result op_albedo(vkrt_context *ctx, vkrt_scene *s)
{
    float rgba[16 * 16 * 4];
    return vkrt_render(ctx, s, &(vkrt_render_desc){ .width = 16, .height = 16, .mode = VKRT_MODE_ALBEDO }, rgba,
                       sizeof rgba / sizeof rgba[0], NULL);
}

static vkrt_result op_path(vkrt_context *ctx, vkrt_scene *s)
{
    float rgba[16 * 12 * 4];
    return vkrt_render(ctx, s, &(vkrt_render_desc){ .width = 16, .height = 12, .mode = VKRT_MODE_PATH, .spp = 2 },
                       rgba, sizeof rgba / sizeof rgba[0], NULL);
}

static vkrt_result op_naive(vkrt_context *ctx, vkrt_scene *s)
{
    float rgba[16 * 16 * 4];
    return vkrt_render(ctx, s, &(vkrt_render_desc){ .width = 16, .height = 16, .traversal = VKRT_TRAVERSAL_NAIVE },
                       rgba, sizeof rgba / sizeof rgba[0], NULL);
}

static vkrt_result op_rays(vkrt_context *ctx, vkrt_scene *s)
{
    vkrt_ray rays[100];
    vkrt_hit hits[100];
    for (int i = 0; i < 100; i++)
        rays[i] = (vkrt_ray){ .origin = { 0.01f * (float)(i - 50), 0.0f, 2.0f }, .dir = { 0.0f, 0.0f, -1.0f } };
    return vkrt_trace_rays(ctx, s, &(vkrt_trace_desc){ 0 }, rays, 100, hits);
}

static const struct {
    const char *name;
    scene_op op;
} scene_ops[] = { { "render", op_render },   { "albedo render", op_albedo }, { "path render", op_path },
                  { "naive render", op_naive }, { "trace_rays", op_rays } };

/* The context's first trace makes its lasting pipeline state (one host block): done before the
 * sweeps, which then see only what a call makes and frees. */
static void warm_up(vkrt_context *ctx)
{
    vkrt_scene *s = NULL;
    CHECK(vkrt_scene_create(ctx, &(vkrt_scene_desc){ 0 }, &s) == VKRT_OK);
    if (s) CHECK(op_render(ctx, s) == VKRT_OK);
    vkrt_scene_destroy(s);
}

static vkrt_scene *bunny_scene(vkrt_context *ctx, VkDeviceSize limit, vkrt_result *out_r)
{
    ctx->vk->scene_buffer_limit = limit;
    vkrt_scene *s = NULL;
    *out_r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = VKRT_MODELS_DIR "/meshes/bunny.obj" }, &s);
    ctx->vk->scene_buffer_limit = 0;
    return s;
}

/* A counted context after its warm-up, and the bunny's scene in *out_scene; NULL, with nothing
 * left behind, where either fails. */
static vkrt_context *warm_bunny_context(vkrt_scene **out_scene)
{
    *out_scene = NULL;
    vkrt_context *ctx = counted_context();
    if (!ctx) return NULL;
    warm_up(ctx);
    vkrt_result r;
    *out_scene = bunny_scene(ctx, 0, &r);
    CHECK_MSG(*out_scene != NULL, "the bunny: %s", vkrt_context_last_error(ctx));
    if (*out_scene) return ctx;
    vkrt_context_destroy(ctx);
    return NULL;
}

/* Whether the context's recycled blocks are exactly `handles` (in any order). */
static bool recycled_are(const vk_context *vk, const VkDeviceMemory *handles, uint32_t count)
{
    if (vk->recycled_count != count) return false;
    for (uint32_t i = 0; i < count; i++) {
        bool found = false;
        for (uint32_t j = 0; j < count; j++) found |= vk->recycled[j].memory == handles[i];
        if (!found) return false;
    }
    return true;
}

/* A call's working buffers take the device memory the call before it left (vk_buffer.c keeps
 * destroyed buffers' memory, VK_RECYCLED_BLOCKS): the same calls again allocate nothing and
 * hand back the same blocks; the pool stays within its caps through calls of other sizes and
 * kinds; it is not counted as memory in use, yet never keeps the context past a budget (a
 * call that needs more than the budget leaves fails as out of device memory, and the pool is
 * released rather than kept beyond it). */
static void device_memory_of_a_call_is_reused_by_the_next(void)
{
    vkrt_scene *s;
    vkrt_context *ctx = warm_bunny_context(&s);
    if (!ctx) return;
    vk_context *vk = ctx->vk;
    const VkDeviceSize scene_held = vk->memory_in_use;
    CHECK(op_rays(ctx, s) == VKRT_OK);
    VkDeviceMemory before[VK_RECYCLED_BLOCKS];
    const uint32_t count = vk->recycled_count;
    for (uint32_t i = 0; i < count; i++) before[i] = vk->recycled[i].memory;
    CHECK_MSG(count > 0 && vk->memory_in_use == scene_held, "after a trace: %u recycled blocks, %llu bytes in use (%llu)",
              count, (unsigned long long)vk->memory_in_use, (unsigned long long)scene_held);
    const uint32_t countdown = 1000000;
    vk->fail_allocation = countdown;
    for (int i = 0; i < 3; i++) CHECK(op_rays(ctx, s) == VKRT_OK);
    /* The hook counts every buffer's memory, recycled or not. */
    CHECK_MSG(vk->fail_allocation < countdown, "the allocation hook counted %u buffers", countdown - vk->fail_allocation);
    vk->fail_allocation = 0;
    CHECK_MSG(recycled_are(vk, before, count) && vk->memory_in_use == scene_held,
              "the same trace again: %u recycled blocks (%u before), the same ones: %d", vk->recycled_count, count,
              recycled_are(vk, before, count));
    for (size_t k = 0; k < sizeof scene_ops / sizeof scene_ops[0]; k++) {
        CHECK_MSG(scene_ops[k].op(ctx, s) == VKRT_OK, "%s: %s", scene_ops[k].name, vkrt_context_last_error(ctx));
        CHECK_MSG(vk->recycled_count <= VK_RECYCLED_BLOCKS && vk->recycled_bytes <= VK_RECYCLED_BYTES,
                  "after %s: %u recycled blocks, %llu bytes", scene_ops[k].name, vk->recycled_count,
                  (unsigned long long)vk->recycled_bytes);
    }
    const VkDeviceSize held = vk->memory_in_use, pooled = vk->recycled_bytes;
    CHECK(pooled > 0);
    vk->memory_budget = held;
    vkrt_result r = op_render(ctx, s);
    CHECK_MSG(r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY, "a render with no room in the budget: %s", vkrt_result_string(r));
    CHECK_MSG(vk->memory_in_use == held && vk->memory_in_use + vk->recycled_bytes <= vk->memory_budget,
              "after it: %llu bytes in use (%llu before), %llu recycled, budget %llu",
              (unsigned long long)vk->memory_in_use, (unsigned long long)held,
              (unsigned long long)vk->recycled_bytes, (unsigned long long)vk->memory_budget);
    vk->memory_budget = 0;
    CHECK(op_render(ctx, s) == VKRT_OK);
    fprintf(stderr, "  %u blocks reused by each trace; %llu bytes kept after every kind of call\n", count,
            (unsigned long long)pooled);
    destroy_and_check_nothing_left(ctx, s);
}

/* A device memory budget of 100 KiB cannot hold the bunny's 208 KB of wide arrays:
 * scene creation fails with VKRT_ERROR_OUT_OF_DEVICE_MEMORY and a message naming the budget,
 * frees every host block and device allocation it made, and the context goes on (the scene
 * loads once the budget is lifted). A budget that holds the scene but not a render's buffers
 * (1 KiB to spare) fails every kind of render and trace the same way; lifted, they succeed. */
static void small_memory_budget_fails_cleanly(void)
{
    vkrt_context *ctx = counted_context();
    if (!ctx) return;
    warm_up(ctx);
    const long blocks = live_blocks;
    const VkDeviceSize held = ctx->vk->memory_in_use;
    ctx->vk->memory_budget = 100 << 10;
    vkrt_result r;
    vkrt_scene *s = bunny_scene(ctx, 0, &r);
    CHECK_MSG(r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY && !s, "scene under a 100 KiB budget: %s", vkrt_result_string(r));
    CHECK_MSG(strstr(vkrt_context_last_error(ctx), "out of device memory") &&
                  strstr(vkrt_context_last_error(ctx), "budget"),
              "message: %s", vkrt_context_last_error(ctx));
    fprintf(stderr, "  %s\n", vkrt_context_last_error(ctx));
    CHECK_EQ_U64(live_blocks, blocks);
    CHECK_EQ_U64(ctx->vk->memory_in_use, held);
    ctx->vk->memory_budget = 0;
    s = bunny_scene(ctx, 0, &r);
    CHECK_MSG(r == VKRT_OK, "scene without a budget: %s", vkrt_context_last_error(ctx));
    if (s) {
        const VkDeviceSize scene_bytes = ctx->vk->memory_in_use;
        ctx->vk->memory_budget = scene_bytes + 1024;
        for (size_t k = 0; k < sizeof scene_ops / sizeof scene_ops[0]; k++) {
            const long before = live_blocks;
            r = scene_ops[k].op(ctx, s);
            CHECK_MSG(r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY, "%s with 1 KiB to spare: %s", scene_ops[k].name,
                      vkrt_result_string(r));
            CHECK_EQ_U64(live_blocks, before);
            CHECK_EQ_U64(ctx->vk->memory_in_use, scene_bytes);
        }
        ctx->vk->memory_budget = 0;
        for (size_t k = 0; k < sizeof scene_ops / sizeof scene_ops[0]; k++)
            CHECK_MSG(scene_ops[k].op(ctx, s) == VKRT_OK, "%s after the budget is lifted: %s", scene_ops[k].name,
                      vkrt_context_last_error(ctx));
    }
    vkrt_scene_destroy(s);
    CHECK_EQ_U64(ctx->vk->memory_in_use, held);
    const unsigned before = log_errors;
    vkrt_context_destroy(ctx);
    CHECK_MSG(log_errors == before, "Vulkan objects left behind at vkDestroyDevice");
    CHECK_MSG(live_blocks == 0, "%ld host blocks leaked", live_blocks);
}

/* A budget with room for the bunny's wide arrays and a small call's buffers, but not for its
 * binary BVH and shading triangles: the scene is made (with no fallback), rays and id renders
 * go through the wide BVH alone; the calls that read the binary arrays (normals, the heat map,
 * naive rays) fail with VKRT_ERROR_OUT_OF_DEVICE_MEMORY, leaving the device memory and the
 * scene as they were, and once the budget is lifted they give the images and hits of a scene
 * made without one. */
static void binary_arrays_beyond_the_budget_fail_alone(void)
{
    vkrt_context *ctx = counted_context();
    if (!ctx) return;
    warm_up(ctx);
    const VkDeviceSize held = ctx->vk->memory_in_use;
    vkrt_result r;
    vkrt_scene *roomy = bunny_scene(ctx, 0, &r);
    const unsigned warned = binary_fallbacks;
    vkrt_scene_stats st = { 0 };
    if (roomy) vkrt_scene_stats_get(roomy, &st);
    const VkDeviceSize binary_bytes = st.node_bytes + st.triangle_bytes;
    ctx->vk->memory_budget = ctx->vk->memory_in_use + st.device_bytes + binary_bytes / 2;
    vkrt_scene *s = bunny_scene(ctx, 0, &r);
    CHECK_MSG(roomy && r == VKRT_OK && s, "scene under a budget: %s", vkrt_context_last_error(ctx));
    CHECK_EQ_U64(binary_fallbacks, warned);
    enum { RAYS = 64, W = 8, H = 8 };
    vkrt_ray *rays = ring_rays(RAYS);
    vkrt_hit ha[RAYS], hb[RAYS];
    float ia[W * H * 4], ib[W * H * 4];
    if (s && rays) {
        const vkrt_trace_desc naive = { .traversal = VKRT_TRAVERSAL_NAIVE };
        const vkrt_render_desc id = { .width = W, .height = H, .mode = VKRT_MODE_ID };
        const vkrt_render_desc reads_binary[] = { { .width = W, .height = H, .mode = VKRT_MODE_NORMAL },
                                                  { .width = W, .height = H, .mode = VKRT_MODE_HEATMAP } };
        CHECK_MSG(vkrt_trace_rays(ctx, s, NULL, rays, RAYS, ha) == VKRT_OK &&
                      vkrt_render(ctx, s, &id, ia, W * H * 4, NULL) == VKRT_OK,
                  "wide traversal under the budget: %s", vkrt_context_last_error(ctx));
        const VkDeviceSize in_use = ctx->vk->memory_in_use;
        r = vkrt_trace_rays(ctx, s, &naive, rays, RAYS, hb);
        CHECK_MSG(r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY, "naive rays under the budget: %s", vkrt_result_string(r));
        for (size_t k = 0; k < sizeof reads_binary / sizeof reads_binary[0]; k++) {
            r = vkrt_render(ctx, s, &reads_binary[k], ib, W * H * 4, NULL);
            CHECK_MSG(r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY, "mode %d under the budget: %s", (int)reads_binary[k].mode,
                      vkrt_result_string(r));
        }
        vkrt_scene_stats after;
        vkrt_scene_stats_get(s, &after);
        CHECK_MSG(ctx->vk->memory_in_use == in_use && after.device_buffers == 0,
                  "after the failures: %llu bytes in use (was %llu), %u binary buffers",
                  (unsigned long long)ctx->vk->memory_in_use, (unsigned long long)in_use, after.device_buffers);
        ctx->vk->memory_budget = 0;
        /* The same scene, then, as one made without a budget. */
        for (size_t k = 0; k < sizeof reads_binary / sizeof reads_binary[0]; k++) {
            CHECK(vkrt_render(ctx, s, &reads_binary[k], ia, W * H * 4, NULL) == VKRT_OK &&
                  vkrt_render(ctx, roomy, &reads_binary[k], ib, W * H * 4, NULL) == VKRT_OK);
            CHECK_MSG(memcmp(ia, ib, sizeof ia) == 0, "mode %d: the image differs from the roomy scene's",
                      (int)reads_binary[k].mode);
        }
        size_t differ = 0, hits = 0;
        vkrt_hit hc[RAYS];
        CHECK(vkrt_trace_rays(ctx, s, &naive, rays, RAYS, hb) == VKRT_OK &&
              vkrt_trace_rays(ctx, roomy, &naive, rays, RAYS, hc) == VKRT_OK);
        for (int i = 0; i < RAYS; i++) {
            differ += memcmp(&hb[i], &hc[i], sizeof hb[i]) != 0;
            hits += hb[i].prim_id != VKRT_NO_HIT;
        }
        CHECK_MSG(differ == 0 && hits > RAYS / 4, "naive rays: %zu of %d hits differ (%zu hit)", differ, RAYS, hits);
        vkrt_scene_stats_get(s, &after);
        CHECK_EQ_U64(after.device_buffers, 2);
    }
    ctx->vk->memory_budget = 0;
    free(rays);
    vkrt_scene_destroy(s);
    vkrt_scene_destroy(roomy);
    CHECK_EQ_U64(ctx->vk->memory_in_use, held);
    vkrt_context_destroy(ctx);
}

/* Device allocation N fails (N = 1, 2, ... until the call succeeds) in creating a split scene
 * (64 KiB buffers: eight pieces and a piece table) and in every kind of render and trace: each
 * failure is VKRT_ERROR_OUT_OF_DEVICE_MEMORY with a message, and leaves the host blocks, the
 * device memory and the context as they were. */
static void every_failed_device_allocation_is_out_of_device_memory(void)
{
    vkrt_context *ctx = counted_context();
    if (!ctx) return;
    warm_up(ctx);
    vk_context *vk = ctx->vk;
    uint32_t n = 1, wide_fallbacks = 0;
    vkrt_scene *s = NULL;
    for (;; n++) {
        const long blocks = live_blocks;
        const VkDeviceSize held = vk->memory_in_use;
        vk->fail_allocation = n;
        vkrt_result r;
        s = bunny_scene(ctx, 64 << 10, &r);
        const bool fired = vk->fail_allocation == 0;
        vk->fail_allocation = 0;
        if (!fired) {
            CHECK_MSG(r == VKRT_OK, "scene with %u allocations: %s", n - 1, vkrt_context_last_error(ctx));
            break;
        }
        if (r == VKRT_OK && s) {
            /* The failed allocation was one of the wide BVH's: the scene keeps to the binary
             * one, which is then what its traversal reads. */
            vkrt_scene_stats st;
            vkrt_scene_stats_get(s, &st);
            CHECK_MSG(st.traversal_bytes >= st.node_bytes + st.triangle_bytes, "scene, device allocation %u failed: "
                      "traced through %" PRIu64 " bytes, the binary arrays' %" PRIu64, n, st.traversal_bytes,
                      st.node_bytes + st.triangle_bytes);
            wide_fallbacks++;
            vkrt_scene_destroy(s);
            s = NULL;
            continue;
        }
        CHECK_MSG(r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY && !s, "scene, device allocation %u failed: %s", n,
                  vkrt_result_string(r));
        CHECK_MSG(strstr(vkrt_context_last_error(ctx), "out of device memory") != NULL, "message: %s",
                  vkrt_context_last_error(ctx));
        CHECK_EQ_U64(live_blocks, blocks);
        CHECK_EQ_U64(vk->memory_in_use, held);
        vkrt_scene_destroy(s);
        s = NULL;
    }
    /* The wide BVH's two buffers (and their staging buffers, on a device that needs them)
     * fall back; every other allocation fails the call. */
    CHECK_MSG(wide_fallbacks >= 2, "%u failed allocations fell back to the binary BVH", wide_fallbacks);
    fprintf(stderr, "  split scene: %u device allocations, each failure clean (%u of them the wide BVH's, which "
                    "fall back to the binary BVH)\n", n - 1, wide_fallbacks);
    for (size_t k = 0; s && k < sizeof scene_ops / sizeof scene_ops[0]; k++) {
        for (n = 1;; n++) {
            const long blocks = live_blocks;
            const VkDeviceSize held = vk->memory_in_use;
            vkrt_scene_stats before;
            vkrt_scene_stats_get(s, &before);
            vk->fail_allocation = n;
            vkrt_result r = scene_ops[k].op(ctx, s);
            const bool fired = vk->fail_allocation == 0;
            vk->fail_allocation = 0;
            if (!fired) {
                CHECK_MSG(r == VKRT_OK, "%s: %s", scene_ops[k].name, vkrt_context_last_error(ctx));
                break;
            }
            CHECK_MSG(r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY, "%s, device allocation %u failed: %s", scene_ops[k].name,
                      n, vkrt_result_string(r));
            /* What stays is the scene's: the surfaces, once uploaded before the failure. */
            vkrt_scene_stats after;
            vkrt_scene_stats_get(s, &after);
            CHECK_MSG(vk->memory_in_use - held == after.device_bytes - before.device_bytes && live_blocks == blocks,
                      "%s, allocation %u: device memory %llu, was %llu; %ld more host blocks", scene_ops[k].name, n,
                      (unsigned long long)vk->memory_in_use, (unsigned long long)held, live_blocks - blocks);
        }
        fprintf(stderr, "  %s: %u device allocations, each failure clean\n", scene_ops[k].name, n - 1);
    }
    destroy_and_check_nothing_left(ctx, s);
}

/* VK_ERROR_DEVICE_LOST from the second submission's vkQueueSubmit or vkWaitForFences (a fence
 * that times out, too), in every kind of render and trace: the call returns
 * VKRT_ERROR_DEVICE_LOST with a message; from then on every call that needs the device returns
 * it at once (scene creation too); the scene and the context are destroyed without a hang,
 * leaking no host block or Vulkan object. */
static void lost_device_is_reported_and_final(void)
{
    const struct {
        bool at_wait;
        VkResult result;
        const char *what;
    } failures[] = { { false, VK_ERROR_DEVICE_LOST, "lost at submission" },
                     { true, VK_ERROR_DEVICE_LOST, "lost at the fence" },
                     { true, VK_TIMEOUT, "fence timed out" } };
    for (size_t k = 0; k < sizeof scene_ops / sizeof scene_ops[0]; k++) {
        for (size_t f = 0; f < sizeof failures / sizeof failures[0]; f++) {
            /* The timeout once is enough. */
            if (failures[f].result == VK_TIMEOUT && k != 2) continue;
            vkrt_context *ctx = counted_context();
            vkrt_result r;
            vkrt_scene *s = ctx ? bunny_scene(ctx, k == 0 ? 64 << 10 : 0, &r) : NULL;
            if (!s) {
                vkrt_context_destroy(ctx);
                continue;
            }
            /* The second submission of the call (its first where it has one only). */
            ctx->vk->fail_submission = 2;
            ctx->vk->fail_result = failures[f].result;
            ctx->vk->fail_at_wait = failures[f].at_wait;
            r = scene_ops[k].op(ctx, s);
            if (ctx->vk->fail_submission) { /* one submission only: fail that */
                ctx->vk->fail_submission = 1;
                r = scene_ops[k].op(ctx, s);
            }
            CHECK_MSG(r == VKRT_ERROR_DEVICE_LOST, "%s, %s: %s", scene_ops[k].name, failures[f].what,
                      vkrt_result_string(r));
            CHECK_MSG(strstr(vkrt_context_last_error(ctx), "lost") != NULL, "message: %s", vkrt_context_last_error(ctx));
            if (k == 2) fprintf(stderr, "  %s: %s\n", failures[f].what, vkrt_context_last_error(ctx));
            const double t0 = core_now_ms();
            for (size_t j = 0; j < sizeof scene_ops / sizeof scene_ops[0]; j++)
                CHECK_MSG(scene_ops[j].op(ctx, s) == VKRT_ERROR_DEVICE_LOST, "%s after the loss", scene_ops[j].name);
            vkrt_scene *again = bunny_scene(ctx, 0, &r);
            CHECK_MSG(r == VKRT_ERROR_DEVICE_LOST && !again, "scene after the loss: %s", vkrt_result_string(r));
            CHECK_MSG(core_now_ms() - t0 < 100.0, "calls after the loss took %.1f ms", core_now_ms() - t0);
            vkrt_scene_destroy(s);
            const unsigned before = log_errors;
            vkrt_context_destroy(ctx);
            CHECK_MSG(log_errors == before, "%s: Vulkan objects left behind at vkDestroyDevice", scene_ops[k].name);
            CHECK_MSG(live_blocks == 0, "%s: %ld host blocks leaked", scene_ops[k].name, live_blocks);
        }
    }
}

/* Host allocation N fails (N = 1, 2, ... until no allocation is left to fail) in creating a
 * split scene and in a naive, a path and an albedo render on it (the albedo render uploads the
 * split surfaces): VKRT_ERROR_OUT_OF_MEMORY each time with nothing leaked, except where vkrt
 * tolerates the failure (the BVH builder's shrinking of its node array) and succeeds. */
static void every_failed_host_allocation_is_out_of_memory(void)
{
    vkrt_context *ctx = counted_context();
    if (!ctx) return;
    warm_up(ctx);
    vkrt_scene *s = NULL;
    long n, tolerated = 0;
    for (n = 1;; n++) {
        const long blocks = live_blocks;
        alloc_calls = 0;
        alloc_fail_at = n;
        vkrt_result r;
        s = bunny_scene(ctx, 64 << 10, &r);
        const bool fired = alloc_calls >= n;
        alloc_fail_at = 0;
        if (!fired) {
            CHECK_MSG(r == VKRT_OK, "scene: %s", vkrt_context_last_error(ctx));
            break;
        }
        if (r == VKRT_OK) {
            tolerated++;
        } else {
            CHECK_MSG(r == VKRT_ERROR_OUT_OF_MEMORY && !s, "split scene, host allocation %ld failed: %s", n,
                      vkrt_result_string(r));
            CHECK_EQ_U64(live_blocks, blocks);
        }
        vkrt_scene_destroy(s);
        s = NULL;
    }
    fprintf(stderr, "  split scene: %ld host allocations, each failure clean (%ld tolerated)\n", n - 1, tolerated);
    CHECK(tolerated <= 1);
    const struct {
        const char *name;
        scene_op op;
    } ops[] = { { "albedo render", op_albedo }, { "naive render", op_naive }, { "path render", op_path } };
    for (size_t k = 0; s && k < sizeof ops / sizeof ops[0]; k++) {
        for (n = 1;; n++) {
            const long blocks = live_blocks;
            alloc_calls = 0;
            alloc_fail_at = n;
            vkrt_result r = ops[k].op(ctx, s);
            const bool fired = alloc_calls >= n;
            alloc_fail_at = 0;
            if (!fired) {
                CHECK_MSG(r == VKRT_OK, "%s: %s", ops[k].name, vkrt_context_last_error(ctx));
                break;
            }
            CHECK_MSG(r == VKRT_ERROR_OUT_OF_MEMORY, "%s, host allocation %ld failed: %s", ops[k].name, n,
                      vkrt_result_string(r));
            CHECK_MSG(live_blocks == blocks, "%s, allocation %ld: %ld blocks leaked", ops[k].name, n,
                      live_blocks - blocks);
        }
        fprintf(stderr, "  %s: %ld host allocations, each failure clean\n", ops[k].name, n - 1);
    }
    destroy_and_check_nothing_left(ctx, s);
}

/* ---- the binned traversal's lists without memory ---- */

enum { BINNED_SIDE = 128 }; /* 16,384 rays from one eye: as few as the binned traversal takes */

/* The default view of s as a depth image (`render`) or as its camera rays' hits, the binned
 * traversal's two kinds of call; *out_binned: the rays that went through lists. */
static vkrt_result binned_call(vkrt_context *ctx, vkrt_scene *s, bool render, const vkrt_ray *rays, float *out_rgba,
                               vkrt_hit *out_hits, uint64_t *out_binned)
{
    const size_t n = (size_t)BINNED_SIDE * BINNED_SIDE;
    vkrt_result r;
    if (render) {
        vkrt_render_stats st = { 0 };
        r = vkrt_render(ctx, s, &(vkrt_render_desc){ .width = BINNED_SIDE, .height = BINNED_SIDE, .mode = VKRT_MODE_DEPTH },
                        out_rgba, 4 * n, &st);
        *out_binned = st.rays_binned;
    } else {
        vkrt_trace_stats st = { 0 };
        r = vkrt_trace_rays(ctx, s, &(vkrt_trace_desc){ .out_stats = &st }, rays, n, out_hits);
        *out_binned = st.rays_binned;
    }
    return r;
}

/* Host allocation N, then device allocation N, fails (N = 1, 2, ... until no allocation is left
 * to fail) in a render and a trace call that the binned traversal takes: where the failure is
 * in the lists (the plan's arrays, its threads, the entries' buffer), the BVH takes the rays
 * and the call gives the same image or hits; elsewhere the call fails with the out-of-memory
 * code. Either way nothing is leaked. */
static void binned_lists_without_memory_leave_the_rays_to_the_bvh(void)
{
    const size_t n = (size_t)BINNED_SIDE * BINNED_SIDE;
    vkrt_scene *s;
    vkrt_context *ctx = warm_bunny_context(&s);
    if (!ctx) return;
    vk_context *vk = ctx->vk;
    vkrt_result r;
    vkrt_ray *rays = malloc(n * sizeof *rays);
    vkrt_hit *hits = malloc(n * sizeof *hits), *want_hits = malloc(n * sizeof *want_hits);
    float *rgba = malloc(4 * n * sizeof *rgba), *want_rgba = malloc(4 * n * sizeof *want_rgba);
    CHECK(vkrt_camera_rays(ctx, NULL, BINNED_SIDE, BINNED_SIDE, rays, n) == VKRT_OK);
    for (int render = 0; render < 2; render++) {
        const char *what = render ? "binned render" : "binned trace_rays";
        uint64_t want_binned = 0, binned = 0;
        r = binned_call(ctx, s, render, rays, want_rgba, want_hits, &want_binned);
        CHECK_MSG(r == VKRT_OK && want_binned > 0, "%s: %s, %" PRIu64 " rays through lists", what,
                  vkrt_context_last_error(ctx), want_binned);
        if (r != VKRT_OK || want_binned == 0) continue;
        for (int device = 0; device < 2; device++) {
            long k, fallbacks = 0, failures = 0;
            for (k = 1;; k++) {
                const long blocks = live_blocks;
                const VkDeviceSize held = vk->memory_in_use;
                alloc_calls = 0;
                if (device) vk->fail_allocation = (uint32_t)k;
                else alloc_fail_at = k;
                r = binned_call(ctx, s, render, rays, rgba, hits, &binned);
                const bool fired = device ? vk->fail_allocation == 0 : alloc_calls >= k;
                vk->fail_allocation = 0;
                alloc_fail_at = 0;
                const bool same = render ? memcmp(rgba, want_rgba, 4 * n * sizeof *rgba) == 0
                                         : memcmp(hits, want_hits, n * sizeof *hits) == 0;
                if (!fired) {
                    CHECK_MSG(r == VKRT_OK && binned == want_binned && same, "%s after %ld allocations: %s", what, k - 1,
                              vkrt_result_string(r));
                    break;
                }
                if (r == VKRT_OK) {
                    CHECK_MSG(binned == 0 && same, "%s, %s allocation %ld failed and the call went on: %" PRIu64
                              " rays through lists, output the same: %d", what, device ? "device" : "host", k, binned, same);
                    fallbacks++;
                } else {
                    CHECK_MSG(r == (device ? VKRT_ERROR_OUT_OF_DEVICE_MEMORY : VKRT_ERROR_OUT_OF_MEMORY),
                              "%s, %s allocation %ld failed: %s", what, device ? "device" : "host", k, vkrt_result_string(r));
                    failures++;
                }
                CHECK_MSG(live_blocks == blocks && vk->memory_in_use == held,
                          "%s, %s allocation %ld: %ld host blocks more, device memory %llu (was %llu)", what,
                          device ? "device" : "host", k, live_blocks - blocks, (unsigned long long)vk->memory_in_use,
                          (unsigned long long)held);
            }
            fprintf(stderr, "  %s: %ld %s allocations; %ld failures left the rays to the BVH, %ld failed the call\n", what,
                    k - 1, device ? "device" : "host", fallbacks, failures);
            /* The plan's arrays and threads (host), the entries' buffer (device). */
            CHECK_MSG(fallbacks >= (device ? 1 : 4), "%s: only %ld %s allocation failures fell back", what, fallbacks,
                      device ? "device" : "host");
        }
    }
    free(rays);
    free(hits);
    free(want_hits);
    free(rgba);
    free(want_rgba);
    destroy_and_check_nothing_left(ctx, s);
}

/* `test_scale sizes` runs the cases that hold for any speed of the machine, `test_scale timed`
 * those that measure wall-clock time (submission pacing, how soon a cancel or a lost device is
 * answered), which meson runs with no other test beside them; no argument runs both. */
int main(int argc, char **argv)
{
    const bool sizes = argc < 2 || strcmp(argv[1], "sizes") == 0;
    const bool timed = argc < 2 || strcmp(argv[1], "timed") == 0;
    if (!sizes && !timed) {
        fprintf(stderr, "usage: test_scale [sizes|timed]\n");
        return 2;
    }
    vkrt_context *cpu = NULL;
    int code = check_contexts(on_log, &gpu, &cpu);
    if (code) return code;
    vkrt_context_destroy(cpu); /* the references are traced over the GPU scenes' host arrays */
    if (sizes) {
        RUN(split_scene_renders_as_one_buffer);
        RUN(split_spatial_split_scene_renders_as_one_buffer);
        RUN(split_scene_lights_as_one_buffer);
        RUN(ten_million_triangles_match_the_cpu_reference);
        RUN(device_memory_of_a_call_is_reused_by_the_next);
        RUN(small_memory_budget_fails_cleanly);
        RUN(binary_arrays_beyond_the_budget_fail_alone);
        RUN(every_failed_device_allocation_is_out_of_device_memory);
        RUN(every_failed_host_allocation_is_out_of_memory);
        RUN(binned_lists_without_memory_leave_the_rays_to_the_bvh);
    }
    if (timed) {
        RUN(smallest_submissions_give_identical_results);
        RUN(progress_cancels_within_one_submission);
        RUN(lost_device_is_reported_and_final);
    }
    CHECK_EQ_U64(vkrt_context_validation_messages(gpu), 0);
    CHECK_EQ_U64(log_errors, 0);
    vkrt_context_destroy(gpu);
    return check_exit();
}
