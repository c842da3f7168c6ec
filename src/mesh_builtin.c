/* The scene shown when no file is given: an icosphere, a torus and a box standing in a row
 * on a ground plane. Sphere and torus carry their analytic (smooth) normals, box and plane
 * flat ones; each object has a material of its own and texture coordinates (sphere:
 * longitude and latitude, torus: around ring and tube, box: each face the unit square,
 * ground: tiled).
 *
 * The default camera looks straight down -z from (0, 0, 1.5), so the whole arrangement is
 * tilted 30 degrees about x: the camera then sees the ground from 30 degrees above, the
 * objects side by side without overlap, and the torus ring face on. */
#include "mesh.h"

#include <math.h>
#include <string.h>

#define BUILTIN_PI 3.14159265358979323846
/* 20 * 4^4 = 5120 triangles: round to the eye at the default framing, and enough work for a
 * BVH to matter. */
#define SPHERE_SUBDIVISIONS 4
#define TORUS_SEGMENTS 72 /* around the ring */
#define TORUS_SIDES 32    /* around the tube */
#define TILT_DEGREES 30.0
#define GROUND_HALF_X 2.3f
#define GROUND_HALF_Z 1.6f
#define TORUS_MAJOR 0.5f
#define TORUS_MINOR 0.2f
/* Tipped 60 degrees toward the camera, the ring faces it once the scene tilt adds 30. */
#define TORUS_TIP_DEGREES 60.0

typedef struct mat4 {
    float m[16]; /* column-major, as mesh_primitive.transform */
} mat4;

static mat4 mat_identity(void)
{
    return (mat4){ { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 } };
}

static mat4 mat_mul(mat4 a, mat4 b)
{
    mat4 r;
    for (int col = 0; col < 4; col++)
        for (int row = 0; row < 4; row++) {
            double s = 0.0;
            for (int k = 0; k < 4; k++) s += (double)a.m[k * 4 + row] * b.m[col * 4 + k];
            r.m[col * 4 + row] = (float)s;
        }
    return r;
}

static mat4 mat_translate(float x, float y, float z)
{
    mat4 r = mat_identity();
    r.m[12] = x;
    r.m[13] = y;
    r.m[14] = z;
    return r;
}

static mat4 mat_scale(float s)
{
    mat4 r = mat_identity();
    r.m[0] = r.m[5] = r.m[10] = s;
    return r;
}

static mat4 mat_rotate_x(double degrees)
{
    double a = degrees * BUILTIN_PI / 180.0;
    mat4 r = mat_identity();
    r.m[5] = (float)cos(a);
    r.m[6] = (float)sin(a);
    r.m[9] = (float)-sin(a);
    r.m[10] = (float)cos(a);
    return r;
}

static mat4 mat_rotate_y(double degrees)
{
    double a = degrees * BUILTIN_PI / 180.0;
    mat4 r = mat_identity();
    r.m[0] = (float)cos(a);
    r.m[2] = (float)-sin(a);
    r.m[8] = (float)sin(a);
    r.m[10] = (float)cos(a);
    return r;
}

static void set3(float *v, double x, double y, double z)
{
    v[0] = (float)x;
    v[1] = (float)y;
    v[2] = (float)z;
}

/* Swaps corners 1 and 2 where a triangle's winding disagrees with its vertex normals, so
 * every surface is counter-clockwise seen from outside whatever order it was generated in. */
static void orient(const float *positions, const float *normals, uint32_t *indices, size_t tris)
{
    for (size_t t = 0; t < tris; t++) {
        uint32_t *i = indices + 3 * t;
        const float *a = positions + 3 * (size_t)i[0], *b = positions + 3 * (size_t)i[1],
                    *c = positions + 3 * (size_t)i[2];
        double e1[3] = { b[0] - a[0], b[1] - a[1], b[2] - a[2] };
        double e2[3] = { c[0] - a[0], c[1] - a[1], c[2] - a[2] };
        double n[3] = { e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0] };
        double s = 0.0;
        for (int k = 0; k < 3; k++)
            for (int j = 0; j < 3; j++) s += n[j] * normals[3 * (size_t)i[k] + j];
        if (s < 0.0) {
            uint32_t tmp = i[1];
            i[1] = i[2];
            i[2] = tmp;
        }
    }
}

/* One object of the scene with its own material. */
typedef struct object_desc {
    const float *positions, *normals, *texcoords;
    size_t vertices;
    uint32_t *indices;
    size_t tris;
    mat4 transform;
    vkrt_material material;
    const char *what;
} object_desc;

static vkrt_result append(core *c, mesh *m, const object_desc *o)
{
    orient(o->positions, o->normals, o->indices, o->tris);
    uint32_t material;
    vkrt_result r = mesh_add_material(c, m, &o->material, NULL, VKRT_ERROR_INVALID_ARGUMENT, "built-in scene", o->what,
                                      &material);
    if (r != VKRT_OK) return r;
    return mesh_append_indexed(c, m,
                               &(mesh_primitive){ .positions = o->positions, .vertex_count = o->vertices,
                                                  .indices = o->indices, .index_count = 3 * o->tris,
                                                  .normals = o->normals, .transform = o->transform.m,
                                                  .texcoords = o->texcoords, .material = MESH_MATERIAL(material) },
                               "built-in scene", o->what);
}

/* Unit icosphere: each level splits every triangle into four at its edge midpoints, pushed
 * out to the sphere. Vertices are not shared; a midpoint is computed from the same two
 * corners (a + b == b + a exactly) on both sides of an edge, so the surface stays closed. */
static vkrt_result add_sphere(core *c, mesh *m, mat4 transform)
{
    const double t = (1.0 + sqrt(5.0)) / 2.0;
    const double base[12][3] = { { -1, t, 0 }, { 1, t, 0 }, { -1, -t, 0 }, { 1, -t, 0 }, { 0, -1, t }, { 0, 1, t },
                                 { 0, -1, -t }, { 0, 1, -t }, { t, 0, -1 }, { t, 0, 1 }, { -t, 0, -1 }, { -t, 0, 1 } };
    static const uint8_t faces[20][3] = { { 0, 11, 5 }, { 0, 5, 1 },  { 0, 1, 7 },  { 0, 7, 10 }, { 0, 10, 11 },
                                          { 1, 5, 9 },  { 5, 11, 4 }, { 11, 10, 2 }, { 10, 7, 6 }, { 7, 1, 8 },
                                          { 3, 9, 4 },  { 3, 4, 2 },  { 3, 2, 6 },  { 3, 6, 8 },  { 3, 8, 9 },
                                          { 4, 9, 5 },  { 2, 4, 11 }, { 6, 2, 10 }, { 8, 6, 7 },  { 9, 8, 1 } };
    size_t tris = 20;
    for (int level = 0; level < SPHERE_SUBDIVISIONS; level++) tris *= 4;
    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    float *a = core_alloc_array(c, tris, 9 * sizeof(float));
    float *b = core_alloc_array(c, tris, 9 * sizeof(float));
    float *uv = core_alloc_array(c, tris, 6 * sizeof(float));
    uint32_t *indices = core_alloc_array(c, tris, 3 * sizeof(uint32_t));
    if (!a || !b || !uv || !indices) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "built-in scene: out of memory making the icosphere");
        goto done;
    }
    double len = sqrt(1.0 + t * t);
    for (size_t f = 0; f < 20; f++)
        for (int k = 0; k < 3; k++) {
            const double *v = base[faces[f][k]];
            set3(a + 9 * f + 3 * k, v[0] / len, v[1] / len, v[2] / len);
        }
    size_t count = 20;
    for (int level = 0; level < SPHERE_SUBDIVISIONS; level++) {
        for (size_t f = 0; f < count; f++) {
            const float *v = a + 9 * f;
            float mid[3][3]; /* ab, bc, ca */
            for (int e = 0; e < 3; e++) {
                const float *p = v + 3 * e, *q = v + 3 * ((e + 1) % 3);
                double x = (double)(p[0] + q[0]), y = (double)(p[1] + q[1]), z = (double)(p[2] + q[2]);
                double l = sqrt(x * x + y * y + z * z);
                set3(mid[e], x / l, y / l, z / l);
            }
            const float *corner[4][3] = { { v, mid[0], mid[2] }, { mid[0], v + 3, mid[1] },
                                          { mid[2], mid[1], v + 6 }, { mid[0], mid[1], mid[2] } };
            for (int child = 0; child < 4; child++)
                for (int k = 0; k < 3; k++) memcpy(b + 9 * (4 * f + child) + 3 * k, corner[child][k], 3 * sizeof(float));
        }
        count *= 4;
        float *swap = a;
        a = b;
        b = swap;
    }
    for (size_t i = 0; i < 3 * tris; i++) {
        indices[i] = (uint32_t)i;
        /* Longitude and latitude, each over [0, 1]. */
        const float *p = a + 3 * i;
        uv[2 * i] = (float)(atan2((double)p[2], (double)p[0]) / (2.0 * BUILTIN_PI) + 0.5);
        uv[2 * i + 1] = (float)(acos(fmax(-1.0, fmin(1.0, (double)p[1]))) / BUILTIN_PI);
    }
    /* On the unit sphere the position is the normal. */
    const object_desc o = { a, a, uv, 3 * tris, indices, tris, transform,
                            { .base_color = { 0.80f, 0.22f, 0.18f, 1.0f }, .roughness = 0.4f }, "icosphere" };
    r = append(c, m, &o);
done:
    core_free(c, a);
    core_free(c, b);
    core_free(c, uv);
    core_free(c, indices);
    return r;
}

/* Torus around the y axis through the origin. */
static vkrt_result add_torus(core *c, mesh *m, mat4 transform)
{
    const size_t nu = TORUS_SEGMENTS, nv = TORUS_SIDES, vertices = nu * nv, tris = 2 * nu * nv;
    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    float *positions = core_alloc_array(c, vertices, 3 * sizeof(float));
    float *normals = core_alloc_array(c, vertices, 3 * sizeof(float));
    float *uv = core_alloc_array(c, vertices, 2 * sizeof(float));
    uint32_t *indices = core_alloc_array(c, tris, 3 * sizeof(uint32_t));
    if (!positions || !normals || !uv || !indices) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "built-in scene: out of memory making the torus");
        goto done;
    }
    for (size_t i = 0; i < nu; i++) {
        double u = 2.0 * BUILTIN_PI * (double)i / (double)nu;
        for (size_t j = 0; j < nv; j++) {
            double v = 2.0 * BUILTIN_PI * (double)j / (double)nv;
            size_t k = i * nv + j;
            set3(normals + 3 * k, cos(u) * cos(v), sin(v), sin(u) * cos(v));
            double ring = TORUS_MAJOR + TORUS_MINOR * cos(v);
            set3(positions + 3 * k, ring * cos(u), TORUS_MINOR * sin(v), ring * sin(u));
            uv[2 * k] = (float)i / (float)nu; /* around the ring, around the tube */
            uv[2 * k + 1] = (float)j / (float)nv;
        }
    }
    uint32_t *out = indices;
    for (size_t i = 0; i < nu; i++)
        for (size_t j = 0; j < nv; j++) {
            uint32_t a = (uint32_t)(i * nv + j), b = (uint32_t)(((i + 1) % nu) * nv + j),
                     cc = (uint32_t)(((i + 1) % nu) * nv + (j + 1) % nv), d = (uint32_t)(i * nv + (j + 1) % nv);
            const uint32_t quad[6] = { a, b, cc, a, cc, d };
            memcpy(out, quad, sizeof quad);
            out += 6;
        }
    const object_desc o = { positions, normals, uv, vertices, indices, tris, transform,
                            { .base_color = { 1.0f, 0.78f, 0.34f, 1.0f }, .metallic = 1.0f, .roughness = 0.3f },
                            "torus" };
    r = append(c, m, &o);
done:
    core_free(c, positions);
    core_free(c, normals);
    core_free(c, uv);
    core_free(c, indices);
    return r;
}

/* Axis-aligned box [-1, 1]^3 with 4 vertices per face, so each face keeps its own normal. */
static vkrt_result add_box(core *c, mesh *m, mat4 transform)
{
    float positions[24 * 3], normals[24 * 3], uv[24 * 2];
    uint32_t indices[36];
    for (int face = 0; face < 6; face++) {
        int axis = face / 2;
        float s = face % 2 ? -1.0f : 1.0f;
        int u = (axis + 1) % 3, v = (axis + 2) % 3;
        static const float corners[4][2] = { { -1, -1 }, { 1, -1 }, { 1, 1 }, { -1, 1 } };
        for (int k = 0; k < 4; k++) {
            float *p = positions + 3 * (4 * face + k), *n = normals + 3 * (4 * face + k);
            p[axis] = s;
            p[u] = corners[k][0];
            p[v] = corners[k][1];
            n[axis] = s;
            n[u] = n[v] = 0.0f;
            uv[2 * (4 * face + k)] = 0.5f * (corners[k][0] + 1.0f); /* each face the whole square */
            uv[2 * (4 * face + k) + 1] = 0.5f * (corners[k][1] + 1.0f);
        }
        const uint32_t base = (uint32_t)(4 * face), quad[6] = { base, base + 1, base + 2, base, base + 2, base + 3 };
        memcpy(indices + 6 * face, quad, sizeof quad);
    }
    const object_desc o = { positions, normals, uv, 24, indices, 12, transform,
                            { .base_color = { 0.18f, 0.32f, 0.78f, 1.0f }, .roughness = 0.6f }, "box" };
    return append(c, m, &o);
}

static vkrt_result add_ground(core *c, mesh *m, mat4 transform)
{
    const float x = GROUND_HALF_X, z = GROUND_HALF_Z;
    float positions[12] = { -x, 0, z, x, 0, z, x, 0, -z, -x, 0, -z };
    float normals[12] = { 0, 1, 0, 0, 1, 0, 0, 1, 0, 0, 1, 0 };
    float uv[8] = { 0, 0, 4, 0, 4, 3, 0, 3 }; /* tiles of about one unit */
    uint32_t indices[6] = { 0, 1, 2, 0, 2, 3 };
    const object_desc o = { positions, normals, uv, 4, indices, 2, transform,
                            { .base_color = { 0.70f, 0.70f, 0.68f, 1.0f }, .roughness = 1.0f }, "ground plane" };
    return append(c, m, &o);
}

vkrt_result mesh_make_builtin(core *c, mesh *m)
{
    memset(m, 0, sizeof *m);
    const mat4 tilt = mat_rotate_x(TILT_DEGREES);
    const float sphere_radius = 0.6f, box_half = 0.45f;
    /* The lowest point of a torus tipped by angle a is R sin(a) + r below its centre. */
    const float torus_lift = (float)(TORUS_MAJOR * sin(TORUS_TIP_DEGREES * BUILTIN_PI / 180.0) + TORUS_MINOR);
    const mat4 sphere = mat_mul(tilt, mat_mul(mat_translate(-1.5f, sphere_radius, 0.2f), mat_scale(sphere_radius)));
    const mat4 torus = mat_mul(tilt, mat_mul(mat_translate(0.0f, torus_lift, -0.2f), mat_rotate_x(TORUS_TIP_DEGREES)));
    const mat4 box = mat_mul(tilt, mat_mul(mat_translate(1.5f, box_half, 0.2f),
                                           mat_mul(mat_rotate_y(30.0), mat_scale(box_half))));
    vkrt_result r;
    if ((r = add_ground(c, m, tilt)) != VKRT_OK) goto done;
    if ((r = add_sphere(c, m, sphere)) != VKRT_OK) goto done;
    if ((r = add_torus(c, m, torus)) != VKRT_OK) goto done;
    r = add_box(c, m, box);
done:
    return mesh_finish(c, m, r);
}
