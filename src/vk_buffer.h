/* A buffer with its memory, and the one-shot command submission used for copies. */
#ifndef VKRT_VK_BUFFER_H
#define VKRT_VK_BUFFER_H

#include "vk_context.h"

typedef struct vk_buffer {
    VkBuffer buffer;
    VkDeviceMemory memory;
    VkDeviceSize size;
    VkDeviceSize allocated;  /* bytes of its device memory allocation (size rounded up by the driver) */
    void *mapped;        /* persistently mapped when the memory is host-visible, else NULL */
    bool coherent;
} vk_buffer;

typedef enum vk_memory_use {
    VK_MEMORY_DEVICE,    /* device-local; host-visible too where the device offers it (lavapipe,
                            integrated GPUs, ReBAR), which spares the staging copy */
    VK_MEMORY_READBACK   /* host-visible, cached where possible: the host reads it */
} vk_memory_use;

vkrt_result vk_buffer_create(vk_context *vk, VkDeviceSize size, VkBufferUsageFlags usage, vk_memory_use use,
                             const char *label, vk_buffer *out);
void vk_buffer_destroy(vk_context *vk, vk_buffer *b);
/* The device address of a buffer created with VK_BUFFER_USAGE_SHADER_DEVICE_ADDRESS_BIT (which
 * needs vk->buffer_address). */
VkDeviceAddress vk_buffer_address(vk_context *vk, const vk_buffer *b);

/* Fills a device buffer: a memcpy when it is mapped, else through a staging buffer. */
vkrt_result vk_buffer_upload(vk_context *vk, vk_buffer *dst, const void *data, VkDeviceSize size);
/* Makes device writes visible to the host before reading b->mapped. */
vkrt_result vk_buffer_invalidate(vk_context *vk, vk_buffer *b);

/* Allocates a primary command buffer from the context pool, begun for one-time submit. */
vkrt_result vk_commands_begin(vk_context *vk, VkCommandBuffer *out);
/* Ends, submits and waits on a fence, then frees the command buffer. */
vkrt_result vk_commands_submit_wait(vk_context *vk, VkCommandBuffer cmd);

#endif
