/* The lighting modes on the CPU backend against answers known in closed form: the white
 * furnace (outside a convex diffuse sphere under a uniform sky, and inside a closed emissive
 * one), a plane lit by point and directional lights (inverse-square and cosine laws), a mirror
 * reflecting a two-coloured emitter, ambient occlusion of an open plane; and the machinery
 * around them: the sampler's stratification, the light table's power-proportional picks,
 * any-hit traversal, specialisation, adaptive sampling against a converged reference,
 * reproducibility and argument checks. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "context.h"
#include "cpu_trace.h"
#include "lighting_fixtures.h"
#include "lights.h"
#include "sampler.h"
#include "shading.h"
#include "trace_fixtures.h"
#include "vkrt.h"

static vkrt_context *cpu;

static void on_log(void *user, vkrt_log_level level, const char *message)
{
    (void)user;
    if (level <= VKRT_LOG_WARN) fprintf(stderr, "  [vkrt] %s\n", message);
}

/* Sobol' points, scrambled or not, put exactly one of 16 consecutive samples in each cell of a
 * 4x4 grid of every dimension pair within a group: they are a (0, 2)-sequence. */
static void sampler_points_are_stratified(void)
{
    for (uint32_t seed = 0; seed < 8; seed++) {
        uint32_t pixel = sampler_pixel_seed(seed * 7 + 1, seed * 3 + 2, seed);
        for (uint32_t group = 0; group < 3; group++) {
            int cells01[16] = { 0 }, cells23[16] = { 0 }, cells02[16] = { 0 };
            for (uint32_t i = 0; i < 16; i++) {
                float u[4];
                sampler_get4(pixel, i, group, u);
                for (int k = 0; k < 4; k++) CHECK(u[k] >= 0.0f && u[k] < 1.0f);
                cells01[(int)(u[0] * 4) * 4 + (int)(u[1] * 4)]++;
                cells23[(int)(u[2] * 4) * 4 + (int)(u[3] * 4)]++;
                cells02[(int)(u[0] * 4) * 4 + (int)(u[2] * 4)]++;
            }
            for (int c = 0; c < 16; c++) {
                CHECK_MSG(cells01[c] == 1, "seed %u group %u: cell %d of dims 0,1 holds %d", seed, group, c, cells01[c]);
                CHECK_MSG(cells23[c] == 1, "seed %u group %u: cell %d of dims 2,3 holds %d", seed, group, c, cells23[c]);
                CHECK_MSG(cells02[c] == 1, "seed %u group %u: cell %d of dims 0,2 holds %d", seed, group, c, cells02[c]);
            }
        }
    }
    /* Other pixels and groups are decorrelated: their first samples differ. */
    float a[4], b[4], c[4];
    sampler_get4(sampler_pixel_seed(0, 0, 0), 0, 0, a);
    sampler_get4(sampler_pixel_seed(1, 0, 0), 0, 0, b);
    sampler_get4(sampler_pixel_seed(0, 0, 0), 0, 1, c);
    CHECK(a[0] != b[0] && a[0] != c[0]);
}

static const float floor_quad[12] = { -1, 0, -1, -1, 0, 1, 1, 0, 1, 1, 0, -1 };

/* The BSDF's sampling and evaluation agree: for metals and mixtures of every roughness, the mean
 * importance-sampling weight (f cos / pdf of sh_bsdf_sample_dir) equals the reflectance that
 * uniform hemisphere sampling of sh_bsdf_eval measures, within 4 standard errors; the pdf a
 * sample reports is the one eval gives for its direction; and no lobe reflects more than comes
 * in. */
static void bsdf_sampling_matches_its_evaluation(void)
{
    const float roughness[] = { 0.1f, 0.3f, 0.6f, 1.0f };
    const float metallic[] = { 0.0f, 0.5f, 1.0f };
    const float cos_o[] = { 0.9f, 0.5f, 0.15f };
    const sh_vec3 n = { 0, 0, 1 };
    test_rng rng = { 1 };
    enum { N = 200000 };
    for (size_t a = 0; a < sizeof roughness / sizeof roughness[0]; a++)
        for (size_t b = 0; b < sizeof metallic / sizeof metallic[0]; b++)
            for (size_t c = 0; c < sizeof cos_o / sizeof cos_o[0]; c++) {
                sh_material m = { { 0.9f, 0.6f, 0.3f }, metallic[b], roughness[a], { 0, 0, 0 } };
                sh_vec3 wo = { sqrtf(1.0f - cos_o[c] * cos_o[c]), 0.0f, cos_o[c] };
                double s1 = 0, s1q = 0, s2 = 0, s2q = 0;
                size_t pdf_mismatch = 0;
                for (int i = 0; i < N; i++) {
                    float u[3] = { (float)rng_uniform(&rng), (float)rng_uniform(&rng), (float)rng_uniform(&rng) };
                    sh_bsdf_sample smp = sh_bsdf_sample_dir(&m, n, n, wo, u);
                    double w = smp.valid ? sh_luminance(smp.weight) : 0.0;
                    if (smp.valid) {
                        float pdf;
                        sh_bsdf_eval(&m, n, n, wo, smp.dir, &pdf);
                        if (fabsf(pdf - smp.pdf) > 1e-3f * pdf) pdf_mismatch++;
                    }
                    s1 += w, s1q += w * w;
                    /* Uniform on the hemisphere: pdf 1 / (2 pi). */
                    double z = rng_uniform(&rng), phi = 6.283185307179586 * rng_uniform(&rng), r = sqrt(1 - z * z);
                    sh_vec3 wi = { (float)(r * cos(phi)), (float)(r * sin(phi)), (float)z };
                    float pdf;
                    double v = sh_luminance(sh_bsdf_eval(&m, n, n, wo, wi, &pdf)) * z * 6.283185307179586;
                    s2 += v, s2q += v * v;
                }
                double m1 = s1 / N, m2 = s2 / N;
                double e1 = sqrt((s1q / N - m1 * m1) / N), e2 = sqrt((s2q / N - m2 * m2) / N);
                CHECK_MSG(fabs(m1 - m2) <= 4.0 * sqrt(e1 * e1 + e2 * e2) + 1e-3,
                          "roughness %.1f metallic %.1f cos %.2f: sampled %.4f +- %.4f, evaluated %.4f +- %.4f",
                          roughness[a], metallic[b], cos_o[c], m1, e1, m2, e2);
                CHECK_MSG(m1 <= 1.0 + 4.0 * e1, "reflects %.4f", m1);
                CHECK_MSG(pdf_mismatch <= N / 1000, "%zu sampled pdfs differ from eval", pdf_mismatch);
            }
    /* The mirror: all of it in one direction, weighted by Fresnel (F0 = 1: exactly 1). */
    sh_material mirror = { { 1, 1, 1 }, 1.0f, 0.0f, { 0, 0, 0 } };
    sh_vec3 wo = { 0.6f, 0.0f, 0.8f };
    sh_bsdf_sample smp = sh_bsdf_sample_dir(&mirror, n, n, wo, (float[3]){ 0.3f, 0.7f, 0.5f });
    CHECK(smp.valid && smp.pdf == 0.0f && fabsf(smp.dir.x + 0.6f) < 1e-6f && fabsf(smp.dir.z - 0.8f) < 1e-6f);
    CHECK(fabsf(smp.weight.x - 1.0f) < 1e-6f);
}

/* Alpha-masked surfaces are not there for shadow rays either: a fully cut-away quad between a
 * point light and the floor casts no shadow, an opaque one does. */
static void alpha_masked_occluders_cast_no_shadow(void)
{
    test_mesh plane = test_quad(floor_quad);
    const float blocker_corners[12] = { -0.5f, 0.3f, -0.5f, -0.5f, 0.3f, 0.5f, 0.5f, 0.3f, 0.5f, 0.5f, 0.3f, -0.5f };
    test_mesh blocker = test_quad(blocker_corners);
    const vkrt_light light = { VKRT_LIGHT_POINT, { 0.0f, 0.6f, 0.0f }, { 1, 1, 1 } };
    const vkrt_material grey = { .base_color = { 0.8f, 0.8f, 0.8f, 1.0f }, .roughness = 1.0f };
    float centre[2];
    for (int cut = 0; cut < 2; cut++) {
        const vkrt_material veil = { .base_color = { 0.8f, 0.8f, 0.8f, cut ? 0.2f : 1.0f }, .roughness = 1.0f,
                                     .alpha_cutoff = 0.5f };
        vkrt_mesh_desc md[2] = { test_mesh_desc(&plane, &grey), test_mesh_desc(&blocker, &veil) };
        vkrt_scene *s = test_scene(cpu, md, 2);
        /* Seen from below the blocker, looking down at the floor. */
        vkrt_render_desc d = { .width = 8, .height = 8, .mode = VKRT_MODE_SHADED, .lights = &light, .light_count = 1,
                               .camera = { { 0, 0.25f, 0.001f }, { 0, 0, 0 }, { 0, 0, -1 }, 30 } };
        float *img = s ? test_render(cpu, s, d, NULL, NULL) : NULL;
        centre[cut] = img ? img[(4 * 8 + 4) * 4] : -1.0f;
        free(img);
        vkrt_scene_destroy(s);
    }
    double expected = 0.8 / 3.14159265358979323846 / (0.6 * 0.6);
    CHECK_MSG(centre[0] == 0.0f, "opaque blocker: floor %g", centre[0]);
    CHECK_MSG(fabs(centre[1] - expected) < 2e-3 * expected, "cut-away blocker: floor %g, unshadowed %g", centre[1], expected);
    test_mesh_free(&plane);
    test_mesh_free(&blocker);
}

/* The camera ray of pixel (x, y) as vkrt documents it (vkrt_gpu_push), in double. */
static void pixel_dir(const double eye[3], const double target[3], const double up[3], double fov, uint32_t w, uint32_t h,
                      uint32_t x, uint32_t y, double out[3])
{
    double f[3] = { target[0] - eye[0], target[1] - eye[1], target[2] - eye[2] };
    double fl = sqrt(f[0] * f[0] + f[1] * f[1] + f[2] * f[2]);
    for (int k = 0; k < 3; k++) f[k] /= fl;
    double r[3] = { f[1] * up[2] - f[2] * up[1], f[2] * up[0] - f[0] * up[2], f[0] * up[1] - f[1] * up[0] };
    double rl = sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    for (int k = 0; k < 3; k++) r[k] /= rl;
    double u[3] = { r[1] * f[2] - r[2] * f[1], r[2] * f[0] - r[0] * f[2], r[0] * f[1] - r[1] * f[0] };
    double t = tan(fov * 3.14159265358979323846 / 360.0), aspect = (double)w / h;
    double sx = 2.0 * (x + 0.5) / w - 1.0, sy = 1.0 - 2.0 * (y + 0.5) / h;
    double d[3];
    for (int k = 0; k < 3; k++) d[k] = f[k] + r[k] * sx * t * aspect + u[k] * sy * t;
    double dl = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    for (int k = 0; k < 3; k++) out[k] = d[k] / dl;
}


/* A diffuse floor (y = 0, albedo 0.8) under a point light at height 0.5 and, separately, a
 * directional light: each pixel's radiance is albedo / pi * I cos(theta) / d^2, and albedo /
 * pi * E cos(theta), to float precision (shaded mode is exact in one sample). */
static void point_and_directional_lights_follow_inverse_square_and_cosine(void)
{
    test_mesh plane = test_quad(floor_quad);
    const vkrt_material grey = { .base_color = { 0.8f, 0.8f, 0.8f, 1.0f }, .roughness = 1.0f };
    vkrt_mesh_desc md = test_mesh_desc(&plane, &grey);
    vkrt_scene *s = test_scene(cpu, &md, 1);
    const double eye[3] = { 0, 2, 0 }, target[3] = { 0, 0, 0 }, up[3] = { 0, 0, -1 };
    const uint32_t W = 24, H = 24;
    for (int kind = 0; s && kind < 2; kind++) {
        vkrt_light light = kind == 0 ? (vkrt_light){ VKRT_LIGHT_POINT, { 0.2f, 0.5f, -0.1f }, { 1.0f, 0.5f, 0.25f } }
                                     : (vkrt_light){ VKRT_LIGHT_DIRECTIONAL, { 0.6f, -0.8f, 0.0f }, { 2.0f, 1.0f, 0.5f } };
        vkrt_render_desc d = { .width = W, .height = H, .mode = VKRT_MODE_SHADED, .lights = &light, .light_count = 1,
                               .camera = { { 0, 2, 0 }, { 0, 0, 0 }, { 0, 0, -1 }, 40 } };
        vkrt_render_stats st;
        float *img = test_render(cpu, s, d, NULL, &st);
        if (!img) continue;
        CHECK(!(st.features & VKRT_FEATURE_RANDOM));
        CHECK_EQ_U64(st.samples, (uint64_t)W * H);
        double worst = 0.0;
        for (uint32_t y = 0; y < H; y++) {
            for (uint32_t x = 0; x < W; x++) {
                double dir[3];
                pixel_dir(eye, target, up, 40, W, H, x, y, dir);
                double t = -eye[1] / dir[1];
                double p[3] = { eye[0] + t * dir[0], 0.0, eye[2] + t * dir[2] };
                for (int c = 0; c < 3; c++) {
                    double expected;
                    if (kind == 0) {
                        double l[3] = { 0.2 - p[0], 0.5, -0.1 - p[2] };
                        double d2 = l[0] * l[0] + l[1] * l[1] + l[2] * l[2];
                        expected = 0.8 / 3.14159265358979323846 * light.color[c] * (0.5 / sqrt(d2)) / d2;
                    } else {
                        expected = 0.8 / 3.14159265358979323846 * light.color[c] * 0.8;
                    }
                    double got = img[(y * W + x) * 4 + c];
                    double rel = fabs(got - expected) / expected;
                    if (rel > worst) worst = rel;
                }
                CHECK(img[(y * W + x) * 4 + 3] == 1.0f);
            }
        }
        /* The shadow ray starts 1/65536 off the floor (ray_offset): that moves cos and d^2 of a
         * light 0.5 away by a few 1e-5. */
        CHECK_MSG(worst < 2e-4, "%s light: worst relative error %.3g", kind ? "directional" : "point", worst);
        free(img);
    }
    vkrt_scene_destroy(s);
    test_mesh_free(&plane);
}

/* Outside a convex, flat-shaded diffuse sphere (albedo 0.5) under a uniform sky of 1, each
 * bounce escapes: path tracing gives exactly 0.5 on the sphere (every sample) and shaded mode's
 * ambient term the same; the sky shows 1 with alpha 0. */
static void furnace_outside_a_convex_sphere_gives_the_albedo(void)
{
    test_mesh sphere = test_sphere(0.5f, 10, 20);
    flat_mesh flat = test_flatten(&sphere);
    const vkrt_material white = { .base_color = { 0.5f, 0.5f, 0.5f, 1.0f }, .roughness = 1.0f };
    vkrt_mesh_desc md = flat_mesh_desc(&flat, &white);
    vkrt_scene *s = test_scene(cpu, &md, 1);
    for (int m = 0; s && m < 2; m++) {
        vkrt_render_desc d = { .width = 32, .height = 32, .mode = m ? VKRT_MODE_SHADED : VKRT_MODE_PATH, .spp = 8,
                               .sky = { { 1, 1, 1 }, { 1, 1, 1 } } };
        float *img = test_render(cpu, s, d, NULL, NULL);
        size_t hits = 0;
        for (size_t i = 0; img && i < 32 * 32; i++) {
            const float *px = img + i * 4;
            if (px[3] == 1.0f) {
                hits++;
                for (int c = 0; c < 3; c++) CHECK_MSG(fabsf(px[c] - 0.5f) < 1e-5f, "mode %d pixel %zu: %g", m, i, px[c]);
            } else {
                CHECK(px[3] == 0.0f && px[0] == 1.0f && px[1] == 1.0f && px[2] == 1.0f);
            }
        }
        CHECK(hits > 200);
        free(img);
    }
    vkrt_scene_destroy(s);
    flat_mesh_free(&flat);
    test_mesh_free(&sphere);
}

/* Inside a closed sphere that emits 1 and reflects 0.5 everywhere, every pixel converges to
 * 1 / (1 - 0.5) = 2: emission, next-event estimation of its triangles weighed by MIS against
 * BSDF sampling, and Russian roulette must add up without bias. */
static void furnace_inside_an_emitting_sphere_converges_to_the_geometric_series(void)
{
    vkrt_scene *s = test_emissive_furnace(cpu);
    if (!s) return;
    vkrt_render_desc d = test_inside_view(VKRT_MODE_PATH, 16);
    d.spp = 256;
    d.max_bounces = 64;
    float *err = NULL;
    vkrt_render_stats st;
    float *img = test_render(cpu, s, d, &err, &st);
    if (img) {
        double mean, stderr_mean;
        test_mean_and_error(img, err, 16 * 16, &mean, &stderr_mean);
        fprintf(stderr, "  furnace inside: mean %.5f (expected 2), standard error %.5f, %u lights\n", mean, stderr_mean,
                st.lights);
        CHECK_MSG(fabs(mean - 2.0) < 4.0 * stderr_mean + 2e-3, "mean %.5f", mean);
        CHECK(st.features & VKRT_FEATURE_EMITTERS);
        /* Every triangle but the degenerate ones at the poles is a light. */
        CHECK_MSG(st.lights >= 12 * 24 * 2 - 2 * 24 && st.lights <= 12 * 24 * 2, "%u lights", st.lights);
        CHECK(st.shadow_rays > 0 && st.bounce_rays > 0);
    }
    free(img);
    free(err);
    vkrt_scene_destroy(s);
}

/* A perfect mirror (metallic 1, roughness 0, base 1: Fresnel 1) facing the camera reflects
 * an emitter behind it, red to the left and green to the right, at exactly its radiance. */
static void mirror_reflects_a_known_pattern(void)
{
    const float mirror_quad[12] = { -0.5f, -0.5f, 0, 0.5f, -0.5f, 0, 0.5f, 0.5f, 0, -0.5f, 0.5f, 0 };
    const float left_quad[12] = { -4, -4, 3, 0, -4, 3, 0, 4, 3, -4, 4, 3 };
    const float right_quad[12] = { 0, -4, 3, 4, -4, 3, 4, 4, 3, 0, 4, 3 };
    test_mesh q[3] = { test_quad(mirror_quad), test_quad(left_quad), test_quad(right_quad) };
    const vkrt_material mirror = { .base_color = { 1, 1, 1, 1 }, .metallic = 1.0f, .roughness = 0.0f };
    const vkrt_material red = { .base_color = { 0, 0, 0, 1 }, .roughness = 1.0f, .emissive = { 1.0f, 0, 0 } };
    const vkrt_material green = { .base_color = { 0, 0, 0, 1 }, .roughness = 1.0f, .emissive = { 0, 1.0f, 0 } };
    vkrt_mesh_desc md[3] = { test_mesh_desc(&q[0], &mirror), test_mesh_desc(&q[1], &red), test_mesh_desc(&q[2], &green) };
    vkrt_scene *s = test_scene(cpu, md, 3);
    vkrt_render_desc d = { .width = 16, .height = 16, .mode = VKRT_MODE_PATH, .spp = 4,
                           .camera = { .eye = { 0, 0, 1.5f }, .fov_y_degrees = 30 } };
    float *img = s ? test_render(cpu, s, d, NULL, NULL) : NULL;
    for (uint32_t y = 0; img && y < 16; y++) {
        for (uint32_t x = 0; x < 16; x++) {
            const float *px = img + (y * 16 + x) * 4;
            float want_r = x < 8 ? 1.0f : 0.0f, want_g = x < 8 ? 0.0f : 1.0f;
            CHECK_MSG(fabsf(px[0] - want_r) < 1e-5f && fabsf(px[1] - want_g) < 1e-5f && px[2] == 0.0f,
                      "pixel (%u, %u): %g %g %g", x, y, px[0], px[1], px[2]);
        }
    }
    free(img);
    vkrt_scene_destroy(s);
    for (int i = 0; i < 3; i++) test_mesh_free(&q[i]);
}

/* Ambient occlusion of an open floor is 1 everywhere; a sphere resting on it darkens the
 * floor around its foot and leaves the far floor at 1. */
static void ambient_occlusion_sees_only_nearby_occluders(void)
{
    test_mesh plane = test_quad(floor_quad);
    test_mesh ball = test_sphere(0.2f, 8, 16);
    for (uint32_t v = 0; v < ball.vertex_count; v++) ball.positions[v * 3 + 1] += 0.2f;
    vkrt_mesh_desc md[2] = { test_mesh_desc(&plane, NULL), test_mesh_desc(&ball, NULL) };
    for (int with_ball = 0; with_ball < 2; with_ball++) {
        vkrt_scene *s = test_scene(cpu, md, with_ball ? 2 : 1);
        vkrt_render_desc d = { .width = 32, .height = 32, .mode = VKRT_MODE_AO, .spp = 16, .ao_samples = 4,
                               .ao_distance = 0.3f, .camera = { { 0, 2, 0.001f }, { 0, 0, 0 }, { 0, 0, -1 }, 50 } };
        float *img = s ? test_render(cpu, s, d, NULL, NULL) : NULL;
        if (img) {
            /* The corner pixel sees the floor 0.8 from the sphere: beyond ao_distance. */
            CHECK_MSG(img[0] == 1.0f, "far floor: %g", img[0]);
            if (!with_ball) {
                for (size_t i = 0; i < 32 * 32; i++) CHECK_MSG(img[i * 4] == 1.0f, "open floor pixel %zu: %g", i, img[i * 4]);
            } else {
                /* Just outside the sphere's silhouette (radius 0.2 seen from 2 up), on the floor. */
                float near_foot = img[(16 * 32 + 16 + 4) * 4];
                CHECK_MSG(near_foot < 0.9f, "floor by the sphere's foot: %g", near_foot);
            }
        }
        free(img);
        vkrt_scene_destroy(s);
    }
    test_mesh_free(&plane);
    test_mesh_free(&ball);
}

/* Next-event estimation picks a light with probability proportional to its estimated power:
 * an emissive triangle of twice the area and the same radiance is picked twice as often, and
 * the cdf ends at exactly 1. */
static void light_table_picks_by_power(void)
{
    vkrt_gpu_tri tris[2] = { 0 };
    tris[0] = (vkrt_gpu_tri){ .v0 = { 0, 0, 0 }, .v1 = { 1, 0, 0 }, .v2 = { 0, 1, 0 }, .prim_id = 0 };
    tris[1] = (vkrt_gpu_tri){ .v0 = { 0, 0, 1 }, .v1 = { 2, 0, 1 }, .v2 = { 0, 1, 1 }, .prim_id = 1 };
    vkrt_gpu_surface surfaces[2] = { { .material = 0 }, { .material = 0 } };
    vkrt_gpu_material materials[1] = { { .emissive = { 1, 1, 1 } } };
    vkrt_light point = { VKRT_LIGHT_POINT, { 0, 2, 0 }, { 1, 1, 1 } };
    light_table_desc d = { .render_lights = &point, .render_light_count = 1, .tris = tris, .tri_count = 2, .prim_count = 2,
                           .surfaces = surfaces, .materials = materials, .scene_radius = 1.0f };
    light_table t;
    core c;
    core_init(&c, NULL, NULL, NULL);
    vkrt_result r = light_table_build(&c, &d, &t);
    CHECK(r == VKRT_OK);
    if (r != VKRT_OK) return;
    CHECK_EQ_U64(t.count, 3);
    CHECK_EQ_U64(t.lighting.punctual_count, 1);
    CHECK(!t.default_rig);
    CHECK_NEAR(t.lights[2].pick / t.lights[1].pick, 2.0, 1e-5);
    /* The point light: 4 pi I against pi * area * L for the triangles. */
    CHECK_NEAR(t.lights[0].pick / t.lights[1].pick, 4.0 / 0.5, 1e-4);
    CHECK(t.lights[2].cdf == 1.0f);
    CHECK_NEAR(t.lighting.emitter_pick, t.lights[1].pick + t.lights[2].pick, 1e-6);
    const float second_pick = t.lights[2].pick;
    light_table_destroy(&c, &t);
    /* A spatial split's copy of triangle 1 (the same prim_id at another position) is the same
     * light: three lights again, and the same picks. */
    vkrt_gpu_tri copies[3] = { tris[0], tris[1], tris[1] };
    light_table_desc dd = d;
    dd.tris = copies;
    dd.tri_count = 3;
    light_table u;
    r = light_table_build(&c, &dd, &u);
    CHECK(r == VKRT_OK);
    if (r == VKRT_OK) {
        CHECK_EQ_U64(u.count, 3);
        CHECK(u.lights[2].tri == 1 && u.lights[2].pick == second_pick && u.lights[2].cdf == 1.0f);
        light_table_destroy(&c, &u);
    }
    /* Nothing lights the scene: the default key light and a sky. */
    light_table_desc dark = { .tris = tris, .tri_count = 0, .surfaces = surfaces, .materials = materials, .scene_radius = 1 };
    r = light_table_build(&c, &dark, &t);
    CHECK(r == VKRT_OK && t.default_rig && t.count == 1 && t.lights[0].type == VKRT_GPU_LIGHT_DIRECTIONAL &&
          t.lighting.sky_zenith.y > 0.0f);
    light_table_destroy(&c, &t);
}

/* An occlusion query stops at its first hit: over random rays through the bunny, any-hit
 * traversal finds a hit exactly where closest-hit does, and enters fewer boxes in all. */
static void any_hit_visits_fewer_nodes_than_closest_hit(void)
{
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(cpu, &(vkrt_scene_desc){ .path = VKRT_MODELS_DIR "/meshes/bunny.obj" }, &s);
    CHECK_MSG(r == VKRT_OK, "%s", vkrt_context_last_error(cpu));
    if (!s) return;
    cpu_trace_scene cs = { .nodes = s->bvh.nodes, .node_count = s->bvh.node_count, .tris = s->tris,
                           .tri_count = s->bvh.tri_count, .surfaces = s->surfaces, .materials = s->materials,
                           .textures = s->textures, .texels = s->texels };
    enum { N = 20000 };
    vkrt_ray *rays = random_rays_in_box(N, 7);
    trace_counts closest = { 0 }, any = { 0 };
    size_t hits = 0, disagree = 0;
    for (size_t i = 0; rays && i < N; i++) {
        vkrt_gpu_ray g;
        memcpy(&g, &rays[i], sizeof g);
        vkrt_gpu_hit hc, ha;
        bool a = cpu_trace_one(&cs, VKRT_TRAVERSAL_BVH, VKRT_INTERSECTOR_WATERTIGHT, &g, false, &hc, &closest);
        bool b = cpu_trace_one(&cs, VKRT_TRAVERSAL_BVH, VKRT_INTERSECTOR_WATERTIGHT, &g, true, &ha, &any);
        hits += a;
        disagree += a != b;
        if (b) CHECK(ha.t >= hc.t);
    }
    fprintf(stderr, "  %zu of %d rays hit; boxes entered: closest %llu, any %llu\n", hits, N,
            (unsigned long long)closest.nodes, (unsigned long long)any.nodes);
    CHECK(hits > N / 20);
    CHECK_EQ_U64(disagree, 0);
    CHECK_MSG(any.nodes < closest.nodes, "any-hit entered %llu boxes, closest-hit %llu", (unsigned long long)any.nodes,
              (unsigned long long)closest.nodes);
    /* The public entry point agrees. */
    vkrt_hit *h_any = trace_all(cpu, s, &(vkrt_trace_desc){ .any_hit = true }, rays, N);
    vkrt_hit *h_closest = trace_all(cpu, s, &(vkrt_trace_desc){ 0 }, rays, N);
    for (size_t i = 0; h_any && h_closest && i < N; i++) CHECK((h_any[i].prim_id == VKRT_NO_HIT) == (h_closest[i].prim_id == VKRT_NO_HIT));
    free(h_any);
    free(h_closest);
    free(rays);
    vkrt_scene_destroy(s);
}

/* A pipeline specialised to the scene's features renders what the full one renders: the
 * built-in scene has no texture and no emitter, the Cornell box no texture, no metal, no point
 * or directional light and no sky, so compiling them in changes no pixel. */
static void specialisation_changes_no_pixel(void)
{
    for (int file = 0; file < 2; file++) {
    vkrt_scene *s = NULL;
    vkrt_scene_create(cpu, &(vkrt_scene_desc){ .path = file ? VKRT_TEST_DATA_DIR "/cornell.obj" : NULL }, &s);
    CHECK(s != NULL);
    const vkrt_mode modes[3] = { VKRT_MODE_SHADED, VKRT_MODE_AO, VKRT_MODE_PATH };
    for (int m = 0; s && m < 3; m++) {
        vkrt_render_desc d = { .width = 24, .height = 24, .mode = modes[m], .spp = 4 };
        vkrt_render_stats a_st, b_st;
        float *a = test_render(cpu, s, d, NULL, &a_st);
        d.all_features = true;
        float *b = test_render(cpu, s, d, NULL, &b_st);
        CHECK(b_st.features == VKRT_FEATURE_ALL);
        const uint32_t unused = file ? VKRT_FEATURE_TEXTURES | VKRT_FEATURE_SPECULAR | VKRT_FEATURE_PUNCTUAL | VKRT_FEATURE_SKY
                                     : VKRT_FEATURE_TEXTURES | VKRT_FEATURE_EMITTERS;
        CHECK_MSG(!(a_st.features & unused), "file %d mode %d: features 0x%x", file, (int)modes[m], a_st.features);
        if (modes[m] == VKRT_MODE_SHADED && !file) CHECK(!(a_st.features & VKRT_FEATURE_RANDOM));
        if (a && b)
            CHECK_MSG(memcmp(a, b, 24 * 24 * 4 * sizeof *a) == 0, "file %d mode %d: specialised image differs", file,
                      (int)modes[m]);
        free(a);
        free(b);
    }
    vkrt_scene_destroy(s);
    }
}

/* Adaptive sampling against a converged reference (1024 samples): with a target of 5% the
 * pixels' RMS relative error stays near it, fewer samples are taken than the cap, and every
 * sky pixel took one. */
static void adaptive_sampling_stops_at_the_requested_error(void)
{
    vkrt_scene *s = NULL;
    vkrt_scene_create(cpu, &(vkrt_scene_desc){ 0 }, &s);
    if (!s) return;
    const uint32_t W = 32, H = 32;
    vkrt_render_desc ref_d = { .width = W, .height = H, .mode = VKRT_MODE_PATH, .spp = 1024, .seed = 99 };
    vkrt_render_stats ref_st, st;
    float *ref = test_render(cpu, s, ref_d, NULL, &ref_st);
    const float target = 0.05f;
    vkrt_render_desc d = { .width = W, .height = H, .mode = VKRT_MODE_PATH, .spp = 1024, .target_error = target };
    float *err = NULL;
    float *img = test_render(cpu, s, d, &err, &st);
    if (ref && img) {
        double sq = 0.0;
        size_t n = 0, sky = 0;
        for (size_t i = 0; i < (size_t)W * H; i++) {
            if (ref[i * 4 + 3] == 0.0f) {
                sky++;
                CHECK(img[i * 4] == ref[i * 4]);
                continue;
            }
            double lr = 0.2126 * ref[i * 4] + 0.7152 * ref[i * 4 + 1] + 0.0722 * ref[i * 4 + 2];
            double la = 0.2126 * img[i * 4] + 0.7152 * img[i * 4 + 1] + 0.0722 * img[i * 4 + 2];
            if (lr < 0.02) continue;
            sq += (la - lr) * (la - lr) / (lr * lr);
            n++;
        }
        double rms = sqrt(sq / (double)n);
        fprintf(stderr, "  adaptive: %.1f samples per pixel (cap 1024), RMS relative error %.4f over %zu pixels "
                        "(target %.2f), %zu sky pixels\n",
                (double)st.samples / (W * H), rms, n, target, sky);
        CHECK(st.features & VKRT_FEATURE_ADAPTIVE);
        CHECK(n > 100);
        CHECK_MSG(rms <= 1.5 * target, "RMS relative error %.4f above 1.5 x %.2f", rms, target);
        CHECK(st.samples < ref_st.samples / 2);
        CHECK(st.samples >= (W * H - sky) * 8 + sky);
    }
    free(ref);
    free(img);
    free(err);
    vkrt_scene_destroy(s);
}

/* all_features compiles the adaptive test in, but without a target every pixel still takes
 * every sample: the image and the sample count are the specialised render's. */
static void all_features_without_a_target_takes_every_sample(void)
{
    vkrt_scene *s = NULL;
    vkrt_scene_create(cpu, &(vkrt_scene_desc){ 0 }, &s);
    if (!s) return;
    vkrt_render_desc d = { .width = 16, .height = 16, .mode = VKRT_MODE_AO, .spp = 16 };
    vkrt_render_stats a_st, b_st;
    float *a = test_render(cpu, s, d, NULL, &a_st);
    d.all_features = true;
    float *b = test_render(cpu, s, d, NULL, &b_st);
    CHECK_EQ_U64(b_st.samples, a_st.samples);
    if (a && b) CHECK(memcmp(a, b, 16 * 16 * 4 * sizeof *a) == 0);
    free(a);
    free(b);
    vkrt_scene_destroy(s);
}

/* The same seed gives the same image, bit for bit; another seed another one. */
static void seed_makes_renders_reproducible(void)
{
    vkrt_scene *s = NULL;
    vkrt_scene_create(cpu, &(vkrt_scene_desc){ 0 }, &s);
    if (!s) return;
    vkrt_render_desc d = { .width = 16, .height = 16, .mode = VKRT_MODE_PATH, .spp = 2, .seed = 5 };
    float *a = test_render(cpu, s, d, NULL, NULL), *b = test_render(cpu, s, d, NULL, NULL);
    d.seed = 6;
    float *c = test_render(cpu, s, d, NULL, NULL);
    if (a && b && c) {
        CHECK(memcmp(a, b, 16 * 16 * 4 * sizeof *a) == 0);
        CHECK(memcmp(a, c, 16 * 16 * 4 * sizeof *a) != 0);
    }
    free(a);
    free(b);
    free(c);
    vkrt_scene_destroy(s);
}

static void bad_lighting_arguments_are_refused(void)
{
    vkrt_scene *s = NULL;
    vkrt_scene_create(cpu, &(vkrt_scene_desc){ 0 }, &s);
    if (!s) return;
    float rgba[4 * 4 * 4];
    const vkrt_light bad[] = {
        { VKRT_LIGHT_POINT, { 0, 1, 0 }, { NAN, 1, 1 } },
        { VKRT_LIGHT_POINT, { 0, 1, 0 }, { -1, 1, 1 } },
        { VKRT_LIGHT_DIRECTIONAL, { 0, 0, 0 }, { 1, 1, 1 } },
        { (vkrt_light_type)7, { 0, 1, 0 }, { 1, 1, 1 } },
        { VKRT_LIGHT_POINT, { INFINITY, 1, 0 }, { 1, 1, 1 } },
    };
    for (size_t i = 0; i < sizeof bad / sizeof bad[0]; i++) {
        vkrt_render_desc d = { .width = 4, .height = 4, .mode = VKRT_MODE_SHADED, .lights = &bad[i], .light_count = 1 };
        vkrt_result r = vkrt_render(cpu, s, &d, rgba, sizeof rgba / sizeof rgba[0], NULL);
        CHECK_MSG(r == VKRT_ERROR_INVALID_ARGUMENT, "light %zu: %s", i, vkrt_result_string(r));
        CHECK(strstr(vkrt_context_last_error(cpu), "lights[0]") != NULL);
    }
    const vkrt_render_desc others[] = {
        { .width = 4, .height = 4, .mode = VKRT_MODE_PATH, .light_count = 2 },
        { .width = 4, .height = 4, .mode = VKRT_MODE_PATH, .spp = 65537 },
        { .width = 4, .height = 4, .mode = VKRT_MODE_AO, .ao_distance = -1 },
        { .width = 4, .height = 4, .mode = VKRT_MODE_PATH, .target_error = NAN },
        { .width = 4, .height = 4, .mode = VKRT_MODE_PATH, .sky = { { -1, 0, 0 }, { 0, 0, 0 } } },
        { .width = 4, .height = 4, .mode = VKRT_MODE_PATH, .precision = VKRT_PRECISION_DOUBLE },
        { .width = 4, .height = 4, .mode = (vkrt_mode)(VKRT_MODE_PATH + 1) },
        { .width = 4, .height = 4, .mode = VKRT_MODE_PATH, .extra_features = VKRT_FEATURE_ALL + 1 },
    };
    for (size_t i = 0; i < sizeof others / sizeof others[0]; i++) {
        vkrt_result r = vkrt_render(cpu, s, &others[i], rgba, sizeof rgba / sizeof rgba[0], NULL);
        CHECK_MSG(r == VKRT_ERROR_INVALID_ARGUMENT, "case %zu: %s", i, vkrt_result_string(r));
    }
    CHECK(strcmp(vkrt_feature_name(VKRT_FEATURE_SKY), "sky") == 0);
    CHECK(strcmp(vkrt_feature_name(3), "") == 0);
    vkrt_scene_destroy(s);
}

int main(void)
{
    vkrt_result r = vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU, .log = on_log }, &cpu);
    if (r != VKRT_OK) return 1;
    RUN(sampler_points_are_stratified);
    RUN(bsdf_sampling_matches_its_evaluation);
    RUN(point_and_directional_lights_follow_inverse_square_and_cosine);
    RUN(furnace_outside_a_convex_sphere_gives_the_albedo);
    RUN(furnace_inside_an_emitting_sphere_converges_to_the_geometric_series);
    RUN(mirror_reflects_a_known_pattern);
    RUN(ambient_occlusion_sees_only_nearby_occluders);
    RUN(alpha_masked_occluders_cast_no_shadow);
    RUN(light_table_picks_by_power);
    RUN(any_hit_visits_fewer_nodes_than_closest_hit);
    RUN(specialisation_changes_no_pixel);
    RUN(adaptive_sampling_stops_at_the_requested_error);
    RUN(all_features_without_a_target_takes_every_sample);
    RUN(seed_makes_renders_reproducible);
    RUN(bad_lighting_arguments_are_refused);
    vkrt_context_destroy(cpu);
    return check_exit();
}
