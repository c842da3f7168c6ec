/* The lighting modes on the device (lavapipe in CI), validation layer on, against the CPU
 * backend: both run the same estimators with the same sampler, so their means must agree
 * within the per-pixel standard errors; and on the device itself the furnace, the
 * specialisations, adaptive sampling, the any-hit occlusion queries and traversals long
 * enough to need lavapipe's resumable passes. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "lighting_fixtures.h"
#include "trace_fixtures.h"
#include "vkrt.h"

static vkrt_context *gpu, *cpu;

static vkrt_scene *builtin(vkrt_context *ctx)
{
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ 0 }, &s);
    CHECK_MSG(r == VKRT_OK, "%s", vkrt_context_last_error(ctx));
    return s;
}

/* The images and error maps of one GPU-against-CPU comparison. */
static void free_pair(float *g, float *c, float *ge, float *ce)
{
    free(g);
    free(c);
    free(ge);
    free(ce);
}

/* Per pixel and channel, |gpu - cpu| within 4 combined standard errors (luminance errors
 * scaled to the channel) plus float slack; at most 0.5% of the pixels may exceed it. */
static void compare_statistically(const char *what, const float *g, const float *ge, const float *c, const float *ce,
                                  size_t pixels)
{
    size_t outside = 0;
    double worst = 0.0;
    for (size_t i = 0; i < pixels; i++) {
        double se = sqrt((double)ge[i] * ge[i] + (double)ce[i] * ce[i]);
        for (int k = 0; k < 4; k++) {
            double d = fabs((double)g[i * 4 + k] - c[i * 4 + k]);
            double bound = 4.0 * se * 2.0 + 1e-4 * (1.0 + fabs(c[i * 4 + k]));
            if (d > bound) outside++;
            if (d > worst) worst = d;
        }
    }
    fprintf(stderr, "  %s: %zu of %zu values outside 4 standard errors, largest difference %.3g\n", what, outside,
            pixels * 4, worst);
    CHECK_MSG(outside <= pixels * 4 / 200, "%s: %zu values outside", what, outside);
}

/* shaded, ao and path on the built-in scene (a metal, the default key light and sky), and path
 * with a point light and a gradient sky: the device's means agree with the CPU's, and so do
 * the sample and ray counts. */
static void gpu_lighting_matches_cpu_statistically(void)
{
    vkrt_scene *sg = builtin(gpu), *sc = builtin(cpu);
    const vkrt_light point = { VKRT_LIGHT_POINT, { 0.3f, 0.8f, 0.6f }, { 0.8f, 0.8f, 0.7f } };
    const struct {
        vkrt_mode mode;
        uint32_t spp;
        bool custom;
    } cases[] = { { VKRT_MODE_SHADED, 1, false }, { VKRT_MODE_AO, 4, false }, { VKRT_MODE_PATH, 8, false },
                  { VKRT_MODE_PATH, 8, true } };
    const uint32_t W = 40, H = 32;
    for (size_t k = 0; sg && sc && k < sizeof cases / sizeof cases[0]; k++) {
        vkrt_render_desc d = { .width = W, .height = H, .mode = cases[k].mode, .spp = cases[k].spp, .seed = 3 };
        if (cases[k].custom) {
            d.lights = &point;
            d.light_count = 1;
            d.sky = (vkrt_sky){ { 0.4f, 0.5f, 0.7f }, { 0.1f, 0.1f, 0.1f } };
        }
        float *ge = NULL, *ce = NULL;
        vkrt_render_stats gs, cs;
        float *g = test_render(gpu, sg, d, &ge, &gs);
        float *c = test_render(cpu, sc, d, &ce, &cs);
        if (g && c) {
            char what[64];
            snprintf(what, sizeof what, "mode %d, %u spp%s", (int)cases[k].mode, cases[k].spp, cases[k].custom ? ", lights" : "");
            compare_statistically(what, g, ge, c, ce, (size_t)W * H);
            CHECK_EQ_U64(gs.features, cs.features);
            CHECK_EQ_U64(gs.lights, cs.lights);
            CHECK_EQ_U64(gs.samples, cs.samples);
            /* Rays are made by the same decisions; a rounding difference may end a path early. */
            CHECK_MSG(llabs((long long)gs.shadow_rays - (long long)cs.shadow_rays) <= (long long)cs.shadow_rays / 100,
                      "%s: shadow rays %llu vs %llu", what, (unsigned long long)gs.shadow_rays,
                      (unsigned long long)cs.shadow_rays);
            CHECK_MSG(llabs((long long)gs.bounce_rays - (long long)cs.bounce_rays) <= (long long)cs.bounce_rays / 100 + 1,
                      "%s: bounce rays %llu vs %llu", what, (unsigned long long)gs.bounce_rays,
                      (unsigned long long)cs.bounce_rays);
        }
        free_pair(g, c, ge, ce);
    }
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
}

/* Files that bring their own light: the Cornell box (an OBJ whose .mtl gives its ceiling lamp a
 * Ke), a glTF with metallic-roughness and emissive textures (every feature but punctual
 * lights), and a glTF with KHR_lights_punctual lights: the device agrees with the CPU. */
static void gpu_scene_lights_and_textures_match_cpu(void)
{
    const struct {
        const char *path;
        vkrt_mode mode;
        uint32_t features; /* must be set */
        uint32_t lights;   /* 0: any */
    } files[] = {
        { VKRT_TEST_DATA_DIR "/cornell.obj", VKRT_MODE_PATH, VKRT_FEATURE_EMITTERS | VKRT_FEATURE_RANDOM, 2 },
        { VKRT_TEST_DATA_DIR "/pbr_textures.gltf", VKRT_MODE_PATH,
          VKRT_FEATURE_TEXTURES | VKRT_FEATURE_EMITTERS | VKRT_FEATURE_SPECULAR, 0 },
        { VKRT_TEST_DATA_DIR "/lights.gltf", VKRT_MODE_SHADED, VKRT_FEATURE_PUNCTUAL, 3 },
    };
    for (size_t f = 0; f < sizeof files / sizeof files[0]; f++) {
        vkrt_scene *sg = NULL, *sc = NULL;
        vkrt_scene_desc sd = { .path = files[f].path };
        vkrt_result rg = vkrt_scene_create(gpu, &sd, &sg), rc = vkrt_scene_create(cpu, &sd, &sc);
        CHECK_MSG(rg == VKRT_OK && rc == VKRT_OK, "%s: %s", files[f].path, vkrt_context_last_error(gpu));
        vkrt_render_desc d = { .width = 24, .height = 24, .mode = files[f].mode, .spp = 8,
                               .camera = { .eye = { 0.0f, 0.0f, 1.7f }, .fov_y_degrees = 40 } };
        float *ge = NULL, *ce = NULL;
        vkrt_render_stats gs, cs;
        float *g = sg ? test_render(gpu, sg, d, &ge, &gs) : NULL;
        float *c = sc ? test_render(cpu, sc, d, &ce, &cs) : NULL;
        if (g && c) {
            compare_statistically(files[f].path, g, ge, c, ce, 24 * 24);
            CHECK_MSG((gs.features & files[f].features) == files[f].features, "%s: features 0x%x", files[f].path, gs.features);
            CHECK_EQ_U64(gs.features, cs.features);
            if (files[f].lights) CHECK_EQ_U64(gs.lights, files[f].lights);
            double sum = 0.0;
            for (size_t i = 0; i < 24 * 24; i++) sum += g[i * 4] + g[i * 4 + 1] + g[i * 4 + 2];
            CHECK_MSG(sum > 0.0, "%s: black", files[f].path);
        }
        free_pair(g, c, ge, ce);
        vkrt_scene_destroy(sg);
        vkrt_scene_destroy(sc);
    }
}

/* Shadow rays on the device honour alpha masks (the wavefront's any-hit pass is the alpha-tested
 * variant): a cut-away quad over a lit floor casts no shadow, as on the CPU. */
static void gpu_alpha_masked_occluders_cast_no_shadow(void)
{
    const float floor_corners[12] = { -1, 0, -1, -1, 0, 1, 1, 0, 1, 1, 0, -1 };
    const float blocker_corners[12] = { -0.5f, 0.3f, -0.5f, -0.5f, 0.3f, 0.5f, 0.5f, 0.3f, 0.5f, 0.5f, 0.3f, -0.5f };
    test_mesh plane = test_quad(floor_corners), blocker = test_quad(blocker_corners);
    const vkrt_light light = { VKRT_LIGHT_POINT, { 0.0f, 0.6f, 0.0f }, { 1, 1, 1 } };
    const vkrt_material veil = { .base_color = { 0.8f, 0.8f, 0.8f, 0.2f }, .roughness = 1.0f, .alpha_cutoff = 0.5f };
    vkrt_mesh_desc md[2] = { test_mesh_desc(&plane, NULL), test_mesh_desc(&blocker, &veil) };
    vkrt_scene *sg = test_scene(gpu, md, 2), *sc = test_scene(cpu, md, 2);
    vkrt_render_desc d = { .width = 8, .height = 8, .mode = VKRT_MODE_SHADED, .lights = &light, .light_count = 1,
                           .camera = { { 0, 0.25f, 0.001f }, { 0, 0, 0 }, { 0, 0, -1 }, 30 } };
    float *g = sg ? test_render(gpu, sg, d, NULL, NULL) : NULL;
    float *c = sc ? test_render(cpu, sc, d, NULL, NULL) : NULL;
    for (size_t i = 0; g && c && i < 64; i++) {
        CHECK_MSG(g[i * 4] > 0.0f, "pixel %zu in shadow", i);
        CHECK_MSG(fabsf(g[i * 4] - c[i * 4]) <= 1e-5f * c[i * 4], "pixel %zu: %g vs %g", i, g[i * 4], c[i * 4]);
    }
    free(g);
    free(c);
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
    test_mesh_free(&plane);
    test_mesh_free(&blocker);
}

/* The emissive furnace on the device: 1 / (1 - albedo) = 2, through NEE, MIS, RR. */
static void gpu_furnace_converges_to_the_geometric_series(void)
{
    vkrt_scene *s = test_emissive_furnace(gpu);
    if (!s) return;
    vkrt_render_desc d = test_inside_view(VKRT_MODE_PATH, 8);
    d.spp = 64;
    d.max_bounces = 64;
    float *err = NULL;
    float *img = test_render(gpu, s, d, &err, NULL);
    if (img) {
        double mean, se;
        test_mean_and_error(img, err, 64, &mean, &se);
        fprintf(stderr, "  furnace inside on the device: mean %.5f (expected 2), standard error %.5f\n", mean, se);
        CHECK_MSG(fabs(mean - 2.0) < 4.0 * se + 2e-3, "mean %.5f", mean);
    }
    free(img);
    free(err);
    vkrt_scene_destroy(s);
}

/* Specialised pipelines give the full pipeline's image on a scene without textures and
 * emitters; a render with a point light and one without compile different variants. */
static void gpu_specialisation_changes_no_pixel(void)
{
    vkrt_scene *s = builtin(gpu);
    const vkrt_mode modes[4] = { VKRT_MODE_SHADED, VKRT_MODE_AO, VKRT_MODE_PATH, VKRT_MODE_PATH };
    for (int m = 0; s && m < 4; m++) {
        /* 12 samples: more than the 8 after which the adaptive test (compiled in by all_features)
         * could stop a pixel, which it must not do without a target. */
        vkrt_render_desc d = { .width = 24, .height = 16, .mode = modes[m], .spp = m == 1 ? 12 : 2 };
        /* The last case is lit by the sky alone: no next-event estimation is compiled in. */
        if (m == 3) d.sky = (vkrt_sky){ { 0.8f, 0.9f, 1.0f }, { 0.2f, 0.2f, 0.2f } };
        vkrt_render_stats a_st, b_st;
        float *a = test_render(gpu, s, d, NULL, &a_st);
        d.all_features = true;
        float *b = test_render(gpu, s, d, NULL, &b_st);
        CHECK(a_st.features != b_st.features);
        /* Shaded under point and directional lights takes one sample when specialised (it is
         * exact) and spp with every feature in: the same image either way. */
        if (m != 0) CHECK_EQ_U64(a_st.samples, b_st.samples);
        if (m == 3) CHECK(!(a_st.features & (VKRT_FEATURE_PUNCTUAL | VKRT_FEATURE_EMITTERS)));
        if (a && b) CHECK_MSG(memcmp(a, b, 24 * 16 * 4 * sizeof *a) == 0, "case %d: specialised image differs", m);
        free(a);
        free(b);
    }
    vkrt_scene_destroy(s);
}

/* Naive traversal of the wavefront's closest-hit and any-hit passes (chunked over the triangles
 * on the device) renders the BVH's image, bit for bit. */
static void gpu_lighting_bvh_and_naive_give_identical_images(void)
{
    vkrt_scene *s = builtin(gpu);
    const vkrt_mode modes[2] = { VKRT_MODE_SHADED, VKRT_MODE_PATH };
    for (int m = 0; s && m < 2; m++) {
        vkrt_render_desc d = { .width = 16, .height = 12, .mode = modes[m], .spp = 2, .traversal = VKRT_TRAVERSAL_BVH };
        float *a = test_render(gpu, s, d, NULL, NULL);
        d.traversal = VKRT_TRAVERSAL_NAIVE;
        float *b = test_render(gpu, s, d, NULL, NULL);
        if (a && b) CHECK_MSG(memcmp(a, b, 16 * 12 * 4 * sizeof *a) == 0, "mode %d: naive image differs", (int)modes[m]);
        free(a);
        free(b);
    }
    vkrt_scene_destroy(s);
}

/* Adaptive sampling on the device makes the CPU's decisions: the same samples per pixel. */
static void gpu_adaptive_sampling_matches_cpu(void)
{
    vkrt_scene *sg = builtin(gpu), *sc = builtin(cpu);
    vkrt_render_desc d = { .width = 24, .height = 16, .mode = VKRT_MODE_PATH, .spp = 64, .target_error = 0.1f };
    vkrt_render_stats gs, cs;
    float *g = sg ? test_render(gpu, sg, d, NULL, &gs) : NULL;
    float *c = sc ? test_render(cpu, sc, d, NULL, &cs) : NULL;
    if (g && c) {
        fprintf(stderr, "  adaptive: %llu samples on the device, %llu on the CPU (cap %u)\n", (unsigned long long)gs.samples,
                (unsigned long long)cs.samples, 24 * 16 * 64);
        CHECK(gs.features & VKRT_FEATURE_ADAPTIVE);
        CHECK(gs.samples < 24 * 16 * 64);
        CHECK_MSG(llabs((long long)gs.samples - (long long)cs.samples) <= (long long)cs.samples / 50,
                  "samples %llu vs %llu", (unsigned long long)gs.samples, (unsigned long long)cs.samples);
    }
    free(g);
    free(c);
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
}

/* vkrt_trace_rays with any_hit on the device: a hit exactly where the closest-hit query has
 * one (on both traversals), and the CPU's answer. */
static void gpu_any_hit_queries_agree_with_closest_hit(void)
{
    vkrt_scene *sg = NULL;
    vkrt_scene_create(gpu, &(vkrt_scene_desc){ .path = VKRT_MODELS_DIR "/meshes/bunny.obj" }, &sg);
    CHECK(sg != NULL);
    enum { N = 4096 };
    vkrt_ray *rays = random_rays_in_box(N, 11);
    for (int naive = 0; sg && rays && naive < 2; naive++) {
        vkrt_traversal t = naive ? VKRT_TRAVERSAL_NAIVE : VKRT_TRAVERSAL_BVH;
        vkrt_hit *any = trace_all(gpu, sg, &(vkrt_trace_desc){ .traversal = t, .any_hit = true }, rays, N);
        vkrt_hit *closest = trace_all(gpu, sg, &(vkrt_trace_desc){ .traversal = t }, rays, N);
        size_t disagree = 0, hits = 0;
        for (size_t i = 0; any && closest && i < N; i++) {
            bool a = any[i].prim_id != VKRT_NO_HIT, c = closest[i].prim_id != VKRT_NO_HIT;
            disagree += a != c;
            hits += c;
            if (a && c) CHECK(any[i].t >= closest[i].t * (1.0f - 1e-6f));
        }
        CHECK(hits > N / 20);
        CHECK_MSG(disagree == 0, "%s: %zu rays disagree", naive ? "naive" : "bvh", disagree);
        free(any);
        free(closest);
    }
    free(rays);
    vkrt_scene_destroy(sg);
}

/* Shadow rays that cross a 100,000-triangle leaf run past lavapipe's loop limit and resume
 * across dispatches: shaded mode over the leaf stack still matches the CPU exactly where both
 * are deterministic (one sample, punctual light). */
static void gpu_shadow_rays_beyond_the_loop_limit_match_cpu(void)
{
    enum { N = 100000 };
    float *pos = malloc((size_t)N * 9 * sizeof *pos);
    if (!pos) return;
    /* N thin triangles stacked in z (one leaf: they overlap in x and y), over a floor. */
    for (uint32_t i = 0; i < N; i++) {
        float z = 0.2f + 0.2f * (float)i / N;
        const float t[9] = { -0.3f, -0.3f, z, 0.3f, -0.3f, z, 0.0f, 0.3f, z };
        memcpy(pos + (size_t)i * 9, t, sizeof t);
    }
    const float floor_corners[12] = { -1, -1, 0, 1, -1, 0, 1, 1, 0, -1, 1, 0 };
    test_mesh floor_quad = test_quad(floor_corners);
    vkrt_mesh_desc md[2] = { { .positions = pos, .vertex_count = N * 3 }, test_mesh_desc(&floor_quad, NULL) };
    vkrt_scene *sg = test_scene(gpu, md, 2), *sc = test_scene(cpu, md, 2);
    const vkrt_light sun = { VKRT_LIGHT_DIRECTIONAL, { 1.0f, 0.0f, -1.0f }, { 1, 1, 1 } };
    vkrt_render_desc d = { .width = 16, .height = 16, .mode = VKRT_MODE_SHADED, .lights = &sun, .light_count = 1,
                           .traversal = VKRT_TRAVERSAL_BVH,
                           .camera = { .eye = { 0.0f, -0.2f, 2.0f }, .target = { 0, 0, 0 }, .fov_y_degrees = 60 } };
    vkrt_render_stats gs;
    float *g = sg ? test_render(gpu, sg, d, NULL, &gs) : NULL;
    float *c = sc ? test_render(cpu, sc, d, NULL, NULL) : NULL;
    if (g && c) {
        size_t differ = 0, shadowed = 0;
        for (size_t i = 0; i < 16 * 16; i++) {
            if (fabsf(g[i * 4] - c[i * 4]) > 1e-4f * (1.0f + fabsf(c[i * 4]))) differ++;
            if (c[i * 4 + 3] == 1.0f && c[i * 4] == 0.0f) shadowed++;
        }
        fprintf(stderr, "  leaf stack: %zu of 256 pixels differ, %zu in shadow, %llu shadow rays\n", differ, shadowed,
                (unsigned long long)gs.shadow_rays);
        CHECK(differ == 0);
        CHECK(shadowed > 4);
        CHECK(gs.shadow_rays > 0);
    }
    free(g);
    free(c);
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
    test_mesh_free(&floor_quad);
    free(pos);
}

int main(void)
{
    int code = check_contexts(check_gpu_log, &gpu, &cpu);
    if (code) return code;
    RUN(gpu_lighting_matches_cpu_statistically);
    RUN(gpu_scene_lights_and_textures_match_cpu);
    RUN(gpu_alpha_masked_occluders_cast_no_shadow);
    RUN(gpu_furnace_converges_to_the_geometric_series);
    RUN(gpu_specialisation_changes_no_pixel);
    RUN(gpu_lighting_bvh_and_naive_give_identical_images);
    RUN(gpu_adaptive_sampling_matches_cpu);
    RUN(gpu_any_hit_queries_agree_with_closest_hit);
    RUN(gpu_shadow_rays_beyond_the_loop_limit_match_cpu);
    return check_gpu_finish(gpu, cpu);
}
