/* The triangle soup every loader fills: validation, world transform, vertex normals, bounds,
 * normalisation and the choice of loader for a file.
 *
 * Missing vertex normals are angle-weighted averages of the adjacent face normals, after
 * Thuermer and Wüthrich, "Computing vertex normals from polygonal facets" (JGT 3(1), 1998):
 * unlike area weighting, the result does not change when a face is split into thinner
 * triangles. */
#include "mesh.h"

#include <errno.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include "texture.h"

/* One per-triangle array moved into a larger allocation (the first tri_count entries kept). */
typedef struct grown {
    void **array;
    size_t per_triangle; /* bytes */
    void *fresh;
} grown;

/* Room for `needed` triangles in every per-triangle array, which share one capacity. */
static int reserve(core *c, mesh *m, size_t needed)
{
    if (needed <= m->tri_capacity) return 0;
    size_t cap = m->tri_capacity ? m->tri_capacity : 64;
    while (cap < needed) {
        if (cap > SIZE_MAX / 2) return -1;
        cap *= 2;
    }
    grown arrays[] = {
        { (void **)&m->positions, 9 * sizeof(float), NULL },
        { (void **)&m->normals, 9 * sizeof(float), NULL },
        { (void **)&m->texcoords, 6 * sizeof(float), NULL },
        { (void **)&m->material_ids, sizeof(uint32_t), NULL },
    };
    enum { ARRAYS = sizeof arrays / sizeof arrays[0] };
    bool ok = true;
    for (int i = 0; i < ARRAYS; i++) ok = (arrays[i].fresh = core_alloc_array(c, cap, arrays[i].per_triangle)) && ok;
    for (int i = 0; i < ARRAYS; i++) {
        if (!ok) {
            core_free(c, arrays[i].fresh);
            continue;
        }
        if (m->tri_count) memcpy(arrays[i].fresh, *arrays[i].array, (size_t)m->tri_count * arrays[i].per_triangle);
        core_free(c, *arrays[i].array);
        *arrays[i].array = arrays[i].fresh;
    }
    if (!ok) return -1;
    m->tri_capacity = cap;
    return 0;
}

vkrt_result mesh_add_texture(core *c, mesh *m, const vkrt_texture_desc *desc, texture_encoding encoding,
                             vkrt_result invalid, const char *source, const char *what, uint32_t *out_index)
{
    if (!desc->rgba8) return core_fail(c, invalid, "%s: %s: texture without pixels", source, what);
    if (desc->width == 0 || desc->height == 0 || desc->width > TEXTURE_MAX_SIDE || desc->height > TEXTURE_MAX_SIDE ||
        (uint64_t)desc->width * desc->height > TEXTURE_MAX_TEXELS)
        return core_fail(c, invalid, "%s: %s: texture of %ux%u texels (each side 1 to %u, at most %u in all)", source,
                         what, desc->width, desc->height, TEXTURE_MAX_SIDE, TEXTURE_MAX_TEXELS);
    if ((unsigned)desc->wrap_u > VKRT_WRAP_MIRROR || (unsigned)desc->wrap_v > VKRT_WRAP_MIRROR)
        return core_fail(c, invalid, "%s: %s: texture wrap mode has no valid value", source, what);
    if (m->texture_count == m->texture_capacity) {
        uint32_t cap = m->texture_capacity ? m->texture_capacity * 2 : 4;
        mesh_texture *fresh = cap > m->texture_capacity ? core_alloc_array(c, cap, sizeof *fresh) : NULL;
        if (!fresh) return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory for %u textures", source, cap);
        if (m->texture_count) memcpy(fresh, m->textures, m->texture_count * sizeof *fresh);
        core_free(c, m->textures);
        m->textures = fresh;
        m->texture_capacity = cap;
    }
    uint32_t *texels = core_alloc_array(c, (size_t)desc->width * desc->height, 2 * sizeof(uint32_t));
    if (!texels)
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory for a %ux%u texture", source, what,
                         desc->width, desc->height);
    if (encoding == TEXTURE_LINEAR) texture_encode_rgba8_linear(desc->rgba8, desc->width, desc->height, texels);
    else texture_encode_rgba8(desc->rgba8, desc->width, desc->height, texels);
    m->textures[m->texture_count] = (mesh_texture){ desc->width, desc->height,
                                                    (uint32_t)desc->wrap_u | (uint32_t)desc->wrap_v << 8, texels };
    *out_index = m->texture_count++;
    return VKRT_OK;
}

vkrt_result mesh_add_material(core *c, mesh *m, const vkrt_material *mat, const mesh_material_textures *textures,
                              vkrt_result invalid, const char *source, const char *what, uint32_t *out_index)
{
    const struct {
        const char *name;
        const float *values;
        int count;
        float max; /* INFINITY: no upper bound */
    } fields[] = {
        { "base_color", mat->base_color, 4, 1.0f },
        { "metallic", &mat->metallic, 1, 1.0f },
        { "roughness", &mat->roughness, 1, 1.0f },
        { "emissive", mat->emissive, 3, INFINITY },
        { "alpha_cutoff", &mat->alpha_cutoff, 1, 1.0f },
    };
    for (size_t f = 0; f < sizeof fields / sizeof fields[0]; f++)
        for (int i = 0; i < fields[f].count; i++) {
            float v = fields[f].values[i];
            if (!(v >= 0.0f && v <= fields[f].max) || !isfinite(v))
                return core_fail(c, invalid, "%s: %s: material %s[%d] is %g, outside [0, %g]", source, what,
                                 fields[f].name, i, (double)v, (double)fields[f].max);
        }
    const mesh_material_textures t = textures ? *textures : MESH_NO_TEXTURES;
    const struct {
        const char *name;
        uint32_t index;
        uint32_t **table; /* the mesh's per-material array for this kind */
    } kinds[] = {
        { "base colour", t.base_color, &m->material_textures },
        { "metallic-roughness", t.metallic_roughness, &m->material_metallic_roughness_textures },
        { "emissive", t.emissive, &m->material_emissive_textures },
    };
    enum { KINDS = sizeof kinds / sizeof kinds[0] };
    for (int k = 0; k < KINDS; k++)
        if (kinds[k].index != VKRT_NO_TEXTURE && kinds[k].index >= m->texture_count)
            return core_fail(c, invalid, "%s: %s: %s texture %u of %u does not exist", source, what, kinds[k].name,
                             kinds[k].index, m->texture_count);
    if (m->material_count == m->material_capacity) {
        uint32_t cap = m->material_capacity ? m->material_capacity * 2 : 8;
        vkrt_material *fresh = cap > m->material_capacity ? core_alloc_array(c, cap, sizeof *fresh) : NULL;
        uint32_t *fresh_textures[KINDS];
        bool ok = fresh != NULL;
        for (int k = 0; k < KINDS; k++)
            ok = (fresh_textures[k] = ok ? core_alloc_array(c, cap, sizeof(uint32_t)) : NULL) != NULL;
        if (!ok) {
            core_free(c, fresh);
            for (int k = 0; k < KINDS; k++) core_free(c, fresh_textures[k]);
            return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory for %u materials", source, cap);
        }
        if (m->material_count) memcpy(fresh, m->materials, m->material_count * sizeof *fresh);
        core_free(c, m->materials);
        m->materials = fresh;
        for (int k = 0; k < KINDS; k++) {
            if (m->material_count) memcpy(fresh_textures[k], *kinds[k].table, m->material_count * sizeof(uint32_t));
            core_free(c, *kinds[k].table);
            *kinds[k].table = fresh_textures[k];
        }
        m->material_capacity = cap;
    }
    vkrt_material *stored = &m->materials[m->material_count];
    *stored = *mat;
    /* The caller's, gone after the call; the mesh keeps texture indices instead. */
    stored->base_color_texture = NULL;
    stored->metallic_roughness_texture = NULL;
    stored->emissive_texture = NULL;
    for (int k = 0; k < KINDS; k++) (*kinds[k].table)[m->material_count] = kinds[k].index;
    *out_index = m->material_count++;
    return VKRT_OK;
}

vkrt_result mesh_add_light(core *c, mesh *m, const vkrt_light *light, vkrt_result invalid, const char *source,
                           const char *what)
{
    if (light->type != VKRT_LIGHT_DIRECTIONAL && light->type != VKRT_LIGHT_POINT)
        return core_fail(c, invalid, "%s: %s: light type %d is neither directional nor point", source, what,
                         (int)light->type);
    for (int i = 0; i < 3; i++) {
        if (!isfinite(light->vector[i]))
            return core_fail(c, invalid, "%s: %s: light %s has a non-finite coordinate (%g)", source, what,
                             light->type == VKRT_LIGHT_POINT ? "position" : "direction", (double)light->vector[i]);
        if (!(light->color[i] >= 0.0f) || !isfinite(light->color[i]))
            return core_fail(c, invalid, "%s: %s: light colour[%d] is %g; it must be finite and >= 0", source, what,
                             i, (double)light->color[i]);
    }
    if (light->type == VKRT_LIGHT_DIRECTIONAL && light->vector[0] == 0.0f && light->vector[1] == 0.0f &&
        light->vector[2] == 0.0f)
        return core_fail(c, invalid, "%s: %s: directional light without a direction (0, 0, 0)", source, what);
    if (m->light_count == m->light_capacity) {
        if (m->light_capacity > UINT32_MAX / 2)
            return core_fail(c, VKRT_ERROR_LIMIT, "%s: %s: more than %u lights", source, what, m->light_capacity);
        uint32_t cap = m->light_capacity ? m->light_capacity * 2 : 4;
        vkrt_light *fresh = core_alloc_array(c, cap, sizeof *fresh);
        if (!fresh) return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory for %u lights", source, cap);
        if (m->light_count) memcpy(fresh, m->lights, m->light_count * sizeof *fresh);
        core_free(c, m->lights);
        m->lights = fresh;
        m->light_capacity = cap;
    }
    m->lights[m->light_count++] = *light;
    return VKRT_OK;
}

static bool finite3(const float *v)
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static const float *first_non_finite(const float *v)
{
    for (int i = 0; i < 3; i++)
        if (!isfinite(v[i])) return &v[i];
    return NULL;
}

static void cross(const double a[3], const double b[3], double out[3])
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static double dot(const double a[3], const double b[3])
{
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* Scales v to unit length in place; false (v untouched) when that is impossible. */
static bool normalize3(double v[3])
{
    double len = sqrt(dot(v, v));
    if (!(len > 0.0) || !isfinite(len)) return false;
    v[0] /= len;
    v[1] /= len;
    v[2] /= len;
    return true;
}

/* The unit normal of triangle (a, b, c) counter-clockwise, flipped by `sign`; (0, 0, 1) when
 * the triangle has no area. */
static void face_normal(const float *a, const float *b, const float *c, double sign, double out[3])
{
    double e1[3] = { (double)b[0] - a[0], (double)b[1] - a[1], (double)b[2] - a[2] };
    double e2[3] = { (double)c[0] - a[0], (double)c[1] - a[1], (double)c[2] - a[2] };
    cross(e1, e2, out);
    out[0] *= sign;
    out[1] *= sign;
    out[2] *= sign;
    if (!normalize3(out)) {
        out[0] = 0.0;
        out[1] = 0.0;
        out[2] = 1.0;
    }
}

/* Angle at corner p between the edges to q and r, in [0, pi]; atan2 stays accurate for the
 * near-0 and near-pi angles of slivers where acos of a dot product does not. */
static double corner_angle(const float *p, const float *q, const float *r)
{
    double u[3] = { (double)q[0] - p[0], (double)q[1] - p[1], (double)q[2] - p[2] };
    double v[3] = { (double)r[0] - p[0], (double)r[1] - p[1], (double)r[2] - p[2] };
    double n[3];
    cross(u, v, n);
    return atan2(sqrt(dot(n, n)), dot(u, v));
}

static void transform_point(const float *t, const float *p, float *out)
{
    for (int i = 0; i < 3; i++)
        out[i] = (float)((double)t[i] * p[0] + (double)t[4 + i] * p[1] + (double)t[8 + i] * p[2] +
                         (double)t[12 + i]);
}

vkrt_result mesh_append_indexed(core *c, mesh *m, const mesh_primitive *p, const char *source,
                                const char *what)
{
    if (!p || (p->vertex_count && !p->positions))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "%s: %s: primitive without positions", source, what);
    size_t index_count = p->indices ? p->index_count : p->vertex_count;
    if (index_count % 3)
        return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY, "%s: %s: %zu %s is not a multiple of 3", source, what,
                         index_count, p->indices ? "indices" : "vertices");
    size_t tris = index_count / 3;
    if (tris == 0) return VKRT_OK;
    if (tris > UINT32_MAX - (size_t)m->tri_count)
        return core_fail(c, VKRT_ERROR_LIMIT, "%s: %s: more than %u triangles in all", source, what, UINT32_MAX);

    const size_t nv = p->vertex_count;
    for (size_t v = 0; v < nv; v++) {
        const float *bad = first_non_finite(p->positions + 3 * v);
        if (bad)
            return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY, "%s: %s: vertex %zu has a non-finite coordinate (%g)",
                             source, what, v, (double)*bad);
        if (p->normals && (bad = first_non_finite(p->normals + 3 * v)))
            return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY, "%s: %s: the normal of vertex %zu is non-finite (%g)",
                             source, what, v, (double)*bad);
        if (p->texcoords && (!isfinite(p->texcoords[2 * v]) || !isfinite(p->texcoords[2 * v + 1])))
            return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY,
                             "%s: %s: the texture coordinates of vertex %zu are non-finite", source, what, v);
    }
    if (p->material > m->material_count)
        return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY, "%s: %s: material %u of %u does not exist", source, what,
                         p->material - 1, m->material_count);
    if (p->indices) {
        for (size_t i = 0; i < index_count; i++)
            if (p->indices[i] >= nv)
                return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY,
                                 "%s: %s: index %zu is %u, out of range for %zu vertices", source, what, i,
                                 p->indices[i], nv);
    }
    if (p->transform) {
        for (int i = 0; i < 16; i++)
            if (!isfinite(p->transform[i]))
                return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY, "%s: %s: the transform has a non-finite element",
                                 source, what);
    }

    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    float *world = NULL;
    double *accum = NULL;
    /* Without a transform the file's coordinates are used as they are, bit for bit. */
    const float *pos = p->positions;
    if (p->transform) {
        world = core_alloc_array(c, nv, 3 * sizeof(float));
        if (!world) goto oom;
        for (size_t v = 0; v < nv; v++) {
            transform_point(p->transform, p->positions + 3 * v, world + 3 * v);
            if (!finite3(world + 3 * v)) {
                r = core_fail(c, VKRT_ERROR_INVALID_GEOMETRY,
                              "%s: %s: vertex %zu overflows to a non-finite coordinate after the transform", source,
                              what, v);
                goto done;
            }
        }
        pos = world;
    }

    /* Normals go through the cofactor matrix, det(M) * inverse-transpose(M): the same direction
     * as the inverse transpose once the sign of det is applied, and still defined for a
     * singular M (a scale of 0 flattens the mesh, and its normals then all point along the
     * flattened axis). A mirroring transform (det < 0) reverses the winding, so computed face
     * normals are flipped to keep pointing out of the surface. */
    double cof[9] = { 1, 0, 0, 0, 1, 0, 0, 0, 1 }; /* row-major: n' = cof * n */
    double sign = 1.0;
    if (p->transform) {
        const float *t = p->transform;
        double a[3][3]; /* a[row][col] */
        for (int row = 0; row < 3; row++)
            for (int col = 0; col < 3; col++) a[row][col] = t[col * 4 + row];
        for (int row = 0; row < 3; row++) {
            for (int col = 0; col < 3; col++) {
                int r0 = (row + 1) % 3, r1 = (row + 2) % 3, c0 = (col + 1) % 3, c1 = (col + 2) % 3;
                cof[row * 3 + col] = a[r0][c0] * a[r1][c1] - a[r0][c1] * a[r1][c0];
            }
        }
        double det = a[0][0] * cof[0] + a[0][1] * cof[1] + a[0][2] * cof[2];
        if (det < 0.0) {
            sign = -1.0;
            for (int i = 0; i < 9; i++) cof[i] = -cof[i];
        }
    }

    if (!p->normals) {
        accum = core_calloc_array(c, nv, 3 * sizeof(double));
        if (!accum) goto oom;
        for (size_t t = 0; t < tris; t++) {
            uint32_t idx[3];
            for (int k = 0; k < 3; k++) idx[k] = p->indices ? p->indices[3 * t + k] : (uint32_t)(3 * t + k);
            const float *v0 = pos + 3 * (size_t)idx[0], *v1 = pos + 3 * (size_t)idx[1], *v2 = pos + 3 * (size_t)idx[2];
            double e1[3] = { (double)v1[0] - v0[0], (double)v1[1] - v0[1], (double)v1[2] - v0[2] };
            double e2[3] = { (double)v2[0] - v0[0], (double)v2[1] - v0[1], (double)v2[2] - v0[2] };
            double n[3];
            cross(e1, e2, n);
            if (!normalize3(n)) continue; /* zero area: no direction to contribute */
            double w[3] = { corner_angle(v0, v1, v2), corner_angle(v1, v2, v0), corner_angle(v2, v0, v1) };
            for (int k = 0; k < 3; k++)
                for (int j = 0; j < 3; j++) accum[3 * (size_t)idx[k] + j] += sign * w[k] * n[j];
        }
    }

    uint32_t material = p->material - 1;
    if (p->material == 0) {
        if (!m->has_default_material) {
            const vkrt_material fallback = vkrt_material_default();
            if ((r = mesh_add_material(c, m, &fallback, NULL, VKRT_ERROR_INVALID_ARGUMENT, source, what,
                                       &m->default_material)) != VKRT_OK)
                goto done;
            m->has_default_material = true;
        }
        material = m->default_material;
    }
    if (reserve(c, m, (size_t)m->tri_count + tris) != 0) goto oom;
    if (p->texcoords) m->has_texcoords = true;
    for (size_t t = 0; t < tris; t++) {
        uint32_t idx[3];
        for (int k = 0; k < 3; k++) idx[k] = p->indices ? p->indices[3 * t + k] : (uint32_t)(3 * t + k);
        size_t out = (size_t)m->tri_count + t;
        float *out_p = m->positions + out * 9;
        float *out_n = m->normals + out * 9;
        float *out_uv = m->texcoords + out * 6;
        m->material_ids[out] = material;
        for (int k = 0; k < 3; k++) {
            out_uv[2 * k] = p->texcoords ? p->texcoords[2 * (size_t)idx[k]] : 0.0f;
            out_uv[2 * k + 1] = p->texcoords ? p->texcoords[2 * (size_t)idx[k] + 1] : 0.0f;
        }
        for (int k = 0; k < 3; k++) memcpy(out_p + 3 * k, pos + 3 * (size_t)idx[k], 3 * sizeof(float));
        double fallback[3];
        face_normal(out_p, out_p + 3, out_p + 6, sign, fallback);
        for (int k = 0; k < 3; k++) {
            double n[3];
            if (p->normals) {
                const float *src = p->normals + 3 * (size_t)idx[k];
                for (int j = 0; j < 3; j++)
                    n[j] = cof[j * 3 + 0] * src[0] + cof[j * 3 + 1] * src[1] + cof[j * 3 + 2] * src[2];
            } else {
                memcpy(n, accum + 3 * (size_t)idx[k], sizeof n);
            }
            if (!normalize3(n)) memcpy(n, fallback, sizeof n);
            for (int j = 0; j < 3; j++) out_n[3 * k + j] = (float)n[j];
        }
    }
    m->tri_count += (uint32_t)tris;
    r = VKRT_OK;
    goto done;
oom:
    r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory appending %zu triangles", source, what, tris);
done:
    core_free(c, world);
    core_free(c, accum);
    return r;
}

void mesh_update_bounds(mesh *m)
{
    if (m->tri_count == 0) {
        memset(m->bounds_min, 0, sizeof m->bounds_min);
        memset(m->bounds_max, 0, sizeof m->bounds_max);
        return;
    }
    for (int j = 0; j < 3; j++) m->bounds_min[j] = m->bounds_max[j] = m->positions[j];
    size_t corners = (size_t)m->tri_count * 3;
    for (size_t i = 0; i < corners; i++) {
        const float *v = m->positions + 3 * i;
        for (int j = 0; j < 3; j++) {
            if (v[j] < m->bounds_min[j]) m->bounds_min[j] = v[j];
            if (v[j] > m->bounds_max[j]) m->bounds_max[j] = v[j];
        }
    }
}

vkrt_result mesh_normalize(core *c, mesh *m, const char *source)
{
    mesh_update_bounds(m);
    if (m->tri_count == 0) return VKRT_OK;
    double centre[3], extent = 0.0;
    for (int j = 0; j < 3; j++) {
        centre[j] = 0.5 * ((double)m->bounds_min[j] + (double)m->bounds_max[j]);
        double e = (double)m->bounds_max[j] - (double)m->bounds_min[j];
        if (e > extent) extent = e;
    }
    /* Finite in double, but the float boxes and ray distances of such a scene overflow. */
    if (!(extent <= FLT_MAX))
        return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY,
                         "%s: coordinates span %.3g, beyond the float range (%.3g): cannot normalise", source,
                         extent, (double)FLT_MAX);
    double scale = extent > 0.0 ? 1.0 / extent : 1.0;
    /* Point lights move with the geometry. Irradiance from a point light is I / d^2, and every
     * distance d scales by `scale`: I times scale^2 lights the surfaces as before. The first pass
     * only checks, so a light that leaves the float range (far from a tiny scene) fails before
     * anything has moved. */
    for (int pass = 0; pass < 2; pass++)
        for (uint32_t i = 0; i < m->light_count; i++) {
            if (m->lights[i].type != VKRT_LIGHT_POINT) continue; /* a direction is the same at any scale */
            vkrt_light l = m->lights[i];
            for (int j = 0; j < 3; j++) {
                l.vector[j] = (float)(((double)l.vector[j] - centre[j]) * scale);
                l.color[j] = (float)((double)l.color[j] * scale * scale);
            }
            if (pass == 1) m->lights[i] = l;
            else if (!finite3(l.vector) || !finite3(l.color))
                return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY,
                                 "%s: point light %u leaves the float range when the scene is normalised (scale %.3g)",
                                 source, i, scale);
        }
    size_t corners = (size_t)m->tri_count * 3;
    for (size_t i = 0; i < corners; i++) {
        float *v = m->positions + 3 * i;
        for (int j = 0; j < 3; j++) v[j] = (float)(((double)v[j] - centre[j]) * scale);
    }
    /* A uniform scale and a translation leave unit normals as they are. */
    mesh_update_bounds(m);
    return VKRT_OK;
}

vkrt_result mesh_finish(core *c, mesh *m, vkrt_result r)
{
    if (r == VKRT_OK) mesh_update_bounds(m);
    else mesh_destroy(c, m);
    return r;
}

void mesh_destroy(core *c, mesh *m)
{
    if (!m) return;
    core_free(c, m->positions);
    core_free(c, m->normals);
    core_free(c, m->texcoords);
    core_free(c, m->material_ids);
    core_free(c, m->materials);
    core_free(c, m->material_textures);
    core_free(c, m->material_metallic_roughness_textures);
    core_free(c, m->material_emissive_textures);
    core_free(c, m->lights);
    for (uint32_t i = 0; i < m->texture_count; i++) core_free(c, m->textures[i].texels);
    core_free(c, m->textures);
    memset(m, 0, sizeof *m);
}

/* True when the part of path after its last '/' ends in ext, ignoring case. */
static bool has_extension(const char *path, const char *ext)
{
    const char *slash = strrchr(path, '/');
    const char *name = slash ? slash + 1 : path;
    size_t n = strlen(name), e = strlen(ext);
    if (n <= e) return false;
    const char *tail = name + n - e;
    for (size_t i = 0; i < e; i++) {
        char ch = tail[i];
        if (ch >= 'A' && ch <= 'Z') ch = (char)(ch - 'A' + 'a');
        if (ch != ext[i]) return false;
    }
    return true;
}

vkrt_result mesh_load(core *c, const char *path, mesh *m)
{
    memset(m, 0, sizeof *m);
    if (!path) return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "mesh path is NULL");
    /* The content decides first: a GLB renamed .obj or without extension still loads. */
    FILE *f = fopen(path, "rb");
    if (!f) return core_fail(c, VKRT_ERROR_IO, "%s: cannot open: %s", path, strerror(errno));
    unsigned char magic[4] = { 0 };
    size_t got = fread(magic, 1, sizeof magic, f);
    int read_errno = ferror(f) ? errno : 0;
    fclose(f);
    if (read_errno) return core_fail(c, VKRT_ERROR_IO, "%s: cannot read: %s", path, strerror(read_errno));
    if (got == 4 && memcmp(magic, "glTF", 4) == 0) return mesh_load_gltf(c, path, m);
    if (has_extension(path, ".gltf") || has_extension(path, ".glb")) return mesh_load_gltf(c, path, m);
    if (has_extension(path, ".obj")) return mesh_load_obj(c, path, m);
    return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: unknown mesh format (expected .obj, .gltf or .glb)", path);
}
