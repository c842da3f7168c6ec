#include "gpu_trace.h"

#include <assert.h>
#include <string.h>

#include "cpu_trace.h"
#include "gpu_pace.h"
#include "ray_bin.h"
#include "ray_cull.h"
#include "vk_pipeline.h"

/* Tiles bound the size of the storage image and of the hit and continuation buffers; the
 * submissions within a tile are rectangles the pacer sizes (gpu_pace.h). */
#define TILE_SIZE 256u

/* With a loop budget every pixel of a tile and every ray of a chunk has a continuation slot;
 * the largest of those buffers (the saved stacks) must fit lavapipe's 128 MiB
 * maxStorageBufferRange with room to spare. */
_Static_assert(TILE_SIZE * TILE_SIZE <= VKRT_RESUME_RAY_CHUNK, "a tile must fit the continuation buffers");
_Static_assert((uint64_t)VKRT_RESUME_RAY_CHUNK * VKRT_TRAVERSAL_STACK_SIZE * sizeof(vkrt_gpu_stack_entry) <= (64u << 20),
               "continuation stacks must stay well under lavapipe's 128 MiB storage buffer range");

/* Per-call device objects: one tile-sized storage image (1x1 for rays), the readback buffer
 * (an image's, or the hits' where they come back through a copy), the hit buffer (naive
 * traversal's carried hits; the output of rays), the ray buffer, the continuation state, stacks
 * and unfinished counter of budgeted BVH traversal, a descriptor set and a timestamp query
 * pool. */
typedef struct render_objects {
    VkImage image;
    VkDeviceMemory image_memory;
    VkMemoryAllocateInfo image_allocation; /* its size and type */
    VkImageView view;
    vk_buffer readback;
    vk_buffer hits;
    vk_buffer rays;
    VkBufferView hit_words, ray_texels; /* the wide traversal's views: R32UI of hits, RGBA32UI of rays */
    vk_texel_buffer slot_tris;          /* the wide ray trace's triangles so far, by ray slot (words) */
    vk_texel_buffer ray_lists;          /* the binned traversal's first entry and entry count, a ray */
    vk_texel_buffer list_tris_placeholder; /* one word, where no call's lists are bound */
    VkBufferView list_tris;             /* what the set binds: the call's lists (borrowed) or the
                                           placeholder's view */
    vk_buffer resume;
    vk_buffer resume_stack;
    vk_buffer unfinished; /* host-visible: read after every submission */
    vk_buffer counters;   /* host-visible: vkrt_gpu_counters per pixel of a tile, when counting */
    VkDescriptorPool pool;
    VkDescriptorSet set;
    VkQueryPool queries;
} render_objects;

static void render_objects_destroy(vk_context *vk, render_objects *o)
{
    if (o->queries) vkDestroyQueryPool(vk->device, o->queries, NULL);
    if (o->pool) vkDestroyDescriptorPool(vk->device, o->pool, NULL);
    if (o->view) vkDestroyImageView(vk->device, o->view, NULL);
    if (o->image) vkDestroyImage(vk->device, o->image, NULL);
    vk_memory_free(vk, o->image_memory, &o->image_allocation);
    if (o->hit_words) vkDestroyBufferView(vk->device, o->hit_words, NULL);
    if (o->ray_texels) vkDestroyBufferView(vk->device, o->ray_texels, NULL);
    vk_texel_buffer_destroy(vk, &o->slot_tris);
    vk_texel_buffer_destroy(vk, &o->ray_lists);
    vk_texel_buffer_destroy(vk, &o->list_tris_placeholder);
    vk_buffer_destroy(vk, &o->readback);
    vk_buffer_destroy(vk, &o->hits);
    vk_buffer_destroy(vk, &o->rays);
    vk_buffer_destroy(vk, &o->resume);
    vk_buffer_destroy(vk, &o->resume_stack);
    vk_buffer_destroy(vk, &o->unfinished);
    vk_buffer_destroy(vk, &o->counters);
}

static vkrt_result create_image(vk_context *vk, uint32_t w, uint32_t h, render_objects *o)
{
    VkImageCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_IMAGE_CREATE_INFO,
        .imageType = VK_IMAGE_TYPE_2D,
        .format = VK_FORMAT_R32G32B32A32_SFLOAT,
        .extent = { w, h, 1 },
        .mipLevels = 1,
        .arrayLayers = 1,
        .samples = VK_SAMPLE_COUNT_1_BIT,
        .tiling = VK_IMAGE_TILING_OPTIMAL,
        .usage = VK_IMAGE_USAGE_STORAGE_BIT | VK_IMAGE_USAGE_TRANSFER_SRC_BIT,
        .initialLayout = VK_IMAGE_LAYOUT_UNDEFINED,
    };
    VkResult res = vkCreateImage(vk->device, &info, NULL, &o->image);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateImage");
    vk_label(vk, VK_OBJECT_TYPE_IMAGE, (uint64_t)o->image, "vkrt tile image");
    VkMemoryRequirements req;
    vkGetImageMemoryRequirements(vk->device, o->image, &req);
    int type = -1;
    for (uint32_t i = 0; i < vk->memory.memoryTypeCount && type < 0; i++)
        if ((req.memoryTypeBits & (1u << i)) &&
            (vk->memory.memoryTypes[i].propertyFlags & VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT))
            type = (int)i;
    for (uint32_t i = 0; i < vk->memory.memoryTypeCount && type < 0; i++)
        if (req.memoryTypeBits & (1u << i)) type = (int)i;
    if (type < 0) return core_fail(vk->core, VKRT_ERROR_VULKAN, "no memory type for the tile image");
    VkMemoryAllocateInfo alloc = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO,
        .allocationSize = req.size,
        .memoryTypeIndex = (uint32_t)type,
    };
    vkrt_result r = vk_memory_allocate(vk, &alloc, "the tile image", &o->image_memory);
    if (r != VKRT_OK) return r;
    o->image_allocation = alloc;
    res = vkBindImageMemory(vk->device, o->image, o->image_memory, 0);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkBindImageMemory");
    VkImageViewCreateInfo view = {
        .sType = VK_STRUCTURE_TYPE_IMAGE_VIEW_CREATE_INFO,
        .image = o->image,
        .viewType = VK_IMAGE_VIEW_TYPE_2D,
        .format = info.format,
        .subresourceRange = { VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1 },
    };
    res = vkCreateImageView(vk->device, &view, NULL, &o->view);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateImageView");
    return VKRT_OK;
}

static vkrt_result create_descriptors(vk_context *vk, const gpu_scene *scene, VkDescriptorSetLayout layout,
                                      render_objects *o)
{
    VkDescriptorPoolSize sizes[] = {
        { VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, VKRT_BINDING_COUNT - 1 - VKRT_BINDING_TEXEL_COUNT }, /* all but: */
        { VK_DESCRIPTOR_TYPE_STORAGE_IMAGE, 1 },
        { VK_DESCRIPTOR_TYPE_STORAGE_TEXEL_BUFFER, VKRT_BINDING_TEXEL_COUNT },
    };
    vkrt_result r = vk_descriptor_set_create(vk, layout, sizes, 3, &o->pool, &o->set);
    if (r != VKRT_OK) return r;
    /* Every storage buffer whole, at its binding; then the image. */
    const struct {
        uint32_t binding;
        VkBuffer buffer;
    } buffers[] = {
        { VKRT_BINDING_NODES, scene->nodes.pieces[0].buffer },   { VKRT_BINDING_TRIS, scene->tris.pieces[0].buffer },
        { VKRT_BINDING_HITS, o->hits.buffer },         { VKRT_BINDING_RAYS, o->rays.buffer },
        { VKRT_BINDING_RESUME, o->resume.buffer },     { VKRT_BINDING_RESUME_STACK, o->resume_stack.buffer },
        { VKRT_BINDING_UNFINISHED, o->unfinished.buffer },    { VKRT_BINDING_COUNTERS, o->counters.buffer },
        { VKRT_BINDING_SURFACES, scene->surfaces.pieces[0].buffer }, { VKRT_BINDING_MATERIALS, scene->materials.buffer },
        { VKRT_BINDING_TEXTURES, scene->textures.buffer },    { VKRT_BINDING_TEXELS, scene->texels.buffer },
        { VKRT_BINDING_PIECES, scene->pieces.buffer },
    };
    enum { BUFFERS = sizeof buffers / sizeof buffers[0] };
    _Static_assert(BUFFERS == VKRT_BINDING_COUNT - 1 - VKRT_BINDING_TEXEL_COUNT,
                   "every binding but the image and the texel buffers has a buffer here");
    VkDescriptorBufferInfo infos[BUFFERS];
    VkWriteDescriptorSet writes[BUFFERS + 1 + VKRT_BINDING_TEXEL_COUNT];
    for (uint32_t i = 0; i < BUFFERS; i++) {
        infos[i] = (VkDescriptorBufferInfo){ buffers[i].buffer, 0, VK_WHOLE_SIZE };
        writes[i] = (VkWriteDescriptorSet){ .sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET, .dstSet = o->set,
                                            .dstBinding = buffers[i].binding, .descriptorCount = 1,
                                            .descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, .pBufferInfo = &infos[i] };
    }
    VkDescriptorImageInfo image = { VK_NULL_HANDLE, o->view, VK_IMAGE_LAYOUT_GENERAL };
    writes[BUFFERS] = (VkWriteDescriptorSet){ .sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET, .dstSet = o->set,
                                              .dstBinding = VKRT_BINDING_IMAGE, .descriptorCount = 1,
                                              .descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_IMAGE, .pImageInfo = &image };
    const VkBufferView texels[VKRT_BINDING_TEXEL_COUNT] = { scene->wide_nodes.view, scene->trace_tris.view,
                                                            o->ray_texels,          o->hit_words,
                                                            o->slot_tris.view,      o->ray_lists.view,
                                                            o->list_tris };
    for (uint32_t i = 0; i < VKRT_BINDING_TEXEL_COUNT; i++)
        writes[BUFFERS + 1 + i] = (VkWriteDescriptorSet){ .sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET,
                                                          .dstSet = o->set,
                                                          .dstBinding = VKRT_BINDING_TEXEL_FIRST + i,
                                                          .descriptorCount = 1,
                                                          .descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_TEXEL_BUFFER,
                                                          .pTexelBufferView = &texels[i] };
    _Static_assert(VKRT_BINDING_WIDE_NODES == VKRT_BINDING_TEXEL_FIRST &&
                       VKRT_BINDING_TRACE_TRIS == VKRT_BINDING_TEXEL_FIRST + 1 &&
                       VKRT_BINDING_RAY_TEXELS == VKRT_BINDING_TEXEL_FIRST + 2 &&
                       VKRT_BINDING_HIT_WORDS == VKRT_BINDING_TEXEL_FIRST + 3 &&
                       VKRT_BINDING_SLOT_TRIS == VKRT_BINDING_TEXEL_FIRST + 4 &&
                       VKRT_BINDING_RAY_LISTS == VKRT_BINDING_TEXEL_FIRST + 5 &&
                       VKRT_BINDING_LIST_TRIS == VKRT_BINDING_TEXEL_FIRST + 6 &&
                       VKRT_BINDING_TEXEL_FIRST + VKRT_BINDING_TEXEL_COUNT == VKRT_BINDING_COUNT,
                   "the texel buffers' bindings are adjacent, and the last");
    vkUpdateDescriptorSets(vk->device, sizeof writes / sizeof writes[0], writes, 0, NULL);
    return VKRT_OK;
}

/* The host-visible buffer a pass's results are copied into for the host to read: an image
 * rectangle's pixels, or a chunk's hits. */
static vkrt_result create_readback(vk_context *vk, VkDeviceSize bytes, render_objects *o)
{
    return vk_buffer_create(vk, bytes, VK_BUFFER_USAGE_TRANSFER_DST_BIT, VK_MEMORY_READBACK, "vkrt readback",
                            &o->readback);
}

/* Image mode: a tile_w x tile_h image and the readback buffer its pixels are copied into,
 * hit_count = pixels for naive traversal (else 1), no rays. Ray mode: a 1x1 image (the layout
 * has the binding), hit_count = ray_count rays, and no readback buffer: the caller adds one
 * (create_hit_readback) where the host reads the hits through a copy.
 * resume_slots: continuation slots of budgeted BVH traversal (0: none needed); counter_slots:
 * pixels whose traversal counters are written (0: not counting); slot_words: the words of the
 * wide ray trace's record by ray slot (ray_slot_words; 0: none needed); list_rays: rays whose
 * binned lists (first entry, count) it holds (0: none); list_tris: the binned call's triangle
 * lists, borrowed (VK_NULL_HANDLE: a placeholder of its own). */
static vkrt_result create_render_objects(vk_context *vk, const gpu_scene *scene, VkDescriptorSetLayout layout,
                                         uint32_t tile_w, uint32_t tile_h, uint32_t hit_count, uint32_t ray_count,
                                         uint32_t resume_slots, uint32_t counter_slots, uint32_t slot_words,
                                         uint32_t list_rays, VkBufferView list_tris, render_objects *o)
{
    memset(o, 0, sizeof *o);
    vkrt_result r = create_image(vk, tile_w, tile_h, o);
    if (r == VKRT_OK && !ray_count) r = create_readback(vk, (VkDeviceSize)tile_w * tile_h * 4 * sizeof(float), o);
    /* Every binding of the layout gets a buffer; one the variant never reads gets a minimal one. */
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (VkDeviceSize)(hit_count ? hit_count : 1) * sizeof(vkrt_gpu_hit),
                             VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_STORAGE_TEXEL_BUFFER_BIT |
                                 VK_BUFFER_USAGE_TRANSFER_DST_BIT | VK_BUFFER_USAGE_TRANSFER_SRC_BIT,
                             VK_MEMORY_DEVICE, "vkrt hits", &o->hits);
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (VkDeviceSize)(ray_count ? ray_count : 1) * sizeof(vkrt_gpu_ray),
                             VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_STORAGE_TEXEL_BUFFER_BIT |
                                 VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                             VK_MEMORY_DEVICE, "vkrt rays", &o->rays);
    /* The same memory seen as texels: the wide traversal reads rays and writes hits through
     * them (lavapipe's storage-buffer accesses go a lane and a word at a time). */
    _Static_assert(sizeof(vkrt_gpu_hit) == 16 && sizeof(vkrt_gpu_ray) == 32, "a hit is one texel, a ray two");
    if (r == VKRT_OK) r = vk_buffer_view_create(vk, o->hits.buffer, o->hits.size, VK_FORMAT_R32_UINT, &o->hit_words);
    if (r == VKRT_OK)
        r = vk_buffer_view_create(vk, o->rays.buffer, o->rays.size, VK_FORMAT_R32G32B32A32_UINT, &o->ray_texels);
    if (r == VKRT_OK) r = vk_word_buffer_create(vk, slot_words, "vkrt ray slot triangles", &o->slot_tris);
    if (r == VKRT_OK) r = vk_word_buffer_create(vk, 2 * (size_t)list_rays, "vkrt ray lists", &o->ray_lists);
    if (r == VKRT_OK && !list_tris)
        r = vk_word_buffer_create(vk, 1, "vkrt list triangles placeholder", &o->list_tris_placeholder);
    o->list_tris = list_tris ? list_tris : o->list_tris_placeholder.view;
    const VkDeviceSize slots = resume_slots ? resume_slots : 1;
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, slots * sizeof(vkrt_gpu_resume), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, VK_MEMORY_DEVICE,
                             "vkrt resume state", &o->resume);
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (resume_slots ? slots * VKRT_TRAVERSAL_STACK_SIZE : 1) * sizeof(vkrt_gpu_stack_entry),
                             VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, VK_MEMORY_DEVICE, "vkrt resume stacks",
                             &o->resume_stack);
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, 2 * sizeof(uint32_t), VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                             VK_MEMORY_READBACK, "vkrt unfinished count and next ray slot", &o->unfinished);
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (VkDeviceSize)(counter_slots ? counter_slots : 1) * sizeof(vkrt_gpu_counters),
                             VK_BUFFER_USAGE_STORAGE_BUFFER_BIT, VK_MEMORY_READBACK, "vkrt traversal counters",
                             &o->counters);
    if (r == VKRT_OK) r = create_descriptors(vk, scene, layout, o);
    if (r == VKRT_OK && vk->timestamps) {
        VkQueryPoolCreateInfo q = {
            .sType = VK_STRUCTURE_TYPE_QUERY_POOL_CREATE_INFO,
            .queryType = VK_QUERY_TYPE_TIMESTAMP,
            .queryCount = 2,
        };
        VkResult res = vkCreateQueryPool(vk->device, &q, NULL, &o->queries);
        if (res != VK_SUCCESS) r = vk_fail(vk, res, "vkCreateQueryPool");
    }
    return r;
}

/* The readback buffer of ray mode: ray_count hits, which record_rays copies there from the hit
 * buffer (HITS_READBACK). */
static vkrt_result create_hit_readback(vk_context *vk, render_objects *o, uint32_t ray_count)
{
    return create_readback(vk, (VkDeviceSize)ray_count * sizeof(vkrt_gpu_hit), o);
}

/* Whether a scene's traversals go through the wide BVH (all but naive ones; renders with heat
 * or counters keep to the binary BVH as well, whose steps those count). */
static bool wide_traversal(const gpu_scene *scene, bool naive)
{
    return scene->wide && !naive;
}

/* The 1D workgroups of a dispatch over `rays` rays of a ray buffer: one invocation a ray, or
 * with the wide traversal one per VKRT_WIDE_RAYS_PER_LANE rays; VKRT_RAY_CHUNK keeps the
 * count far below the 65,535 a dispatch allows. */
static uint32_t ray_groups(const gpu_scene *scene, bool naive, uint32_t rays)
{
    const uint32_t per_invocation = wide_traversal(scene, naive) ? VKRT_WIDE_RAYS_PER_LANE : 1;
    return core_div_up(rays, VKRT_TRACE_GROUP_SIZE * per_invocation);
}

/* The continuation slots a budgeted pass over `rays` rays needs: one an invocation (the
 * slot trace_buffer_ray and trace_buffer_rays_wide use), so the wide traversal needs a
 * VKRT_WIDE_RAYS_PER_LANE-th of the memory. */
static uint32_t ray_resume_slots(const gpu_scene *scene, bool naive, uint32_t rays)
{
    return wide_traversal(scene, naive) ? ray_groups(scene, naive, rays) * VKRT_TRACE_GROUP_SIZE : rays;
}

/* The words of the wide ray trace's record of each ray's triangle so far (store_slot_tri in
 * shaders/trace.comp): VKRT_WIDE_RAYS_PER_LANE for each ray slot of a pass over `rays` rays;
 * none for other traversals. */
static uint32_t ray_slot_words(const gpu_scene *scene, bool naive, uint32_t rays)
{
    return wide_traversal(scene, naive) ? ray_groups(scene, naive, rays) * VKRT_TRACE_GROUP_SIZE * VKRT_WIDE_RAYS_PER_LANE
                                        : 0;
}

static uint32_t gpu_mode(vkrt_mode m)
{
    switch (m) {
    case VKRT_MODE_DEPTH: return VKRT_GPU_MODE_DEPTH;
    case VKRT_MODE_HEATMAP: return VKRT_GPU_MODE_HEATMAP;
    case VKRT_MODE_ID: return VKRT_GPU_MODE_ID;
    case VKRT_MODE_ALBEDO: return VKRT_GPU_MODE_ALBEDO;
    case VKRT_MODE_UV: return VKRT_GPU_MODE_UV;
    default: return VKRT_GPU_MODE_NORMAL;
    }
}

static uint32_t gpu_heat(vkrt_heat h)
{
    switch (h) {
    case VKRT_HEAT_LEAVES: return VKRT_GPU_HEAT_LEAVES;
    case VKRT_HEAT_TRIS: return VKRT_GPU_HEAT_TRIS;
    default: return VKRT_GPU_HEAT_NODES;
    }
}

static uint32_t gpu_isect(vkrt_intersector i)
{
    return i == VKRT_INTERSECTOR_MOLLER_TRUMBORE ? VKRT_GPU_ISECT_MOLLER_TRUMBORE : VKRT_GPU_ISECT_WATERTIGHT;
}

/* One buffer barrier over the whole buffer. */
static void record_buffer_barrier(VkCommandBuffer cmd, VkBuffer buffer, VkPipelineStageFlags src_stage,
                                  VkAccessFlags src_access, VkPipelineStageFlags dst_stage, VkAccessFlags dst_access)
{
    VkBufferMemoryBarrier b = {
        .sType = VK_STRUCTURE_TYPE_BUFFER_MEMORY_BARRIER,
        .srcAccessMask = src_access,
        .dstAccessMask = dst_access,
        .srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED,
        .dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED,
        .buffer = buffer,
        .size = VK_WHOLE_SIZE,
    };
    vkCmdPipelineBarrier(cmd, src_stage, dst_stage, 0, 0, NULL, 1, &b, 0, NULL);
}

/* What one submission over a tile's rectangle or a chunk of rays records. */
typedef struct pass_range {
    bool again;          /* a later pass over the same pixels or rays: the image keeps what the
                            earlier ones wrote */
    uint32_t tri_first;  /* naive traversal: the pass's triangles [tri_first, tri_end), whole */
    uint32_t tri_end;    /* chunks of VKRT_NAIVE_CHUNK_TRIS (the last one shorter) */
} pass_range;

/* Naive traversal: one dispatch per chunk of VKRT_NAIVE_CHUNK_TRIS triangles of the pass's
 * range, each reading the closest hits the one before wrote; the range starting at triangle 0
 * clears the hit buffer first. */
static void record_naive_chunks(VkCommandBuffer cmd, const vk_trace_pipeline *pipe, const render_objects *o,
                                const gpu_scene *scene, vkrt_gpu_push push, pass_range range, uint32_t groups_x,
                                uint32_t groups_y)
{
    if (range.tri_first == 0) {
        /* t = +inf (0x7f800000) and no triangle (0xffffffff) would need two fills; a fill of
         * the whole record with 0x7f800000 gives t = +inf, and the shader treats any hit with
         * t = +inf as none, so one fill suffices. */
        vkCmdFillBuffer(cmd, o->hits.buffer, 0, VK_WHOLE_SIZE, 0x7f800000u);
        /* The first chunk reads the cleared hits. */
        record_buffer_barrier(cmd, o->hits.buffer, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                              VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                              VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    }
    for (uint32_t first = range.tri_first; first < range.tri_end; first += VKRT_NAIVE_CHUNK_TRIS) {
        push.tri_first = first;
        push.tri_end = scene->tri_count - first > VKRT_NAIVE_CHUNK_TRIS ? first + VKRT_NAIVE_CHUNK_TRIS
                                                                        : scene->tri_count;
        push.last_chunk = push.tri_end == scene->tri_count;
        if (first != 0) {
            /* Each chunk reads the closest hit the previous chunk wrote, in this submission
             * or the one before. */
            VkMemoryBarrier chunk_done = {
                .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
                .srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT,
                .dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT,
            };
            vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0,
                                 1, &chunk_done, 0, NULL, 0, NULL);
        }
        vkCmdPushConstants(cmd, pipe->layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof push, &push);
        vkCmdDispatch(cmd, groups_x, groups_y, 1);
    }
}

/* The image to GENERAL for the shader's writes. The first use of the image waits for
 * nothing; a rectangle's first pass discards the previous contents (an earlier rectangle,
 * already copied out); a later pass keeps the pixels written so far. Returns the barrier for
 * the transition back. */
static VkImageMemoryBarrier record_image_to_general(VkCommandBuffer cmd, const render_objects *o, bool first,
                                                    bool keep)
{
    VkImageMemoryBarrier to_general = {
        .sType = VK_STRUCTURE_TYPE_IMAGE_MEMORY_BARRIER,
        .srcAccessMask = first ? 0 : VK_ACCESS_TRANSFER_READ_BIT,
        .dstAccessMask = VK_ACCESS_SHADER_WRITE_BIT,
        .oldLayout = keep ? VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL : VK_IMAGE_LAYOUT_UNDEFINED,
        .newLayout = VK_IMAGE_LAYOUT_GENERAL,
        .srcQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED,
        .dstQueueFamilyIndex = VK_QUEUE_FAMILY_IGNORED,
        .image = o->image,
        .subresourceRange = { VK_IMAGE_ASPECT_COLOR_BIT, 0, 1, 0, 1 },
    };
    vkCmdPipelineBarrier(cmd, first ? VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT : VK_PIPELINE_STAGE_TRANSFER_BIT,
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 0, NULL, 0, NULL, 1, &to_general);
    return to_general;
}

/* The trace dispatch(es) over groups_x x groups_y workgroups, and a wide ray trace's finish
 * after them, between two timestamps. With a
 * loop budget (BVH traversal on lavapipe) or ray slots to take (a wide ray trace) the
 * unfinished counter and the next ray slot are cleared first; the former is handed to the
 * host after. */
static void record_dispatches(VkCommandBuffer cmd, const vk_trace_pipeline *pipe, const render_objects *o,
                              const gpu_scene *scene, vkrt_gpu_push push, bool naive, bool budget, pass_range range,
                              uint32_t groups_x, uint32_t groups_y)
{
    /* A wide ray trace (it has a finish pass) takes its ray slots from the second counter. */
    if (budget || pipe->finish) {
        /* The previous pass (an earlier submission) wrote the continuation state this one
         * reads or overwrites, and its atomics wrote the counter the fill overwrites. */
        VkMemoryBarrier previous = {
            .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
            .srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT,
            .dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT,
        };
        vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                             VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &previous, 0,
                             NULL, 0, NULL);
        vkCmdFillBuffer(cmd, o->unfinished.buffer, 0, VK_WHOLE_SIZE, 0);
        /* The dispatch's atomics add to the cleared counter. */
        record_buffer_barrier(cmd, o->unfinished.buffer, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                              VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT);
    }
    if (o->queries) {
        vkCmdResetQueryPool(cmd, o->queries, 0, 2);
        vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_TOP_OF_PIPE_BIT, o->queries, 0);
    }
    vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipe->pipeline);
    vkCmdBindDescriptorSets(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipe->layout, 0, 1, &o->set, 0, NULL);
    if (!naive) {
        vkCmdPushConstants(cmd, pipe->layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof push, &push);
        vkCmdDispatch(cmd, groups_x, groups_y, 1);
    } else {
        record_naive_chunks(cmd, pipe, o, scene, push, range, groups_x, groups_y);
    }
    if (pipe->finish) {
        /* A wide ray trace's finish reads the triangles the trace recorded and the unfinished
         * count, and writes the hits. Recorded in every pass, it does its work in the one that
         * leaves nothing unfinished, the last. */
        VkMemoryBarrier traced = {
            .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
            .srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT,
            .dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT,
        };
        vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, 0, 1,
                             &traced, 0, NULL, 0, NULL);
        vkCmdBindPipeline(cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipe->finish);
        vkCmdDispatch(cmd, groups_x, groups_y, 1);
    }
    if (o->queries) vkCmdWriteTimestamp(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, o->queries, 1);
    /* The host reads the counter after the fence. */
    if (budget)
        record_buffer_barrier(cmd, o->unfinished.buffer, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                              VK_ACCESS_SHADER_WRITE_BIT, VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
}

/* Records one pass over a rectangle of the image (its first, a resume of the traversals the
 * budget stopped, or the next naive chunks): trace dispatch(es), then a copy of the
 * rectangle's pixels into the readback buffer. */
static void record_tile(VkCommandBuffer cmd, const vk_trace_pipeline *pipe, const render_objects *o,
                        const gpu_scene *scene, vkrt_gpu_push push, bool naive, bool budget, bool first_use,
                        pass_range range)
{
    VkImageMemoryBarrier to_general = record_image_to_general(cmd, o, first_use && !range.again, range.again);
    record_dispatches(cmd, pipe, o, scene, push, naive, budget, range,
                      core_div_up(push.tile_width, VKRT_TRACE_GROUP_X), core_div_up(push.tile_height, VKRT_TRACE_GROUP_Y));
    /* The copy reads what the shader wrote. */
    VkImageMemoryBarrier to_transfer = to_general;
    to_transfer.srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT;
    to_transfer.dstAccessMask = VK_ACCESS_TRANSFER_READ_BIT;
    to_transfer.oldLayout = VK_IMAGE_LAYOUT_GENERAL;
    to_transfer.newLayout = VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL;
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 0, NULL, 0, NULL,
                         1, &to_transfer);
    VkBufferImageCopy region = {
        .bufferRowLength = push.tile_width,
        .bufferImageHeight = push.tile_height,
        .imageSubresource = { VK_IMAGE_ASPECT_COLOR_BIT, 0, 0, 1 },
        .imageExtent = { push.tile_width, push.tile_height, 1 },
    };
    vkCmdCopyImageToBuffer(cmd, o->image, VK_IMAGE_LAYOUT_TRANSFER_SRC_OPTIMAL, o->readback.buffer, 1, &region);
    /* The host reads the readback buffer, and the counters where the variant writes them,
     * after the fence. */
    record_buffer_barrier(cmd, o->readback.buffer, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                          VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
    record_buffer_barrier(cmd, o->counters.buffer, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                          VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
}

/* Adds the counters of a finished rectangle's pixels to *sum. */
static vkrt_result add_tile_counts(vk_context *vk, render_objects *o, uint32_t pixels, trace_counts *sum)
{
    vkrt_result r = vk_buffer_invalidate(vk, &o->counters);
    const vkrt_gpu_counters *c = o->counters.mapped;
    for (uint32_t i = 0; r == VKRT_OK && i < pixels; i++) {
        sum->nodes += c[i].nodes;
        sum->leaves += c[i].leaves;
        sum->tris += c[i].tris;
    }
    return r;
}

static double tile_device_ms(vk_context *vk, const render_objects *o)
{
    if (!o->queries) return 0.0;
    uint64_t stamps[2];
    VkResult res = vkGetQueryPoolResults(vk->device, o->queries, 0, 2, sizeof stamps, stamps, sizeof stamps[0],
                                         VK_QUERY_RESULT_64_BIT | VK_QUERY_RESULT_WAIT_BIT);
    if (res != VK_SUCCESS || stamps[1] < stamps[0]) return 0.0;
    return (double)(stamps[1] - stamps[0]) * vk->timestamp_period_ns * 1e-6;
}

/* After a pass with a loop budget: how many traversals it left unfinished. */
static vkrt_result read_unfinished(vk_context *vk, render_objects *o, uint32_t *out_count)
{
    vkrt_result r = vk_buffer_invalidate(vk, &o->unfinished);
    *out_count = r == VKRT_OK ? *(const uint32_t *)o->unfinished.mapped : 0;
    return r;
}

/* Where a pass over a chunk of rays leaves its hits for the host. */
typedef enum hits_way {
    HITS_READBACK,  /* copied into the readback buffer, which the host maps */
    HITS_MAPPED,    /* in the hit buffer itself, mapped (a CPU device): no copy */
    HITS_ON_DEVICE  /* nowhere: they stay on the device (the wavefront) */
} hits_way;

/* The buffer whose mapping holds a pass's hits for the host (hits other than HITS_ON_DEVICE). */
static vk_buffer *hits_for_host(render_objects *o, hits_way hits)
{
    return hits == HITS_MAPPED ? &o->hits : &o->readback;
}

static void record_rays(VkCommandBuffer cmd, const vk_trace_pipeline *pipe, const render_objects *o,
                        const gpu_scene *scene, vkrt_gpu_push push, bool naive, bool binned, bool budget,
                        bool first_use, pass_range range, hits_way hits);

/* What one rectangle of an image or chunk of rays is traced with. */
typedef struct pass_desc {
    const vk_trace_pipeline *pipe;
    const gpu_scene *scene;
    bool naive, budget;
    bool binned;       /* a ray chunk through the binned traversal (src/ray_bin.h) */
    bool rays;         /* a ray chunk, else a rectangle of the image */
    hits_way hits;     /* where a chunk of rays leaves its hits (an image rectangle: unused) */
    bool first;        /* the first rectangle or chunk of the call */
    const char *what;  /* "render" or "trace", for the cancellation message */
    gpu_pacer *pacer;  /* sizes the naive passes and learns from every pass */
    vkrt_progress_fn progress;
    void *progress_user;
    float fraction;    /* progress reported between passes */
} pass_desc;

/* The submission target of vk (the test knob, or GPU_SUBMIT_TARGET_MS). */
static double submit_target_ms(const vk_context *vk)
{
    return vk->submit_target_ms > 0.0 ? vk->submit_target_ms : GPU_SUBMIT_TARGET_MS;
}

/* A first pass submitted (launch_first_pass) and not yet waited for. */
typedef struct pass_in_flight {
    vk_submission submission;
    double submitted_ms;  /* core_now_ms() at its submission, for the pacer */
} pass_in_flight;

/* Records and submits the first pass of a chunk of rays through the BVH (one pass: no naive
 * triangle chunks) without waiting for it; run_passes takes it from there. */
static vkrt_result launch_first_pass(vk_context *vk, render_objects *o, const pass_desc *d, vkrt_gpu_push push,
                                     pass_in_flight *out)
{
    assert(d->rays && !d->naive);
    const pass_range range = { .again = false, .tri_first = 0, .tri_end = d->scene->tri_count };
    push.resume = 0;
    VkCommandBuffer cmd;
    vkrt_result r = vk_commands_begin(vk, &cmd);
    if (r != VKRT_OK) return r;
    record_rays(cmd, d->pipe, o, d->scene, push, false, d->binned, d->budget, d->first, range, d->hits);
    out->submitted_ms = core_now_ms();
    return vk_commands_submit(vk, cmd, &out->submission);
}

/* Records one pass over the rectangle or chunk (with naive traversal, the next triangle chunks
 * from range->tri_first, as many as the pacer allows: range->tri_end is set) and waits for it;
 * the pacer learns its time. */
static vkrt_result submit_pass(vk_context *vk, render_objects *o, const pass_desc *d, vkrt_gpu_push push,
                               pass_range *range, uint64_t items)
{
    const uint32_t tri_count = d->scene->tri_count;
    uint64_t chunks = 1;
    if (d->naive) {
        chunks = d->pacer->units / items;
        if (chunks < 1) chunks = 1;
        const uint64_t end = range->tri_first + chunks * VKRT_NAIVE_CHUNK_TRIS;
        range->tri_end = end < tri_count ? (uint32_t)end : tri_count;
        chunks = core_div_up(range->tri_end - range->tri_first, VKRT_NAIVE_CHUNK_TRIS);
    }
    VkCommandBuffer cmd;
    vkrt_result r = vk_commands_begin(vk, &cmd);
    if (r != VKRT_OK) return r;
    if (d->rays)
        record_rays(cmd, d->pipe, o, d->scene, push, d->naive, d->binned, d->budget, d->first, *range, d->hits);
    else record_tile(cmd, d->pipe, o, d->scene, push, d->naive, d->budget, d->first, *range);
    const double t0 = core_now_ms();
    if ((r = vk_commands_submit_wait(vk, cmd)) != VKRT_OK) return r;
    gpu_pacer_report(d->pacer, items * chunks, core_now_ms() - t0);
    return VKRT_OK;
}

/* Submits the rectangle's or chunk's first pass (or waits for it, where launch_first_pass
 * submitted it: `launched`, else NULL), then more while the loop budget left any traversal
 * unfinished (resume passes) or naive traversal has triangle chunks left, with progress and
 * cancellation between them. Adds the device time to *device_ms (may be NULL); the readback
 * buffer (a chunk of rays: hits_for_host's) then holds the complete result. */
static vkrt_result run_passes(vk_context *vk, render_objects *o, const pass_desc *d, vkrt_gpu_push push,
                              double *device_ms, pass_in_flight *launched)
{
    const uint64_t items = d->rays ? push.tile_width : (uint64_t)push.tile_width * push.tile_height;
    const uint32_t tri_count = d->scene->tri_count;
    pass_range range = { .again = false, .tri_first = 0, .tri_end = tri_count };
    push.resume = 0;
    for (;;) {
        vkrt_result r;
        if (launched) {
            /* The first pass is on the device already. */
            r = vk_submission_wait(vk, &launched->submission);
            if (r == VKRT_OK) gpu_pacer_report(d->pacer, items, core_now_ms() - launched->submitted_ms);
            launched = NULL;
        } else {
            r = submit_pass(vk, o, d, push, &range, items);
        }
        if (r != VKRT_OK) return r;
        if (device_ms) *device_ms += tile_device_ms(vk, o);
        bool done;
        if (d->naive) {
            range.tri_first = range.tri_end;
            done = range.tri_first == tri_count;
        } else {
            uint32_t unfinished = 0;
            if (d->budget && (r = read_unfinished(vk, o, &unfinished)) != VKRT_OK) return r;
            done = unfinished == 0;
            push.resume = 1;
        }
        /* Between two submissions; an image rectangle's or ray chunk's caller asks before its
         * next one. */
        if ((!done || d->hits == HITS_ON_DEVICE) && d->progress && !d->progress(d->progress_user, "trace", d->fraction))
            return core_fail(vk->core, VKRT_ERROR_CANCELLED, "%s cancelled by the progress callback", d->what);
        if (done) return d->hits == HITS_ON_DEVICE ? VKRT_OK : vk_buffer_invalidate(vk, hits_for_host(o, d->hits));
        range.again = true;
    }
}

static uint32_t naive_chunks(const gpu_scene *scene)
{
    return core_div_up(scene->tri_count, VKRT_NAIVE_CHUNK_TRIS);
}

/* A pacer for a render or a trace: its units are pixels or rays times naive chunks, from one
 * 8x8 workgroup up to `items` (a tile or the ray capacity) times every chunk. */
static void pacer_for(const vk_context *vk, const gpu_scene *scene, bool naive, uint64_t items, gpu_pacer *p)
{
    uint64_t max_units = 1;
    while (max_units < items) max_units *= 2;
    if (naive)
        for (uint32_t c = naive_chunks(scene); c > 1; c = (c + 1) / 2) max_units *= 2;
    /* The start suits the default target; a smaller one starts proportionally smaller. */
    const double target = submit_target_ms(vk);
    const double start = (naive ? GPU_PACE_START_NAIVE_UNITS : GPU_PACE_START_UNITS) *
                         (target < GPU_SUBMIT_TARGET_MS ? target / GPU_SUBMIT_TARGET_MS : 1.0);
    gpu_pacer_init(p, target, VKRT_TRACE_GROUP_SIZE, max_units, (uint64_t)start, 1);
}

/* Whether a render goes through the wide BVH: heat and counters are the binary BVH's steps,
 * which the CPU counts too. */
static bool render_is_wide(const gpu_scene *scene, const gpu_trace_params *params)
{
    return wide_traversal(scene, params->traversal == VKRT_TRAVERSAL_NAIVE) && !params->counters &&
           params->mode != VKRT_MODE_HEATMAP;
}

/* The binary arrays a traversal reads: none through the wide BVH, which holds the triangles'
 * corners and prim_id; the triangles for naive traversal, and the nodes too for the binary
 * BVH. */
static uint32_t traversal_arrays(bool wide, bool naive)
{
    return wide ? 0u : naive ? GPU_ARRAY_TRIS : GPU_ARRAY_NODES | GPU_ARRAY_TRIS;
}

uint32_t gpu_trace_render_arrays(const gpu_scene *scene, const gpu_trace_params *params)
{
    uint32_t arrays = traversal_arrays(render_is_wide(scene, params), params->traversal == VKRT_TRAVERSAL_NAIVE);
    /* Normals are shaded from the triangles' vertex normals, and depth refined from their
     * corners in double; id, albedo and uv read the hit and the surfaces alone. */
    if (params->mode == VKRT_MODE_NORMAL || params->mode == VKRT_MODE_DEPTH) arrays |= GPU_ARRAY_TRIS;
    return arrays;
}

uint32_t gpu_trace_rays_arrays(const gpu_scene *scene, vkrt_traversal traversal)
{
    const bool naive = traversal == VKRT_TRAVERSAL_NAIVE;
    return traversal_arrays(wide_traversal(scene, naive), naive);
}

/* The arrays a call reads are there (the caller's gpu_scene_upload_arrays); inline, since
 * only asserts call it. */
static inline bool arrays_uploaded(const gpu_scene *scene, uint32_t arrays)
{
    return (!(arrays & GPU_ARRAY_NODES) || scene->nodes_uploaded) && (!(arrays & GPU_ARRAY_TRIS) || scene->tris_uploaded);
}

/* ---- the binned traversal's lists (src/ray_bin.h) ---- */

/* The binned traversal's terms. Its lists are built on the host, which on a CPU device is what
 * runs the traversal too: the full dragon's million camera rays took 45-55 ms to list and 20-29
 * ms of device time to test, against 140-200 ms of device time through the wide BVH (README,
 * "Binned traversal"). Listing costs every triangle's projection whatever the rays, so it needs
 * enough rays for the scene's triangles (at a triangle a ray the full dragon's lists still pay:
 * 0.83 there); a list's loop runs as long as the longest of a SIMD group's eight, and lavapipe
 * ends loops silently after 65,535 turns. */
#define GPU_BIN_MIN_RAYS 16384u
#define GPU_BIN_MAX_RAYS (1u << 22)
#define GPU_BIN_TRIS_PER_RAY 1u     /* at most this many triangles a ray */
#define GPU_BIN_ENTRIES_PER_RAY 16u /* all lists together, at most */
#define GPU_BIN_MAX_LIST 4096u

/* Whether `count` rays (or pixels) of a scene may take the binned traversal: a CPU device, the
 * wide arrays' triangles to list (`tris`, the scene's in BVH order), and rays enough for them.
 * What the rays ask of the trace (closest hits, the watertight test, no alpha test) is the
 * callers'. */
static bool binning_suits(const vk_context *vk, const gpu_scene *scene, const vkrt_gpu_tri *tris, size_t count)
{
    return vk->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU && !vk->no_ray_binning && tris && scene->wide &&
           scene->node_count && count >= GPU_BIN_MIN_RAYS && count <= GPU_BIN_MAX_RAYS &&
           scene->tri_count <= (uint64_t)count * GPU_BIN_TRIS_PER_RAY;
}

/* A call's lists: the plan (each ray's first entry and count) and the entries on the device. */
typedef struct binned_lists {
    bool built;             /* the rays share one origin and their lists keep within the limits */
    ray_bins bins;
    vk_texel_buffer tris;   /* the entries, triangle indices */
} binned_lists;

static void binned_lists_destroy(vk_context *vk, binned_lists *l)
{
    vk_texel_buffer_destroy(vk, &l->tris);
    ray_bins_destroy(vk->core, &l->bins);
    memset(l, 0, sizeof *l);
}

/* Words the host writes for buffer b (a CPU device's memory is mapped: b's own, else a host
 * array that host_words_end uploads); NULL, with the error set, when out of host memory. */
static uint32_t *host_words_begin(vk_context *vk, vk_buffer *b, size_t words, const char *what)
{
    uint32_t *w = b->mapped ? b->mapped : core_alloc_array(vk->core, words ? words : 1, sizeof *w);
    if (!w) core_fail(vk->core, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for %s (%zu words)", what, words);
    return w;
}

/* Puts the words host_words_begin handed out where the device reads them. */
static vkrt_result host_words_end(vk_context *vk, vk_buffer *b, uint32_t *w, size_t words)
{
    if (b->mapped) return vk_buffer_flush(vk, b);
    const vkrt_result r = vk_buffer_upload(vk, b, w, (VkDeviceSize)(words ? words : 1) * sizeof *w);
    core_free(vk->core, w);
    return r;
}

/* The planned lists' entries, written into their buffer (a CPU device's memory is the host's:
 * where the device reads them). */
static vkrt_result binned_lists_upload(vk_context *vk, binned_lists *l)
{
    const uint32_t entries = l->bins.entry_count;
    vkrt_result r = vk_word_buffer_create(vk, entries, "vkrt triangle lists", &l->tris);
    if (r != VKRT_OK) return r;
    uint32_t *words = host_words_begin(vk, &l->tris.buffer, entries, "list entries");
    if (!words) return VKRT_ERROR_OUT_OF_MEMORY;
    ray_bin_fill(&l->bins, words);
    return host_words_end(vk, &l->tris.buffer, words, entries);
}

/* Lists the triangles of `count` rays (those of `rays`, else the primary rays of `camera`,
 * ray_bin_plan_camera) on the host and puts the lists on the device, where the rays share one
 * origin, the lists keep within the limits and memory holds them; l->built says whether they
 * did (else the BVH takes the rays). Fails only where the device does otherwise than by
 * running out of memory. */
static vkrt_result binned_lists_build(vk_context *vk, const gpu_scene *scene, const vkrt_gpu_tri *tris,
                                      uint32_t threads, const vkrt_ray *rays, const vkrt_gpu_push *camera,
                                      size_t count, binned_lists *l)
{
    uint64_t max_entries = (uint64_t)count * GPU_BIN_ENTRIES_PER_RAY;
    if (max_entries > vk->properties.limits.maxTexelBufferElements)
        max_entries = vk->properties.limits.maxTexelBufferElements;
    if (max_entries > UINT32_MAX) max_entries = UINT32_MAX;
    const ray_bin_limits limits = { .max_entries = (uint32_t)max_entries, .max_list = GPU_BIN_MAX_LIST };
    ray_bin_outcome outcome;
    vkrt_result r = rays ? ray_bin_plan(vk->core, &vk->bin_scratch, rays, (uint32_t)count, tris, scene->tri_count,
                                        &scene->root, limits, threads, &l->bins, &outcome)
                         : ray_bin_plan_camera(vk->core, &vk->bin_scratch, camera, tris, scene->tri_count, &scene->root,
                                               limits, threads, &l->bins, &outcome);
    if (r == VKRT_OK && outcome == RAY_BIN_BUILT) r = binned_lists_upload(vk, l);
    l->built = r == VKRT_OK && outcome == RAY_BIN_BUILT;
    if (r == VKRT_ERROR_OUT_OF_MEMORY || r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY) {
        /* The lists only save time: where the host or the device has no room for them, the
         * BVH, which needs nothing more, takes the rays. */
        core_log(vk->core, VKRT_LOG_WARN, "%s; the BVH traces these %zu rays instead of triangle lists",
                 vk->core->last_error, count);
        binned_lists_destroy(vk, l);
        core_clear_error(vk->core);
        r = VKRT_OK;
    }
    return r;
}

/* Whether a render may trace its camera rays through the binned traversal: closest hits shaded
 * (the heat map and the counters show the BVH itself), through the wide BVH's arrays (whose
 * triangles the lists index) with the watertight test and no alpha test, and binning_suits. */
static bool render_binning_suits(const vk_context *vk, const gpu_scene *scene, const gpu_trace_params *params,
                                 const vk_trace_variant *variant)
{
    return variant->wide && variant->traversal == VKRT_GPU_TRAVERSAL_BVH && !variant->counters &&
           variant->mode != VKRT_GPU_MODE_HEATMAP && !params->alpha_tested &&
           params->intersector != VKRT_INTERSECTOR_MOLLER_TRUMBORE &&
           binning_suits(vk, scene, params->tris, (size_t)params->camera.width * params->camera.height);
}

/* The lists of the rectangle `push` names (tile_x, tile_y, tile_width x tile_height of an
 * image `width` wide), slot by slot as the shader reads them, into o->ray_lists; their entries
 * added to *tests. */
static vkrt_result rect_lists(vk_context *vk, render_objects *o, const ray_bins *bins, uint32_t width,
                              const vkrt_gpu_push *push, uint64_t *tests)
{
    const size_t n = (size_t)push->tile_width * push->tile_height;
    uint32_t *words = host_words_begin(vk, &o->ray_lists.buffer, 2 * n, "the pixels' lists");
    if (!words) return VKRT_ERROR_OUT_OF_MEMORY;
    for (uint32_t row = 0; row < push->tile_height; row++)
        for (uint32_t col = 0; col < push->tile_width; col++) {
            uint32_t *list = words + 2 * ((size_t)row * push->tile_width + col);
            ray_bin_list(bins, (push->tile_y + row) * width + push->tile_x + col, list);
            *tests += list[1];
        }
    return host_words_end(vk, &o->ray_lists.buffer, words, 2 * n);
}

vkrt_result gpu_trace_render(vk_context *vk, const gpu_scene *scene, const gpu_trace_params *params,
                             float *out_rgba, double *out_device_ms, trace_counts *out_counts)
{
    assert(arrays_uploaded(scene, gpu_trace_render_arrays(scene, params)));
    *out_device_ms = 0.0;
    *out_counts = (trace_counts){ 0 };
    const uint32_t width = params->camera.width, height = params->camera.height;
    const bool naive = params->traversal == VKRT_TRAVERSAL_NAIVE;
    /* Naive traversal needs no budget: each chunk dispatch loops VKRT_NAIVE_CHUNK_TRIS times. */
    vk_trace_variant variant = {
        .mode = gpu_mode(params->mode),
        .traversal = naive ? VKRT_GPU_TRAVERSAL_NAIVE : VKRT_GPU_TRAVERSAL_BVH,
        .heat = gpu_heat(params->heat),
        .raygen = VKRT_GPU_RAYGEN_CAMERA,
        .isect = gpu_isect(params->intersector),
        .budget = naive ? 0 : vk->trace_budget,
        /* Naive traversal's counts are known without tracing: no variant for them. */
        .counters = params->counters && !naive,
        .alpha = params->alpha_tested,
        /* Only albedo and the alpha test sample textures: other modes share one pipeline. */
        .textures = params->textured && (params->alpha_tested || params->mode == VKRT_MODE_ALBEDO),
        .split = scene->split_shift,
    };
    /* Only heatmap reads the heat kind: other modes share one pipeline whatever it is. */
    if (variant.mode != VKRT_GPU_MODE_HEATMAP) variant.heat = VKRT_GPU_HEAT_NODES;
    variant.wide = render_is_wide(scene, params);
    /* On a CPU device the camera rays may skip the BVH (README, "Binned traversal"). */
    binned_lists lists = { 0 };
    const double listing_start = core_now_ms();
    vkrt_result r = render_binning_suits(vk, scene, params, &variant)
                        ? binned_lists_build(vk, scene, params->tris, params->threads, NULL, &params->camera,
                                             (size_t)width * height, &lists)
                        : VKRT_OK;
    if (lists.built) {
        variant.traversal = VKRT_GPU_TRAVERSAL_BINNED;
        variant.budget = 0;
        /* The host's listing is the trace's work as much as the device's tests are. */
        *out_device_ms += core_now_ms() - listing_start;
    }
    vk_trace_pipeline pipe;
    if (r == VKRT_OK) r = vk_trace_pipeline_get(vk, variant, &pipe);
    if (r != VKRT_OK) {
        binned_lists_destroy(vk, &lists);
        return r;
    }

    const bool budget = variant.budget != 0;
    const uint32_t tile_w = width < TILE_SIZE ? width : TILE_SIZE;
    const uint32_t tile_h = height < TILE_SIZE ? height : TILE_SIZE;
    render_objects o;
    r = create_render_objects(vk, scene, pipe.set_layout, tile_w, tile_h, naive ? tile_w * tile_h : 1, 0,
                              budget ? tile_w * tile_h : 0, variant.counters ? tile_w * tile_h : 0, 0,
                              lists.built ? tile_w * tile_h : 0, lists.built ? lists.tris.view : VK_NULL_HANDLE, &o);
    gpu_pacer pacer;
    pacer_for(vk, scene, naive, (uint64_t)tile_w * tile_h, &pacer);
    const uint32_t tiles_x = core_div_up(width, tile_w), tiles_y = core_div_up(height, tile_h);
    const uint32_t tiles = tiles_x * tiles_y;
    const double pixels = (double)width * height;
    uint64_t done = 0;
    bool first = true;
    /* Tiles bound the buffers; within one, rectangles sized by the pacer bound each
     * submission's time. */
    for (uint32_t t = 0; r == VKRT_OK && t < tiles; t++) {
        const uint32_t tx = (t % tiles_x) * tile_w, ty = (t / tiles_x) * tile_h;
        const uint32_t tw = width - tx < tile_w ? width - tx : tile_w, th = height - ty < tile_h ? height - ty : tile_h;
        for (uint32_t x = 0, y = 0; r == VKRT_OK && y < th;) {
            const float fraction = (float)((double)done / pixels);
            if (params->progress && !params->progress(params->progress_user, "trace", fraction)) {
                r = core_fail(vk->core, VKRT_ERROR_CANCELLED, "render cancelled by the progress callback");
                break;
            }
            uint32_t rw, rh;
            gpu_pacer_rect(tw, th, x, y, gpu_pacer_items(&pacer, naive ? naive_chunks(scene) : 1), &rw, &rh);
            vkrt_gpu_push push = params->camera;
            push.tile_x = tx + x;
            push.tile_y = ty + y;
            push.tile_width = rw;
            push.tile_height = rh;
            push.tri_first = 0;
            push.tri_end = scene->tri_count;
            push.tri_total = scene->tri_count;
            push.last_chunk = 1;
            const pass_desc pass = { .pipe = &pipe, .scene = scene, .naive = naive, .budget = budget, .first = first,
                                     .what = "render", .pacer = &pacer, .progress = params->progress,
                                     .progress_user = params->progress_user, .fraction = fraction };
            first = false;
            if (lists.built && (r = rect_lists(vk, &o, &lists.bins, width, &push, &out_counts->binned_tests)) != VKRT_OK)
                break;
            if ((r = run_passes(vk, &o, &pass, push, out_device_ms, NULL)) != VKRT_OK) break;
            if (variant.counters && (r = add_tile_counts(vk, &o, rw * rh, out_counts)) != VKRT_OK) break;
            const float *src = o.readback.mapped;
            for (uint32_t row = 0; row < rh; row++) {
                float *dst = out_rgba + ((size_t)(push.tile_y + row) * width + push.tile_x) * 4;
                memcpy(dst, src + (size_t)row * rw * 4, (size_t)rw * 4 * sizeof(float));
            }
            done += (uint64_t)rw * rh;
            x += rw;
            if (x == tw) {
                x = 0;
                y += rh;
            }
        }
    }
    if (r == VKRT_OK && params->counters && naive) out_counts->tris = (uint64_t)scene->tri_count * width * height;
    out_counts->submissions = pacer.submissions;
    out_counts->longest_submission_ms = pacer.longest_ms;
    out_counts->rays_binned = lists.built ? (uint64_t)width * height : 0;
    if (r == VKRT_OK && params->progress) params->progress(params->progress_user, "trace", 1.0f);
    render_objects_destroy(vk, &o);
    binned_lists_destroy(vk, &lists);
    return r;
}

/* Records one pass over a chunk of rays (its first, a resume, or the next naive chunks):
 * dispatch(es) over the rays, then a copy of the hits into the readback buffer where `hits`
 * says so. */
static void record_rays(VkCommandBuffer cmd, const vk_trace_pipeline *pipe, const render_objects *o,
                        const gpu_scene *scene, vkrt_gpu_push push, bool naive, bool binned, bool budget,
                        bool first_use, pass_range range, hits_way hits)
{
    /* The storage image is never written in ray mode, but its descriptor must be in the layout
     * it names. */
    if (first_use && !range.again) record_image_to_general(cmd, o, true, false);
    /* The shader reads the rays the host, a staging copy or (the wavefront) shade.comp wrote,
     * and overwrites hits that the previous chunk's copy or shade stage read. */
    VkMemoryBarrier inputs = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
        .srcAccessMask = VK_ACCESS_HOST_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_TRANSFER_READ_BIT |
                         VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_SHADER_READ_BIT,
        .dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT,
    };
    vkCmdPipelineBarrier(cmd, VK_PIPELINE_STAGE_HOST_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT,
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT, 0, 1, &inputs, 0, NULL,
                         0, NULL);
    /* The binned traversal (no finish pass) takes one ray an invocation. */
    const uint32_t groups =
        binned ? core_div_up(push.tile_width, VKRT_TRACE_GROUP_SIZE) : ray_groups(scene, naive, push.tile_width);
    record_dispatches(cmd, pipe, o, scene, push, naive, budget, range, groups, 1);
    if (hits == HITS_ON_DEVICE) return;
    if (hits == HITS_MAPPED) {
        /* The host reads the hits where the shader wrote them, after the fence. */
        record_buffer_barrier(cmd, o->hits.buffer, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                              VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
        return;
    }
    /* The copy reads the hits the shader wrote. */
    record_buffer_barrier(cmd, o->hits.buffer, VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT, VK_ACCESS_SHADER_WRITE_BIT,
                          VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_READ_BIT);
    VkBufferCopy region = { .size = (VkDeviceSize)push.tile_width * sizeof(vkrt_gpu_hit) };
    vkCmdCopyBuffer(cmd, o->hits.buffer, o->readback.buffer, 1, &region);
    /* The host reads the readback buffer after the fence. */
    record_buffer_barrier(cmd, o->readback.buffer, VK_PIPELINE_STAGE_TRANSFER_BIT, VK_ACCESS_TRANSFER_WRITE_BIT,
                          VK_PIPELINE_STAGE_HOST_BIT, VK_ACCESS_HOST_READ_BIT);
}

/* The pipeline variant of a ray buffer traced from `raygen` (buffer or wavefront). Mode and heat
 * are unused there: fixed, so every ray call shares one pipeline. */
static vk_trace_variant ray_variant(const vk_context *vk, const gpu_scene *scene, const gpu_trace_rays_params *params,
                                    uint32_t raygen)
{
    const bool naive = params->traversal == VKRT_TRAVERSAL_NAIVE;
    return (vk_trace_variant){
        .mode = VKRT_GPU_MODE_ID,
        .traversal = naive ? VKRT_GPU_TRAVERSAL_NAIVE : VKRT_GPU_TRAVERSAL_BVH,
        .heat = VKRT_GPU_HEAT_NODES,
        .raygen = raygen,
        .isect = gpu_isect(params->intersector),
        .budget = naive ? 0 : vk->trace_budget,
        .alpha = params->alpha_tested,
        .anyhit = params->any_hit,
        .textures = params->textured && params->alpha_tested,
        .split = scene->split_shift,
        .wide = wide_traversal(scene, naive),
    };
}

/* One chunk of a vkrt_trace_rays call on its way through the device. Two take turns, each
 * with its own buffers, so that the host copies the next chunk's rays in (with the cull) while
 * the device traces this one, and puts this one's hits back while the device traces the next.
 * On a CPU device the host's share (5-6 ms of 1M primary rays) otherwise left one of lavapipe's
 * cores idle: 0.97x the time on primary rays, 0.98-0.99x on AO rays (the full dragon and
 * dragon_200k, in-process pairs). A GPU whose ray buffers the host maps gains the copy's time;
 * one that stages them (vk_buffer_upload) waits for the queue there, as it did before. */
typedef struct ray_chunk {
    render_objects o;
    bool created;           /* o was made (the second chunk's only when the call needs it) */
    bool used;              /* a pass was recorded with o: the image's layout is set */
    uint32_t *sent_index;   /* with the host cull: the call's position of each ray sent */
    size_t first;           /* the call's position of the chunk's first ray read */
    uint32_t sent;          /* rays on the device (0: the chunk holds none) */
    pass_desc desc;
    vkrt_gpu_push push;
    pass_in_flight pass;    /* its first pass, where launched and not yet waited for */
    bool launched;
} ray_chunk;

/* What every chunk of a vkrt_trace_rays call shares. */
typedef struct ray_call {
    vk_context *vk;
    const gpu_scene *scene;
    const gpu_trace_rays_params *params;
    vk_trace_pipeline pipe;
    const vkrt_ray *rays;
    size_t count, next;     /* the call's rays; the first not yet read into a chunk */
    vkrt_hit *out_hits;
    bool naive, budget, cull;
    binned_lists lists;     /* lists.built: through the binned traversal's lists */
    hits_way hits;
    uint32_t capacity, naive_chunks;
    gpu_pacer pacer;
    double device_ms;       /* the passes' device time so far */
    uint64_t culled;        /* rays the host answered (call->cull) */
    uint64_t binned_tests;  /* the entries of the lists sent */
} ray_call;

/* Makes chunk c's buffers, with a readback buffer for its hits where `readback` (the first
 * chunk's is added once its buffers show where the hits come back: gpu_trace_rays). */
static vkrt_result ray_chunk_create(ray_call *call, ray_chunk *c, bool readback)
{
    vk_context *vk = call->vk;
    vkrt_result r = create_render_objects(
        vk, call->scene, call->pipe.set_layout, 1, 1, call->capacity, call->capacity,
        call->budget ? ray_resume_slots(call->scene, call->naive, call->capacity) : 0, 0,
        call->lists.built ? 0 : ray_slot_words(call->scene, call->naive, call->capacity),
        call->lists.built ? call->capacity : 0, call->lists.built ? call->lists.tris.view : VK_NULL_HANDLE, &c->o);
    c->created = true;
    if (r == VKRT_OK && readback) r = create_hit_readback(vk, &c->o, call->capacity);
    if (r == VKRT_OK && call->cull && !(c->sent_index = core_calloc_array(vk->core, call->capacity, sizeof *c->sent_index)))
        r = VKRT_ERROR_OUT_OF_MEMORY;
    return r;
}

static void ray_chunk_destroy(vk_context *vk, ray_chunk *c)
{
    /* An error between its launch and its wait leaves a pass on the device: wait before its
     * buffers go. */
    if (c->launched) vk_submission_wait(vk, &c->pass.submission);
    core_free(vk->core, c->sent_index);
    if (c->created) render_objects_destroy(vk, &c->o);
}

/* The binned lists (first entry, count) of chunk c's n rays, the first read at the call's
 * position `first`, into its list buffer, in the order the rays were sent. */
static vkrt_result ray_chunk_lists(ray_call *call, ray_chunk *c, size_t first, uint32_t n)
{
    uint32_t *words = host_words_begin(call->vk, &c->o.ray_lists.buffer, 2 * (size_t)n, "the rays' lists");
    if (!words) return VKRT_ERROR_OUT_OF_MEMORY;
    for (uint32_t i = 0; i < n; i++) {
        ray_bin_list(&call->lists.bins, (uint32_t)(first + (call->cull ? c->sent_index[i] : i)), words + 2 * i);
        call->binned_tests += words[2 * i + 1];
    }
    return host_words_end(call->vk, &c->o.ray_lists.buffer, words, 2 * (size_t)n);
}

/* Reads the call's next rays into chunk c, as many as the pacer allows and its buffers hold:
 * with the host cull, only those that may enter the scene's box (their positions in
 * sent_index, the others' misses written to out_hits at once), reading on past chunks whose
 * rays all miss. c->sent stays 0 where no ray is left to send. Asks the progress callback
 * before each chunk. */
static vkrt_result ray_chunk_fill(ray_call *call, ray_chunk *c)
{
    vk_context *vk = call->vk;
    c->sent = 0;
    while (call->next < call->count) {
        const size_t first = call->next, left_rays = call->count - first;
        const float fraction = (float)((double)first / (double)call->count);
        if (call->params->progress && !call->params->progress(call->params->progress_user, "trace", fraction))
            return core_fail(vk->core, VKRT_ERROR_CANCELLED, "trace cancelled by the progress callback");
        /* As many rays as the pacer allows with every naive chunk, at least one workgroup. */
        uint64_t n = gpu_pacer_items(&call->pacer, call->naive_chunks);
        if (n < VKRT_TRACE_GROUP_SIZE) n = VKRT_TRACE_GROUP_SIZE;
        if (n > call->capacity) n = call->capacity;
        if (n > left_rays) n = left_rays;
        size_t read = n;
        vkrt_result r;
        if (call->cull) {
            /* Positions within a chunk are 32-bit: read at most 2^32 - 1 rays a chunk. */
            const size_t left = left_rays < UINT32_MAX ? left_rays : UINT32_MAX;
            if (call->lists.built)
                n = ray_bin_compact(&call->lists.bins, call->rays + first, first, left, n, c->o.rays.mapped, c->sent_index,
                                    call->out_hits + first, &read);
            else
                n = ray_cull_compact(call->rays + first, left, call->scene->node_count ? &call->scene->root : NULL, n,
                                     c->o.rays.mapped, c->sent_index, call->out_hits + first, &read);
            call->next += read;
            call->culled += read - n;
            if (n == 0) continue;
            r = vk_buffer_flush(vk, &c->o.rays);
        } else {
            r = vk_buffer_upload(vk, &c->o.rays, call->rays + first, n * sizeof *call->rays);
            call->next += read;
        }
        if (r == VKRT_OK && call->lists.built) r = ray_chunk_lists(call, c, first, (uint32_t)n);
        if (r != VKRT_OK) return r;
        c->first = first;
        c->sent = (uint32_t)n;
        c->push = (vkrt_gpu_push){ .tile_width = (uint32_t)n, .tile_height = 1, .tri_end = call->scene->tri_count,
                                   .tri_total = call->scene->tri_count, .last_chunk = 1 };
        c->desc = (pass_desc){ .pipe = &call->pipe, .scene = call->scene, .naive = call->naive, .budget = call->budget,
                               .binned = call->lists.built, .rays = true, .hits = call->hits, .first = !c->used, .what = "trace",
                               .pacer = &call->pacer, .progress = call->params->progress,
                               .progress_user = call->params->progress_user, .fraction = fraction };
        return VKRT_OK;
    }
    return VKRT_OK;
}

/* Submits chunk c's first pass without waiting (naive traversal, whose passes the pacer sizes
 * one by one, is submitted and waited for in ray_chunk_finish). */
static vkrt_result ray_chunk_launch(ray_call *call, ray_chunk *c)
{
    c->used = true;
    if (call->naive) return VKRT_OK;
    vkrt_result r = launch_first_pass(call->vk, &c->o, &c->desc, c->push, &c->pass);
    c->launched = r == VKRT_OK;
    return r;
}

/* Waits for chunk c's first pass and runs what passes are left; its hits are then where
 * call->hits says. */
static vkrt_result ray_chunk_finish(ray_call *call, ray_chunk *c)
{
    pass_in_flight *launched = c->launched ? &c->pass : NULL;
    c->launched = false; /* run_passes waits for it first, whatever follows */
    return run_passes(call->vk, &c->o, &c->desc, c->push, &call->device_ms, launched);
}

/* Chunk c's hits to their rays' places in out_hits. The wide traversal's finish writes a miss
 * as its triangle word alone, NO_HIT, the rest of its hit unwritten: it becomes the miss here. */
static void ray_chunk_collect(ray_call *call, ray_chunk *c)
{
    const vkrt_hit *sent_hits = hits_for_host(&c->o, call->hits)->mapped;
    const vkrt_hit miss = cpu_trace_miss();
    for (size_t i = 0; i < c->sent; i++) {
        const vkrt_hit *h = &sent_hits[i];
        call->out_hits[c->first + (call->cull ? c->sent_index[i] : i)] = h->prim_id == VKRT_NO_HIT ? miss : *h;
    }
    c->sent = 0;
}

/* Whether a call's rays may take the binned traversal: besides binning_suits, closest hits
 * through the BVH with the watertight test (whose rounding ray_bin.c's widening covers) and no
 * alpha test. */
static bool rays_binning_suit(const vk_context *vk, const gpu_scene *scene, const gpu_trace_rays_params *params,
                              size_t count)
{
    return params->traversal != VKRT_TRAVERSAL_NAIVE && !params->any_hit && !params->alpha_tested &&
           params->intersector != VKRT_INTERSECTOR_MOLLER_TRUMBORE && binning_suits(vk, scene, params->tris, count);
}

static void ray_call_destroy(ray_call *call)
{
    binned_lists_destroy(call->vk, &call->lists);
}

vkrt_result gpu_trace_rays(vk_context *vk, const gpu_scene *scene, const gpu_trace_rays_params *params,
                           const vkrt_ray *rays, size_t count, vkrt_hit *out_hits, double *out_device_ms,
                           trace_counts *out_counts)
{
    assert(arrays_uploaded(scene, gpu_trace_rays_arrays(scene, params->traversal)));
    ray_call call = { .vk = vk, .scene = scene, .params = params, .rays = rays, .count = count, .out_hits = out_hits };
    call.naive = params->traversal == VKRT_TRAVERSAL_NAIVE;
    vkrt_result r = rays_binning_suit(vk, scene, params, count)
                        ? binned_lists_build(vk, scene, params->tris, params->threads, rays, NULL, count, &call.lists)
                        : VKRT_OK;
    vk_trace_variant variant = ray_variant(vk, scene, params, VKRT_GPU_RAYGEN_BUFFER);
    if (call.lists.built) {
        variant.traversal = VKRT_GPU_TRAVERSAL_BINNED;
        variant.budget = 0;
    }
    if (r == VKRT_OK) r = vk_trace_pipeline_get(vk, variant, &call.pipe);
    if (r != VKRT_OK) {
        ray_call_destroy(&call);
        return r;
    }
    call.budget = variant.budget != 0;
    /* With a budget, smaller chunks keep the continuation buffers small. */
    const uint32_t max_chunk = call.budget ? VKRT_RESUME_RAY_CHUNK : VKRT_RAY_CHUNK;
    call.capacity = count < max_chunk ? (uint32_t)count : max_chunk;
    call.naive_chunks = call.naive ? naive_chunks(scene) : 1;
    pacer_for(vk, scene, call.naive, call.capacity, &call.pacer);
    ray_chunk chunks[2] = { 0 };
    /* On a CPU device (lavapipe), through the BVH, only the rays that may enter the scene's box
     * reach the device (ray_cull.h), copied straight into the mapped ray buffer, their positions
     * in `sent_index` for the hits' way back: there a ray that misses the scene costs an
     * iteration of the traversal loop on the host's own cores, a whole iteration's work for all
     * eight lanes of a SIMD group, where the host's test costs a few nanoseconds. A GPU spends
     * less on such a ray than the host's test would, and gets every ray. So does naive
     * traversal, the BVH's reference. Decided before the first chunk's buffers are made, by
     * what they will be: mapped on a CPU device, whose memory is the host's. */
    call.cull = !call.naive && vk->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
    r = ray_chunk_create(&call, &chunks[0], false);
    if (r == VKRT_OK && call.cull && !chunks[0].o.rays.mapped) {
        /* Not mapped after all: every ray goes to the device. */
        call.cull = false;
        core_free(vk->core, chunks[0].sent_index);
        chunks[0].sent_index = NULL;
    }
    /* Where the rays go straight into mapped memory, so can the hits come back: the host reads
     * the hit buffer itself, without the copy into the readback buffer that lavapipe's threads
     * would make (0.99x the time on primary rays). */
    call.hits = call.cull && chunks[0].o.hits.mapped ? HITS_MAPPED : HITS_READBACK;
    if (r == VKRT_OK && call.hits == HITS_READBACK) r = create_hit_readback(vk, &chunks[0].o, call.capacity);
    if (r == VKRT_OK) r = ray_chunk_fill(&call, &chunks[0]);
    if (r == VKRT_OK && chunks[0].sent) r = ray_chunk_launch(&call, &chunks[0]);
    for (int at = 0; r == VKRT_OK && chunks[at].sent; at ^= 1) {
        ray_chunk *c = &chunks[at], *next = &chunks[at ^ 1];
        /* The next chunk's rays into the other buffers while the device traces this one. */
        if (call.next < count && !next->created) r = ray_chunk_create(&call, next, call.hits == HITS_READBACK);
        if (r == VKRT_OK && call.next < count) r = ray_chunk_fill(&call, next);
        const vkrt_result finished = ray_chunk_finish(&call, c);
        if (r == VKRT_OK) r = finished;
        /* The next chunk goes to the device before this one's hits go back. */
        if (r == VKRT_OK && next->sent) r = ray_chunk_launch(&call, next);
        if (r == VKRT_OK) ray_chunk_collect(&call, c);
    }
    if (r == VKRT_OK && params->progress) params->progress(params->progress_user, "trace", 1.0f);
    ray_chunk_destroy(vk, &chunks[0]);
    ray_chunk_destroy(vk, &chunks[1]);
    *out_device_ms = call.device_ms;
    *out_counts = (trace_counts){ .submissions = call.pacer.submissions,
                                  .longest_submission_ms = call.pacer.longest_ms,
                                  .rays_culled = call.culled,
                                  .rays_binned = call.lists.built ? count - call.culled : 0,
                                  .binned_tests = call.binned_tests };
    ray_call_destroy(&call);
    return r;
}

/* ---- the wavefront's traversal passes ---- */

struct gpu_wavefront_tracer {
    vk_trace_pipeline pipe;
    render_objects o;
    bool naive, budget;
    bool first;
    uint32_t capacity;
};

gpu_wavefront_tracer *gpu_wavefront_tracer_alloc(vk_context *vk)
{
    return core_calloc_array(vk->core, 1, sizeof(gpu_wavefront_tracer));
}

vkrt_result gpu_wavefront_tracer_init(vk_context *vk, gpu_wavefront_tracer *t, const gpu_scene *scene,
                                      const gpu_trace_rays_params *params, uint32_t capacity)
{
    assert(arrays_uploaded(scene, gpu_trace_rays_arrays(scene, params->traversal)));
    const bool naive = params->traversal == VKRT_TRAVERSAL_NAIVE;
    const vk_trace_variant variant = ray_variant(vk, scene, params, VKRT_GPU_RAYGEN_WAVEFRONT);
    vkrt_result r = vk_trace_pipeline_get(vk, variant, &t->pipe);
    t->naive = naive;
    t->budget = variant.budget != 0;
    t->first = true;
    t->capacity = capacity;
    if (r == VKRT_OK)
        r = create_render_objects(vk, scene, t->pipe.set_layout, 1, 1, capacity, capacity,
                                  t->budget ? ray_resume_slots(scene, naive, capacity) : 0, 0,
                                  ray_slot_words(scene, naive, capacity), 0, VK_NULL_HANDLE, &t->o);
    return r;
}

VkBuffer gpu_wavefront_rays(const gpu_wavefront_tracer *t)
{
    return t->o.rays.buffer;
}

VkBuffer gpu_wavefront_hits(const gpu_wavefront_tracer *t)
{
    return t->o.hits.buffer;
}

void gpu_wavefront_pacer(const vk_context *vk, const gpu_scene *scene, bool naive, uint32_t capacity, gpu_pacer *out)
{
    pacer_for(vk, scene, naive, capacity, out);
    /* Stages and traversals take turns: each kind must have been fast before it grows. */
    out->grow_after = 4;
}

vkrt_result gpu_wavefront_trace(vk_context *vk, gpu_wavefront_tracer *t, const gpu_scene *scene, uint32_t count,
                                gpu_pacer *pacer, const gpu_wave_progress *progress, double *device_ms)
{
    if (count > t->capacity)
        return core_fail(vk->core, VKRT_ERROR_INVALID_ARGUMENT, "%u rays exceed the wavefront's %u", count, t->capacity);
    if (count == 0) return VKRT_OK;
    vkrt_gpu_push push = { .tile_width = count, .tile_height = 1, .tri_end = scene->tri_count,
                           .tri_total = scene->tri_count, .last_chunk = 1 };
    const pass_desc pass = { .pipe = &t->pipe, .scene = scene, .naive = t->naive, .budget = t->budget, .rays = true,
                             .hits = HITS_ON_DEVICE, .first = t->first, .what = "render", .pacer = pacer,
                             .progress = progress->progress, .progress_user = progress->user,
                             .fraction = progress->fraction };
    t->first = false;
    return run_passes(vk, &t->o, &pass, push, device_ms, NULL);
}

void gpu_wavefront_tracer_destroy(vk_context *vk, gpu_wavefront_tracer *t)
{
    if (!t) return;
    render_objects_destroy(vk, &t->o);
    core_free(vk->core, t);
}
