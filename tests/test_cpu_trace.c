/* The C reference tracer: camera, packing, analytic depths and normals, the promise that BVH
 * and naive traversal (and every builder) give bit-identical closest hits with either
 * intersector, watertightness, the double-precision reference, vkrt_trace_rays and
 * secondary-ray origins; and that the 4-wide traversal (cpu_trace_bvh4.h) is the binary one's
 * answer, box test by box test and hit by hit. */
#include <float.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "bvh.h"
#include "camera.h"
#include "check.h"
#include "context.h"
#include "core.h"
#include "cpu_trace.h"
#include "mesh.h"
#include "ray_cull.h"
#include "scene_pack.h"
#include "texture.h"
#include "trace_fixtures.h"

static core c;
static vkrt_context *cpu; /* the public API on the CPU backend */

/* ---- fixtures ---- */

/* A mesh built by hand; normals default to the face normal of each triangle. */
static mesh mesh_from(const float *positions, const float *normals, uint32_t tri_count)
{
    mesh m = { 0 };
    m.tri_count = tri_count;
    m.tri_capacity = tri_count;
    m.positions = core_alloc_array(&c, (size_t)tri_count * 9, sizeof(float));
    m.normals = core_alloc_array(&c, (size_t)tri_count * 9, sizeof(float));
    if (!m.positions || !m.normals) abort();
    memcpy(m.positions, positions, (size_t)tri_count * 9 * sizeof(float));
    for (uint32_t i = 0; i < tri_count; i++) {
        const float *p = positions + (size_t)i * 9;
        float n[3];
        if (normals) {
            memcpy(n, normals + (size_t)i * 3, sizeof n);
        } else {
            double e1[3] = { p[3] - p[0], p[4] - p[1], p[5] - p[2] };
            double e2[3] = { p[6] - p[0], p[7] - p[1], p[8] - p[2] };
            double x = e1[1] * e2[2] - e1[2] * e2[1], y = e1[2] * e2[0] - e1[0] * e2[2],
                   z = e1[0] * e2[1] - e1[1] * e2[0];
            double l = sqrt(x * x + y * y + z * z);
            n[0] = l > 0 ? (float)(x / l) : 0.0f;
            n[1] = l > 0 ? (float)(y / l) : 0.0f;
            n[2] = l > 0 ? (float)(z / l) : 1.0f;
        }
        for (int k = 0; k < 3; k++) memcpy(m.normals + (size_t)i * 9 + k * 3, n, sizeof n);
    }
    for (int a = 0; a < 3; a++) {
        m.bounds_min[a] = INFINITY;
        m.bounds_max[a] = -INFINITY;
    }
    for (size_t i = 0; i < (size_t)tri_count * 3; i++)
        for (int a = 0; a < 3; a++) {
            m.bounds_min[a] = fminf(m.bounds_min[a], m.positions[i * 3 + a]);
            m.bounds_max[a] = fmaxf(m.bounds_max[a], m.positions[i * 3 + a]);
        }
    return m;
}

static void mesh_free_local(mesh *m)
{
    core_free(&c, m->positions);
    core_free(&c, m->normals);
    memset(m, 0, sizeof *m);
}

/* The simplest valid BVH: one leaf root holding every triangle in file order. */
static void bvh_single_leaf(const mesh *m, bvh *b)
{
    memset(b, 0, sizeof *b);
    b->nodes = core_alloc(&c, sizeof *b->nodes);
    b->tri_order = core_alloc_array(&c, m->tri_count, sizeof *b->tri_order);
    if (!b->nodes || !b->tri_order) abort();
    b->node_count = 1;
    b->tri_count = m->tri_count;
    for (uint32_t i = 0; i < m->tri_count; i++) b->tri_order[i] = i;
    /* From the corners, not m->bounds_*, which a loaded and normalised mesh may not refresh. */
    float lo[3] = { INFINITY, INFINITY, INFINITY }, hi[3] = { -INFINITY, -INFINITY, -INFINITY };
    for (size_t i = 0; i < (size_t)m->tri_count * 3; i++)
        for (int a = 0; a < 3; a++) {
            lo[a] = fminf(lo[a], m->positions[i * 3 + a]);
            hi[a] = fmaxf(hi[a], m->positions[i * 3 + a]);
        }
    b->nodes[0] = (vkrt_gpu_node){
        .bmin = { lo[0], lo[1], lo[2] },
        .bmax = { hi[0], hi[1], hi[2] },
        .left_first = 0,
        .tri_count = m->tri_count,
    };
}

typedef enum builder_kind { BUILD_SINGLE_LEAF, BUILD_MIDPOINT, BUILD_SAH, BUILD_SBVH, BUILD_KINDS } builder_kind;
static const char *const builder_names[BUILD_KINDS] = { "single-leaf", "midpoint", "sah", "sbvh" };

typedef struct scene {
    bvh b;
    vkrt_gpu_tri *tris;
    bool local_bvh;
} scene;

static bool scene_make(const mesh *m, builder_kind kind, scene *s)
{
    memset(s, 0, sizeof *s);
    if (kind == BUILD_SINGLE_LEAF) {
        bvh_single_leaf(m, &s->b);
        s->local_bvh = true;
    } else {
        bvh_build_desc d = { .builder = kind == BUILD_MIDPOINT ? VKRT_BVH_BUILDER_MIDPOINT
                                        : kind == BUILD_SBVH   ? VKRT_BVH_BUILDER_SPATIAL_SAH
                                                               : VKRT_BVH_BUILDER_BINNED_SAH };
        vkrt_result r = bvh_build(&c, m, &d, &s->b);
        CHECK_MSG(r == VKRT_OK, "bvh_build(%s): %s", builder_names[kind], c.last_error);
        if (r != VKRT_OK) return false;
        char why[256] = "";
        CHECK_MSG(bvh_validate(&s->b, m, why, sizeof why), "%s: %s", builder_names[kind], why);
    }
    s->tris = core_alloc_array(&c, s->b.tri_count, sizeof *s->tris);
    if (!s->tris) abort();
    scene_pack_triangles(m, &s->b, s->tris);
    return true;
}

static void scene_free(scene *s)
{
    core_free(&c, s->tris);
    if (s->local_bvh) {
        core_free(&c, s->b.nodes);
        core_free(&c, s->b.tri_order);
    } else {
        bvh_destroy(&c, &s->b);
    }
    memset(s, 0, sizeof *s);
}

typedef struct render_opts {
    vkrt_mode mode;
    vkrt_traversal traversal;
    vkrt_heat heat;
    vkrt_intersector intersector;
    vkrt_precision precision;
    uint32_t width, height, threads;
    vkrt_camera camera;
    vkrt_progress_fn progress;
    void *progress_user;
} render_opts;

/* Renders into a new buffer (the caller frees it); *out_result gets cpu_trace_render's code. */
static float *render_r(const scene *s, render_opts o, vkrt_result *out_result)
{
    cpu_trace_params p = {
        .mode = o.mode ? o.mode : VKRT_MODE_NORMAL,
        .traversal = o.traversal ? o.traversal : VKRT_TRAVERSAL_BVH,
        .heat = o.heat ? o.heat : VKRT_HEAT_NODES,
        .intersector = o.intersector,
        .precision = o.precision,
        .threads = o.threads ? o.threads : 2,
        .progress = o.progress,
        .progress_user = o.progress_user,
    };
    vkrt_result r = camera_setup(&c, &o.camera, o.width, o.height, &p.camera);
    if (r == VKRT_OK) r = camera_setup_double(&c, &o.camera, o.width, o.height, &p.camera_d);
    CHECK_MSG(r == VKRT_OK, "camera_setup: %s", c.last_error);
    float *img = calloc((size_t)o.width * o.height * 4, sizeof(float));
    if (!img) abort();
    cpu_trace_scene cs = { s->b.nodes, s->b.node_count, s->tris, s->b.tri_count, NULL, NULL };
    trace_counts counts;
    if (r == VKRT_OK) r = cpu_trace_render(&c, &cs, &p, img, &counts);
    *out_result = r;
    return img;
}

static float *render(const scene *s, render_opts o)
{
    vkrt_result r;
    float *img = render_r(s, o, &r);
    CHECK_MSG(r == VKRT_OK, "cpu_trace_render: %s", c.last_error);
    return img;
}

/* The ray of pixel (x, y), in double, from the push constants (what both tracers start from). */
static void pixel_ray(const vkrt_gpu_push *p, uint32_t x, uint32_t y, double o[3], double d[3])
{
    double sx = 2.0 * (x + 0.5) / p->width - 1.0, sy = 1.0 - 2.0 * (y + 0.5) / p->height;
    double v[3] = { p->forward.x + sx * p->right.x + sy * p->up.x, p->forward.y + sx * p->right.y + sy * p->up.y,
                    p->forward.z + sx * p->right.z + sy * p->up.z };
    double l = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
    for (int a = 0; a < 3; a++) d[a] = v[a] / l;
    o[0] = p->eye.x, o[1] = p->eye.y, o[2] = p->eye.z;
}

/* An icosphere-like UV sphere plus a ground quad: closed, curved, many equal-distance edges. */
static mesh make_sphere_scene(uint32_t rings, uint32_t segments)
{
    uint32_t n = rings * segments * 2 + 2;
    float *pos = calloc((size_t)n * 9, sizeof(float));
    if (!pos) abort();
    uint32_t k = 0;
    const double pi = 3.14159265358979323846;
    for (uint32_t i = 0; i < rings; i++) {
        double t0 = pi * i / rings, t1 = pi * (i + 1) / rings;
        for (uint32_t j = 0; j < segments; j++) {
            double p0 = 2 * pi * j / segments, p1 = 2 * pi * (j + 1) / segments;
            double q[4][3] = {
                { sin(t0) * cos(p0), cos(t0), sin(t0) * sin(p0) },
                { sin(t1) * cos(p0), cos(t1), sin(t1) * sin(p0) },
                { sin(t1) * cos(p1), cos(t1), sin(t1) * sin(p1) },
                { sin(t0) * cos(p1), cos(t0), sin(t0) * sin(p1) },
            };
            int idx[6] = { 0, 1, 2, 0, 2, 3 };
            for (int t = 0; t < 6; t++)
                for (int a = 0; a < 3; a++) pos[(size_t)k * 9 + t * 3 + a] = (float)(0.35 * q[idx[t]][a]);
            k += 2;
        }
    }
    float ground[18] = { -0.5f, -0.4f, -0.5f, -0.5f, -0.4f, 0.5f, 0.5f, -0.4f, 0.5f,
                         -0.5f, -0.4f, -0.5f, 0.5f, -0.4f, 0.5f, 0.5f, -0.4f, -0.5f };
    memcpy(pos + (size_t)k * 9, ground, sizeof ground);
    mesh m = mesh_from(pos, NULL, n);
    free(pos);
    return m;
}

/* A random triangle soup: overlapping, intersecting and coincident triangles (the last ones
 * duplicate earlier ones, so ties at equal t must go to the lower prim_id). */
static mesh make_soup(uint32_t count, uint32_t seed)
{
    float *pos = calloc((size_t)count * 9, sizeof(float));
    if (!pos) abort();
    uint32_t state = seed;
    for (uint32_t i = 0; i < count; i++) {
        if (i >= count - count / 8) {
            memcpy(pos + (size_t)i * 9, pos + (size_t)(i - count / 2) * 9, 9 * sizeof(float));
            continue;
        }
        float centre[3];
        for (int a = 0; a < 3; a++) {
            state = state * 1664525u + 1013904223u;
            centre[a] = (float)((state >> 8) / 16777216.0 - 0.5) * 0.8f;
        }
        for (int v = 0; v < 3; v++)
            for (int a = 0; a < 3; a++) {
                state = state * 1664525u + 1013904223u;
                pos[(size_t)i * 9 + v * 3 + a] = centre[a] + (float)((state >> 8) / 16777216.0 - 0.5) * 0.25f;
            }
    }
    mesh m = mesh_from(pos, NULL, count);
    free(pos);
    return m;
}

static bool load_model(const char *name, mesh *m)
{
    char path[512];
    snprintf(path, sizeof path, "%s/meshes/%s", VKRT_MODELS_DIR, name);
    memset(m, 0, sizeof *m);
    vkrt_result r = mesh_load(&c, path, m);
    CHECK_MSG(r == VKRT_OK, "mesh_load(%s): %s", path, c.last_error);
    if (r != VKRT_OK) return false;
    r = mesh_normalize(&c, m, path);
    CHECK_MSG(r == VKRT_OK, "mesh_normalize(%s): %s", path, c.last_error);
    return r == VKRT_OK;
}

static size_t bytes(render_opts o)
{
    return (size_t)o.width * o.height * 4 * sizeof(float);
}

static uint32_t count_hits(const float *id_img, render_opts o)
{
    uint32_t n = 0;
    for (size_t i = 0; i < (size_t)o.width * o.height; i++) n += id_img[i * 4] >= 0.0f;
    return n;
}

/* ---- camera ---- */

static void camera_defaults_frame_the_unit_scene(void)
{
    vkrt_gpu_push p = { 0 };
    CHECK(camera_setup(&c, &(vkrt_camera){ 0 }, 64, 32, &p) == VKRT_OK);
    CHECK(p.eye.x == 0.0f && p.eye.y == 0.0f && p.eye.z == 1.5f);
    CHECK(p.forward.x == 0.0f && p.forward.y == 0.0f && p.forward.z == -1.0f);
    double half = tan(22.5 * 3.14159265358979323846 / 180.0);
    CHECK_NEAR(p.right.x, half * 2.0, 1e-6);
    CHECK_NEAR(p.right.y, 0.0, 1e-7);
    CHECK_NEAR(p.up.y, half, 1e-6);
    CHECK_NEAR(p.up.x, 0.0, 1e-7);
    CHECK_EQ_U64(p.width, 64);
    CHECK_EQ_U64(p.height, 32);

    vkrt_gpu_push q = { 0 };
    CHECK(camera_setup(&c, &(vkrt_camera){ .fov_y_degrees = 45.0f, .up = { 0, 2, 0 }, .eye = { 0, 0, 1.5f } }, 64,
                       32, &q) == VKRT_OK);
    CHECK(memcmp(&p, &q, sizeof p) == 0);
}

static void camera_rejects_bad_input(void)
{
    vkrt_gpu_push p = { 0 };
    CHECK(camera_setup(&c, &(vkrt_camera){ .eye = { NAN, 0, 1 } }, 8, 8, &p) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(camera_setup(&c, &(vkrt_camera){ .target = { 0, INFINITY, 0 } }, 8, 8, &p) ==
          VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(camera_setup(&c, &(vkrt_camera){ .up = { 0, NAN, 0 } }, 8, 8, &p) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(camera_setup(&c, &(vkrt_camera){ .fov_y_degrees = NAN }, 8, 8, &p) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(camera_setup(&c, &(vkrt_camera){ .fov_y_degrees = 180.0f }, 8, 8, &p) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(c.last_error, "fov_y_degrees") != NULL);
    CHECK(camera_setup(&c, &(vkrt_camera){ .fov_y_degrees = -10.0f }, 8, 8, &p) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(camera_setup(&c, &(vkrt_camera){ .fov_y_degrees = 179.0f }, 8, 8, &p) == VKRT_OK);
    CHECK(camera_setup(&c, &(vkrt_camera){ .fov_y_degrees = 0.0f }, 8, 8, &p) == VKRT_OK);
    /* Looking straight down the default up vector. */
    CHECK(camera_setup(&c, &(vkrt_camera){ .eye = { 0, 2, 0 } }, 8, 8, &p) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(strstr(c.last_error, "up") != NULL);
    CHECK(camera_setup(&c, &(vkrt_camera){ .eye = { 0, 0, 2 }, .up = { 0, 0, -3 } }, 8, 8, &p) ==
          VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(camera_setup(&c, &(vkrt_camera){ 0 }, 0, 8, &p) == VKRT_ERROR_INVALID_ARGUMENT);
}

/* ---- packing ---- */

static void octahedral_normals_round_trip_within_1e4(void)
{
    double worst = 0.0;
    const uint32_t n = 200000;
    for (uint32_t i = 0; i < n + 26; i++) {
        float v[3];
        if (i < n) { /* Fibonacci sphere: evenly spread over every octant */
            double z = 1.0 - 2.0 * (i + 0.5) / n, r = sqrt(1.0 - z * z), phi = i * 2.39996322972865332;
            v[0] = (float)(r * cos(phi)), v[1] = (float)(r * sin(phi)), v[2] = (float)z;
        } else { /* the axes, face diagonals and corners, where the fold has its seams */
            int k = (int)(i - n) + ((int)(i - n) >= 13 ? 1 : 0);
            double d[3] = { k % 3 - 1, (k / 3) % 3 - 1, k / 9 - 1 };
            double l = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            for (int a = 0; a < 3; a++) v[a] = (float)(d[a] / l);
        }
        float w[3];
        normal_decode_oct(normal_encode_oct(v), w);
        double e = sqrt((double)(v[0] - w[0]) * (v[0] - w[0]) + (double)(v[1] - w[1]) * (v[1] - w[1]) +
                        (double)(v[2] - w[2]) * (v[2] - w[2]));
        double len = sqrt((double)w[0] * w[0] + (double)w[1] * w[1] + (double)w[2] * w[2]);
        CHECK_NEAR(len, 1.0, 1e-6);
        if (e > worst) worst = e;
    }
    CHECK_MSG(worst < 1e-4, "worst round-trip error %g", worst);
    float zero[3] = { 0, 0, 0 }, w[3];
    normal_decode_oct(normal_encode_oct(zero), w);
    CHECK(w[0] == 0.0f && w[1] == 0.0f && w[2] == 1.0f);
}

static void packing_follows_bvh_order_with_face_normals(void)
{
    float pos[27] = { 0, 0, 0, 1, 0, 0, 0, 1, 0,      /* +z */
                      0, 0, 0, 0, 1, 0, 1, 0, 0,      /* -z */
                      0, 0, 0, 1, 1, 1, 2, 2, 2 };    /* zero area */
    mesh m = mesh_from(pos, NULL, 3);
    uint32_t order[3] = { 2, 0, 1 };
    bvh b = { .tri_order = order, .tri_count = 3 };
    vkrt_gpu_tri t[3];
    scene_pack_triangles(&m, &b, t);
    CHECK_EQ_U64(t[0].prim_id, 2);
    CHECK_EQ_U64(t[1].prim_id, 0);
    CHECK_EQ_U64(t[2].prim_id, 1);
    CHECK(t[1].v1.x == 1.0f && t[1].v2.y == 1.0f);
    CHECK(t[1].face_n.x == 0.0f && t[1].face_n.y == 0.0f && t[1].face_n.z == 1.0f);
    CHECK(t[2].face_n.z == -1.0f);
    CHECK(t[0].face_n.x == 0.0f && t[0].face_n.y == 0.0f && t[0].face_n.z == 0.0f);
    float n[3];
    normal_decode_oct(t[2].n1, n);
    CHECK_NEAR(n[2], -1.0, 1e-6);
    mesh_free_local(&m);
}

/* ---- analytic images ---- */

static void single_triangle_gives_analytic_depth_and_exact_ids(void)
{
    /* Two triangles off screen first, so the visible one has prim_id 2. */
    float pos[27] = { 10, 10, 0, 11, 10, 0, 10, 11, 0,
                      -10, 10, 0, -11, 10, 0, -10, 11, 0,
                      -0.5f, -0.5f, 0, 0.5f, -0.5f, 0, 0, 0.5f, 0 };
    mesh m = mesh_from(pos, NULL, 3);
    for (int k = 0; k < BUILD_KINDS; k++) {
        scene s;
        if (!scene_make(&m, (builder_kind)k, &s)) continue;
        render_opts o = { .mode = VKRT_MODE_DEPTH, .width = 33, .height = 33 };
        float *depth = render(&s, o);
        o.mode = VKRT_MODE_ID;
        float *id = render(&s, o);
        const float *centre = depth + ((size_t)16 * 33 + 16) * 4;
        CHECK(centre[0] == 1.5f && centre[3] == 1.0f);
        const float *cid = id + ((size_t)16 * 33 + 16) * 4;
        CHECK(cid[0] == 2.0f && cid[3] == 1.0f);
        CHECK_NEAR(cid[1], 0.25, 1e-6);
        CHECK_NEAR(cid[2], 0.5, 1e-6);

        vkrt_gpu_push p;
        camera_setup(&c, &(vkrt_camera){ 0 }, 33, 33, &p);
        uint32_t hits = 0, wrong = 0;
        for (uint32_t y = 0; y < 33; y++)
            for (uint32_t x = 0; x < 33; x++) {
                double o3[3], d[3];
                pixel_ray(&p, x, y, o3, d);
                double t = -o3[2] / d[2];
                double px = o3[0] + t * d[0], py = o3[1] + t * d[1];
                /* Inside the triangle by the three edge functions, with a margin for rounding. */
                double e0 = py + 0.5, e1 = 0.5 - py - 2.0 * (px), e2 = 0.5 - py + 2.0 * px;
                double inside = fmin(e0, fmin(e1 / sqrt(5.0), e2 / sqrt(5.0)));
                const float *pd = depth + ((size_t)y * 33 + x) * 4, *pi = id + ((size_t)y * 33 + x) * 4;
                if (inside > 1e-4) {
                    hits++;
                    wrong += pi[0] != 2.0f || pi[3] != 1.0f || fabs(pd[0] - t) > 1e-6 * t;
                } else if (inside < -1e-4) {
                    wrong += pi[0] != -1.0f || pi[1] != 0.0f || pi[2] != 0.0f || pi[3] != 0.0f ||
                             pd[0] != -1.0f || pd[3] != 0.0f;
                }
            }
        CHECK(hits > 100);
        CHECK_MSG(wrong == 0, "%s: %u pixels disagree with the analytic triangle", builder_names[k], wrong);
        free(depth);
        free(id);
        scene_free(&s);
    }
    mesh_free_local(&m);
}

static mesh make_cube(void)
{
    /* Unit cube [-0.5, 0.5]^3, two triangles per face, outward winding. */
    static const float q[6][4][3] = {
        { { -.5f, -.5f, .5f }, { .5f, -.5f, .5f }, { .5f, .5f, .5f }, { -.5f, .5f, .5f } },
        { { .5f, -.5f, -.5f }, { -.5f, -.5f, -.5f }, { -.5f, .5f, -.5f }, { .5f, .5f, -.5f } },
        { { .5f, -.5f, .5f }, { .5f, -.5f, -.5f }, { .5f, .5f, -.5f }, { .5f, .5f, .5f } },
        { { -.5f, -.5f, -.5f }, { -.5f, -.5f, .5f }, { -.5f, .5f, .5f }, { -.5f, .5f, -.5f } },
        { { -.5f, .5f, .5f }, { .5f, .5f, .5f }, { .5f, .5f, -.5f }, { -.5f, .5f, -.5f } },
        { { -.5f, -.5f, -.5f }, { .5f, -.5f, -.5f }, { .5f, -.5f, .5f }, { -.5f, -.5f, .5f } },
    };
    float pos[12 * 9];
    int idx[6] = { 0, 1, 2, 0, 2, 3 };
    for (int f = 0; f < 6; f++)
        for (int t = 0; t < 6; t++)
            for (int a = 0; a < 3; a++) pos[f * 18 + t * 3 + a] = q[f][idx[t]][a];
    return mesh_from(pos, NULL, 12);
}

static void cube_face_gives_analytic_depth(void)
{
    mesh m = make_cube();
    for (int k = 0; k < BUILD_KINDS; k++) {
        scene s;
        if (!scene_make(&m, (builder_kind)k, &s)) continue;
        render_opts o = { .mode = VKRT_MODE_DEPTH, .width = 48, .height = 40, .camera = { .eye = { 0, 0, 3 } } };
        float *depth = render(&s, o);
        vkrt_gpu_push p;
        camera_setup(&c, &o.camera, o.width, o.height, &p);
        uint32_t checked = 0, wrong = 0, misses_wrong = 0;
        for (uint32_t y = 0; y < o.height; y++)
            for (uint32_t x = 0; x < o.width; x++) {
                double or[3], d[3];
                pixel_ray(&p, x, y, or, d);
                double t = (0.5 - or[2]) / d[2];
                double px = or[0] + t * d[0], py = or[1] + t * d[1];
                const float *pd = depth + ((size_t)y * o.width + x) * 4;
                if (fabs(px) < 0.5 - 1e-4 && fabs(py) < 0.5 - 1e-4) {
                    checked++;
                    wrong += !(fabs(pd[0] - t) <= 1e-6 * t) || pd[3] != 1.0f;
                } else if (fabs(px) > 0.5 + 1e-4 || fabs(py) > 0.5 + 1e-4) {
                    /* From (0, 0, 3) the side faces are hidden: outside the front face is a miss. */
                    misses_wrong += pd[0] != -1.0f || pd[3] != 0.0f;
                }
            }
        CHECK(checked > 200);
        CHECK_MSG(wrong == 0 && misses_wrong == 0, "%s: %u hits, %u misses wrong", builder_names[k], wrong,
                  misses_wrong);
        free(depth);
        scene_free(&s);
    }
    mesh_free_local(&m);
}

static void normal_mode_on_a_plane_gives_its_normal(void)
{
    /* A large tilted plane (normal (0, 1, 1) / sqrt 2) seen from above and in front. */
    const float s2 = 0.70710678f;
    float pos[18] = { -2, -2, 2, 2, -2, 2, 2, 2, -2, -2, -2, 2, 2, 2, -2, -2, 2, -2 };
    float nrm[6] = { 0, s2, s2, 0, s2, s2 };
    mesh m = mesh_from(pos, nrm, 2);
    scene s;
    if (scene_make(&m, BUILD_SAH, &s)) {
        render_opts o = { .mode = VKRT_MODE_NORMAL, .width = 24, .height = 24,
                          .camera = { .eye = { 0, 1, 1 }, .fov_y_degrees = 60 } };
        float *img = render(&s, o);
        uint32_t hits = 0;
        for (size_t i = 0; i < (size_t)o.width * o.height; i++) {
            const float *px = img + i * 4;
            if (px[3] == 0.0f) continue;
            hits++;
            CHECK_NEAR(px[0], 0.5, 1e-4);
            CHECK_NEAR(px[1], s2 * 0.5 + 0.5, 1e-4);
            CHECK_NEAR(px[2], s2 * 0.5 + 0.5, 1e-4);
            CHECK(px[3] == 1.0f);
        }
        CHECK_EQ_U64(hits, (uint64_t)o.width * o.height);
        free(img);
        /* Seen from behind, the tracer is two-sided and still shows the stored normal. */
        o.camera = (vkrt_camera){ .eye = { 0, -1, -1 } };
        img = render(&s, o);
        const float *centre = img + ((size_t)12 * o.width + 12) * 4;
        CHECK(centre[3] == 1.0f);
        CHECK_NEAR(centre[1], s2 * 0.5 + 0.5, 1e-4);
        free(img);
        scene_free(&s);
    }
    mesh_free_local(&m);
}

static void miss_pixels_follow_the_mode_conventions(void)
{
    float pos[9] = { 5, 5, 0, 6, 5, 0, 5, 6, 0 };
    mesh m = mesh_from(pos, NULL, 1);
    scene s;
    if (scene_make(&m, BUILD_SINGLE_LEAF, &s)) {
        render_opts o = { .width = 4, .height = 4 };
        const vkrt_mode modes[3] = { VKRT_MODE_NORMAL, VKRT_MODE_DEPTH, VKRT_MODE_ID };
        const float expect[3][4] = { { 0, 0, 0, 0 }, { -1, 0, 0, 0 }, { -1, 0, 0, 0 } };
        for (int k = 0; k < 3; k++) {
            o.mode = modes[k];
            float *img = render(&s, o);
            for (size_t i = 0; i < 16; i++) CHECK(memcmp(img + i * 4, expect[k], sizeof expect[k]) == 0);
            free(img);
        }
        scene_free(&s);
    }
    mesh_free_local(&m);
}

/* ---- traversal equivalence ---- */

typedef struct named_mesh {
    const char *name;
    mesh m;
    bool loaded; /* true: free with mesh_destroy */
    uint32_t size;
} named_mesh;

static int test_meshes(named_mesh *out)
{
    int n = 0;
    out[n++] = (named_mesh){ "sphere+ground", make_sphere_scene(24, 32), false, 64 };
    out[n++] = (named_mesh){ "soup", make_soup(600, 7), false, 64 };
    out[n++] = (named_mesh){ "cube", make_cube(), false, 48 };
    const char *files[3] = { "teapot.obj", "bunny.obj", "homer_10k.obj" };
    const uint32_t sizes[3] = { 80, 96, 48 };
    for (int i = 0; i < 3; i++) {
        out[n] = (named_mesh){ files[i], { 0 }, true, sizes[i] };
        if (load_model(files[i], &out[n].m)) n++;
    }
    return n;
}

static void free_test_meshes(named_mesh *ms, int n)
{
    for (int i = 0; i < n; i++) {
        if (ms[i].loaded) mesh_destroy(&c, &ms[i].m);
        else mesh_free_local(&ms[i].m);
    }
}

/* Every builder's BVH renders the naive images bit for bit. The naive images are rendered over
 * two triangle orders, the mesh's own (the single leaf) and the spatial-split BVH's (reordered,
 * and with triangles referenced more than once), and must agree too: a naive render is some
 * seconds under the sanitizers, so the midpoint and SAH orders are left to their BVH images. */
static void bvh_and_naive_give_identical_id_and_depth_images(void)
{
    named_mesh ms[8];
    int n = test_meshes(ms);
    /* A camera off the axes, so rays are not axis-aligned and hit boxes at odd angles. */
    const vkrt_camera cams[2] = { { .fov_y_degrees = 0.0f }, { .eye = { 0.9f, 0.5f, 1.1f }, .target = { 0, 0.05f, 0 } } };
    for (int i = 0; i < n; i++) {
        float *naive_id[4] = { NULL }, *naive_depth[4] = { NULL };
        for (int k = 0; k < BUILD_KINDS; k++) {
            scene s;
            if (!scene_make(&ms[i].m, (builder_kind)k, &s)) continue;
            const bool naive_here = k == BUILD_SINGLE_LEAF || k == BUILD_SBVH;
            for (int ci = 0; ci < 4; ci++) {
                /* Cameras 2 and 3: cameras 0 and 1 with Moller-Trumbore. */
                render_opts o = { .width = ms[i].size, .height = ms[i].size, .camera = cams[ci % 2], .threads = 2,
                                  .intersector = ci < 2 ? VKRT_INTERSECTOR_WATERTIGHT : VKRT_INTERSECTOR_MOLLER_TRUMBORE };
                if (naive_here) {
                    o.traversal = VKRT_TRAVERSAL_NAIVE;
                    o.mode = VKRT_MODE_ID;
                    float *id = render(&s, o);
                    o.mode = VKRT_MODE_DEPTH;
                    float *depth = render(&s, o);
                    if (!naive_id[ci]) {
                        naive_id[ci] = id, naive_depth[ci] = depth;
                    } else {
                        CHECK_MSG(memcmp(naive_id[ci], id, bytes(o)) == 0 && memcmp(naive_depth[ci], depth, bytes(o)) == 0,
                                  "%s cam %d: naive images differ between the mesh's order and the %s order", ms[i].name,
                                  ci, builder_names[k]);
                        free(id);
                        free(depth);
                    }
                }
                if (!naive_id[ci]) continue; /* scene_make failed for the single leaf: reported there */
                o.traversal = VKRT_TRAVERSAL_BVH;
                o.mode = VKRT_MODE_ID;
                float *bvh_id = render(&s, o);
                o.mode = VKRT_MODE_DEPTH;
                float *bvh_depth = render(&s, o);
                CHECK_MSG(memcmp(bvh_id, naive_id[ci], bytes(o)) == 0, "%s %s cam %d: id images differ", ms[i].name,
                          builder_names[k], ci);
                CHECK_MSG(memcmp(bvh_depth, naive_depth[ci], bytes(o)) == 0, "%s %s cam %d: depth images differ",
                          ms[i].name, builder_names[k], ci);
                CHECK_MSG(count_hits(bvh_id, o) > (uint32_t)(o.width * o.height / 20), "%s cam %d: too few hits",
                          ms[i].name, ci);
                free(bvh_id);
                free(bvh_depth);
            }
            scene_free(&s);
        }
        for (int ci = 0; ci < 4; ci++) {
            free(naive_id[ci]);
            free(naive_depth[ci]);
        }
    }
    free_test_meshes(ms, n);
}

static void midpoint_and_sah_give_identical_images_in_every_mode(void)
{
    mesh m;
    if (!load_model("bunny.obj", &m)) return;
    scene a, b;
    bool ok_a = scene_make(&m, BUILD_MIDPOINT, &a), ok_b = scene_make(&m, BUILD_SAH, &b);
    if (ok_a && ok_b) {
        const vkrt_mode modes[3] = { VKRT_MODE_ID, VKRT_MODE_DEPTH, VKRT_MODE_NORMAL };
        for (int k = 0; k < 3; k++) {
            render_opts o = { .mode = modes[k], .width = 72, .height = 56 };
            float *ia = render(&a, o), *ib = render(&b, o);
            CHECK_MSG(memcmp(ia, ib, bytes(o)) == 0, "mode %d differs between midpoint and sah", (int)modes[k]);
            free(ia);
            free(ib);
        }
    }
    if (ok_a) scene_free(&a);
    if (ok_b) scene_free(&b);
    mesh_destroy(&c, &m);
}

/* ---- heat ---- */

static void heatmap_counts_are_consistent(void)
{
    mesh m = make_sphere_scene(16, 24);
    for (int k = BUILD_MIDPOINT; k < BUILD_KINDS; k++) {
        scene s;
        if (!scene_make(&m, (builder_kind)k, &s)) continue;
        render_opts o = { .mode = VKRT_MODE_HEATMAP, .width = 40, .height = 40,
                          .camera = { .eye = { 0.3f, 0.6f, 1.2f } } };
        o.traversal = VKRT_TRAVERSAL_NAIVE;
        o.heat = VKRT_HEAT_TRIS;
        float *naive = render(&s, o);
        o.traversal = VKRT_TRAVERSAL_BVH;
        float *tris = render(&s, o);
        o.heat = VKRT_HEAT_NODES;
        float *nodes = render(&s, o);
        o.heat = VKRT_HEAT_LEAVES;
        float *leaves = render(&s, o);
        o.mode = VKRT_MODE_ID;
        float *id = render(&s, o);
        o.traversal = VKRT_TRAVERSAL_NAIVE;
        o.heat = VKRT_HEAT_NODES;
        o.mode = VKRT_MODE_HEATMAP;
        float *naive_nodes = render(&s, o);
        uint32_t bad = 0;
        for (size_t i = 0; i < (size_t)o.width * o.height; i++) {
            const float *px = naive + i * 4;
            /* Naive traversal tests every stored triangle: with spatial splits, each copy. */
            bad += px[0] != (float)s.b.tri_count || px[1] != 0.0f || px[2] != 0.0f || px[3] != 1.0f;
            bad += naive_nodes[i * 4] != 0.0f || naive_nodes[i * 4 + 3] != 1.0f;
            bad += leaves[i * 4] > nodes[i * 4] || nodes[i * 4] > (float)s.b.node_count;
            bad += tris[i * 4] > (float)s.b.tri_count;
            bad += nodes[i * 4 + 3] != 1.0f || leaves[i * 4 + 3] != 1.0f || tris[i * 4 + 3] != 1.0f;
            /* A hit needs a leaf entered and a triangle tested. */
            if (id[i * 4] >= 0.0f) bad += leaves[i * 4] < 1.0f || tris[i * 4] < 1.0f || nodes[i * 4] < 1.0f;
        }
        CHECK_MSG(bad == 0, "%s: %u heat values inconsistent", builder_names[k], bad);
        free(naive);
        free(tris);
        free(nodes);
        free(leaves);
        free(id);
        free(naive_nodes);
        scene_free(&s);
    }
    mesh_free_local(&m);
}

/* ---- threads and progress ---- */

static void thread_counts_give_identical_images(void)
{
    mesh m = make_sphere_scene(20, 28);
    scene s;
    if (scene_make(&m, BUILD_SAH, &s)) {
        const vkrt_mode modes[4] = { VKRT_MODE_NORMAL, VKRT_MODE_DEPTH, VKRT_MODE_ID, VKRT_MODE_HEATMAP };
        for (int k = 0; k < 4; k++) {
            /* 70x45 leaves partial tiles on the right and bottom. */
            render_opts o = { .mode = modes[k], .width = 70, .height = 45, .threads = 1 };
            float *one = render(&s, o);
            o.threads = 2;
            float *two = render(&s, o);
            o.threads = 5;
            float *five = render(&s, o);
            CHECK_MSG(memcmp(one, two, bytes(o)) == 0, "mode %d: 1 vs 2 threads differ", (int)modes[k]);
            CHECK_MSG(memcmp(one, five, bytes(o)) == 0, "mode %d: 1 vs 5 threads differ", (int)modes[k]);
            free(one);
            free(two);
            free(five);
        }
        scene_free(&s);
    }
    mesh_free_local(&m);
}

static void count_warning(void *user, vkrt_log_level level, const char *message)
{
    (void)message;
    if (level == VKRT_LOG_WARN) ++*(int *)user;
}

/* Worker threads that fail to start (the test cap stops them where pthread_create would)
 * leave the image to the threads that did, down to the caller alone: the same pixels, and a
 * warning through the log. */
static void thread_start_failure_gives_the_same_image(void)
{
    mesh m = make_sphere_scene(20, 28);
    scene s;
    if (scene_make(&m, BUILD_SAH, &s)) {
        render_opts o = { .mode = VKRT_MODE_NORMAL, .width = 70, .height = 45, .threads = 1 };
        float *one = render(&s, o);
        int warnings = 0;
        c.log = count_warning;
        c.log_user = &warnings;
        for (uint32_t cap = 1; cap <= 2; cap++) {
            c.test_thread_cap = cap;
            warnings = 0;
            o.threads = 4;
            float *capped = render(&s, o);
            CHECK_MSG(memcmp(one, capped, bytes(o)) == 0, "%u of 4 threads started: the image differs", cap);
            CHECK_MSG(warnings == 1, "%u of 4 threads started: %d warnings, not 1", cap, warnings);
            free(capped);
        }
        c.test_thread_cap = 0;
        c.log = NULL;
        c.log_user = NULL;
        free(one);
        scene_free(&s);
    }
    mesh_free_local(&m);
}

typedef struct progress_log {
    pthread_t caller;
    atomic_int calls;
    int cancel_after; /* < 0: never */
    bool wrong_thread, out_of_range, not_monotonic;
    float last;
} progress_log;

static bool on_progress(void *user, const char *stage, float fraction)
{
    progress_log *l = user;
    (void)stage;
    int n = atomic_fetch_add(&l->calls, 1) + 1;
    if (!pthread_equal(pthread_self(), l->caller)) l->wrong_thread = true;
    if (!(fraction >= 0.0f && fraction <= 1.0f)) l->out_of_range = true;
    if (fraction < l->last) l->not_monotonic = true;
    l->last = fraction;
    return l->cancel_after < 0 || n < l->cancel_after;
}

static void progress_runs_on_the_caller_and_cancel_returns_cancelled(void)
{
    mesh m = make_sphere_scene(16, 24);
    scene s;
    if (scene_make(&m, BUILD_SAH, &s)) {
        progress_log l = { .caller = pthread_self(), .cancel_after = -1 };
        render_opts o = { .width = 128, .height = 128, .threads = 3, .progress = on_progress, .progress_user = &l };
        vkrt_result r;
        float *img = render_r(&s, o, &r);
        CHECK(r == VKRT_OK);
        CHECK(atomic_load(&l.calls) >= 1);
        CHECK(l.last == 1.0f);
        CHECK(!l.wrong_thread && !l.out_of_range && !l.not_monotonic);
        free(img);

        for (uint32_t threads = 1; threads <= 3; threads += 2) {
            progress_log lc = { .caller = pthread_self(), .cancel_after = 1 };
            o.progress_user = &lc;
            o.threads = threads;
            o.traversal = VKRT_TRAVERSAL_NAIVE;
            img = render_r(&s, o, &r);
            CHECK(r == VKRT_ERROR_CANCELLED);
            CHECK(!lc.wrong_thread);
            /* Honoured at once: no further callbacks after the one that said stop. */
            CHECK_EQ_U64(atomic_load(&lc.calls), 1);
            free(img);
        }
        scene_free(&s);
    }
    mesh_free_local(&m);
}

/* ---- robustness: watertightness, the double reference, arbitrary rays ---- */

/* A mesh of ../shared/models/meshes as a scene of the CPU context (normalised). */
static vkrt_scene *model_scene(const char *name)
{
    char path[512];
    snprintf(path, sizeof path, "%s/meshes/%s", VKRT_MODELS_DIR, name);
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(cpu, &(vkrt_scene_desc){ .path = path }, &s);
    CHECK_MSG(r == VKRT_OK, "%s: %s", path, vkrt_context_last_error(cpu));
    return s;
}

static void cpu_float_watertight_never_misses_shared_edges_and_vertices(void)
{
    check_watertight_on(cpu, VKRT_PRECISION_FLOAT, "cpu float");
}

static void cpu_double_watertight_never_misses_shared_edges_and_vertices(void)
{
    check_watertight_on(cpu, VKRT_PRECISION_DOUBLE, "cpu double");
}

static void cpu_trace_rays_follow_the_documented_rules(void)
{
    check_ray_rules_on(cpu, VKRT_PRECISION_FLOAT, "cpu float");
    check_ray_rules_on(cpu, VKRT_PRECISION_DOUBLE, "cpu double");
}

/* Texture arithmetic: every finite half survives half -> float -> half; floats round to the
 * nearest half (ties to even); sampling at texel centres returns the texels, between them their
 * blend, and each wrap mode maps coordinates outside [0, 1] as glTF defines it. */
static void texture_halves_round_trip_and_wraps_follow_their_modes(void)
{
    size_t bad = 0;
    for (uint32_t h = 0; h < 0x10000u; h++) {
        if ((h & 0x7C00u) == 0x7C00u && (h & 0x3FFu)) continue; /* NaN */
        bad += half_from_float(half_to_float((uint16_t)h)) != h;
    }
    CHECK_EQ_U64(bad, 0);
    CHECK(half_from_float(1.0f + 0x1p-11f) == 0x3C00u);            /* a tie: to even (1.0) */
    CHECK(half_from_float(1.0f + 3 * 0x1p-11f) == 0x3C02u);        /* a tie: to even (up) */
    CHECK(half_from_float(65520.0f) == 0x7C00u && half_from_float(65519.0f) == 0x7BFFu);
    CHECK(half_from_float(0x1p-24f) == 0x0001u && half_from_float(0x1p-25f) == 0x0000u);

    /* 4x1 texels whose red is 0, 1/3, 2/3, 1 (exact in half after rounding, compared as such). */
    uint8_t rgba[16];
    static const uint8_t reds[4] = { 0, 100, 200, 255 };
    for (int i = 0; i < 4; i++) rgba[4 * i] = reds[i], rgba[4 * i + 1] = rgba[4 * i + 2] = 0, rgba[4 * i + 3] = 255;
    uint32_t texels[8];
    texture_encode_rgba8(rgba, 4, 1, texels);
    float red[4];
    for (int i = 0; i < 4; i++) red[i] = half_to_float((uint16_t)(texels[2 * i] & 0xFFFFu));
    CHECK(red[0] == 0.0f && red[3] == 1.0f && red[1] > 0.12f && red[1] < 0.13f); /* sRGB 100 is linear 0.127 */
    const struct {
        uint32_t wrap;
        float u, expected;
    } cases[] = {
        { VKRT_GPU_WRAP_REPEAT, 0.125f, -1 },  { VKRT_GPU_WRAP_REPEAT, 1.125f, -1 }, { VKRT_GPU_WRAP_REPEAT, -0.875f, -1 },
        { VKRT_GPU_WRAP_CLAMP, 1.5f, -4 },     { VKRT_GPU_WRAP_CLAMP, -3.0f, -2 },   { VKRT_GPU_WRAP_MIRROR, 1.875f, -1 },
        { VKRT_GPU_WRAP_MIRROR, 1.125f, -4 },  { VKRT_GPU_WRAP_REPEAT, 0.25f, -3 },  { VKRT_GPU_WRAP_REPEAT, 1e31f, -5 },
    };
    /* expected: -1 texel 0, -2 texel 0 (clamped), -3 the blend of texels 0 and 1 halfway, -4
     * texel 3, -5 u = 0 (a coordinate too large to wrap): the edge, texels 3 and 0 halfway. */
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        vkrt_gpu_texture t = { 0, 4, 1, cases[k].wrap | cases[k].wrap << 8 };
        float out[4];
        texture_sample(&t, texels, cases[k].u, 0.5f, out);
        float want = cases[k].expected == -4   ? red[3]
                     : cases[k].expected == -3 ? red[0] * 0.5f + red[1] * 0.5f
                     : cases[k].expected == -5 ? red[3] * 0.5f + red[0] * 0.5f
                                               : red[0];
        CHECK_MSG(out[0] == want && out[3] == 1.0f, "case %zu: u %g wrap %u: red %g, expected %g", k,
                  (double)cases[k].u, cases[k].wrap, (double)out[0], (double)want);
    }
}

static void cpu_grazing_hit_distances_are_exact(void)
{
    check_grazing_distances_on(cpu, cpu, "cpu float");
}

static void cpu_secondary_rays_never_rehit_their_own_triangle(void)
{
    check_no_self_intersection_on(cpu, "cpu");
}

static void cpu_camera_rays_hit_what_the_render_shows_on_exported_triangles(void)
{
    check_camera_rays_and_triangles_on(cpu, "cpu");
}

/* Rays in random directions from random points of the scene's box, into shared meshes: the
 * double reference and float agree on nearly every prim_id, and each precision's BVH and naive
 * traversal agree exactly. */
static void cpu_trace_rays_bvh_naive_and_precisions_agree(void)
{
    const char *files[2] = { "bunny.obj", "teapot.obj" };
    for (int f = 0; f < 2; f++) {
        vkrt_scene *s = model_scene(files[f]);
        if (!s) continue;
        enum { N = 20000 };
        vkrt_ray *rays = random_rays_in_box(N, 99 + (uint64_t)f);
        for (int isect = VKRT_INTERSECTOR_WATERTIGHT; isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
            vkrt_hit *h[2][2];
            for (int prec = 0; prec < 2; prec++)
                for (int t = 0; t < 2; t++) {
                    vkrt_trace_desc d = { .traversal = t ? VKRT_TRAVERSAL_NAIVE : VKRT_TRAVERSAL_BVH,
                                          .intersector = (vkrt_intersector)isect,
                                          .precision = prec ? VKRT_PRECISION_DOUBLE : VKRT_PRECISION_FLOAT };
                    h[prec][t] = trace_all(cpu, s, &d, rays, N);
                }
            size_t same = 0, hits = 0;
            for (int i = 0; i < N; i++) {
                same += h[0][0][i].prim_id == h[1][0][i].prim_id;
                hits += h[0][0][i].prim_id != VKRT_NO_HIT;
            }
            CHECK_MSG(memcmp(h[0][0], h[0][1], N * sizeof *h[0][0]) == 0, "%s isect %d: float BVH and naive differ", files[f], isect);
            CHECK_MSG(memcmp(h[1][0], h[1][1], N * sizeof *h[1][0]) == 0, "%s isect %d: double BVH and naive differ", files[f], isect);
            CHECK_MSG(same >= (size_t)(0.9999 * N), "%s isect %d: float and double agree on %zu of %d rays", files[f], isect, same, N);
            CHECK_MSG(hits > N / 10, "%s: only %zu of %d rays hit", files[f], hits, N);
            fprintf(stderr, "  %s isect %d: float = double on %zu of %d rays (%zu hit)\n", files[f], isect, same, N, hits);
            for (int k = 0; k < 4; k++) free(h[k / 2][k % 2]);
        }
        free(rays);
        vkrt_scene_destroy(s);
    }
}

/* Camera renders of shared meshes: the double reference and float agree on the triangle id of
 * at least 99.99% of pixels, where a pixel whose ids differ but whose depths agree within
 * 1e-6 relative counts as agreeing: overlapping triangles at one depth (dragon_48k has them),
 * a z-fight neither precision can decide. The strict id agreement must still reach 99.9%. */
static void double_reference_and_float_agree_on_camera_renders(void)
{
    const char *files[3] = { "bunny.obj", "teapot.obj", "dragon_48k.obj" };
    const uint32_t w = 256, h = 256;
    size_t n = vkrt_render_floats(w, h);
    float *img[4];
    for (int k = 0; k < 4; k++)
        if (!(img[k] = malloc(n * sizeof *img[k]))) abort();
    for (int f = 0; f < 3; f++) {
        vkrt_scene *s = model_scene(files[f]);
        if (!s) continue;
        /* img: float id, float depth, double id, double depth */
        for (int k = 0; k < 4; k++) {
            vkrt_render_desc d = { .width = w, .height = h, .mode = k % 2 ? VKRT_MODE_DEPTH : VKRT_MODE_ID,
                                   .precision = k < 2 ? VKRT_PRECISION_FLOAT : VKRT_PRECISION_DOUBLE,
                                   .camera = { .eye = { 0.8f, 0.4f, 1.2f } } };
            CHECK(vkrt_render(cpu, s, &d, img[k], n, NULL) == VKRT_OK);
        }
        size_t same = 0, z_fights = 0, hits = 0;
        for (size_t i = 0; i < (size_t)w * h; i++) {
            float tf = img[1][i * 4], td = img[3][i * 4];
            if (img[0][i * 4] == img[2][i * 4]) same++;
            else if (tf >= 0 && td >= 0 && fabsf(tf - td) <= 1e-6f * td) z_fights++;
            hits += td >= 0;
        }
        fprintf(stderr, "  %s: float = double on %zu of %u pixels, %zu z-fights (%zu hit)\n", files[f], same, w * h,
                z_fights, hits);
        CHECK_MSG(same + z_fights >= (size_t)(0.9999 * w * h), "%s: float and double agree on %zu + %zu z-fights of %u pixels",
                  files[f], same, z_fights, w * h);
        CHECK_MSG(same >= (size_t)(0.999 * w * h), "%s: float and double ids agree on %zu of %u pixels", files[f], same, w * h);
        CHECK(hits > (size_t)w * h / 20);
        vkrt_scene_destroy(s);
    }
    for (int k = 0; k < 4; k++) free(img[k]);
}

/* From inside a closed box or icosphere every pixel hits, in every precision and with either
 * intersector. */
static void eye_inside_a_closed_mesh_always_hits(void)
{
    closed_mesh m = icosphere(3, 1.0, (const double[3]){ 0, 0, 0 });
    vkrt_scene *scenes[2] = { unit_cube_scene(cpu), closed_mesh_scene(cpu, &m) };
    const uint32_t w = 48, h = 40;
    size_t n = vkrt_render_floats(w, h);
    float *img = malloc(n * sizeof *img);
    if (!img) abort();
    for (int k = 0; k < 2; k++) {
        if (!scenes[k]) continue;
        for (int prec = VKRT_PRECISION_FLOAT; prec <= VKRT_PRECISION_DOUBLE; prec++)
            for (int isect = VKRT_INTERSECTOR_WATERTIGHT; isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
                /* The eye at the centre (on the cube's diagonals) and off it, looking along an axis. */
                const vkrt_camera cams[2] = { { .eye = { 0, 0, 0 }, .target = { 0, 0, 1 }, .fov_y_degrees = 120 },
                                              { .eye = { 0.1f, -0.2f, 0.15f }, .target = { 1, -0.2f, 0.15f }, .fov_y_degrees = 90 } };
                for (int ci = 0; ci < 2; ci++) {
                    vkrt_render_desc d = { .width = w, .height = h, .mode = VKRT_MODE_ID, .camera = cams[ci],
                                           .intersector = (vkrt_intersector)isect, .precision = (vkrt_precision)prec };
                    CHECK(vkrt_render(cpu, scenes[k], &d, img, n, NULL) == VKRT_OK);
                    size_t misses = 0;
                    for (size_t i = 0; i < (size_t)w * h; i++) misses += img[i * 4] < 0;
                    if (isect == VKRT_INTERSECTOR_WATERTIGHT)
                        CHECK_MSG(misses == 0, "mesh %d precision %d camera %d: %zu pixels miss", k, prec, ci, misses);
                    else if (misses)
                        fprintf(stderr, "  Moller-Trumbore, mesh %d precision %d camera %d: %zu pixels leak\n", k, prec, ci, misses);
                }
            }
        vkrt_scene_destroy(scenes[k]);
    }
    free(img);
    closed_mesh_free(&m);
}

/* ---- the 4-wide traversal against the binary one ---- */

static bool same_float(float a, float b) { return memcmp(&a, &b, sizeof a) == 0 || (isnan(a) && isnan(b)); }

/* The four-box test (float4.h) equals intersect_box_f on each slot, hit mask and
 * entry distances bit for bit, on what the slab rules exist for: +0 and -0 direction
 * components (infinite reciprocals), denormal and huge components, origins on a box's planes
 * and corners, flat and infinite boxes, boxes touching the origin, inverted and NaN boxes,
 * unused slots, and best_t of 0, -0, +inf and NaN. */
static void bvh4_box_test_simd_equals_binary_box_test_on_hostile_inputs(void)
{
    const float comps[] = { 0.0f, -0.0f, 1.0f, -1.0f, 0.5f, -0.25f, 1e-40f, -1e-40f, 3e38f, -3e38f, 1e-20f };
    const float coords[] = { 0.0f, -0.0f, 1.0f, -1.0f, 0.5f, 2.0f, -3.0f, INFINITY, -INFINITY, FLT_MAX, -FLT_MAX, 1e-30f };
    const float bests[] = { INFINITY, 0.0f, -0.0f, 1.0f, 1e-30f, 3.5f, NAN };
    const size_t nc = sizeof comps / sizeof comps[0], nx = sizeof coords / sizeof coords[0];
    test_rng rng = { 2024 };
    size_t tests = 0, hits = 0, differ = 0;
    for (int iter = 0; iter < 200000; iter++) {
        vkrt_gpu_ray ray = { .tmin = iter % 5 == 0 ? 0.0f : iter % 5 == 1 ? -0.0f : iter % 5 == 2 ? 1e-3f : iter % 5 == 3 ? -INFINITY : 0.75f };
        float o[3], d[3];
        for (int a = 0; a < 3; a++) {
            d[a] = comps[(size_t)(rng_uniform(&rng) * nc)];
            /* Origins on the coordinate grid the boxes use, so they sit on planes and corners. */
            o[a] = rng_uniform(&rng) < 0.6 ? coords[(size_t)(rng_uniform(&rng) * 6)] : (float)(4.0 * rng_uniform(&rng) - 2.0);
        }
        ray.origin = (vkrt_float3){ o[0], o[1], o[2] };
        ray.dir = (vkrt_float3){ d[0], d[1], d[2] };
        bvh4_node n;
        for (int k = 0; k < BVH4_WIDTH; k++) {
            double kind = rng_uniform(&rng);
            n.child[k] = kind < 0.08 ? BVH4_EMPTY : (uint32_t)k;
            n.count[k] = 0;
            for (int a = 0; a < 3; a++) {
                float lo = coords[(size_t)(rng_uniform(&rng) * nx)], hi = coords[(size_t)(rng_uniform(&rng) * nx)];
                if (kind < 0.5 && lo > hi) {
                    float t = lo;
                    lo = hi, hi = t;
                } else if (kind < 0.6) {
                    hi = lo; /* flat */
                } else if (kind < 0.7) {
                    lo = o[a], hi = o[a] + 1.0f; /* touching the origin */
                } else if (kind < 0.72) {
                    lo = NAN;
                }
                n.lo[a][k] = lo, n.hi[a][k] = hi;
            }
        }
        float best = bests[(size_t)(rng_uniform(&rng) * (sizeof bests / sizeof bests[0]))];
        float t_simd[BVH4_WIDTH], t_scalar[BVH4_WIDTH];
        unsigned m_simd = cpu_trace_box4_test(&ray, &n, best, true, t_simd);
        unsigned m_scalar = cpu_trace_box4_test(&ray, &n, best, false, t_scalar);
        bool same = m_simd == m_scalar;
        for (int k = 0; k < BVH4_WIDTH; k++)
            if (n.child[k] != BVH4_EMPTY) same = same && same_float(t_simd[k], t_scalar[k]);
        if (!same && differ++ < 3)
            fprintf(stderr, "  differ: o (%g %g %g) d (%g %g %g) tmin %g best %g: masks %x %x\n", o[0], o[1], o[2], d[0],
                    d[1], d[2], ray.tmin, best, m_simd, m_scalar);
        tests++;
        for (unsigned k = 0; k < BVH4_WIDTH; k++) hits += (m_scalar >> k) & 1u;
    }
    fprintf(stderr, "  %zu four-box tests, %zu boxes hit, %zu differ\n", tests, hits, differ);
    CHECK_EQ_U64(differ, 0);
    CHECK(hits > tests / 10);
}

/* vkrt_trace_rays' cull on the host (ray_cull.h) answers as the reference's first step does,
 * the root box test of a ray from the buffer, on the inputs where that test has its special
 * cases: origins on the box's planes and corners, +-0, denormal, huge and infinite direction
 * components, NaN and infinite origins, tmin and tmax of every kind (tmax 0 meaning infinity,
 * NaN, below tmin), flat and inverted boxes. A ray culled that the reference enters would lose
 * its hits; one kept that it does not enter would cost the device a traversal. */
static void ray_cull_test4_equals_the_reference_root_test_on_hostile_rays(void)
{
    const float comps[] = { 0.0f, -0.0f, 1.0f, -1.0f, 0.5f, -0.25f, 1e-40f, -1e-40f, 3e38f, -3e38f, 1e-20f, INFINITY, NAN };
    const float coords[] = { 0.0f, -0.0f, 1.0f, -1.0f, 0.5f, 2.0f, -3.0f, INFINITY, -INFINITY, FLT_MAX, -FLT_MAX, 1e-30f, NAN };
    const float spans[] = { 0.0f, -0.0f, 1e-3f, 0.75f, 4.0f, -1.0f, 1e30f, INFINITY, NAN };
    const size_t nc = sizeof comps / sizeof comps[0], nx = sizeof coords / sizeof coords[0];
    const size_t ns = sizeof spans / sizeof spans[0];
    test_rng rng = { 77 };
    size_t tests = 0, entered = 0, differ = 0;
    for (int iter = 0; iter < 100000; iter++) {
        vkrt_gpu_node box = { 0 };
        const double kind = rng_uniform(&rng);
        float lo[3], hi[3];
        for (int a = 0; a < 3; a++) {
            lo[a] = coords[(size_t)(rng_uniform(&rng) * 7)], hi[a] = coords[(size_t)(rng_uniform(&rng) * 7)];
            if (kind < 0.7 && lo[a] > hi[a]) {
                float t = lo[a];
                lo[a] = hi[a], hi[a] = t;
            } else if (kind < 0.8) {
                hi[a] = lo[a]; /* flat */
            }
        }
        box.bmin = (vkrt_float3){ lo[0], lo[1], lo[2] };
        box.bmax = (vkrt_float3){ hi[0], hi[1], hi[2] };
        vkrt_ray rays[4];
        for (int l = 0; l < 4; l++) {
            float o[3], d[3];
            for (int a = 0; a < 3; a++) {
                const double u = rng_uniform(&rng);
                /* On the box's planes, on the grid, anywhere, or not a number at all. */
                o[a] = u < 0.3 ? (rng_uniform(&rng) < 0.5 ? lo[a] : hi[a])
                       : u < 0.6 ? coords[(size_t)(rng_uniform(&rng) * nx)]
                                 : (float)(6.0 * rng_uniform(&rng) - 3.0);
                /* Towards the box's middle (through it, where the middle is finite), a special
                 * component, or anywhere. */
                const double v = rng_uniform(&rng);
                d[a] = v < 0.5   ? 0.5f * lo[a] + 0.5f * hi[a] - o[a]
                       : v < 0.75 ? comps[(size_t)(rng_uniform(&rng) * nc)]
                                  : (float)(2.0 * rng_uniform(&rng) - 1.0);
            }
            rays[l] = (vkrt_ray){ .origin = { o[0], o[1], o[2] }, .dir = { d[0], d[1], d[2] },
                                  .tmin = rng_uniform(&rng) < 0.5 ? 0.0f : spans[(size_t)(rng_uniform(&rng) * ns)],
                                  .tmax = rng_uniform(&rng) < 0.3 ? 0.0f : spans[(size_t)(rng_uniform(&rng) * ns)] };
        }
        unsigned mask = ray_cull_test4(rays, &box), ref = 0;
        for (unsigned l = 0; l < 4; l++) ref |= (unsigned)cpu_trace_ray_enters_box(&rays[l], &box) << l;
        if (mask != ref && differ++ < 3)
            fprintf(stderr, "  differ: box (%g %g %g)-(%g %g %g): masks %x %x\n", lo[0], lo[1], lo[2], hi[0], hi[1],
                    hi[2], mask, ref);
        tests += 4;
        entered += (size_t)__builtin_popcount(ref);
    }
    fprintf(stderr, "  %zu rays, %zu enter the box, %zu groups of four differ\n", tests, entered, differ);
    CHECK_EQ_U64(differ, 0);
    CHECK(entered > tests / 10 && entered < tests - tests / 10);
}

/* ray_cull_compact keeps the rays that may enter the box in their order with their positions,
 * writes a miss for each ray it read and culled and nothing past what it read, and stops at
 * the first ray it has no room for, so that the next chunk starts there. */
static void ray_cull_compact_keeps_order_and_stops_where_the_room_ends(void)
{
    const vkrt_gpu_node box = { .bmin = { -0.5f, -0.5f, -0.5f }, .bmax = { 0.5f, 0.5f, 0.5f } };
    enum { N = 103 }; /* not a multiple of four: the last group is short */
    vkrt_ray rays[N];
    bool enters[N];
    size_t entering = 0;
    for (size_t i = 0; i < N; i++) {
        /* From z = 2 towards -z at x = 0.2 * (i % 13 - 6): through the box for |x| <= 0.5. */
        const float x = 0.2f * (float)((int)(i % 13) - 6);
        rays[i] = (vkrt_ray){ .origin = { x, 0.0f, 2.0f }, .dir = { 0.0f, 0.0f, -1.0f } };
        if (i % 17 == 5) rays[i].origin[1] = NAN; /* must miss */
        enters[i] = cpu_trace_ray_enters_box(&rays[i], &box);
        entering += enters[i];
    }
    CHECK(entering > N / 3 && entering < N - N / 4);
    const vkrt_hit untouched = { .t = 42.0f, .prim_id = 7, .u = 0.25f, .v = 0.5f };
    for (size_t room = 1; room <= N + 1; room += 6) {
        vkrt_ray out[N];
        uint32_t index[N];
        vkrt_hit hits[N];
        for (size_t i = 0; i < N; i++) hits[i] = untouched;
        size_t read = 0, first = 0, chunks = 0, total = 0;
        bool order_ok = true, hits_ok = true;
        /* Chunk after chunk, as gpu_trace_rays reads them. */
        while (first < N) {
            size_t copied = ray_cull_compact(rays + first, N - first, &box, room, out, index, hits + first, &read);
            CHECK(copied <= room && read > 0);
            for (size_t k = 0; k < copied; k++) {
                size_t i = first + index[k];
                order_ok = order_ok && i < first + read && enters[i] && memcmp(&out[k], &rays[i], sizeof out[k]) == 0 &&
                           (k == 0 || index[k] > index[k - 1]);
            }
            /* The read rays that enter are exactly the copied ones, and the read ones that do
             * not hold misses; a chunk that stopped for room stopped at an entering ray. */
            size_t entering_read = 0;
            for (size_t i = first; i < first + read; i++) {
                entering_read += enters[i];
                hits_ok = hits_ok && (enters[i] ? memcmp(&hits[i], &untouched, sizeof untouched) == 0
                                                : hits[i].t == -1.0f && hits[i].prim_id == VKRT_NO_HIT &&
                                                      hits[i].u == 0.0f && hits[i].v == 0.0f);
            }
            CHECK_EQ_U64(entering_read, copied);
            if (first + read < N) CHECK(copied == room && enters[first + read]);
            for (size_t i = first + read; i < N; i++) hits_ok = hits_ok && memcmp(&hits[i], &untouched, sizeof untouched) == 0;
            total += copied;
            first += read;
            chunks++;
        }
        CHECK_MSG(order_ok, "room %zu: copied rays out of order or wrong", room);
        CHECK_MSG(hits_ok, "room %zu: misses written wrong", room);
        CHECK_EQ_U64(total, entering);
        CHECK(chunks <= entering / room + 1);
    }
    /* An empty scene: nothing to enter, every ray a miss. */
    vkrt_ray out[N];
    uint32_t index[N];
    vkrt_hit hits[N];
    size_t read = 0;
    CHECK_EQ_U64(ray_cull_compact(rays, N, NULL, N, out, index, hits, &read), 0);
    CHECK_EQ_U64(read, N);
    for (size_t i = 0; i < N; i++) CHECK(hits[i].prim_id == VKRT_NO_HIT && hits[i].t == -1.0f);
}

/* The SIMD four-triangle watertight test equals intersect_triangle_watertight_f, answer and
 * t, u, v bit for bit, where its special cases live: corners on a small integer grid and rays
 * from grid points along grid directions and at corners and edge midpoints (edge values of
 * exactly 0, the double re-evaluation), degenerate triangles (det = 0), rays in a triangle's
 * plane, +-0 direction components and hits at tmin and tmax. */
static void watertight4_equals_scalar_watertight_on_hostile_triangles(void)
{
    test_rng rng = { 4077 };
    vkrt_gpu_tri tri[4];
    size_t tests = 0, hits = 0, differ = 0;
    for (int iter = 0; iter < 100000; iter++) {
        for (int l = 0; l < 4; l++) {
            float p[9];
            for (int k = 0; k < 9; k++) p[k] = (float)(int)(5.0 * rng_uniform(&rng)) - 2.0f;
            double kind = rng_uniform(&rng);
            if (kind < 0.1) memcpy(p + 6, p + 3, 3 * sizeof *p); /* two corners equal */
            else if (kind < 0.2)
                for (int k = 0; k < 3; k++) p[6 + k] = 2.0f * p[3 + k] - p[k]; /* collinear */
            else if (kind < 0.3)
                for (int k = 0; k < 9; k++) p[k] += (float)(rng_uniform(&rng) - 0.5); /* off the grid */
            tri[l] = (vkrt_gpu_tri){ .v0 = { p[0], p[1], p[2] }, .prim_id = (uint32_t)l, .v1 = { p[3], p[4], p[5] },
                                     .v2 = { p[6], p[7], p[8] } };
        }
        const vkrt_gpu_tri *const tris[4] = { &tri[0], &tri[1], &tri[2], &tri[3] };
        vkrt_gpu_ray ray = { .tmin = 0.0f, .tmax = INFINITY };
        float o[3], target[3];
        for (int k = 0; k < 3; k++) o[k] = (float)(int)(7.0 * rng_uniform(&rng)) - 3.0f;
        const vkrt_gpu_tri *aim = &tri[(int)(4.0 * rng_uniform(&rng))];
        const float corner[3][3] = { { aim->v0.x, aim->v0.y, aim->v0.z }, { aim->v1.x, aim->v1.y, aim->v1.z },
                                     { aim->v2.x, aim->v2.y, aim->v2.z } };
        double how = rng_uniform(&rng);
        for (int k = 0; k < 3; k++) {
            if (how < 0.3) target[k] = corner[0][k];                                   /* a corner */
            else if (how < 0.6) target[k] = 0.5f * (corner[0][k] + corner[1][k]);     /* an edge midpoint */
            else if (how < 0.8) target[k] = (corner[0][k] + corner[1][k] + corner[2][k]) / 3.0f;
            else target[k] = o[k] + (float)(int)(3.0 * rng_uniform(&rng)) - 1.0f;      /* a grid direction */
        }
        ray.origin = (vkrt_float3){ o[0], o[1], o[2] };
        ray.dir = (vkrt_float3){ target[0] - o[0], target[1] - o[1], target[2] - o[2] };
        if (ray.dir.x == 0 && ray.dir.y == 0 && ray.dir.z == 0) ray.dir.z = -0.0f, ray.dir.x = 1.0f;
        if (iter % 7 == 0) ray.tmin = 1.0f; /* the target at t = 1 sits on the boundary */
        if (iter % 11 == 0) ray.tmax = 1.0f;
        float t[2][4], u[2][4], v[2][4];
        unsigned m_simd = cpu_trace_watertight4_test(&ray, tris, true, t[0], u[0], v[0]);
        unsigned m_scalar = cpu_trace_watertight4_test(&ray, tris, false, t[1], u[1], v[1]);
        bool same = m_simd == m_scalar;
        for (int l = 0; l < 4; l++)
            if (m_scalar & (1u << l)) same = same && same_float(t[0][l], t[1][l]) && same_float(u[0][l], u[1][l]) &&
                                              same_float(v[0][l], v[1][l]);
        if (!same && differ++ < 3)
            fprintf(stderr, "  differ: o (%g %g %g) d (%g %g %g): masks %x %x\n", o[0], o[1], o[2], ray.dir.x, ray.dir.y,
                    ray.dir.z, m_simd, m_scalar);
        tests += 4;
        for (int l = 0; l < 4; l++) hits += (m_scalar >> l) & 1u;
    }
    fprintf(stderr, "  %zu triangle tests, %zu hit, %zu groups of four differ\n", tests, hits, differ);
    CHECK_EQ_U64(differ, 0);
    CHECK(hits > tests / 20);
}

/* Rays for the identity test, in a new array: the camera rays of three views (one from inside
 * the model's box), rays from random points of the box in random directions, and from each
 * camera hit four cosine-distributed rays about the facing geometric normal from
 * vkrt_ray_offset's origin, half up to 0.5 (the ao mode's and the bench's) and half unbounded. */
static vkrt_ray *identity_rays(const cpu_trace_scene *binary, size_t *out_count)
{
    enum { W = 96, H = 96, VIEWS = 3, RANDOM = 20000, AO_PER_HIT = 4 };
    const vkrt_camera views[VIEWS] = { { .fov_y_degrees = 0.0f }, { .eye = { 0.8f, 0.4f, 1.2f } },
                                       { .eye = { 0.05f, 0.1f, 0.3f }, .target = { -0.2f, 0.0f, -0.4f }, .fov_y_degrees = 100 } };
    size_t cap = (size_t)VIEWS * W * H * (1 + AO_PER_HIT) + RANDOM, n = 0;
    vkrt_ray *rays = calloc(cap, sizeof *rays);
    if (!rays) abort();
    for (int v = 0; v < VIEWS; v++) CHECK(vkrt_camera_rays(cpu, &views[v], W, H, rays + n + (size_t)v * W * H, (size_t)W * H) == VKRT_OK);
    n += (size_t)VIEWS * W * H;
    size_t primary = n;
    vkrt_ray *random = random_rays_in_box(RANDOM, 77);
    memcpy(rays + n, random, RANDOM * sizeof *rays);
    free(random);
    n += RANDOM;
    test_rng rng = { 5 };
    for (size_t i = 0; i < primary; i++) {
        vkrt_gpu_ray g;
        vkrt_gpu_hit h;
        trace_counts ignored = { 0 };
        memcpy(&g, &rays[i], sizeof g);
        if (!cpu_trace_one(binary, VKRT_TRAVERSAL_BVH, VKRT_INTERSECTOR_WATERTIGHT, &g, false, &h, &ignored)) continue;
        const vkrt_gpu_tri *t = &binary->tris[h.tri];
        float w = 1.0f - h.u - h.v, p[3], nrm[3] = { t->face_n.x, t->face_n.y, t->face_n.z };
        const float v0[3] = { t->v0.x, t->v0.y, t->v0.z }, v1[3] = { t->v1.x, t->v1.y, t->v1.z }, v2[3] = { t->v2.x, t->v2.y, t->v2.z };
        for (int a = 0; a < 3; a++) p[a] = v0[a] * w + v1[a] * h.u + v2[a] * h.v;
        if (nrm[0] * g.dir.x + nrm[1] * g.dir.y + nrm[2] * g.dir.z > 0.0f)
            for (int a = 0; a < 3; a++) nrm[a] = -nrm[a];
        float origin[3];
        vkrt_ray_offset(p, nrm, origin);
        for (int k = 0; k < AO_PER_HIT; k++) {
            double d[3];
            rng_unit_vector(&rng, d);
            double dn = d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2];
            for (int a = 0; a < 3; a++) d[a] += nrm[a] - (dn < 0 ? 2.0 * dn * nrm[a] : 0.0); /* cosine-like, outward */
            vkrt_ray *r = &rays[n++];
            *r = (vkrt_ray){ .tmax = k % 2 ? 0.0f : 0.5f };
            memcpy(r->origin, origin, sizeof origin);
            for (int a = 0; a < 3; a++) r->dir[a] = (float)d[a];
        }
    }
    *out_count = n;
    return rays;
}

/* A scene's CPU views: through its binary BVH alone, and with its 4-wide BVH as well. */
static void scene_views(const vkrt_scene *s, cpu_trace_scene *out_binary, cpu_trace_scene *out_wide)
{
    *out_binary = (cpu_trace_scene){ .nodes = s->bvh.nodes, .node_count = s->bvh.node_count, .tris = s->tris,
                                     .tri_count = s->bvh.tri_count };
    *out_wide = *out_binary;
    out_wide->wide = &s->wide;
}

/* The default camera for a w x h image, in float and in double. */
static void default_camera(uint32_t w, uint32_t h, vkrt_gpu_push *out_cam, camera_basis *out_cam_d)
{
    CHECK(camera_setup(&c, &(vkrt_camera){ 0 }, w, h, out_cam) == VKRT_OK);
    CHECK(camera_setup_double(&c, &(vkrt_camera){ 0 }, w, h, out_cam_d) == VKRT_OK);
}

/* A model's scene, its two CPU views, its identity rays and two hit arrays for them, and the
 * default camera with two images of FIXTURE_W x FIXTURE_H, for two ways of tracing to compare. */
enum { FIXTURE_W = 64, FIXTURE_H = 48 };
typedef struct ray_fixture {
    vkrt_scene *scene;
    cpu_trace_scene binary, wide;
    vkrt_ray *rays;
    size_t n;
    vkrt_hit *a, *b;
    vkrt_gpu_push cam;
    camera_basis cam_d;
    float *image_a, *image_b;
} ray_fixture;

static bool ray_fixture_open(const char *file, ray_fixture *out)
{
    *out = (ray_fixture){ .scene = model_scene(file) };
    if (!out->scene) return false;
    scene_views(out->scene, &out->binary, &out->wide);
    out->rays = identity_rays(&out->binary, &out->n);
    out->a = calloc(out->n, sizeof *out->a);
    out->b = calloc(out->n, sizeof *out->b);
    default_camera(FIXTURE_W, FIXTURE_H, &out->cam, &out->cam_d);
    out->image_a = malloc((size_t)FIXTURE_W * FIXTURE_H * 4 * sizeof(float));
    out->image_b = malloc((size_t)FIXTURE_W * FIXTURE_H * 4 * sizeof(float));
    if (!out->a || !out->b || !out->image_a || !out->image_b) abort();
    return true;
}

static void ray_fixture_close(ray_fixture *f)
{
    free(f->a);
    free(f->b);
    free(f->image_a);
    free(f->image_b);
    free(f->rays);
    vkrt_scene_destroy(f->scene);
}

/* On real meshes, every ray of identity_rays through the binary and the 4-wide traversal, with
 * both intersectors: closest hits identical (t, u, v and triangle, so prim_id, bit for bit),
 * one ray at a time and through cpu_trace_rays (with the refined distance); any-hit rays hit
 * exactly where the closest-hit ones do, no nearer. Renders without counters are the same
 * images; the heat map and the counters come from the binary traversal either way. */
static void bvh4_and_binary_traversal_give_identical_hits(void)
{
    const char *files[2] = { "bunny.obj", "dragon_11k.obj" };
    for (int f = 0; f < 2; f++) {
        ray_fixture fx;
        if (!ray_fixture_open(files[f], &fx)) continue;
        CHECK_MSG(fx.scene->wide.nodes != NULL, "%s: the CPU scene has no 4-wide BVH", files[f]);
        const cpu_trace_scene binary = fx.binary, wide = fx.wide;
        const size_t n = fx.n;
        const vkrt_ray *rays = fx.rays;
        vkrt_hit *hb = fx.a, *hw = fx.b;
        for (int isect = VKRT_INTERSECTOR_WATERTIGHT; isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
            size_t hits = 0, differ = 0, any_differ = 0;
            for (size_t i = 0; i < n; i++) {
                vkrt_gpu_ray g;
                memcpy(&g, &rays[i], sizeof g);
                vkrt_gpu_hit a, b, any_a, any_b;
                trace_counts counts = { 0 }, wide_counts = { 0 };
                bool hit_a = cpu_trace_one(&binary, VKRT_TRAVERSAL_BVH, (vkrt_intersector)isect, &g, false, &a, &counts);
                bool hit_b = cpu_trace_one(&wide, VKRT_TRAVERSAL_BVH, (vkrt_intersector)isect, &g, false, &b, &wide_counts);
                bool any_hit_a = cpu_trace_one(&binary, VKRT_TRAVERSAL_BVH, (vkrt_intersector)isect, &g, true, &any_a, &counts);
                bool any_hit_b = cpu_trace_one(&wide, VKRT_TRAVERSAL_BVH, (vkrt_intersector)isect, &g, true, &any_b, &wide_counts);
                hits += hit_a;
                if (hit_a != hit_b || memcmp(&a, &b, sizeof a) != 0) {
                    if (differ++ < 3)
                        fprintf(stderr, "  ray %zu: binary tri %u t %.9g, 4-wide tri %u t %.9g\n", i, a.tri, a.t, b.tri, b.t);
                }
                any_differ += any_hit_a != hit_a || any_hit_b != hit_a || (any_hit_b && !(any_b.t >= a.t));
                CHECK(wide_counts.nodes == 0 && wide_counts.tris == 0);
            }
            fprintf(stderr, "  %s isect %d: %zu rays (%zu hit): %zu closest hits differ, %zu any-hit answers\n",
                    files[f], isect, n, hits, differ, any_differ);
            CHECK_EQ_U64(differ, 0);
            CHECK_EQ_U64(any_differ, 0);
            CHECK(hits > n / 10);
            for (int any = 0; any < 2; any++) {
                cpu_trace_rays_params p = { .traversal = VKRT_TRAVERSAL_BVH, .any_hit = any,
                                            .intersector = (vkrt_intersector)isect, .threads = 2 };
                CHECK(cpu_trace_rays(&c, &binary, &p, rays, n, hb) == VKRT_OK);
                CHECK(cpu_trace_rays(&c, &wide, &p, rays, n, hw) == VKRT_OK);
                if (!any) {
                    CHECK_MSG(memcmp(hb, hw, n * sizeof *hb) == 0, "%s isect %d: cpu_trace_rays differ", files[f], isect);
                    continue;
                }
                size_t disagree = 0;
                for (size_t i = 0; i < n; i++) disagree += (hb[i].prim_id == VKRT_NO_HIT) != (hw[i].prim_id == VKRT_NO_HIT);
                CHECK_EQ_U64(disagree, 0);
            }
        }
        /* Renders: the same images in the modes that read hits; the counted ones equal too. */
        const uint32_t w = FIXTURE_W, h = FIXTURE_H;
        const vkrt_gpu_push cam = fx.cam;
        const camera_basis cam_d = fx.cam_d;
        float *ib = fx.image_a, *iw = fx.image_b;
        for (vkrt_mode m = VKRT_MODE_NORMAL; m <= VKRT_MODE_ID; m++) {
            for (int counted = 0; counted < 2; counted++) {
                cpu_trace_params p = { .camera = cam, .mode = m, .traversal = VKRT_TRAVERSAL_BVH, .heat = VKRT_HEAT_NODES,
                                       .camera_d = cam_d, .counters = counted, .threads = 2 };
                trace_counts cb, cw;
                CHECK(cpu_trace_render(&c, &binary, &p, ib, &cb) == VKRT_OK);
                CHECK(cpu_trace_render(&c, &wide, &p, iw, &cw) == VKRT_OK);
                CHECK_MSG(memcmp(ib, iw, (size_t)w * h * 4 * sizeof *ib) == 0, "%s mode %d: images differ", files[f], (int)m);
                CHECK(cb.nodes == cw.nodes && cb.leaves == cw.leaves && cb.tris == cw.tris);
                if (counted) CHECK(cw.nodes > 0 && cw.tris > 0);
            }
        }
        ray_fixture_close(&fx);
    }
}

/* CPU_TRACE_PACKET_LANES coherent rays from the buffer go through the 4-wide BVH as a packet
 * (packet8_load: the rays' reciprocals, watertight axes and shears divided eight lanes at a
 * time, float8 one AVX register in the x86-64-v3 build, two halves in the baseline); the
 * binary BVH traces them one by one (ray_from_buffer_f). Both must answer bit for bit alike
 * where the setup has its cases: directions along each axis with either sign (kz and the swap
 * of kx and ky), components of +-0 and denormals (parallel lanes, infinite reciprocals), ties
 * between the largest components, every kind of tmin and tmax, and groups with a ray that must
 * miss (which leave the packet path). */
static void packets_answer_as_single_rays_on_axis_and_edge_directions(void)
{
    const float tiny[] = { 0.0f, -0.0f, 1e-3f, -1e-3f, 2e-2f, -2e-2f, 1e-40f, -1e-40f };
    const float spans[][2] = { { 0.0f, 0.0f }, { 0.0f, 0.5f }, { 0.2f, 0.0f }, { 0.0f, 1.4f }, { 1.0f, 2.0f } };
    const size_t nt = sizeof tiny / sizeof tiny[0], ns = sizeof spans / sizeof spans[0];
    const char *files[2] = { "bunny.obj", "dragon_11k.obj" };
    for (int f = 0; f < 2; f++) {
        vkrt_scene *model = model_scene(files[f]);
        if (!model) continue;
        cpu_trace_scene binary, wide;
        scene_views(model, &binary, &wide);
        enum { GROUPS = 3000, TAIL = 64, L = CPU_TRACE_PACKET_LANES };
        const size_t n = (size_t)(GROUPS + TAIL) * L;
        vkrt_ray *rays = calloc(n, sizeof *rays);
        vkrt_hit *hb = calloc(n, sizeof *hb), *hw = calloc(n, sizeof *hw);
        if (!rays || !hb || !hw) abort();
        test_rng rng = { 31 + (uint64_t)f };
        size_t zero_lanes = 0, tie_rays = 0;
        for (size_t g = 0; g < GROUPS + TAIL; g++) {
            /* From outside the unit box along axis a (either side), towards the scene, or
             * along a diagonal where two components tie. */
            const int a = (int)(g % 3), side = (int)(g / 3 % 2) ? 1 : -1, diagonal = g % 7 == 0;
            float o[3] = { 0.0f, 0.0f, 0.0f }, base[3] = { 0.0f, 0.0f, 0.0f };
            o[a] = 1.5f * (float)side;
            o[(a + 1) % 3] = (float)(0.3 * (rng_uniform(&rng) - 0.5));
            base[a] = -(float)side;
            if (diagonal) {
                /* Through the middle of the scene at 45 degrees: |dir| ties on axes a and a + 1. */
                base[(a + 1) % 3] = (g / 14 % 2) ? 1.0f : -1.0f;
                o[a] = 0.8f * (float)side;
                o[(a + 1) % 3] += -0.8f * base[(a + 1) % 3];
            }
            const float *span = spans[g % ns];
            for (int l = 0; l < L; l++) {
                vkrt_ray *r = &rays[g * L + (size_t)l];
                memcpy(r->origin, o, sizeof o);
                for (int k = 0; k < 3; k++) r->dir[k] = base[k];
                /* Lane offsets small enough for one packet (PACKET8_MIN_COSINE). */
                const int b = (a + 2) % 3, c2 = diagonal ? a : (a + 1) % 3;
                r->dir[b] += tiny[(size_t)(rng_uniform(&rng) * (double)nt) % nt];
                if (!diagonal) r->dir[c2] += tiny[(size_t)(rng_uniform(&rng) * (double)nt) % nt];
                r->tmin = span[0];
                r->tmax = span[1];
                for (int k = 0; k < 3; k++) zero_lanes += r->dir[k] == 0.0f;
                tie_rays += diagonal;
            }
            if (g >= GROUPS) {
                /* The tail: one ray of the group must miss, so the group leaves the packet path. */
                vkrt_ray *r = &rays[g * L + (size_t)(g % L)];
                switch (g % 3) {
                case 0: r->dir[0] = NAN; break;
                case 1: r->dir[0] = r->dir[1] = r->dir[2] = 0.0f; break;
                default: r->origin[1] = INFINITY; break;
                }
            }
        }
        for (int isect = VKRT_INTERSECTOR_WATERTIGHT; isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
            for (int any = 0; any < 2; any++) {
                cpu_trace_rays_params p = { .traversal = VKRT_TRAVERSAL_BVH, .any_hit = any,
                                            .intersector = (vkrt_intersector)isect, .threads = 2 };
                CHECK(cpu_trace_rays(&c, &binary, &p, rays, n, hb) == VKRT_OK);
                CHECK(cpu_trace_rays(&c, &wide, &p, rays, n, hw) == VKRT_OK);
                size_t hits = 0, tie_hits = 0, differ = 0;
                for (size_t i = 0; i < n; i++) {
                    hits += hb[i].prim_id != VKRT_NO_HIT;
                    tie_hits += i / L % 7 == 0 && hb[i].prim_id != VKRT_NO_HIT;
                    const bool same = any ? (hb[i].prim_id == VKRT_NO_HIT) == (hw[i].prim_id == VKRT_NO_HIT)
                                          : memcmp(&hb[i], &hw[i], sizeof hb[i]) == 0;
                    if (!same && differ++ < 3)
                        fprintf(stderr, "  ray %zu: single tri %u t %.9g, packet tri %u t %.9g\n", i, hb[i].prim_id,
                                hb[i].t, hw[i].prim_id, hw[i].t);
                }
                fprintf(stderr, "  %s isect %d any %d: %zu rays, %zu hit (%zu of %zu with tied components), %zu zero components, %zu differ\n",
                        files[f], isect, any, n, hits, tie_hits, tie_rays, zero_lanes, differ);
                CHECK_EQ_U64(differ, 0);
                CHECK(hits > n / 4 && hits < n);
                CHECK(tie_hits > tie_rays / 4);
                CHECK(zero_lanes > n / 4);
            }
        }
        free(rays);
        free(hb);
        free(hw);
        vkrt_scene_destroy(model);
    }
}

/* The x86-64-v3 build of the CPU tracer (cpu_trace_isa) answers as the baseline build bit for
 * bit: vkrt_trace_rays' hits through the 4-wide and the binary BVH, closest and any hit, float
 * and double, both intersectors, and the renders of the modes that read hits with their
 * counters. The same source compiled for AVX2 must round every operation as the baseline does
 * (no contraction into FMA), or the CPU's images would stop equalling the GPU's. On a host
 * without x86-64-v3 both runs are the baseline, which the test says. */
static void x86_64_v3_build_answers_as_the_baseline_bit_for_bit(void)
{
    const cpu_trace_code code = cpu_trace_isa(&c);
    fprintf(stderr, "  this host runs the %s code\n", cpu_trace_isa_name(code));
    c.test_cpu_baseline = true;
    CHECK(cpu_trace_isa(&c) == CPU_TRACE_BASELINE);
    c.test_cpu_baseline = false;
    const char *files[2] = { "bunny.obj", "dragon_11k.obj" };
    for (int f = 0; f < 2; f++) {
        ray_fixture fx;
        if (!ray_fixture_open(files[f], &fx)) continue;
        const cpu_trace_scene binary = fx.binary, wide = fx.wide;
        const size_t n = fx.n;
        const vkrt_ray *rays = fx.rays;
        vkrt_hit *hb = fx.a, *hv = fx.b;
        size_t calls = 0, differ = 0;
        for (int w = 0; w < 2; w++) {
            for (int isect = VKRT_INTERSECTOR_WATERTIGHT; isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
                for (int prec = VKRT_PRECISION_FLOAT; prec <= VKRT_PRECISION_DOUBLE; prec++) {
                    for (int any = 0; any < 2; any++) {
                        cpu_trace_rays_params p = { .traversal = VKRT_TRAVERSAL_BVH, .any_hit = any,
                                                    .intersector = (vkrt_intersector)isect,
                                                    .precision = (vkrt_precision)prec, .threads = 2 };
                        c.test_cpu_baseline = true;
                        CHECK(cpu_trace_rays(&c, w ? &wide : &binary, &p, rays, n, hb) == VKRT_OK);
                        c.test_cpu_baseline = false;
                        CHECK(cpu_trace_rays(&c, w ? &wide : &binary, &p, rays, n, hv) == VKRT_OK);
                        calls++;
                        if (memcmp(hb, hv, n * sizeof *hb) != 0 && differ++ < 3)
                            fprintf(stderr, "  %s wide %d isect %d precision %d any %d: hits differ\n", files[f], w,
                                    isect, prec, any);
                    }
                }
            }
        }
        const uint32_t w = FIXTURE_W, h = FIXTURE_H;
        const vkrt_gpu_push cam = fx.cam;
        const camera_basis cam_d = fx.cam_d;
        float *ib = fx.image_a, *iv = fx.image_b;
        for (int wide_bvh = 0; wide_bvh < 2; wide_bvh++) {
            for (vkrt_mode m = VKRT_MODE_NORMAL; m <= VKRT_MODE_ID; m++) {
                for (int counted = 0; counted < 2; counted++) {
                    cpu_trace_params p = { .camera = cam, .mode = m, .traversal = VKRT_TRAVERSAL_BVH,
                                           .heat = VKRT_HEAT_NODES, .camera_d = cam_d, .counters = counted,
                                           .threads = 2 };
                    trace_counts cb, cv;
                    c.test_cpu_baseline = true;
                    CHECK(cpu_trace_render(&c, wide_bvh ? &wide : &binary, &p, ib, &cb) == VKRT_OK);
                    c.test_cpu_baseline = false;
                    CHECK(cpu_trace_render(&c, wide_bvh ? &wide : &binary, &p, iv, &cv) == VKRT_OK);
                    calls++;
                    if ((memcmp(ib, iv, (size_t)w * h * 4 * sizeof *ib) != 0 || cb.nodes != cv.nodes ||
                         cb.tris != cv.tris) &&
                        differ++ < 3)
                        fprintf(stderr, "  %s wide %d mode %d counted %d: images differ\n", files[f], wide_bvh, (int)m,
                                counted);
                }
            }
        }
        fprintf(stderr, "  %s: %zu calls (%zu rays each or 64x48 images), %zu differ\n", files[f], calls, n, differ);
        CHECK_EQ_U64(differ, 0);
        ray_fixture_close(&fx);
    }
}

int main(void)
{
    core_init(&c, NULL, NULL, NULL);
    if (vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU }, &cpu) != VKRT_OK) return 1;
    RUN(camera_defaults_frame_the_unit_scene);
    RUN(camera_rejects_bad_input);
    RUN(octahedral_normals_round_trip_within_1e4);
    RUN(packing_follows_bvh_order_with_face_normals);
    RUN(single_triangle_gives_analytic_depth_and_exact_ids);
    RUN(cube_face_gives_analytic_depth);
    RUN(normal_mode_on_a_plane_gives_its_normal);
    RUN(miss_pixels_follow_the_mode_conventions);
    RUN(bvh_and_naive_give_identical_id_and_depth_images);
    RUN(midpoint_and_sah_give_identical_images_in_every_mode);
    RUN(heatmap_counts_are_consistent);
    RUN(thread_counts_give_identical_images);
    RUN(thread_start_failure_gives_the_same_image);
    RUN(progress_runs_on_the_caller_and_cancel_returns_cancelled);
    RUN(cpu_trace_rays_follow_the_documented_rules);
    RUN(cpu_float_watertight_never_misses_shared_edges_and_vertices);
    RUN(cpu_double_watertight_never_misses_shared_edges_and_vertices);
    RUN(cpu_trace_rays_bvh_naive_and_precisions_agree);
    RUN(bvh4_box_test_simd_equals_binary_box_test_on_hostile_inputs);
    RUN(ray_cull_test4_equals_the_reference_root_test_on_hostile_rays);
    RUN(ray_cull_compact_keeps_order_and_stops_where_the_room_ends);
    RUN(watertight4_equals_scalar_watertight_on_hostile_triangles);
    RUN(bvh4_and_binary_traversal_give_identical_hits);
    RUN(packets_answer_as_single_rays_on_axis_and_edge_directions);
    RUN(x86_64_v3_build_answers_as_the_baseline_bit_for_bit);
    RUN(double_reference_and_float_agree_on_camera_renders);
    RUN(eye_inside_a_closed_mesh_always_hits);
    RUN(cpu_grazing_hit_distances_are_exact);
    RUN(texture_halves_round_trip_and_wraps_follow_their_modes);
    RUN(cpu_secondary_rays_never_rehit_their_own_triangle);
    RUN(cpu_camera_rays_hit_what_the_render_shows_on_exported_triangles);
    vkrt_context_destroy(cpu);
    return check_exit();
}
