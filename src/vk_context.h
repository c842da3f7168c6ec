/* The Vulkan side of a context: instance, optional validation layer and its messenger,
 * the chosen physical device, one compute queue, a command pool and the pipeline cache. */
#ifndef VKRT_VK_CONTEXT_H
#define VKRT_VK_CONTEXT_H

#include <stdbool.h>
#include <vulkan/vulkan.h>

#include "core.h"

/* Device memory a context keeps from the buffers it destroys, for the next buffers it makes:
 * every vkrt_trace_rays call and render makes its working buffers (rays, hits, continuation
 * state, tiles) and destroys them at its end. On a CPU device (lavapipe) device memory is the
 * host's heap: fresh memory faults its pages in, zeroed, at first touch, and memory freed back
 * to the system is unmapped, a TLB shootdown across the cores. Calls whose allocations took
 * that road (430-950 page faults a call against 0-140, depending on the heap's state, for the
 * whole process) took up to 1.8x the time of the same calls in the same process whose didn't
 * (docs/issue7.md, the twenty-fourth session). At most this many blocks and bytes are kept. */
#define VK_RECYCLED_BLOCKS 64u
#define VK_RECYCLED_BYTES ((VkDeviceSize)64 << 20)

struct vk_pipelines;

typedef struct vk_context {
    core *core;                       /* borrowed from the owning vkrt_context */
    VkInstance instance;
    VkDebugUtilsMessengerEXT messenger;
    PFN_vkDestroyDebugUtilsMessengerEXT destroy_messenger;
    PFN_vkSetDebugUtilsObjectNameEXT set_object_name;
    VkPhysicalDevice physical;
    VkPhysicalDeviceProperties properties;
    VkPhysicalDeviceMemoryProperties memory;
    VkDevice device;
    VkQueue queue;
    uint32_t queue_family;
    bool timestamps;                  /* the queue supports timestamp queries */
    double timestamp_period_ns;
    bool float64;                     /* shaderFloat64 enabled: the shader refines hit distances in double */
    bool exact_rounding;              /* the shaders emulate correctly rounded division and square
                                         root (VKRT_EXACT_ROUNDING): a device with doubles whose
                                         driver is not lavapipe; tests set it on lavapipe too, before
                                         the first pipeline is made */
    bool buffer_address;              /* bufferDeviceAddress enabled: a scene beyond one storage buffer
                                         is split into pieces the shaders reach by address */
    VkDeviceSize max_allocation;      /* maxMemoryAllocationSize: one device memory allocation at most */
    uint32_t naive_share;             /* lanes of a subgroup whose triangle reads naive traversal
                                         shares (VKRT_NAIVE_SHARE, vk_naive_share); 1: none. Tests
                                         may set it before the first pipeline is made */
    uint32_t trace_budget;            /* BVH loop iterations per dispatch (VKRT_SPEC_BUDGET); 0: unlimited */
    VkCommandPool command_pool;
    VkPipelineCache pipeline_cache;
    char *pipeline_cache_path;        /* NULL: in memory only */
    uint32_t validation_messages;     /* validation warnings and errors received */
    bool lost;                        /* a call returned VK_ERROR_DEVICE_LOST (or a fence never
                                         signalled): nothing is submitted any more */
    VkFence hung_fence;               /* a submission whose fence timed out, and its command */
    VkCommandBuffer hung_commands;    /* buffer: freed at destruction, after the device is idle */
    VkDeviceSize memory_in_use;       /* device memory of this context's live allocations (the
                                         recycled blocks below apart), */
    VkDeviceSize heap_in_use[VK_MAX_MEMORY_HEAPS]; /* in all and per memory heap */
    VkDeviceSize memory_budget;       /* 0: none; else device memory allocations that would take
                                         memory_in_use past this many bytes fail as out of device
                                         memory, without asking the driver
                                         (vkrt_context_desc.device_memory_limit; tests set it too) */
    /* Device memory of destroyed buffers, kept mapped for the next buffer of its type and about
     * its size (vk_buffer.c): not in memory_in_use, and within memory_budget with it. */
    struct vk_recycled_block {
        VkDeviceMemory memory;
        VkDeviceSize size;
        uint32_t type;
        bool address;                 /* allocated for buffers reached by device address */
        void *mapped;
    } recycled[VK_RECYCLED_BLOCKS];
    uint32_t recycled_count;          /* oldest first */
    VkDeviceSize recycled_bytes;
    struct vk_pipelines *pipelines;   /* compiled lazily, owned (vk_pipeline.c) */
    struct ray_bin_scratch *bin_scratch; /* the binned traversal's host memory, kept between calls
                                         (ray_bin.h); owned */
    /* Test knobs: zero from vk_context_create, set by tests through this private header only. */
    VkDeviceSize scene_buffer_limit;  /* 0: the device's limits; else the most bytes one buffer of a
                                         scene's arrays may hold, so small scenes split into pieces
                                         (at least 128: two triangles) */
    double submit_target_ms;          /* 0: GPU_SUBMIT_TARGET_MS; else the time each submission aims
                                         at (tiny: every submission as small as it can be) */
    uint32_t fail_allocation;         /* 0: none; N: the Nth device memory allocation from now fails
                                         with VK_ERROR_OUT_OF_DEVICE_MEMORY (once) */
    uint32_t fail_submission;         /* 0: none; N: the Nth submission from now returns
                                         fail_result (once), from vkQueueSubmit (nothing is
                                         submitted) or, with fail_at_wait, from vkWaitForFences
                                         (after the real wait, so the work has finished) */
    VkResult fail_result;
    bool fail_at_wait;
    bool no_wide_traversal;           /* scenes uploaded from now on keep to the binary BVH */
    bool no_ray_binning;              /* vkrt_trace_rays never takes the binned traversal */
} vk_context;

/* How many lanes of a subgroup share their triangle reads in naive traversal: the largest power
 * of two up to VKRT_NAIVE_SHARE_MAX and the subgroup size, where compute shaders have the basic,
 * vote and ballot operations and the subgroups fill a trace workgroup exactly (so that lanes 0
 * to the share - 1 of every subgroup are there to broadcast); else 1. */
uint32_t vk_naive_share(const VkPhysicalDeviceSubgroupProperties *subgroup);

/* Creates everything for the device the desc chooses. Failures: VKRT_ERROR_NO_DEVICE (no
 * loader, no driver, no usable device, index out of range), VKRT_ERROR_VULKAN (a call
 * failed, or validation asked for and not installed), VKRT_ERROR_OUT_OF_MEMORY. */
vkrt_result vk_context_create(core *c, const vkrt_context_desc *desc, vk_context **out);
/* Waits for the device, saves the pipeline cache, destroys everything; NULL is a no-op. */
void vk_context_destroy(vk_context *vk);

vkrt_result vk_devices_list(core *c, vkrt_device_info *out, uint32_t *inout_count);

/* Records a failed Vulkan call: maps VkResult to a vkrt_result (VK_ERROR_DEVICE_LOST also marks
 * the context lost) and names the call. */
vkrt_result vk_fail(vk_context *vk, VkResult result, const char *call);
/* VKRT_ERROR_DEVICE_LOST, with a message saying so, once the device is lost; else VKRT_OK.
 * Every path that would use the device asks first. */
vkrt_result vk_check_lost(vk_context *vk);
const char *vk_result_string(VkResult result);

/* Labels a Vulkan object for validation messages and debuggers, where debug utils exist. */
void vk_label(vk_context *vk, VkObjectType type, uint64_t handle, const char *name);

#endif
