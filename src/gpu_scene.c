/* A scene's arrays on the device: see gpu_scene.h. */
#include "gpu_scene.h"

#include <assert.h>
#include <stdio.h>
#include <string.h>

#include "wide_pack.h"

static vkrt_result check_range(vk_context *vk, VkDeviceSize bytes, const char *what)
{
    VkDeviceSize limit = vk->properties.limits.maxStorageBufferRange;
    if (bytes > limit)
        return core_fail(vk->core, VKRT_ERROR_LIMIT,
                         "the scene's %s need %llu bytes, more than this device's storage buffer limit of %llu bytes",
                         what, (unsigned long long)bytes, (unsigned long long)limit);
    return VKRT_OK;
}

/* The most bytes one buffer of the scene's arrays may hold: what a descriptor can bind (the
 * first piece of each array is bound as an ordinary storage buffer), what one allocation may
 * be, and the test knob, whichever is least. */
static VkDeviceSize piece_limit(const vk_context *vk)
{
    VkDeviceSize limit = vk->properties.limits.maxStorageBufferRange;
    if (vk->max_allocation && vk->max_allocation < limit) limit = vk->max_allocation;
    if (vk->scene_buffer_limit && vk->scene_buffer_limit < limit) limit = vk->scene_buffer_limit;
    /* Two triangles at least, so a split scene's pieces hold 2^1 elements or more. */
    return limit < 2 * sizeof(vkrt_gpu_tri) ? 2 * sizeof(vkrt_gpu_tri) : limit;
}

/* The pieces an array of `count` elements is split into (1 where the scene is not split). */
static uint64_t piece_count(uint64_t count, uint32_t shift)
{
    return shift ? (count + ((uint64_t)1 << shift) - 1) >> shift : 1;
}

static void gpu_array_destroy(vk_context *vk, gpu_array *a)
{
    for (uint32_t i = 0; i < a->count; i++) vk_buffer_destroy(vk, &a->pieces[i]);
    core_free(vk->core, a->pieces);
    a->pieces = NULL;
    a->count = 0;
}

/* `count` elements of `elem_size` bytes into one buffer (shift 0), or into pieces of
 * 2^shift elements each. */
static vkrt_result gpu_array_upload(vk_context *vk, const void *data, uint64_t count, size_t elem_size, uint32_t shift,
                                    const char *label, gpu_array *out)
{
    const uint64_t per_piece = shift ? (uint64_t)1 << shift : (count ? count : 1);
    const uint64_t pieces = count ? piece_count(count, shift) : 1;
    out->pieces = core_calloc_array(vk->core, (size_t)pieces, sizeof *out->pieces);
    if (!out->pieces)
        return core_fail(vk->core, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for the %llu buffers of the scene's %s",
                         (unsigned long long)pieces, label);
    out->count = (uint32_t)pieces;
    VkBufferUsageFlags usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    if (shift) usage |= VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT;
    vkrt_result r = VKRT_OK;
    for (uint64_t k = 0; k < pieces && r == VKRT_OK; k++) {
        const uint64_t first = k * per_piece;
        const uint64_t n = count - first < per_piece ? count - first : per_piece;
        char name[64];
        if (shift) snprintf(name, sizeof name, "vkrt %s (piece %llu)", label, (unsigned long long)k);
        else snprintf(name, sizeof name, "vkrt %s", label);
        r = vk_buffer_create(vk, n * elem_size, usage, VK_MEMORY_DEVICE, name, &out->pieces[k]);
        if (r == VKRT_OK) r = vk_buffer_upload(vk, &out->pieces[k], (const char *)data + first * elem_size, n * elem_size);
    }
    return r;
}

/* Fills the piece table of a split scene with the address of every piece (the entries of an
 * array still a placeholder stay zero: no pipeline reads it before it is uploaded). */
static vkrt_result write_piece_table(vk_context *vk, gpu_scene *s)
{
    if (!s->split_shift) return VKRT_OK;
    const size_t entries = (size_t)s->pieces.size / sizeof(vkrt_gpu_address);
    vkrt_gpu_address *table = core_calloc_array(vk->core, entries, sizeof *table);
    if (!table) return core_fail(vk->core, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for the scene's piece table");
    const gpu_array *arrays[VKRT_PIECE_ARRAYS] = {
        [VKRT_PIECE_TRIS] = &s->tris, [VKRT_PIECE_NODES] = &s->nodes, [VKRT_PIECE_SURFACES] = &s->surfaces };
    const bool uploaded[VKRT_PIECE_ARRAYS] = {
        [VKRT_PIECE_TRIS] = s->tris_uploaded, [VKRT_PIECE_NODES] = s->nodes_uploaded,
        [VKRT_PIECE_SURFACES] = s->surfaces_uploaded };
    for (uint32_t a = 0; a < VKRT_PIECE_ARRAYS; a++) {
        if (!uploaded[a]) continue;
        for (uint32_t k = 0; k < arrays[a]->count; k++) {
            VkDeviceAddress address = vk_buffer_address(vk, &arrays[a]->pieces[k]);
            table[(size_t)VKRT_PIECE_ARRAYS * k + a] = (vkrt_gpu_address){ (uint32_t)address, (uint32_t)(address >> 32) };
        }
    }
    vkrt_result r = vk_buffer_upload(vk, &s->pieces, table, s->pieces.size);
    core_free(vk->core, table);
    return r;
}

/* Both wide texel buffers, `usable` (else a texel each, placeholders for the bindings). */
static vkrt_result create_wide_buffers(vk_context *vk, const wide_arrays *w, bool usable, gpu_scene *out)
{
    vkrt_result r = vk_texel_buffer_create(vk, w->node_texels, usable ? w->node_count * VKRT_WIDE_NODE_TEXELS : 0,
                                           "vkrt wide BVH", &out->wide_nodes);
    if (r == VKRT_OK)
        r = vk_texel_buffer_create(vk, w->tri_texels, usable ? (uint32_t)w->tri_texel_count : 0, "vkrt wide triangles",
                                   &out->trace_tris);
    if (r != VKRT_OK) {
        vk_texel_buffer_destroy(vk, &out->wide_nodes);
        vk_texel_buffer_destroy(vk, &out->trace_tris);
    }
    return r;
}

/* The wide traversal's texel buffers, or placeholders where the wide BVH does not fit the
 * traversal's stack, the device's texel buffer limit or its memory. A split scene (whose
 * triangles exceed one storage buffer) has them too: a texel buffer's limit is in texels (2^27
 * on lavapipe, 2.5 a triangle), not the storage buffer range, and the binary BVH it was traced
 * through before was 2x slower on primary rays of the 1e7-triangle procedural scene, 5x on
 * AO rays. A scene whose wide arrays the device cannot allocate (each is one buffer, where the
 * binary arrays are in pieces) keeps to the binary BVH, with a warning, rather than failing,
 * as one beyond their limits does. */
static vkrt_result upload_wide(vk_context *vk, const bvh *b, const vkrt_gpu_tri *tris, uint32_t threads, gpu_scene *out,
                               uint64_t *out_unfit_bytes)
{
    *out_unfit_bytes = 0;
    wide_arrays w = { 0 };
    vkrt_result r = VKRT_OK;
    const double t0 = core_now_ms();
    if (!vk->no_wide_traversal) r = wide_pack(vk->core, b, tris, threads, &w);
    out->wide_pack_ms = core_now_ms() - t0;
    if (r != VKRT_OK) return r;
    const uint64_t texel_limit = vk->properties.limits.maxTexelBufferElements;
    /* The wide traversal also reads a chunk's rays (two texels each) and writes its hits (four
     * words each) through texel views of the ray and hit buffers. */
    const bool usable = w.node_count && wide_traversal_fits(w.depth, w.tri_count) &&
                        (uint64_t)w.node_count * VKRT_WIDE_NODE_TEXELS <= texel_limit &&
                        w.tri_texel_count <= texel_limit && 4ull * VKRT_RAY_CHUNK <= texel_limit;
    r = create_wide_buffers(vk, &w, usable, out);
    bool wide = usable;
    if (r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY && usable) {
        *out_unfit_bytes = ((uint64_t)w.node_count * VKRT_WIDE_NODE_TEXELS + w.tri_texel_count) * 16u;
        wide = false;
        r = create_wide_buffers(vk, &w, false, out);
    }
    out->wide = r == VKRT_OK && wide;
    wide_arrays_destroy(vk->core, &w);
    return r;
}

vkrt_result gpu_scene_upload(vk_context *vk, const bvh *b, const vkrt_gpu_tri *tris, uint32_t threads, gpu_scene *out)
{
    memset(out, 0, sizeof *out);
    const uint32_t node_count = b->node_count, tri_count = b->tri_count;
    const VkDeviceSize limit = piece_limit(vk);
    const VkDeviceSize tri_bytes = (VkDeviceSize)tri_count * sizeof *tris;
    vkrt_result r = VKRT_OK;
    /* The triangles are the largest array (at most 2T - 1 nodes of 32 bytes are fewer bytes than
     * T triangles of 64) and set the one shift of every array: a piece holds as many triangles
     * as fit the limit, rounded down to a power of two. */
    assert((VkDeviceSize)node_count * sizeof *b->nodes <= tri_bytes);
    if (tri_bytes > limit) {
        if (!vk->buffer_address)
            return core_fail(vk->core, VKRT_ERROR_LIMIT,
                             "the scene's triangles need %llu bytes, more than one buffer of this device may hold "
                             "(%llu bytes), and the device lacks bufferDeviceAddress to split them across buffers",
                             (unsigned long long)tri_bytes, (unsigned long long)limit);
        uint32_t shift = 1;
        while (((VkDeviceSize)2 << shift) * sizeof *tris <= limit && shift < 31) shift++;
        out->split_shift = shift;
    }
    out->node_count = node_count;
    out->tri_count = tri_count;
    if (node_count) out->root = b->nodes[0];
    /* Every binding needs a buffer; these stand in until a call reads the array. */
    const vkrt_gpu_node no_node = { 0 };
    const vkrt_gpu_tri no_tri = { 0 };
    const vkrt_gpu_surface no_surface = { 0 };
    if ((r = gpu_array_upload(vk, &no_node, 1, sizeof no_node, 0, "BVH nodes (placeholder)", &out->nodes)) != VKRT_OK)
        goto fail;
    if ((r = gpu_array_upload(vk, &no_tri, 1, sizeof no_tri, 0, "triangles (placeholder)", &out->tris)) != VKRT_OK)
        goto fail;
    if ((r = gpu_array_upload(vk, &no_surface, 1, sizeof no_surface, 0, "surfaces (placeholder)", &out->surfaces)) !=
        VKRT_OK)
        goto fail;
    VkBufferUsageFlags usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    /* The table has room for every piece of every array; the surfaces' are as many as the
     * triangles' at most (spatial splits copy triangles, not surfaces). */
    const uint64_t node_pieces = piece_count(node_count, out->split_shift);
    const uint64_t tri_pieces = piece_count(tri_count, out->split_shift);
    const uint64_t most = tri_pieces > node_pieces ? tri_pieces : node_pieces;
    const VkDeviceSize table_bytes =
        (VkDeviceSize)(out->split_shift ? VKRT_PIECE_ARRAYS * most : 1) * sizeof(vkrt_gpu_address);
    if ((r = vk_buffer_create(vk, table_bytes, usage, VK_MEMORY_DEVICE, "vkrt piece table", &out->pieces)) != VKRT_OK)
        goto fail;
    const vkrt_gpu_address none = { 0, 0 };
    if (!out->split_shift && (r = vk_buffer_upload(vk, &out->pieces, &none, sizeof none)) != VKRT_OK) goto fail;
    if ((r = write_piece_table(vk, out)) != VKRT_OK) goto fail;
    vk_buffer *placeholders[3] = { &out->materials, &out->textures, &out->texels };
    const VkDeviceSize placeholder_bytes[3] = { sizeof(vkrt_gpu_material), sizeof(vkrt_gpu_texture),
                                                2 * sizeof(uint32_t) };
    for (int i = 0; i < 3; i++)
        if ((r = vk_buffer_create(vk, placeholder_bytes[i], usage, VK_MEMORY_DEVICE, "vkrt surfaces (placeholder)",
                                  placeholders[i])) != VKRT_OK)
            goto fail;
    uint64_t unfit_bytes;
    if ((r = upload_wide(vk, b, tris, threads, out, &unfit_bytes)) != VKRT_OK) goto fail;
    /* Without the wide arrays every traversal reads the binary ones. */
    if (!out->wide && (r = gpu_scene_upload_arrays(vk, out, b, tris, GPU_ARRAY_NODES | GPU_ARRAY_TRIS)) != VKRT_OK)
        goto fail;
    if (unfit_bytes)
        core_log(vk->core, VKRT_LOG_WARN,
                 "the 4-wide BVH of %u triangles (%llu bytes) does not fit the device memory left; the scene is "
                 "traced through its binary BVH",
                 tri_count, (unsigned long long)unfit_bytes);
    return VKRT_OK;
fail:
    gpu_scene_destroy(vk, out);
    return r;
}

vkrt_result gpu_scene_upload_arrays(vk_context *vk, gpu_scene *s, const bvh *b, const vkrt_gpu_tri *tris,
                                    uint32_t arrays)
{
    struct {
        uint32_t bit;
        bool *uploaded;
        gpu_array *target;
        const void *data;
        uint32_t count;
        size_t elem_size;
        const char *label;
        gpu_array fresh, old;
    } parts[] = {
        { GPU_ARRAY_NODES, &s->nodes_uploaded, &s->nodes, b->nodes, b->node_count, sizeof *b->nodes, "BVH nodes",
          { 0 }, { 0 } },
        { GPU_ARRAY_TRIS, &s->tris_uploaded, &s->tris, tris, b->tri_count, sizeof *tris, "triangles", { 0 }, { 0 } },
    };
    enum { PARTS = sizeof parts / sizeof parts[0] };
    assert(b->node_count == s->node_count && b->tri_count == s->tri_count);
    vkrt_result r = VKRT_OK;
    bool any = false;
    for (int i = 0; i < PARTS && r == VKRT_OK; i++) {
        if (!(arrays & parts[i].bit) || *parts[i].uploaded) continue;
        any = true;
        r = gpu_array_upload(vk, parts[i].data, parts[i].count, parts[i].elem_size, s->split_shift, parts[i].label,
                             &parts[i].fresh);
    }
    if (!any) return VKRT_OK;
    if (r == VKRT_OK) {
        for (int i = 0; i < PARTS; i++) {
            if (!parts[i].fresh.pieces) continue;
            parts[i].old = *parts[i].target;
            *parts[i].target = parts[i].fresh;
            *parts[i].uploaded = true;
        }
        r = write_piece_table(vk, s);
        /* Without their table entries a split scene's arrays cannot be read: back to the
         * placeholders, which the table does not name. */
        for (int i = 0; i < PARTS && r != VKRT_OK; i++) {
            if (!parts[i].fresh.pieces) continue;
            *parts[i].target = parts[i].old;
            *parts[i].uploaded = false;
        }
    }
    for (int i = 0; i < PARTS; i++) gpu_array_destroy(vk, r == VKRT_OK ? &parts[i].old : &parts[i].fresh);
    return r;
}

void gpu_scene_destroy(vk_context *vk, gpu_scene *s)
{
    gpu_array_destroy(vk, &s->nodes);
    gpu_array_destroy(vk, &s->tris);
    gpu_array_destroy(vk, &s->surfaces);
    vk_buffer_destroy(vk, &s->materials);
    vk_buffer_destroy(vk, &s->textures);
    vk_buffer_destroy(vk, &s->texels);
    vk_buffer_destroy(vk, &s->pieces);
    vk_texel_buffer_destroy(vk, &s->wide_nodes);
    vk_texel_buffer_destroy(vk, &s->trace_tris);
}

void gpu_scene_usage(const gpu_scene *s, uint64_t *out_bytes, uint32_t *out_buffers)
{
    uint64_t bytes = s->materials.allocated + s->textures.allocated + s->texels.allocated + s->pieces.allocated +
                     s->wide_nodes.buffer.allocated + s->trace_tris.buffer.allocated;
    const gpu_array *arrays[3] = { &s->nodes, &s->tris, &s->surfaces };
    for (int a = 0; a < 3; a++)
        for (uint32_t k = 0; k < arrays[a]->count; k++) bytes += arrays[a]->pieces[k].allocated;
    *out_bytes = bytes;
    *out_buffers = (s->nodes_uploaded ? s->nodes.count : 0) + (s->tris_uploaded ? s->tris.count : 0);
}

uint64_t gpu_scene_traversal_bytes(const gpu_scene *s)
{
    if (s->wide) return s->wide_nodes.buffer.size + s->trace_tris.buffer.size;
    uint64_t bytes = 0;
    const gpu_array *arrays[2] = { &s->nodes, &s->tris };
    for (int a = 0; a < 2; a++)
        for (uint32_t k = 0; k < arrays[a]->count; k++) bytes += arrays[a]->pieces[k].size;
    return bytes;
}

vkrt_result gpu_scene_upload_surfaces(vk_context *vk, gpu_scene *s, const gpu_surface_data *d)
{
    if (s->surfaces_uploaded) return VKRT_OK;
    struct {
        vk_buffer *target;
        const void *data;
        VkDeviceSize bytes;
        const char *name;
        vk_buffer fresh;
    } parts[] = {
        { &s->materials, d->materials, (VkDeviceSize)d->material_count * sizeof *d->materials, "materials", { 0 } },
        { &s->textures, d->textures, (VkDeviceSize)d->texture_count * sizeof *d->textures, "textures", { 0 } },
        { &s->texels, d->texels, (VkDeviceSize)d->texel_count * 2 * sizeof *d->texels, "texels", { 0 } },
    };
    enum { PARTS = sizeof parts / sizeof parts[0] };
    VkBufferUsageFlags usage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    /* The surfaces, one per triangle of the mesh (prim_id), split as the triangles are (and so
     * within the limit). */
    gpu_array surfaces = { 0 };
    vkrt_result r = VKRT_OK;
    if (!s->split_shift) r = check_range(vk, (VkDeviceSize)d->surface_count * sizeof *d->surfaces, "surfaces");
    if (r == VKRT_OK)
        r = gpu_array_upload(vk, d->surfaces, d->surface_count, sizeof *d->surfaces, s->split_shift, "surfaces",
                             &surfaces);
    for (int i = 0; i < PARTS && r == VKRT_OK; i++) {
        r = check_range(vk, parts[i].bytes, parts[i].name);
        if (r == VKRT_OK) r = vk_buffer_create(vk, parts[i].bytes, usage, VK_MEMORY_DEVICE, parts[i].name, &parts[i].fresh);
        if (r == VKRT_OK) r = vk_buffer_upload(vk, &parts[i].fresh, parts[i].data, parts[i].bytes);
    }
    for (int i = 0; i < PARTS; i++) {
        vk_buffer *keep = r == VKRT_OK ? parts[i].target : &parts[i].fresh;
        vk_buffer_destroy(vk, keep);
        if (r == VKRT_OK) *parts[i].target = parts[i].fresh;
    }
    gpu_array_destroy(vk, r == VKRT_OK ? &s->surfaces : &surfaces);
    if (r != VKRT_OK) return r;
    s->surfaces = surfaces;
    s->surfaces_uploaded = true;
    /* Without their table entries a split scene's surfaces cannot be read: the next render
     * that needs them uploads them again (replacing these). */
    if ((r = write_piece_table(vk, s)) != VKRT_OK) s->surfaces_uploaded = false;
    return r;
}
