#include "vk_buffer.h"

#include <string.h>

static int find_memory_type(const VkPhysicalDeviceMemoryProperties *mem, uint32_t type_bits,
                            VkMemoryPropertyFlags required, VkMemoryPropertyFlags preferred)
{
    for (int pass = 0; pass < 2; pass++) {
        VkMemoryPropertyFlags want = pass == 0 ? (required | preferred) : required;
        for (uint32_t i = 0; i < mem->memoryTypeCount; i++) {
            if (!(type_bits & (1u << i))) continue;
            if ((mem->memoryTypes[i].propertyFlags & want) == want) return (int)i;
        }
    }
    return -1;
}

/* The Nth call of a test hook's countdown (0: the hook is off): true once, when it reaches 1. */
static bool countdown_fires(uint32_t *countdown)
{
    if (*countdown == 0) return false;
    return --*countdown == 0;
}

/* Frees the recycled blocks, oldest first, until at most `keep_bytes` are kept. */
static void recycled_trim(vk_context *vk, VkDeviceSize keep_bytes)
{
    uint32_t dropped = 0;
    while (dropped < vk->recycled_count && vk->recycled_bytes > keep_bytes) {
        struct vk_recycled_block *b = &vk->recycled[dropped++];
        if (b->mapped) vkUnmapMemory(vk->device, b->memory);
        vkFreeMemory(vk->device, b->memory, NULL);
        vk->recycled_bytes -= b->size;
    }
    vk->recycled_count -= dropped;
    memmove(vk->recycled, vk->recycled + dropped, vk->recycled_count * sizeof vk->recycled[0]);
}

void vk_memory_recycled_release(vk_context *vk)
{
    recycled_trim(vk, 0);
}

/* The checks and the allocation of vk_memory_allocate, the fail_allocation hook left to the
 * caller. Recycled blocks give way first where the heap or the budget, counting them, would
 * refuse the request, and where the driver does. */
static vkrt_result allocate_checked(vk_context *vk, const VkMemoryAllocateInfo *info, const char *label, bool fail,
                                    VkDeviceMemory *out)
{
    *out = VK_NULL_HANDLE;
    const VkDeviceSize size = info->allocationSize;
    const uint32_t heap = vk->memory.memoryTypes[info->memoryTypeIndex].heapIndex;
    const VkDeviceSize heap_size = vk->memory.memoryHeaps[heap].size;
    if (vk->heap_in_use[heap] + vk->recycled_bytes + size > heap_size ||
        (vk->memory_budget && vk->memory_in_use + vk->recycled_bytes + size > vk->memory_budget))
        vk_memory_recycled_release(vk);
    /* A request the heap cannot hold on top of what this context holds already is refused
     * before the driver is asked: some drivers (lavapipe among them) would overcommit. */
    if (vk->heap_in_use[heap] + size > heap_size)
        return core_fail(vk->core, VKRT_ERROR_OUT_OF_DEVICE_MEMORY,
                         "out of device memory: %s needs %llu bytes, and this context already holds %llu of the "
                         "device's %llu-byte memory heap",
                         label, (unsigned long long)size, (unsigned long long)vk->heap_in_use[heap],
                         (unsigned long long)heap_size);
    if (vk->memory_budget && vk->memory_in_use + size > vk->memory_budget)
        return core_fail(vk->core, VKRT_ERROR_OUT_OF_DEVICE_MEMORY,
                         "out of device memory: %s needs %llu bytes, and this context already holds %llu of its "
                         "%llu-byte budget",
                         label, (unsigned long long)size, (unsigned long long)vk->memory_in_use,
                         (unsigned long long)vk->memory_budget);
    VkResult res = fail ? VK_ERROR_OUT_OF_DEVICE_MEMORY : vkAllocateMemory(vk->device, info, NULL, out);
    if (!fail && (res == VK_ERROR_OUT_OF_DEVICE_MEMORY || res == VK_ERROR_OUT_OF_HOST_MEMORY) && vk->recycled_count) {
        vk_memory_recycled_release(vk);
        res = vkAllocateMemory(vk->device, info, NULL, out);
    }
    if (res != VK_SUCCESS) {
        *out = VK_NULL_HANDLE;
        const bool host = res == VK_ERROR_OUT_OF_HOST_MEMORY;
        if (host || res == VK_ERROR_OUT_OF_DEVICE_MEMORY)
            return core_fail(vk->core, host ? VKRT_ERROR_OUT_OF_MEMORY : VKRT_ERROR_OUT_OF_DEVICE_MEMORY,
                             "out of %s memory: vkAllocateMemory of %llu bytes for %s failed: %s",
                             host ? "host" : "device", (unsigned long long)size, label, vk_result_string(res));
        return vk_fail(vk, res, "vkAllocateMemory");
    }
    vk->memory_in_use += size;
    vk->heap_in_use[heap] += size;
    return VKRT_OK;
}

vkrt_result vk_memory_allocate(vk_context *vk, const VkMemoryAllocateInfo *info, const char *label,
                               VkDeviceMemory *out)
{
    return allocate_checked(vk, info, label, countdown_fires(&vk->fail_allocation), out);
}

void vk_memory_free(vk_context *vk, VkDeviceMemory memory, const VkMemoryAllocateInfo *info)
{
    if (!memory) return;
    vkFreeMemory(vk->device, memory, NULL);
    vk->memory_in_use -= info->allocationSize;
    vk->heap_in_use[vk->memory.memoryTypes[info->memoryTypeIndex].heapIndex] -= info->allocationSize;
}

/* Takes a recycled block for `size` bytes of memory type `type` into *out, at most an eighth
 * larger (a call's working buffers come back at the sizes they had, and a scene's buffers
 * should not hold, and report, memory they do not need), as live memory; false: none. Never
 * past memory_budget's count of live memory. */
static bool recycled_take(vk_context *vk, VkDeviceSize size, uint32_t type, bool address,
                          struct vk_recycled_block *out)
{
    for (uint32_t i = vk->recycled_count; i-- > 0;) {
        const struct vk_recycled_block b = vk->recycled[i];
        if (b.type != type || b.address != address || b.size < size || b.size - size > size / 8) continue;
        if (vk->memory_budget && vk->memory_in_use + b.size > vk->memory_budget) continue;
        vk->recycled_count--;
        memmove(vk->recycled + i, vk->recycled + i + 1, (vk->recycled_count - i) * sizeof vk->recycled[0]);
        vk->recycled_bytes -= b.size;
        vk->memory_in_use += b.size;
        vk->heap_in_use[vk->memory.memoryTypes[type].heapIndex] += b.size;
        *out = b;
        return true;
    }
    return false;
}

/* Keeps a destroyed buffer's memory (still mapped) for a later buffer, or frees it where it
 * is larger than the pool; the oldest blocks go to make room. */
static void recycle(vk_context *vk, VkDeviceMemory memory, VkDeviceSize size, uint32_t type, bool address,
                    void *mapped)
{
    vk->memory_in_use -= size;
    vk->heap_in_use[vk->memory.memoryTypes[type].heapIndex] -= size;
    if (size > VK_RECYCLED_BYTES || vk->lost) {
        if (mapped) vkUnmapMemory(vk->device, memory);
        vkFreeMemory(vk->device, memory, NULL);
        return;
    }
    recycled_trim(vk, VK_RECYCLED_BYTES - size);
    if (vk->recycled_count == VK_RECYCLED_BLOCKS) {
        const VkDeviceSize oldest = vk->recycled[0].size;
        recycled_trim(vk, vk->recycled_bytes - oldest);
    }
    vk->recycled[vk->recycled_count++] =
        (struct vk_recycled_block){ .memory = memory, .size = size, .type = type, .address = address, .mapped = mapped };
    vk->recycled_bytes += size;
}

vkrt_result vk_buffer_create(vk_context *vk, VkDeviceSize size, VkBufferUsageFlags usage, vk_memory_use use,
                             const char *label, vk_buffer *out)
{
    memset(out, 0, sizeof *out);
    out->size = size;
    VkBufferCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_BUFFER_CREATE_INFO,
        .size = size ? size : 16,
        .usage = usage,
        .sharingMode = VK_SHARING_MODE_EXCLUSIVE,
    };
    VkResult res = vkCreateBuffer(vk->device, &info, NULL, &out->buffer);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateBuffer");
    vk_label(vk, VK_OBJECT_TYPE_BUFFER, (uint64_t)out->buffer, label);

    VkMemoryRequirements req;
    vkGetBufferMemoryRequirements(vk->device, out->buffer, &req);
    VkMemoryPropertyFlags required, preferred;
    if (use == VK_MEMORY_DEVICE) {
        required = VK_MEMORY_PROPERTY_DEVICE_LOCAL_BIT;
        preferred = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT | VK_MEMORY_PROPERTY_HOST_COHERENT_BIT;
    } else {
        required = VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT;
        preferred = VK_MEMORY_PROPERTY_HOST_CACHED_BIT;
    }
    int type = find_memory_type(&vk->memory, req.memoryTypeBits, required, preferred);
    if (type < 0) type = find_memory_type(&vk->memory, req.memoryTypeBits, 0, 0);
    if (type < 0) {
        vk_buffer_destroy(vk, out);
        return core_fail(vk->core, VKRT_ERROR_VULKAN, "no memory type for buffer %s", label);
    }
    VkMemoryPropertyFlags flags = vk->memory.memoryTypes[type].propertyFlags;
    /* A small scene on a large device may keep host-visible memory that is not device-local,
     * so staging is decided by what the chosen type offers, not by what was asked for. */
    /* A buffer the shaders reach by address needs memory that has one. */
    VkMemoryAllocateFlagsInfo address_flags = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_FLAGS_INFO,
        .flags = VK_MEMORY_ALLOCATE_DEVICE_ADDRESS_BIT,
    };
    VkMemoryAllocateInfo alloc = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_ALLOCATE_INFO,
        .pNext = (usage & VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT) ? &address_flags : NULL,
        .allocationSize = req.size,
        .memoryTypeIndex = (uint32_t)type,
    };
    const bool address = alloc.pNext != NULL;
    /* The hook counts every buffer's memory, recycled or not, so that its failures reach the
     * same buffers whatever the pool holds. */
    const bool fail = countdown_fires(&vk->fail_allocation);
    struct vk_recycled_block kept;
    vkrt_result r = VKRT_OK;
    if (!fail && recycled_take(vk, req.size, (uint32_t)type, address, &kept)) {
        out->memory = kept.memory;
        out->mapped = kept.mapped;
        out->allocated = kept.size;
    } else {
        r = allocate_checked(vk, &alloc, label, fail, &out->memory);
        out->allocated = req.size;
    }
    out->memory_type = (uint32_t)type;
    out->address = address;
    if (r != VKRT_OK) {
        vk_buffer_destroy(vk, out);
        return r;
    }
    res = vkBindBufferMemory(vk->device, out->buffer, out->memory, 0);
    if (res != VK_SUCCESS) {
        vk_buffer_destroy(vk, out);
        return vk_fail(vk, res, "vkBindBufferMemory");
    }
    out->coherent = (flags & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT) && (flags & VK_MEMORY_PROPERTY_HOST_COHERENT_BIT);
    if ((flags & VK_MEMORY_PROPERTY_HOST_VISIBLE_BIT) && !out->mapped) {
        res = vkMapMemory(vk->device, out->memory, 0, VK_WHOLE_SIZE, 0, &out->mapped);
        if (res != VK_SUCCESS) {
            vk_buffer_destroy(vk, out);
            return vk_fail(vk, res, "vkMapMemory");
        }
        /* Before the first write. On a CPU device (lavapipe) this is ordinary host memory, the
         * memory the shaders read; a GPU's mapped memory is the driver's, left as it is. */
        if (vk->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU)
            core_advise_huge_pages(out->mapped, (size_t)req.size);
    }
    return VKRT_OK;
}

VkDeviceAddress vk_buffer_address(vk_context *vk, const vk_buffer *b)
{
    VkBufferDeviceAddressInfo info = { .sType = VK_STRUCTURE_TYPE_BUFFER_DEVICE_ADDRESS_INFO, .buffer = b->buffer };
    return vkGetBufferDeviceAddress(vk->device, &info);
}

void vk_buffer_destroy(vk_context *vk, vk_buffer *b)
{
    if (b->buffer) vkDestroyBuffer(vk->device, b->buffer, NULL);
    if (b->memory) recycle(vk, b->memory, b->allocated, b->memory_type, b->address, b->mapped);
    memset(b, 0, sizeof *b);
}

vkrt_result vk_buffer_flush(vk_context *vk, vk_buffer *b)
{
    if (b->coherent) return VKRT_OK;
    VkMappedMemoryRange range = { .sType = VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE, .memory = b->memory, .size = VK_WHOLE_SIZE };
    VkResult res = vkFlushMappedMemoryRanges(vk->device, 1, &range);
    return res == VK_SUCCESS ? VKRT_OK : vk_fail(vk, res, "vkFlushMappedMemoryRanges");
}

vkrt_result vk_buffer_invalidate(vk_context *vk, vk_buffer *b)
{
    if (b->coherent) return VKRT_OK;
    VkMappedMemoryRange range = { .sType = VK_STRUCTURE_TYPE_MAPPED_MEMORY_RANGE, .memory = b->memory, .size = VK_WHOLE_SIZE };
    VkResult res = vkInvalidateMappedMemoryRanges(vk->device, 1, &range);
    return res == VK_SUCCESS ? VKRT_OK : vk_fail(vk, res, "vkInvalidateMappedMemoryRanges");
}

vkrt_result vk_buffer_upload(vk_context *vk, vk_buffer *dst, const void *data, VkDeviceSize size)
{
    if (dst->mapped) {
        memcpy(dst->mapped, data, (size_t)size);
        return vk_buffer_flush(vk, dst);
    }
    vk_buffer staging;
    vkrt_result r = vk_buffer_create(vk, size, VK_BUFFER_USAGE_TRANSFER_SRC_BIT, VK_MEMORY_READBACK, "vkrt staging", &staging);
    if (r != VKRT_OK) return r;
    memcpy(staging.mapped, data, (size_t)size);
    if ((r = vk_buffer_flush(vk, &staging)) == VKRT_OK) {
        VkCommandBuffer cmd;
        if ((r = vk_commands_begin(vk, &cmd)) == VKRT_OK) {
            VkBufferCopy region = { .size = size };
            vkCmdCopyBuffer(cmd, staging.buffer, dst->buffer, 1, &region);
            r = vk_commands_submit_wait(vk, cmd);
        }
    }
    vk_buffer_destroy(vk, &staging);
    return r;
}

/* A storage texel buffer of `bytes` and its view in `format`: what vk_texel_buffer_create and
 * vk_word_buffer_create make before the contents. */
static vkrt_result texel_buffer_make(vk_context *vk, VkDeviceSize bytes, VkFormat format, const char *label,
                                     vk_texel_buffer *out)
{
    memset(out, 0, sizeof *out);
    vkrt_result r = vk_buffer_create(vk, bytes, VK_BUFFER_USAGE_STORAGE_TEXEL_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT,
                                     VK_MEMORY_DEVICE, label, &out->buffer);
    if (r == VKRT_OK) r = vk_buffer_view_create(vk, out->buffer.buffer, bytes, format, &out->view);
    if (r != VKRT_OK) vk_texel_buffer_destroy(vk, out);
    return r;
}

vkrt_result vk_texel_buffer_create(vk_context *vk, const uint32_t *data, uint32_t texels, const char *label,
                                   vk_texel_buffer *out)
{
    const uint32_t zero[4] = { 0 };
    const VkDeviceSize bytes = (VkDeviceSize)(texels ? texels : 1) * sizeof zero;
    vkrt_result r = texel_buffer_make(vk, bytes, VK_FORMAT_R32G32B32A32_UINT, label, out);
    if (r != VKRT_OK) return r; /* texel_buffer_make cleaned up */
    r = vk_buffer_upload(vk, &out->buffer, texels ? (const void *)data : zero, bytes);
    if (r != VKRT_OK) vk_texel_buffer_destroy(vk, out);
    return r;
}

vkrt_result vk_buffer_view_create(vk_context *vk, VkBuffer buffer, VkDeviceSize bytes, VkFormat format,
                                  VkBufferView *out)
{
    *out = VK_NULL_HANDLE;
    const VkDeviceSize texel = (format == VK_FORMAT_R32_UINT ? 1 : 4) * sizeof(uint32_t);
    const VkDeviceSize limit = (VkDeviceSize)vk->properties.limits.maxTexelBufferElements;
    const VkDeviceSize texels = bytes / texel < limit ? bytes / texel : limit;
    VkBufferViewCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_BUFFER_VIEW_CREATE_INFO,
        .buffer = buffer,
        .format = format,
        .range = (texels ? texels : 1) * texel,
    };
    VkResult res = vkCreateBufferView(vk->device, &info, NULL, out);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateBufferView");
    return VKRT_OK;
}

vkrt_result vk_word_buffer_create(vk_context *vk, size_t words, const char *label, vk_texel_buffer *out)
{
    return texel_buffer_make(vk, (VkDeviceSize)(words ? words : 1) * sizeof(uint32_t), VK_FORMAT_R32_UINT, label, out);
}

void vk_texel_buffer_destroy(vk_context *vk, vk_texel_buffer *t)
{
    if (t->view) vkDestroyBufferView(vk->device, t->view, NULL);
    t->view = VK_NULL_HANDLE;
    vk_buffer_destroy(vk, &t->buffer);
}

vkrt_result vk_commands_begin(vk_context *vk, VkCommandBuffer *out)
{
    *out = VK_NULL_HANDLE;
    vkrt_result r = vk_check_lost(vk);
    if (r != VKRT_OK) return r;
    VkCommandBufferAllocateInfo alloc = {
        .sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_ALLOCATE_INFO,
        .commandPool = vk->command_pool,
        .level = VK_COMMAND_BUFFER_LEVEL_PRIMARY,
        .commandBufferCount = 1,
    };
    VkResult res = vkAllocateCommandBuffers(vk->device, &alloc, out);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkAllocateCommandBuffers");
    VkCommandBufferBeginInfo begin = {
        .sType = VK_STRUCTURE_TYPE_COMMAND_BUFFER_BEGIN_INFO,
        .flags = VK_COMMAND_BUFFER_USAGE_ONE_TIME_SUBMIT_BIT,
    };
    res = vkBeginCommandBuffer(*out, &begin);
    if (res != VK_SUCCESS) {
        vkFreeCommandBuffers(vk->device, vk->command_pool, 1, out);
        return vk_fail(vk, res, "vkBeginCommandBuffer");
    }
    return VKRT_OK;
}

vkrt_result vk_commands_submit(vk_context *vk, VkCommandBuffer cmd, vk_submission *out)
{
    *out = (vk_submission){ 0 };
    VkFence fence = VK_NULL_HANDLE;
    VkResult res = vkEndCommandBuffer(cmd);
    const char *call = "vkEndCommandBuffer";
    if (res == VK_SUCCESS) {
        VkFenceCreateInfo fence_info = { .sType = VK_STRUCTURE_TYPE_FENCE_CREATE_INFO };
        res = vkCreateFence(vk->device, &fence_info, NULL, &fence);
        call = "vkCreateFence";
    }
    const bool inject = res == VK_SUCCESS && countdown_fires(&vk->fail_submission);
    if (res == VK_SUCCESS) {
        VkSubmitInfo submit = { .sType = VK_STRUCTURE_TYPE_SUBMIT_INFO, .commandBufferCount = 1, .pCommandBuffers = &cmd };
        res = inject && !vk->fail_at_wait ? vk->fail_result : vkQueueSubmit(vk->queue, 1, &submit, fence);
        call = "vkQueueSubmit";
    }
    if (res != VK_SUCCESS) {
        if (fence) vkDestroyFence(vk->device, fence, NULL);
        vkFreeCommandBuffers(vk->device, vk->command_pool, 1, &cmd);
        return vk_fail(vk, res, call);
    }
    *out = (vk_submission){ .cmd = cmd, .fence = fence, .fail_at_wait = inject };
    return VKRT_OK;
}

vkrt_result vk_submission_wait(vk_context *vk, vk_submission *s)
{
    if (!s->cmd) return VKRT_OK;
    /* Bounded, so a device that never answers cannot hang the caller: submissions are sized
     * to 100 ms, and drivers report a reset GPU as lost within seconds. */
    VkResult res = vkWaitForFences(vk->device, 1, &s->fence, VK_TRUE, VK_SUBMIT_TIMEOUT_NS);
    if (res == VK_SUCCESS && s->fail_at_wait) res = vk->fail_result;
    if (res == VK_TIMEOUT) {
        /* Still pending: its fence and command buffer wait for the context's destruction. */
        vk->hung_fence = s->fence;
        vk->hung_commands = s->cmd;
        vk->lost = true;
        *s = (vk_submission){ 0 };
        return core_fail(vk->core, VKRT_ERROR_DEVICE_LOST,
                         "a submission did not finish within %.0f s: the device is treated as lost; destroy the "
                         "context, and its scenes, and create a new one",
                         (double)VK_SUBMIT_TIMEOUT_NS * 1e-9);
    }
    vkDestroyFence(vk->device, s->fence, NULL);
    vkFreeCommandBuffers(vk->device, vk->command_pool, 1, &s->cmd);
    *s = (vk_submission){ 0 };
    return res == VK_SUCCESS ? VKRT_OK : vk_fail(vk, res, "vkWaitForFences");
}

vkrt_result vk_commands_submit_wait(vk_context *vk, VkCommandBuffer cmd)
{
    vk_submission s;
    vkrt_result r = vk_commands_submit(vk, cmd, &s);
    return r == VKRT_OK ? vk_submission_wait(vk, &s) : r;
}
