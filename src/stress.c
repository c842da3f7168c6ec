/* `vkrt stress`: meshes and rays chosen to break a float ray tracer, traced on each backend
 * with each intersector and compared with the CPU double-precision reference.
 *
 * Watertightness follows pbrt-v4's shapes_test.cpp (rays from inside a closed mesh, rays aimed
 * at its vertices) and Woop, Benthin and Wald, "Watertight Ray/Triangle Intersection", JCGT
 * 2013: rays aimed at points of shared edges and vertices. Uses vkrt.h only. */
#include "stress.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "cli_contexts.h"

#define PI 3.14159265358979323846
/* VKRT_MAX_BVH_DEPTH of shaders/vkrt_shared.h: the depth every builder promises to stay within. */
#define BVH_DEPTH_CAP 64u
/* The reference's hit point lies on another triangle (a shared edge or vertex) when it is
 * this close to it, relative to the scene extent: float rounding of hit points is ~1e-7. */
#define SHARED_POINT_TOLERANCE 1e-5
/* Depth errors are relative to max(t, this share of the scene extent): a hit at the origin of
 * a ray started on a surface has no meaningful relative error. */
#define DEPTH_FLOOR 1e-3
/* The reference tests every triangle (no BVH to trust) up to this many ray-triangle tests. */
#define NAIVE_REFERENCE_TESTS 2e8

/* ---- random numbers: splitmix64, so every run traces the same rays --------------------- */

typedef struct rng {
    uint64_t state;
} rng;

static uint64_t rng_next(rng *r)
{
    uint64_t z = (r->state += 0x9e3779b97f4a7c15ull);
    z = (z ^ (z >> 30)) * 0xbf58476d1ce4e5b9ull;
    z = (z ^ (z >> 27)) * 0x94d049bb133111ebull;
    return z ^ (z >> 31);
}

static double rng_uniform(rng *r) /* [0, 1) */
{
    return (double)(rng_next(r) >> 11) * 0x1.0p-53;
}

static void rng_unit_vector(rng *r, double v[3])
{
    double z = 2.0 * rng_uniform(r) - 1.0, phi = 2.0 * PI * rng_uniform(r), s = sqrt(1.0 - z * z);
    v[0] = s * cos(phi);
    v[1] = s * sin(phi);
    v[2] = z;
}

static double dot3(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

static bool normalize3(double v[3])
{
    double len = sqrt(dot3(v, v));
    if (!(len > 0.0)) return false;
    for (int i = 0; i < 3; i++) v[i] /= len;
    return true;
}

/* ---- meshes, welded by the exact float coordinates of their vertices ------------------- */

typedef struct smesh {
    float *pos;              /* 3 per vertex */
    uint32_t *idx;           /* 3 per triangle */
    size_t vertices, vcap, tris, tcap;
    uint32_t *slots;         /* weld table: vertex index + 1, 0 empty */
    size_t slot_count;       /* a power of two, at least twice the vertex count */
    bool failed;             /* out of memory somewhere */
} smesh;

static bool grow(void **array, size_t *cap, size_t needed, size_t elem)
{
    if (needed <= *cap) return true;
    size_t n = *cap ? *cap : 64;
    while (n < needed) n *= 2;
    void *p = realloc(*array, n * elem);
    if (!p) return false;
    *array = p;
    *cap = n;
    return true;
}

static uint32_t float_bits(float f)
{
    uint32_t u;
    if (f == 0.0f) f = 0.0f; /* -0 welds with +0 */
    memcpy(&u, &f, sizeof u);
    return u;
}

static size_t weld_hash(const float p[3], size_t mask)
{
    uint64_t h = float_bits(p[0]) * 0x9e3779b97f4a7c15ull;
    h ^= float_bits(p[1]) * 0xc2b2ae3d27d4eb4full;
    h ^= float_bits(p[2]) * 0x165667b19e3779f9ull;
    return (size_t)(h ^ (h >> 29)) & mask;
}

/* A vertex that is never welded (duplicate vertices on purpose). */
static uint32_t mesh_vertex_raw(smesh *m, const double p[3])
{
    if (!grow((void **)&m->pos, &m->vcap, m->vertices + 1, 3 * sizeof(float))) {
        m->failed = true;
        return 0;
    }
    for (int i = 0; i < 3; i++) m->pos[3 * m->vertices + i] = (float)p[i];
    return (uint32_t)m->vertices++;
}

static bool rehash(smesh *m, size_t slot_count)
{
    uint32_t *slots = calloc(slot_count, sizeof *slots);
    if (!slots) return false;
    for (size_t v = 0; v < m->vertices; v++) {
        size_t h = weld_hash(m->pos + 3 * v, slot_count - 1);
        while (slots[h]) h = (h + 1) & (slot_count - 1);
        slots[h] = (uint32_t)v + 1;
    }
    free(m->slots);
    m->slots = slots;
    m->slot_count = slot_count;
    return true;
}

/* The vertex at p rounded to float; one index per distinct float position. */
static uint32_t mesh_vertex(smesh *m, const double p[3])
{
    if (m->failed) return 0;
    if (2 * (m->vertices + 1) > m->slot_count && !rehash(m, m->slot_count ? 2 * m->slot_count : 1024)) {
        m->failed = true;
        return 0;
    }
    float f[3] = { (float)p[0], (float)p[1], (float)p[2] };
    size_t h = weld_hash(f, m->slot_count - 1);
    for (; m->slots[h]; h = (h + 1) & (m->slot_count - 1)) {
        const float *q = m->pos + 3 * (m->slots[h] - 1);
        if (q[0] == f[0] && q[1] == f[1] && q[2] == f[2]) return m->slots[h] - 1;
    }
    uint32_t v = mesh_vertex_raw(m, p);
    if (!m->failed) m->slots[h] = v + 1;
    return v;
}

static void mesh_tri(smesh *m, uint32_t a, uint32_t b, uint32_t c)
{
    if (m->failed) return;
    if (!grow((void **)&m->idx, &m->tcap, m->tris + 1, 3 * sizeof(uint32_t))) {
        m->failed = true;
        return;
    }
    uint32_t *t = m->idx + 3 * m->tris++;
    t[0] = a;
    t[1] = b;
    t[2] = c;
}

static void mesh_tri_at(smesh *m, const double a[3], const double b[3], const double c[3])
{
    uint32_t ia = mesh_vertex(m, a), ib = mesh_vertex(m, b), ic = mesh_vertex(m, c);
    mesh_tri(m, ia, ib, ic);
}

static void mesh_free(smesh *m)
{
    free(m->pos);
    free(m->idx);
    free(m->slots);
    memset(m, 0, sizeof *m);
}

static void vertex(const smesh *m, uint32_t v, double out[3])
{
    for (int i = 0; i < 3; i++) out[i] = (double)m->pos[3 * (size_t)v + i];
}

/* Unit normal (a zero vector for no area) of triangle t as stored in float. */
static void face_normal(const smesh *m, size_t t, double n[3])
{
    double a[3], b[3], c[3];
    vertex(m, m->idx[3 * t], a);
    vertex(m, m->idx[3 * t + 1], b);
    vertex(m, m->idx[3 * t + 2], c);
    double e1[3] = { b[0] - a[0], b[1] - a[1], b[2] - a[2] }, e2[3] = { c[0] - a[0], c[1] - a[1], c[2] - a[2] };
    n[0] = e1[1] * e2[2] - e1[2] * e2[1];
    n[1] = e1[2] * e2[0] - e1[0] * e2[2];
    n[2] = e1[0] * e2[1] - e1[1] * e2[0];
    if (!normalize3(n)) n[0] = n[1] = n[2] = 0.0;
}

static void centroid(const smesh *m, size_t t, double c[3])
{
    double a[3], b[3], d[3];
    vertex(m, m->idx[3 * t], a);
    vertex(m, m->idx[3 * t + 1], b);
    vertex(m, m->idx[3 * t + 2], d);
    for (int i = 0; i < 3; i++) c[i] = (a[i] + b[i] + d[i]) / 3.0;
}

/* The torus' inside point nearest to p (on its core circle of radius R in the xy plane). */
static void torus_core_point(double R, const double p[3], double out[3])
{
    double r = hypot(p[0], p[1]);
    out[0] = r > 0 ? R * p[0] / r : R;
    out[1] = r > 0 ? R * p[1] / r : 0.0;
    out[2] = 0.0;
}

/* Makes every face normal point away from the inside: the origin, or the torus core when
 * torus_R > 0. The leak rays rely on outward normals to enter the volume transversally. */
static void orient_outward(smesh *m, double torus_R)
{
    for (size_t t = 0; t < m->tris; t++) {
        double n[3], c[3], in[3] = { 0, 0, 0 };
        face_normal(m, t, n);
        centroid(m, t, c);
        if (torus_R > 0) torus_core_point(torus_R, c, in);
        double away[3] = { c[0] - in[0], c[1] - in[1], c[2] - in[2] };
        if (dot3(n, away) < 0) {
            uint32_t s = m->idx[3 * t + 1];
            m->idx[3 * t + 1] = m->idx[3 * t + 2];
            m->idx[3 * t + 2] = s;
        }
    }
}

static void icosphere_face(smesh *m, const double a[3], const double b[3], const double c[3], int level)
{
    if (level == 0) {
        mesh_tri_at(m, a, b, c);
        return;
    }
    /* a + b == b + a exactly, so both faces of an edge make the same midpoint and it welds. */
    double ab[3], bc[3], ca[3];
    for (int i = 0; i < 3; i++) {
        ab[i] = a[i] + b[i];
        bc[i] = b[i] + c[i];
        ca[i] = c[i] + a[i];
    }
    normalize3(ab);
    normalize3(bc);
    normalize3(ca);
    icosphere_face(m, a, ab, ca, level - 1);
    icosphere_face(m, ab, b, bc, level - 1);
    icosphere_face(m, ca, bc, c, level - 1);
    icosphere_face(m, ab, bc, ca, level - 1);
}

/* Unit sphere: 20 * 4^level triangles. */
static void make_icosphere(smesh *m, int level)
{
    const double g = (1.0 + sqrt(5.0)) / 2.0;
    double v[12][3] = { { -1, g, 0 }, { 1, g, 0 }, { -1, -g, 0 }, { 1, -g, 0 }, { 0, -1, g }, { 0, 1, g },
                        { 0, -1, -g }, { 0, 1, -g }, { g, 0, -1 }, { g, 0, 1 }, { -g, 0, -1 }, { -g, 0, 1 } };
    static const int f[20][3] = { { 0, 11, 5 }, { 0, 5, 1 }, { 0, 1, 7 }, { 0, 7, 10 }, { 0, 10, 11 },
                                  { 1, 5, 9 }, { 5, 11, 4 }, { 11, 10, 2 }, { 10, 7, 6 }, { 7, 1, 8 },
                                  { 3, 9, 4 }, { 3, 4, 2 }, { 3, 2, 6 }, { 3, 6, 8 }, { 3, 8, 9 },
                                  { 4, 9, 5 }, { 2, 4, 11 }, { 6, 2, 10 }, { 8, 6, 7 }, { 9, 8, 1 } };
    for (int i = 0; i < 12; i++) normalize3(v[i]);
    for (int i = 0; i < 20; i++) icosphere_face(m, v[f[i][0]], v[f[i][1]], v[f[i][2]], level);
    orient_outward(m, 0.0);
}

#define TORUS_R 0.7
#define TORUS_r 0.3

static void torus_point(int i, int j, int nu, int nv, double p[3])
{
    double u = 2.0 * PI * (i % nu) / nu, w = 2.0 * PI * (j % nv) / nv;
    p[0] = (TORUS_R + TORUS_r * cos(w)) * cos(u);
    p[1] = (TORUS_R + TORUS_r * cos(w)) * sin(u);
    p[2] = TORUS_r * sin(w);
}

static void make_torus(smesh *m, int nu, int nv)
{
    for (int i = 0; i < nu; i++)
        for (int j = 0; j < nv; j++) {
            double a[3], b[3], c[3], d[3];
            torus_point(i, j, nu, nv, a);
            torus_point(i + 1, j, nu, nv, b);
            torus_point(i + 1, j + 1, nu, nv, c);
            torus_point(i, j + 1, nu, nv, d);
            mesh_tri_at(m, a, b, c);
            mesh_tri_at(m, a, c, d);
        }
    orient_outward(m, TORUS_R);
}

/* [-1, 1]^3 with each face an n x n grid of quads; lattice coordinates come from the same
 * integer expression on every face, so the faces weld along the cube's edges. */
static void make_cube(smesh *m, int n)
{
    for (int axis = 0; axis < 3; axis++)
        for (int side = 0; side < 2; side++)
            for (int i = 0; i < n; i++)
                for (int j = 0; j < n; j++) {
                    double q[4][3];
                    int di[4] = { 0, 1, 1, 0 }, dj[4] = { 0, 0, 1, 1 };
                    for (int k = 0; k < 4; k++) {
                        q[k][axis] = side ? 1.0 : -1.0;
                        q[k][(axis + 1) % 3] = -1.0 + 2.0 * (i + di[k]) / n;
                        q[k][(axis + 2) % 3] = -1.0 + 2.0 * (j + dj[k]) / n;
                    }
                    mesh_tri_at(m, q[0], q[1], q[2]);
                    mesh_tri_at(m, q[0], q[2], q[3]);
                }
    orient_outward(m, 0.0);
}

/* A closed cylinder of radius 0.02 and length 2 cut into `segments` long thin side slivers
 * (aspect ratio 2 / (2 pi 0.02 / segments)) and two fans of thin cap triangles. */
#define SLIVER_RADIUS 0.02
static void make_sliver_cylinder(smesh *m, int segments)
{
    double top[3] = { 0, 0, 1 }, bottom[3] = { 0, 0, -1 };
    for (int i = 0; i < segments; i++) {
        double u0 = 2.0 * PI * i / segments, u1 = 2.0 * PI * ((i + 1) % segments) / segments;
        double a[3] = { SLIVER_RADIUS * cos(u0), SLIVER_RADIUS * sin(u0), -1 }, b[3] = { SLIVER_RADIUS * cos(u1), SLIVER_RADIUS * sin(u1), -1 };
        double c[3] = { b[0], b[1], 1 }, d[3] = { a[0], a[1], 1 };
        mesh_tri_at(m, a, b, c);
        mesh_tri_at(m, a, c, d);
        mesh_tri_at(m, top, d, c);
        mesh_tri_at(m, bottom, b, a);
    }
    orient_outward(m, 0.0);
}

/* ---- rays -------------------------------------------------------------------------- */

typedef struct ray_set {
    vkrt_ray *rays;
    uint8_t *must_hit; /* 1: the ray enters a closed surface (or starts inside one) */
    size_t count, cap, mcap;
    bool failed;
} ray_set;

static void add_ray(ray_set *s, const double o[3], const double d[3], bool must_hit)
{
    if (s->failed) return;
    if (!grow((void **)&s->rays, &s->cap, s->count + 1, sizeof *s->rays) ||
        !grow((void **)&s->must_hit, &s->mcap, s->count + 1, 1)) {
        s->failed = true;
        return;
    }
    vkrt_ray *r = &s->rays[s->count];
    for (int i = 0; i < 3; i++) {
        r->origin[i] = (float)o[i];
        r->dir[i] = (float)d[i];
    }
    r->tmin = 0.0f;
    r->tmax = 0.0f;
    s->must_hit[s->count++] = must_hit;
}

/* A random unit direction entering the surface at a point whose adjacent faces have the
 * given outward normals: at least `margin` against every one, so the ray crosses into the
 * volume there whatever rounding does to it. false when none is found. */
static bool entering_direction(rng *r, const double (*normals)[3], int count, double margin, double d[3])
{
    double avg[3] = { 0, 0, 0 };
    for (int k = 0; k < count; k++)
        for (int i = 0; i < 3; i++) avg[i] += normals[k][i];
    if (!normalize3(avg)) return false;
    for (int attempt = 0; attempt < 64; attempt++) {
        double jitter[3];
        rng_unit_vector(r, jitter);
        double spread = attempt < 48 ? 0.9 : 0.0;
        for (int i = 0; i < 3; i++) d[i] = -avg[i] + spread * jitter[i];
        if (!normalize3(d)) continue;
        bool ok = true;
        for (int k = 0; k < count && ok; k++) ok = dot3(d, normals[k]) <= -margin;
        if (ok) return true;
    }
    return false;
}

/* Rays from outside aimed at p along `dirs` entering directions, from distance `dist`. */
static void aim_from_outside(ray_set *s, rng *r, const double p[3], const double (*normals)[3], int count, int dirs,
                             double dist)
{
    for (int k = 0; k < dirs; k++) {
        double d[3];
        if (!entering_direction(r, normals, count, 0.05, d)) return;
        double far = dist * (0.5 + rng_uniform(r));
        double o[3] = { p[0] - far * d[0], p[1] - far * d[1], p[2] - far * d[2] };
        add_ray(s, o, d, true);
    }
}

/* Edge -> faces and vertex -> faces of a closed mesh. */
typedef struct adjacency {
    uint64_t *edges;          /* (min << 32 | max) per face edge, sorted; each paired twice */
    uint32_t *edge_face;      /* the face of each entry */
    size_t edge_entries;
    uint32_t *vert_first;     /* CSR: faces of vertex v at vert_faces[vert_first[v] ..] */
    uint32_t *vert_faces;
    double (*normals)[3];     /* outward unit normal per face */
} adjacency;

static int compare_edge_entry(const void *a, const void *b)
{
    const uint64_t *x = a, *y = b;
    return (x[0] > y[0]) - (x[0] < y[0]);
}

static void adjacency_free(adjacency *a)
{
    free(a->edges);
    free(a->edge_face);
    free(a->vert_first);
    free(a->vert_faces);
    free(a->normals);
    memset(a, 0, sizeof *a);
}

static bool adjacency_build(const smesh *m, adjacency *a)
{
    memset(a, 0, sizeof *a);
    a->edge_entries = 3 * m->tris;
    uint64_t *pairs = malloc(a->edge_entries * 2 * sizeof *pairs);
    a->edges = malloc(a->edge_entries * sizeof *a->edges);
    a->edge_face = malloc(a->edge_entries * sizeof *a->edge_face);
    a->vert_first = calloc(m->vertices + 1, sizeof *a->vert_first);
    a->vert_faces = malloc(3 * m->tris * sizeof *a->vert_faces);
    a->normals = malloc(m->tris * sizeof *a->normals);
    if (!pairs || !a->edges || !a->edge_face || !a->vert_first || !a->vert_faces || !a->normals) {
        free(pairs);
        adjacency_free(a);
        return false;
    }
    for (size_t t = 0; t < m->tris; t++) {
        face_normal(m, t, a->normals[t]);
        for (int k = 0; k < 3; k++) {
            uint64_t u = m->idx[3 * t + k], v = m->idx[3 * t + (k + 1) % 3];
            pairs[2 * (3 * t + k)] = u < v ? (u << 32 | v) : (v << 32 | u);
            pairs[2 * (3 * t + k) + 1] = t;
            a->vert_first[m->idx[3 * t + k] + 1]++;
        }
    }
    qsort(pairs, a->edge_entries, 2 * sizeof *pairs, compare_edge_entry);
    for (size_t i = 0; i < a->edge_entries; i++) {
        a->edges[i] = pairs[2 * i];
        a->edge_face[i] = (uint32_t)pairs[2 * i + 1];
    }
    free(pairs);
    for (size_t v = 0; v < m->vertices; v++) a->vert_first[v + 1] += a->vert_first[v];
    uint32_t *fill = calloc(m->vertices, sizeof *fill);
    if (!fill) {
        adjacency_free(a);
        return false;
    }
    for (size_t t = 0; t < m->tris; t++)
        for (int k = 0; k < 3; k++) {
            uint32_t v = m->idx[3 * t + k];
            a->vert_faces[a->vert_first[v] + fill[v]++] = (uint32_t)t;
        }
    free(fill);
    return true;
}

typedef void (*interior_fn)(rng *r, double out[3]);

static void inside_sphere(rng *r, double p[3])
{
    rng_unit_vector(r, p);
    double s = 0.9 * cbrt(rng_uniform(r));
    for (int i = 0; i < 3; i++) p[i] *= s;
}

static void inside_torus(rng *r, double p[3])
{
    double u = 2.0 * PI * rng_uniform(r), d[3];
    rng_unit_vector(r, d);
    double s = 0.9 * TORUS_r * cbrt(rng_uniform(r));
    p[0] = TORUS_R * cos(u) + s * d[0];
    p[1] = TORUS_R * sin(u) + s * d[1];
    p[2] = s * d[2];
}

static void inside_cube(rng *r, double p[3])
{
    for (int i = 0; i < 3; i++) p[i] = 1.8 * rng_uniform(r) - 0.9;
}

static void inside_sliver_cylinder(rng *r, double p[3])
{
    double u = 2.0 * PI * rng_uniform(r), s = 0.9 * SLIVER_RADIUS * sqrt(rng_uniform(r));
    p[0] = s * cos(u);
    p[1] = s * sin(u);
    p[2] = 1.8 * rng_uniform(r) - 0.9;
}

typedef struct leak_sizes {
    size_t edges, vertices;   /* how many of each to aim at (spread evenly) */
    int dirs;                 /* outside directions per target point */
    size_t inside;            /* random rays from inside */
} leak_sizes;

/* Where along a shared edge the leak rays aim (the midpoint and other parameters). */
static const double edge_params[] = { 0.5, 1.0 / 3.0, 0.25, 0.1, 0.9 };

/* Rays aimed at points of shared edges (edge_params) and at shared vertices, from outside along
 * entering directions and from inside; random rays from inside. All must hit. */
static void leak_rays(const smesh *m, interior_fn interior, const leak_sizes *z, double dist, rng *r, ray_set *s)
{
    adjacency a;
    if (!adjacency_build(m, &a)) {
        s->failed = true;
        return;
    }
    size_t unique = a.edge_entries / 2;
    size_t step = unique > z->edges ? unique / z->edges : 1;
    for (size_t e = 0; e + 1 < a.edge_entries; e += 2 * step) {
        if (a.edges[e] != a.edges[e + 1]) { /* not a shared edge: the mesh is open here */
            e -= 2 * step - 1;
            continue;
        }
        double p0[3], p1[3], normals[2][3];
        vertex(m, (uint32_t)(a.edges[e] >> 32), p0);
        vertex(m, (uint32_t)(a.edges[e] & 0xffffffffu), p1);
        memcpy(normals[0], a.normals[a.edge_face[e]], sizeof normals[0]);
        memcpy(normals[1], a.normals[a.edge_face[e + 1]], sizeof normals[1]);
        for (size_t k = 0; k < sizeof edge_params / sizeof edge_params[0]; k++) {
            double p[3], o[3];
            for (int i = 0; i < 3; i++) p[i] = p0[i] + edge_params[k] * (p1[i] - p0[i]);
            aim_from_outside(s, r, p, (const double (*)[3])normals, 2, z->dirs, dist);
            interior(r, o);
            double d[3] = { p[0] - o[0], p[1] - o[1], p[2] - o[2] };
            add_ray(s, o, d, true);
        }
    }
    step = m->vertices > z->vertices ? m->vertices / z->vertices : 1;
    double (*normals)[3] = NULL;
    size_t ncap = 0;
    for (size_t v = 0; v < m->vertices; v += step) {
        uint32_t first = a.vert_first[v], count = a.vert_first[v + 1] - first;
        if (!count) continue;
        if (!grow((void **)&normals, &ncap, count, sizeof *normals)) {
            s->failed = true;
            break;
        }
        for (uint32_t k = 0; k < count; k++) memcpy(normals[k], a.normals[a.vert_faces[first + k]], sizeof normals[k]);
        double p[3], o[3];
        vertex(m, (uint32_t)v, p);
        aim_from_outside(s, r, p, (const double (*)[3])normals, (int)count, z->dirs, dist);
        interior(r, o);
        double d[3] = { p[0] - o[0], p[1] - o[1], p[2] - o[2] };
        add_ray(s, o, d, true);
    }
    free(normals);
    for (size_t i = 0; i < z->inside; i++) {
        double o[3], d[3];
        interior(r, o);
        rng_unit_vector(r, d);
        add_ray(s, o, d, true);
    }
    adjacency_free(&a);
}

/* Pinhole rays from eye towards target over a w x h grid with a 40 degree field of view. */
static void camera_rays(ray_set *s, const double eye[3], const double target[3], int w, int h, bool must_hit)
{
    double f[3] = { target[0] - eye[0], target[1] - eye[1], target[2] - eye[2] };
    normalize3(f);
    double up[3] = { 0, 1, 0 };
    if (fabs(f[1]) > 0.9) up[0] = 1, up[1] = 0;
    double rt[3] = { f[1] * up[2] - f[2] * up[1], f[2] * up[0] - f[0] * up[2], f[0] * up[1] - f[1] * up[0] };
    normalize3(rt);
    double u[3] = { rt[1] * f[2] - rt[2] * f[1], rt[2] * f[0] - rt[0] * f[2], rt[0] * f[1] - rt[1] * f[0] };
    double k = tan(20.0 * PI / 180.0);
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            double sx = (2.0 * (x + 0.5) / w - 1.0) * k, sy = (1.0 - 2.0 * (y + 0.5) / h) * k, d[3];
            for (int i = 0; i < 3; i++) d[i] = f[i] + sx * rt[i] + sy * u[i];
            normalize3(d);
            add_ray(s, eye, d, must_hit);
        }
}

/* ---- cases ------------------------------------------------------------------------- */

typedef struct stress_case {
    char name[48];
    smesh mesh;
    ray_set rays;
    bool both_builders;  /* degenerate geometry: every builder */
    bool strict_ids;     /* a different triangle is a mismatch even where the hit point is on both */
    double limit;        /* mismatches allowed, as a share of the rays; < 0: reported only */
    double extent;       /* largest side of the bounding box */
} stress_case;

static void case_free(stress_case *c)
{
    mesh_free(&c->mesh);
    free(c->rays.rays);
    free(c->rays.must_hit);
    memset(c, 0, sizeof *c);
}

static void mesh_bounds(const smesh *m, double lo[3], double hi[3])
{
    for (int i = 0; i < 3; i++) lo[i] = INFINITY, hi[i] = -INFINITY;
    for (size_t v = 0; v < m->vertices; v++)
        for (int i = 0; i < 3; i++) {
            lo[i] = fmin(lo[i], m->pos[3 * v + i]);
            hi[i] = fmax(hi[i], m->pos[3 * v + i]);
        }
}

/* The largest side of a box. */
static double box_extent(const double lo[3], const double hi[3])
{
    double e = 0;
    for (int i = 0; i < 3; i++) e = fmax(e, hi[i] - lo[i]);
    return e;
}

static double mesh_extent(const smesh *m)
{
    double lo[3], hi[3];
    mesh_bounds(m, lo, hi);
    return box_extent(lo, hi);
}

enum { CASE_LEAK_ICOSPHERE, CASE_LEAK_TORUS, CASE_LEAK_CUBE, CASE_LEAK_SLIVERS, CASE_LEAK_COUNT_ };

static void make_leak_case(stress_case *c, int which, bool quick, rng *r)
{
    leak_sizes z = { .edges = quick ? 150 : 3000, .vertices = quick ? 100 : 2000, .dirs = quick ? 2 : 4,
                     .inside = quick ? 600 : 20000 };
    interior_fn interior = inside_sphere;
    switch (which) {
    case CASE_LEAK_ICOSPHERE:
        make_icosphere(&c->mesh, quick ? 3 : 5);
        snprintf(c->name, sizeof c->name, "leak-icosphere-%zu", c->mesh.tris);
        break;
    case CASE_LEAK_TORUS:
        make_torus(&c->mesh, quick ? 48 : 192, quick ? 24 : 96);
        snprintf(c->name, sizeof c->name, "leak-torus-%zu", c->mesh.tris);
        interior = inside_torus;
        break;
    case CASE_LEAK_CUBE:
        make_cube(&c->mesh, quick ? 12 : 48);
        snprintf(c->name, sizeof c->name, "leak-cube-%zu", c->mesh.tris);
        interior = inside_cube;
        break;
    default:
        make_sliver_cylinder(&c->mesh, quick ? 256 : 2048);
        snprintf(c->name, sizeof c->name, "leak-slivers-%zu", c->mesh.tris);
        interior = inside_sliver_cylinder;
        break;
    }
    c->limit = 1e-4;
    c->extent = mesh_extent(&c->mesh);
    leak_rays(&c->mesh, interior, &z, c->extent, r, &c->rays);
}

/* Rays from one eye at points of shared edges (edge_params) and at shared
 * vertices of a closed mesh, where the direction enters every face at the point by `margin`
 * (the far side turned away): each must hit. Rays from one point are what the GPU backend's
 * binned traversal takes on a CPU device (README, "Binned traversal"), whose lists must hold
 * every triangle the watertight test may hit. */
static void leak_rays_from_eye(const smesh *m, const double eye[3], double margin, ray_set *s)
{
    adjacency a;
    if (!adjacency_build(m, &a)) {
        s->failed = true;
        return;
    }
    for (size_t e = 0; e + 1 < a.edge_entries; e += 2) {
        if (a.edges[e] != a.edges[e + 1]) { /* not a shared edge: the mesh is open here */
            e--;
            continue;
        }
        double p0[3], p1[3];
        vertex(m, (uint32_t)(a.edges[e] >> 32), p0);
        vertex(m, (uint32_t)(a.edges[e] & 0xffffffffu), p1);
        const double *n0 = a.normals[a.edge_face[e]], *n1 = a.normals[a.edge_face[e + 1]];
        for (size_t k = 0; k < sizeof edge_params / sizeof edge_params[0]; k++) {
            double d[3];
            for (int i = 0; i < 3; i++) d[i] = p0[i] + edge_params[k] * (p1[i] - p0[i]) - eye[i];
            if (normalize3(d) && dot3(d, n0) <= -margin && dot3(d, n1) <= -margin) add_ray(s, eye, d, true);
        }
    }
    for (size_t v = 0; v < m->vertices; v++) {
        uint32_t first = a.vert_first[v], count = a.vert_first[v + 1] - first;
        double d[3];
        vertex(m, (uint32_t)v, d);
        for (int i = 0; i < 3; i++) d[i] -= eye[i];
        bool enters = count > 0 && normalize3(d);
        for (uint32_t k = 0; k < count && enters; k++) enters = dot3(d, a.normals[a.vert_faces[first + k]]) <= -margin;
        if (enters) add_ray(s, eye, d, true);
    }
    adjacency_free(&a);
}

enum { CASE_EYE_ICOSPHERE, CASE_EYE_SLIVERS, CASE_EYE_COUNT_ };

/* Leaks through the binned traversal: the icosphere and the sliver cylinder of the leak cases,
 * every ray from one eye (leak_rays_from_eye, then camera rays). */
static void make_eye_leak_case(stress_case *c, int which, bool quick)
{
    /* Slivers thinner than the camera's pixels would give each ray more than the lists take (16
     * entries a ray): 512 segments at 256 x 256, not the leak case's 2,048. */
    if (which == CASE_EYE_ICOSPHERE) make_icosphere(&c->mesh, quick ? 3 : 5);
    else make_sliver_cylinder(&c->mesh, quick ? 256 : 512);
    snprintf(c->name, sizeof c->name, "eye-%s-%zu", which == CASE_EYE_ICOSPHERE ? "icosphere" : "slivers",
             c->mesh.tris);
    c->limit = 1e-4;
    double lo[3], hi[3], centre[3];
    mesh_bounds(&c->mesh, lo, hi);
    c->extent = box_extent(lo, hi);
    for (int i = 0; i < 3; i++) centre[i] = 0.5 * (lo[i] + hi[i]);
    const double eye[3] = { centre[0] + 0.7 * c->extent, centre[1] + 0.9 * c->extent, centre[2] + 2.2 * c->extent };
    leak_rays_from_eye(&c->mesh, eye, 0.05, &c->rays);
    /* Then camera rays at the centre, as many as the binned traversal takes (16,384 at least,
     * and no fewer than the triangles): every ray of the case from the one eye. */
    int w = quick ? 128 : 256;
    while ((size_t)w * (size_t)w < c->mesh.tris) w *= 2;
    camera_rays(&c->rays, eye, centre, w, w, false);
}

/* Writes 1e-6, 1, 1e3 ... as the case name wants them. */
static void power_name(char *out, size_t size, double v)
{
    if (v == 0) snprintf(out, size, "0");
    else if (v == 1) snprintf(out, size, "1");
    else snprintf(out, size, "1e%d", (int)lround(log10(v)));
}

/* An icosphere and a torus beside it, scaled by s about the origin and moved `offset` away
 * from it (along a fixed unit vector), seen by a camera moved along; plus rays from inside
 * the sphere, or with `one_eye` the camera's rays alone, as many as the binned traversal takes
 * (`eye-scale...`). The ids of the camera rays must equal the reference's. */
static void make_scale_case(stress_case *c, double s, double offset, bool one_eye, bool quick, rng *r)
{
    char sn[16], dn[16];
    power_name(sn, sizeof sn, s);
    power_name(dn, sizeof dn, offset);
    snprintf(c->name, sizeof c->name, "%sscale%s@%s", one_eye ? "eye-" : "", sn, dn);
    const double dir[3] = { 0.8, 0.36, -0.48 };
    double at[3] = { offset * dir[0], offset * dir[1], offset * dir[2] };
    smesh sphere = { 0 }, torus = { 0 };
    make_icosphere(&sphere, 3);
    make_torus(&torus, 48, 24);
    const smesh *parts[2] = { &sphere, &torus };
    const double shift[2][3] = { { -0.9, 0, 0 }, { 0.9, 0, 0.3 } };
    for (int k = 0; k < 2; k++) {
        uint32_t base = (uint32_t)c->mesh.vertices;
        for (size_t v = 0; v < parts[k]->vertices; v++) {
            double p[3];
            vertex(parts[k], (uint32_t)v, p);
            for (int i = 0; i < 3; i++) p[i] = at[i] + s * (p[i] + shift[k][i]);
            mesh_vertex_raw(&c->mesh, p);
        }
        for (size_t t = 0; t < parts[k]->tris; t++)
            mesh_tri(&c->mesh, base + parts[k]->idx[3 * t], base + parts[k]->idx[3 * t + 1], base + parts[k]->idx[3 * t + 2]);
    }
    mesh_free(&sphere);
    mesh_free(&torus);
    c->strict_ids = true;
    c->limit = 1e-4;
    c->extent = mesh_extent(&c->mesh);
    double eye[3] = { at[0] + s * 0.6, at[1] + s * 1.2, at[2] + s * 5.0 };
    if (one_eye) {
        int w = quick ? 128 : 256;
        camera_rays(&c->rays, eye, at, w, w, false);
        return;
    }
    int w = quick ? 48 : 128;
    camera_rays(&c->rays, eye, at, w, w, false);
    for (int i = 0; i < (quick ? 300 : 3000); i++) {
        double o[3], d[3];
        inside_sphere(r, o);
        for (int k = 0; k < 3; k++) o[k] = at[k] + s * (o[k] + shift[0][k]);
        rng_unit_vector(r, d);
        add_ray(&c->rays, o, d, true);
    }
}

/* A ray aimed at point p of a sheet in the plane z = 0 from distance dist, from either side
 * and at least 0.2 (cosine) off grazing: it must hit where the sheet covers p. */
static void aim_at_sheet(ray_set *s, rng *r, double x, double y, double dist)
{
    double d[3];
    do rng_unit_vector(r, d);
    while (fabs(d[2]) < 0.2);
    double o[3] = { x - dist * d[0], y - dist * d[1], -dist * d[2] };
    add_ray(s, o, d, true);
}

/* Rays aimed at random points of the plane z = 0 inside [lo, hi]^2, kept `inset` (a share of
 * the side) from its border. */
static void rays_at_sheet(ray_set *s, rng *r, const double lo[2], const double hi[2], double inset, size_t count,
                          double dist)
{
    for (size_t i = 0; i < count; i++)
        aim_at_sheet(s, r, lo[0] + (hi[0] - lo[0]) * (inset + (1 - 2 * inset) * rng_uniform(r)),
                     lo[1] + (hi[1] - lo[1]) * (inset + (1 - 2 * inset) * rng_uniform(r)), dist);
}

enum { CASE_DEG_ZERO_AREA, CASE_DEG_SLIVERS, CASE_DEG_FAN, CASE_DEG_IDENTICAL, CASE_DEG_FLAT, CASE_DEG_COUNT_ };

static void make_degenerate_case(stress_case *c, int which, bool quick, rng *r)
{
    smesh *m = &c->mesh;
    c->both_builders = true;
    c->limit = 1e-4;
    switch (which) {
    case CASE_DEG_ZERO_AREA: {
        /* A closed icosphere with, per face, a triangle with a repeated vertex, one whose third
         * vertex is the edge midpoint (collinear to rounding) and a copy on duplicate vertices. */
        smesh base = { 0 };
        make_icosphere(&base, quick ? 2 : 4);
        for (size_t v = 0; v < base.vertices; v++) {
            double p[3];
            vertex(&base, (uint32_t)v, p);
            mesh_vertex_raw(m, p);
        }
        for (size_t t = 0; t < base.tris; t++) {
            const uint32_t *f = base.idx + 3 * t;
            mesh_tri(m, f[0], f[1], f[2]);
            mesh_tri(m, f[0], f[0], f[1]);
            double a[3], b[3], mid[3], p[3];
            vertex(&base, f[0], a);
            vertex(&base, f[1], b);
            for (int i = 0; i < 3; i++) mid[i] = 0.5 * (a[i] + b[i]);
            mesh_tri(m, f[0], mesh_vertex_raw(m, mid), f[1]);
            if (t % 4 == 0) {
                uint32_t d[3];
                for (int k = 0; k < 3; k++) {
                    vertex(&base, f[k], p);
                    d[k] = mesh_vertex_raw(m, p);
                }
                mesh_tri(m, d[0], d[1], d[2]);
            }
        }
        mesh_free(&base);
        snprintf(c->name, sizeof c->name, "zero-area-%zu", m->tris);
        for (size_t i = 0; i < (quick ? 800 : 8000); i++) {
            double o[3], d[3];
            inside_sphere(r, o);
            rng_unit_vector(r, d);
            add_ray(&c->rays, o, d, true);
            vertex(m, m->idx[3 * (rng_next(r) % m->tris)], d); /* aimed at a vertex */
            for (int k = 0; k < 3; k++) d[k] -= o[k];
            add_ray(&c->rays, o, d, true);
        }
        break;
    }
    case CASE_DEG_SLIVERS: {
        /* A strip of slivers 1 long and 1e-6 wide (aspect 1e6) sharing their long edges. */
        const int n = quick ? 200 : 1000;
        const double w = 1e-6;
        for (int i = 0; i < n; i++) {
            double a[3] = { i * w, 0, 0 }, b[3] = { (i + 1) * w, 0, 0 }, cc[3] = { (i + 1) * w, 1, 0 }, d[3] = { i * w, 1, 0 };
            mesh_tri_at(m, a, b, cc);
            mesh_tri_at(m, a, cc, d);
        }
        snprintf(c->name, sizeof c->name, "slivers-1e6-%zu", m->tris);
        double lo[2] = { 0, 0 }, hi[2] = { n * w, 1 };
        rays_at_sheet(&c->rays, r, lo, hi, 0.01, quick ? 1000 : 10000, 2.0);
        for (int i = 1; i < n; i += quick ? 4 : 1) /* aimed at the shared long edges */
            aim_at_sheet(&c->rays, r, i * w, rng_uniform(r) * 0.98 + 0.01, 2.0);
        break;
    }
    case CASE_DEG_FAN: {
        /* 100,000 triangles around one vertex: the disc of radius 1 in z = 0. */
        const int n = 100000;
        double centre[3] = { 0, 0, 0 };
        for (int i = 0; i < n; i++) {
            double a[3] = { cos(2 * PI * i / n), sin(2 * PI * i / n), 0 };
            double b[3] = { cos(2 * PI * ((i + 1) % n) / n), sin(2 * PI * ((i + 1) % n) / n), 0 };
            mesh_tri_at(m, centre, a, b);
        }
        snprintf(c->name, sizeof c->name, "fan-%zu", m->tris);
        for (int i = 0; i < (quick ? 200 : 2000); i++) /* at the shared vertex, from both sides */
            aim_at_sheet(&c->rays, r, 0.0, 0.0, 2.0);
        for (int i = 0; i < (quick ? 300 : 3000); i++) { /* inside the disc; every 7th on a spoke */
            double rad = 0.98 * sqrt(rng_uniform(r)), ang = 2 * PI * (i % 7 ? rng_uniform(r) : (double)(rng_next(r) % n) / n);
            aim_at_sheet(&c->rays, r, rad * cos(ang), rad * sin(ang), 2.0);
        }
        break;
    }
    case CASE_DEG_IDENTICAL: {
        /* 10,000 copies of one triangle: every centroid equal, nothing to split on; the
         * closest-hit tie must go to the lowest id. */
        double a[3] = { -0.5, -0.4, 0.1 }, b[3] = { 0.6, -0.3, -0.1 }, d3[3] = { 0.0, 0.7, 0.0 };
        uint32_t ia = mesh_vertex(m, a), ib = mesh_vertex(m, b), ic = mesh_vertex(m, d3);
        for (int i = 0; i < 10000; i++) mesh_tri(m, ia, ib, ic);
        snprintf(c->name, sizeof c->name, "identical-%zu", m->tris);
        c->strict_ids = true;
        double n[3];
        face_normal(m, 0, n);
        for (int i = 0; i < (quick ? 400 : 4000); i++) {
            double u = rng_uniform(r), v = rng_uniform(r);
            if (u + v > 1) u = 1 - u, v = 1 - v;
            u = 0.01 + 0.97 * u;
            v = 0.01 + 0.97 * v * (1 - u / 0.98);
            double p[3], d[3];
            for (int k = 0; k < 3; k++) p[k] = a[k] + u * (b[k] - a[k]) + v * (d3[k] - a[k]);
            do rng_unit_vector(r, d);
            while (fabs(dot3(d, n)) < 0.2);
            double o[3] = { p[0] - 2 * d[0], p[1] - 2 * d[1], p[2] - 2 * d[2] };
            add_ray(&c->rays, o, d, true);
        }
        break;
    }
    default: {
        /* Boxes of zero thickness: a 64 x 64 grid in z = 0 and one in x = 0.5, hit along and
         * across the axes (direction components of exactly +0 and -0). */
        const int n = quick ? 32 : 64;
        for (int i = 0; i < n; i++)
            for (int j = 0; j < n; j++) {
                double x0 = -1 + 2.0 * i / n, x1 = -1 + 2.0 * (i + 1) / n, y0 = -1 + 2.0 * j / n, y1 = -1 + 2.0 * (j + 1) / n;
                double a[3] = { x0, y0, 0 }, b[3] = { x1, y0, 0 }, cc[3] = { x1, y1, 0 }, d[3] = { x0, y1, 0 };
                mesh_tri_at(m, a, b, cc);
                mesh_tri_at(m, a, cc, d);
                double e[3] = { 0.5, x0, y0 }, f[3] = { 0.5, x1, y0 }, g[3] = { 0.5, x1, y1 }, h[3] = { 0.5, x0, y1 };
                mesh_tri_at(m, e, f, g);
                mesh_tri_at(m, e, g, h);
            }
        snprintf(c->name, sizeof c->name, "flat-%zu", m->tris);
        double lo[2] = { -1, -1 }, hi[2] = { 1, 1 };
        rays_at_sheet(&c->rays, r, lo, hi, 0.01, quick ? 600 : 6000, 3.0);
        for (int i = 0; i < (quick ? 600 : 6000); i++) { /* straight down and up, at grid points */
            int gi = 1 + (int)(rng_next(r) % (uint64_t)(n - 1)), gj = 1 + (int)(rng_next(r) % (uint64_t)(n - 1));
            double x = i % 2 ? -1 + 2.0 * gi / n : 1.96 * rng_uniform(r) - 0.98;
            double y = i % 3 ? -1 + 2.0 * gj / n : 1.96 * rng_uniform(r) - 0.98;
            double up = i % 4 < 2 ? 1.0 : -1.0;
            double o[3] = { x, y, -3 * up }, d[3] = { i % 5 ? 0.0 : -0.0, i % 7 ? -0.0 : 0.0, up };
            add_ray(&c->rays, o, d, true);
        }
        break;
    }
    }
    c->extent = mesh_extent(m);
}

enum { CASE_RAY_ZERO_DIR, CASE_RAY_ON_CUBE, CASE_RAY_ON_SPHERE, CASE_RAY_GRAZING, CASE_RAY_EYE_TORUS, CASE_RAY_EYE_BOX,
       CASE_RAY_COUNT_ };

/* A ray starting at p on a surface with outward normal nrm, at least 0.2 (cosine) off its
 * plane: inwards it must hit (the far side of a closed mesh). */
static void ray_from_surface(ray_set *s, rng *r, const double p[3], const double nrm[3])
{
    double d[3];
    do rng_unit_vector(r, d);
    while (fabs(dot3(d, nrm)) < 0.2);
    add_ray(s, p, d, dot3(d, nrm) < 0);
}

/* A coordinate inside a face of the tessellated cube: an inner lattice line of its n x n grid,
 * or a random value in (-span, span). */
static double face_coordinate(rng *r, int n, bool lattice, double span)
{
    if (lattice) return -1 + 2.0 * (double)(1 + rng_next(r) % (uint64_t)(n - 1)) / n;
    return span * (2 * rng_uniform(r) - 1);
}

/* A point in the plane of a random face of the cube [-1,1]^3, with coordinates a and b along
 * the next two axes; the face's outward normal goes to nrm. Returns the face's axis. */
static int cube_face_point(rng *r, double a, double b, double p[3], double nrm[3])
{
    int axis = (int)(rng_next(r) % 3);
    double side = (rng_next(r) & 1) ? 1.0 : -1.0;
    p[axis] = side;
    p[(axis + 1) % 3] = a;
    p[(axis + 2) % 3] = b;
    nrm[0] = nrm[1] = nrm[2] = 0.0;
    nrm[axis] = side;
    return axis;
}

static void make_ray_case(stress_case *c, int which, bool quick, rng *r)
{
    smesh *m = &c->mesh;
    const int n = quick ? 8 : 24;
    c->limit = 1e-4;
    switch (which) {
    case CASE_RAY_ZERO_DIR:
        /* Along the axes (two components +0 or -0) and in axis planes (one), at lattice points
         * and random points inside the cube's faces, from outside and from inside. */
        make_cube(m, n);
        snprintf(c->name, sizeof c->name, "zero-dir");
        for (int i = 0; i < (quick ? 1500 : 15000); i++) {
            double a = face_coordinate(r, n, i % 2, 0.99), b = face_coordinate(r, n, i % 3, 0.99), p[3], nrm[3];
            int axis = cube_face_point(r, a, b, p, nrm);
            double d[3] = { (rng_next(r) & 1) ? 0.0 : -0.0, (rng_next(r) & 1) ? 0.0 : -0.0, (rng_next(r) & 1) ? 0.0 : -0.0 };
            d[axis] = -nrm[axis];
            if (i % 4 == 3) d[(axis + 1 + (i / 4) % 2) % 3] = 0.5 * (2 * rng_uniform(r) - 1);
            double o[3];
            if (i % 5 == 4) { /* from inside, outwards: the reversed ray from a point inside */
                for (int k = 0; k < 3; k++) d[k] = -d[k];
                for (int k = 0; k < 3; k++) o[k] = p[k] - 1.5 * d[k];
            } else {
                for (int k = 0; k < 3; k++) o[k] = p[k] - 3.0 * d[k];
            }
            add_ray(&c->rays, o, d, true);
        }
        break;
    case CASE_RAY_ON_CUBE:
        /* Origins exactly on a face (representable: the face coordinate is +-1): inwards must
         * hit. Outwards, float rounding may still hit the face the ray starts on at t ~ 0 (what
         * a secondary ray's origin offset is for), so mismatches are reported only. */
        make_cube(m, n);
        snprintf(c->name, sizeof c->name, "on-surface-cube");
        c->limit = -1;
        for (int i = 0; i < (quick ? 1000 : 10000); i++) {
            double p[3], nrm[3];
            cube_face_point(r, face_coordinate(r, n, i % 2, 0.95), face_coordinate(r, n, false, 0.95), p, nrm);
            ray_from_surface(&c->rays, r, p, nrm);
        }
        break;
    case CASE_RAY_ON_SPHERE: {
        /* Origins on icosphere faces (rounded to float, so a hair off the plane): inwards must
         * hit; outwards may hit the own face at t ~ 0, which is what a secondary ray's origin
         * offset is for, so mismatches are reported only. */
        make_icosphere(m, 3);
        snprintf(c->name, sizeof c->name, "on-surface-sphere");
        c->limit = -1;
        for (int i = 0; i < (quick ? 1000 : 10000); i++) {
            size_t t = rng_next(r) % m->tris;
            double a[3], b[3], cc[3], p[3], nrm[3];
            vertex(m, m->idx[3 * t], a);
            vertex(m, m->idx[3 * t + 1], b);
            vertex(m, m->idx[3 * t + 2], cc);
            face_normal(m, t, nrm);
            double u = 0.05 + 0.45 * rng_uniform(r), v = 0.05 + 0.45 * rng_uniform(r);
            for (int k = 0; k < 3; k++) p[k] = a[k] + u * (b[k] - a[k]) + v * (cc[k] - a[k]);
            ray_from_surface(&c->rays, r, p, nrm);
        }
        break;
    }
    case CASE_RAY_GRAZING:
        /* Rays lying in the plane of a cube face, along it and diagonally across it: they touch
         * the cube only along its boundary, so either answer is right; reported only. */
        make_cube(m, n);
        snprintf(c->name, sizeof c->name, "grazing");
        c->limit = -1;
        for (int i = 0; i < (quick ? 1000 : 10000); i++) {
            double a = i % 2 ? -1 + 2.0 * (double)(rng_next(r) % (uint64_t)(n + 1)) / n : 1.98 * rng_uniform(r) - 0.99;
            double p[3], nrm[3], d[3] = { 0, 0, 0 };
            int axis = cube_face_point(r, a, -2.0, p, nrm);
            d[(axis + 2) % 3] = 1.0;
            if (i % 3 == 2) d[(axis + 1) % 3] = 0.5 * (2 * rng_uniform(r) - 1);
            add_ray(&c->rays, p, d, false);
        }
        break;
    case CASE_RAY_EYE_TORUS: {
        /* The eye inside the torus' tube, looking along it and everywhere: every ray hits. */
        make_torus(m, quick ? 48 : 192, quick ? 24 : 96);
        snprintf(c->name, sizeof c->name, "eye-in-torus");
        double eye[3] = { TORUS_R, 0.02, 0.05 }, ahead[3] = { TORUS_R, 1, 0.05 };
        camera_rays(&c->rays, eye, ahead, quick ? 32 : 96, quick ? 32 : 96, true);
        for (int i = 0; i < (quick ? 500 : 5000); i++) {
            double d[3];
            rng_unit_vector(r, d);
            add_ray(&c->rays, eye, d, true);
        }
        break;
    }
    default: {
        /* The eye inside a box (the tessellated cube): off centre, and at the exact centre
         * looking along the axes at lattice points. */
        make_cube(m, n);
        snprintf(c->name, sizeof c->name, "eye-in-box");
        double eye[3] = { 0.3, -0.2, 0.1 }, ahead[3] = { 0.3, -0.2, -1 }, centre[3] = { 0, 0, 0 };
        camera_rays(&c->rays, eye, ahead, quick ? 32 : 96, quick ? 32 : 96, true);
        for (int i = 0; i < (quick ? 500 : 5000); i++) {
            double d[3];
            rng_unit_vector(r, d);
            add_ray(&c->rays, eye, d, true);
        }
        for (int axis = 0; axis < 3; axis++)
            for (int side = -1; side <= 1; side += 2) {
                double d[3] = { 0, 0, 0 };
                d[axis] = side;
                add_ray(&c->rays, centre, d, true);
            }
        break;
    }
    }
    c->extent = mesh_extent(m);
}

/* ---- running and comparing ---------------------------------------------------------- */

typedef struct row {
    size_t rays, leaks, mismatches, ref_leaks;
    double max_rel_depth;
} row;

/* Distance from p to triangle t (Ericson, Real-Time Collision Detection, 5.1.5). */
static double triangle_distance(const smesh *m, size_t t, const double p[3])
{
    double a[3], b[3], c[3], ab[3], ac[3], ap[3], q[3];
    vertex(m, m->idx[3 * t], a);
    vertex(m, m->idx[3 * t + 1], b);
    vertex(m, m->idx[3 * t + 2], c);
    for (int i = 0; i < 3; i++) {
        ab[i] = b[i] - a[i];
        ac[i] = c[i] - a[i];
        ap[i] = p[i] - a[i];
    }
    double d1 = dot3(ab, ap), d2 = dot3(ac, ap), v, w;
    double bp[3] = { p[0] - b[0], p[1] - b[1], p[2] - b[2] }, cp[3] = { p[0] - c[0], p[1] - c[1], p[2] - c[2] };
    double d3 = dot3(ab, bp), d4 = dot3(ac, bp), d5 = dot3(ab, cp), d6 = dot3(ac, cp);
    double va = d3 * d6 - d5 * d4, vb = d5 * d2 - d1 * d6, vc = d1 * d4 - d3 * d2;
    if (d1 <= 0 && d2 <= 0) v = 0, w = 0;                                    /* vertex a */
    else if (d3 >= 0 && d4 <= d3) v = 1, w = 0;                              /* vertex b */
    else if (d6 >= 0 && d5 <= d6) v = 0, w = 1;                              /* vertex c */
    else if (vc <= 0 && d1 >= 0 && d3 <= 0) v = d1 / (d1 - d3), w = 0;       /* edge ab */
    else if (vb <= 0 && d2 >= 0 && d6 <= 0) v = 0, w = d2 / (d2 - d6);       /* edge ac */
    else if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {                      /* edge bc */
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        v = 1 - w;
    } else {                                                                 /* inside */
        double den = 1 / (va + vb + vc);
        v = vb * den;
        w = vc * den;
    }
    for (int i = 0; i < 3; i++) q[i] = a[i] + v * ab[i] + w * ac[i] - p[i];
    return sqrt(dot3(q, q));
}

/* A ray agrees with the reference when both miss, or both hit the same triangle or (unless
 * the case wants strict ids) the reference's hit point lies on the backend's triangle too (a
 * shared edge or vertex, overlapping copies). Depth errors are measured on agreeing hits. */
static row compare_hits(const stress_case *c, const vkrt_hit *ref, const vkrt_hit *got)
{
    row w = { .rays = c->rays.count };
    for (size_t i = 0; i < c->rays.count; i++) {
        bool rh = ref[i].prim_id != VKRT_NO_HIT, gh = got[i].prim_id != VKRT_NO_HIT;
        if (c->rays.must_hit[i] && !gh) w.leaks++;
        if (c->rays.must_hit[i] && !rh) w.ref_leaks++;
        if (rh != gh) {
            w.mismatches++;
            continue;
        }
        if (!rh) continue;
        const float *d = c->rays.rays[i].dir, *o = c->rays.rays[i].origin;
        if (ref[i].prim_id != got[i].prim_id) {
            double p[3];
            for (int k = 0; k < 3; k++) p[k] = (double)o[k] + (double)ref[i].t * (double)d[k];
            if (c->strict_ids || got[i].prim_id >= c->mesh.tris ||
                triangle_distance(&c->mesh, got[i].prim_id, p) > SHARED_POINT_TOLERANCE * c->extent) {
                w.mismatches++;
                continue;
            }
        }
        double len = sqrt((double)d[0] * d[0] + (double)d[1] * d[1] + (double)d[2] * d[2]);
        double floor = DEPTH_FLOOR * c->extent / len;
        double rel = fabs((double)got[i].t - (double)ref[i].t) / fmax((double)ref[i].t, floor);
        if (!(rel <= w.max_rel_depth)) w.max_rel_depth = rel; /* NaN shows */
    }
    return w;
}

typedef struct runner {
    const stress_options *o;
    stress_report *report;
    vkrt_context *cpu, *gpu; /* cpu always traces the reference; gpu is NULL for --backend cpu */
    bool cpu_rows;           /* false for --backend gpu */
    FILE *out;
} runner;

static vkrt_result failure(runner *u, vkrt_context *ctx, vkrt_result r, const char *what, const stress_case *c)
{
    snprintf(u->report->error, sizeof u->report->error, "stress case %s: %s: %s", c->name, what,
             ctx && vkrt_context_last_error(ctx)[0] ? vkrt_context_last_error(ctx) : vkrt_result_string(r));
    return r;
}

static const char *builder_name(vkrt_bvh_builder b)
{
    return b == VKRT_BVH_BUILDER_MIDPOINT ? "midpoint" : b == VKRT_BVH_BUILDER_SPATIAL_SAH ? "sbvh" : "sah";
}

static vkrt_result run_case(runner *u, const stress_case *c)
{
    if (c->mesh.failed || c->rays.failed) {
        snprintf(u->report->error, sizeof u->report->error, "stress case %s: out of memory", c->name);
        return VKRT_ERROR_OUT_OF_MEMORY;
    }
    const vkrt_bvh_builder builders[3] = { VKRT_BVH_BUILDER_BINNED_SAH, VKRT_BVH_BUILDER_MIDPOINT,
                                           VKRT_BVH_BUILDER_SPATIAL_SAH };
    vkrt_mesh_desc md = { .positions = c->mesh.pos, .vertex_count = (uint32_t)c->mesh.vertices,
                          .indices = c->mesh.idx, .index_count = (uint32_t)(3 * c->mesh.tris) };
    size_t n = c->rays.count;
    vkrt_hit *ref = malloc(n * sizeof *ref), *got = malloc(n * sizeof *got);
    vkrt_result r = VKRT_OK;
    vkrt_scene *cs = NULL, *gs = NULL;
    if (!ref || !got) {
        r = VKRT_ERROR_OUT_OF_MEMORY;
        snprintf(u->report->error, sizeof u->report->error, "stress case %s: out of memory", c->name);
        goto done;
    }
    for (int b = 0; b < (c->both_builders ? 3 : 1); b++) {
        /* World coordinates: the rays are made for them, and scale is what is tested. */
        vkrt_scene_desc sd = { .meshes = &md, .mesh_count = 1, .keep_world_coordinates = true,
                               .builder = builders[b] };
        if ((r = vkrt_scene_create(u->cpu, &sd, &cs)) != VKRT_OK) {
            r = failure(u, u->cpu, r, "creating the CPU scene", c);
            goto done;
        }
        vkrt_scene_stats st;
        vkrt_scene_stats_get(cs, &st);
        bool bounded = st.depth <= BVH_DEPTH_CAP && st.nodes < 2 * st.bvh_references;
        /* The reference trusts no BVH where testing every triangle is affordable. */
        vkrt_trace_desc rd = { .precision = VKRT_PRECISION_DOUBLE, .intersector = VKRT_INTERSECTOR_WATERTIGHT,
                               .traversal = (double)n * (double)st.triangles <= NAIVE_REFERENCE_TESTS
                                                ? VKRT_TRAVERSAL_NAIVE : VKRT_TRAVERSAL_BVH };
        if ((r = vkrt_trace_rays(u->cpu, cs, &rd, c->rays.rays, n, ref)) != VKRT_OK) {
            r = failure(u, u->cpu, r, "tracing the double reference", c);
            goto done;
        }
        for (int backend = 0; backend < 2; backend++) {
            vkrt_context *ctx = backend == 0 ? u->gpu : u->cpu_rows ? u->cpu : NULL;
            if (!ctx) continue;
            vkrt_scene *scene = cs;
            if (backend == 0) {
                if ((r = vkrt_scene_create(ctx, &sd, &gs)) != VKRT_OK) {
                    r = failure(u, ctx, r, "creating the GPU scene", c);
                    goto done;
                }
                scene = gs;
            }
            for (int k = 0; k < 2; k++) {
                vkrt_intersector isect = k == 0 ? VKRT_INTERSECTOR_WATERTIGHT : VKRT_INTERSECTOR_MOLLER_TRUMBORE;
                if (u->o->intersector && u->o->intersector != isect) continue;
                vkrt_trace_stats ts = { 0 };
                vkrt_trace_desc td = { .intersector = isect, .precision = VKRT_PRECISION_FLOAT, .out_stats = &ts };
                if ((r = vkrt_trace_rays(ctx, scene, &td, c->rays.rays, n, got)) != VKRT_OK) {
                    r = failure(u, ctx, r, "tracing", c);
                    goto done;
                }
                row w = compare_hits(c, ref, got);
                size_t limit = c->limit < 0 ? SIZE_MAX : (size_t)floor(c->limit * (double)n);
                bool asserted = isect == VKRT_INTERSECTOR_WATERTIGHT;
                bool ok = w.leaks == 0 && w.mismatches <= limit && bounded;
                char limit_text[24];
                if (c->limit < 0) snprintf(limit_text, sizeof limit_text, "-");
                else snprintf(limit_text, sizeof limit_text, "%zu", limit);
                fprintf(u->out, "%-22s %-8s %-4s %-10s %8zu %6zu %8zu %6s %13.2e %5u  %s\n", c->name,
                        builder_name(builders[b]), backend == 0 ? "gpu" : "cpu", k == 0 ? "watertight" : "mt", w.rays,
                        w.leaks, w.mismatches, limit_text, w.max_rel_depth, st.depth,
                        !asserted ? "-" : ok ? "ok" : "FAIL");
                fflush(u->out);
                u->report->rows++;
                if (asserted && !ok) u->report->failed_rows++;
                if (w.ref_leaks)
                    fprintf(u->out, "  note: the double reference missed %zu ray%s that must hit\n", w.ref_leaks,
                            w.ref_leaks == 1 ? "" : "s");
                if (ts.rays_binned)
                    fprintf(u->out, "  note: %s %s: %llu rays through the binned traversal's lists, %llu answered on "
                                    "the host\n", backend == 0 ? "gpu" : "cpu", k == 0 ? "watertight" : "mt",
                            (unsigned long long)ts.rays_binned, (unsigned long long)ts.rays_culled);
            }
            vkrt_scene_destroy(gs);
            gs = NULL;
        }
        vkrt_scene_destroy(cs);
        cs = NULL;
    }
done:
    vkrt_scene_destroy(gs);
    vkrt_scene_destroy(cs);
    free(ref);
    free(got);
    return r;
}

static double now_seconds(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

vkrt_result stress_run(const stress_options *o, stress_report *out)
{
    memset(out, 0, sizeof *out);
    runner u = { .o = o, .report = out, .out = o->out ? o->out : stdout };
    double t0 = now_seconds();
    vkrt_result r = cli_contexts_create(&o->context, o->backend != VKRT_BACKEND_CPU, &u.gpu, &u.cpu, out->error,
                                        sizeof out->error);
    if (r != VKRT_OK) return r;
    u.cpu_rows = o->backend != VKRT_BACKEND_GPU;
    fprintf(u.out, "vkrt stress%s: %s against the CPU double-precision reference (watertight)\n",
            o->quick ? " --quick" : "", u.gpu ? vkrt_context_device_name(u.gpu) : "CPU float");
    fprintf(u.out, "leaks: rays that must hit (entering or inside a closed surface) and miss. mismatches: hit\n"
                   "against miss, or a triangle other than the reference's that its hit point is not on (a shared\n"
                   "edge or vertex agrees, except in the scale and identical cases). limit: mismatches allowed\n"
                   "('-': reported only). max rel depth: over agreeing hits. depth: of the BVH (at most 64).\n"
                   "Watertight rows must have 0 leaks and mismatches <= limit; mt rows are reported only.\n\n");
    fprintf(u.out, "%-22s %-8s %-4s %-10s %8s %6s %8s %6s %13s %5s  %s\n", "case", "bvh", "back", "isect", "rays", "leaks",
            "mismatch", "limit", "max rel depth", "depth", "result");

    static const double scales_full[][2] = { { 1e-6, 0 }, { 1e-3, 0 }, { 1, 0 }, { 1e3, 0 }, { 1e6, 0 },
                                             { 1e-6, 1e-3 }, { 1e-3, 1 }, { 1, 1e3 }, { 1e3, 1e3 },
                                             { 1e3, 1e6 }, { 1e6, 1e6 } };
    static const double scales_quick[][2] = { { 1e-6, 0 }, { 1e6, 0 }, { 1e-6, 1e-3 }, { 1e3, 1e6 } };
    size_t scale_count = o->quick ? sizeof scales_quick / sizeof scales_quick[0] : sizeof scales_full / sizeof scales_full[0];
    /* The binned traversal's cases: scales at both ends, and far from the origin. */
    static const double eye_scales[][2] = { { 1e-6, 0 }, { 1e6, 0 }, { 1e3, 1e6 } };
    const size_t eye_scale_count = sizeof eye_scales / sizeof eye_scales[0];
    size_t total = CASE_LEAK_COUNT_ + scale_count + CASE_DEG_COUNT_ + CASE_RAY_COUNT_ + CASE_EYE_COUNT_ + eye_scale_count;
    rng random = { 0x5eed5eedull };
    for (size_t i = 0; i < total && r == VKRT_OK; i++) {
        stress_case c = { 0 };
        size_t k = i;
        if (k < CASE_LEAK_COUNT_) make_leak_case(&c, (int)k, o->quick, &random);
        else if ((k -= CASE_LEAK_COUNT_) < scale_count) {
            const double *s = o->quick ? scales_quick[k] : scales_full[k];
            make_scale_case(&c, s[0], s[1], false, o->quick, &random);
        } else if ((k -= scale_count) < CASE_DEG_COUNT_) make_degenerate_case(&c, (int)k, o->quick, &random);
        else if ((k -= CASE_DEG_COUNT_) < CASE_RAY_COUNT_) make_ray_case(&c, (int)k, o->quick, &random);
        else if ((k -= CASE_RAY_COUNT_) < CASE_EYE_COUNT_) make_eye_leak_case(&c, (int)k, o->quick);
        else make_scale_case(&c, eye_scales[k - CASE_EYE_COUNT_][0], eye_scales[k - CASE_EYE_COUNT_][1], true, o->quick,
                             &random);
        r = run_case(&u, &c);
        case_free(&c);
    }
    out->validation_messages = vkrt_context_validation_messages(u.gpu) + vkrt_context_validation_messages(u.cpu);
    if (r == VKRT_OK)
        fprintf(u.out, "\n%u rows, %u watertight row%s failed; %.1f s\n", out->rows, out->failed_rows,
                out->failed_rows == 1 ? "" : "s", now_seconds() - t0);
    vkrt_context_destroy(u.gpu);
    vkrt_context_destroy(u.cpu);
    return r;
}
