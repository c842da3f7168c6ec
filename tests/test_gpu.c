/* The Vulkan path on the device (lavapipe in CI), validation layer on: every pipeline
 * variant compiles and runs, the GPU agrees with the C reference, BVH and naive traversal give
 * identical images, tiling is seamless. Any validation message fails the test. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "camera.h"
#include "check.h"
#include "context.h"
#include "cpu_trace.h"
#include "huge_pages.h"
#include "ray_bin.h"
#include "ray_cull.h"
#include "ray_offset.h"
#include "shaders_embedded.h"
#include "trace_fixtures.h"
#include "vk_buffer.h"
#include "vk_pipeline.h"
#include "vkrt.h"

static vkrt_context *gpu, *cpu;

static vkrt_scene *make_scene(vkrt_context *ctx, const char *path, vkrt_bvh_builder builder)
{
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = path, .builder = builder }, &s);
    CHECK_MSG(r == VKRT_OK, "%s: %s", path ? path : "built-in", vkrt_context_last_error(ctx));
    return s;
}

static float *render(vkrt_context *ctx, vkrt_scene *s, const vkrt_render_desc *d)
{
    size_t n = vkrt_render_floats(d->width, d->height);
    float *rgba = malloc(n * sizeof *rgba);
    vkrt_result r = vkrt_render(ctx, s, d, rgba, n, NULL);
    CHECK_MSG(r == VKRT_OK, "render: %s", vkrt_context_last_error(ctx));
    if (r != VKRT_OK) {
        free(rgba);
        return NULL;
    }
    return rgba;
}

typedef struct agreement {
    size_t pixels, same_id, both_hit;
    double max_rel_depth;
} agreement;

/* Compares two id-mode images: r = triangle id or -1, and the depth renders alongside. */
static agreement compare(const float *id_a, const float *id_b, const float *depth_a, const float *depth_b, size_t pixels)
{
    agreement a = { .pixels = pixels };
    for (size_t i = 0; i < pixels; i++) {
        if (id_a[i * 4] == id_b[i * 4]) a.same_id++;
        float da = depth_a[i * 4], db = depth_b[i * 4];
        if (da >= 0 && db >= 0) {
            a.both_hit++;
            double rel = fabs((double)da - (double)db) / fmax((double)db, 1e-30);
            if (rel > a.max_rel_depth) a.max_rel_depth = rel;
        }
    }
    return a;
}

static void gpu_matches_cpu_on(const char *path, vkrt_bvh_builder builder, uint32_t w, uint32_t h)
{
    vkrt_scene *sg = make_scene(gpu, path, builder), *sc = make_scene(cpu, path, builder);
    if (!sg || !sc) goto done;
    vkrt_render_desc d = { .width = w, .height = h, .mode = VKRT_MODE_ID };
    float *gid = render(gpu, sg, &d), *cid = render(cpu, sc, &d);
    d.mode = VKRT_MODE_DEPTH;
    float *gdepth = render(gpu, sg, &d), *cdepth = render(cpu, sc, &d);
    if (gid && cid && gdepth && cdepth) {
        agreement a = compare(gid, cid, gdepth, cdepth, (size_t)w * h);
        double share = (double)a.same_id / (double)a.pixels;
        CHECK_MSG(share >= 0.999, "%s: GPU and CPU ids agree on %.4f%% of pixels", path ? path : "built-in", share * 100);
        CHECK_MSG(a.max_rel_depth <= 1e-5, "%s: max relative depth difference %.3g", path ? path : "built-in",
                  a.max_rel_depth);
        CHECK_MSG(a.both_hit > a.pixels / 20, "%s: only %zu of %zu pixels hit", path ? path : "built-in", a.both_hit,
                  a.pixels);
    }
    free(gid);
    free(cid);
    free(gdepth);
    free(cdepth);
done:
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
}

static void gpu_matches_cpu_reference(void)
{
    gpu_matches_cpu_on(VKRT_MODELS_DIR "/meshes/bunny.obj", VKRT_BVH_BUILDER_BINNED_SAH, 96, 96);
    gpu_matches_cpu_on(VKRT_MODELS_DIR "/meshes/bunny.obj", VKRT_BVH_BUILDER_MIDPOINT, 96, 96);
    gpu_matches_cpu_on(VKRT_MODELS_DIR "/meshes/bunny.obj", VKRT_BVH_BUILDER_SPATIAL_SAH, 96, 96);
    gpu_matches_cpu_on(VKRT_MODELS_DIR "/meshes/dragon_48k.obj", VKRT_BVH_BUILDER_BINNED_SAH, 96, 96);
    gpu_matches_cpu_on(NULL, VKRT_BVH_BUILDER_DEFAULT, 96, 96);
}

/* A size that is no multiple of the 256-pixel tile or the 8x8 workgroup checks the seams. */
static void gpu_tiles_are_seamless(void)
{
    gpu_matches_cpu_on(VKRT_MODELS_DIR "/meshes/teapot.obj", VKRT_BVH_BUILDER_DEFAULT, 300, 261);
}

static void gpu_normal_and_heatmap_match_cpu(void)
{
    vkrt_scene *sg = make_scene(gpu, VKRT_MODELS_DIR "/meshes/bunny.obj", VKRT_BVH_BUILDER_DEFAULT);
    vkrt_scene *sc = make_scene(cpu, VKRT_MODELS_DIR "/meshes/bunny.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!sg || !sc) goto done;
    const uint32_t w = 64, h = 64;
    vkrt_render_desc d = { .width = w, .height = h, .mode = VKRT_MODE_NORMAL };
    float *g = render(gpu, sg, &d), *c = render(cpu, sc, &d);
    size_t close = 0;
    for (size_t i = 0; g && c && i < (size_t)w * h; i++) {
        float dx = g[i * 4] - c[i * 4], dy = g[i * 4 + 1] - c[i * 4 + 1], dz = g[i * 4 + 2] - c[i * 4 + 2];
        if (dx * dx + dy * dy + dz * dz < 1e-6f && g[i * 4 + 3] == c[i * 4 + 3]) close++;
    }
    CHECK_MSG(close >= (size_t)(0.999 * w * h), "normal mode: %zu of %u pixels agree", close, w * h);
    free(g);
    free(c);
    for (vkrt_heat heat = VKRT_HEAT_NODES; heat <= VKRT_HEAT_TRIS; heat++) {
        d.mode = VKRT_MODE_HEATMAP;
        d.heat = heat;
        g = render(gpu, sg, &d);
        c = render(cpu, sc, &d);
        size_t same = 0;
        float max_count = 0;
        for (size_t i = 0; g && c && i < (size_t)w * h; i++) {
            if (g[i * 4] == c[i * 4]) same++;
            if (g[i * 4] > max_count) max_count = g[i * 4];
        }
        CHECK_MSG(same >= (size_t)(0.99 * w * h), "heatmap %d: %zu of %u pixels agree", (int)heat, same, w * h);
        CHECK_MSG(max_count > 1, "heatmap %d: counts never exceed %g", (int)heat, max_count);
        free(g);
        free(c);
    }
done:
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
}

/* dragon_48k has 47,794 triangles: naive traversal runs in several chunks of
 * VKRT_NAIVE_CHUNK_TRIS (six: the first stores its hits, four restore and store, the last
 * restores), which must merge to exactly the BVH's closest hits. 32x32 pixels: each naive
 * render tests 49 million ray-triangle pairs on lavapipe. */
static void gpu_bvh_and_naive_give_identical_images(void)
{
    vkrt_scene *s = make_scene(gpu, VKRT_MODELS_DIR "/meshes/dragon_48k.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    const uint32_t w = 32, h = 32;
    for (int k = 0; k < 4; k++) {
        vkrt_mode mode = k % 2 ? VKRT_MODE_ID : VKRT_MODE_DEPTH;
        vkrt_intersector isect = k < 2 ? VKRT_INTERSECTOR_WATERTIGHT : VKRT_INTERSECTOR_MOLLER_TRUMBORE;
        vkrt_render_desc d = { .width = w, .height = h, .mode = mode, .traversal = VKRT_TRAVERSAL_BVH,
                               .intersector = isect };
        float *b = render(gpu, s, &d);
        d.traversal = VKRT_TRAVERSAL_NAIVE;
        float *n = render(gpu, s, &d);
        if (b && n) {
            size_t hits = 0;
            for (size_t i = 0; i < (size_t)w * h; i++) hits += b[i * 4] >= 0;
            CHECK_MSG(memcmp(b, n, (size_t)w * h * 4 * sizeof(float)) == 0, "mode %d isect %d: BVH and naive images differ",
                      (int)mode, (int)isect);
            CHECK_MSG(hits > (size_t)w * h / 10, "mode %d: only %zu pixels hit", (int)mode, hits);
        }
        free(b);
        free(n);
    }
    vkrt_scene_destroy(s);
}

static void gpu_builtin_scene_renders(void)
{
    vkrt_scene *s = make_scene(gpu, NULL, VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    vkrt_render_desc d = { .width = 64, .height = 64 };
    float *px = render(gpu, s, &d);
    size_t hits = 0, unit = 0;
    for (size_t i = 0; px && i < 64 * 64; i++) {
        if (px[i * 4 + 3] != 1.0f) continue;
        hits++;
        float x = px[i * 4] * 2 - 1, y = px[i * 4 + 1] * 2 - 1, z = px[i * 4 + 2] * 2 - 1;
        if (fabsf(x * x + y * y + z * z - 1.0f) < 1e-3f) unit++;
    }
    CHECK_MSG(hits > 64 * 64 / 4, "built-in scene: only %zu of 4096 pixels hit", hits);
    CHECK_EQ_U64(unit, hits);
    free(px);
    vkrt_scene_destroy(s);
}

/* Every specialisation the CLI can ask for compiles, runs and passes validation. */
static void gpu_every_pipeline_variant_runs(void)
{
    vkrt_scene *s = make_scene(gpu, VKRT_MODELS_DIR "/meshes/teapot.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    for (vkrt_traversal t = VKRT_TRAVERSAL_BVH; t <= VKRT_TRAVERSAL_NAIVE; t++) {
        for (vkrt_mode m = VKRT_MODE_NORMAL; m <= VKRT_MODE_UV; m++) {
            for (vkrt_heat heat = VKRT_HEAT_NODES; heat <= (m == VKRT_MODE_HEATMAP ? VKRT_HEAT_TRIS : VKRT_HEAT_NODES);
                 heat++) {
                vkrt_render_desc d = { .width = 16, .height = 16, .mode = m, .traversal = t, .heat = heat };
                free(render(gpu, s, &d));
            }
        }
    }
    vkrt_scene_destroy(s);
}

static void gpu_render_rejects_bad_arguments(void)
{
    vkrt_scene *s = make_scene(gpu, VKRT_MODELS_DIR "/meshes/teapot.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    float px[16];
    CHECK(vkrt_render(gpu, s, &(vkrt_render_desc){ .width = 2, .height = 2 }, px, 15, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(vkrt_context_last_error(gpu), "out_rgba") != NULL);
    CHECK(vkrt_render(gpu, s, &(vkrt_render_desc){ .width = 2, .height = 2, .mode = 99 }, px, 16, NULL) ==
          VKRT_ERROR_INVALID_ARGUMENT);
    vkrt_render_desc nan_eye = { .width = 2, .height = 2, .camera = { .eye = { NAN, 0, 1 } } };
    CHECK(vkrt_render(gpu, s, &nan_eye, px, 16, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    vkrt_scene_destroy(s);
}

/* Fills `count` words with distinct, ordinary float bit patterns (no NaNs to be canonicalised). */
/* ---- check shaders: a compute shader of shaders/ run once over storage buffers ---- */

/* Buffer i at binding i: data[i] uploaded, or, where data[i] is NULL, a host-readable output. */
static bool create_check_buffers(vk_buffer *buffers, const void *const *data, const size_t *sizes, uint32_t count)
{
    vk_context *vk = gpu->vk;
    bool ok = true;
    for (uint32_t i = 0; i < count && ok; i++) {
        ok = data[i] ? vk_buffer_create(vk, sizes[i], VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                                        VK_MEMORY_DEVICE, "check input", &buffers[i]) == VKRT_OK &&
                           vk_buffer_upload(vk, &buffers[i], data[i], sizes[i]) == VKRT_OK
                     : vk_buffer_create(vk, sizes[i], VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, VK_MEMORY_READBACK,
                                        "check output", &buffers[i]) == VKRT_OK;
    }
    CHECK_MSG(ok, "check buffers: %s", vkrt_context_last_error(gpu));
    return ok;
}

/* Compiles `source`, binds buffers[i] at binding i, pushes `push`, dispatches `groups` x 1 x 1
 * and waits; the host may then read the READBACK buffers (invalidated here). */
static bool run_check_shader(const char *name, const char *source, vk_buffer *buffers, uint32_t count,
                             const void *push, uint32_t push_size, uint32_t groups)
{
    enum { MAX_BINDINGS = 16 };
    vk_context *vk = gpu->vk;
    VkDescriptorSetLayout set_layout = VK_NULL_HANDLE;
    VkPipelineLayout layout = VK_NULL_HANDLE;
    VkShaderModule module = VK_NULL_HANDLE;
    VkPipeline pipeline = VK_NULL_HANDLE;
    VkDescriptorPool pool = VK_NULL_HANDLE;
    uint32_t *spirv = NULL;
    size_t spirv_words = 0;
    bool ok = count <= MAX_BINDINGS && vk_compile_glsl(vk->core, name, source, &spirv, &spirv_words) == VKRT_OK;
    CHECK_MSG(ok, "%s: %s", name, vkrt_context_last_error(gpu));
    if (!ok) return false;
    VkDescriptorSetLayoutBinding b[MAX_BINDINGS];
    for (uint32_t i = 0; i < count; i++)
        b[i] = (VkDescriptorSetLayoutBinding){ i, VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, 1, VK_SHADER_STAGE_COMPUTE_BIT, NULL };
    VkDescriptorSetLayoutCreateInfo sl = { .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO,
                                           .bindingCount = count, .pBindings = b };
    VkPushConstantRange range = { VK_SHADER_STAGE_COMPUTE_BIT, 0, push_size };
    VkShaderModuleCreateInfo mi = { .sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO, .codeSize = spirv_words * 4,
                                    .pCode = spirv };
    VkDescriptorPoolSize ps = { VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, count };
    VkDescriptorPoolCreateInfo pi = { .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO, .maxSets = 1,
                                      .poolSizeCount = 1, .pPoolSizes = &ps };
    ok = vkCreateDescriptorSetLayout(vk->device, &sl, NULL, &set_layout) == VK_SUCCESS;
    VkPipelineLayoutCreateInfo pl = { .sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO, .setLayoutCount = 1,
                                      .pSetLayouts = &set_layout, .pushConstantRangeCount = 1,
                                      .pPushConstantRanges = &range };
    ok = ok && vkCreatePipelineLayout(vk->device, &pl, NULL, &layout) == VK_SUCCESS;
    ok = ok && vkCreateShaderModule(vk->device, &mi, NULL, &module) == VK_SUCCESS;
    VkComputePipelineCreateInfo ci = {
        .sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO,
        .stage = { .sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO, .stage = VK_SHADER_STAGE_COMPUTE_BIT,
                   .module = module, .pName = "main" },
        .layout = layout,
    };
    ok = ok && vkCreateComputePipelines(vk->device, VK_NULL_HANDLE, 1, &ci, NULL, &pipeline) == VK_SUCCESS;
    ok = ok && vkCreateDescriptorPool(vk->device, &pi, NULL, &pool) == VK_SUCCESS;
    VkDescriptorSet set = VK_NULL_HANDLE;
    VkDescriptorSetAllocateInfo ai = { .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO, .descriptorPool = pool,
                                       .descriptorSetCount = 1, .pSetLayouts = &set_layout };
    ok = ok && vkAllocateDescriptorSets(vk->device, &ai, &set) == VK_SUCCESS;
    CHECK_MSG(ok, "%s: pipeline set-up failed", name);
    if (ok) {
        VkDescriptorBufferInfo bi[MAX_BINDINGS];
        VkWriteDescriptorSet w[MAX_BINDINGS];
        for (uint32_t i = 0; i < count; i++) {
            bi[i] = (VkDescriptorBufferInfo){ buffers[i].buffer, 0, VK_WHOLE_SIZE };
            w[i] = (VkWriteDescriptorSet){ .sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET, .dstSet = set, .dstBinding = i,
                                           .descriptorCount = 1, .descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                                           .pBufferInfo = &bi[i] };
        }
        vkUpdateDescriptorSets(vk->device, count, w, 0, NULL);
        VkCommandBuffer cmd;
        ok = vk_commands_begin(vk, &cmd) == VKRT_OK;
        if (ok) {
            vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipeline);
            vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, layout, 0, 1, &set, 0, NULL);
            vkCmdPushConstants(cmd, layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, push_size, push);
            vkCmdDispatch(cmd, groups, 1, 1);
            /* The host reads what the shader wrote. */
            VkMemoryBarrier to_host = { .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
                                        .srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT,
                                        .dstAccessMask = VK_ACCESS_HOST_READ_BIT };
            vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_HOST_BIT, 0, 1, &to_host, 0,
                                 NULL, 0, NULL);
            ok = vk_commands_submit_wait(vk, cmd) == VKRT_OK;
        }
        for (uint32_t i = 0; ok && i < count; i++)
            if (buffers[i].mapped) ok = vk_buffer_invalidate(vk, &buffers[i]) == VKRT_OK;
        CHECK_MSG(ok, "%s: dispatch failed: %s", name, vkrt_context_last_error(gpu));
    }
    if (pool) vkDestroyDescriptorPool(vk->device, pool, NULL);
    if (pipeline) vkDestroyPipeline(vk->device, pipeline, NULL);
    if (module) vkDestroyShaderModule(vk->device, module, NULL);
    if (layout) vkDestroyPipelineLayout(vk->device, layout, NULL);
    if (set_layout) vkDestroyDescriptorSetLayout(vk->device, set_layout, NULL);
    core_free(vk->core, spirv);
    return ok;
}

static void fill_distinct(void *p, size_t bytes, float base)
{
    for (size_t i = 0; i < bytes / 4; i++) {
        float f = base + (float)i;
        memcpy((char *)p + i * 4, &f, 4);
    }
}

/* shaders/layout_check.comp copies every field of element 1 of each shared struct (and of the
 * push constants) out in declaration order; as each struct is 4-byte scalars without padding,
 * the words must equal the C struct's memory word for word. */
static void gpu_shared_layouts_match_c(void)
{
    vkrt_gpu_node nodes[2];
    vkrt_gpu_tri tris[2];
    vkrt_gpu_hit hits[2];
    vkrt_gpu_ray rays[2];
    vkrt_gpu_push push;
    vkrt_gpu_resume states[2];
    vkrt_gpu_stack_entry entries[2];
    vkrt_gpu_counters counters[2];
    vkrt_gpu_surface surfaces[2];
    vkrt_gpu_material materials[2];
    vkrt_gpu_texture textures[2];
    vkrt_gpu_light lights[2];
    vkrt_gpu_lighting lightings[2];
    vkrt_gpu_path paths[2];
    vkrt_gpu_accum accums[2];
    vkrt_gpu_address addresses[2];
    fill_distinct(nodes, sizeof nodes, 100.0f);
    fill_distinct(tris, sizeof tris, 200.0f);
    fill_distinct(hits, sizeof hits, 300.0f);
    fill_distinct(rays, sizeof rays, 350.0f);
    fill_distinct(&push, sizeof push, 400.0f);
    fill_distinct(states, sizeof states, 500.0f);
    fill_distinct(entries, sizeof entries, 600.0f);
    fill_distinct(counters, sizeof counters, 700.0f);
    fill_distinct(surfaces, sizeof surfaces, 800.0f);
    fill_distinct(materials, sizeof materials, 900.0f);
    fill_distinct(textures, sizeof textures, 1000.0f);
    fill_distinct(lights, sizeof lights, 1100.0f);
    fill_distinct(lightings, sizeof lightings, 1200.0f);
    fill_distinct(paths, sizeof paths, 1300.0f);
    fill_distinct(accums, sizeof accums, 1400.0f);
    fill_distinct(addresses, sizeof addresses, 1500.0f);
    enum { PARTS = 16, BUFFERS = 16, MAX_WORDS = 256 };
    /* The order in which layout_check.comp writes the structs out. */
    const void *parts[PARTS] = { &nodes[1],    &tris[1],      &hits[1],     &rays[1],      &push,
                                 &states[1],   &entries[1],   &counters[1], &surfaces[1],  &materials[1],
                                 &textures[1], &lights[1],    &lightings[1], &paths[1],    &accums[1],
                                 &addresses[1] };
    const size_t part_sizes[PARTS] = { sizeof nodes[1],    sizeof tris[1],     sizeof hits[1],      sizeof rays[1],
                                       sizeof push,        sizeof states[1],   sizeof entries[1],   sizeof counters[1],
                                       sizeof surfaces[1], sizeof materials[1], sizeof textures[1], sizeof lights[1],
                                       sizeof lightings[1], sizeof paths[1],   sizeof accums[1],
                                       sizeof addresses[1] };
    uint32_t expected[MAX_WORDS];
    size_t words = 0;
    for (int i = 0; i < PARTS; i++) {
        CHECK(words + part_sizes[i] / 4 <= MAX_WORDS);
        if (words + part_sizes[i] / 4 > MAX_WORDS) return;
        memcpy(expected + words, parts[i], part_sizes[i]);
        words += part_sizes[i] / 4;
    }

    /* Binding 3 receives the words; every other binding is an input. */
    vk_buffer buffers[BUFFERS] = { 0 };
    const void *data[BUFFERS] = { nodes,    tris,     hits,   NULL,   rays,   states, entries, counters,
                                  surfaces, materials, textures, lights, lightings, paths, accums, addresses };
    const size_t sizes[BUFFERS] = { sizeof nodes,     sizeof tris,      sizeof hits,     MAX_WORDS * 4,
                                    sizeof rays,      sizeof states,    sizeof entries,  sizeof counters,
                                    sizeof surfaces,  sizeof materials, sizeof textures, sizeof lights,
                                    sizeof lightings, sizeof paths,     sizeof accums,   sizeof addresses };
    bool ok = create_check_buffers(buffers, data, sizes, BUFFERS);
    ok = ok && run_check_shader("layout_check.comp", vkrt_shader_layout_check_comp, buffers, BUFFERS, &push, sizeof push, 1);
    if (ok) {
        const uint32_t *got = buffers[3].mapped;
        for (size_t i = 0; i < words; i++)
            CHECK_MSG(got[i] == expected[i], "word %zu: shader read 0x%08x, C wrote 0x%08x", i, got[i], expected[i]);
    }
    for (int i = 0; i < BUFFERS; i++) vk_buffer_destroy(gpu->vk, &buffers[i]);
}

/* Runs a check shader over `count` cases: binding 0 the inputs, binding 1 the outputs it
 * writes, the count its push constant. Returns the mapped outputs, or NULL once a check has
 * failed; the caller destroys both buffers either way. */
static const float *run_check_cases(const char *name, const char *source, const float *inputs, size_t in_floats,
                                    size_t out_floats, uint32_t count, vk_buffer buffers[2])
{
    const void *data[2] = { inputs, NULL };
    const size_t sizes[2] = { in_floats * sizeof(float), out_floats * sizeof(float) };
    bool ok = create_check_buffers(buffers, data, sizes, 2);
    ok = ok && run_check_shader(name, source, buffers, 2, &count, sizeof count, (count + 63) / 64);
    return ok ? buffers[1].mapped : NULL;
}

/* ray_offset() in GLSL against the C function, bit for bit, on hit points from 1e-30 to 1e30,
 * zero and negative coordinates, points on both sides of the float/integer switch, and unit
 * normals in every octant and along the axes. */
static void gpu_ray_offset_matches_c(void)
{
    enum { CASES = 4096 };
    float *inputs = malloc(CASES * 6 * sizeof *inputs);
    if (!inputs) abort();
    test_rng rng = { 2024 };
    for (size_t i = 0; i < CASES; i++) {
        double n[3];
        rng_unit_vector(&rng, n);
        if (i % 16 == 0) n[0] = n[1] = n[2] = 0.0, n[i / 16 % 3] = (i / 48) % 2 ? -1.0 : 1.0;
        for (int a = 0; a < 3; a++) {
            double magnitude = pow(10.0, 60.0 * rng_uniform(&rng) - 30.0);
            if (i % 7 == 0) magnitude = VKRT_OFFSET_ORIGIN * (0.5 + rng_uniform(&rng)); /* around the switch */
            if (i % 11 == (size_t)a) magnitude = 0.0;
            inputs[i * 6 + a] = (float)(rng_uniform(&rng) < 0.5 ? -magnitude : magnitude);
            inputs[i * 6 + 3 + a] = (float)n[a];
        }
    }
    vk_buffer buffers[2] = { { 0 } };
    const float *got = run_check_cases("offset_check.comp", vkrt_shader_offset_check_comp, inputs, CASES * 6,
                                       CASES * 3, CASES, buffers);
    if (got) {
        size_t differ = 0, moved = 0;
        for (size_t i = 0; i < CASES; i++) {
            const float *in = inputs + i * 6;
            vkrt_float3 want = ray_offset((vkrt_float3){ in[0], in[1], in[2] }, (vkrt_float3){ in[3], in[4], in[5] });
            const float w[3] = { want.x, want.y, want.z };
            for (int a = 0; a < 3; a++) {
                moved += w[a] != in[a];
                if (memcmp(&w[a], &got[i * 3 + a], sizeof(float)) != 0 && differ++ < 5)
                    fprintf(stderr, "  case %zu axis %d: p %.9g n %.9g: C %.9g, GLSL %.9g\n", i, a, (double)in[a],
                            (double)in[3 + a], (double)w[a], (double)got[i * 3 + a]);
            }
        }
        fprintf(stderr, "  %d cases: %zu coordinates moved by the offset, %zu differ between C and GLSL\n", CASES, moved,
                differ);
        CHECK_MSG(differ == 0, "%zu offset coordinates differ between GLSL and C", differ);
        CHECK_MSG(moved > CASES, "the offset moved only %zu coordinates", moved);
    }
    for (int i = 0; i < 2; i++) vk_buffer_destroy(gpu->vk, &buffers[i]);
    free(inputs);
}

/* The emulated correctly rounded division and square root (shaders/rounding.glsl, which real
 * GPUs run) against C's / and sqrtf, bit for bit: random operands over the normal range
 * (quotients from far below 1 to overflow), operands whose quotient lies within a float
 * rounding of a midpoint, and the IEEE special cases (zeros of both signs, infinities, NaN).
 * And the correction step alone, from a first guess an ulp below and an ulp above the right
 * one: lavapipe's own double division is exact, so only this shows that the step would mend a
 * device whose double division or root is a little off. Denormal operands and results are
 * left out: they are left to the device's double result by design. */
static void gpu_emulated_rounding_matches_c(void)
{
    enum { CASES = 1 << 16 };
    CHECK_MSG(gpu->vk->float64, "the device has no doubles: nothing is emulated");
    if (!gpu->vk->float64) return;
    float *inputs = malloc(CASES * 2 * sizeof *inputs);
    if (!inputs) abort();
    const float specials[] = { 0.0f, -0.0f, INFINITY, -INFINITY, NAN, 1.0f, -1.0f, 3.0f, FLT_MAX, FLT_MIN, 0.1f };
    enum { SPECIALS = sizeof specials / sizeof specials[0] };
    test_rng rng = { 4711 };
    for (size_t i = 0; i < CASES; i++) {
        float a, b;
        if (i < SPECIALS * SPECIALS) {
            a = specials[i / SPECIALS];
            b = specials[i % SPECIALS];
        } else if (i % 2) {
            /* a / b within a float rounding of the midpoint above a random q in [1, 2). */
            b = (float)ldexp(1.0 + rng_uniform(&rng), (int)(rng_uniform(&rng) * 120.0) - 60);
            float q = (float)(1.0 + rng_uniform(&rng));
            double mid = ((double)q + (double)nextafterf(q, 2.0f)) * 0.5;
            a = (float)(mid * b);
        } else {
            a = (float)ldexp(1.0 + rng_uniform(&rng), (int)(rng_uniform(&rng) * 250.0) - 125);
            b = (float)ldexp(1.0 + rng_uniform(&rng), (int)(rng_uniform(&rng) * 250.0) - 125);
            if (fabsf(a / b) < FLT_MIN) b = 1.0f; /* no denormal quotient */
        }
        inputs[2 * i] = rng_uniform(&rng) < 0.5 ? a : -a;
        inputs[2 * i + 1] = rng_uniform(&rng) < 0.5 ? b : -b;
    }
    vk_buffer buffers[2] = { { 0 } };
    const float *got = run_check_cases("rounding_check.comp", vkrt_shader_rounding_check_comp, inputs, CASES * 2,
                                       CASES * 6, CASES, buffers);
    if (got) {
        size_t differ = 0, compared = 0, corrected = 0;
        for (size_t i = 0; i < CASES; i++) {
            const float a = inputs[2 * i], b = inputs[2 * i + 1];
            const float q = fabsf(a) / fabsf(b), s = sqrtf(fabsf(a));
            /* -ffp-contract=off and ISO C: these are IEEE's correctly rounded operations. */
            const float want[6] = { a / b, sqrtf(a), q, q, s, s };
            const bool normal_q = q >= FLT_MIN && q <= 0x1p127f, normal_s = s >= FLT_MIN && s <= 0x1p127f;
            const bool used[6] = { true, true, normal_q, normal_q, normal_s, normal_s };
            for (int k = 0; k < 6; k++) {
                if (!used[k]) continue;
                const float g = got[i * 6 + k];
                bool same = (isnan(g) && isnan(want[k])) || memcmp(&g, &want[k], sizeof g) == 0;
                compared++;
                corrected += k >= 2 && same;
                if (!same && differ++ < 5)
                    fprintf(stderr, "  case %zu output %d: a %.9g b %.9g: C %.9g, GLSL %.9g\n", i, k, (double)a,
                            (double)b, (double)want[k], (double)g);
            }
        }
        fprintf(stderr, "  %d cases: %zu results compared (%zu from a guess an ulp off), %zu differ\n", CASES,
                compared, corrected, differ);
        CHECK_MSG(differ == 0, "%zu emulated results differ from C's", differ);
        CHECK_MSG(corrected > CASES, "only %zu results from a guess an ulp off were compared", corrected);
    }
    for (int i = 0; i < 2; i++) vk_buffer_destroy(gpu->vk, &buffers[i]);
    free(inputs);
}

/* The detector behind every other test: a deliberate misuse (a buffer with no usage flags,
 * VUID-VkBufferCreateInfo-usage-requiredbitmask) must reach the count. */
static void gpu_validation_messages_are_counted(void)
{
    vkrt_context *probe = NULL;
    unsigned before = check_validation_logged;
    vkrt_context_desc desc = { .backend = VKRT_BACKEND_GPU, .validation = true, .log = check_gpu_log };
    CHECK(vkrt_context_create(&desc, &probe) == VKRT_OK);
    if (!probe) return;
    fprintf(stderr, "  (one validation error expected next)\n");
    VkBufferCreateInfo info = { .sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO, .size = 64, .usage = 0 };
    VkBuffer buffer = VK_NULL_HANDLE;
    vkCreateBuffer(probe->vk->device, &info, NULL, &buffer);
    if (buffer) vkDestroyBuffer(probe->vk->device, buffer, NULL);
    CHECK(vkrt_context_validation_messages(probe) >= 1);
    vkrt_context_destroy(probe);
    check_validation_logged = before; /* expected: not a failure of this run */
}

/* Random rays into shared meshes: the GPU agrees with the CPU on the prim_id of at least 99.9%
 * of the rays (depth within 1e-5 relative where both hit the same triangle), and GPU BVH and
 * naive traversal agree bit for bit, with either intersector. The bunny takes more rays than
 * one submission holds; dragon_48k's naive traversal runs in several triangle chunks. */
static void gpu_trace_rays_match_cpu_and_naive(void)
{
    const struct {
        const char *path;
        size_t rays;
        bool naive;
    } cases[2] = {
        { VKRT_MODELS_DIR "/meshes/bunny.obj", VKRT_RAY_CHUNK + 4099, false },
        { VKRT_MODELS_DIR "/meshes/dragon_48k.obj", 1500, true },
    };
    for (int k = 0; k < 2; k++) {
        vkrt_scene *sg = make_scene(gpu, cases[k].path, VKRT_BVH_BUILDER_DEFAULT);
        vkrt_scene *sc = make_scene(cpu, cases[k].path, VKRT_BVH_BUILDER_DEFAULT);
        size_t n = cases[k].rays;
        vkrt_ray *rays = random_rays_in_box(n, 4242 + (uint64_t)k);
        for (int isect = VKRT_INTERSECTOR_WATERTIGHT; sg && sc && isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
            vkrt_trace_desc d = { .intersector = (vkrt_intersector)isect };
            vkrt_hit *g = trace_all(gpu, sg, &d, rays, n), *c = trace_all(cpu, sc, &d, rays, n);
            size_t same = 0, hits = 0;
            double max_rel = 0;
            for (size_t i = 0; i < n; i++) {
                if (g[i].prim_id != c[i].prim_id) continue;
                same++;
                if (c[i].prim_id == VKRT_NO_HIT) continue;
                hits++;
                max_rel = fmax(max_rel, fabs((double)g[i].t - c[i].t) / c[i].t);
            }
            fprintf(stderr, "  %s isect %d: GPU = CPU on %zu of %zu rays (%zu hits), max relative t difference %.3g\n",
                    cases[k].path, isect, same, n, hits, max_rel);
            CHECK_MSG(same >= (size_t)(0.999 * n), "%s isect %d: GPU and CPU agree on %zu of %zu rays", cases[k].path,
                      isect, same, n);
            CHECK_MSG(max_rel <= 1e-5, "%s isect %d: relative t difference %.3g", cases[k].path, isect, max_rel);
            CHECK_MSG(hits > n / 10, "%s: only %zu of %zu rays hit", cases[k].path, hits, n);
            if (cases[k].naive) {
                d.traversal = VKRT_TRAVERSAL_NAIVE;
                vkrt_hit *gn = trace_all(gpu, sg, &d, rays, n);
                CHECK_MSG(memcmp(g, gn, n * sizeof *g) == 0, "%s isect %d: GPU BVH and naive hits differ", cases[k].path,
                          isect);
                free(gn);
            }
            free(g);
            free(c);
        }
        free(rays);
        vkrt_scene_destroy(sg);
        vkrt_scene_destroy(sc);
    }
}

/* vkrt_trace_rays through the BVH sends the device only the rays that may enter the scene's
 * box and writes the others' misses on the host (ray_cull.h). Rays from a sphere around the
 * bunny towards points around it, most of them missing its box, a few that must miss (NaN
 * origins, zero directions) and a few too short to reach it, more than a chunk of them: the
 * BVH's closest hits equal naive traversal's, which gets every ray, bit for bit, its any-hit
 * answers naive traversal's (whether, not which), and both the CPU backend's. Rays that all
 * miss: a call with nothing for the device. */
static void gpu_trace_rays_answer_rays_missing_the_scene_box_on_the_host(void)
{
    const char *path = VKRT_MODELS_DIR "/meshes/bunny.obj";
    vkrt_scene *sg = make_scene(gpu, path, VKRT_BVH_BUILDER_DEFAULT);
    vkrt_scene *sc = make_scene(cpu, path, VKRT_BVH_BUILDER_DEFAULT);
    if (!sg || !sc) {
        CHECK(!"scenes");
        vkrt_scene_destroy(sg);
        vkrt_scene_destroy(sc);
        return;
    }
    const size_t n = VKRT_RESUME_RAY_CHUNK + 3001;
    vkrt_ray *rays = calloc(n, sizeof *rays);
    CHECK(rays != NULL);
    test_rng rng = { 31337 };
    size_t enter = 0;
    for (size_t i = 0; rays && i < n; i++) {
        double o[3], target[3];
        rng_unit_vector(&rng, o);
        for (int a = 0; a < 3; a++) target[a] = 1.6 * (rng_uniform(&rng) - 0.5);
        vkrt_ray *r = &rays[i];
        *r = (vkrt_ray){ .origin = { (float)(1.5 * o[0]), (float)(1.5 * o[1]), (float)(1.5 * o[2]) } };
        for (int a = 0; a < 3; a++) r->dir[a] = (float)target[a] - r->origin[a];
        if (i % 97 == 3) r->origin[i % 3] = NAN;
        if (i % 89 == 7) r->dir[0] = r->dir[1] = r->dir[2] = 0.0f;
        if (i % 83 == 11) r->tmax = 0.05f; /* ends before the box */
        enter += cpu_trace_ray_enters_box(r, &sg->bvh.nodes[0]);
    }
    fprintf(stderr, "  %zu of %zu rays may enter the box\n", enter, n);
    CHECK(enter > n / 5 && enter < n - n / 4);
    /* What each call reports (vkrt_trace_stats): the rays the host answered are exactly those
     * that cannot enter the box, on a CPU device through the BVH only. */
    const bool cpu_device = gpu->vk->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
    for (int any = 0; rays && any <= 1; any++) {
        vkrt_trace_stats sg_stats, sc_stats, gn_stats;
        memset(&sg_stats, 0xA5, sizeof sg_stats);
        vkrt_trace_desc d = { .any_hit = any != 0, .out_stats = &sg_stats };
        vkrt_hit *g = trace_all(gpu, sg, &d, rays, n);
        d.out_stats = &sc_stats;
        vkrt_hit *c = trace_all(cpu, sc, &d, rays, n);
        d.traversal = VKRT_TRAVERSAL_NAIVE;
        d.out_stats = &gn_stats;
        vkrt_hit *gn = trace_all(gpu, sg, &d, rays, n);
        fprintf(stderr, "  any hit %d: GPU BVH %llu rays culled, %u submissions, %.2f of %.2f ms on the device\n", any,
                (unsigned long long)sg_stats.rays_culled, sg_stats.submissions, sg_stats.trace_ms, sg_stats.total_ms);
        CHECK_EQ_U64(sg_stats.rays, n);
        CHECK_EQ_U64(sg_stats.rays_culled, cpu_device ? n - enter : 0);
        CHECK_EQ_U64(gn_stats.rays_culled, 0);
        CHECK_EQ_U64(sc_stats.rays_culled, 0);
        const uint32_t chunk = gpu->vk->trace_budget ? VKRT_RESUME_RAY_CHUNK : VKRT_RAY_CHUNK;
        CHECK(sg_stats.submissions >= core_div_up((uint32_t)(n - sg_stats.rays_culled), chunk));
        CHECK(gn_stats.submissions >= core_div_up((uint32_t)n, VKRT_RAY_CHUNK) && sc_stats.submissions == 0);
        CHECK(sg_stats.trace_ms >= 0.0 && sg_stats.trace_ms <= sg_stats.total_ms);
        CHECK(!gpu->vk->timestamps || sg_stats.trace_ms > 0.0);
        CHECK(sc_stats.rays == n && sc_stats.trace_ms > 0.0 && sc_stats.trace_ms <= sc_stats.total_ms);
        size_t hits = 0, same = 0;
        for (size_t i = 0; i < n; i++) {
            hits += g[i].prim_id != VKRT_NO_HIT;
            /* Any hit answers whether, not which. */
            same += any ? (g[i].prim_id == VKRT_NO_HIT) == (c[i].prim_id == VKRT_NO_HIT) : g[i].prim_id == c[i].prim_id;
        }
        fprintf(stderr, "  any hit %d: %zu hits, GPU = CPU on %zu rays\n", any, hits, same);
        CHECK(hits > n / 10);
        CHECK_MSG(memcmp(g, gn, n * sizeof *g) == 0 || any, "GPU BVH and naive closest hits differ");
        size_t same_naive = 0;
        for (size_t i = 0; any && i < n; i++) same_naive += (g[i].prim_id == VKRT_NO_HIT) == (gn[i].prim_id == VKRT_NO_HIT);
        CHECK(!any || same_naive == n);
        CHECK(same >= (size_t)(0.999 * n));
        free(g);
        free(c);
        free(gn);
    }
    /* A call whose rays all miss the box sends the device nothing and answers every ray. */
    vkrt_ray away[5];
    vkrt_hit away_hits[5];
    for (int i = 0; i < 5; i++) away[i] = (vkrt_ray){ .origin = { 0.0f, 0.0f, 2.0f + (float)i }, .dir = { 0.0f, 0.1f * (float)i, 1.0f } };
    memset(away_hits, 0x5A, sizeof away_hits);
    vkrt_trace_stats away_stats;
    CHECK(vkrt_trace_rays(gpu, sg, &(vkrt_trace_desc){ .out_stats = &away_stats }, away, 5, away_hits) == VKRT_OK);
    for (int i = 0; i < 5; i++) CHECK(away_hits[i].t == -1.0f && away_hits[i].prim_id == VKRT_NO_HIT && away_hits[i].u == 0.0f);
    CHECK(away_stats.rays == 5 && away_stats.rays_culled == (cpu_device ? 5u : 0u));
    CHECK(!cpu_device || (away_stats.submissions == 0 && away_stats.trace_ms == 0.0));
    /* No rays: a call that does nothing reports nothing. */
    vkrt_trace_stats none;
    memset(&none, 0xA5, sizeof none);
    CHECK(vkrt_trace_rays(gpu, sg, &(vkrt_trace_desc){ .out_stats = &none }, NULL, 0, NULL) == VKRT_OK);
    CHECK(none.rays == 0 && none.rays_culled == 0 && none.submissions == 0 && none.trace_ms == 0.0);
    free(rays);
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
}

/* The spatial-split BVH (a triangle in several leaves, each box bounding its part) answers
 * every ray as the binned SAH BVH does, on either backend: bit for bit closest hits (prim_id,
 * t, u, v), the same any-hit answers, the same id, depth, normal and albedo images, and naive
 * traversal over its triangle copies the same hits. homer_10k's
 * SBVH holds 22% more references than triangles; rays start inside the box as well as outside. */
static void gpu_spatial_splits_give_the_hits_of_sah(void)
{
    const char *path = VKRT_MODELS_DIR "/meshes/homer_10k.obj";
    vkrt_scene *scenes[2][2] = { { NULL } }; /* [sbvh][cpu] */
    for (int k = 0; k < 2; k++)
        for (int b = 0; b < 2; b++)
            scenes[k][b] = make_scene(b ? cpu : gpu, path, k ? VKRT_BVH_BUILDER_SPATIAL_SAH : VKRT_BVH_BUILDER_BINNED_SAH);
    vkrt_scene_stats st = { 0 };
    if (scenes[1][0] && vkrt_scene_stats_get(scenes[1][0], &st) == VKRT_OK)
        CHECK_MSG(st.bvh_references > st.triangles + st.triangles / 10, "%llu references for %llu triangles",
                  (unsigned long long)st.bvh_references, (unsigned long long)st.triangles);
    const size_t n = 20000;
    vkrt_ray *rays = random_rays_in_box(n, 977);
    for (int b = 0; b < 2 && scenes[0][0] && scenes[0][1] && scenes[1][0] && scenes[1][1]; b++) {
        vkrt_context *ctx = b ? cpu : gpu;
        const char *backend = b ? "cpu" : "gpu";
        for (int any = 0; any < 2; any++) {
            vkrt_trace_desc d = { .any_hit = any != 0 };
            vkrt_hit *sah = trace_all(ctx, scenes[0][b], &d, rays, n), *sbvh = trace_all(ctx, scenes[1][b], &d, rays, n);
            size_t same = 0, hits = 0;
            for (size_t i = 0; i < n; i++) {
                hits += sah[i].prim_id != VKRT_NO_HIT;
                same += any ? (sah[i].prim_id == VKRT_NO_HIT) == (sbvh[i].prim_id == VKRT_NO_HIT)
                            : memcmp(&sah[i], &sbvh[i], sizeof sah[i]) == 0;
            }
            fprintf(stderr, "  %s %s: sbvh = sah on %zu of %zu rays (%zu hit)\n", backend, any ? "any hit" : "closest",
                    same, n, hits);
            CHECK_MSG(same == n, "%s %s: sbvh and sah differ on %zu of %zu rays", backend, any ? "any hit" : "closest",
                      n - same, n);
            CHECK_MSG(hits > n / 20, "%s: only %zu of %zu rays hit", backend, hits, n);
            if (!any && !b) {
                d.traversal = VKRT_TRAVERSAL_NAIVE;
                vkrt_hit *naive = trace_all(ctx, scenes[1][b], &d, rays, n);
                CHECK_MSG(memcmp(naive, sbvh, n * sizeof *naive) == 0, "gpu: sbvh naive and BVH hits differ");
                free(naive);
            }
            free(sah);
            free(sbvh);
        }
        /* Albedo reads the surfaces, one per prim_id: fewer than the SBVH's triangle copies. */
        const vkrt_mode modes[4] = { VKRT_MODE_ID, VKRT_MODE_DEPTH, VKRT_MODE_NORMAL, VKRT_MODE_ALBEDO };
        const char *const mode_names[4] = { "id", "depth", "normal", "albedo" };
        for (int mode = 0; mode < 4; mode++) {
            vkrt_render_desc rd = { .width = 64, .height = 64, .mode = modes[mode] };
            float *a = render(ctx, scenes[0][b], &rd), *c = render(ctx, scenes[1][b], &rd);
            CHECK_MSG(a && c && memcmp(a, c, (size_t)64 * 64 * 4 * sizeof *a) == 0, "%s: sbvh and sah %s images differ",
                      backend, mode_names[mode]);
            free(a);
            free(c);
        }
    }
    free(rays);
    for (int k = 0; k < 2; k++)
        for (int b = 0; b < 2; b++) vkrt_scene_destroy(scenes[k][b]);
}

/* How many of the rays the wide and the binary BVH answer differently: the whole hit for
 * closest-hit queries, whether it hits for any-hit ones; *out_hits counts the binary's hits. */
static size_t wide_and_binary_differences(vkrt_scene *wide, vkrt_scene *binary, const vkrt_trace_desc *d,
                                          const vkrt_ray *rays, size_t n, size_t *out_hits)
{
    vkrt_hit *w = trace_all(gpu, wide, d, rays, n), *b = trace_all(gpu, binary, d, rays, n);
    size_t differ = 0, hits = 0;
    for (size_t i = 0; i < n; i++) {
        hits += b[i].prim_id != VKRT_NO_HIT;
        differ += d->any_hit ? (w[i].prim_id == VKRT_NO_HIT) != (b[i].prim_id == VKRT_NO_HIT)
                             : memcmp(&w[i], &b[i], sizeof w[i]) != 0;
    }
    free(w);
    free(b);
    *out_hits = hits;
    return differ;
}

/* The wide BVH through texel buffers (the default wherever a scene fits one buffer per array)
 * against the binary BVH it was collapsed from (the test knob keeps a scene to it): the same
 * closest hits bit for bit, ray arrays (VKRT_WIDE_RAYS_PER_LANE rays per invocation, more than
 * one submission) and renders alike, and any-hit queries hit where the binary traversal's do.
 * Its arrays (nodes and whole triangles) take at most 64 bytes a triangle (issue 7's memory
 * bound), fewer than the binary BVH's. */
static void gpu_wide_traversal_matches_the_binary_one(void)
{
    const char *path = VKRT_MODELS_DIR "/meshes/dragon_48k.obj";
    vkrt_scene *wide = make_scene(gpu, path, VKRT_BVH_BUILDER_DEFAULT);
    gpu->vk->no_wide_traversal = true;
    vkrt_scene *binary = make_scene(gpu, path, VKRT_BVH_BUILDER_DEFAULT);
    gpu->vk->no_wide_traversal = false;
    if (!wide || !binary) goto done;
    CHECK_MSG(wide->gpu.wide && !binary->gpu.wide, "wide arrays uploaded: %d and %d", wide->gpu.wide, binary->gpu.wide);
    vkrt_scene_stats ws, bs;
    CHECK(vkrt_scene_stats_get(wide, &ws) == VKRT_OK && vkrt_scene_stats_get(binary, &bs) == VKRT_OK);
    const double wide_bytes = (double)ws.traversal_bytes / (double)ws.triangles;
    const double binary_bytes = (double)bs.traversal_bytes / (double)bs.triangles;
    fprintf(stderr, "  traversal arrays: wide %.1f, binary %.1f bytes a triangle\n", wide_bytes, binary_bytes);
    CHECK_MSG(wide_bytes > 40.0 && wide_bytes <= 64.0 && wide_bytes < binary_bytes,
              "wide arrays %.1f bytes a triangle (binary %.1f)", wide_bytes, binary_bytes);
    /* The binary scene holds its arrays from the start; the wide one holds the wide arrays (and
     * one-element placeholders) until a call reads the binary ones. */
    CHECK_MSG(ws.device_buffers == 0 && bs.device_buffers == 2, "binary arrays' buffers: wide %u, binary %u",
              ws.device_buffers, bs.device_buffers);
    const size_t n = VKRT_RAY_CHUNK + 777;
    vkrt_ray *rays = random_rays_in_box(n, 99);
    /* Every fourth ray parallel to one or two axes (+-0 components) with its origin on box
     * planes in them: vertex coordinates, as the binary boxes' bounds are, where its slab test
     * takes its branch for 0 * inf. The wide nodes' quantised planes seldom fall on them (a
     * broken handling of their 0 * inf changed no hit here):
     * gpu_wide_boxes_hold_rays_along_their_planes tests that. The hits must be the same. */
    vkrt_scene_stats st = { 0 };
    float *pos = NULL;
    if (vkrt_scene_stats_get(wide, &st) == VKRT_OK && (pos = malloc(st.triangles * 9 * sizeof *pos)) &&
        vkrt_scene_triangles_get(wide, pos, st.triangles * 9) == VKRT_OK) {
        test_rng rng = { 1234 };
        for (size_t i = 0; i < n; i += 4) {
            const int axis = (int)(rng_uniform(&rng) * 3) % 3, both = rng_uniform(&rng) < 0.5;
            for (int a = 0; a < 3; a++) {
                const float v = pos[(size_t)(rng_uniform(&rng) * (double)st.triangles) % st.triangles * 9 +
                                    (size_t)(rng_uniform(&rng) * 3) % 3 * 3 + a];
                const bool zero = a != axis && (both || a == (axis + 1) % 3);
                rays[i].origin[a] = zero ? v : (rng_uniform(&rng) < 0.5 ? -0.7f : 0.7f);
                rays[i].dir[a] = zero ? (rng_uniform(&rng) < 0.5 ? 0.0f : -0.0f)
                                      : (rays[i].origin[a] > 0 ? -1.0f : 1.0f) * (float)(0.2 + rng_uniform(&rng));
            }
            rays[i].tmax = 0.0f;
        }
    }
    free(pos);
    for (int any = 0; any < 2; any++)
        for (int isect = VKRT_INTERSECTOR_WATERTIGHT; isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
            vkrt_trace_desc d = { .intersector = (vkrt_intersector)isect, .any_hit = any };
            size_t hits, differ = wide_and_binary_differences(wide, binary, &d, rays, n, &hits);
            fprintf(stderr, "  any hit %d, isect %d: %zu of %zu rays differ (%zu hits)\n", any, isect, differ, n, hits);
            CHECK_MSG(differ == 0 && hits > n / 10, "any hit %d, isect %d: %zu of %zu rays differ", any, isect, differ, n);
        }
    free(rays);
    /* Rays traced through the wide BVH alone: the scene's device memory is still within issue
     * 7's 64 bytes a triangle. */
    vkrt_scene_stats traced;
    CHECK(vkrt_scene_stats_get(wide, &traced) == VKRT_OK);
    const double device_bytes = (double)traced.device_bytes / (double)traced.triangles;
    fprintf(stderr, "  device memory after the traces: %.1f bytes a triangle (binary scene %.1f)\n", device_bytes,
            (double)bs.device_bytes / (double)bs.triangles);
    CHECK_MSG(traced.device_buffers == 0 && device_bytes <= 64.0, "after the traces: %u buffers, %.1f bytes a triangle",
              traced.device_buffers, device_bytes);
    for (vkrt_mode m = VKRT_MODE_NORMAL; m <= VKRT_MODE_ID; m++) {
        if (m == VKRT_MODE_HEATMAP) continue; /* the binary BVH's steps, whichever the scene has */
        vkrt_render_desc rd = { .width = 96, .height = 80, .mode = m };
        float *a = render(gpu, wide, &rd), *c = render(gpu, binary, &rd);
        CHECK_MSG(a && c && memcmp(a, c, vkrt_render_floats(96, 80) * sizeof *a) == 0, "mode %d: images differ", (int)m);
        free(a);
        free(c);
    }
    /* Normals and depth read the shading triangles; no render here read the binary nodes. */
    CHECK(vkrt_scene_stats_get(wide, &traced) == VKRT_OK);
    CHECK_MSG(traced.device_buffers == 1 && traced.device_bytes >= ws.traversal_bytes + traced.triangle_bytes,
              "after the renders: %u buffers, %" PRIu64 " bytes", traced.device_buffers, traced.device_bytes);
done:
    vkrt_scene_destroy(wide);
    vkrt_scene_destroy(binary);
}

static void gpu_trace_rays_follow_the_documented_rules(void)
{
    check_ray_rules_on(gpu, VKRT_PRECISION_FLOAT, "gpu");
}

static void gpu_watertight_never_misses_shared_edges_and_vertices(void)
{
    check_watertight_on(gpu, VKRT_PRECISION_FLOAT, "gpu");
}

static void gpu_grazing_hit_distances_are_exact(void)
{
    check_grazing_distances_on(gpu, cpu, "gpu");
}

static void gpu_secondary_rays_never_rehit_their_own_triangle(void)
{
    check_no_self_intersection_on(gpu, "gpu");
}

static void gpu_camera_rays_hit_what_the_render_shows_on_exported_triangles(void)
{
    check_camera_rays_and_triangles_on(gpu, "gpu");
}

/* A scene of its own positions and indices, in world coordinates. */
static vkrt_scene *mesh_scene(vkrt_context *ctx, const float *pos, uint32_t vertices, const uint32_t *idx,
                              uint32_t tris, vkrt_bvh_builder builder)
{
    vkrt_mesh_desc md = { .positions = pos, .vertex_count = vertices, .indices = idx, .index_count = tris * 3 };
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(
        ctx, &(vkrt_scene_desc){ .meshes = &md, .mesh_count = 1, .keep_world_coordinates = true, .builder = builder },
        &s);
    CHECK_MSG(r == VKRT_OK, "in-memory scene: %s", vkrt_context_last_error(ctx));
    return s;
}

/* The host's lists turn away the ray sets they do not suit, each for its reason. */
static void ray_bin_says_why_rays_do_not_suit(void)
{
    vkrt_scene *s = make_scene(cpu, VKRT_MODELS_DIR "/meshes/dragon_11k.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    const uint32_t w = 128, h = 96, n = w * h;
    vkrt_ray *rays = malloc((size_t)n * sizeof *rays);
    const vkrt_gpu_node box = { .bmin = { -0.5f, -0.5f, -0.5f }, .bmax = { 0.5f, 0.5f, 0.5f } };
    const struct {
        vkrt_camera camera;
        ray_bin_limits limits;
        ray_bin_outcome expected;
        const char *what;
    } cases[] = {
        { { .fov_y_degrees = 0.0f }, { 16u * n, 4096 }, RAY_BIN_BUILT, "the default view" },
        { { .fov_y_degrees = 0.0f }, { 1000, 4096 }, RAY_BIN_TOO_LONG, "entries past the limit" },
        { { .fov_y_degrees = 0.0f }, { 16u * n, 2 }, RAY_BIN_TOO_LONG, "a list past the limit" },
        { { .eye = { 0.0f, 0.0f, 0.1f }, .target = { 0.0f, 0.0f, -1.0f } }, { 16u * n, 4096 }, RAY_BIN_BEHIND,
          "an eye inside the box" },
        { { .eye = { 0.0f, 0.0f, 1.5f }, .target = { 1.5f, 0.0f, 0.0f }, .fov_y_degrees = 4.0f },
          { 16u * n, 4096 },
          RAY_BIN_NONE_ENTER,
          "rays beside the box" },
    };
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        CHECK(vkrt_camera_rays(cpu, &cases[k].camera, w, h, rays, n) == VKRT_OK);
        ray_bins bins;
        ray_bin_outcome outcome;
        CHECK(ray_bin_plan(&s->ctx->core, NULL, rays, n, s->tris, s->bvh.tri_count, &box, cases[k].limits, 2, &bins,
                           &outcome) == VKRT_OK);
        CHECK_MSG(outcome == cases[k].expected, "%s: outcome %d, expected %d", cases[k].what, (int)outcome,
                  (int)cases[k].expected);
        CHECK_MSG((outcome == RAY_BIN_BUILT) == (bins.job != NULL), "%s: plan left %s", cases[k].what,
                  bins.job ? "state" : "none");
        ray_bins_destroy(&s->ctx->core, &bins);
    }
    /* Rays from many origins. */
    vkrt_ray *random = random_rays_in_box(n, 3);
    ray_bins bins;
    ray_bin_outcome outcome;
    CHECK(ray_bin_plan(&s->ctx->core, NULL, random, n, s->tris, s->bvh.tri_count, &box, (ray_bin_limits){ 16u * n, 4096 },
                       2, &bins, &outcome) == VKRT_OK &&
          outcome == RAY_BIN_ORIGINS_DIFFER);
    ray_bins_destroy(&s->ctx->core, &bins);
    free(random);
    /* One origin is asked only of rays that may enter the box: the default view's rays, the
     * first 300 of them moved elsewhere and turned away from it, list as the view's, and those
     * 300 get no list. */
    CHECK(vkrt_camera_rays(cpu, NULL, w, h, rays, n) == VKRT_OK);
    for (uint32_t i = 0; i < 300; i++) {
        rays[i].origin[0] = rays[i].origin[1] = rays[i].origin[2] = 2.0f;
        rays[i].dir[0] = 1.0f;
        rays[i].dir[1] = rays[i].dir[2] = 0.0f;
    }
    CHECK(ray_bin_plan(&s->ctx->core, NULL, rays, n, s->tris, s->bvh.tri_count, &box, (ray_bin_limits){ 16u * n, 4096 },
                       2, &bins, &outcome) == VKRT_OK);
    CHECK_MSG(outcome == RAY_BIN_BUILT, "rays turned away from elsewhere first: outcome %d", (int)outcome);
    if (outcome == RAY_BIN_BUILT) {
        uint32_t listed = 0;
        for (uint32_t i = 0; i < 300; i++) listed += bins.ray_cell[i] != RAY_BIN_NO_CELL;
        CHECK_EQ_U64(listed, 0);
    }
    ray_bins_destroy(&s->ctx->core, &bins);
    free(rays);
    vkrt_scene_destroy(s);
}

/* n rays (a multiple of 4) from `eye`: a third aimed at points all but on the surface of `box`
 * (its corners, edges and faces, each moved by 0 to 1e-3 of its largest side in a random
 * direction), a third at points 0.05 to 0.3 of that off its faces, a third within it; an eighth
 * of them short, a few with a NaN tmin or tmax, or a tmin past the box. */
static vkrt_ray *rays_about_a_box(const float eye[3], const vkrt_gpu_node *box, size_t n, uint64_t seed)
{
    vkrt_ray *rays = calloc(n, sizeof *rays);
    if (!rays) abort();
    test_rng rng = { seed };
    const float lo[3] = { box->bmin.x, box->bmin.y, box->bmin.z }, hi[3] = { box->bmax.x, box->bmax.y, box->bmax.z };
    const double offsets[] = { 0.0, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3 };
    double side_max = 0.0;
    for (int a = 0; a < 3; a++) side_max = fmax(side_max, (double)hi[a] - lo[a]);
    for (size_t i = 0; i < n; i++) {
        double target[3];
        const int kind = (int)(i % 3), axis = (int)(rng_uniform(&rng) * 3.0) % 3, side = rng_uniform(&rng) < 0.5;
        for (int a = 0; a < 3; a++) {
            double u = rng_uniform(&rng);
            if (kind == 0 && rng_uniform(&rng) < 0.4) u = u < 0.5 ? 0.0 : 1.0; /* an edge or a corner */
            target[a] = lo[a] + u * (hi[a] - lo[a]);
        }
        if (kind < 2) target[axis] = side ? hi[axis] : lo[axis];
        if (kind == 0) {
            const double off = offsets[(int)(rng_uniform(&rng) * 6.0) % 6];
            for (int a = 0; a < 3; a++) target[a] += off * side_max * (2.0 * rng_uniform(&rng) - 1.0);
        } else if (kind == 1) {
            target[axis] += (side ? 1.0 : -1.0) * (0.05 + 0.25 * rng_uniform(&rng)) * side_max;
        }
        for (int a = 0; a < 3; a++) {
            rays[i].origin[a] = eye[a];
            rays[i].dir[a] = (float)(target[a] - eye[a]);
        }
        const double v = rng_uniform(&rng);
        if (v < 0.125) rays[i].tmax = (float)(0.1 + 0.5 * rng_uniform(&rng));
        else if (v < 0.15) rays[i].tmin = NAN;
        else if (v < 0.175) rays[i].tmax = NAN;
        else if (v < 0.2) rays[i].tmin = 5.0f;
    }
    return rays;
}

/* A ray from the shared origin gets a cell wherever the box test lets it into the scene's box
 * (ray_cull_test4, as the BVH's first step), however near the box's edges it passes and whatever
 * the box's size and place; and where it passes well beside the box (here a view of one face,
 * whose projection is the box's), none. */
static void ray_bin_gives_a_cell_to_every_ray_the_box_test_lets_in(void)
{
    vkrt_scene *s = make_scene(cpu, VKRT_MODELS_DIR "/meshes/dragon_11k.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    const vkrt_gpu_node box = { .bmin = { -0.5f, -0.5f, -0.5f }, .bmax = { 0.5f, 0.5f, 0.5f } };
    const vkrt_gpu_node grown = { .bmin = { -0.55f, -0.55f, -0.55f }, .bmax = { 0.55f, 0.55f, 0.55f } };
    const float eyes[][3] = { { 0.0f, 0.0f, 1.5f }, { -1.1f, 0.7f, 0.3f }, { 0.9f, 0.4f, -0.8f }, { 0.3f, -2.5f, 0.2f } };
    const size_t n = 6000;
    for (size_t e = 0; e < sizeof eyes / sizeof eyes[0]; e++) {
        vkrt_ray *rays = rays_about_a_box(eyes[e], &box, n, 100 + e);
        ray_bins bins;
        ray_bin_outcome outcome;
        CHECK(ray_bin_plan(&s->ctx->core, NULL, rays, (uint32_t)n, s->tris, s->bvh.tri_count, &box,
                           (ray_bin_limits){ UINT32_MAX, UINT32_MAX }, 2, &bins, &outcome) == VKRT_OK);
        CHECK_MSG(outcome == RAY_BIN_BUILT, "eye %zu: outcome %d", e, (int)outcome);
        if (outcome == RAY_BIN_BUILT) {
            size_t let_in = 0, without = 0, beside = 0, beside_with = 0;
            for (size_t i = 0; i < n; i += 4) {
                /* Beside the box whatever the rays' bounds: */
                vkrt_ray whole[4];
                memcpy(whole, &rays[i], sizeof whole);
                for (int l = 0; l < 4; l++) whole[l].tmin = whole[l].tmax = 0.0f;
                const unsigned in = ray_cull_test4(&rays[i], &box), near = ray_cull_test4(whole, &grown);
                for (unsigned l = 0; l < 4; l++) {
                    const bool cell = bins.ray_cell[i + l] != RAY_BIN_NO_CELL;
                    let_in += in >> l & 1;
                    without += (in >> l & 1) && !cell;
                    beside += !(near >> l & 1);
                    beside_with += !(near >> l & 1) && cell;
                }
            }
            fprintf(stderr, "  eye %zu: %zu of %zu rays let into the box, %zu pass beside it\n", e, let_in, n, beside);
            CHECK_MSG(let_in > n / 4 && without == 0, "eye %zu: %zu of %zu rays the box test lets in have no cell", e,
                      without, let_in);
            if (e == 0)
                CHECK_MSG(beside > n / 40 && beside_with == 0, "eye 0: %zu of %zu rays well beside the box have a cell",
                          beside_with, beside);
        }
        ray_bins_destroy(&s->ctx->core, &bins);
        free(rays);
    }
    /* Boxes from 1e-6 to 1e6 across, up to 1e6 from the world's origin, eyes from just outside
     * them (the box all but reaching the eye's plane, where the projection's bounds grow widest)
     * to far off, a few triangles in each. */
    test_rng rng = { 4242 };
    size_t planned = 0, let_in = 0, without = 0;
    for (int k = 0; k < 200; k++) {
        const double size = pow(10.0, 12.0 * rng_uniform(&rng) - 6.0);
        float lo[3], hi[3], eye[3];
        for (int a = 0; a < 3; a++) {
            const double at = rng_uniform(&rng) < 0.5 ? 0.0 : (2.0 * rng_uniform(&rng) - 1.0) * pow(10.0, 6.0 * rng_uniform(&rng));
            lo[a] = (float)(at - size * (0.01 + rng_uniform(&rng)));
            hi[a] = (float)(at + size * (0.01 + rng_uniform(&rng)));
        }
        double dir[3];
        rng_unit_vector(&rng, dir);
        const double reach = size * (k % 2 ? 1.0 + 0.6 * rng_uniform(&rng) : 1.5 + 10.0 * rng_uniform(&rng));
        for (int a = 0; a < 3; a++) eye[a] = (float)(0.5 * ((double)lo[a] + hi[a]) + dir[a] * reach);
        const vkrt_gpu_node b = { .bmin = { lo[0], lo[1], lo[2] }, .bmax = { hi[0], hi[1], hi[2] } };
        vkrt_gpu_tri tris[16];
        memset(tris, 0, sizeof tris);
        for (int t = 0; t < 16; t++) {
            vkrt_float3 *v[3] = { &tris[t].v0, &tris[t].v1, &tris[t].v2 };
            for (int c = 0; c < 3; c++) {
                v[c]->x = lo[0] + (float)rng_uniform(&rng) * (hi[0] - lo[0]);
                v[c]->y = lo[1] + (float)rng_uniform(&rng) * (hi[1] - lo[1]);
                v[c]->z = lo[2] + (float)rng_uniform(&rng) * (hi[2] - lo[2]);
            }
        }
        const size_t m = 1024;
        vkrt_ray *rays = rays_about_a_box(eye, &b, m, 500 + (uint64_t)k);
        ray_bins bins;
        ray_bin_outcome outcome;
        CHECK(ray_bin_plan(&s->ctx->core, NULL, rays, (uint32_t)m, tris, 16, &b, (ray_bin_limits){ UINT32_MAX, UINT32_MAX },
                           2, &bins, &outcome) == VKRT_OK);
        if (outcome == RAY_BIN_BUILT) {
            planned++;
            for (size_t i = 0; i < m; i += 4) {
                const unsigned in = ray_cull_test4(&rays[i], &b);
                for (unsigned l = 0; l < 4; l++) {
                    let_in += in >> l & 1;
                    without += (in >> l & 1) && bins.ray_cell[i + l] == RAY_BIN_NO_CELL;
                }
            }
        }
        ray_bins_destroy(&s->ctx->core, &bins);
        free(rays);
    }
    fprintf(stderr, "  boxes of every size: %zu of 200 planned, %zu rays let in\n", planned, let_in);
    CHECK_MSG(planned > 150 && let_in > planned * 500 && without == 0,
              "boxes of every size: %zu of %zu rays the box test lets in have no cell (%zu planned)", without, let_in,
              planned);
    vkrt_scene_destroy(s);
}

/* ray_bin_plan_camera, which makes a camera's rays as it reads them, lists exactly as
 * ray_bin_plan does from the rays vkrt_camera_rays makes: the same cells, lists and entries. */
static void ray_bin_camera_plan_lists_as_the_camera_rays_do(void)
{
    vkrt_scene *s = make_scene(cpu, VKRT_MODELS_DIR "/meshes/dragon_11k.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    const uint32_t w = 170, h = 110, n = w * h; /* not a multiple of 4 rays: the last lanes too */
    const vkrt_gpu_node box = { .bmin = { -0.5f, -0.5f, -0.5f }, .bmax = { 0.5f, 0.5f, 0.5f } };
    const ray_bin_limits limits = { 16u * n, 4096 };
    const vkrt_camera views[] = {
        { .fov_y_degrees = 0.0f },
        { .eye = { 0.1f, 0.0f, 0.62f }, .target = { 0.1f, 0.0f, 0.0f }, .fov_y_degrees = 100.0f },
    };
    vkrt_ray *rays = malloc((size_t)n * sizeof *rays);
    for (size_t v = 0; v < sizeof views / sizeof views[0]; v++) {
        vkrt_gpu_push push = { 0 };
        CHECK(camera_setup(&s->ctx->core, &views[v], w, h, &push) == VKRT_OK);
        CHECK(vkrt_camera_rays(cpu, &views[v], w, h, rays, n) == VKRT_OK);
        ray_bins a, b;
        ray_bin_outcome oa, ob;
        CHECK(ray_bin_plan(&s->ctx->core, NULL, rays, n, s->tris, s->bvh.tri_count, &box, limits, 2, &a, &oa) == VKRT_OK);
        CHECK(ray_bin_plan_camera(&s->ctx->core, NULL, &push, s->tris, s->bvh.tri_count, &box, limits, 2, &b, &ob) ==
              VKRT_OK);
        CHECK_MSG(oa == RAY_BIN_BUILT && ob == RAY_BIN_BUILT, "view %zu: outcomes %d and %d", v, (int)oa, (int)ob);
        if (oa == RAY_BIN_BUILT && ob == RAY_BIN_BUILT) {
            uint32_t *ea = malloc(((size_t)a.entry_count + 1) * sizeof *ea), *eb = malloc(((size_t)b.entry_count + 1) * sizeof *eb);
            ray_bin_fill(&a, ea);
            ray_bin_fill(&b, eb);
            size_t differ = 0;
            for (uint32_t i = 0; i < n; i++) {
                uint32_t la[2], lb[2];
                ray_bin_list(&a, i, la);
                ray_bin_list(&b, i, lb);
                /* Where a list starts within its room depends on how the threads shared the triangles
                 * out and culled them; what it holds does not. */
                differ += la[1] != lb[1] || memcmp(&ea[la[0]], &eb[lb[0]], la[1] * sizeof *ea) != 0;
            }
            fprintf(stderr, "  view %zu: room for %u entries; %zu of %u rays' lists differ\n", v, a.entry_count, differ, n);
            CHECK_MSG(differ == 0 && a.entry_count == b.entry_count && a.entry_count > 0 && a.culled == b.culled,
                      "view %zu: %zu lists differ, room %u and %u", v, differ, a.entry_count, b.entry_count);
            free(ea);
            free(eb);
        }
        ray_bins_destroy(&s->ctx->core, &a);
        ray_bins_destroy(&s->ctx->core, &b);
    }
    free(rays);
    vkrt_scene_destroy(s);
}

/* The entries of the lists ray_bin_plan makes for n rays over the GPU scene s: the triangle
 * tests the binned traversal makes for them (vkrt_trace_stats.binned_tests). */
static uint64_t planned_tests(vkrt_scene *s, const vkrt_ray *rays, uint32_t n)
{
    ray_bins bins;
    ray_bin_outcome outcome;
    const ray_bin_limits limits = { .max_entries = UINT32_MAX, .max_list = UINT32_MAX };
    vkrt_result r = ray_bin_plan(&s->ctx->core, NULL, rays, n, s->tris, s->gpu.tri_count, &s->gpu.root, limits, 2, &bins,
                                 &outcome);
    CHECK_MSG(r == VKRT_OK && outcome == RAY_BIN_BUILT, "the plan: %s, outcome %d", vkrt_result_string(r), (int)outcome);
    uint64_t tests = 0;
    if (r == VKRT_OK && outcome == RAY_BIN_BUILT) {
        uint32_t *entries = malloc((size_t)(bins.entry_count ? bins.entry_count : 1) * sizeof *entries);
        ray_bin_fill(&bins, entries);
        for (uint32_t i = 0; i < n; i++) {
            uint32_t list[2];
            ray_bin_list(&bins, i, list);
            tests += list[1];
        }
        free(entries);
    }
    ray_bins_destroy(&s->ctx->core, &bins);
    return tests;
}

/* Traces rays on the GPU where the binned traversal may take them and again kept to the BVH (the
 * test knob), and counts the rays whose hits differ in any bit; *out_stats gets the first
 * call's statistics. */
static size_t binned_and_bvh_differences(vkrt_scene *s, const vkrt_trace_desc *desc, const vkrt_ray *rays, size_t n,
                                         vkrt_trace_stats *out_stats, size_t *out_hits)
{
    vkrt_hit *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
    vkrt_trace_stats sa = { 0 }, sb = { 0 };
    vkrt_trace_desc d = desc ? *desc : (vkrt_trace_desc){ 0 };
    d.out_stats = &sa;
    vkrt_result r = vkrt_trace_rays(gpu, s, &d, rays, n, a);
    CHECK_MSG(r == VKRT_OK, "binned trace: %s", vkrt_context_last_error(gpu));
    gpu->vk->no_ray_binning = true;
    d.out_stats = &sb;
    r = vkrt_trace_rays(gpu, s, &d, rays, n, b);
    gpu->vk->no_ray_binning = false;
    CHECK_MSG(r == VKRT_OK, "BVH trace: %s", vkrt_context_last_error(gpu));
    CHECK_MSG(sb.rays_binned == 0, "the knob kept %" PRIu64 " rays binned", sb.rays_binned);
    size_t differ = 0, hits = 0;
    for (size_t i = 0; i < n; i++) {
        differ += memcmp(&a[i], &b[i], sizeof a[i]) != 0;
        hits += b[i].prim_id != VKRT_NO_HIT;
    }
    *out_stats = sa;
    *out_hits = hits;
    free(a);
    free(b);
    return differ;
}

static void check_binned(vkrt_scene *s, const vkrt_trace_desc *desc, const vkrt_ray *rays, size_t n, bool listed,
                         const char *what)
{
    vkrt_trace_stats st;
    size_t hits, differ = binned_and_bvh_differences(s, desc, rays, n, &st, &hits);
    fprintf(stderr, "  %s: %zu rays, %" PRIu64 " through lists, %" PRIu64 " answered on the host, %zu hits, %zu differ\n",
            what, n, st.rays_binned, st.rays_culled, hits, differ);
    CHECK_MSG(differ == 0, "%s: %zu of %zu rays' hits differ", what, differ, n);
    CHECK_MSG(hits > 0, "%s: no ray hits", what);
    /* Every ray with a list that is not empty goes through the lists, the others answered on the
     * host as misses (so every ray that hits went through them), or none. */
    if (listed) {
        CHECK_MSG(st.rays_binned >= hits && st.rays_binned + st.rays_culled == n,
                  "%s: %" PRIu64 " of %zu rays through lists, %zu hits", what, st.rays_binned, n, hits);
        const uint64_t tests = planned_tests(s, rays, (uint32_t)n);
        CHECK_MSG(st.binned_tests == tests && tests >= hits, "%s: %" PRIu64 " tests counted, the lists hold %" PRIu64,
                  what, st.binned_tests, tests);
    } else {
        CHECK_MSG(st.rays_binned == 0 && st.binned_tests == 0, "%s: %" PRIu64 " rays through lists", what,
                  st.rays_binned);
    }
}

/* Rays from `eye` at every corner and edge midpoint of triangles (positions `pos`, 9 floats a
 * triangle), exactly where two triangles meet, with some invalid rays and short ones mixed in:
 * every triangle a ray may hit must be in its list. */
static vkrt_ray *rays_at_corners(const float *pos, uint32_t tris, const float eye[3], size_t *out_n)
{
    const size_t n = (size_t)tris * 6;
    vkrt_ray *rays = calloc(n, sizeof *rays);
    test_rng rng = { 77 };
    for (size_t i = 0; i < n; i++) {
        const float *t = pos + i / 6 * 9;
        const int k = (int)(i % 6);
        float target[3];
        for (int a = 0; a < 3; a++)
            target[a] = k < 3 ? t[k * 3 + a] : 0.5f * (t[(k - 3) * 3 + a] + t[(k - 2) % 3 * 3 + a]);
        for (int a = 0; a < 3; a++) {
            rays[i].origin[a] = eye[a];
            rays[i].dir[a] = target[a] - eye[a];
        }
        const double u = rng_uniform(&rng);
        if (u < 0.01) rays[i].dir[0] = NAN;                               /* not valid: misses */
        else if (u < 0.02) rays[i].dir[0] = rays[i].dir[1] = rays[i].dir[2] = 0.0f;
        else if (u < 0.10) rays[i].tmax = (float)(0.999 + 0.002 * rng_uniform(&rng)); /* ends at the target */
        else if (u < 0.15) rays[i].tmin = (float)(0.999 + 0.002 * rng_uniform(&rng)); /* starts there */
    }
    *out_n = n;
    return rays;
}

/* Rays that share one origin take lists of the triangles each may hit, built on the host (on a
 * CPU device: lavapipe, here): the same hits as the BVH bit for bit, on camera rays, on rays at
 * the triangles' corners and edges, and where the lists would not suit (other rays, an eye
 * inside the scene's box, directions too wide, lists too long, any-hit and Moller-Trumbore
 * queries) the BVH takes the rays. */
static void gpu_rays_sharing_an_origin_take_lists_with_the_bvh_hits(void)
{
    vkrt_scene *s = make_scene(gpu, VKRT_MODELS_DIR "/meshes/dragon_48k.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    const uint32_t w = 256, h = 192;
    const size_t n = (size_t)w * h;
    vkrt_ray *rays = malloc(n * sizeof *rays);
    const vkrt_camera cameras[] = {
        { .fov_y_degrees = 0.0f }, /* the default view */
        { .eye = { 0.9f, 0.4f, -0.8f }, .target = { 0.0f, 0.05f, 0.0f }, .fov_y_degrees = 30.0f },
        { .eye = { 0.05f, 1.3f, 0.2f }, .target = { 0.0f, 0.0f, 0.0f }, .up = { 0.0f, 0.0f, 1.0f } },
        /* close to the mesh: its box nearly reaches the eye's plane, lists long at the edges */
        { .eye = { 0.1f, 0.0f, 0.62f }, .target = { 0.1f, 0.0f, 0.0f }, .fov_y_degrees = 100.0f },
    };
    for (size_t c = 0; c < sizeof cameras / sizeof cameras[0]; c++) {
        CHECK(vkrt_camera_rays(gpu, &cameras[c], w, h, rays, n) == VKRT_OK);
        char what[64];
        snprintf(what, sizeof what, "camera %zu", c);
        check_binned(s, NULL, rays, n, true, what);
        /* The camera's rays beside rays about the scene's box from the same eye: by its edges, off
         * its faces, short, with NaN bounds. */
        if (c < 3) {
            const size_t about = 12000;
            vkrt_ray *mixed = rays_about_a_box(rays[0].origin, &s->gpu.root, n + about, 300 + c);
            memcpy(mixed, rays, n * sizeof *rays);
            snprintf(what, sizeof what, "camera %zu and rays about the box", c);
            check_binned(s, NULL, mixed, n + about, true, what);
            free(mixed);
        }
    }
    vkrt_scene_stats st;
    CHECK(vkrt_scene_stats_get(s, &st) == VKRT_OK);
    float *pos = malloc((size_t)st.triangles * 9 * sizeof *pos);
    if (vkrt_scene_triangles_get(s, pos, (size_t)st.triangles * 9) == VKRT_OK) {
        const float eyes[][3] = { { 0.0f, 0.0f, 1.5f }, { -1.1f, 0.7f, 0.3f } };
        for (int e = 0; e < 2; e++) {
            size_t m;
            vkrt_ray *corner = rays_at_corners(pos, st.triangles, eyes[e], &m);
            check_binned(s, NULL, corner, m, true, e ? "corners and edges, eye 1" : "corners and edges, eye 0");
            /* The same rays as any-hit or Moller-Trumbore queries keep to the BVH. */
            check_binned(s, &(vkrt_trace_desc){ .any_hit = true }, corner, m, false, "any hit");
            check_binned(s, &(vkrt_trace_desc){ .intersector = VKRT_INTERSECTOR_MOLLER_TRUMBORE }, corner, m, false,
                         "Moller-Trumbore");
            free(corner);
        }
    }
    free(pos);
    /* Where the lists do not suit, the BVH. Rays from many origins: */
    vkrt_ray *random = random_rays_in_box(n, 5);
    check_binned(s, NULL, random, n, false, "many origins");
    free(random);
    /* An eye inside the scene's box: */
    CHECK(vkrt_camera_rays(gpu, &(vkrt_camera){ .eye = { 0.0f, 0.0f, 0.1f }, .target = { 0.0f, 0.0f, -1.0f } }, w, h,
                           rays, n) == VKRT_OK);
    check_binned(s, NULL, rays, n, false, "eye inside the box");
    /* Directions wider than the lists' projection takes: a camera's rays and their opposites. */
    CHECK(vkrt_camera_rays(gpu, &(vkrt_camera){ .eye = { 0.0f, 0.0f, 3.0f }, .fov_y_degrees = 20.0f }, w, h, rays,
                           n) == VKRT_OK);
    for (size_t i = 1; i < n; i += 2)
        for (int a = 0; a < 3; a++) rays[i].dir[a] = -rays[i].dir[a];
    check_binned(s, NULL, rays, n, false, "opposite directions");
    /* Rays that all pass beside the scene (its box in front of the eye): every one a miss, as
     * through the BVH. */
    CHECK(vkrt_camera_rays(gpu,
                           &(vkrt_camera){ .eye = { 0.0f, 0.0f, 1.5f }, .target = { 1.5f, 0.0f, 0.0f }, .fov_y_degrees = 4.0f },
                           w, h, rays, n) == VKRT_OK);
    {
        vkrt_trace_stats beside;
        size_t hits, differ = binned_and_bvh_differences(s, NULL, rays, n, &beside, &hits);
        fprintf(stderr, "  beside the scene: %zu hits, %" PRIu64 " through lists, %zu differ\n", hits,
                beside.rays_binned, differ);
        CHECK_MSG(hits == 0 && differ == 0 && beside.rays_binned == 0 && beside.rays_culled == n,
                  "beside the scene: %zu hits, %zu differ, %" PRIu64 " binned, %" PRIu64 " culled", hits, differ,
                  beside.rays_binned, beside.rays_culled);
    }
    /* Too few rays for the scene's triangles: */
    CHECK(vkrt_camera_rays(gpu, NULL, 64, 64, rays, n) == VKRT_OK);
    check_binned(s, NULL, rays, 64 * 64, false, "few rays");
    vkrt_scene_destroy(s);

    /* Lists too long: 1,500 squares stacked across the whole view, both triangles of each in every
     * ray's list. */
    const uint32_t layers = 1500;
    float *sq = malloc((size_t)layers * 4 * 3 * sizeof *sq);
    uint32_t *idx = malloc((size_t)layers * 6 * sizeof *idx);
    for (uint32_t l = 0; l < layers; l++) {
        const float z = -0.2f - 0.0005f * (float)l;
        const float corners[4][2] = { { -3, -3 }, { 3, -3 }, { 3, 3 }, { -3, 3 } };
        for (int k = 0; k < 4; k++) {
            sq[(l * 4 + k) * 3] = corners[k][0];
            sq[(l * 4 + k) * 3 + 1] = corners[k][1];
            sq[(l * 4 + k) * 3 + 2] = z;
        }
        const uint32_t q[6] = { 0, 1, 2, 0, 2, 3 };
        for (int k = 0; k < 6; k++) idx[l * 6 + k] = l * 4 + q[k];
    }
    vkrt_scene *stack = mesh_scene(gpu, sq, layers * 4, idx, layers * 2, VKRT_BVH_BUILDER_DEFAULT);
    if (stack) {
        CHECK(vkrt_camera_rays(gpu, &(vkrt_camera){ .eye = { 0.0f, 0.0f, 1.0f }, .target = { 0.0f, 0.0f, 0.0f } }, w,
                               h, rays, n) == VKRT_OK);
        check_binned(stack, NULL, rays, n, false, "1,500 squares deep");
        /* A few of them list well. */
        vkrt_scene_destroy(stack);
        stack = mesh_scene(gpu, sq, 6 * 4, idx, 6 * 2, VKRT_BVH_BUILDER_DEFAULT);
        if (stack) check_binned(stack, NULL, rays, n, true, "6 squares deep");
        /* One square: most rays' lists hold one triangle, which they hit. */
        vkrt_scene_destroy(stack);
        stack = mesh_scene(gpu, sq, 4, idx, 2, VKRT_BVH_BUILDER_DEFAULT);
        if (stack) check_binned(stack, NULL, rays, n, true, "one square");
    }
    vkrt_scene_destroy(stack);
    free(sq);
    free(idx);
    free(rays);
}

/* Renders the view on the GPU where the binned traversal may take its camera rays and again
 * kept to the BVH (the test knob): the images must agree in every bit. Returns the binned
 * render's rays_binned. */
static uint64_t render_binned_and_bvh(vkrt_scene *s, const vkrt_render_desc *d, const char *what)
{
    const size_t n = vkrt_render_floats(d->width, d->height);
    float *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
    vkrt_render_stats sa, sb;
    vkrt_result ra = vkrt_render(gpu, s, d, a, n, &sa);
    gpu->vk->no_ray_binning = true;
    vkrt_result rb = vkrt_render(gpu, s, d, b, n, &sb);
    gpu->vk->no_ray_binning = false;
    CHECK_MSG(ra == VKRT_OK && rb == VKRT_OK, "%s: %s", what, vkrt_context_last_error(gpu));
    size_t differ = 0, seen = 0;
    for (size_t i = 0; ra == VKRT_OK && rb == VKRT_OK && i < n; i += 4) {
        differ += memcmp(&a[i], &b[i], 4 * sizeof *a) != 0;
        seen += memcmp(&b[i], &b[0], 4 * sizeof *b) != 0; /* not the corner's background */
    }
    fprintf(stderr, "  %s: %ux%u, %" PRIu64 " rays through lists, %zu of %zu pixels differ\n", what, d->width,
            d->height, sa.rays_binned, differ, n / 4);
    CHECK_MSG(differ == 0, "%s: %zu pixels differ from the BVH's image", what, differ);
    CHECK_MSG(seen > 0, "%s: the image is one colour", what);
    CHECK_MSG(sb.rays_binned == 0 && sb.binned_tests == 0, "%s: the knob kept %" PRIu64 " rays binned", what,
              sb.rays_binned);
    if (sa.rays_binned) {
        /* Every pixel's list tested: the entries of the camera rays' lists. */
        const uint32_t pixels = d->width * d->height;
        vkrt_ray *rays = malloc((size_t)pixels * sizeof *rays);
        CHECK(vkrt_camera_rays(gpu, &d->camera, d->width, d->height, rays, pixels) == VKRT_OK);
        const uint64_t tests = planned_tests(s, rays, pixels);
        CHECK_MSG(sa.binned_tests == tests && tests > 0, "%s: %" PRIu64 " tests counted, the lists hold %" PRIu64,
                  what, sa.binned_tests, tests);
        free(rays);
    } else {
        CHECK_MSG(sa.binned_tests == 0, "%s: %" PRIu64 " tests counted without lists", what, sa.binned_tests);
    }
    free(a);
    free(b);
    return sa.rays_binned;
}

/* vkrt_render's camera rays through the host's lists on a CPU device (README, "Binned
 * traversal"): the same image as through the BVH in every mode that shades closest hits, over
 * tiles and from views near and far; the heat map, the counters, naive traversal and an eye
 * inside the box keep to the BVH. */
static void gpu_renders_take_lists_with_the_bvh_image(void)
{
    if (gpu->vk->properties.deviceType != VK_PHYSICAL_DEVICE_TYPE_CPU) return; /* a GPU never bins */
    vkrt_scene *s = make_scene(gpu, VKRT_MODELS_DIR "/meshes/dragon_11k.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    /* 520 x 40: three tiles across (TILE_SIZE 256), the mesh over the first two, 20,800 pixels
     * for 11,102 triangles. */
    const uint32_t w = 520, h = 40, pixels = w * h;
    const vkrt_mode modes[] = { VKRT_MODE_NORMAL, VKRT_MODE_DEPTH, VKRT_MODE_ID, VKRT_MODE_ALBEDO, VKRT_MODE_UV };
    const char *names[] = { "normal", "depth", "id", "albedo", "uv" };
    for (size_t m = 0; m < sizeof modes / sizeof modes[0]; m++) {
        const uint64_t binned = render_binned_and_bvh(s, &(vkrt_render_desc){ .width = w, .height = h, .mode = modes[m] },
                                                      names[m]);
        CHECK_MSG(binned == pixels, "%s: %" PRIu64 " of %u rays through lists", names[m], binned, pixels);
    }
    const vkrt_camera views[] = {
        { .eye = { 0.9f, 0.4f, -0.8f }, .target = { 0.0f, 0.05f, 0.0f }, .fov_y_degrees = 30.0f },
        /* close to the mesh: its box nearly reaches the eye's plane, lists long at the edges */
        { .eye = { 0.1f, 0.0f, 0.62f }, .target = { 0.1f, 0.0f, 0.0f }, .fov_y_degrees = 100.0f },
    };
    for (size_t v = 0; v < sizeof views / sizeof views[0]; v++) {
        const uint64_t binned = render_binned_and_bvh(
            s, &(vkrt_render_desc){ .width = 160, .height = 120, .camera = views[v] }, v ? "close view" : "side view");
        CHECK_MSG(binned == 160 * 120, "view %zu: %" PRIu64 " rays through lists", v, binned);
    }
    /* What keeps to the BVH: */
    const struct {
        vkrt_render_desc desc;
        const char *what;
    } keep_bvh[] = {
        { { .width = w, .height = h, .mode = VKRT_MODE_HEATMAP }, "heat map" },
        { { .width = w, .height = h, .traversal_counters = true }, "traversal counters" },
        { { .width = w, .height = h, .traversal = VKRT_TRAVERSAL_NAIVE }, "naive traversal" },
        { { .width = w, .height = h, .intersector = VKRT_INTERSECTOR_MOLLER_TRUMBORE }, "Moller-Trumbore" },
        { { .width = w, .height = h, .camera = { .eye = { 0.0f, 0.0f, 0.1f }, .target = { 0.0f, 0.0f, -1.0f } } },
          "an eye inside the box" },
        { { .width = 100, .height = 100 }, "fewer pixels than triangles" },
    };
    for (size_t k = 0; k < sizeof keep_bvh / sizeof keep_bvh[0]; k++) {
        const uint64_t binned = render_binned_and_bvh(s, &keep_bvh[k].desc, keep_bvh[k].what);
        CHECK_MSG(binned == 0, "%s: %" PRIu64 " rays through lists", keep_bvh[k].what, binned);
    }
    vkrt_scene_destroy(s);
}

/* Checks planned and filled lists (ray_bin.h) of rays[0 .. n) for scene s: every entry of a
 * list a triangle, each list in the triangles' order without repeats, none longer than the plan
 * said, and every triangle the watertight test hits (brute force over all of them) in the list
 * of every step-th ray, hits for at least a quarter of those; where the plan culled, a hit
 * beyond the ray's closest may be left out (*out_hidden counts those). Returns the most of those
 * rays any one triangle has a hit for. */
static size_t lists_hold_hits(const vkrt_scene *s, const vkrt_ray *rays, uint32_t n, uint32_t step,
                              const ray_bins *bins, const uint32_t *entries, const char *what, size_t *out_hidden)
{
    const uint32_t tris = s->bvh.tri_count;
    uint32_t *rays_hitting = calloc(tris, sizeof *rays_hitting);
    size_t unwritten = 0, unordered = 0, missing = 0, hidden = 0, hits = 0, checked = 0, longest = 0, most = 0;
    size_t listed_entries = 0;
    for (uint32_t i = 0; i < n; i++) {
        uint32_t list[2];
        ray_bin_list(bins, i, list);
        if (list[1] > longest) longest = list[1];
        listed_entries += list[1];
        for (uint32_t k = 0; k < list[1]; k++) unwritten += entries[list[0] + k] >= tris;
        for (uint32_t k = 1; k < list[1]; k++) unordered += entries[list[0] + k] <= entries[list[0] + k - 1];
        if (i % step) continue;
        checked++;
        vkrt_gpu_ray ray;
        memcpy(&ray, &rays[i], sizeof ray);
        if (ray.tmax == 0.0f) ray.tmax = INFINITY;
        /* The ray's hits, then its closest (distance, then prim_id): only a hit beyond it may be
         * left out. */
        float closest_t = INFINITY;
        uint32_t closest_prim = UINT32_MAX;
        uint32_t unlisted_hits = 0;
        float unlisted_nearest = INFINITY;
        for (uint32_t t = 0; t < tris; t += 4) {
            const vkrt_gpu_tri *four[4];
            for (int k = 0; k < 4; k++) four[k] = &s->tris[t + k < tris ? t + k : t];
            float tt[4], uu[4], vv[4];
            const unsigned mask = cpu_trace_watertight4_test(&ray, four, false, tt, uu, vv);
            for (int k = 0; k < 4 && t + k < tris; k++) {
                if (!(mask >> k & 1)) continue;
                hits++;
                if (++rays_hitting[t + k] > most) most = rays_hitting[t + k];
                const uint32_t prim = s->tris[t + k].prim_id;
                if (tt[k] < closest_t || (tt[k] == closest_t && prim < closest_prim)) {
                    closest_t = tt[k];
                    closest_prim = prim;
                }
                bool listed = false;
                for (uint32_t e = 0; e < list[1] && !listed; e++) listed = entries[list[0] + e] == t + k;
                if (!listed) {
                    unlisted_hits++;
                    unlisted_nearest = tt[k] < unlisted_nearest ? tt[k] : unlisted_nearest;
                }
            }
        }
        /* Left out where culled and strictly beyond the closest hit, which is listed. */
        if (bins->culled && unlisted_nearest > closest_t) hidden += unlisted_hits;
        else missing += unlisted_hits;
    }
    free(rays_hitting);
    fprintf(stderr,
            "  %s: %u rays, %zu entries listed (room for %u, longest %zu), %zu checked by brute force: %zu hits, "
            "%zu hidden ones left out, %zu missing\n",
            what, n, listed_entries, bins->entry_count, longest, checked, hits, hidden, missing);
    CHECK_MSG(unwritten == 0 && unordered == 0, "%s: %zu list entries unwritten, %zu out of order", what, unwritten,
              unordered);
    CHECK_MSG(longest <= bins->longest, "%s: longest list %zu, room for %u", what, longest, bins->longest);
    CHECK_MSG(hits > checked / 4 && missing == 0, "%s: %zu of %zu hit triangles missing from lists", what, missing,
              hits);
    if (out_hidden) *out_hidden = hidden;
    return most;
}

/* Ray i's list for each of rays 0 .. n - 1 in turn, its length and then its entries: lists
 * that leave room unwritten compared as the device reads them. Ownership: free the result. */
static uint32_t *flat_lists(const ray_bins *bins, const uint32_t *entries, uint32_t n, uint32_t *out_words)
{
    size_t total = n;
    for (uint32_t i = 0; i < n; i++) {
        uint32_t list[2];
        ray_bin_list(bins, i, list);
        total += list[1];
    }
    uint32_t *flat = malloc(total * sizeof *flat), words = 0;
    for (uint32_t i = 0; i < n; i++) {
        uint32_t list[2];
        ray_bin_list(bins, i, list);
        flat[words++] = list[1];
        for (uint32_t k = 0; k < list[1]; k++) flat[words++] = entries[list[0] + k];
    }
    *out_words = words;
    return flat;
}

/* The lists of rays[0 .. n) for scene s's triangles in box, planned on `threads` threads and
 * filled, as flat_lists gives them (*out_count words); NULL, with a failed check, where the plan
 * did not build them. */
static uint32_t *planned_lists(vkrt_scene *s, const vkrt_ray *rays, uint32_t n, const vkrt_gpu_node *box,
                               uint32_t threads, uint32_t *out_count)
{
    ray_bins bins;
    ray_bin_outcome outcome;
    const ray_bin_limits limits = { .max_entries = 64u * n, .max_list = 1u << 20 };
    CHECK(ray_bin_plan(&s->ctx->core, NULL, rays, n, s->tris, s->bvh.tri_count, box, limits, threads, &bins,
                       &outcome) == VKRT_OK);
    CHECK_MSG(outcome == RAY_BIN_BUILT, "%u rays on %u threads: outcome %d", n, threads, (int)outcome);
    *out_count = 0;
    if (outcome != RAY_BIN_BUILT) return NULL;
    uint32_t *entries = malloc((size_t)(bins.entry_count ? bins.entry_count : 1) * sizeof *entries);
    ray_bin_fill(&bins, entries);
    uint32_t *flat = flat_lists(&bins, entries, n, out_count);
    free(entries);
    ray_bins_destroy(&s->ctx->core, &bins);
    return flat;
}

/* The host's lists themselves (src/ray_bin.h), on a scene's own triangles: every slot written,
 * each list in the triangles' order without repeats, and every triangle the watertight test
 * hits (brute force over all of them) in the list of each ray checked: camera rays, rays at the
 * triangles' corners and edge midpoints, and camera rays moved off their grid with a band of
 * rows left without rays (each of a camera's cells holds one ray, whose bounds are a point: a
 * test that took a cell's low bounds for its high ones would pass there; moved, a cell's rays
 * spread over it, and it misses 401 hit triangles), a turned camera and one that sees the mesh
 * in its lowest rows alone (the cameras' rays found on a lattice, the others not); and the same
 * lists on any number of threads, and from the baseline build as from the x86-64-v3 one. */
static void ray_bin_lists_hold_every_triangle_a_ray_hits(void)
{
    vkrt_scene *s = make_scene(cpu, VKRT_MODELS_DIR "/meshes/dragon_11k.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    const uint32_t tris = s->bvh.tri_count;
    float lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY };
    for (uint32_t t = 0; t < tris; t++) {
        const vkrt_float3 *v[3] = { &s->tris[t].v0, &s->tris[t].v1, &s->tris[t].v2 };
        for (int k = 0; k < 3; k++) {
            const float c[3] = { v[k]->x, v[k]->y, v[k]->z };
            for (int a = 0; a < 3; a++) {
                lo[a] = fminf(lo[a], c[a]);
                hi[a] = fmaxf(hi[a], c[a]);
            }
        }
    }
    const vkrt_gpu_node box = { .bmin = { lo[0], lo[1], lo[2] }, .bmax = { hi[0], hi[1], hi[2] } };
    float *pos = malloc((size_t)tris * 9 * sizeof *pos);
    for (uint32_t t = 0; t < tris; t++) {
        const vkrt_float3 *v[3] = { &s->tris[t].v0, &s->tris[t].v1, &s->tris[t].v2 };
        for (int k = 0; k < 3; k++) {
            pos[t * 9 + k * 3] = v[k]->x;
            pos[t * 9 + k * 3 + 1] = v[k]->y;
            pos[t * 9 + k * 3 + 2] = v[k]->z;
        }
    }
    size_t corner_n;
    vkrt_ray *corner = rays_at_corners(pos, tris, (const float[3]){ 0.3f, -0.2f, 1.4f }, &corner_n);
    const size_t camera_n = 160 * 120;
    vkrt_ray *camera = malloc(camera_n * sizeof *camera);
    CHECK(vkrt_camera_rays(cpu, NULL, 160, 120, camera, camera_n) == VKRT_OK);
    /* Each direction moved by up to 1.5 pixels across and down (the view's pixels are some 0.007
     * apart at unit depth), and the rays of rows 40 to 59 made invalid. */
    vkrt_ray *moved = malloc(camera_n * sizeof *moved);
    memcpy(moved, camera, camera_n * sizeof *moved);
    test_rng rng = { 2026 };
    for (size_t i = 0; i < camera_n; i++) {
        for (int a = 0; a < 2; a++) moved[i].dir[a] += (float)(0.02 * (rng_uniform(&rng) - 0.5));
        if (i / 160 >= 40 && i / 160 < 60) moved[i].dir[0] = NAN;
    }
    /* A camera turned about all three axes, its image an odd size: its pixel centres a lattice
     * still, along its own rows (the plan's frame follows the rays' first row). */
    const size_t turned_n = 173 * 131;
    vkrt_ray *turned = malloc(turned_n * sizeof *turned);
    const vkrt_camera turned_camera = { .eye = { 0.9f, 0.5f, 1.1f }, .target = { 0.05f, -0.02f, 0.0f },
                                        .up = { 0.3f, 1.0f, 0.1f }, .fov_y_degrees = 50.0f };
    CHECK(vkrt_camera_rays(cpu, &turned_camera, 173, 131, turned, turned_n) == VKRT_OK);
    /* A camera above the mesh, which it sees in its lowest rows alone: past the first 16,384
     * rays (the plan's first item of rays), where its rays may enter the box. */
    const size_t above_n = 200 * 150;
    vkrt_ray *above = malloc(above_n * sizeof *above);
    const vkrt_camera above_camera = { .eye = { 0.0f, 0.45f, 1.5f }, .target = { 0.0f, 0.45f, 0.0f },
                                       .fov_y_degrees = 45.0f };
    CHECK(vkrt_camera_rays(cpu, &above_camera, 200, 150, above, above_n) == VKRT_OK);
    /* The camera's rays starting 1.1 on, inside the mesh: a lattice still, but a ray may start
     * past a triangle that hides others from the eye, so nothing is culled. */
    vkrt_ray *late = malloc(camera_n * sizeof *late);
    memcpy(late, camera, camera_n * sizeof *late);
    for (size_t i = 0; i < camera_n; i++) late[i].tmin = 1.1f;
    const struct {
        const vkrt_ray *rays;
        size_t n, step;
        const char *what;
        bool lattice; /* the plan should find the rays on a lattice */
        bool culled;  /* and cull the lists */
    } sets[] = { { camera, camera_n, 3, "camera", true, true },
                 { corner, corner_n, 13, "corners and edges", false, false },
                 { moved, camera_n, 3, "camera rays off the grid", false, false },
                 { turned, turned_n, 3, "turned camera", true, true },
                 { above, above_n, 5, "camera above the mesh", true, true },
                 { late, camera_n, 3, "camera rays starting inside the mesh", true, false } };
    const int pass_set[] = { 0, 1, 0, 2, 3, 4, 5 };
    /* The camera's lists planned first without kept scratch, then with the scratch each plan
     * leaves (the corners' plan after the camera's, the camera's again after theirs): the same
     * lists. */
    ray_bin_scratch *scratch = NULL;
    uint32_t *first_lists = NULL, first_count = 0;
    for (int pass = 0; pass < (int)(sizeof pass_set / sizeof pass_set[0]); pass++) {
        const int set = pass_set[pass];
        const vkrt_ray *rays = sets[set].rays;
        const uint32_t n = (uint32_t)sets[set].n;
        ray_bins bins;
        ray_bin_outcome outcome;
        const ray_bin_limits limits = { .max_entries = 64u * n, .max_list = 1u << 20 };
        CHECK(ray_bin_plan(&s->ctx->core, pass ? &scratch : NULL, rays, n, s->tris, tris, &box, limits, 2, &bins,
                           &outcome) == VKRT_OK);
        CHECK_MSG(outcome == RAY_BIN_BUILT, "%s: outcome %d", sets[set].what, (int)outcome);
        if (outcome != RAY_BIN_BUILT) continue;
        CHECK_MSG(bins.on_lattice == sets[set].lattice && bins.culled == sets[set].culled,
                  "%s: on a lattice %d, culled %d, expected %d and %d", sets[set].what, (int)bins.on_lattice,
                  (int)bins.culled, (int)sets[set].lattice, (int)sets[set].culled);
        uint32_t *entries = malloc((size_t)(bins.entry_count ? bins.entry_count : 1) * sizeof *entries);
        memset(entries, 0xFF, (size_t)bins.entry_count * sizeof *entries);
        ray_bin_fill(&bins, entries);
        uint32_t words;
        uint32_t *flat = flat_lists(&bins, entries, n, &words);
        if (pass == 2) {
            CHECK_MSG(words == first_count && memcmp(flat, first_lists, first_count * sizeof *flat) == 0,
                      "the camera's lists from kept scratch differ (%u words, %u before)", words, first_count);
        } else {
            size_t hidden;
            lists_hold_hits(s, rays, n, sets[set].step, &bins, entries, sets[set].what, &hidden);
            /* The dragon hides much of itself from the camera. */
            if (set == 0) CHECK_MSG(hidden > 0, "camera: no hidden hit left out of the lists");
        }
        if (pass == 0) {
            first_lists = flat;
            first_count = words;
        } else {
            free(flat);
        }
        free(entries);
        ray_bins_destroy(&s->ctx->core, &bins);
    }
    CHECK_MSG(scratch != NULL, "no scratch kept");
    ray_bin_scratch_destroy(&s->ctx->core, scratch);
    /* However many threads count the triangles, and however they share them out as they go (a
     * pair of items takes its segment's chunks from both ends, an odd item its own; more
     * threads than cores here), the camera's lists are the first pass's on two threads. */
    const uint32_t thread_counts[] = { 1, 3, 5, 8 };
    for (size_t k = 0; k < sizeof thread_counts / sizeof thread_counts[0] && first_lists; k++) {
        uint32_t count;
        uint32_t *entries = planned_lists(s, camera, (uint32_t)camera_n, &box, thread_counts[k], &count);
        CHECK_MSG(entries && count == first_count && memcmp(entries, first_lists, first_count * sizeof *entries) == 0,
                  "%u threads: the camera's lists differ (%u words, %u on two threads)", thread_counts[k], count,
                  first_count);
        free(entries);
    }
    free(first_lists);
    /* The x86-64-v3 build of the plan and the fill (where the host runs it, as the CPU tracer
     * does: cpu_trace_isa) lists what the baseline build does, on the lattice and off it. */
    fprintf(stderr, "  the lists' plan runs the %s code here\n", cpu_trace_isa_name(cpu_trace_isa(&s->ctx->core)));
    const struct {
        const vkrt_ray *rays;
        size_t n;
    } isa_sets[] = { { camera, camera_n }, { moved, camera_n }, { corner, corner_n } };
    for (size_t k = 0; k < sizeof isa_sets / sizeof isa_sets[0]; k++) {
        uint32_t *lists[2], count[2] = { 0, 0 };
        for (int baseline = 0; baseline < 2; baseline++) {
            s->ctx->core.test_cpu_baseline = baseline;
            lists[baseline] = planned_lists(s, isa_sets[k].rays, (uint32_t)isa_sets[k].n, &box, 2, &count[baseline]);
        }
        s->ctx->core.test_cpu_baseline = false;
        CHECK_MSG(lists[0] && lists[1] && count[0] == count[1] &&
                      memcmp(lists[0], lists[1], (size_t)count[0] * sizeof *lists[0]) == 0,
                  "set %zu: the baseline build's lists differ (%u words against %u)", k, count[1], count[0]);
        free(lists[0]);
        free(lists[1]);
    }
    free(camera);
    free(turned);
    free(above);
    free(late);
    free(moved);
    free(corner);
    free(pos);
    vkrt_scene_destroy(s);
}

/* Plans and fills the lists of rays[0 .. n) for scene s, which must find them on a lattice, and
 * checks every ray's by brute force (lists_hold_hits): the most rays one triangle has hits for,
 * 0 where no lists were built. */
static size_t lattice_lists_hold_hits(vkrt_scene *s, const vkrt_ray *rays, uint32_t n, const char *what,
                                      size_t *out_hidden)
{
    ray_bins bins;
    ray_bin_outcome outcome;
    const ray_bin_limits limits = { .max_entries = 64u * n, .max_list = 1u << 20 };
    CHECK(ray_bin_plan(&s->ctx->core, NULL, rays, n, s->tris, s->bvh.tri_count, &s->bvh.nodes[0], limits, 2, &bins,
                       &outcome) == VKRT_OK);
    CHECK_MSG(outcome == RAY_BIN_BUILT && bins.on_lattice, "%s: outcome %d, on a lattice %d", what, (int)outcome,
              (int)bins.on_lattice);
    if (outcome != RAY_BIN_BUILT) return 0;
    uint32_t *entries = malloc((size_t)(bins.entry_count ? bins.entry_count : 1) * sizeof *entries);
    memset(entries, 0xFF, (size_t)bins.entry_count * sizeof *entries);
    ray_bin_fill(&bins, entries);
    const size_t most = lists_hold_hits(s, rays, n, 1, &bins, entries, what, out_hidden);
    free(entries);
    ray_bins_destroy(&s->ctx->core, &bins);
    return most;
}

/* On a lattice the count tests each triangle's edges at its span's cells in the grid's units,
 * four triangles together where a span holds up to 64 cells and row by row where it holds more
 * (src/ray_bin.c): the teapot from close by, whose nearest triangles have hits for over 64 of
 * its 160 x 120 rays, every ray checked by brute force. */
static void ray_bin_lattice_lists_hold_the_hits_of_big_triangles(void)
{
    vkrt_scene *s = make_scene(cpu, VKRT_MODELS_DIR "/meshes/teapot.obj", VKRT_BVH_BUILDER_DEFAULT);
    if (!s) return;
    const uint32_t w = 160, h = 120, n = w * h;
    const vkrt_camera close = { .eye = { 0.1f, 0.0f, 0.62f }, .target = { 0.1f, 0.0f, 0.0f }, .fov_y_degrees = 100.0f };
    vkrt_ray *rays = malloc((size_t)n * sizeof *rays);
    CHECK(vkrt_camera_rays(cpu, &close, w, h, rays, n) == VKRT_OK);
    const size_t most = lattice_lists_hold_hits(s, rays, n, "teapot close up", NULL);
    CHECK_MSG(most > 64, "the largest triangle has hits for %zu rays: none spans over 64 cells", most);
    free(rays);
    vkrt_scene_destroy(s);
}

/* A 97 x 73 camera's rays (into *out_rays) and the corners of a bumpy sheet on every third of
 * them, cols x rows corners each at its own depth along its ray (into pos), so that the sheet's
 * edges pass through the pixel centres between them along rows, columns and diagonals, up to
 * rounding. */
static void sheet_on_every_third_ray(vkrt_ray **out_rays, uint32_t cols, uint32_t rows, float *pos)
{
    const uint32_t w = 97, h = 73;
    const vkrt_camera view = { .eye = { 0.0f, 0.0f, 1.5f }, .target = { 0.0f, 0.0f, 0.0f }, .fov_y_degrees = 45.0f };
    vkrt_ray *rays = malloc((size_t)w * h * sizeof *rays);
    CHECK(vkrt_camera_rays(cpu, &view, w, h, rays, (size_t)w * h) == VKRT_OK);
    for (uint32_t y = 0; y < rows; y++)
        for (uint32_t x = 0; x < cols; x++) {
            const vkrt_ray *r = &rays[(size_t)(3 * y) * w + 3 * x];
            const float depth = 1.2f + 0.05f * (float)((x * 7 + y * 3) % 5);
            for (int k = 0; k < 3; k++) pos[(y * cols + x) * 3 + k] = r->origin[k] + r->dir[k] * depth;
        }
    *out_rays = rays;
}

/* The lattice's count against rays that graze its triangles: a bumpy sheet whose corners lie on
 * every third of a camera's rays (each at its own depth), so that its edges pass through the
 * pixel centres between them along rows, columns and diagonals, up to rounding. The watertight
 * test decides those rays' hits by a few ulps; the lists must hold every triangle it gives one
 * (without the count's tolerances they miss some). */
static void ray_bin_lattice_lists_hold_grazing_hits(void)
{
    const uint32_t n = 97 * 73, cols = 97 / 3 + 1, rows = 73 / 3 + 1;
    float *pos = malloc((size_t)cols * rows * 3 * sizeof *pos);
    uint32_t *idx = malloc((size_t)(cols - 1) * (rows - 1) * 6 * sizeof *idx), tris = 0;
    vkrt_ray *rays;
    sheet_on_every_third_ray(&rays, cols, rows, pos);
    for (uint32_t y = 0; y + 1 < rows; y++)
        for (uint32_t x = 0; x + 1 < cols; x++) {
            const uint32_t a = y * cols + x, b = a + 1, c = a + cols, d = c + 1;
            /* The diagonals both ways, in a checkerboard. */
            const uint32_t quad[2][6] = { { a, b, d, a, d, c }, { a, b, c, b, d, c } };
            memcpy(idx + 3 * tris, quad[(x + y) % 2], sizeof quad[0]);
            tris += 2;
        }
    vkrt_scene *s = mesh_scene(cpu, pos, cols * rows, idx, tris, VKRT_BVH_BUILDER_DEFAULT);
    if (s) {
        lattice_lists_hold_hits(s, rays, n, "grazed sheet", NULL);
        vkrt_scene_destroy(s);
    }
    free(idx);
    free(pos);
    free(rays);
}

/* Occlusion culling keeps every ray's closest hit: a sheet of triangles with every edge open and
 * through pixel centres (half of the grazed sheet's, the other half left out) before a back
 * plane, and a triangle of over 64 cells whose edges pass through them too, where a ray on an
 * edge may miss the sheet or the triangle and hit what lies behind (the cover test's edges moved
 * inwards by the may-hit test's tolerance: without it, some of those rays lose their hit);
 * and nine narrow triangles 0.1 to 0.9 steps of depth (2^-16 of the scene's) before a wider one,
 * all flat to the view, which their rays hit first (the depths' room and steps rounded outwards:
 * without both, some are culled behind the wider one). The lists leave out the plane behind the
 * sheet. */
static void ray_bin_lattice_culling_keeps_the_closest_hits(void)
{
    enum { NARROW = 9 };
    const uint32_t n = 97 * 73, cols = 97 / 3 + 1, rows = 73 / 3 + 1, sheet = cols * rows, extra = 10 + 3 * NARROW;
    float *pos = malloc(((size_t)sheet + extra) * 3 * sizeof *pos);
    uint32_t *idx = malloc(((size_t)(cols - 1) * (rows - 1) + 4 + NARROW) * 3 * sizeof *idx), tris = 0;
    vkrt_ray *rays;
    sheet_on_every_third_ray(&rays, cols, rows, pos);
    /* The left half's quads, one triangle of each (the diagonals both ways). */
    for (uint32_t y = 0; y + 1 < rows; y++)
        for (uint32_t x = 0; x + 1 < cols / 2; x++) {
            const uint32_t a = y * cols + x, b = a + 1, c = a + cols, d = c + 1;
            const uint32_t tri[2][3] = { { a, b, d }, { b, c, a } };
            memcpy(idx + 3 * tris, tri[(x + y) % 2], sizeof tri[0]);
            tris++;
        }
    /* The back plane at depth 2.5, the wide triangle at 2.3 on the right, the narrow ones within it
     * (the scene's box spans depths 1.2 to 2.5: a step is 1.98e-5). */
    const float more[7][3] = { { -3.0f, -3.0f, -1.0f }, { 3.0f, -3.0f, -1.0f }, { 3.0f, 3.0f, -1.0f },
                               { -3.0f, 3.0f, -1.0f },  { 0.1f, -0.8f, -0.8f }, { 1.2f, -0.8f, -0.8f },
                               { 1.2f, 0.8f, -0.8f } };
    float *at = pos + (size_t)sheet * 3;
    memcpy(at, more, sizeof more);
    at += 3 * 7;
    for (int i = 0; i < NARROW; i++) {
        const float y = -0.75f + 0.12f * (float)i, z = -0.8f + 0.1f * (float)(i + 1) * 1.98e-5f;
        const float corners[3][3] = { { 0.9f, y, z }, { 1.15f, y, z }, { 1.15f, y + 0.1f, z } };
        memcpy(at, corners, sizeof corners);
        at += 9;
    }
    const uint32_t more_idx[3][3] = { { sheet, sheet + 1, sheet + 2 },
                                      { sheet, sheet + 2, sheet + 3 },
                                      { sheet + 4, sheet + 5, sheet + 6 } };
    memcpy(idx + 3 * tris, more_idx, sizeof more_idx);
    tris += 3;
    for (uint32_t i = 0; i < NARROW; i++, tris++)
        for (uint32_t k = 0; k < 3; k++) idx[3 * tris + k] = sheet + 7 + 3 * i + k;
    /* The big triangle, its corners on the rays of pixels (57, 12), (75, 12) and (75, 30) at 1.8,
     * before the wide one and clear of the narrow ones. */
    const uint32_t big_pixels[3][2] = { { 57, 12 }, { 75, 12 }, { 75, 30 } };
    for (uint32_t k = 0; k < 3; k++) {
        const vkrt_ray *r = &rays[(size_t)big_pixels[k][1] * 97 + big_pixels[k][0]];
        for (int a = 0; a < 3; a++) at[3 * k + a] = r->origin[a] + r->dir[a] * 1.8f;
        idx[3 * tris + k] = sheet + 7 + 3 * NARROW + k;
    }
    tris++;
    vkrt_scene *s = mesh_scene(cpu, pos, sheet + extra, idx, tris, VKRT_BVH_BUILDER_DEFAULT);
    if (s) {
        size_t hidden = 0;
        lattice_lists_hold_hits(s, rays, n, "open sheet before a plane", &hidden);
        CHECK_MSG(hidden > 0, "the plane behind the sheet and the wide triangle was never left out");
        vkrt_scene_destroy(s);
    }
    free(idx);
    free(pos);
    free(rays);
}

/* The same mesh twice: *wide traced through the wide BVH, *binary kept to the binary one (the
 * test knob). */
static void wide_and_binary_scenes(const float *pos, uint32_t vertices, const uint32_t *idx, uint32_t tris,
                                   vkrt_bvh_builder builder, vkrt_scene **wide, vkrt_scene **binary)
{
    *wide = mesh_scene(gpu, pos, vertices, idx, tris, builder);
    gpu->vk->no_wide_traversal = true;
    *binary = mesh_scene(gpu, pos, vertices, idx, tris, builder);
    gpu->vk->no_wide_traversal = false;
}

/* ---- rays along the wide nodes' box planes ---- */

enum { GRID_CUBES = 5, PLANE_RAYS = 96 };

/* GRID_CUBES^3 cubes of side 1/2 at whole coordinates (12 triangles each): every vertex
 * coordinate is a multiple of 1/2, and so is every child box plane of the wide BVH, whose
 * quantisation steps are powers of two no coarser than that over this extent (wide_pack.c), so
 * the planes decode to the faces' coordinates exactly. */
static void make_cube_grid(float **out_pos, uint32_t **out_idx, uint32_t *out_vertices, uint32_t *out_tris)
{
    static const uint32_t faces[12][3] = { { 0, 2, 1 }, { 1, 2, 3 }, { 4, 5, 6 }, { 5, 7, 6 }, { 0, 1, 4 }, { 1, 5, 4 },
                                           { 2, 6, 3 }, { 3, 6, 7 }, { 0, 4, 2 }, { 2, 4, 6 }, { 1, 3, 5 }, { 3, 7, 5 } };
    const uint32_t cubes = GRID_CUBES * GRID_CUBES * GRID_CUBES;
    float *pos = malloc(cubes * 8 * 3 * sizeof *pos);
    uint32_t *idx = malloc(cubes * 36 * sizeof *idx);
    if (!pos || !idx) abort();
    for (uint32_t c = 0; c < cubes; c++) {
        const uint32_t cell[3] = { c % GRID_CUBES, c / GRID_CUBES % GRID_CUBES, c / (GRID_CUBES * GRID_CUBES) };
        for (uint32_t v = 0; v < 8; v++)
            for (int a = 0; a < 3; a++) pos[(c * 8 + v) * 3 + a] = (float)cell[a] + 0.5f * (float)(v >> a & 1u);
        for (uint32_t f = 0; f < 12; f++)
            for (int k = 0; k < 3; k++) idx[c * 36 + f * 3 + k] = c * 8 + faces[f][k];
    }
    *out_pos = pos;
    *out_idx = idx;
    *out_vertices = cubes * 8;
    *out_tris = cubes * 12;
}

/* Rays of the cube grid that lie in a face's plane (a +0 or -0 direction component, the origin
 * on the plane), half of them along a line where two planes meet (two zero components): in the
 * wide traversal's box test the plane's distance is 0 times an infinite reciprocal, NaN, on
 * every box bounded by that plane, which must count as the slab holding the whole ray, as
 * the binary traversal's slab() has it. The rays meet the faces across their path on their
 * edges and corners, hits the watertight test keeps; a box of those faces culled loses them.
 * The wide BVH's hits must be the binary one's bit for bit, closest and any-hit. */
static void gpu_wide_boxes_hold_rays_along_their_planes(void)
{
    float *pos;
    uint32_t *idx, vertices, tris;
    make_cube_grid(&pos, &idx, &vertices, &tris);
    vkrt_scene *wide, *binary;
    wide_and_binary_scenes(pos, vertices, idx, tris, VKRT_BVH_BUILDER_DEFAULT, &wide, &binary);
    free(pos);
    free(idx);
    const size_t planes = 2 * GRID_CUBES, n = 3 * planes * PLANE_RAYS;
    vkrt_ray *rays = calloc(n, sizeof *rays);
    if (!rays) abort();
    test_rng rng = { 4711 };
    size_t k = 0;
    for (int axis = 0; axis < 3; axis++)
        for (size_t plane = 0; plane < planes; plane++)
            for (int i = 0; i < PLANE_RAYS; i++, k++) {
                /* Across the grid along `across`, from outside it, in the plane of `axis`; a
                 * second zero component puts it on the plane `along` too. */
                const int across = (axis + 1 + (i & 1)) % 3, along = 3 - axis - across;
                const bool edge = (i & 2) != 0;
                vkrt_ray *r = &rays[k];
                r->origin[axis] = 0.5f * (float)plane;
                r->dir[axis] = rng_uniform(&rng) < 0.5 ? 0.0f : -0.0f;
                const bool from_low = rng_uniform(&rng) < 0.5;
                r->origin[across] = from_low ? -1.0f : (float)GRID_CUBES + 1.0f;
                r->dir[across] = (from_low ? 1.0f : -1.0f) * (float)(0.5 + rng_uniform(&rng));
                r->origin[along] = edge ? 0.5f * (float)((size_t)(rng_uniform(&rng) * (double)planes) % planes)
                                         : (float)(GRID_CUBES * rng_uniform(&rng));
                r->dir[along] = edge ? (rng_uniform(&rng) < 0.5 ? 0.0f : -0.0f) : (float)(rng_uniform(&rng) - 0.5);
            }
    if (wide && binary)
        CHECK_MSG(wide->gpu.wide && !binary->gpu.wide, "wide arrays uploaded: %d and %d", wide->gpu.wide, binary->gpu.wide);
    for (int any = 0; any < 2 && wide && binary; any++) {
        const vkrt_trace_desc d = { .any_hit = any };
        size_t hits, differ = wide_and_binary_differences(wide, binary, &d, rays, n, &hits);
        fprintf(stderr, "  any hit %d: %zu of %zu rays along planes differ (%zu hits)\n", any, differ, n, hits);
        CHECK_MSG(differ == 0 && hits > n / 4, "any hit %d: %zu of %zu rays differ, %zu hits", any, differ, n, hits);
    }
    free(rays);
    vkrt_scene_destroy(wide);
    vkrt_scene_destroy(binary);
}

/* ---- a wide BVH of more levels than a third of the stack ---- */

enum { CHAIN_TRIS = 70, CHAIN_UP_FROM = 61, CHAIN_RAYS = 64, CHAIN_RANDOM_RAYS = 4096 };

/* CHAIN_TRIS triangles in the planes x = 0.4^i, all with their centroid on the x axis, so the
 * midpoint builder splits the first off at each level (below the midpoint of 0.4^i and about 0:
 * the rest): a chain as deep as VKRT_MAX_BVH_DEPTH, its last leaf the triangles left at that
 * depth, which the 4-wide collapse makes 22 levels (three binary levels a wide node). In the
 * (y, z) plane, triangle i points down (vertices (-1, 1), (1, 1), (0, -2)) from CHAIN_UP_FROM
 * on and up ((-1, -1), (1, -1), (0, 2)) before: both boxes hold (0.6, +-0.9), which only the
 * up ones cover at z = -0.9 and only the down ones at z = 0.9. */
static void make_chain(float **out_pos, uint32_t **out_idx)
{
    float *pos = malloc(CHAIN_TRIS * 9 * sizeof *pos);
    uint32_t *idx = malloc(CHAIN_TRIS * 3 * sizeof *idx);
    if (!pos || !idx) abort();
    for (uint32_t i = 0; i < CHAIN_TRIS; i++) {
        const float x = (float)pow(0.4, (double)i), up = i < CHAIN_UP_FROM ? 1.0f : -1.0f;
        const float v[9] = { x, -1, -up, x, 1, -up, x, 0, 2 * up };
        memcpy(pos + i * 9, v, sizeof v);
        for (uint32_t k = 0; k < 3; k++) idx[i * 3 + k] = i * 3 + k;
    }
    *out_pos = pos;
    *out_idx = idx;
}

/* The wide traversal keeps one stack entry a level (a group of a node's children), so a wide BVH
 * of more than 21 levels (the bound of three entries a level, which sent such scenes to the
 * binary traversal) takes it too. Rays along +x from just before the chain's smallest plane
 * enter every node nearest child first: the chain's deeper part, leaving each node's leaves in a
 * group on the stack. Those at z = -0.9 hit only the up triangles, the nearest of which
 * (CHAIN_UP_FROM - 1) waits in the group pushed at the 21st level: a stack that lost its deepest
 * entries would answer with an earlier one. Those at z = 0.9 hit the last triangle first. With
 * rays from every side, closest and any-hit queries must give the binary traversal's hits bit
 * for bit. */
static void gpu_deep_wide_bvhs_take_the_wide_traversal(void)
{
    float *pos;
    uint32_t *idx;
    make_chain(&pos, &idx);
    vkrt_scene *wide, *binary;
    wide_and_binary_scenes(pos, CHAIN_TRIS * 3, idx, CHAIN_TRIS, VKRT_BVH_BUILDER_MIDPOINT, &wide, &binary);
    free(pos);
    free(idx);
    if (!wide || !binary) goto done;
    bvh4 collapsed;
    CHECK(bvh4_collapse(&gpu->core, &wide->bvh, &collapsed) == VKRT_OK);
    fprintf(stderr, "  chain: binary depth %u, %u wide levels\n", wide->bvh.depth, collapsed.depth);
    CHECK_MSG(wide->bvh.depth == VKRT_MAX_BVH_DEPTH && collapsed.depth > VKRT_TRAVERSAL_STACK_SIZE / 3,
              "binary depth %u, %u wide levels", wide->bvh.depth, collapsed.depth);
    bvh4_destroy(&gpu->core, &collapsed);
    CHECK_MSG(wide->gpu.wide && !binary->gpu.wide, "wide arrays uploaded: %d and %d", wide->gpu.wide, binary->gpu.wide);
    const size_t n = 2 * CHAIN_RAYS + CHAIN_RANDOM_RAYS;
    vkrt_ray *rays = calloc(n, sizeof *rays);
    if (!rays) abort();
    test_rng rng = { 271828 };
    for (size_t i = 0; i < n; i++) {
        vkrt_ray *r = &rays[i];
        if (i < 2 * CHAIN_RAYS) {
            const float z = i < CHAIN_RAYS ? -0.9f : 0.9f;
            *r = (vkrt_ray){ .origin = { -ldexpf(1.0f, -110), 0.6f + 0.2f * (float)rng_uniform(&rng),
                                         z + 0.05f * (float)(rng_uniform(&rng) - 0.5) },
                             .dir = { 1.0f, 0.001f * (float)(rng_uniform(&rng) - 0.5),
                                      0.001f * (float)(rng_uniform(&rng) - 0.5) } };
            continue;
        }
        /* From a sphere of radius 3 round the chain towards a point in its box. */
        double d[3];
        rng_unit_vector(&rng, d);
        const double target[3] = { rng_uniform(&rng), 2 * rng_uniform(&rng) - 1, 4 * rng_uniform(&rng) - 2 };
        for (int a = 0; a < 3; a++) {
            r->origin[a] = (float)(3 * d[a]);
            r->dir[a] = (float)(target[a] - 3 * d[a]);
        }
    }
    for (int any = 0; any < 2; any++) {
        const vkrt_trace_desc d = { .any_hit = any };
        size_t hits, differ = wide_and_binary_differences(wide, binary, &d, rays, n, &hits);
        fprintf(stderr, "  any hit %d: %zu of %zu rays differ (%zu hits)\n", any, differ, n, hits);
        CHECK_MSG(differ == 0 && hits > n / 4, "any hit %d: %zu of %zu rays differ, %zu hits", any, differ, n, hits);
    }
    vkrt_hit *h = trace_all(gpu, wide, &(vkrt_trace_desc){ 0 }, rays, 2 * CHAIN_RAYS);
    size_t wrong = 0;
    for (size_t i = 0; i < 2 * CHAIN_RAYS; i++)
        wrong += h[i].prim_id != (i < CHAIN_RAYS ? CHAIN_UP_FROM - 1u : CHAIN_TRIS - 1u);
    CHECK_MSG(wrong == 0, "%zu of %d rays along the chain hit another triangle than its nearest (ray 0: %u)", wrong,
              2 * CHAIN_RAYS, h[0].prim_id);
    free(h);
    free(rays);
done:
    vkrt_scene_destroy(wide);
    vkrt_scene_destroy(binary);
}

/* ---- traversals longer than lavapipe's loop limit (65,535 iterations per SIMD group) ---- */

enum { FAN_TRIS = 100000, STACK_TRIS = 70000, LONG_RAYS = 48 };
/* Rays down through the stacked leaf: a workgroup's worth and LONG_RAYS more, so that in the
 * wide traversal (ray slots of VKRT_WIDE_RAYS_PER_LANE rays, consecutive slots taking
 * consecutive rays) the lanes on the first LONG_RAYS slots go on to a second ray, and are saved
 * and resumed within it: a continuation that must restore which slot and which of its rays a
 * lane was on. */
enum { STACK_RAYS = VKRT_TRACE_GROUP_SIZE + LONG_RAYS };

/* FAN_TRIS triangles around the origin (the disc of radius 1 in z = 0): every box holds the
 * shared vertex, so a ray through it tests nearly every triangle. */
static void make_fan(float **out_pos, uint32_t **out_idx)
{
    float *pos = malloc((FAN_TRIS + 1) * 3 * sizeof *pos);
    uint32_t *idx = malloc(FAN_TRIS * 3 * sizeof *idx);
    if (!pos || !idx) abort();
    pos[0] = pos[1] = pos[2] = 0.0f;
    for (uint32_t i = 0; i < FAN_TRIS; i++) {
        double a = 6.283185307179586 * i / FAN_TRIS;
        pos[3 + i * 3] = (float)cos(a), pos[4 + i * 3] = (float)sin(a), pos[5 + i * 3] = 0.0f;
        idx[i * 3] = 0, idx[i * 3 + 1] = 1 + i, idx[i * 3 + 2] = 1 + (i + 1) % FAN_TRIS;
    }
    *out_pos = pos;
    *out_idx = idx;
}

/* STACK_TRIS triangles (-1, -1, d), (1, -1, -d), (0, 2, 0), d = k / 2^17: the same box centre
 * and the same vertex sum, so every builder makes them one leaf, and z = -d x, so a ray down
 * at x < 0 is nearest to the last triangle. */
static void make_leaf_stack(float **out_pos, uint32_t **out_idx)
{
    float *pos = malloc(STACK_TRIS * 9 * sizeof *pos);
    uint32_t *idx = malloc(STACK_TRIS * 3 * sizeof *idx);
    if (!pos || !idx) abort();
    for (uint32_t k = 0; k < STACK_TRIS; k++) {
        float d = (float)k / 131072.0f;
        const float v[9] = { -1, -1, d, 1, -1, -d, 0, 2, 0 };
        memcpy(pos + k * 9, v, sizeof v);
        for (uint32_t j = 0; j < 3; j++) idx[k * 3 + j] = k * 3 + j;
    }
    *out_pos = pos;
    *out_idx = idx;
}

/* Every ray hits on the GPU, where `exact` with the CPU's t and prim_id bit for bit, and with
 * a t within t_tolerance (relative) of the CPU's. */
static void check_long_rays(vkrt_scene *sg, vkrt_scene *sc, vkrt_intersector isect, bool exact, double t_tolerance,
                            const vkrt_ray *rays, size_t n, const char *what)
{
    vkrt_trace_desc d = { .intersector = isect };
    vkrt_hit *g = trace_all(gpu, sg, &d, rays, n), *c = trace_all(cpu, sc, &d, rays, n);
    size_t same = 0, hits = 0;
    double worst = 0.0;
    for (size_t i = 0; i < n; i++) {
        same += g[i].prim_id == c[i].prim_id && memcmp(&g[i].t, &c[i].t, sizeof g[i].t) == 0;
        hits += g[i].prim_id != VKRT_NO_HIT;
        if (g[i].prim_id != VKRT_NO_HIT && c[i].prim_id != VKRT_NO_HIT)
            worst = fmax(worst, fabs((double)g[i].t - c[i].t) / c[i].t);
    }
    fprintf(stderr, "  %s: %zu of %zu rays hit, %zu equal the CPU's, t within %.2g\n", what, hits, n, same, worst);
    CHECK_MSG(hits == n, "%s: %zu of %zu rays miss on the GPU", what, n - hits, n);
    CHECK_MSG(!exact || same == n, "%s: GPU hits equal the CPU's for %zu of %zu rays", what, same, n);
    CHECK_MSG(worst <= t_tolerance, "%s: t differs by %.3g relatively", what, worst);
    free(g);
    free(c);
}

/* Rays aimed exactly at the fan's shared vertex and down through the stacked leaf need over
 * 65,535 loop iterations each: on lavapipe the traversal stops at its budget and is resumed
 * by further dispatches, and the hits (t and prim_id) still equal the CPU's, with both
 * builders. Without the budget lavapipe ends the loops early and the hits differ. (GPU BVH
 * against GPU naive is no check here: through the vertex, triangle t and box t round
 * differently, so a box may be pruned whose triangle would win the tie by an ulp.) */
static void gpu_traversals_beyond_the_loop_limit_match_cpu(void)
{
    float *fan_pos, *stack_pos;
    uint32_t *fan_idx, *stack_idx;
    make_fan(&fan_pos, &fan_idx);
    make_leaf_stack(&stack_pos, &stack_idx);
    vkrt_ray fan_rays[LONG_RAYS], stack_rays[STACK_RAYS];
    test_rng rng = { 77 };
    for (int i = 0; i < STACK_RAYS; i++) {
        double d[3];
        do rng_unit_vector(&rng, d);
        while (fabs(d[2]) < 0.2);
        /* dir = -origin exactly, so the ray passes through the vertex at t = 1. */
        if (i < LONG_RAYS) {
            fan_rays[i] = (vkrt_ray){ .origin = { (float)(2 * d[0]), (float)(2 * d[1]), (float)(2 * d[2]) } };
            for (int a = 0; a < 3; a++) fan_rays[i].dir[a] = -fan_rays[i].origin[a];
        }
        stack_rays[i] = (vkrt_ray){ .origin = { (float)(-0.45 + 0.4 * rng_uniform(&rng)), (float)(rng_uniform(&rng) - 0.5), 2 },
                                    .dir = { 0, 0, -1 } };
    }
    const vkrt_bvh_builder builders[2] = { VKRT_BVH_BUILDER_BINNED_SAH, VKRT_BVH_BUILDER_MIDPOINT };
    for (int k = 0; k < 2; k++) {
        const vkrt_bvh_builder b = builders[k];
        const char *name = b == VKRT_BVH_BUILDER_MIDPOINT ? "midpoint" : "sah";
        char what[80];
        vkrt_scene *sg = mesh_scene(gpu, fan_pos, FAN_TRIS + 1, fan_idx, FAN_TRIS, b);
        vkrt_scene *sc = mesh_scene(cpu, fan_pos, FAN_TRIS + 1, fan_idx, FAN_TRIS, b);
        /* Through the vertex every edge value is zero, where the CPU's float watertight test
         * decides in double and the GPU's accepts; Moller-Trumbore gives each of the 100,000
         * triangles its own rounding of t = 1 there, and which of them wins depends on the
         * order the boxes are pruned in, which the GPU's wide traversal and the CPU's do not
         * share. Both must hit every ray (watertight must not leak), within a few ulps of t. */
        snprintf(what, sizeof what, "fan-%d, %s, watertight", FAN_TRIS, name);
        if (sg && sc) check_long_rays(sg, sc, VKRT_INTERSECTOR_WATERTIGHT, false, 1e-6, fan_rays, LONG_RAYS, what);
        snprintf(what, sizeof what, "fan-%d, %s, mt", FAN_TRIS, name);
        if (sg && sc) check_long_rays(sg, sc, VKRT_INTERSECTOR_MOLLER_TRUMBORE, false, 1e-6, fan_rays, LONG_RAYS, what);
        vkrt_scene_destroy(sg);
        vkrt_scene_destroy(sc);
        sg = mesh_scene(gpu, stack_pos, STACK_TRIS * 3, stack_idx, STACK_TRIS, b);
        sc = mesh_scene(cpu, stack_pos, STACK_TRIS * 3, stack_idx, STACK_TRIS, b);
        vkrt_scene_stats st = { 0 };
        if (sg && vkrt_scene_stats_get(sg, &st) == VKRT_OK)
            CHECK_MSG(st.max_leaf_triangles == STACK_TRIS, "%s: largest leaf %u, not all %d triangles", name,
                      st.max_leaf_triangles, STACK_TRIS);
        snprintf(what, sizeof what, "one leaf of %d, %s", STACK_TRIS, name);
        if (sg && sc) check_long_rays(sg, sc, VKRT_INTERSECTOR_WATERTIGHT, true, 0.0, stack_rays, STACK_RAYS, what);
        vkrt_scene_destroy(sg);
        vkrt_scene_destroy(sc);
    }
    free(fan_pos);
    free(fan_idx);
    free(stack_pos);
    free(stack_idx);
}

/* The stacked leaf seen from above: every pixel's ray tests all STACK_TRIS triangles of the
 * one leaf, so on lavapipe every pixel is saved and resumed, twice. id, depth and the
 * triangles-tested heatmap equal the CPU's pixel for pixel: the closest hit and the heat
 * counters survive the continuation. */
static void gpu_image_beyond_the_loop_limit_matches_cpu(void)
{
    float *pos;
    uint32_t *idx;
    make_leaf_stack(&pos, &idx);
    vkrt_scene *sg = mesh_scene(gpu, pos, STACK_TRIS * 3, idx, STACK_TRIS, VKRT_BVH_BUILDER_DEFAULT);
    vkrt_scene *sc = mesh_scene(cpu, pos, STACK_TRIS * 3, idx, STACK_TRIS, VKRT_BVH_BUILDER_DEFAULT);
    const uint32_t w = 9, h = 7;
    const vkrt_mode modes[3] = { VKRT_MODE_ID, VKRT_MODE_DEPTH, VKRT_MODE_HEATMAP };
    for (int m = 0; sg && sc && m < 3; m++) {
        vkrt_render_desc d = { .width = w, .height = h, .mode = modes[m], .heat = VKRT_HEAT_TRIS,
                               .camera = { .eye = { -0.2f, 0, 3 }, .target = { -0.2f, 0, 0 }, .fov_y_degrees = 10 } };
        float *g = render(gpu, sg, &d), *c = render(cpu, sc, &d);
        size_t same = 0, long_rays = 0;
        for (size_t i = 0; g && c && i < (size_t)w * h; i++) {
            same += memcmp(g + i * 4, c + i * 4, 4 * sizeof *g) == 0;
            long_rays += g[i * 4] == (float)STACK_TRIS;
        }
        CHECK_MSG(same == (size_t)w * h, "mode %d: %zu of %u pixels equal the CPU's", (int)modes[m], same, w * h);
        if (modes[m] == VKRT_MODE_HEATMAP)
            CHECK_MSG(long_rays == (size_t)w * h, "only %zu of %u pixels test all %d triangles", long_rays, w * h,
                      STACK_TRIS);
        free(g);
        free(c);
    }
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
    free(pos);
    free(idx);
}

/* The heatmap's three counts of every pixel, summed: what vkrt_render_stats' traversal
 * counters must report for the same render. */
static void heatmap_sums(vkrt_context *ctx, vkrt_scene *s, vkrt_render_desc d, uint64_t out[3])
{
    d.mode = VKRT_MODE_HEATMAP;
    d.traversal_counters = false;
    for (int k = 0; k < 3; k++) {
        d.heat = (vkrt_heat)(VKRT_HEAT_NODES + k);
        float *img = render(ctx, s, &d);
        out[k] = 0;
        for (size_t i = 0; img && i < (size_t)d.width * d.height; i++) out[k] += (uint64_t)img[i * 4];
        free(img);
    }
}

static vkrt_render_stats counted_render(vkrt_context *ctx, vkrt_scene *s, vkrt_render_desc d)
{
    size_t n = vkrt_render_floats(d.width, d.height);
    float *rgba = malloc(n * sizeof *rgba);
    vkrt_render_stats st = { 0 };
    d.traversal_counters = true;
    vkrt_result r = rgba ? vkrt_render(ctx, s, &d, rgba, n, &st) : VKRT_ERROR_OUT_OF_MEMORY;
    CHECK_MSG(r == VKRT_OK, "render: %s", vkrt_context_last_error(ctx));
    free(rgba);
    return st;
}

/* vkrt_render_stats' traversal counters on both backends: equal to the sums of the same
 * backend's heatmaps (BVH; on bunny with both builders, and the leaf stack whose rays run past
 * lavapipe's loop limit and resume), within 1% between GPU and CPU, zero when not asked for,
 * and triangles x rays for naive traversal. */
static void gpu_traversal_counters_sum_the_heatmap(void)
{
    const uint32_t w = 96, h = 64;
    for (int b = 0; b < 3; b++) {
        vkrt_scene *sg = NULL, *sc = NULL;
        /* BVH named: the default traversal of the leaf stack (one leaf) is naive by the cost model. */
        vkrt_render_desc d = { .width = w, .height = h, .traversal = VKRT_TRAVERSAL_BVH };
        float *pos = NULL;
        uint32_t *idx = NULL;
        if (b < 2) {
            vkrt_bvh_builder builder = b ? VKRT_BVH_BUILDER_MIDPOINT : VKRT_BVH_BUILDER_DEFAULT;
            sg = make_scene(gpu, VKRT_MODELS_DIR "/meshes/bunny.obj", builder);
            sc = make_scene(cpu, VKRT_MODELS_DIR "/meshes/bunny.obj", builder);
        } else {
            make_leaf_stack(&pos, &idx);
            sg = mesh_scene(gpu, pos, STACK_TRIS * 3, idx, STACK_TRIS, VKRT_BVH_BUILDER_DEFAULT);
            sc = mesh_scene(cpu, pos, STACK_TRIS * 3, idx, STACK_TRIS, VKRT_BVH_BUILDER_DEFAULT);
            d = (vkrt_render_desc){ .width = 9, .height = 7, .traversal = VKRT_TRAVERSAL_BVH,
                                    .camera = { .eye = { -0.2f, 0, 3 }, .target = { -0.2f, 0, 0 }, .fov_y_degrees = 10 } };
        }
        for (int k = 0; sg && sc && k < 2; k++) {
            vkrt_context *ctx = k ? cpu : gpu;
            vkrt_scene *s = k ? sc : sg;
            uint64_t sums[3];
            heatmap_sums(ctx, s, d, sums);
            vkrt_render_stats st = counted_render(ctx, s, d);
            fprintf(stderr, "  case %d %s: %llu rays, %llu nodes, %llu leaves, %llu triangle tests\n", b, k ? "cpu" : "gpu",
                    (unsigned long long)st.rays, (unsigned long long)st.nodes_visited,
                    (unsigned long long)st.leaves_visited, (unsigned long long)st.tris_tested);
            CHECK_MSG(st.nodes_visited == sums[0] && st.leaves_visited == sums[1] && st.tris_tested == sums[2],
                      "case %d %s: counters %llu %llu %llu, heatmap sums %llu %llu %llu", b, k ? "cpu" : "gpu",
                      (unsigned long long)st.nodes_visited, (unsigned long long)st.leaves_visited,
                      (unsigned long long)st.tris_tested, (unsigned long long)sums[0], (unsigned long long)sums[1],
                      (unsigned long long)sums[2]);
            /* A pushed leaf may be culled before its triangles are tested: tests can be fewer. */
            CHECK_MSG(st.leaves_visited > 0 && st.leaves_visited <= st.nodes_visited && st.tris_tested > 0,
                      "case %d: implausible counters", b);
        }
        vkrt_render_stats g = counted_render(gpu, sg, d), c = counted_render(cpu, sc, d);
        CHECK_MSG(llabs((long long)g.nodes_visited - (long long)c.nodes_visited) * 100 <= (long long)c.nodes_visited &&
                      llabs((long long)g.tris_tested - (long long)c.tris_tested) * 100 <= (long long)c.tris_tested,
                  "case %d: GPU and CPU counters differ by more than 1%%", b);
        vkrt_render_stats plain = { .nodes_visited = 1 };
        size_t n = vkrt_render_floats(d.width, d.height);
        float *rgba = malloc(n * sizeof *rgba);
        CHECK(rgba && vkrt_render(gpu, sg, &d, rgba, n, &plain) == VKRT_OK);
        CHECK_MSG(plain.nodes_visited == 0 && plain.tris_tested == 0, "counters filled without being asked for");
        if (b == 0) {
            vkrt_scene_stats ss;
            CHECK(vkrt_scene_stats_get(sg, &ss) == VKRT_OK);
            d.traversal = VKRT_TRAVERSAL_NAIVE;
            for (int k = 0; k < 2; k++) {
                vkrt_render_stats st = counted_render(k ? cpu : gpu, k ? sc : sg, d);
                CHECK_MSG(st.nodes_visited == 0 && st.tris_tested == (uint64_t)ss.triangles * w * h,
                          "naive %s: %llu triangle tests, expected %llu", k ? "cpu" : "gpu",
                          (unsigned long long)st.tris_tested, (unsigned long long)ss.triangles * w * h);
            }
        }
        free(rgba);
        free(pos);
        free(idx);
        vkrt_scene_destroy(sg);
        vkrt_scene_destroy(sc);
    }
}

/* Two unit squares side by side in z = 0 (x in [-1, 0] and [0, 1], y in [-0.5, 0.5]), each
 * with its own material and the unit square's texture coordinates, seen face on from
 * (0, 0, 2): a hit pixel's albedo is its square's base colour and alpha exactly, and its uv the
 * position within the square (u = x - x0, v = y + 0.5) to float rounding; on both backends,
 * bit for bit alike. Files and the built-in scene: GPU and CPU alike, and the stats. */
static void gpu_albedo_and_uv_show_materials_and_texture_coordinates(void)
{
    static const float pos[2][12] = { { -1, -0.5f, 0, 0, -0.5f, 0, 0, 0.5f, 0, -1, 0.5f, 0 },
                                      { 0, -0.5f, 0, 1, -0.5f, 0, 1, 0.5f, 0, 0, 0.5f, 0 } };
    static const float uv[8] = { 0, 0, 1, 0, 1, 1, 0, 1 };
    static const uint32_t idx[6] = { 0, 1, 2, 0, 2, 3 };
    const vkrt_material mats[2] = { { .base_color = { 0.25f, 0.5f, 0.75f, 1.0f }, .roughness = 0.5f },
                                    { .base_color = { 1.0f, 0.125f, 0.0f, 0.5f }, .metallic = 1.0f } };
    vkrt_mesh_desc md[2];
    for (int i = 0; i < 2; i++)
        md[i] = (vkrt_mesh_desc){ .positions = pos[i], .vertex_count = 4, .indices = idx, .index_count = 6,
                                  .texcoords = uv, .material = &mats[i] };
    vkrt_scene_desc sd = { .meshes = md, .mesh_count = 2, .keep_world_coordinates = true };
    vkrt_scene *sg = NULL, *sc = NULL;
    CHECK(vkrt_scene_create(gpu, &sd, &sg) == VKRT_OK);
    CHECK(vkrt_scene_create(cpu, &sd, &sc) == VKRT_OK);
    const uint32_t w = 48, h = 48;
    const double half = tan(30.0 * 3.14159265358979323846 / 180.0);
    vkrt_render_desc d = { .width = w, .height = h, .camera = { .eye = { 0, 0, 2 }, .fov_y_degrees = 60 } };
    for (int mode = 0; sg && sc && mode < 2; mode++) {
        d.mode = mode ? VKRT_MODE_UV : VKRT_MODE_ALBEDO;
        float *g = render(gpu, sg, &d), *c = render(cpu, sc, &d);
        CHECK_MSG(g && c && memcmp(g, c, (size_t)w * h * 4 * sizeof *g) == 0, "mode %d: GPU and CPU images differ", (int)d.mode);
        size_t hits = 0, wrong = 0;
        for (uint32_t y = 0; g && y < h; y++)
            for (uint32_t x = 0; x < w; x++) {
                const float *p = g + ((size_t)y * w + x) * 4;
                double sx = 2.0 * (x + 0.5) / w - 1.0, sy = 1.0 - 2.0 * (y + 0.5) / h;
                double hx = 2.0 * sx * half, hy = 2.0 * sy * half; /* the hit in z = 0 */
                bool inside = fabs(hx) < 1.0 && fabs(hy) < 0.5;
                bool on_edge = fabs(fabs(hx) - 1.0) < 0.05 || fabs(fabs(hy) - 0.5) < 0.05 || fabs(hx) < 0.05;
                if (on_edge) continue; /* pixel centres close to an edge: not decided here */
                if (!inside) {
                    wrong += p[0] != 0.0f || p[1] != 0.0f || p[2] != 0.0f || p[3] != 0.0f;
                    continue;
                }
                hits++;
                int square = hx > 0.0;
                if (d.mode == VKRT_MODE_ALBEDO) {
                    wrong += memcmp(p, mats[square].base_color, 4 * sizeof(float)) != 0;
                } else {
                    double u = hx - (square ? 0.0 : -1.0), v = hy + 0.5;
                    wrong += fabs(p[0] - u) > 1e-5 || fabs(p[1] - v) > 1e-5 || p[2] != 0.0f || p[3] != 1.0f;
                }
            }
        CHECK_MSG(hits > (size_t)w * h / 4 && wrong == 0, "mode %d: %zu of %zu decided pixels wrong", (int)d.mode, wrong,
                  hits);
        free(g);
        free(c);
    }
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);

    /* A textured square: 2x2 texels (sRGB 0, 64, 128, 255 in red; alpha 255), repeat in u and
     * clamp in v, the unit square's coordinates times 2 in u. Every decided pixel's albedo is
     * the base colour times the bilinear blend of the decoded texels, computed here in double. */
    static const uint8_t texels8[16] = { 0, 10, 20, 255, 64, 10, 20, 255, 128, 10, 20, 255, 255, 10, 20, 255 };
    const vkrt_texture_desc tex = { .rgba8 = texels8, .width = 2, .height = 2, .wrap_u = VKRT_WRAP_REPEAT,
                                    .wrap_v = VKRT_WRAP_CLAMP };
    const vkrt_material textured = { .base_color = { 1.0f, 0.5f, 1.0f, 1.0f }, .roughness = 1.0f,
                                     .base_color_texture = &tex };
    static const float uv2[8] = { 0, 0, 2, 0, 2, 1, 0, 1 };
    vkrt_mesh_desc one = { .positions = pos[1], .vertex_count = 4, .indices = idx, .index_count = 6, .texcoords = uv2,
                           .material = &textured };
    sd = (vkrt_scene_desc){ .meshes = &one, .mesh_count = 1, .keep_world_coordinates = true };
    CHECK(vkrt_scene_create(gpu, &sd, &sg) == VKRT_OK);
    CHECK(vkrt_scene_create(cpu, &sd, &sc) == VKRT_OK);
    d.mode = VKRT_MODE_ALBEDO;
    if (sg && sc) {
        float *g = render(gpu, sg, &d), *c = render(cpu, sc, &d);
        CHECK_MSG(g && c && memcmp(g, c, (size_t)w * h * 4 * sizeof *g) == 0, "textured albedo: GPU and CPU differ");
        double lin[4];
        for (int i = 0; i < 4; i++) {
            double s = texels8[4 * i] / 255.0;
            lin[i] = s <= 0.04045 ? s / 12.92 : pow((s + 0.055) / 1.055, 2.4);
        }
        size_t hits = 0, wrong = 0;
        double max_err = 0.0;
        for (uint32_t y = 0; g && y < h; y++)
            for (uint32_t x = 0; x < w; x++) {
                double sx = 2.0 * (x + 0.5) / w - 1.0, sy = 1.0 - 2.0 * (y + 0.5) / h;
                double hx = 2.0 * sx * half, hy = 2.0 * sy * half;
                if (!(hx > 0.05 && hx < 0.95 && fabs(hy) < 0.45)) continue;
                hits++;
                double u = 2.0 * hx, v = hy + 0.5; /* corners 0 and 1 (y = -0.5) have v = 0 */
                double tu = u - floor(u), px = tu * 2 - 0.5, py = fmin(fmax(v, -1.0), 2.0) * 2 - 0.5;
                double fx = px - floor(px), fy = py - floor(py);
                int ix = (int)floor(px), iy = (int)floor(py);
                int xa = (ix + 2) % 2, xb = (ix + 3) % 2;
                int ya = iy < 0 ? 0 : (iy > 1 ? 1 : iy), yb = iy + 1 < 0 ? 0 : (iy + 1 > 1 ? 1 : iy + 1);
                double red = (lin[ya * 2 + xa] * (1 - fx) + lin[ya * 2 + xb] * fx) * (1 - fy) +
                             (lin[yb * 2 + xa] * (1 - fx) + lin[yb * 2 + xb] * fx) * fy;
                const float *p = g + ((size_t)y * w + x) * 4;
                double err = fabs(p[0] - red);
                max_err = fmax(max_err, err);
                wrong += err > 2e-3 || fabs(p[3] - 1.0) > 1e-3;
            }
        CHECK_MSG(hits > 100 && wrong == 0, "textured albedo: %zu of %zu pixels off (max error %.3g)", wrong, hits,
                  max_err);
        free(g);
        free(c);
    }
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);

    const char *files[3] = { VKRT_MODELS_DIR "/gltf/draco/three_meshes_two_materials_one_no_material/"
                                             "three_meshes_two_materials_one_no_material.gltf",
                             VKRT_MODELS_DIR "/gltf/draco/Box/Box.gltf", NULL };
    for (int f = 0; f < 3; f++) {
        sg = make_scene(gpu, files[f], VKRT_BVH_BUILDER_DEFAULT);
        sc = make_scene(cpu, files[f], VKRT_BVH_BUILDER_DEFAULT);
        vkrt_scene_stats st;
        CHECK(sg && vkrt_scene_stats_get(sg, &st) == VKRT_OK);
        if (f == 2) CHECK_MSG(st.materials == 4 && st.has_texcoords, "built-in scene: %u materials", st.materials);
        CHECK(st.host_bytes >= st.node_bytes + st.triangle_bytes + st.surface_bytes + 4 * st.triangles);
        d = (vkrt_render_desc){ .width = 40, .height = 40 };
        for (int mode = 0; sg && sc && mode < 2; mode++) {
            d.mode = mode ? VKRT_MODE_UV : VKRT_MODE_ALBEDO;
            float *g = render(gpu, sg, &d), *c = render(cpu, sc, &d);
            size_t same = 0;
            for (size_t i = 0; g && c && i < 40 * 40; i++) same += memcmp(g + 4 * i, c + 4 * i, 4 * sizeof *g) == 0;
            CHECK_MSG(same >= 40 * 40 - 2, "%s mode %d: %zu of 1600 pixels equal", files[f] ? files[f] : "built-in",
                      (int)d.mode, same);
            free(g);
            free(c);
        }
        vkrt_scene_destroy(sg);
        vkrt_scene_destroy(sc);
    }
}

/* Alpha MASK: a square (z = 0.5) whose 2x2 texture is opaque on one diagonal and clear on the
 * other, cut at 0.5, in front of an opaque square (z = 0): near each texel centre the `id`
 * image shows the front square where its texel is opaque and the back one where it is clear,
 * on both backends, bit for bit alike, BVH = naive; vkrt_trace_rays passes through too. */
static void gpu_alpha_masked_surfaces_let_rays_through(void)
{
    static const float front[12] = { -1, -1, 0.5f, 1, -1, 0.5f, 1, 1, 0.5f, -1, 1, 0.5f };
    static const float back[12] = { -2, -2, 0, 2, -2, 0, 2, 2, 0, -2, 2, 0 };
    static const float uv[8] = { 0, 1, 1, 1, 1, 0, 0, 0 }; /* v = 0 at the top (y = 1) */
    static const uint32_t idx[6] = { 0, 1, 2, 0, 2, 3 };
    static const uint8_t texels8[16] = { 255, 255, 255, 255, 255, 255, 255, 0, 255, 255, 255, 0, 255, 255, 255, 255 };
    const vkrt_texture_desc tex = { .rgba8 = texels8, .width = 2, .height = 2, .wrap_u = VKRT_WRAP_CLAMP,
                                    .wrap_v = VKRT_WRAP_CLAMP };
    const vkrt_material masked = { .base_color = { 1, 1, 1, 1 }, .roughness = 1, .base_color_texture = &tex,
                                   .alpha_cutoff = 0.5f };
    vkrt_mesh_desc md[2] = {
        { .positions = front, .vertex_count = 4, .indices = idx, .index_count = 6, .texcoords = uv, .material = &masked },
        { .positions = back, .vertex_count = 4, .indices = idx, .index_count = 6 },
    };
    vkrt_scene_desc sd = { .meshes = md, .mesh_count = 2, .keep_world_coordinates = true };
    vkrt_scene *sg = NULL, *sc = NULL;
    CHECK(vkrt_scene_create(gpu, &sd, &sg) == VKRT_OK);
    CHECK(vkrt_scene_create(cpu, &sd, &sc) == VKRT_OK);
    vkrt_scene_stats st;
    CHECK(sg && vkrt_scene_stats_get(sg, &st) == VKRT_OK && st.alpha_tested);
    const uint32_t w = 40, h = 40;
    vkrt_render_desc d = { .width = w, .height = h, .mode = VKRT_MODE_ID,
                           .camera = { .eye = { 0, 0, 3 }, .fov_y_degrees = 50 } };
    float *g = sg ? render(gpu, sg, &d) : NULL, *c = sc ? render(cpu, sc, &d) : NULL;
    d.traversal = VKRT_TRAVERSAL_NAIVE;
    float *gn = sg ? render(gpu, sg, &d) : NULL;
    /* Triangle ids only: on the back square's diagonal (a shared edge) the CPU's exact zero rule
     * may change the barycentrics by an ulp (Robustness rules), never the triangle. */
    size_t same_ids = 0;
    for (size_t i = 0; g && c && i < (size_t)w * h; i++) same_ids += g[4 * i] == c[4 * i];
    CHECK_MSG(same_ids == (size_t)w * h, "alpha-tested id images: GPU and CPU ids differ on %zu pixels",
              (size_t)w * h - same_ids);
    CHECK_MSG(g && gn && memcmp(g, gn, (size_t)w * h * 4 * sizeof *g) == 0, "alpha-tested id images: BVH and naive differ");
    const double half = tan(25.0 * 3.14159265358979323846 / 180.0);
    size_t decided = 0, wrong = 0;
    for (uint32_t y = 0; g && y < h; y++)
        for (uint32_t x = 0; x < w; x++) {
            double sx = 2.0 * (x + 0.5) / w - 1.0, sy = 1.0 - 2.0 * (y + 0.5) / h;
            double fx = 2.5 * sx * half, fy = 2.5 * sy * half; /* where the ray crosses z = 0.5 */
            double u = (fx + 1) / 2, v = (1 - fy) / 2;
            if (fabs(fmod(u, 0.5) - 0.25) > 0.1 || fabs(fmod(v, 0.5) - 0.25) > 0.1 || u < 0 || u > 1 || v < 0 || v > 1)
                continue; /* only near a texel centre is the blended alpha far from the cutoff */
            decided++;
            bool opaque = (u < 0.5) == (v < 0.5); /* texels (0, 0) and (1, 1) */
            float id = g[((size_t)y * w + x) * 4];
            wrong += opaque ? !(id == 0.0f || id == 1.0f) : !(id == 2.0f || id == 3.0f);
        }
    CHECK_MSG(decided > 50 && wrong == 0, "alpha test: %zu of %zu decided pixels wrong", wrong, decided);
    /* Rays through the centres of a clear and an opaque texel. */
    vkrt_ray rays[2] = { { .origin = { 0.5f, 0.5f, 2 }, .dir = { 0, 0, -1 } }, { .origin = { -0.5f, 0.5f, 2 }, .dir = { 0, 0, -1 } } };
    for (int k = 0; sg && sc && k < 2; k++) {
        vkrt_hit hits[2];
        CHECK(vkrt_trace_rays(k ? cpu : gpu, k ? sc : sg, &(vkrt_trace_desc){ 0 }, rays, 2, hits) == VKRT_OK);
        CHECK_MSG(hits[0].prim_id >= 2 && hits[0].t == 2.0f && hits[1].prim_id < 2 && hits[1].t == 1.5f,
                  "%s rays: prim %u at %g, prim %u at %g", k ? "cpu" : "gpu", hits[0].prim_id, (double)hits[0].t,
                  hits[1].prim_id, (double)hits[1].t);
    }
    free(g);
    free(c);
    free(gn);
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
}

/* Double precision is the CPU reference's alone: the GPU refuses it with a message saying so. */
static void gpu_refuses_double_precision(void)
{
    vkrt_scene *s = unit_cube_scene(gpu);
    if (!s) return;
    float px[16];
    vkrt_render_desc d = { .width = 2, .height = 2, .precision = VKRT_PRECISION_DOUBLE };
    CHECK(vkrt_render(gpu, s, &d, px, 16, NULL) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(vkrt_context_last_error(gpu), "CPU backend") != NULL);
    vkrt_ray ray = { .origin = { 0, 0, 2 }, .dir = { 0, 0, -1 } };
    vkrt_hit hit;
    CHECK(vkrt_trace_rays(gpu, s, &(vkrt_trace_desc){ .precision = VKRT_PRECISION_DOUBLE }, &ray, 1, &hit) ==
          VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(vkrt_context_last_error(gpu), "precision") != NULL);
    vkrt_scene_destroy(s);
}

/* From inside a closed icosphere every pixel hits. */
static void gpu_eye_inside_a_closed_mesh_always_hits(void)
{
    closed_mesh m = icosphere(3, 1.0, (const double[3]){ 0, 0, 0 });
    vkrt_scene *s = closed_mesh_scene(gpu, &m);
    if (s) {
        vkrt_render_desc d = { .width = 40, .height = 32, .mode = VKRT_MODE_ID,
                               .camera = { .eye = { 0.1f, -0.2f, 0.15f }, .target = { 1, 0.3f, 0.15f }, .fov_y_degrees = 120 } };
        float *img = render(gpu, s, &d);
        size_t misses = 0;
        for (size_t i = 0; img && i < 40 * 32; i++) misses += img[i * 4] < 0;
        CHECK_MSG(misses == 0, "%zu pixels miss from inside", misses);
        free(img);
        vkrt_scene_destroy(s);
    }
    closed_mesh_free(&m);
}

/* A CPU device's buffers are ordinary host memory, mapped: vk_buffer asks for huge pages for a
 * large one before anything is written to it, as core_alloc does for the library's arrays.
 * (A real GPU's mapped memory is the device's, which takes no such advice.) */
static void gpu_large_mapped_buffers_are_advised_huge_pages(void)
{
    vk_context *vk = gpu->vk;
    if (vk->properties.deviceType != VK_PHYSICAL_DEVICE_TYPE_CPU) {
        fprintf(stderr, "  not a CPU device: its mapped memory is the device's\n");
        return;
    }
    vk_buffer b = { 0 };
    const size_t size = 4 * CORE_HUGE_PAGE_MIN;
    CHECK(vk_buffer_create(vk, size, VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, VK_MEMORY_DEVICE, "huge page test", &b) ==
          VKRT_OK);
    CHECK_MSG(b.mapped != NULL, "lavapipe's device memory is not mapped");
    if (b.mapped) {
        int advised = mapping_advised_huge((unsigned char *)b.mapped + size / 2);
        CHECK_MSG(advised == 1, "a %zu-byte mapped buffer: advised %d", size, advised);
    }
    vk_buffer_destroy(vk, &b);
}

/* Naive traversal reads VKRT_NAIVE_SHARE triangles a step, one a lane, and every lane of the
 * subgroup tests them all (trace_naive_chunk). The rule that sets the share (vk_naive_share);
 * on lavapipe, whose subgroups are its SIMD groups, the reads are shared and its shaders say so;
 * and a context that reads every triangle in every lane (a share of 1, the path of devices
 * without subgroup votes and ballots) gives the same images at a size whose rows end inside a
 * subgroup, and the same hits for a ray count that ends inside one (a ray at each triangle and
 * three invalid ones), closest and any-hit, as the BVH does. */
static void gpu_naive_traversal_shares_triangle_reads_across_a_subgroup(void)
{
    const VkSubgroupFeatureFlags basic = VK_SUBGROUP_FEATURE_BASIC_BIT, vote = VK_SUBGROUP_FEATURE_VOTE_BIT,
                                 ballot = VK_SUBGROUP_FEATURE_BALLOT_BIT, all = basic | vote | ballot;
    const struct {
        uint32_t size;
        VkShaderStageFlags stages;
        VkSubgroupFeatureFlags operations;
        uint32_t share;
    } rules[] = {
        { 8, VK_SHADER_STAGE_COMPUTE_BIT, all, 8 },
        { 4, VK_SHADER_STAGE_COMPUTE_BIT, all | VK_SUBGROUP_FEATURE_SHUFFLE_BIT, 4 },
        { 32, VK_SHADER_STAGE_ALL, all, VKRT_NAIVE_SHARE_MAX },
        { 64, VK_SHADER_STAGE_COMPUTE_BIT, all, VKRT_NAIVE_SHARE_MAX },
        { 1, VK_SHADER_STAGE_COMPUTE_BIT, all, 1 },
        { 2 * VKRT_TRACE_GROUP_SIZE, VK_SHADER_STAGE_COMPUTE_BIT, all, 1 },
        { 8, VK_SHADER_STAGE_FRAGMENT_BIT, all, 1 },
        { 8, VK_SHADER_STAGE_COMPUTE_BIT, basic | ballot, 1 },
        { 8, VK_SHADER_STAGE_COMPUTE_BIT, basic | vote, 1 },
    };
    for (size_t i = 0; i < sizeof rules / sizeof rules[0]; i++) {
        VkPhysicalDeviceSubgroupProperties props = { .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES,
                                                     .subgroupSize = rules[i].size,
                                                     .supportedStages = rules[i].stages,
                                                     .supportedOperations = rules[i].operations };
        uint32_t share = vk_naive_share(&props);
        CHECK_MSG(share == rules[i].share, "rule %zu: subgroups of %u share %u, wanted %u", i, rules[i].size, share,
                  rules[i].share);
    }
    if (gpu->vk->trace_budget != 0)
        CHECK_MSG(gpu->vk->naive_share >= 4, "lavapipe's naive traversal shares %u lanes' reads", gpu->vk->naive_share);
    char *source = vk_shader_source(gpu->vk, vkrt_shader_trace_comp), define[48];
    snprintf(define, sizeof define, "#define VKRT_NAIVE_SHARE %u\n", gpu->vk->naive_share);
    CHECK_MSG(source && strstr(source, define), "the shaders do not say the device's share (%u)", gpu->vk->naive_share);
    core_free(gpu->vk->core, source);

    vkrt_context *alone = NULL;
    vkrt_context_desc desc = { .backend = VKRT_BACKEND_GPU, .log = check_gpu_log, .validation = true,
                               .pipeline_cache_path = getenv("VKRT_PIPELINE_CACHE") };
    CHECK(vkrt_context_create(&desc, &alone) == VKRT_OK);
    if (!alone) return;
    alone->vk->naive_share = 1;
    const char *path = VKRT_MODELS_DIR "/meshes/bunny.obj";
    vkrt_scene *shared_scene = make_scene(gpu, path, VKRT_BVH_BUILDER_DEFAULT);
    vkrt_scene *alone_scene = make_scene(alone, path, VKRT_BVH_BUILDER_DEFAULT);
    const uint32_t w = 21, h = 13;
    for (int k = 0; shared_scene && alone_scene && k < 2; k++) {
        vkrt_render_desc d = { .width = w, .height = h, .mode = k ? VKRT_MODE_ID : VKRT_MODE_DEPTH,
                               .traversal = VKRT_TRAVERSAL_BVH };
        float *through_bvh = render(gpu, shared_scene, &d);
        d.traversal = VKRT_TRAVERSAL_NAIVE;
        float *shared_image = render(gpu, shared_scene, &d), *alone_image = render(alone, alone_scene, &d);
        if (through_bvh && shared_image && alone_image) {
            size_t bytes = (size_t)w * h * 4 * sizeof(float), hits = 0;
            for (size_t i = 0; i < (size_t)w * h; i++) hits += through_bvh[i * 4] >= 0;
            CHECK_MSG(memcmp(through_bvh, shared_image, bytes) == 0, "mode %d: shared naive reads differ from the BVH's image", k);
            CHECK_MSG(memcmp(through_bvh, alone_image, bytes) == 0, "mode %d: unshared naive reads differ from the BVH's image", k);
            CHECK_MSG(hits > (size_t)w * h / 10, "mode %d: only %zu pixels hit", k, hits);
        }
        free(through_bvh);
        free(shared_image);
        free(alone_image);
    }
    /* A ray towards each triangle's centroid from a hundredth along its normal, which hits it
     * unless another triangle lies in between, so that a triangle left untested changes an
     * answer; then three invalid rays. 3,677 rays: the last subgroup ends part-way. */
    vkrt_scene_stats stats = { 0 };
    if (shared_scene) vkrt_scene_stats_get(shared_scene, &stats);
    const size_t tris = stats.triangles, n = tris + 3;
    float *corners = malloc(tris * 9 * sizeof *corners);
    vkrt_ray *rays = calloc(n, sizeof *rays);
    const bool ready = corners && rays && tris && vkrt_scene_triangles_get(shared_scene, corners, tris * 9) == VKRT_OK;
    CHECK_MSG(ready, "the bunny's %zu triangles", tris);
    for (size_t t = 0; ready && t < tris; t++) {
        const float *v = corners + 9 * t;
        double e1[3], e2[3], normal[3], length = 0.0;
        for (int a = 0; a < 3; a++) e1[a] = (double)v[3 + a] - v[a], e2[a] = (double)v[6 + a] - v[a];
        for (int a = 0; a < 3; a++) {
            normal[a] = e1[(a + 1) % 3] * e2[(a + 2) % 3] - e1[(a + 2) % 3] * e2[(a + 1) % 3];
            length += normal[a] * normal[a];
        }
        length = sqrt(length) > 0.0 ? sqrt(length) : 1.0;
        for (int a = 0; a < 3; a++) {
            double centroid = ((double)v[a] + v[3 + a] + v[6 + a]) / 3.0;
            rays[t].origin[a] = (float)(centroid + 0.01 * normal[a] / length);
            rays[t].dir[a] = (float)(-normal[a] / length);
        }
    }
    if (ready) {
        rays[tris] = (vkrt_ray){ .origin = { 0.0f, NAN, 2.0f }, .dir = { 0.0f, 0.0f, -1.0f } };
        rays[tris + 1] = (vkrt_ray){ .origin = { 0.0f, 0.0f, 2.0f } }; /* a zero direction */
        rays[tris + 2] = (vkrt_ray){ .origin = { 0.0f, 0.0f, 2.0f }, .dir = { 0.0f, 0.0f, -INFINITY } };
    }
    for (int any = 0; ready && alone_scene && any < 2; any++) {
        vkrt_trace_desc d = { .any_hit = any, .traversal = VKRT_TRAVERSAL_BVH };
        vkrt_hit *through_bvh = trace_all(gpu, shared_scene, &d, rays, n);
        d.traversal = VKRT_TRAVERSAL_NAIVE;
        vkrt_hit *shared_hits = trace_all(gpu, shared_scene, &d, rays, n), *alone_hits = trace_all(alone, alone_scene, &d, rays, n);
        if (through_bvh && shared_hits && alone_hits) {
            size_t hits = 0, differ = 0;
            for (size_t i = 0; i < n; i++) {
                bool hit = through_bvh[i].prim_id != VKRT_NO_HIT;
                hits += hit;
                if (any) {
                    differ += hit != (shared_hits[i].prim_id != VKRT_NO_HIT);
                    differ += hit != (alone_hits[i].prim_id != VKRT_NO_HIT);
                } else {
                    differ += memcmp(&through_bvh[i], &shared_hits[i], sizeof through_bvh[i]) != 0;
                    differ += memcmp(&through_bvh[i], &alone_hits[i], sizeof through_bvh[i]) != 0;
                }
            }
            CHECK_MSG(differ == 0, "any-hit %d: %zu naive answers differ from the BVH's", any, differ);
            fprintf(stderr, "  any-hit %d: %zu of %zu rays hit; %zu naive answers, shared or not, differ from the BVH's\n", any,
                    hits, n, differ);
            CHECK_MSG(hits > tris * 9 / 10 && through_bvh[tris].prim_id == VKRT_NO_HIT &&
                          through_bvh[tris + 1].prim_id == VKRT_NO_HIT && through_bvh[tris + 2].prim_id == VKRT_NO_HIT,
                      "any-hit %d: %zu of %zu rays hit, or an invalid ray hit", any, hits, n);
        }
        free(through_bvh);
        free(shared_hits);
        free(alone_hits);
    }
    free(rays);
    free(corners);
    vkrt_scene_destroy(shared_scene);
    vkrt_scene_destroy(alone_scene);
    CHECK_EQ_U64(vkrt_context_validation_messages(alone), 0);
    vkrt_context_destroy(alone);
}

/* The bit-exact comparisons of the tests above again, in a context whose shaders divide and
 * take square roots through the emulation that real GPUs run (rounding.glsl): on lavapipe,
 * whose own operators round correctly, it must change no bit of any image or hit. The shaders
 * of that context carry the define that selects it; those of the default context carry it
 * exactly where it emulates, which lavapipe's (a CPU device) must not. On a real GPU (an
 * NVIDIA H100 ran this) both contexts emulate and the comparisons simply run twice. */
static void gpu_emulated_rounding_gives_the_same_images(void)
{
    vkrt_context *native = gpu, *emulated = NULL;
    vkrt_context_desc desc = { .backend = VKRT_BACKEND_GPU, .log = check_gpu_log, .validation = true,
                               .pipeline_cache_path = getenv("VKRT_PIPELINE_CACHE") };
    CHECK(vkrt_context_create(&desc, &emulated) == VKRT_OK);
    if (!emulated) return;
    emulated->vk->exact_rounding = true;
    const char *define = "#define VKRT_EXACT_ROUNDING";
    char *plain = vk_shader_source(native->vk, vkrt_shader_trace_comp);
    char *exact = vk_shader_source(emulated->vk, vkrt_shader_trace_comp);
    CHECK_MSG(plain && (strstr(plain, define) != NULL) == native->vk->exact_rounding,
              "the default context's shaders do not match its rounding (emulated: %d)", native->vk->exact_rounding);
    if (native->vk->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU)
        CHECK_MSG(!native->vk->exact_rounding, "lavapipe's own division and square root are not used");
    CHECK_MSG(exact && strstr(exact, define), "the emulated context's shaders do not emulate");
    core_free(native->vk->core, plain);
    core_free(emulated->vk->core, exact);
    gpu = emulated;
    gpu_image_beyond_the_loop_limit_matches_cpu();
    gpu_albedo_and_uv_show_materials_and_texture_coordinates();
    gpu_alpha_masked_surfaces_let_rays_through();
    gpu_trace_rays_match_cpu_and_naive();
    gpu = native;
    CHECK_EQ_U64(vkrt_context_validation_messages(emulated), 0);
    vkrt_context_destroy(emulated);
}

int main(void)
{
    int code = check_contexts(check_gpu_log, &gpu, &cpu);
    if (code) return code;

    RUN(gpu_validation_messages_are_counted);
    RUN(gpu_shared_layouts_match_c);
    RUN(gpu_ray_offset_matches_c);
    RUN(gpu_emulated_rounding_matches_c);
    RUN(gpu_large_mapped_buffers_are_advised_huge_pages);
    RUN(gpu_every_pipeline_variant_runs);
    RUN(gpu_matches_cpu_reference);
    RUN(gpu_tiles_are_seamless);
    RUN(gpu_normal_and_heatmap_match_cpu);
    RUN(gpu_bvh_and_naive_give_identical_images);
    RUN(gpu_naive_traversal_shares_triangle_reads_across_a_subgroup);
    RUN(gpu_builtin_scene_renders);
    RUN(gpu_render_rejects_bad_arguments);
    RUN(gpu_refuses_double_precision);
    RUN(gpu_trace_rays_follow_the_documented_rules);
    RUN(gpu_trace_rays_match_cpu_and_naive);
    RUN(gpu_trace_rays_answer_rays_missing_the_scene_box_on_the_host);
    RUN(ray_bin_lists_hold_every_triangle_a_ray_hits);
    RUN(ray_bin_lattice_lists_hold_the_hits_of_big_triangles);
    RUN(ray_bin_lattice_lists_hold_grazing_hits);
    RUN(ray_bin_lattice_culling_keeps_the_closest_hits);
    RUN(ray_bin_says_why_rays_do_not_suit);
    RUN(ray_bin_gives_a_cell_to_every_ray_the_box_test_lets_in);
    RUN(ray_bin_camera_plan_lists_as_the_camera_rays_do);
    RUN(gpu_rays_sharing_an_origin_take_lists_with_the_bvh_hits);
    RUN(gpu_renders_take_lists_with_the_bvh_image);
    RUN(gpu_wide_traversal_matches_the_binary_one);
    RUN(gpu_wide_boxes_hold_rays_along_their_planes);
    RUN(gpu_deep_wide_bvhs_take_the_wide_traversal);
    RUN(gpu_spatial_splits_give_the_hits_of_sah);
    RUN(gpu_watertight_never_misses_shared_edges_and_vertices);
    RUN(gpu_eye_inside_a_closed_mesh_always_hits);
    RUN(gpu_grazing_hit_distances_are_exact);
    RUN(gpu_secondary_rays_never_rehit_their_own_triangle);
    RUN(gpu_camera_rays_hit_what_the_render_shows_on_exported_triangles);
    RUN(gpu_traversals_beyond_the_loop_limit_match_cpu);
    RUN(gpu_image_beyond_the_loop_limit_matches_cpu);
    RUN(gpu_traversal_counters_sum_the_heatmap);
    RUN(gpu_albedo_and_uv_show_materials_and_texture_coordinates);
    RUN(gpu_alpha_masked_surfaces_let_rays_through);
    RUN(gpu_emulated_rounding_gives_the_same_images);

    return check_gpu_finish(gpu, cpu);
}
