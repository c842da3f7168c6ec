/* A buffer with its memory, and the one-shot command submissions: waited for at once (copies),
 * or left in flight while the host works (vkrt_trace_rays' chunks). */
#ifndef VKRT_VK_BUFFER_H
#define VKRT_VK_BUFFER_H

#include "vk_context.h"

typedef struct vk_buffer {
    VkBuffer buffer;
    VkDeviceMemory memory;
    VkDeviceSize size;
    VkDeviceSize allocated;  /* bytes of its device memory allocation (size rounded up by the driver) */
    uint32_t memory_type;    /* of that allocation */
    void *mapped;        /* persistently mapped when the memory is host-visible, else NULL */
    bool coherent;
    bool address;        /* its memory was allocated for device addresses */
} vk_buffer;

typedef enum vk_memory_use {
    VK_MEMORY_DEVICE,    /* device-local; host-visible too where the device offers it (lavapipe,
                            integrated GPUs, ReBAR), which spares the staging copy */
    VK_MEMORY_READBACK   /* host-visible, cached where possible: the host reads it */
} vk_memory_use;

vkrt_result vk_buffer_create(vk_context *vk, VkDeviceSize size, VkBufferUsageFlags usage, vk_memory_use use,
                             const char *label, vk_buffer *out);
/* Destroys the buffer; its memory stays with the context, mapped, for a later buffer of its type
 * and size (up to VK_RECYCLED_BLOCKS blocks, vk_context.h). */
void vk_buffer_destroy(vk_context *vk, vk_buffer *b);
/* The device address of a buffer created with VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT (which
 * needs vk->buffer_address). */
VkDeviceAddress vk_buffer_address(vk_context *vk, const vk_buffer *b);

/* A storage texel buffer of RGBA32UI texels, read only, and its view (the wide traversal's
 * arrays: texel reads are lavapipe's fastest). `texels` of 0 makes a one-texel
 * placeholder for a binding the variant never reads. */
typedef struct vk_texel_buffer {
    vk_buffer buffer;
    VkBufferView view;
} vk_texel_buffer;

vkrt_result vk_texel_buffer_create(vk_context *vk, const uint32_t *data, uint32_t texels, const char *label,
                                   vk_texel_buffer *out);
/* A view of the first `bytes` of buffer, created with a texel-buffer usage, in `format`
 * (VK_FORMAT_R32G32B32A32_UINT or VK_FORMAT_R32_UINT): as many whole texels as they hold (at
 * least one), at most the device's maxTexelBufferElements. Destroy with vkDestroyBufferView. */
vkrt_result vk_buffer_view_create(vk_context *vk, VkBuffer buffer, VkDeviceSize bytes, VkFormat format,
                                  VkBufferView *out);
void vk_texel_buffer_destroy(vk_context *vk, vk_texel_buffer *t);
/* A texel buffer of `words` R32UI texels (at least one) that the host fills after this returns,
 * through buffer.mapped where the device's memory is mapped, else by vk_buffer_upload; the
 * shaders read and write it a word at a time (imageLoad, imageStore). Destroy with
 * vk_texel_buffer_destroy. */
vkrt_result vk_word_buffer_create(vk_context *vk, size_t words, const char *label, vk_texel_buffer *out);

/* Fills a device buffer: a memcpy when it is mapped, else through a staging buffer. */
vkrt_result vk_buffer_upload(vk_context *vk, vk_buffer *dst, const void *data, VkDeviceSize size);
/* Makes host writes through b->mapped visible to the device. */
vkrt_result vk_buffer_flush(vk_context *vk, vk_buffer *b);
/* Makes device writes visible to the host before reading b->mapped. */
vkrt_result vk_buffer_invalidate(vk_context *vk, vk_buffer *b);

/* Every device memory allocation of the library goes through these: they keep
 * vk->memory_in_use and vk->heap_in_use, refuse what the heap (or the test knob's budget)
 * cannot hold with VKRT_ERROR_OUT_OF_DEVICE_MEMORY, naming `label`, once the recycled blocks
 * are freed, and honour the fail_allocation test hook. */
vkrt_result vk_memory_allocate(vk_context *vk, const VkMemoryAllocateInfo *info, const char *label,
                               VkDeviceMemory *out);
/* Frees what vk_memory_allocate made from `info` (the same size and type); NULL: no-op. */
void vk_memory_free(vk_context *vk, VkDeviceMemory memory, const VkMemoryAllocateInfo *info);
/* Frees the memory the context keeps from destroyed buffers (vk_buffer_destroy keeps it for
 * the next vk_buffer_create: VK_RECYCLED_BLOCKS in vk_context.h). */
void vk_memory_recycled_release(vk_context *vk);

/* How long a submission may take before its device is treated as lost: far beyond the 100 ms
 * submissions are sized to, and beyond lavapipe compiling a pipeline at its first dispatch. */
#define VK_SUBMIT_TIMEOUT_NS 120000000000ull

/* Allocates a primary command buffer from the context pool, begun for one-time submit;
 * VKRT_ERROR_DEVICE_LOST once the device is lost. */
vkrt_result vk_commands_begin(vk_context *vk, VkCommandBuffer *out);
/* Ends, submits and waits on a fence, then frees the command buffer. A lost device
 * (VK_ERROR_DEVICE_LOST, or no answer within VK_SUBMIT_TIMEOUT_NS) is VKRT_ERROR_DEVICE_LOST
 * and marks the context lost. */
vkrt_result vk_commands_submit_wait(vk_context *vk, VkCommandBuffer cmd);

/* A submission in flight, for a caller with host work to do meanwhile: its command buffer and
 * fence (both null: none). */
typedef struct vk_submission {
    VkCommandBuffer cmd;
    VkFence fence;
    bool fail_at_wait;  /* the fail_submission test knob fired, to fail the wait */
} vk_submission;

/* vk_commands_submit_wait in two halves: ends and submits cmd (freed on failure), then waits,
 * which frees it and the fence (none in flight: VKRT_OK at once). Every submission made must
 * be waited for before the buffers it uses are destroyed. */
vkrt_result vk_commands_submit(vk_context *vk, VkCommandBuffer cmd, vk_submission *out);
vkrt_result vk_submission_wait(vk_context *vk, vk_submission *s);

#endif
