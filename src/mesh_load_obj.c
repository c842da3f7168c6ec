/* Wavefront OBJ through tinyobjloader's callback parser (third_party/tinyobj_shim.h).
 *
 * The file is read whole, screened for what tinyobjloader accepts silently (binary bytes, and
 * "nan"/"inf" coordinates, which it turns into 0), then parsed statement by statement. Faces
 * are fanned from their first corner as they arrive, so triangles stay in file order; each
 * `o`/`g` starts a new primitive for mesh_append_indexed(), which smooths computed normals
 * only within it. Index checks wait for the end of the file, because an OBJ face may name a
 * vertex defined further down. */
#include "mesh.h"

#include <errno.h>
#include <math.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include "tinyobj_shim.h"

typedef struct obj_tri {
    int64_t v[3];  /* 0-based position indices, range-checked after parsing */
    int64_t vn[3]; /* 0-based normal indices, or -1 where the face has no complete set */
    int64_t vt[3]; /* 0-based texture coordinate indices, or -1 likewise */
    size_t face;   /* 1-based `f` statement it came from */
    int material;  /* index into the .mtl materials (`usemtl`), -1: the default */
} obj_tri;

typedef struct obj_state {
    core *c;
    mesh *m;               /* the materials go straight into it */
    const char *path;
    char *directory;       /* of path, ending in '/' ("" for the current one): .mtl and textures */
    uint32_t *materials;   /* per .mtl material: MESH_MATERIAL(its index in m) */
    size_t material_count, material_capacity;
    int current_material;
    const char *text;
    size_t size;
    vkrt_result error; /* first failure inside a callback; later statements are ignored */
    float *positions;
    size_t position_count, position_capacity;
    float *normals;
    size_t normal_count, normal_capacity;
    float *texcoords;      /* `vt` as (u, v, 0) triples */
    size_t texcoord_count, texcoord_capacity;
    obj_tri *tris;
    size_t tri_count, tri_capacity;
    size_t *object_starts; /* first triangle of each `o`/`g` run */
    size_t object_count, object_capacity;
    size_t face_count, short_faces;
} obj_state;

typedef struct obj_scan {
    size_t vertices, lines, points, statements, unknown;
} obj_scan;

static bool is_blank(char ch)
{
    return ch == ' ' || ch == '\t';
}

/* End of the line starting at i: the index of its '\r' or '\n' (or size). Line breaks are
 * "\n", "\r\n" and a lone "\r", as tinyobjloader's safeGetline reads them. */
static size_t line_end(const char *text, size_t size, size_t i)
{
    while (i < size && text[i] != '\n' && text[i] != '\r') i++;
    return i;
}

static size_t next_line(const char *text, size_t size, size_t end)
{
    if (end < size && text[end] == '\r' && end + 1 < size && text[end + 1] == '\n') return end + 2;
    return end < size ? end + 1 : size;
}

static bool keyword(const char *s, size_t n, const char *word)
{
    size_t w = strlen(word);
    /* tinyobjloader wants a blank after the keyword, so a bare "v" is no statement. */
    return n > w && memcmp(s, word, w) == 0 && is_blank(s[w]);
}

/* 1-based line number of the k-th (1-based) statement starting with word; 0 if none. Only
 * used to word error messages, so the extra pass costs nothing on the success path. */
static size_t statement_line(const char *text, size_t size, const char *word, size_t k)
{
    size_t line = 0, seen = 0;
    for (size_t i = 0; i < size;) {
        size_t end = line_end(text, size, i);
        line++;
        size_t s = i;
        while (s < end && is_blank(text[s])) s++;
        if (keyword(text + s, end - s, word) && ++seen == k) return line;
        i = next_line(text, size, end);
    }
    return 0;
}

static bool word_ci(const char *s, size_t n, const char *word)
{
    size_t w = strlen(word);
    if (n < w) return false;
    for (size_t i = 0; i < w; i++) {
        char ch = s[i];
        if (ch >= 'A' && ch <= 'Z') ch = (char)(ch - 'A' + 'a');
        if (ch != word[i]) return false;
    }
    return true;
}

/* Rejects what tinyobjloader would accept silently and counts what it ignores silently. */
static vkrt_result scan_text(core *c, const char *path, const char *text, size_t size, obj_scan *out)
{
    memset(out, 0, sizeof *out);
    for (size_t i = 0; i < size; i++) {
        unsigned char ch = (unsigned char)text[i];
        /* Text never holds control characters other than whitespace (and DOS's end-of-file
         * mark); tinyobjloader would read a binary file as a run of unknown statements. */
        if (ch < 0x20 && ch != '\t' && ch != '\n' && ch != '\r' && ch != '\v' && ch != '\f' && ch != 0x1a)
            return core_fail(c, VKRT_ERROR_PARSE, "%s: not an OBJ file: binary byte 0x%02x at offset %zu", path, ch,
                             i);
    }
    static const char *const known[] = { "v", "vn", "vt", "vp", "vw", "f", "l", "p", "o", "g", "s", "t",
                                         "usemtl", "mtllib", "cstype", "deg", "curv", "curv2", "surf",
                                         "parm", "trim", "hole", "end", "bmat", "step", "mg", "lod" };
    size_t line = 0, normals = 0;
    for (size_t i = 0; i < size;) {
        size_t end = line_end(text, size, i);
        line++;
        size_t s = i;
        while (s < end && is_blank(text[s])) s++;
        const char *st = text + s;
        size_t n = end - s;
        i = next_line(text, size, end);
        if (n == 0 || st[0] == '#') continue;
        bool recognised = false;
        for (size_t k = 0; k < sizeof known / sizeof known[0]; k++)
            if (keyword(st, n, known[k])) recognised = true;
        if (!recognised) {
            out->unknown++;
            continue;
        }
        out->statements++;
        if (keyword(st, n, "l")) out->lines++;
        if (keyword(st, n, "p")) out->points++;
        bool vertex = keyword(st, n, "v"), normal = keyword(st, n, "vn");
        if (!vertex && !normal) continue;
        size_t number = vertex ? ++out->vertices : ++normals;
        /* tinyobjloader parses "nan" and "inf" as 0, so they are caught here. */
        size_t t = vertex ? 1 : 2;
        for (int component = 0; component < 3; component++) {
            while (t < n && is_blank(st[t])) t++;
            if (t >= n || st[t] == '#') break;
            size_t tok = t;
            while (t < n && !is_blank(st[t])) t++;
            size_t w = tok < n && (st[tok] == '+' || st[tok] == '-') ? tok + 1 : tok;
            if (word_ci(st + w, t - w, "nan") || word_ci(st + w, t - w, "inf"))
                return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY, "%s: line %zu: %s %zu has a non-finite coordinate (%.*s)",
                                 path, line, vertex ? "vertex" : "normal", number, (int)(t - tok < 16 ? t - tok : 16),
                                 st + tok);
        }
    }
    return VKRT_OK;
}

static void fail_in_callback(obj_state *s, vkrt_result r)
{
    if (s->error == VKRT_OK) s->error = r;
}

/* One `v` or `vn` record (keyword), appended to its array of triples. Checked after the append
 * so the message can number the record: a finite decimal too large for a float reads as
 * infinity. noun and plural name the record in messages ("vertex", "vertices"). */
static void push_triple(obj_state *s, float **items, size_t *count, size_t *capacity, const float xyz[3],
                        const char *keyword, const char *noun, const char *plural)
{
    if (s->error) return;
    if (core_grow(s->c, (void **)items, capacity, *count + 1, 3 * sizeof(float))) {
        fail_in_callback(s, core_fail(s->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory reading %s", s->path, plural));
        return;
    }
    memcpy(*items + 3 * (*count)++, xyz, 3 * sizeof(float));
    if (!isfinite(xyz[0]) || !isfinite(xyz[1]) || !isfinite(xyz[2])) {
        size_t line = statement_line(s->text, s->size, keyword, *count);
        fail_in_callback(s, core_fail(s->c, VKRT_ERROR_INVALID_GEOMETRY,
                                      "%s: line %zu: %s %zu has a non-finite coordinate (overflows a float)",
                                      s->path, line, noun, *count));
    }
}

static void on_vertex(void *user, float x, float y, float z)
{
    obj_state *s = user;
    push_triple(s, &s->positions, &s->position_count, &s->position_capacity, (const float[3]){ x, y, z }, "v",
                "vertex", "vertices");
}

static void on_normal(void *user, float x, float y, float z)
{
    obj_state *s = user;
    push_triple(s, &s->normals, &s->normal_count, &s->normal_capacity, (const float[3]){ x, y, z }, "vn", "normal",
                "normals");
}

static void on_texcoord(void *user, float u, float v)
{
    obj_state *s = user;
    push_triple(s, &s->texcoords, &s->texcoord_count, &s->texcoord_capacity, (const float[3]){ u, v, 0.0f }, "vt",
                "texture coordinate", "texture coordinates");
}

static float clamp01(float v)
{
    return v > 0.0f ? (v < 1.0f ? v : 1.0f) : 0.0f; /* NaN: 0 */
}

/* The texture file an .mtl names (relative to the .obj), or VKRT_NO_TEXTURE without one. */
static vkrt_result mtl_texture(obj_state *s, const char *name, texture_encoding encoding, const char *what,
                               uint32_t *out)
{
    *out = VKRT_NO_TEXTURE;
    if (!name[0]) return VKRT_OK;
    size_t n = strlen(s->directory) + strlen(name) + 1;
    char *file = core_alloc(s->c, n);
    if (!file) return core_fail(s->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory reading materials", s->path);
    snprintf(file, n, "%s%s", s->directory, name);
    vkrt_result r = mesh_add_texture_file(s->c, s->m, file, VKRT_WRAP_REPEAT, VKRT_WRAP_REPEAT, encoding, s->path,
                                          what, out);
    core_free(s->c, file);
    return r;
}

/* An .mtl material as a vkrt_material: Kd the base colour, d its alpha, Ns (a Phong exponent)
 * the roughness whose GGX lobe has the same width, sqrt(sqrt(2 / (Ns + 2))) (Walter et al.
 * 2007), Ke the emission. The PBR extension's Pr, where given, is the roughness instead, and its
 * Pm the metallic (0 without). map_Kd and map_Ke (sRGB) are read relative to the .obj; map_Pr
 * and map_Pm are not read (vkrt's metallic-roughness texture packs both in one image). */
static void add_material(obj_state *s, const tinyobj_shim_material *src, size_t index)
{
    vkrt_material mat = { .base_color = { clamp01(src->diffuse[0]), clamp01(src->diffuse[1]),
                                          clamp01(src->diffuse[2]), clamp01(src->dissolve) } };
    double ns = src->shininess > 0.0f ? (double)src->shininess : 0.0;
    mat.roughness = src->has_roughness ? clamp01(src->roughness) : clamp01((float)sqrt(sqrt(2.0 / (ns + 2.0))));
    mat.metallic = clamp01(src->metallic);
    for (int k = 0; k < 3; k++) mat.emissive[k] = src->emission[k] > 0.0f && isfinite(src->emission[k]) ? src->emission[k] : 0.0f;
    char what[96];
    snprintf(what, sizeof what, "material %zu (%.40s)", index, src->name);
    mesh_material_textures textures = MESH_NO_TEXTURES;
    uint32_t mesh_index = 0;
    vkrt_result r = mtl_texture(s, src->diffuse_texture, TEXTURE_SRGB, what, &textures.base_color);
    if (r == VKRT_OK) r = mtl_texture(s, src->emissive_texture, TEXTURE_SRGB, what, &textures.emissive);
    /* map_Ke without Ke (tinyobjloader's 0 0 0): the texture alone is the emission, since a map
     * scaled by nothing would be the same as none. */
    if (textures.emissive != VKRT_NO_TEXTURE && mat.emissive[0] == 0.0f && mat.emissive[1] == 0.0f &&
        mat.emissive[2] == 0.0f)
        mat.emissive[0] = mat.emissive[1] = mat.emissive[2] = 1.0f;
    if (r == VKRT_OK) r = mesh_add_material(s->c, s->m, &mat, &textures, VKRT_ERROR_PARSE, s->path, what, &mesh_index);
    if (r != VKRT_OK) {
        fail_in_callback(s, r);
        return;
    }
    s->materials[index] = MESH_MATERIAL(mesh_index);
}

/* `mtllib`: the materials read so far; those not seen before join the mesh's table. */
static void on_materials(void *user, const tinyobj_shim_material *materials, size_t count)
{
    obj_state *s = user;
    if (s->error || count <= s->material_count) return;
    if (core_grow(s->c, (void **)&s->materials, &s->material_capacity, count, sizeof *s->materials)) {
        fail_in_callback(s, core_fail(s->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory reading materials", s->path));
        return;
    }
    for (size_t i = s->material_count; i < count && !s->error; i++) add_material(s, &materials[i], i);
    if (!s->error) s->material_count = count;
}

static void on_group(void *user);

/* `usemtl`: the faces that follow have this material, in a primitive of their own. */
static void on_use_material(void *user, int index)
{
    obj_state *s = user;
    if (s->error || index == s->current_material) return;
    s->current_material = index;
    on_group(s);
}

/* 1-based or negative (relative) OBJ index to 0-based; false for 0, which OBJ does not allow
 * (tinyobjloader also yields 0 for a missing or non-numeric index). */
static bool resolve(int raw, size_t count, int64_t *out)
{
    if (raw > 0) *out = (int64_t)raw - 1;
    else if (raw < 0) *out = (int64_t)count + raw;
    else return false;
    return true;
}

static void on_face(void *user, const tinyobj_shim_corner *corners, size_t count)
{
    obj_state *s = user;
    if (s->error) return;
    size_t face = ++s->face_count;
    if (count < 3) {
        s->short_faces++;
        return;
    }
    bool all_normals = true, all_texcoords = true;
    for (size_t k = 0; k < count; k++) {
        int64_t v;
        if (!resolve(corners[k].v, s->position_count, &v) || v < 0) {
            size_t line = statement_line(s->text, s->size, "f", face);
            fail_in_callback(s, core_fail(s->c, VKRT_ERROR_INVALID_GEOMETRY,
                                          corners[k].v == 0
                                              ? "%s: line %zu: face %zu: corner %zu has vertex index 0 or no number "
                                                "(OBJ indices start at 1)"
                                              : "%s: line %zu: face %zu: corner %zu has relative index %d, before the "
                                                "first vertex",
                                          s->path, line, face, k + 1, corners[k].v));
            return;
        }
        /* A normal index that names no normal counts as none (tinyobjloader itself only
         * warns; files in the wild reference normals they never define): the face then gets
         * computed normals, and only positions must be right. */
        int64_t vn;
        if (corners[k].vn == 0 || (resolve(corners[k].vn, s->normal_count, &vn) && vn < 0)) all_normals = false;
        int64_t vt; /* likewise for texture coordinates: without a complete set, (0, 0) */
        if (corners[k].vt == 0 || (resolve(corners[k].vt, s->texcoord_count, &vt) && vt < 0)) all_texcoords = false;
    }
    if (core_grow(s->c, (void **)&s->tris, &s->tri_capacity, s->tri_count + (count - 2), sizeof *s->tris)) {
        fail_in_callback(s, core_fail(s->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory reading faces", s->path));
        return;
    }
    int64_t v0 = -1, vn0 = -1, vt0 = -1; /* resolve() set them for every corner above */
    resolve(corners[0].v, s->position_count, &v0);
    if (all_normals) resolve(corners[0].vn, s->normal_count, &vn0);
    if (all_texcoords) resolve(corners[0].vt, s->texcoord_count, &vt0);
    for (size_t k = 1; k + 1 < count; k++) {
        obj_tri *t = &s->tris[s->tri_count++];
        t->face = face;
        t->material = s->current_material;
        t->v[0] = v0;
        resolve(corners[k].v, s->position_count, &t->v[1]);
        resolve(corners[k + 1].v, s->position_count, &t->v[2]);
        t->vn[0] = vn0;
        t->vn[1] = t->vn[2] = -1;
        if (all_normals) {
            resolve(corners[k].vn, s->normal_count, &t->vn[1]);
            resolve(corners[k + 1].vn, s->normal_count, &t->vn[2]);
        }
        t->vt[0] = vt0;
        t->vt[1] = t->vt[2] = -1;
        if (all_texcoords) {
            resolve(corners[k].vt, s->texcoord_count, &t->vt[1]);
            resolve(corners[k + 1].vt, s->texcoord_count, &t->vt[2]);
        }
    }
}

static void on_group(void *user)
{
    obj_state *s = user;
    if (s->error) return;
    if (s->object_count && s->object_starts[s->object_count - 1] == s->tri_count) return;
    if (core_grow(s->c, (void **)&s->object_starts, &s->object_capacity, s->object_count + 1, sizeof(size_t))) {
        fail_in_callback(s, core_fail(s->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory reading groups", s->path));
        return;
    }
    s->object_starts[s->object_count++] = s->tri_count;
}

static vkrt_result read_file(core *c, const char *path, char **out_text, size_t *out_size)
{
    *out_text = NULL;
    *out_size = 0;
    FILE *f = fopen(path, "rb");
    if (!f) return core_fail(c, VKRT_ERROR_IO, "%s: cannot open: %s", path, strerror(errno));
    vkrt_result r = VKRT_OK;
    char *text = NULL;
    size_t size = 0, capacity = 0;
    for (;;) {
        if (core_grow(c, (void **)&text, &capacity, size + 65536, 1)) {
            r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory reading the file", path);
            break;
        }
        size_t got = fread(text + size, 1, capacity - size, f);
        size += got;
        if (got == 0) {
            if (ferror(f)) r = core_fail(c, VKRT_ERROR_IO, "%s: cannot read: %s", path, strerror(errno));
            break;
        }
    }
    fclose(f);
    if (r != VKRT_OK) {
        core_free(c, text);
        return r;
    }
    *out_text = text;
    *out_size = size;
    return VKRT_OK;
}

/* Appends triangles [first, last) as one primitive over the vertices they use. */
static vkrt_result append_object(obj_state *s, mesh *m, size_t first, size_t last, uint32_t *remap,
                                 size_t object)
{
    core *c = s->c;
    size_t tris = last - first;
    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    uint32_t *indices = core_alloc_array(c, tris, 3 * sizeof(uint32_t));
    float *local = core_alloc_array(c, tris, 9 * sizeof(float)); /* at most 3 new vertices per triangle */
    size_t used = 0;
    if (!indices || !local) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory building object %zu", s->path, object);
        goto done;
    }
    for (size_t t = 0; t < tris; t++) {
        for (int k = 0; k < 3; k++) {
            size_t v = (size_t)s->tris[first + t].v[k];
            if (remap[v] == UINT32_MAX) {
                remap[v] = (uint32_t)used;
                memcpy(local + 3 * used, s->positions + 3 * v, 3 * sizeof(float));
                used++;
            }
            indices[3 * t + k] = remap[v];
        }
    }
    char what[64];
    snprintf(what, sizeof what, "object %zu", object);
    size_t base = m->tri_count;
    int material = s->tris[first].material; /* one per object: `usemtl` starts a new one */
    r = mesh_append_indexed(c, m,
                            &(mesh_primitive){ .positions = local, .vertex_count = used, .indices = indices,
                                               .index_count = 3 * tris,
                                               .material = material >= 0 && (size_t)material < s->material_count
                                                               ? s->materials[material]
                                                               : 0 },
                            s->path, what);
    if (r != VKRT_OK) goto done;
    /* The file's own normals replace the computed ones on faces that give one per corner. */
    for (size_t t = 0; t < tris; t++) {
        const obj_tri *src = &s->tris[first + t];
        if (src->vn[0] < 0) continue;
        for (int k = 0; k < 3; k++) {
            const float *n = s->normals + 3 * (size_t)src->vn[k];
            double len = sqrt((double)n[0] * n[0] + (double)n[1] * n[1] + (double)n[2] * n[2]);
            if (!(len > 0.0)) continue; /* "vn 0 0 0": keep the computed normal */
            float *out = m->normals + (base + t) * 9 + 3 * k;
            for (int j = 0; j < 3; j++) out[j] = (float)(n[j] / len);
        }
    }
    /* And their texture coordinates, where a face gives one per corner. OBJ puts v = 0 at the
     * bottom of an image, glTF (and vkrt) at the top: v is flipped. */
    for (size_t t = 0; t < tris; t++) {
        const obj_tri *src = &s->tris[first + t];
        if (src->vt[0] < 0) continue;
        m->has_texcoords = true;
        for (int k = 0; k < 3; k++) {
            const float *uv = s->texcoords + 3 * (size_t)src->vt[k];
            m->texcoords[(base + t) * 6 + 2 * k] = uv[0];
            m->texcoords[(base + t) * 6 + 2 * k + 1] = 1.0f - uv[1];
        }
    }
done:
    for (size_t t = 0; t < tris; t++)
        for (int k = 0; k < 3; k++) remap[(size_t)s->tris[first + t].v[k]] = UINT32_MAX;
    core_free(c, indices);
    core_free(c, local);
    return r;
}

/* Clears (to -1) the three indices at `member` (offsetof vn or vt) of every triangle that names
 * one at or past `defined`; returns how many triangles lost theirs. */
static size_t drop_undefined(obj_state *s, size_t member, size_t defined)
{
    size_t dropped = 0;
    for (size_t t = 0; t < s->tri_count; t++) {
        int64_t *index = (int64_t *)((char *)&s->tris[t] + member);
        if (index[0] >= (int64_t)defined || index[1] >= (int64_t)defined || index[2] >= (int64_t)defined) {
            index[0] = index[1] = index[2] = -1;
            dropped++;
        }
    }
    return dropped;
}

static vkrt_result check_indices(obj_state *s)
{
    for (size_t t = 0; t < s->tri_count; t++) {
        const obj_tri *tri = &s->tris[t];
        for (int k = 0; k < 3; k++) {
            if (tri->v[k] >= (int64_t)s->position_count)
                return core_fail(s->c, VKRT_ERROR_INVALID_GEOMETRY,
                                 "%s: line %zu: face %zu refers to vertex %lld, but the file has %zu vertices", s->path,
                                 statement_line(s->text, s->size, "f", tri->face), tri->face,
                                 (long long)tri->v[k] + 1, s->position_count);
        }
    }
    /* Normals and texture coordinates may be defined after the face that names them, so faces
     * naming one past the end are known only now; they fall back to computed normals and to
     * (0, 0) (see on_face). */
    size_t dropped = drop_undefined(s, offsetof(obj_tri, vn), s->normal_count);
    if (dropped)
        core_log(s->c, VKRT_LOG_WARN, "%s: %zu triangles name normals the file does not define; computed instead",
                 s->path, dropped);
    dropped = drop_undefined(s, offsetof(obj_tri, vt), s->texcoord_count);
    if (dropped)
        core_log(s->c, VKRT_LOG_WARN,
                 "%s: %zu triangles name texture coordinates the file does not define; (0, 0) instead", s->path,
                 dropped);
    return VKRT_OK;
}

vkrt_result mesh_load_obj(core *c, const char *path, mesh *m)
{
    memset(m, 0, sizeof *m);
    obj_state s = { .c = c, .m = m, .path = path, .current_material = -1 };
    uint32_t *remap = NULL;
    char *text = NULL;
    size_t size = 0;
    vkrt_result r = read_file(c, path, &text, &size);
    if (r != VKRT_OK) goto done;
    s.text = text;
    s.size = size;
    obj_scan scan;
    if ((r = scan_text(c, path, text, size, &scan)) != VKRT_OK) goto done;
    if (scan.statements == 0 && scan.unknown > 0) {
        r = core_fail(c, VKRT_ERROR_PARSE, "%s: not an OBJ file: none of its %zu lines is an OBJ statement", path,
                      scan.unknown);
        goto done;
    }
    if (scan.vertices > (size_t)INT32_MAX) {
        r = core_fail(c, VKRT_ERROR_LIMIT, "%s: more than %d vertices", path, INT32_MAX);
        goto done;
    }

    const char *slash = strrchr(path, '/');
    size_t dir_length = slash ? (size_t)(slash - path) + 1 : 0;
    if (!(s.directory = core_alloc(c, dir_length + 1))) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory", path);
        goto done;
    }
    memcpy(s.directory, path, dir_length);
    s.directory[dir_length] = '\0';
    on_group(&s); /* faces before any `o` or `g` form the first object */
    char message[256];
    tinyobj_shim_status status = tinyobj_shim_parse(
        text, size, dir_length ? s.directory : "./",
        &(tinyobj_shim_callbacks){ .user = &s, .vertex = on_vertex, .normal = on_normal, .texcoord = on_texcoord,
                                   .face = on_face, .group = on_group, .materials = on_materials,
                                   .use_material = on_use_material },
        message, sizeof message);
    if (s.error) {
        r = s.error;
        goto done;
    }
    if (status == TINYOBJ_SHIM_OUT_OF_MEMORY) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory in tinyobjloader", path);
        goto done;
    }
    if (status != TINYOBJ_SHIM_OK) {
        r = core_fail(c, VKRT_ERROR_PARSE, "%s: tinyobjloader: %s", path, message);
        goto done;
    }
    if ((r = check_indices(&s)) != VKRT_OK) goto done;

    if (s.tri_count == 0) {
        if (scan.lines || scan.points)
            r = core_fail(c, VKRT_ERROR_EMPTY_SCENE, "%s: has only points or lines (%zu `l`, %zu `p`), no faces", path,
                          scan.lines, scan.points);
        else if (s.short_faces)
            r = core_fail(c, VKRT_ERROR_EMPTY_SCENE, "%s: has no face with 3 or more corners", path);
        else
            r = core_fail(c, VKRT_ERROR_EMPTY_SCENE, "%s: has no faces", path);
        goto done;
    }
    if (s.tri_count > UINT32_MAX) {
        r = core_fail(c, VKRT_ERROR_LIMIT, "%s: more than %u triangles", path, UINT32_MAX);
        goto done;
    }

    core_free(c, text); /* the triangles no longer need it, and the mesh may be large */
    text = NULL;
    s.text = NULL;
    s.size = 0;
    remap = core_alloc_array(c, s.position_count, sizeof *remap);
    if (!remap) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory", path);
        goto done;
    }
    memset(remap, 0xff, s.position_count * sizeof *remap);
    for (size_t o = 0; o < s.object_count; o++) {
        size_t first = s.object_starts[o];
        size_t last = o + 1 < s.object_count ? s.object_starts[o + 1] : s.tri_count;
        if (first == last) continue;
        if ((r = append_object(&s, m, first, last, remap, o)) != VKRT_OK) goto done;
    }
    r = VKRT_OK;
done:
    mesh_finish(c, m, r);
    core_free(c, remap);
    core_free(c, text);
    core_free(c, s.positions);
    core_free(c, s.normals);
    core_free(c, s.texcoords);
    core_free(c, s.tris);
    core_free(c, s.directory);
    core_free(c, s.materials);
    core_free(c, s.object_starts);
    return r;
}
