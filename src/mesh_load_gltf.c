/* glTF 2.0 (.gltf with external or base64 buffers, and .glb) through cgltf.
 *
 * The default scene's nodes are walked depth first, each node's mesh before its children,
 * and every triangle primitive of a node's mesh is appended with the node's world
 * transform, as is every node's KHR_lights_punctual light. The walk multiplies transforms
 * down the path it took instead of asking cgltf for a node's world matrix, because cgltf
 * keeps one parent per node while files do give a node several parents (an instance under
 * each); a node on the current path is a cycle. */
#include "mesh.h"

#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <string.h>

#include <cgltf.h>

#include "file_read.h"

/* Each node instance costs a stack entry and a matrix product; a hierarchy that shares
 * nodes along many levels can still expand exponentially, so the walk has a ceiling. */
#define GLTF_MAX_NODE_VISITS (1u << 24)

static void *gltf_alloc(void *user, cgltf_size size)
{
    return core_alloc(user, size);
}

static void gltf_free(void *user, void *pointer)
{
    core_free(user, pointer);
}

/* cgltf's file reader, for the glTF and the buffer files beside it. cgltf's own allocates a
 * buffer's whole byteLength before it learns how long the file is (and ftell()'s LLONG_MAX for
 * a directory): file_read learns that first and refuses what the file cannot hold. */
static cgltf_result gltf_read_file(const struct cgltf_memory_options *memory, const struct cgltf_file_options *file,
                                   const char *path, cgltf_size *size, void **data)
{
    (void)file;
    void *bytes = NULL;
    size_t got = 0;
    switch (file_read(memory->user_data, path, size ? *size : 0, &bytes, &got)) {
    case FILE_READ_OK: break;
    case FILE_READ_CANNOT_OPEN: return cgltf_result_file_not_found;
    case FILE_READ_OUT_OF_MEMORY: return cgltf_result_out_of_memory;
    default: return cgltf_result_io_error;
    }
    if (size) *size = got;
    *data = bytes;
    return cgltf_result_success;
}

static vkrt_result parse_failure(core *c, const char *path, cgltf_result cr, int saved_errno)
{
    switch (cr) {
    case cgltf_result_file_not_found:
        return core_fail(c, VKRT_ERROR_IO, "%s: cannot open: %s", path,
                         saved_errno ? strerror(saved_errno) : "file not found");
    case cgltf_result_io_error:
        return core_fail(c, VKRT_ERROR_IO, "%s: cannot read the file", path);
    case cgltf_result_out_of_memory:
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory parsing glTF", path);
    case cgltf_result_data_too_short:
        return core_fail(c, VKRT_ERROR_PARSE, "%s: truncated glTF: the data is shorter than its header says", path);
    case cgltf_result_unknown_format:
        return core_fail(c, VKRT_ERROR_PARSE, "%s: not a glTF file (neither JSON nor GLB version 2)", path);
    case cgltf_result_invalid_json:
        return core_fail(c, VKRT_ERROR_PARSE, "%s: invalid glTF JSON", path);
    case cgltf_result_invalid_gltf:
        return core_fail(c, VKRT_ERROR_PARSE,
                         "%s: invalid glTF (a required property is missing or a reference is out of range)", path);
    case cgltf_result_legacy_gltf:
        return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: glTF 1.0 is not supported (glTF 2.0 is)", path);
    default:
        return core_fail(c, VKRT_ERROR_PARSE, "%s: cgltf failed (result %d)", path, (int)cr);
    }
}

/* Extensions a file may require that vkrt reads or can do without: KHR_mesh_quantization is
 * decoded by cgltf_accessor_unpack_floats and KHR_lights_punctual read by the walk; the others
 * only refine materials and textures, which then look plainer. */
static bool extension_supported(const char *name)
{
    static const char *const exact[] = { "KHR_mesh_quantization", "KHR_texture_transform", "KHR_texture_basisu",
                                         "EXT_texture_webp", "KHR_lights_punctual", "KHR_materials_variants" };
    for (size_t i = 0; i < sizeof exact / sizeof exact[0]; i++)
        if (strcmp(name, exact[i]) == 0) return true;
    return strncmp(name, "KHR_materials_", 14) == 0;
}

static vkrt_result check_required_extensions(core *c, const char *path, const cgltf_data *data)
{
    for (cgltf_size i = 0; i < data->extensions_required_count; i++) {
        const char *name = data->extensions_required[i];
        if (!extension_supported(name))
            return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: requires the glTF extension %s, which vkrt cannot decode",
                             path, name);
    }
    return VKRT_OK;
}

static vkrt_result buffers_failure(core *c, const char *path, const cgltf_data *data, cgltf_result cr)
{
    /* cgltf stops at the first buffer it cannot load: the first one left without data. */
    cgltf_size i = 0;
    while (i < data->buffers_count && (data->buffers[i].data || !data->buffers[i].uri)) i++;
    const char *uri = i < data->buffers_count ? data->buffers[i].uri : "(GLB binary chunk)";
    char shown[80];
    snprintf(shown, sizeof shown, "%s", uri); /* a data: URI can be megabytes long */
    switch (cr) {
    case cgltf_result_file_not_found:
        return core_fail(c, VKRT_ERROR_IO, "%s: buffer %zu: cannot open '%s'", path, (size_t)i, shown);
    case cgltf_result_io_error:
        return core_fail(c, VKRT_ERROR_IO, "%s: buffer %zu: cannot read '%s' (not a file, or shorter than its "
                         "byteLength)", path, (size_t)i, shown);
    case cgltf_result_out_of_memory:
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory loading buffer %zu", path, (size_t)i);
    case cgltf_result_data_too_short:
        return core_fail(c, VKRT_ERROR_PARSE, "%s: the GLB binary chunk is shorter than buffer 0", path);
    case cgltf_result_unknown_format:
        return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: buffer %zu: unsupported uri '%s' (only relative files and "
                         "base64 data URIs)", path, (size_t)i, shown);
    default:
        return parse_failure(c, path, cr, 0);
    }
}

/* True when every element of a non-sparse index accessor lies inside loaded buffer data, so
 * its indices can be read before cgltf_validate() has vouched for the sizes. */
static bool accessor_readable(const cgltf_accessor *a)
{
    const cgltf_buffer_view *view = a->buffer_view;
    if (!view || a->is_sparse || !view->buffer || !view->buffer->data) return false;
    if (view->offset > view->buffer->size || view->size > view->buffer->size - view->offset) return false;
    cgltf_size elem;
    switch (a->component_type) {
    case cgltf_component_type_r_8u: elem = 1; break;
    case cgltf_component_type_r_16u: elem = 2; break;
    case cgltf_component_type_r_32u: elem = 4; break;
    default: return false; /* not an index type */
    }
    if (a->count == 0) return true;
    if (a->stride && a->count - 1 > (SIZE_MAX - elem - a->offset) / a->stride) return false;
    return a->offset + a->stride * (a->count - 1) + elem <= view->size;
}

/* cgltf_validate() reports an index past the vertex count as "data too short"; name it. */
static vkrt_result find_bad_index(core *c, const char *path, const cgltf_data *data)
{
    for (cgltf_size mi = 0; mi < data->meshes_count; mi++) {
        const cgltf_mesh *mesh_ = &data->meshes[mi];
        for (cgltf_size pi = 0; pi < mesh_->primitives_count; pi++) {
            const cgltf_primitive *prim = &mesh_->primitives[pi];
            const cgltf_accessor *indices = prim->indices;
            if (!indices || prim->attributes_count == 0 || !accessor_readable(indices)) continue;
            cgltf_size vertices = prim->attributes[0].data->count;
            for (cgltf_size i = 0; i < indices->count; i++) {
                cgltf_size v = cgltf_accessor_read_index(indices, i);
                if (v >= vertices)
                    return core_fail(c, VKRT_ERROR_INVALID_GEOMETRY,
                                     "%s: mesh %zu primitive %zu: index %zu is %zu, out of range for %zu vertices",
                                     path, (size_t)mi, (size_t)pi, (size_t)i, (size_t)v, (size_t)vertices);
            }
        }
    }
    return VKRT_OK;
}

static const cgltf_accessor *find_attribute(const cgltf_primitive *prim, cgltf_attribute_type type)
{
    for (cgltf_size i = 0; i < prim->attributes_count; i++)
        if (prim->attributes[i].type == type && prim->attributes[i].index == 0) return prim->attributes[i].data;
    return NULL;
}

/* Whether an accessor's bytes are present; an accessor without a buffer view is all zeros by
 * the specification, and cgltf reads it so. */
static bool view_loaded(const cgltf_buffer_view *view)
{
    return view && (view->data || (view->buffer && view->buffer->data));
}

static bool accessor_loaded(const cgltf_accessor *a)
{
    if (a->buffer_view && !view_loaded(a->buffer_view)) return false;
    if (a->is_sparse && (!view_loaded(a->sparse.indices_buffer_view) || !view_loaded(a->sparse.values_buffer_view)))
        return false;
    return true;
}

static size_t component_bytes(cgltf_component_type t)
{
    switch (t) {
    case cgltf_component_type_r_16:
    case cgltf_component_type_r_16u: return 2;
    case cgltf_component_type_r_32u:
    case cgltf_component_type_r_32f: return 4;
    default: return 1;
    }
}

static bool aligned_at(const cgltf_buffer_view *view, cgltf_size offset, size_t bytes)
{
    return !view || !view->buffer->data || ((uintptr_t)view->buffer->data + view->offset + offset) % bytes == 0;
}

/* glTF 2.0 requires every accessor's data (and its stride) aligned to its component size, and
 * cgltf reads them through typed pointers: a file that breaks the rule (a misplaced offset, or a
 * GLB whose binary chunk starts unaligned) is refused rather than read misaligned. */
static bool accessor_aligned(const cgltf_accessor *a)
{
    size_t bytes = component_bytes(a->component_type);
    if (!aligned_at(a->buffer_view, a->offset, bytes) || a->stride % bytes) return false;
    if (a->is_sparse)
        return aligned_at(a->sparse.indices_buffer_view, a->sparse.indices_byte_offset,
                          component_bytes(a->sparse.indices_component_type)) &&
               aligned_at(a->sparse.values_buffer_view, a->sparse.values_byte_offset, bytes);
    return true;
}

/* n elements of `stride` bytes whose last takes `last` bytes, from `offset` into a range of
 * `size` bytes, lie inside it; without overflow, whatever the file claims. */
static bool elements_fit(cgltf_size size, cgltf_size offset, cgltf_size n, cgltf_size stride, cgltf_size last)
{
    if (offset > size) return false;
    const cgltf_size room = size - offset;
    if (n == 0) return true;
    if (last > room) return false;
    return stride == 0 || n - 1 <= (room - last) / stride;
}

/* cgltf allocates a data: URI buffer's whole byteLength before it decodes a character, so a
 * byteLength past what the URI's base64 text can hold is refused first (found by fuzz_gltf: a
 * byteLength of -20, which cgltf reads as 2^64 - 20, went to the allocator as that). A buffer
 * file's length is checked by gltf_read_file, the GLB binary chunk's by cgltf. */
static vkrt_result check_data_uri_lengths(core *c, const char *path, const cgltf_data *data)
{
    for (cgltf_size i = 0; i < data->buffers_count; i++) {
        const cgltf_buffer *b = &data->buffers[i];
        const char *comma = b->uri && !strncmp(b->uri, "data:", 5) ? strchr(b->uri, ',') : NULL;
        /* The base64 URIs cgltf decodes; it calls any other data: URI unsupported. */
        if (b->data || !comma || comma - b->uri < 7 || strncmp(comma - 7, ";base64", 7)) continue;
        size_t chars = strlen(comma + 1), holds = chars / 4 * 3 + chars % 4 * 3 / 4;
        if (b->size > holds)
            return core_fail(c, VKRT_ERROR_PARSE, "%s: buffer %zu: its byteLength (%lld) is more than its data: URI "
                             "holds (%zu bytes)", path, (size_t)i, (long long)b->size, holds);
    }
    return VKRT_OK;
}

/* Every buffer view inside its buffer and every accessor inside its buffer view, before
 * cgltf_validate or anything else computes an address from them: cgltf 1.12 adds the offsets
 * to the buffer's address unchecked, and its own checks add them up in size_t, where a
 * negative byteOffset wraps (found by fuzz_gltf: a view at byteOffset -68 of length 72 passed
 * them, and the index bound was read 68 bytes before the buffer). */
static vkrt_result check_data_ranges(core *c, const char *path, const cgltf_data *data)
{
    for (cgltf_size i = 0; i < data->buffer_views_count; i++) {
        const cgltf_buffer_view *v = &data->buffer_views[i];
        bool inside = !v->buffer || elements_fit(v->buffer->size, v->offset, 1, 0, v->size);
        if (v->has_meshopt_compression) {
            const cgltf_meshopt_compression *mc = &v->meshopt_compression;
            inside = inside && mc->buffer && elements_fit(mc->buffer->size, mc->offset, 1, 0, mc->size);
        }
        if (!inside)
            return core_fail(c, VKRT_ERROR_PARSE, "%s: buffer view %zu reaches past the end of its buffer", path,
                             (size_t)i);
    }
    for (cgltf_size i = 0; i < data->accessors_count; i++) {
        const cgltf_accessor *a = &data->accessors[i];
        const cgltf_size element = cgltf_num_components(a->type) * component_bytes(a->component_type);
        bool inside = !a->buffer_view || elements_fit(a->buffer_view->size, a->offset, a->count, a->stride, element);
        if (a->is_sparse) {
            const cgltf_accessor_sparse *sp = &a->sparse;
            inside = inside && sp->indices_buffer_view && sp->values_buffer_view &&
                     elements_fit(sp->indices_buffer_view->size, sp->indices_byte_offset, sp->count,
                                  component_bytes(sp->indices_component_type),
                                  component_bytes(sp->indices_component_type)) &&
                     elements_fit(sp->values_buffer_view->size, sp->values_byte_offset, sp->count, element, element);
        }
        if (!inside)
            return core_fail(c, VKRT_ERROR_PARSE, "%s: accessor %zu reaches past the end of its buffer view", path,
                             (size_t)i);
    }
    return VKRT_OK;
}

/* What cgltf_validate itself reads through typed pointers (primitive indices and sparse
 * indices, for their bounds) must be aligned before it runs. */
static vkrt_result check_validated_alignment(core *c, const char *path, const cgltf_data *data)
{
    for (cgltf_size i = 0; i < data->accessors_count; i++) {
        const cgltf_accessor *a = &data->accessors[i];
        if (a->is_sparse && !aligned_at(a->sparse.indices_buffer_view, a->sparse.indices_byte_offset,
                                        component_bytes(a->sparse.indices_component_type)))
            return core_fail(c, VKRT_ERROR_PARSE, "%s: accessor %zu: its sparse indices are not aligned", path, (size_t)i);
    }
    for (cgltf_size m = 0; m < data->meshes_count; m++)
        for (cgltf_size p = 0; p < data->meshes[m].primitives_count; p++) {
            const cgltf_accessor *indices = data->meshes[m].primitives[p].indices;
            if (indices && !accessor_aligned(indices))
                return core_fail(c, VKRT_ERROR_PARSE,
                                 "%s: mesh %zu primitive %zu: its indices are not aligned to their size (glTF 2.0 "
                                 "requires it)",
                                 path, (size_t)m, (size_t)p);
        }
    return VKRT_OK;
}

typedef struct gltf_walk {
    core *c;
    const char *path;
    const cgltf_data *data;
    mesh *m;
    size_t skipped_primitives; /* points and lines */
    size_t triangle_primitives;
    uint32_t *materials;       /* per glTF material: MESH_MATERIAL(its index in m), 0 until a
                                  primitive uses it */
    uint32_t *textures;        /* per glTF texture and encoding (entry 2 * texture + encoding): 1 +
                                  its index in m, 0 until used, UINT32_MAX when it could not be
                                  read; a texture used as colour and as data is decoded twice */
    bool *spot_warned;         /* per glTF light: its cone has been reported ignored */
    const cgltf_options *options;
} gltf_walk;

/* The bytes of a glTF image held in the file itself: its buffer view or a base64 data: URI.
 * *owned tells the caller to free them. NULL with *reason otherwise (an image in a file of its
 * own included), and *out_of_memory set when that was the cause. */
static const uint8_t *image_bytes(gltf_walk *w, const cgltf_image *image, size_t *size, bool *owned,
                                  const char **reason, bool *out_of_memory)
{
    *out_of_memory = false;
    *owned = false;
    *size = 0;
    if (image->buffer_view) {
        const cgltf_buffer_view *v = image->buffer_view;
        if (!v->buffer->data || v->offset + v->size > v->buffer->size) {
            *reason = "its buffer view has no data";
            return NULL;
        }
        *size = v->size;
        return (const uint8_t *)v->buffer->data + v->offset;
    }
    if (!image->uri) {
        *reason = "it has neither a URI nor a buffer view";
        return NULL;
    }
    if (strncmp(image->uri, "data:", 5) == 0) {
        const char *comma = strstr(image->uri, ";base64,");
        if (!comma) {
            *reason = "its data: URI is not base64";
            return NULL;
        }
        const char *b64 = comma + 8;
        size_t n = strlen(b64), pad = n && b64[n - 1] == '=' ? (n > 1 && b64[n - 2] == '=' ? 2 : 1) : 0;
        *size = n / 4 * 3 - pad;
        void *out = NULL;
        cgltf_result cr = n % 4 ? cgltf_result_invalid_gltf : cgltf_load_buffer_base64(w->options, *size, b64, &out);
        if (cr != cgltf_result_success) {
            *out_of_memory = cr == cgltf_result_out_of_memory;
            *reason = "its base64 data cannot be decoded";
            return NULL;
        }
        *owned = true;
        return out;
    }
    *reason = "it is a file"; /* texture_of reads those with mesh_add_texture_file */
    return NULL;
}

static vkrt_wrap gltf_wrap(cgltf_int mode)
{
    return mode == 33071 ? VKRT_WRAP_CLAMP : mode == 33648 ? VKRT_WRAP_MIRROR : VKRT_WRAP_REPEAT;
}

/* The mesh texture of a glTF texture, decoded on first use with that encoding. A texture that
 * cannot be read (missing file, undecodable image) is a warning and no texture: VKRT_NO_TEXTURE. */
static vkrt_result texture_of(gltf_walk *w, const cgltf_texture *t, texture_encoding encoding, const char *what,
                              uint32_t *out)
{
    *out = VKRT_NO_TEXTURE;
    size_t k = 2 * (size_t)(t - w->data->textures) + (encoding == TEXTURE_LINEAR);
    if (w->textures[k]) {
        *out = w->textures[k] == UINT32_MAX ? VKRT_NO_TEXTURE : w->textures[k] - 1;
        return VKRT_OK;
    }
    w->textures[k] = UINT32_MAX;
    vkrt_wrap wrap_u = t->sampler ? gltf_wrap(t->sampler->wrap_s) : VKRT_WRAP_REPEAT;
    vkrt_wrap wrap_v = t->sampler ? gltf_wrap(t->sampler->wrap_t) : VKRT_WRAP_REPEAT;
    uint32_t index;
    vkrt_result r;
    const cgltf_image *image = t->image;
    if (image && !image->buffer_view && image->uri && strncmp(image->uri, "data:", 5)) {
        /* A file beside the glTF, its URI percent-decoded. */
        const char *slash = strrchr(w->path, '/');
        size_t dir = slash ? (size_t)(slash - w->path) + 1 : 0, n = dir + strlen(image->uri) + 1;
        char *file = core_alloc(w->c, n);
        if (!file) return core_fail(w->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory", w->path, what);
        memcpy(file, w->path, dir);
        strcpy(file + dir, image->uri);
        cgltf_decode_uri(file + dir);
        r = mesh_add_texture_file(w->c, w->m, file, wrap_u, wrap_v, encoding, w->path, what, &index);
        core_free(w->c, file);
    } else {
        const char *reason = "it has no image";
        size_t size = 0;
        bool owned = false, out_of_memory = false;
        const uint8_t *bytes = image ? image_bytes(w, image, &size, &owned, &reason, &out_of_memory) : NULL;
        if (out_of_memory)
            return core_fail(w->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory reading an embedded texture", w->path,
                             what);
        if (!bytes) {
            core_log(w->c, VKRT_LOG_WARN, "%s: %s: texture (embedded) cannot be read (%s); the material has no texture",
                     w->path, what, reason);
            return VKRT_OK;
        }
        r = mesh_add_texture_image(w->c, w->m, bytes, size, wrap_u, wrap_v, encoding, "(embedded)", w->path, what,
                                   &index);
        if (owned) core_free(w->c, (void *)bytes);
    }
    if (r != VKRT_OK || index == VKRT_NO_TEXTURE) return r;
    w->textures[k] = index + 1;
    *out = index;
    return VKRT_OK;
}

/* The mesh texture a material's texture view names (kind names it in messages), or
 * VKRT_NO_TEXTURE where the view names none. */
static vkrt_result view_texture(gltf_walk *w, const cgltf_texture_view *view, const char *kind,
                                texture_encoding encoding, const char *what, uint32_t *out)
{
    *out = VKRT_NO_TEXTURE;
    if (!view->texture) return VKRT_OK;
    if (view->texcoord != 0)
        core_log(w->c, VKRT_LOG_WARN, "%s: %s: %s texture reads TEXCOORD_%d; TEXCOORD_0 used", w->path, what, kind,
                 (int)view->texcoord);
    return texture_of(w, view->texture, encoding, what, out);
}

/* The mesh material of a primitive's glTF material, added on first use; 0 (the default) for a
 * primitive without one. Factors follow the glTF 2.0 defaults where absent; the emissive
 * strength of KHR_materials_emissive_strength scales the emissive factor. The base colour and
 * emissive textures are sRGB colour; the metallic-roughness texture is linear data (roughness
 * in G, metallic in B), as the specification stores them. */
static vkrt_result primitive_material(gltf_walk *w, const cgltf_primitive *prim, uint32_t *out)
{
    *out = 0;
    if (!prim->material) return VKRT_OK;
    size_t k = (size_t)(prim->material - w->data->materials);
    if (w->materials[k]) {
        *out = w->materials[k];
        return VKRT_OK;
    }
    const cgltf_material *g = prim->material;
    vkrt_material mat = { .base_color = { 1.0f, 1.0f, 1.0f, 1.0f }, .metallic = 1.0f, .roughness = 1.0f };
    if (g->has_pbr_metallic_roughness) {
        memcpy(mat.base_color, g->pbr_metallic_roughness.base_color_factor, sizeof mat.base_color);
        mat.metallic = g->pbr_metallic_roughness.metallic_factor;
        mat.roughness = g->pbr_metallic_roughness.roughness_factor;
    }
    /* MASK cuts at alpha_cutoff (0.5 by default, cgltf's too); BLEND is drawn opaque. */
    if (g->alpha_mode == cgltf_alpha_mode_mask) mat.alpha_cutoff = g->alpha_cutoff > 0.0f ? g->alpha_cutoff : 1e-6f;
    float strength = g->has_emissive_strength ? g->emissive_strength.emissive_strength : 1.0f;
    for (int i = 0; i < 3; i++) mat.emissive[i] = g->emissive_factor[i] * strength;
    char what[64];
    snprintf(what, sizeof what, "material %zu", k);
    mesh_material_textures textures = MESH_NO_TEXTURES;
    vkrt_result r = VKRT_OK;
    if (g->has_pbr_metallic_roughness) {
        const cgltf_pbr_metallic_roughness *pbr = &g->pbr_metallic_roughness;
        r = view_texture(w, &pbr->base_color_texture, "base colour", TEXTURE_SRGB, what, &textures.base_color);
        if (r == VKRT_OK)
            r = view_texture(w, &pbr->metallic_roughness_texture, "metallic-roughness", TEXTURE_LINEAR, what,
                             &textures.metallic_roughness);
    }
    if (r == VKRT_OK) r = view_texture(w, &g->emissive_texture, "emissive", TEXTURE_SRGB, what, &textures.emissive);
    if (r != VKRT_OK) return r;
    uint32_t index;
    r = mesh_add_material(w->c, w->m, &mat, &textures, VKRT_ERROR_PARSE, w->path, what, &index);
    if (r != VKRT_OK) return r;
    *out = w->materials[k] = MESH_MATERIAL(index);
    return VKRT_OK;
}

/* Triangle list indices for a primitive; strips and fans follow the winding rules of the
 * glTF 2.0 specification (section 3.7.2.1), so every triangle faces the same way. */
static vkrt_result build_indices(gltf_walk *w, const cgltf_primitive *prim, size_t count, const char *what,
                                 uint32_t **out, size_t *out_count)
{
    *out = NULL;
    *out_count = 0;
    uint32_t *src = core_alloc_array(w->c, count, sizeof *src);
    if (!src) return core_fail(w->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory", w->path, what);
    for (size_t i = 0; i < count; i++) {
        cgltf_size v = prim->indices ? cgltf_accessor_read_index(prim->indices, i) : i;
        /* Anything past UINT32_MAX is out of range for any vertex count vkrt accepts. */
        src[i] = v > UINT32_MAX ? UINT32_MAX : (uint32_t)v;
    }
    size_t tris = 0;
    if (prim->type == cgltf_primitive_type_triangles) tris = count / 3;
    else if (count >= 3) tris = count - 2;
    if (prim->type == cgltf_primitive_type_triangles) {
        *out = src;
        *out_count = tris * 3;
        return VKRT_OK;
    }
    uint32_t *list = core_alloc_array(w->c, tris, 3 * sizeof *list);
    if (!list) {
        core_free(w->c, src);
        return core_fail(w->c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory", w->path, what);
    }
    for (size_t i = 0; i < tris; i++) {
        uint32_t *t = list + 3 * i;
        if (prim->type == cgltf_primitive_type_triangle_strip) {
            t[0] = src[i];
            t[1] = src[i + 1 + i % 2];
            t[2] = src[i + 2 - i % 2];
        } else {
            t[0] = src[i + 1];
            t[1] = src[i + 2];
            t[2] = src[0];
        }
    }
    core_free(w->c, src);
    *out = list;
    *out_count = tris * 3;
    return VKRT_OK;
}

static vkrt_result append_primitive(gltf_walk *w, const cgltf_primitive *prim, size_t mesh_index, size_t prim_index,
                                    size_t node_index, const float *world)
{
    core *c = w->c;
    if (prim->type != cgltf_primitive_type_triangles && prim->type != cgltf_primitive_type_triangle_strip &&
        prim->type != cgltf_primitive_type_triangle_fan) {
        w->skipped_primitives++;
        return VKRT_OK;
    }
    w->triangle_primitives++;
    char what[96];
    snprintf(what, sizeof what, "mesh %zu primitive %zu (node %zu)", mesh_index, prim_index, node_index);
    const cgltf_accessor *pos = find_attribute(prim, cgltf_attribute_type_position);
    if (!pos) {
        /* The specification lets a client skip a primitive without positions. */
        core_log(c, VKRT_LOG_WARN, "%s: %s has no POSITION; skipped", w->path, what);
        return VKRT_OK;
    }
    if (prim->has_draco_mesh_compression && !pos->buffer_view)
        return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: %s is stored only Draco-compressed (KHR_draco_mesh_compression)",
                         w->path, what);
    if (pos->type != cgltf_type_vec3)
        return core_fail(c, VKRT_ERROR_PARSE, "%s: %s: POSITION is not a VEC3 accessor", w->path, what);
    const cgltf_accessor *nrm = find_attribute(prim, cgltf_attribute_type_normal);
    if (nrm && (nrm->type != cgltf_type_vec3 || nrm->count != pos->count)) nrm = NULL; /* computed instead */
    const cgltf_accessor *uv = find_attribute(prim, cgltf_attribute_type_texcoord);
    if (uv && (uv->type != cgltf_type_vec2 || uv->count != pos->count)) {
        core_log(c, VKRT_LOG_WARN, "%s: %s: TEXCOORD_0 is not a VEC2 per vertex; ignored", w->path, what);
        uv = NULL;
    }
    const cgltf_accessor *checks[4] = { pos, nrm, prim->indices, uv };
    static const char *const check_names[4] = { "POSITION", "NORMAL", "the index accessor", "TEXCOORD_0" };
    for (int i = 0; i < 4; i++) {
        if (checks[i] && !accessor_loaded(checks[i])) {
            bool meshopt = checks[i]->buffer_view && checks[i]->buffer_view->has_meshopt_compression;
            return core_fail(c, meshopt ? VKRT_ERROR_UNSUPPORTED : VKRT_ERROR_PARSE, "%s: %s: %s has no buffer data%s",
                             w->path, what, check_names[i], meshopt ? " (EXT_meshopt_compression is not supported)" : "");
        }
        if (checks[i] && !accessor_aligned(checks[i]))
            return core_fail(c, VKRT_ERROR_PARSE, "%s: %s: %s is not aligned to its component size (glTF 2.0 requires it)",
                             w->path, what, check_names[i]);
    }
    if (prim->indices && prim->indices->is_sparse)
        return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: %s: sparse index accessors are not supported", w->path, what);
    if (pos->count > UINT32_MAX)
        return core_fail(c, VKRT_ERROR_LIMIT, "%s: %s: more than %u vertices", w->path, what, UINT32_MAX);

    uint32_t material;
    vkrt_result r = primitive_material(w, prim, &material);
    if (r != VKRT_OK) return r;
    size_t nv = pos->count;
    float *positions = core_alloc_array(c, nv, 3 * sizeof(float));
    float *normals = nrm ? core_alloc_array(c, nv, 3 * sizeof(float)) : NULL;
    float *texcoords = uv ? core_alloc_array(c, nv, 2 * sizeof(float)) : NULL;
    uint32_t *indices = NULL;
    size_t index_count = 0;
    if (!positions || (nrm && !normals) || (uv && !texcoords)) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: %s: out of memory", w->path, what);
        goto done;
    }
    /* unpack_floats converts every component type (KHR_mesh_quantization's integers,
     * normalized or not) and applies sparse substitutions. */
    if (nv && cgltf_accessor_unpack_floats(pos, positions, nv * 3) != nv * 3) {
        r = core_fail(c, VKRT_ERROR_PARSE, "%s: %s: POSITION cannot be read", w->path, what);
        goto done;
    }
    if (nrm && nv && cgltf_accessor_unpack_floats(nrm, normals, nv * 3) != nv * 3) {
        r = core_fail(c, VKRT_ERROR_PARSE, "%s: %s: NORMAL cannot be read", w->path, what);
        goto done;
    }
    if (uv && nv && cgltf_accessor_unpack_floats(uv, texcoords, nv * 2) != nv * 2) {
        r = core_fail(c, VKRT_ERROR_PARSE, "%s: %s: TEXCOORD_0 cannot be read", w->path, what);
        goto done;
    }
    size_t count = prim->indices ? prim->indices->count : nv;
    if ((r = build_indices(w, prim, count, what, &indices, &index_count)) != VKRT_OK) goto done;
    r = mesh_append_indexed(c, w->m,
                            &(mesh_primitive){ .positions = positions, .vertex_count = nv, .indices = indices,
                                               .index_count = index_count, .normals = normals, .transform = world,
                                               .texcoords = texcoords, .material = material },
                            w->path, what);
done:
    core_free(c, positions);
    core_free(c, normals);
    core_free(c, texcoords);
    core_free(c, indices);
    return r;
}

/* The node hierarchy as child lists: node i's children are child[first[i] .. first[i + 1]). */
typedef struct gltf_hierarchy {
    size_t *first;
    size_t *child;
} gltf_hierarchy;

static void hierarchy_free(core *c, gltf_hierarchy *h)
{
    core_free(c, h->first);
    core_free(c, h->child);
    h->first = h->child = NULL;
}

static vkrt_result hierarchy_from_cgltf(core *c, const char *path, const cgltf_data *data, gltf_hierarchy *h)
{
    size_t total = 0;
    for (cgltf_size i = 0; i < data->nodes_count; i++) total += data->nodes[i].children_count;
    h->first = core_alloc_array(c, data->nodes_count + 1, sizeof *h->first);
    h->child = core_alloc_array(c, total, sizeof *h->child);
    if (!h->first || !h->child) return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory", path);
    size_t n = 0;
    for (cgltf_size i = 0; i < data->nodes_count; i++) {
        h->first[i] = n;
        for (cgltf_size k = 0; k < data->nodes[i].children_count; k++)
            h->child[n++] = (size_t)(data->nodes[i].children[k] - data->nodes);
    }
    h->first[data->nodes_count] = n;
    return VKRT_OK;
}

/* ---- nodes with several parents ----------------------------------------------------------
 * cgltf 1.12 refuses a file that lists a node as the child of two nodes (glTF-Validator's
 * NODE_PARENT_OVERRIDE), and exporters write exactly that to instance a subtree. Such a file
 * is parsed a second time with its "children" keys renamed to a key cgltf skips, and the
 * child lists are read from the JSON here. The JSON has then already passed cgltf's parser;
 * this reader still checks every byte it reads. */

#define HIDDEN_CHILDREN "\"chIldren\"" /* same length as "children", so GLB offsets hold */
#define JSON_MAX_DEPTH 64              /* deeper nesting is no glTF vkrt can use */

typedef struct json_reader {
    const char *p, *end;
} json_reader;

static void json_space(json_reader *j)
{
    while (j->p < j->end && (*j->p == ' ' || *j->p == '\t' || *j->p == '\n' || *j->p == '\r')) j->p++;
}

static bool json_expect(json_reader *j, char ch)
{
    json_space(j);
    if (j->p >= j->end || *j->p != ch) return false;
    j->p++;
    return true;
}

/* A string's raw bytes between the quotes (escapes left as written, as cgltf compares keys). */
static bool json_string(json_reader *j, const char **s, size_t *n)
{
    if (!json_expect(j, '"')) return false;
    const char *start = j->p;
    while (j->p < j->end && *j->p != '"') j->p += *j->p == '\\' ? 2 : 1;
    if (j->p >= j->end) return false;
    *s = start;
    *n = (size_t)(j->p - start);
    j->p++;
    return true;
}

static bool json_skip(json_reader *j, int depth)
{
    json_space(j);
    if (j->p >= j->end || depth > JSON_MAX_DEPTH) return false;
    char ch = *j->p;
    if (ch == '"') {
        const char *s;
        size_t n;
        return json_string(j, &s, &n);
    }
    if (ch == '{' || ch == '[') {
        char close = ch == '{' ? '}' : ']';
        j->p++;
        if (json_expect(j, close)) return true;
        do {
            if (ch == '{') {
                const char *s;
                size_t n;
                if (!json_string(j, &s, &n) || !json_expect(j, ':')) return false;
            }
            if (!json_skip(j, depth + 1)) return false;
        } while (json_expect(j, ','));
        return json_expect(j, close);
    }
    /* number, true, false, null */
    const char *start = j->p;
    while (j->p < j->end && *j->p != ',' && *j->p != '}' && *j->p != ']' && *j->p != ' ' && *j->p != '\n' &&
           *j->p != '\r' && *j->p != '\t')
        j->p++;
    return j->p > start;
}

static bool json_key_is(const char *s, size_t n, const char *quoted)
{
    size_t q = strlen(quoted) - 2;
    return n == q && memcmp(s, quoted + 1, q) == 0;
}

/* Reads nodes[i].<hidden children> into h; false when the JSON is not as cgltf read it. */
static bool read_hidden_children(core *c, const char *json, size_t size, size_t nodes_count, gltf_hierarchy *h,
                                 bool *out_of_memory)
{
    size_t capacity = 0, used = 0, node = 0;
    json_reader j = { json, json + size };
    h->first = core_calloc_array(c, nodes_count + 1, sizeof *h->first);
    if (!h->first) return !(*out_of_memory = true);
    if (!json_expect(&j, '{')) return false;
    if (json_expect(&j, '}')) return nodes_count == 0;
    do {
        const char *key;
        size_t n;
        if (!json_string(&j, &key, &n) || !json_expect(&j, ':')) return false;
        if (!json_key_is(key, n, "\"nodes\"")) {
            if (!json_skip(&j, 1)) return false;
            continue;
        }
        if (!json_expect(&j, '[')) return false;
        if (json_expect(&j, ']')) continue;
        do {
            if (node >= nodes_count || !json_expect(&j, '{')) return false;
            h->first[node] = used;
            if (!json_expect(&j, '}')) {
                do {
                    if (!json_string(&j, &key, &n) || !json_expect(&j, ':')) return false;
                    if (!json_key_is(key, n, HIDDEN_CHILDREN)) {
                        if (!json_skip(&j, 2)) return false;
                        continue;
                    }
                    if (!json_expect(&j, '[')) return false;
                    if (json_expect(&j, ']')) continue;
                    do {
                        json_space(&j);
                        size_t v = 0, digits = 0;
                        while (j.p < j.end && *j.p >= '0' && *j.p <= '9' && digits < 12) {
                            v = v * 10 + (size_t)(*j.p++ - '0');
                            digits++;
                        }
                        if (!digits || v >= nodes_count) return false;
                        if (core_grow(c, (void **)&h->child, &capacity, used + 1, sizeof *h->child))
                            return !(*out_of_memory = true);
                        h->child[used++] = v;
                    } while (json_expect(&j, ','));
                    if (!json_expect(&j, ']')) return false;
                } while (json_expect(&j, ','));
                if (!json_expect(&j, '}')) return false;
            }
            node++;
        } while (json_expect(&j, ','));
        if (!json_expect(&j, ']')) return false;
    } while (json_expect(&j, ','));
    if (!json_expect(&j, '}') || node != nodes_count) return false;
    h->first[nodes_count] = used;
    if (!h->child && !(h->child = core_alloc(c, 1))) return !(*out_of_memory = true);
    return true;
}

static vkrt_result read_whole_file(core *c, const char *path, char **out, size_t *out_size)
{
    void *bytes = NULL;
    file_read_status status = file_read(c, path, 0, &bytes, out_size);
    if (status == FILE_READ_OUT_OF_MEMORY)
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory reading the file", path);
    if (status != FILE_READ_OK)
        return core_fail(c, VKRT_ERROR_IO, "%s: cannot read: %s", path, file_read_status_text(status, errno));
    *out = bytes;
    return VKRT_OK;
}

static uint32_t read_u32le(const char *p)
{
    const unsigned char *u = (const unsigned char *)p;
    return (uint32_t)u[0] | (uint32_t)u[1] << 8 | (uint32_t)u[2] << 16 | (uint32_t)u[3] << 24;
}

/* Parses path again with its child lists hidden from cgltf. *out_file holds the file, which
 * a GLB's binary chunk points into, until cgltf_free(). When the file still does not parse,
 * returns VKRT_OK with *out_data NULL, and the caller reports the first failure. */
static vkrt_result parse_with_shared_children(core *c, const char *path, const cgltf_options *options,
                                              cgltf_data **out_data, char **out_file, gltf_hierarchy *h)
{
    char *file = NULL;
    size_t size = 0;
    vkrt_result r = read_whole_file(c, path, &file, &size);
    if (r != VKRT_OK) return r;
    *out_file = file;
    char *json = file;
    size_t json_size = size;
    if (size >= 20 && memcmp(file, "glTF", 4) == 0) {
        json = file + 20;
        json_size = read_u32le(file + 12);
        if (json_size > size - 20 || read_u32le(file + 16) != 0x4E4F534Au) return VKRT_OK; /* not a JSON chunk */
    }
    const size_t key = sizeof HIDDEN_CHILDREN - 1;
    for (size_t i = 0; i + key <= json_size; i++)
        if (memcmp(json + i, "\"children\"", key) == 0) memcpy(json + i, HIDDEN_CHILDREN, key);
    cgltf_result cr = cgltf_parse(options, file, size, out_data);
    if (cr == cgltf_result_out_of_memory)
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory parsing glTF", path);
    if (cr != cgltf_result_success) {
        *out_data = NULL;
        return VKRT_OK;
    }
    bool oom = false;
    if (!read_hidden_children(c, json, json_size, (*out_data)->nodes_count, h, &oom))
        return oom ? core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory", path)
                   : core_fail(c, VKRT_ERROR_PARSE, "%s: cannot read the node hierarchy", path);
    return VKRT_OK;
}

/* ---- the walk ---------------------------------------------------------------------------- */

typedef struct walk_frame {
    size_t node;
    size_t next_child; /* position in the hierarchy's child array */
    float world[16];
} walk_frame;

static void multiply(const float *a, const float *b, float *out)
{
    for (int col = 0; col < 4; col++)
        for (int row = 0; row < 4; row++) {
            double sum = 0.0;
            for (int k = 0; k < 4; k++) sum += (double)a[k * 4 + row] * b[col * 4 + k];
            out[col * 4 + row] = (float)sum;
        }
}

static bool finite3(const float *v)
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

/* A node's KHR_lights_punctual light, placed by the node's world transform: a directional light
 * shines along the node's -Z axis, a point light sits at its origin. Intensities are taken as
 * radiometric as they are (candela as W/sr, lux as W/m^2): the tracers have no photometric
 * scale, and a constant factor would only change the exposure. `range` is a cut-off the
 * extension lets a renderer ignore; the falloff stays 1/d^2. A spot light is lit as a point
 * light: its cone is ignored, with a warning. */
static vkrt_result append_light(gltf_walk *w, const cgltf_light *g, size_t node_index, const float *world)
{
    size_t k = (size_t)(g - w->data->lights);
    char what[64];
    snprintf(what, sizeof what, "light %zu (node %zu)", k, node_index);
    bool valid = g->intensity >= 0.0f && isfinite(g->intensity);
    for (int i = 0; i < 3; i++) valid = valid && g->color[i] >= 0.0f && isfinite(g->color[i]);
    if (!valid)
        return core_fail(w->c, VKRT_ERROR_PARSE, "%s: %s: color (%g, %g, %g) and intensity %g must be finite and >= 0",
                         w->path, what, (double)g->color[0], (double)g->color[1], (double)g->color[2],
                         (double)g->intensity);
    vkrt_light light = { .type = VKRT_LIGHT_POINT };
    for (int i = 0; i < 3; i++) light.color[i] = (float)((double)g->color[i] * g->intensity);
    if (!finite3(light.color))
        return core_fail(w->c, VKRT_ERROR_PARSE, "%s: %s: color times intensity %g overflows the float range", w->path,
                         what, (double)g->intensity);
    switch (g->type) {
    case cgltf_light_type_directional: {
        light.type = VKRT_LIGHT_DIRECTIONAL;
        double d[3] = { -(double)world[8], -(double)world[9], -(double)world[10] };
        double length = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        if (length == 0.0) {
            /* A node scaled to 0 along its Z axis: the light points nowhere and adds nothing. */
            core_log(w->c, VKRT_LOG_WARN, "%s: %s: the node's transform collapses its -Z axis, the direction the "
                     "light shines; the light is ignored", w->path, what);
            return VKRT_OK;
        }
        for (int i = 0; i < 3; i++) light.vector[i] = (float)(d[i] / length); /* NaN for an infinite axis */
        break;
    }
    case cgltf_light_type_spot:
        if (!w->spot_warned[k]) {
            w->spot_warned[k] = true;
            core_log(w->c, VKRT_LOG_WARN, "%s: %s: spot light lit as a point light (its cone is ignored)", w->path,
                     what);
        }
        /* fall through */
    case cgltf_light_type_point:
        for (int i = 0; i < 3; i++) light.vector[i] = world[12 + i];
        break;
    default:
        core_log(w->c, VKRT_LOG_WARN, "%s: %s has no type vkrt knows (directional, point or spot); ignored", w->path,
                 what);
        return VKRT_OK;
    }
    return mesh_add_light(w->c, w->m, &light, VKRT_ERROR_PARSE, w->path, what);
}

static vkrt_result walk_nodes(gltf_walk *w, const gltf_hierarchy *h, const size_t *roots, size_t root_count)
{
    core *c = w->c;
    const cgltf_data *data = w->data;
    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    /* A path never holds a node twice (that is a cycle), so nodes_count frames suffice. */
    walk_frame *stack = core_alloc_array(c, data->nodes_count, sizeof *stack);
    bool *on_path = core_calloc_array(c, data->nodes_count, sizeof *on_path);
    size_t visits = 0;
    if (!stack || !on_path) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory walking the node hierarchy", w->path);
        goto done;
    }
    static const float identity[16] = { 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1 };
    for (size_t ri = 0; ri < root_count; ri++) {
        size_t depth = 0;
        size_t next = roots[ri];
        bool have_next = true;
        const float *parent_world = identity;
        for (;;) {
            if (have_next) {
                if (on_path[next]) {
                    r = core_fail(c, VKRT_ERROR_PARSE, "%s: node %zu is its own ancestor (a cycle in the hierarchy)",
                                  w->path, next);
                    goto done;
                }
                if (++visits > GLTF_MAX_NODE_VISITS) {
                    r = core_fail(c, VKRT_ERROR_LIMIT, "%s: the node hierarchy expands to more than %u node instances",
                                  w->path, GLTF_MAX_NODE_VISITS);
                    goto done;
                }
                const cgltf_node *node = &data->nodes[next];
                walk_frame *f = &stack[depth++];
                f->node = next;
                f->next_child = h->first[next];
                float local[16];
                cgltf_node_transform_local(node, local);
                multiply(parent_world, local, f->world);
                on_path[next] = true;
                if (node->mesh) {
                    const cgltf_mesh *mesh_ = node->mesh;
                    for (cgltf_size p = 0; p < mesh_->primitives_count; p++) {
                        r = append_primitive(w, &mesh_->primitives[p], (size_t)(mesh_ - data->meshes), (size_t)p, next,
                                             f->world);
                        if (r != VKRT_OK) goto done;
                    }
                }
                if (node->light && (r = append_light(w, node->light, next, f->world)) != VKRT_OK) goto done;
            }
            if (depth == 0) break;
            walk_frame *top = &stack[depth - 1];
            if (top->next_child < h->first[top->node + 1]) {
                next = h->child[top->next_child++];
                have_next = true;
                parent_world = top->world;
            } else {
                on_path[top->node] = false;
                depth--;
                have_next = false;
            }
        }
    }
    r = VKRT_OK;
done:
    core_free(c, stack);
    core_free(c, on_path);
    return r;
}

vkrt_result mesh_load_gltf(core *c, const char *path, mesh *m)
{
    memset(m, 0, sizeof *m);
    cgltf_options options = { .memory = { .alloc_func = gltf_alloc, .free_func = gltf_free, .user_data = c },
                              .file = { .read = gltf_read_file } };
    cgltf_data *data = NULL;
    char *file = NULL; /* only for a file with shared children */
    gltf_hierarchy h = { 0 };
    size_t *roots = NULL;
    errno = 0;
    cgltf_result cr = cgltf_parse_file(&options, path, &data);
    int parse_errno = errno;
    vkrt_result r;
    if (cr == cgltf_result_invalid_gltf) {
        data = NULL;
        if ((r = parse_with_shared_children(c, path, &options, &data, &file, &h)) != VKRT_OK) goto done;
        if (!data) {
            r = parse_failure(c, path, cr, 0);
            goto done;
        }
    } else if (cr != cgltf_result_success) {
        r = parse_failure(c, path, cr, parse_errno);
        goto done;
    } else if ((r = hierarchy_from_cgltf(c, path, data, &h)) != VKRT_OK) {
        goto done;
    }
    /* Before the buffers: a Draco-only file may have none vkrt could load anyway. */
    if ((r = check_required_extensions(c, path, data)) != VKRT_OK) goto done;
    if ((r = check_data_uri_lengths(c, path, data)) != VKRT_OK) goto done;
    if ((cr = cgltf_load_buffers(&options, data, path)) != cgltf_result_success) {
        r = buffers_failure(c, path, data, cr);
        goto done;
    }
    if ((r = check_data_ranges(c, path, data)) != VKRT_OK) goto done;
    if ((r = check_validated_alignment(c, path, data)) != VKRT_OK) goto done;
    if ((cr = cgltf_validate(data)) != cgltf_result_success) {
        if ((r = find_bad_index(c, path, data)) != VKRT_OK) goto done;
        r = cr == cgltf_result_data_too_short
                ? core_fail(c, VKRT_ERROR_PARSE, "%s: an accessor or buffer view reaches past the end of its data", path)
                : parse_failure(c, path, cr, 0);
        goto done;
    }

    const cgltf_scene *scene = data->scene ? data->scene : data->scenes_count ? &data->scenes[0] : NULL;
    size_t root_count = 0;
    roots = core_alloc_array(c, scene ? scene->nodes_count : data->nodes_count, sizeof *roots);
    if (!roots) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory", path);
        goto done;
    }
    if (scene) {
        for (cgltf_size i = 0; i < scene->nodes_count; i++) roots[root_count++] = (size_t)(scene->nodes[i] - data->nodes);
    } else {
        /* No scene at all: every node that no node lists as a child, in index order. */
        for (cgltf_size i = 0; i < data->nodes_count; i++) roots[i] = 1;
        for (size_t k = 0; k < h.first[data->nodes_count]; k++) roots[h.child[k]] = 0;
        for (cgltf_size i = 0; i < data->nodes_count; i++)
            if (roots[i]) roots[root_count++] = i;
    }
    gltf_walk w = { .c = c, .path = path, .data = data, .m = m, .options = &options };
    w.materials = core_calloc_array(c, data->materials_count ? data->materials_count : 1, sizeof *w.materials);
    w.textures = core_calloc_array(c, data->textures_count ? data->textures_count : 1, 2 * sizeof *w.textures);
    w.spot_warned = core_calloc_array(c, data->lights_count ? data->lights_count : 1, sizeof *w.spot_warned);
    if (!w.materials || !w.textures || !w.spot_warned) {
        core_free(c, w.materials);
        core_free(c, w.textures);
        core_free(c, w.spot_warned);
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory", path);
        goto done;
    }
    r = walk_nodes(&w, &h, roots, root_count);
    core_free(c, w.materials);
    core_free(c, w.textures);
    core_free(c, w.spot_warned);
    if (r != VKRT_OK) goto done;
    if (m->tri_count == 0) {
        if (w.skipped_primitives && !w.triangle_primitives)
            r = core_fail(c, VKRT_ERROR_EMPTY_SCENE, "%s: has only points or lines (%zu primitives), no triangles", path,
                          w.skipped_primitives);
        else
            r = core_fail(c, VKRT_ERROR_EMPTY_SCENE, "%s: the scene has no triangles", path);
        goto done;
    }
    r = VKRT_OK;
done:
    mesh_finish(c, m, r);
    core_free(c, roots);
    hierarchy_free(c, &h);
    cgltf_free(data);
    core_free(c, file);
    return r;
}
