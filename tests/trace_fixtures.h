/* Ray tests that run on any backend through vkrt.h, shared by test_cpu_trace.c (CPU float and
 * double) and test_gpu.c (GPU): a closed icosphere built in memory, rays aimed exactly at its
 * shared edges and vertices (watertightness), the documented miss rules of vkrt_trace_rays,
 * +0/-0 direction components, secondary rays spawned with vkrt_ray_offset() that must never
 * re-hit their own triangle, and the camera rays and triangles the API hands to other tracers.
 * Include after check.h. */
#ifndef VKRT_TRACE_FIXTURES_H
#define VKRT_TRACE_FIXTURES_H

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "check.h"
#include "vkrt.h"

/* ---- random numbers (splitmix64: reproducible on every platform) ---- */

typedef struct test_rng {
    uint64_t state;
} test_rng;

static inline double rng_uniform(test_rng *r)
{
    uint64_t z = (r->state += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return (double)(z >> 11) / 9007199254740992.0;
}

static inline void rng_unit_vector(test_rng *r, double out[3])
{
    double z = 2.0 * rng_uniform(r) - 1.0, phi = 6.283185307179586 * rng_uniform(r);
    double s = sqrt(fmax(0.0, 1.0 - z * z));
    out[0] = s * cos(phi), out[1] = s * sin(phi), out[2] = z;
}

/* Rays from random points of the box [-0.6, 0.6]^3 (a normalised scene and its margin) in
 * random directions, with lengths from 0.01 to 100 (t is in units of |dir|). */
static inline vkrt_ray *random_rays_in_box(size_t n, uint64_t seed)
{
    vkrt_ray *rays = calloc(n, sizeof *rays);
    if (!rays) abort();
    test_rng rng = { seed };
    for (size_t i = 0; i < n; i++) {
        double o[3], d[3];
        rng_unit_vector(&rng, d);
        for (int a = 0; a < 3; a++) o[a] = 1.2 * (rng_uniform(&rng) - 0.5);
        double len = pow(10.0, 4.0 * rng_uniform(&rng) - 2.0);
        rays[i] = (vkrt_ray){ .origin = { (float)o[0], (float)o[1], (float)o[2] },
                              .dir = { (float)(d[0] * len), (float)(d[1] * len), (float)(d[2] * len) } };
    }
    return rays;
}

/* ---- a closed mesh ---- */

typedef struct closed_mesh {
    float *positions;      /* 3 per vertex */
    uint32_t vertex_count;
    uint32_t *indices;     /* 3 per triangle, outward winding */
    uint32_t index_count;
    uint32_t *edges;       /* 2 per shared edge (each edge of a closed mesh has two triangles) */
    uint32_t edge_count;
    double centre[3], radius;
} closed_mesh;

static inline uint32_t ico_edge_vertex(closed_mesh *m, double (*v)[3], uint32_t *cap, uint32_t a, uint32_t b)
{
    uint32_t lo = a < b ? a : b, hi = a < b ? b : a;
    for (uint32_t e = 0; e < m->edge_count; e++)
        if (m->edges[e * 3] == lo && m->edges[e * 3 + 1] == hi) return m->edges[e * 3 + 2];
    uint32_t k = m->vertex_count++;
    if (k >= *cap) abort();
    double l = 0;
    for (int i = 0; i < 3; i++) l += (v[a][i] + v[b][i]) * (v[a][i] + v[b][i]);
    for (int i = 0; i < 3; i++) v[k][i] = (v[a][i] + v[b][i]) / sqrt(l);
    m->edges[m->edge_count * 3] = lo, m->edges[m->edge_count * 3 + 1] = hi, m->edges[m->edge_count * 3 + 2] = k;
    m->edge_count++;
    return k;
}

/* An icosahedron subdivided `levels` times onto the sphere of `radius` around `centre`: closed,
 * every vertex and edge shared. Corners are computed in double and rounded once. */
static inline closed_mesh icosphere(uint32_t levels, double radius, const double centre[3])
{
    static const double ico_v[12][3] = {
        { -1, 1.618033988749895, 0 }, { 1, 1.618033988749895, 0 }, { -1, -1.618033988749895, 0 },
        { 1, -1.618033988749895, 0 }, { 0, -1, 1.618033988749895 }, { 0, 1, 1.618033988749895 },
        { 0, -1, -1.618033988749895 }, { 0, 1, -1.618033988749895 }, { 1.618033988749895, 0, -1 },
        { 1.618033988749895, 0, 1 }, { -1.618033988749895, 0, -1 }, { -1.618033988749895, 0, 1 },
    };
    static const uint32_t ico_f[20][3] = {
        { 0, 11, 5 }, { 0, 5, 1 }, { 0, 1, 7 }, { 0, 7, 10 }, { 0, 10, 11 }, { 1, 5, 9 }, { 5, 11, 4 },
        { 11, 10, 2 }, { 10, 7, 6 }, { 7, 1, 8 }, { 3, 9, 4 }, { 3, 4, 2 }, { 3, 2, 6 }, { 3, 6, 8 },
        { 3, 8, 9 }, { 4, 9, 5 }, { 2, 4, 11 }, { 6, 2, 10 }, { 8, 6, 7 }, { 9, 8, 1 },
    };
    closed_mesh m = { 0 };
    uint32_t faces = 20;
    for (uint32_t l = 0; l < levels; l++) faces *= 4;
    uint32_t cap = faces / 2 + 2; /* Euler: V = F / 2 + 2 */
    double (*v)[3] = calloc(cap, sizeof *v);
    uint32_t *tri = calloc((size_t)faces * 3, sizeof *tri), *next = calloc((size_t)faces * 3, sizeof *next);
    m.edges = calloc((size_t)faces * 3 * 3 / 2 + 3, sizeof *m.edges);
    if (!v || !tri || !next || !m.edges) abort();
    for (uint32_t i = 0; i < 12; i++) {
        double l = sqrt(ico_v[i][0] * ico_v[i][0] + ico_v[i][1] * ico_v[i][1] + ico_v[i][2] * ico_v[i][2]);
        for (int a = 0; a < 3; a++) v[i][a] = ico_v[i][a] / l;
    }
    memcpy(tri, ico_f, sizeof ico_f);
    m.vertex_count = 12;
    for (uint32_t l = 0, n = 20; l < levels; l++, n *= 4) {
        m.edge_count = 0;
        for (uint32_t f = 0; f < n; f++) {
            uint32_t a = tri[f * 3], b = tri[f * 3 + 1], c = tri[f * 3 + 2];
            uint32_t ab = ico_edge_vertex(&m, v, &cap, a, b), bc = ico_edge_vertex(&m, v, &cap, b, c),
                     ca = ico_edge_vertex(&m, v, &cap, c, a);
            const uint32_t out[12] = { a, ab, ca, b, bc, ab, c, ca, bc, ab, bc, ca };
            memcpy(next + (size_t)f * 12, out, sizeof out);
        }
        memcpy(tri, next, (size_t)n * 12 * sizeof *tri);
    }
    /* The final edge list (two entries each: the midpoint slot is not needed any more). */
    m.edge_count = 0;
    for (uint32_t f = 0; f < faces; f++)
        for (int k = 0; k < 3; k++) {
            uint32_t a = tri[f * 3 + k], b = tri[f * 3 + (k + 1) % 3];
            if (a < b) {
                m.edges[m.edge_count * 2] = a;
                m.edges[m.edge_count * 2 + 1] = b;
                m.edge_count++;
            }
        }
    m.positions = calloc((size_t)m.vertex_count * 3, sizeof *m.positions);
    if (!m.positions) abort();
    for (uint32_t i = 0; i < m.vertex_count; i++)
        for (int a = 0; a < 3; a++) m.positions[i * 3 + a] = (float)(centre[a] + radius * v[i][a]);
    m.indices = tri;
    m.index_count = faces * 3;
    memcpy(m.centre, centre, sizeof m.centre);
    m.radius = radius;
    free(v);
    free(next);
    return m;
}

static inline void closed_mesh_free(closed_mesh *m)
{
    free(m->positions);
    free(m->indices);
    free(m->edges);
    memset(m, 0, sizeof *m);
}

static inline vkrt_scene *closed_mesh_scene(vkrt_context *ctx, const closed_mesh *m)
{
    vkrt_mesh_desc md = { .positions = m->positions, .vertex_count = m->vertex_count, .indices = m->indices,
                          .index_count = m->index_count };
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .meshes = &md, .mesh_count = 1, .keep_world_coordinates = true },
                                      &s);
    CHECK_MSG(r == VKRT_OK, "in-memory icosphere: %s", vkrt_context_last_error(ctx));
    return s;
}

static inline vkrt_hit *trace_all(vkrt_context *ctx, vkrt_scene *s, const vkrt_trace_desc *d, const vkrt_ray *rays,
                                  size_t n)
{
    vkrt_hit *hits = calloc(n ? n : 1, sizeof *hits);
    if (!hits) abort();
    vkrt_result r = vkrt_trace_rays(ctx, s, d, rays, n, hits);
    CHECK_MSG(r == VKRT_OK, "vkrt_trace_rays: %s", vkrt_context_last_error(ctx));
    /* Every hit names one of the scene's triangles; one that does not fails here and is made a
     * miss, so that the callers, which read the triangle a hit names, check on rather than
     * read past their arrays. */
    vkrt_scene_stats st;
    CHECK(vkrt_scene_stats_get(s, &st) == VKRT_OK);
    size_t unnamed = 0;
    for (size_t i = 0; i < n; i++) {
        if (hits[i].prim_id == VKRT_NO_HIT || hits[i].prim_id < st.triangles) continue;
        unnamed++;
        hits[i] = (vkrt_hit){ .t = -1.0f, .prim_id = VKRT_NO_HIT };
    }
    CHECK_MSG(unnamed == 0, "vkrt_trace_rays: %zu of %zu hits name no triangle of the scene's %llu", unnamed, n,
              (unsigned long long)st.triangles);
    return hits;
}

static inline vkrt_ray ray_towards(const double o[3], const float target[3])
{
    vkrt_ray r = { .origin = { (float)o[0], (float)o[1], (float)o[2] } };
    for (int a = 0; a < 3; a++) r.dir[a] = target[a] - r.origin[a];
    return r;
}

/* ---- watertightness ---- */

/* Rays from random points inside the sphere (and its centre) aimed exactly at every vertex and
 * at three points of every shared edge (the midpoint and the float points next to it): from
 * inside a closed mesh every ray must hit. Returns the misses; *out_rays the rays traced. */
static inline size_t watertight_misses(vkrt_context *ctx, vkrt_scene *s, const closed_mesh *m, vkrt_intersector isect,
                                       vkrt_precision precision, vkrt_traversal traversal, size_t *out_rays)
{
    enum { ORIGINS = 6, EDGE_POINTS = 3 };
    size_t n = (size_t)ORIGINS * (m->vertex_count + (size_t)m->edge_count * EDGE_POINTS);
    vkrt_ray *rays = calloc(n, sizeof *rays);
    if (!rays) abort();
    test_rng rng = { 12345 };
    size_t k = 0;
    for (int o = 0; o < ORIGINS; o++) {
        double origin[3], dir[3];
        rng_unit_vector(&rng, dir);
        double r = o == 0 ? 0.0 : m->radius * 0.9 * rng_uniform(&rng);
        for (int a = 0; a < 3; a++) origin[a] = m->centre[a] + r * dir[a];
        for (uint32_t v = 0; v < m->vertex_count; v++) rays[k++] = ray_towards(origin, m->positions + v * 3);
        for (uint32_t e = 0; e < m->edge_count; e++) {
            const float *a = m->positions + m->edges[e * 2] * 3, *b = m->positions + m->edges[e * 2 + 1] * 3;
            for (int p = 0; p < EDGE_POINTS; p++) {
                double f = p == 0 ? 0.5 : p == 1 ? 1.0 / 3.0 : 0.9;
                float target[3];
                for (int i = 0; i < 3; i++) target[i] = (float)(a[i] + f * ((double)b[i] - a[i]));
                rays[k++] = ray_towards(origin, target);
            }
        }
    }
    vkrt_trace_desc d = { .traversal = traversal, .intersector = isect, .precision = precision };
    vkrt_hit *hits = trace_all(ctx, s, &d, rays, n);
    size_t misses = 0;
    for (size_t i = 0; i < n; i++) misses += hits[i].prim_id == VKRT_NO_HIT;
    free(hits);
    free(rays);
    *out_rays = n;
    return misses;
}

/* Watertight never misses, at the origin and far from it; Möller-Trumbore's leaks are printed
 * (measured, not asserted). */
static inline void check_watertight_on(vkrt_context *ctx, vkrt_precision precision, const char *label)
{
    const double centres[3][3] = { { 0, 0, 0 }, { 1000.5, -2000.25, 500.125 }, { 0.1, 0.2, -0.3 } };
    const double radii[3] = { 1.0, 3.0, 1e-3 };
    for (int c = 0; c < 3; c++) {
        closed_mesh m = icosphere(3, radii[c], centres[c]);
        vkrt_scene *s = closed_mesh_scene(ctx, &m);
        for (vkrt_traversal t = VKRT_TRAVERSAL_BVH; s && t <= VKRT_TRAVERSAL_NAIVE; t++) {
            size_t rays, wt = watertight_misses(ctx, s, &m, VKRT_INTERSECTOR_WATERTIGHT, precision, t, &rays);
            size_t mt = watertight_misses(ctx, s, &m, VKRT_INTERSECTOR_MOLLER_TRUMBORE, precision, t, &rays);
            CHECK_MSG(wt == 0, "%s, sphere %d, traversal %d: watertight missed %zu of %zu rays", label, c, (int)t, wt,
                      rays);
            fprintf(stderr, "  %s, sphere r=%g at (%g, %g, %g), %s: Moller-Trumbore leaks %zu of %zu rays\n", label,
                    radii[c], centres[c][0], centres[c][1], centres[c][2], t == VKRT_TRAVERSAL_BVH ? "bvh" : "naive", mt,
                    rays);
        }
        vkrt_scene_destroy(s);
        closed_mesh_free(&m);
    }
}

/* ---- the documented rules of vkrt_trace_rays ---- */

/* Unit cube [-0.5, 0.5]^3, 12 triangles; prim 0 and 1 form the face z = +0.5. */
static inline vkrt_scene *unit_cube_scene(vkrt_context *ctx)
{
    static const float p[8][3] = { { -.5f, -.5f, .5f }, { .5f, -.5f, .5f }, { .5f, .5f, .5f }, { -.5f, .5f, .5f },
                                   { -.5f, -.5f, -.5f }, { .5f, -.5f, -.5f }, { .5f, .5f, -.5f }, { -.5f, .5f, -.5f } };
    static const uint32_t idx[36] = { 0, 1, 2, 0, 2, 3, 5, 4, 7, 5, 7, 6, 1, 5, 6, 1, 6, 2,
                                      4, 0, 3, 4, 3, 7, 3, 2, 6, 3, 6, 7, 4, 5, 1, 4, 1, 0 };
    vkrt_mesh_desc md = { .positions = &p[0][0], .vertex_count = 8, .indices = idx, .index_count = 36 };
    vkrt_scene *s = NULL;
    vkrt_result r = vkrt_scene_create(ctx, &(vkrt_scene_desc){ .meshes = &md, .mesh_count = 1, .keep_world_coordinates = true },
                                      &s);
    CHECK_MSG(r == VKRT_OK, "cube: %s", vkrt_context_last_error(ctx));
    return s;
}

static inline bool hit_is_finite(const vkrt_hit *h)
{
    return isfinite(h->t) && isfinite(h->u) && isfinite(h->v);
}

/* Misses (NaN or infinite origin or direction, zero direction, t outside (tmin, tmax)), tmax = 0
 * as infinity, t in units of |dir|, and direction components of +0 and -0 with the origin on a
 * box plane (0 * inf in the slab test): every traversal and intersector, no NaN anywhere. */
static inline void check_ray_rules_on(vkrt_context *ctx, vkrt_precision precision, const char *label)
{
    vkrt_scene *s = unit_cube_scene(ctx);
    if (!s) return;
    const float inf = INFINITY, nan = NAN, z = 0.0f, nz = -0.0f;
    /* expect_t < 0: a miss. on_edge: the ray meets the surface exactly on an edge or vertex,
     * where only the watertight test is bound to hit. */
    const struct {
        vkrt_ray ray;
        float expect_t;
        bool on_edge;
    } cases[] = {
        { { { 0.1f, 0.2f, 2.0f }, 0, { 0, 0, -1 }, 0 }, 1.5f, false },      /* tmax 0: infinity */
        { { { 0.1f, 0.2f, 2.0f }, 0, { 0, 0, -2 }, 0 }, 0.75f, false },     /* t in units of |dir| */
        { { { 0.1f, 0.2f, 2.0f }, 0, { 0, 0, -1 }, 1.4f }, -1, false },     /* beyond tmax */
        { { { 0.1f, 0.2f, 2.0f }, 1.6f, { 0, 0, -1 }, 0 }, 2.5f, false },   /* before tmin: the back face */
        { { { 0.1f, 0.2f, 2.0f }, 2.6f, { 0, 0, -1 }, 0 }, -1, false },
        { { { 0.1f, 0.2f, 2.0f }, 0, { 0, 0, 1 }, 0 }, -1, false },         /* pointing away */
        { { { nan, 0.2f, 2.0f }, 0, { 0, 0, -1 }, 0 }, -1, false },
        { { { 0.1f, inf, 2.0f }, 0, { 0, 0, -1 }, 0 }, -1, false },
        { { { 0.1f, 0.2f, -inf }, 0, { 0, 0, 1 }, 0 }, -1, false },
        { { { 0.1f, 0.2f, 2.0f }, 0, { 0, nan, -1 }, 0 }, -1, false },
        { { { 0.1f, 0.2f, 2.0f }, 0, { 0, 0, -inf }, 0 }, -1, false },
        { { { 0.1f, 0.2f, 2.0f }, 0, { 0, 0, 0 }, 0 }, -1, false },         /* zero direction */
        { { { 0.1f, 0.2f, 2.0f }, 0, { nz, nz, nz }, 0 }, -1, false },
        /* +0 and -0 components with the origin on the planes x = 0.5, y = +-0.5 of the boxes */
        { { { 0.5f, 0.2f, 2.0f }, 0, { nz, z, -1 }, 0 }, 1.5f, true },
        { { { 0.5f, 0.2f, 2.0f }, 0, { z, nz, -1 }, 0 }, 1.5f, true },
        { { { 0.5f, -0.5f, 2.0f }, 0, { nz, z, -1 }, 0 }, 1.5f, true },
        { { { -0.5f, -0.5f, 2.0f }, 0, { z, nz, -1 }, 0 }, 1.5f, true },
        { { { 0.5f, 0.5f, -2.0f }, 0, { z, z, 1 }, 0 }, 1.5f, true },
        { { { 0.1f, 0.5f, -2.0f }, 0, { z, nz, 1 }, 0 }, 1.5f, true },
        { { { 0.5000001f, 0.2f, 2.0f }, 0, { nz, z, -1 }, 0 }, -1, false }, /* just outside the slab */
        { { { 0.5000001f, 0.2f, 2.0f }, 0, { z, z, -1 }, 0 }, -1, false },
        { { { 0.1f, -0.5000001f, 2.0f }, 0, { z, nz, -1 }, 0 }, -1, false },
        { { { 2.0f, 0.5f, 0.5f }, 0, { -1, nz, z }, 0 }, 1.5f, true },     /* along an edge of the cube */
        { { { 0.0f, 0.0f, 0.0f }, 0, { z, z, 1 }, 0 }, 0.5f, true },       /* from inside, on a diagonal */
        { { { 0.0f, 0.0f, 0.0f }, 0, { nz, 1, nz }, 0 }, 0.5f, true },
        { { { 0.1f, 0.2f, 0.3f }, 0, { nz, 1, z }, 0 }, 0.3f, false },     /* from inside */
        { { { 0.1f, 0.2f, 0.3f }, 0, { -1, nz, z }, 0 }, 0.6f, false },
    };
    const size_t n = sizeof cases / sizeof cases[0];
    vkrt_ray rays[sizeof cases / sizeof cases[0]];
    for (size_t i = 0; i < n; i++) rays[i] = cases[i].ray;
    for (int isect = VKRT_INTERSECTOR_WATERTIGHT; isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++)
        for (vkrt_traversal t = VKRT_TRAVERSAL_BVH; t <= VKRT_TRAVERSAL_NAIVE; t++) {
            vkrt_trace_desc d = { .traversal = t, .intersector = (vkrt_intersector)isect, .precision = precision };
            vkrt_hit *h = trace_all(ctx, s, &d, rays, n);
            for (size_t i = 0; i < n; i++) {
                CHECK_MSG(hit_is_finite(&h[i]), "%s isect %d traversal %d ray %zu: t %g u %g v %g", label, isect, (int)t,
                          i, h[i].t, h[i].u, h[i].v);
                bool bound = isect == VKRT_INTERSECTOR_WATERTIGHT || !cases[i].on_edge;
                if (cases[i].expect_t < 0) {
                    CHECK_MSG(h[i].t == -1.0f && h[i].prim_id == VKRT_NO_HIT,
                              "%s isect %d traversal %d ray %zu: hit %u at %g, expected a miss", label, isect, (int)t, i,
                              h[i].prim_id, h[i].t);
                } else if (bound || h[i].prim_id != VKRT_NO_HIT) {
                    CHECK_MSG(h[i].prim_id != VKRT_NO_HIT && fabsf(h[i].t - cases[i].expect_t) <= 1e-6f * cases[i].expect_t,
                              "%s isect %d traversal %d ray %zu: prim %u t %.9g, expected t %g", label, isect, (int)t, i,
                              h[i].prim_id, h[i].t, cases[i].expect_t);
                }
            }
            free(h);
        }
    /* No rays: nothing to do, and NULL arrays are then allowed. */
    CHECK(vkrt_trace_rays(ctx, s, NULL, NULL, 0, NULL) == VKRT_OK);
    vkrt_hit one;
    CHECK(vkrt_trace_rays(ctx, s, NULL, NULL, 1, &one) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_trace_rays(ctx, s, &(vkrt_trace_desc){ .intersector = 7 }, rays, 1, &one) == VKRT_ERROR_INVALID_ARGUMENT);
    CHECK(vkrt_trace_rays(ctx, s, &(vkrt_trace_desc){ .precision = 7 }, rays, 1, &one) == VKRT_ERROR_INVALID_ARGUMENT);
    vkrt_scene_destroy(s);
}

/* ---- self-intersection ---- */

/* Spawns secondary rays from the hits of primary rays into icospheres scaled 1e-6..1e6 and
 * translated up to 1e6: origin vkrt_ray_offset(hit point, face normal turned towards the new ray),
 * direction random in that hemisphere (reflection-like) or the other (transmission-like, the
 * offset then along the reversed normal). None may hit its own triangle. */
static inline void check_no_self_intersection_on(vkrt_context *ctx, const char *label)
{
    const double scales[5] = { 1e-6, 1e-3, 1.0, 1e3, 1e6 };
    const double shifts[4] = { 0.0, 1.0, 1e3, 1e6 };
    enum { PRIMARY = 1500, SECONDARY = 4 };
    size_t total_spawned = 0, self_hits = 0;
    for (int si = 0; si < 5; si++)
        for (int ti = 0; ti < 4; ti++) {
            const double centre[3] = { shifts[ti], -0.5 * shifts[ti], 0.25 * shifts[ti] };
            closed_mesh m = icosphere(2, scales[si], centre);
            vkrt_scene *s = closed_mesh_scene(ctx, &m);
            if (!s) {
                closed_mesh_free(&m);
                continue;
            }
            test_rng rng = { 777 + (uint64_t)si * 10 + (uint64_t)ti };
            vkrt_ray *primary = calloc(PRIMARY, sizeof *primary);
            vkrt_ray *secondary = calloc((size_t)PRIMARY * SECONDARY, sizeof *secondary);
            uint32_t *own = calloc((size_t)PRIMARY * SECONDARY, sizeof *own);
            if (!primary || !secondary || !own) abort();
            for (int i = 0; i < PRIMARY; i++) {
                double o[3], t[3];
                rng_unit_vector(&rng, o);
                rng_unit_vector(&rng, t);
                float target[3];
                for (int a = 0; a < 3; a++) {
                    o[a] = centre[a] + 3.0 * scales[si] * o[a];
                    target[a] = (float)(centre[a] + 0.6 * scales[si] * t[a]);
                }
                primary[i] = ray_towards(o, target);
            }
            vkrt_hit *ph = trace_all(ctx, s, NULL, primary, PRIMARY);
            size_t n = 0;
            for (int i = 0; i < PRIMARY; i++) {
                if (ph[i].prim_id == VKRT_NO_HIT) continue;
                const uint32_t *tri = m.indices + ph[i].prim_id * 3;
                const float *v0 = m.positions + tri[0] * 3, *v1 = m.positions + tri[1] * 3, *v2 = m.positions + tri[2] * 3;
                /* The hit point as a float renderer computes it, from the barycentrics. */
                float w = 1.0f - ph[i].u - ph[i].v;
                const float p[3] = { v0[0] * w + v1[0] * ph[i].u + v2[0] * ph[i].v, v0[1] * w + v1[1] * ph[i].u + v2[1] * ph[i].v,
                                     v0[2] * w + v1[2] * ph[i].u + v2[2] * ph[i].v };
                double e1[3], e2[3], nd[3];
                for (int a = 0; a < 3; a++) e1[a] = (double)v1[a] - v0[a], e2[a] = (double)v2[a] - v0[a];
                nd[0] = e1[1] * e2[2] - e1[2] * e2[1], nd[1] = e1[2] * e2[0] - e1[0] * e2[2], nd[2] = e1[0] * e2[1] - e1[1] * e2[0];
                double len = sqrt(nd[0] * nd[0] + nd[1] * nd[1] + nd[2] * nd[2]);
                if (!(len > 0)) continue;
                /* Towards the side the primary ray came from. */
                double facing = nd[0] * primary[i].dir[0] + nd[1] * primary[i].dir[1] + nd[2] * primary[i].dir[2];
                for (int a = 0; a < 3; a++) nd[a] = (facing > 0 ? -nd[a] : nd[a]) / len;
                for (int k = 0; k < SECONDARY; k++) {
                    /* Even k: a reflection (the incoming side); odd k: a transmission. */
                    double sign = k % 2 == 0 ? 1.0 : -1.0, d[3];
                    rng_unit_vector(&rng, d);
                    double side = sign * (d[0] * nd[0] + d[1] * nd[1] + d[2] * nd[2]);
                    if (side == 0.0) continue;
                    if (side < 0)
                        for (int a = 0; a < 3; a++) d[a] = -d[a];
                    const float nrm[3] = { (float)(sign * nd[0]), (float)(sign * nd[1]), (float)(sign * nd[2]) };
                    secondary[n] = (vkrt_ray){ .dir = { (float)d[0], (float)d[1], (float)d[2] } };
                    vkrt_ray_offset(p, nrm, secondary[n].origin);
                    own[n++] = ph[i].prim_id;
                }
            }
            vkrt_hit *sh = trace_all(ctx, s, NULL, secondary, n);
            size_t self = 0;
            for (size_t i = 0; i < n; i++) self += sh[i].prim_id == own[i];
            CHECK_MSG(self == 0, "%s: scale %g, shift %g: %zu of %zu secondary rays hit their own triangle", label,
                      scales[si], shifts[ti], self, n);
            /* Where float can still resolve the sphere, the primary rays must find it. */
            if (scales[si] >= 1e-4 * shifts[ti])
                CHECK_MSG(n > PRIMARY, "%s: scale %g, shift %g: only %zu secondary rays", label, scales[si], shifts[ti], n);
            total_spawned += n;
            self_hits += self;
            free(sh);
            free(ph);
            free(primary);
            free(secondary);
            free(own);
            vkrt_scene_destroy(s);
            closed_mesh_free(&m);
        }
    fprintf(stderr, "  %s: %zu secondary rays, %zu hit their own triangle\n", label, total_spawned, self_hits);
}

/* ---- what other tracers are handed: camera rays and triangles ---- */

/* vkrt_camera_rays() traced with vkrt_trace_rays() hit the triangles an id render shows, pixel
 * for pixel, and each hit lies on the triangle vkrt_scene_triangles_get() gives for its prim_id
 * (the same traced coordinates, in prim_id order): the built-in scene, a view of its own. */
static inline void check_camera_rays_and_triangles_on(vkrt_context *ctx, const char *label)
{
    enum { W = 40, H = 30 };
    const vkrt_camera cam = { .eye = { 0.8f, 0.4f, 1.2f }, .fov_y_degrees = 50.0f };
    vkrt_scene *s = NULL;
    CHECK_MSG(vkrt_scene_create(ctx, &(vkrt_scene_desc){ 0 }, &s) == VKRT_OK, "%s: %s", label, vkrt_context_last_error(ctx));
    if (!s) return;
    vkrt_scene_stats st;
    vkrt_scene_stats_get(s, &st);
    float *id = malloc(vkrt_render_floats(W, H) * sizeof *id), *tris = malloc(st.triangles * 9 * sizeof *tris);
    vkrt_ray *rays = malloc(W * H * sizeof *rays);
    if (!id || !tris || !rays) abort();
    vkrt_render_desc rd = { .width = W, .height = H, .camera = cam, .mode = VKRT_MODE_ID };
    CHECK(vkrt_render(ctx, s, &rd, id, vkrt_render_floats(W, H), NULL) == VKRT_OK);
    CHECK(vkrt_camera_rays(ctx, &cam, W, H, rays, W * H) == VKRT_OK);
    CHECK(vkrt_scene_triangles_get(s, tris, st.triangles * 9) == VKRT_OK);
    vkrt_hit *h = trace_all(ctx, s, NULL, rays, W * H);
    size_t same = 0, hits = 0, on_triangle = 0;
    for (size_t i = 0; i < W * H; i++) {
        same += id[4 * i] == (h[i].prim_id == VKRT_NO_HIT ? -1.0f : (float)h[i].prim_id);
        if (h[i].prim_id == VKRT_NO_HIT) continue;
        hits++;
        /* The hit point from t against the one from the barycentrics on the exported corners. */
        const float *v = tris + (size_t)h[i].prim_id * 9;
        double w = 1.0 - h[i].u - h[i].v, worst = 0.0;
        for (int a = 0; a < 3; a++) {
            double from_t = rays[i].origin[a] + (double)h[i].t * rays[i].dir[a];
            double from_uv = w * v[a] + h[i].u * v[3 + a] + h[i].v * v[6 + a];
            worst = fmax(worst, fabs(from_t - from_uv));
        }
        on_triangle += worst < 1e-5;
    }
    CHECK_MSG(same == W * H, "%s: camera rays hit the id render's triangle on %zu of %d pixels", label, same, W * H);
    CHECK_MSG(hits > W * H / 8 && on_triangle == hits, "%s: %zu of %zu hits lie on their exported triangle", label,
              on_triangle, hits);
    /* Every exported corner inside the scene's bounds. */
    size_t outside = 0;
    for (size_t k = 0; k < st.triangles * 3; k++)
        for (int a = 0; a < 3; a++)
            outside += tris[3 * k + a] < st.bounds_min[a] || tris[3 * k + a] > st.bounds_max[a];
    CHECK_MSG(outside == 0, "%s: %zu exported coordinates outside the scene bounds", label, outside);
    free(h);
    free(rays);
    free(tris);
    free(id);
    vkrt_scene_destroy(s);
}

/* Rays grazing one large triangle in the plane y = 0 at 1e-1 ... 1e-4 radians: the float
 * edge functions lose digits to cancellation there, so the reported distance is refined in
 * double (refine_hit_distance): it must be the exact distance of that float ray rounded once,
 * within one float ulp of the double reference traced from the same rays (`reference`, a CPU
 * context). Both intersectors. */
static inline void check_grazing_distances_on(vkrt_context *ctx, vkrt_context *reference, const char *label)
{
    static const float pos[9] = { -100.0f, 0.0f, -100.0f, 0.0f, 0.0f, 200.0f, 100.0f, 0.0f, -100.0f };
    vkrt_mesh_desc md = { .positions = pos, .vertex_count = 3 };
    vkrt_scene_desc sd = { .meshes = &md, .mesh_count = 1, .keep_world_coordinates = true };
    vkrt_scene *s = NULL, *ref = NULL;
    CHECK_MSG(vkrt_scene_create(ctx, &sd, &s) == VKRT_OK, "%s: %s", label, vkrt_context_last_error(ctx));
    CHECK_MSG(vkrt_scene_create(reference, &sd, &ref) == VKRT_OK, "reference: %s", vkrt_context_last_error(reference));
    enum { N = 4000 };
    vkrt_ray *rays = calloc(N, sizeof *rays);
    if (!rays) abort();
    test_rng rng = { 777 };
    for (size_t i = 0; i < N; i++) {
        double angle = pow(10.0, -1.0 - 3.0 * rng_uniform(&rng)), phi = 6.283185307179586 * rng_uniform(&rng);
        double distance = 1.0 + 9.0 * rng_uniform(&rng); /* from origin to the hit */
        double hit[3] = { 4.0 * (rng_uniform(&rng) - 0.5), 0.0, 4.0 * (rng_uniform(&rng) - 0.5) };
        double dir[3] = { cos(angle) * cos(phi), -sin(angle), cos(angle) * sin(phi) };
        rays[i] = (vkrt_ray){ .origin = { (float)(hit[0] - distance * dir[0]), (float)(hit[1] - distance * dir[1]),
                                          (float)(hit[2] - distance * dir[2]) },
                              .dir = { (float)dir[0], (float)dir[1], (float)dir[2] } };
    }
    for (int isect = VKRT_INTERSECTOR_WATERTIGHT; s && ref && isect <= VKRT_INTERSECTOR_MOLLER_TRUMBORE; isect++) {
        vkrt_trace_desc d = { .intersector = (vkrt_intersector)isect };
        vkrt_trace_desc dd = { .intersector = (vkrt_intersector)isect, .precision = VKRT_PRECISION_DOUBLE };
        vkrt_hit *h = trace_all(ctx, s, &d, rays, N), *hd = trace_all(reference, ref, &dd, rays, N);
        size_t both = 0, beyond = 0;
        double max_rel = 0;
        for (size_t i = 0; i < N; i++) {
            if (h[i].prim_id == VKRT_NO_HIT || hd[i].prim_id == VKRT_NO_HIT) continue;
            both++;
            double rel = fabs((double)h[i].t - (double)hd[i].t) / (double)hd[i].t;
            max_rel = fmax(max_rel, rel);
            beyond += rel > 0x1p-23;
        }
        fprintf(stderr, "  %s isect %d: %zu of %d grazing rays hit on both, max relative t error %.3g\n", label, isect,
                both, N, max_rel);
        CHECK_MSG(both >= N - N / 1000, "%s isect %d: only %zu of %d grazing rays hit", label, isect, both, N);
        CHECK_MSG(beyond == 0, "%s isect %d: %zu grazing distances off by more than one float ulp (max %.3g)", label,
                  isect, beyond, max_rel);
        free(h);
        free(hd);
    }
    free(rays);
    vkrt_scene_destroy(s);
    vkrt_scene_destroy(ref);
}

#endif
