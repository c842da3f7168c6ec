/* glTF 2.0 (.gltf with external or base64 buffers, and .glb) through cgltf.
 *
 * The default scene's nodes are walked depth first, each node's mesh before its children,
 * and every triangle primitive of a node's mesh is appended with the node's world
 * transform. The walk multiplies transforms down the path it took instead of asking cgltf
 * for a node's world matrix, because cgltf keeps one parent per node while files do give a
 * node several parents (an instance under each); a node on the current path is a cycle. */
#include "mesh.h"

#include <errno.h>
#include <stdio.h>
#include <string.h>

#include <cgltf.h>

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
        return core_fail(c, VKRT_ERROR_PARSE, "%s: invalid glTF (a required property is missing or a reference is out of range)", path);
    case cgltf_result_legacy_gltf:
        return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: glTF 1.0 is not supported (glTF 2.0 is)", path);
    default:
        return core_fail(c, VKRT_ERROR_PARSE, "%s: cgltf failed (result %d)", path, (int)cr);
    }
}

/* Extensions a file may require that change nothing vkrt reads: geometry only, no materials
 * or textures. KHR_mesh_quantization is decoded by cgltf_accessor_unpack_floats. */
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
        return core_fail(c, VKRT_ERROR_IO, "%s: buffer %zu: cannot read '%s' (shorter than its byteLength?)", path,
                         (size_t)i, shown);
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

typedef struct gltf_walk {
    core *c;
    const char *path;
    const cgltf_data *data;
    mesh *m;
    size_t skipped_primitives; /* points and lines */
    size_t triangle_primitives;
} gltf_walk;

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
    const cgltf_accessor *checks[3] = { pos, nrm, prim->indices };
    for (int i = 0; i < 3; i++) {
        if (checks[i] && !accessor_loaded(checks[i])) {
            bool meshopt = checks[i]->buffer_view && checks[i]->buffer_view->has_meshopt_compression;
            return core_fail(c, meshopt ? VKRT_ERROR_UNSUPPORTED : VKRT_ERROR_PARSE, "%s: %s: %s has no buffer data%s",
                             w->path, what, i == 0 ? "POSITION" : i == 1 ? "NORMAL" : "the index accessor",
                             meshopt ? " (EXT_meshopt_compression is not supported)" : "");
        }
    }
    if (prim->indices && prim->indices->is_sparse)
        return core_fail(c, VKRT_ERROR_UNSUPPORTED, "%s: %s: sparse index accessors are not supported", w->path, what);
    if (pos->count > UINT32_MAX)
        return core_fail(c, VKRT_ERROR_LIMIT, "%s: %s: more than %u vertices", w->path, what, UINT32_MAX);

    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    size_t nv = pos->count;
    float *positions = core_alloc_array(c, nv, 3 * sizeof(float));
    float *normals = nrm ? core_alloc_array(c, nv, 3 * sizeof(float)) : NULL;
    uint32_t *indices = NULL;
    size_t index_count = 0;
    if (!positions || (nrm && !normals)) {
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
    size_t count = prim->indices ? prim->indices->count : nv;
    if ((r = build_indices(w, prim, count, what, &indices, &index_count)) != VKRT_OK) goto done;
    r = mesh_append_indexed(c, w->m,
                            &(mesh_primitive){ .positions = positions, .vertex_count = nv, .indices = indices,
                                               .index_count = index_count, .normals = normals, .transform = world },
                            w->path, what);
done:
    core_free(c, positions);
    core_free(c, normals);
    core_free(c, indices);
    return r;
}

typedef struct walk_frame {
    const cgltf_node *node;
    cgltf_size next_child;
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

static vkrt_result walk_nodes(gltf_walk *w, cgltf_node *const *roots, size_t root_count)
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
        const cgltf_node *next = roots[ri];
        const float *parent_world = identity;
        for (;;) {
            if (next) {
                size_t index = (size_t)(next - data->nodes);
                if (on_path[index]) {
                    r = core_fail(c, VKRT_ERROR_PARSE, "%s: node %zu is its own ancestor (a cycle in the hierarchy)",
                                  w->path, index);
                    goto done;
                }
                if (++visits > GLTF_MAX_NODE_VISITS) {
                    r = core_fail(c, VKRT_ERROR_LIMIT, "%s: the node hierarchy expands to more than %u node instances",
                                  w->path, GLTF_MAX_NODE_VISITS);
                    goto done;
                }
                walk_frame *f = &stack[depth++];
                f->node = next;
                f->next_child = 0;
                float local[16];
                cgltf_node_transform_local(next, local);
                multiply(parent_world, local, f->world);
                on_path[index] = true;
                if (next->mesh) {
                    const cgltf_mesh *mesh_ = next->mesh;
                    for (cgltf_size p = 0; p < mesh_->primitives_count; p++) {
                        r = append_primitive(w, &mesh_->primitives[p], (size_t)(mesh_ - data->meshes), (size_t)p, index,
                                             f->world);
                        if (r != VKRT_OK) goto done;
                    }
                }
            }
            if (depth == 0) break;
            walk_frame *top = &stack[depth - 1];
            if (top->next_child < top->node->children_count) {
                next = top->node->children[top->next_child++];
                parent_world = top->world;
            } else {
                on_path[(size_t)(top->node - data->nodes)] = false;
                depth--;
                next = NULL;
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
    cgltf_options options = { .memory = { .alloc_func = gltf_alloc, .free_func = gltf_free, .user_data = c } };
    cgltf_data *data = NULL;
    cgltf_node **roots = NULL;
    errno = 0;
    cgltf_result cr = cgltf_parse_file(&options, path, &data);
    vkrt_result r;
    if (cr != cgltf_result_success) {
        r = parse_failure(c, path, cr, errno);
        goto fail;
    }
    /* Before the buffers: a Draco-only file may have none vkrt could load anyway. */
    if ((r = check_required_extensions(c, path, data)) != VKRT_OK) goto fail;
    if ((cr = cgltf_load_buffers(&options, data, path)) != cgltf_result_success) {
        r = buffers_failure(c, path, data, cr);
        goto fail;
    }
    if ((cr = cgltf_validate(data)) != cgltf_result_success) {
        if ((r = find_bad_index(c, path, data)) != VKRT_OK) goto fail;
        r = cr == cgltf_result_data_too_short
                ? core_fail(c, VKRT_ERROR_PARSE, "%s: an accessor or buffer view reaches past the end of its data", path)
                : parse_failure(c, path, cr, 0);
        goto fail;
    }

    const cgltf_scene *scene = data->scene ? data->scene : data->scenes_count ? &data->scenes[0] : NULL;
    cgltf_node *const *root_list;
    size_t root_count = 0;
    if (scene) {
        root_list = scene->nodes;
        root_count = scene->nodes_count;
    } else {
        /* No scene at all: every node nothing lists as a child. */
        roots = core_alloc_array(c, data->nodes_count, sizeof *roots);
        if (!roots) {
            r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "%s: out of memory", path);
            goto fail;
        }
        for (cgltf_size i = 0; i < data->nodes_count; i++)
            if (!data->nodes[i].parent) roots[root_count++] = &data->nodes[i];
        root_list = roots;
    }
    gltf_walk w = { .c = c, .path = path, .data = data, .m = m };
    if ((r = walk_nodes(&w, root_list, root_count)) != VKRT_OK) goto fail;
    if (m->tri_count == 0) {
        if (w.skipped_primitives && !w.triangle_primitives)
            r = core_fail(c, VKRT_ERROR_EMPTY_SCENE, "%s: has only points or lines (%zu primitives), no triangles", path,
                          w.skipped_primitives);
        else
            r = core_fail(c, VKRT_ERROR_EMPTY_SCENE, "%s: the scene has no triangles", path);
        goto fail;
    }
    core_free(c, roots);
    cgltf_free(data);
    mesh_update_bounds(m);
    return VKRT_OK;
fail:
    core_free(c, roots);
    cgltf_free(data);
    mesh_destroy(c, m);
    return r;
}
