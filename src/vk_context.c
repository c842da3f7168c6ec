#include "vk_context.h"

#include "vk_buffer.h"

#include <stdio.h>
#include <string.h>
#include <unistd.h>

#include "../shaders/vkrt_shared.h"
#include "ray_bin.h"
#include "tls_pin.h"
#include "vk_pipeline.h"

#define VALIDATION_LAYER "VK_LAYER_KHRONOS_validation"

const char *vk_result_string(VkResult result)
{
    switch (result) {
#define CASE(x) case x: return #x;
        CASE(VK_SUCCESS) CASE(VK_NOT_READY) CASE(VK_TIMEOUT) CASE(VK_EVENT_SET) CASE(VK_EVENT_RESET)
        CASE(VK_INCOMPLETE) CASE(VK_ERROR_OUT_OF_HOST_MEMORY) CASE(VK_ERROR_OUT_OF_DEVICE_MEMORY)
        CASE(VK_ERROR_INITIALIZATION_FAILED) CASE(VK_ERROR_DEVICE_LOST) CASE(VK_ERROR_MEMORY_MAP_FAILED)
        CASE(VK_ERROR_LAYER_NOT_PRESENT) CASE(VK_ERROR_EXTENSION_NOT_PRESENT) CASE(VK_ERROR_FEATURE_NOT_PRESENT)
        CASE(VK_ERROR_INCOMPATIBLE_DRIVER) CASE(VK_ERROR_TOO_MANY_OBJECTS) CASE(VK_ERROR_FORMAT_NOT_SUPPORTED)
        CASE(VK_ERROR_FRAGMENTED_POOL) CASE(VK_ERROR_UNKNOWN) CASE(VK_ERROR_OUT_OF_POOL_MEMORY)
#undef CASE
    default: return "VkResult (unknown)";
    }
}

vkrt_result vk_fail(vk_context *vk, VkResult result, const char *call)
{
    vkrt_result r = VKRT_ERROR_VULKAN;
    if (result == VK_ERROR_OUT_OF_HOST_MEMORY) r = VKRT_ERROR_OUT_OF_MEMORY;
    else if (result == VK_ERROR_OUT_OF_DEVICE_MEMORY) r = VKRT_ERROR_OUT_OF_DEVICE_MEMORY;
    else if (result == VK_ERROR_DEVICE_LOST) r = VKRT_ERROR_DEVICE_LOST;
    if (r == VKRT_ERROR_DEVICE_LOST) {
        vk->lost = true;
        return core_fail(vk->core, r, "%s failed: %s: the device was lost (reset, hung or removed); destroy the "
                                      "context, and its scenes, and create a new one",
                         call, vk_result_string(result));
    }
    return core_fail(vk->core, r, "%s failed: %s", call, vk_result_string(result));
}

vkrt_result vk_check_lost(vk_context *vk)
{
    if (!vk->lost) return VKRT_OK;
    return core_fail(vk->core, VKRT_ERROR_DEVICE_LOST,
                     "the Vulkan device was lost in an earlier call; destroy the context, and its scenes, and "
                     "create a new one");
}

void vk_label(vk_context *vk, VkObjectType type, uint64_t handle, const char *name)
{
    if (!vk->set_object_name || !handle) return;
    VkDebugUtilsObjectNameInfoEXT info = {
        .sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_OBJECT_NAME_INFO_EXT,
        .objectType = type,
        .objectHandle = handle,
        .pObjectName = name,
    };
    vk->set_object_name(vk->device, &info);
}

static VKAPI_ATTR VkBool32 VKAPI_CALL on_debug_message(VkDebugUtilsMessageSeverityFlagBitsEXT severity,
                                                       VkDebugUtilsMessageTypeFlagsEXT types,
                                                       const VkDebugUtilsMessengerCallbackDataEXT *data,
                                                       void *user)
{
    vk_context *vk = user;
    bool error = severity & VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT;
    /* Validation findings are counted so tests can fail on any; the loader's own messages
     * (general type: a missing driver file, say) only explain a failure already reported. */
    bool validation =
        types & (VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT);
    if (validation) vk->validation_messages++;
    core_log(vk->core, validation ? (error ? VKRT_LOG_ERROR : VKRT_LOG_WARN) : VKRT_LOG_INFO, "Vulkan %s: %s",
             validation ? "validation" : "loader", data && data->pMessage ? data->pMessage : "(no message)");
    return VK_FALSE;
}

static bool layer_available(const char *name)
{
    uint32_t count = 0;
    if (vkEnumerateInstanceLayerProperties(&count, NULL) != VK_SUCCESS) return false;
    VkLayerProperties layers[64];
    if (count > 64) count = 64;
    if (vkEnumerateInstanceLayerProperties(&count, layers) < 0) return false;
    for (uint32_t i = 0; i < count; i++)
        if (strcmp(layers[i].layerName, name) == 0) return true;
    return false;
}

static bool instance_extension_available(const char *name)
{
    uint32_t count = 0;
    if (vkEnumerateInstanceExtensionProperties(NULL, &count, NULL) != VK_SUCCESS) return false;
    VkExtensionProperties props[128];
    if (count > 128) count = 128;
    if (vkEnumerateInstanceExtensionProperties(NULL, &count, props) < 0) return false;
    for (uint32_t i = 0; i < count; i++)
        if (strcmp(props[i].extensionName, name) == 0) return true;
    return false;
}

static vkrt_result create_instance(vk_context *vk, bool validation)
{
    uint32_t loader_version = 0;
    /* vkEnumerateInstanceVersion exists from loader 1.1 on; without it there is no 1.2. */
    if (vkEnumerateInstanceVersion(&loader_version) != VK_SUCCESS || loader_version < VK_API_VERSION_1_2)
        return core_fail(vk->core, VKRT_ERROR_NO_DEVICE, "the Vulkan loader does not support Vulkan 1.2");

    const char *layers[1];
    uint32_t layer_count = 0;
    if (validation) {
        if (!layer_available(VALIDATION_LAYER))
            return core_fail(vk->core, VKRT_ERROR_VULKAN,
                             "validation requested but %s is not installed (Debian: vulkan-validationlayers)",
                             VALIDATION_LAYER);
        layers[layer_count++] = VALIDATION_LAYER;
    }
    const char *extensions[1];
    uint32_t extension_count = 0;
    bool debug_utils = instance_extension_available(VK_EXT_DEBUG_UTILS_EXTENSION_NAME);
    if (debug_utils) extensions[extension_count++] = VK_EXT_DEBUG_UTILS_EXTENSION_NAME;

    VkApplicationInfo app = {
        .sType = VK_STRUCTURE_TYPE_APPLICATION_INFO,
        .pApplicationName = "vkrt",
        .applicationVersion = VKRT_VERSION,
        .pEngineName = "vkrt",
        .engineVersion = VKRT_VERSION,
        .apiVersion = VK_API_VERSION_1_2,
    };
    /* Chained into instance creation too, so messages about vkCreateInstance itself arrive. */
    VkDebugUtilsMessengerCreateInfoEXT messenger_info = {
        .sType = VK_STRUCTURE_TYPE_DEBUG_UTILS_MESSENGER_CREATE_INFO_EXT,
        .messageSeverity = VK_DEBUG_UTILS_MESSAGE_SEVERITY_WARNING_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_SEVERITY_ERROR_BIT_EXT,
        .messageType = VK_DEBUG_UTILS_MESSAGE_TYPE_GENERAL_BIT_EXT | VK_DEBUG_UTILS_MESSAGE_TYPE_VALIDATION_BIT_EXT |
                       VK_DEBUG_UTILS_MESSAGE_TYPE_PERFORMANCE_BIT_EXT,
        .pfnUserCallback = on_debug_message,
        .pUserData = vk,
    };
    VkInstanceCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_INSTANCE_CREATE_INFO,
        .pNext = debug_utils ? &messenger_info : NULL,
        .pApplicationInfo = &app,
        .enabledLayerCount = layer_count,
        .ppEnabledLayerNames = layers,
        .enabledExtensionCount = extension_count,
        .ppEnabledExtensionNames = extensions,
    };
    VkResult res = vkCreateInstance(&info, NULL, &vk->instance);
    if (res == VK_ERROR_INCOMPATIBLE_DRIVER)
        return core_fail(vk->core, VKRT_ERROR_NO_DEVICE, "no Vulkan driver is installed (vkCreateInstance: %s)",
                         vk_result_string(res));
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateInstance");
    /* The drivers are loaded now; those that need static TLS must stay (tls_pin.h). */
    vkrt_result pinned = tls_pin_static_libraries(vk->core);
    if (pinned != VKRT_OK) return pinned;

    if (debug_utils) {
        PFN_vkCreateDebugUtilsMessengerEXT create =
            (PFN_vkCreateDebugUtilsMessengerEXT)vkGetInstanceProcAddr(vk->instance, "vkCreateDebugUtilsMessengerEXT");
        vk->destroy_messenger =
            (PFN_vkDestroyDebugUtilsMessengerEXT)vkGetInstanceProcAddr(vk->instance, "vkDestroyDebugUtilsMessengerEXT");
        vk->set_object_name =
            (PFN_vkSetDebugUtilsObjectNameEXT)vkGetInstanceProcAddr(vk->instance, "vkSetDebugUtilsObjectNameEXT");
        if (create && vk->destroy_messenger) {
            res = create(vk->instance, &messenger_info, NULL, &vk->messenger);
            if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateDebugUtilsMessengerEXT");
        }
    }
    return VKRT_OK;
}

static vkrt_device_type device_type(VkPhysicalDeviceType t)
{
    switch (t) {
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return VKRT_DEVICE_INTEGRATED_GPU;
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return VKRT_DEVICE_DISCRETE_GPU;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return VKRT_DEVICE_VIRTUAL_GPU;
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return VKRT_DEVICE_CPU;
    default: return VKRT_DEVICE_OTHER;
    }
}

/* A real GPU wins over lavapipe; lavapipe (a CPU device) is never skipped. */
static int device_rank(VkPhysicalDeviceType t)
{
    switch (t) {
    case VK_PHYSICAL_DEVICE_TYPE_DISCRETE_GPU: return 4;
    case VK_PHYSICAL_DEVICE_TYPE_INTEGRATED_GPU: return 3;
    case VK_PHYSICAL_DEVICE_TYPE_VIRTUAL_GPU: return 2;
    case VK_PHYSICAL_DEVICE_TYPE_CPU: return 1;
    default: return 0;
    }
}

static bool compute_queue_family(VkPhysicalDevice physical, uint32_t *out_family)
{
    uint32_t count = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &count, NULL);
    VkQueueFamilyProperties families[32];
    if (count > 32) count = 32;
    vkGetPhysicalDeviceQueueFamilyProperties(physical, &count, families);
    /* Prefer a compute family that also has graphics (the main queue, with timestamps on all
     * drivers); any compute family works. */
    int best = -1;
    for (uint32_t i = 0; i < count; i++) {
        if (!(families[i].queueFlags & VK_QUEUE_COMPUTE_BIT)) continue;
        if (best < 0 || (families[i].timestampValidBits && !families[best].timestampValidBits)) best = (int)i;
    }
    if (best < 0) return false;
    *out_family = (uint32_t)best;
    return true;
}

static bool device_usable(VkPhysicalDevice physical, const VkPhysicalDeviceProperties *props)
{
    uint32_t family;
    return props->apiVersion >= VK_API_VERSION_1_2 && compute_queue_family(physical, &family);
}

#define MAX_DEVICES 16

static vkrt_result enumerate(vk_context *vk, VkPhysicalDevice *devices, uint32_t *count)
{
    *count = MAX_DEVICES;
    VkResult res = vkEnumeratePhysicalDevices(vk->instance, count, devices);
    if (res < 0) return vk_fail(vk, res, "vkEnumeratePhysicalDevices");
    if (*count == 0) return core_fail(vk->core, VKRT_ERROR_NO_DEVICE, "no Vulkan device found (is mesa-vulkan-drivers installed?)");
    return VKRT_OK;
}

static vkrt_result pick_device(vk_context *vk, const vkrt_context_desc *desc)
{
    VkPhysicalDevice devices[MAX_DEVICES];
    uint32_t count;
    vkrt_result r = enumerate(vk, devices, &count);
    if (r != VKRT_OK) return r;
    if (desc->select_device) {
        if (desc->device_index >= count)
            return core_fail(vk->core, VKRT_ERROR_NO_DEVICE, "device %u requested but only %u Vulkan device%s found",
                             desc->device_index, count, count == 1 ? "" : "s");
        VkPhysicalDeviceProperties props;
        vkGetPhysicalDeviceProperties(devices[desc->device_index], &props);
        if (!device_usable(devices[desc->device_index], &props))
            return core_fail(vk->core, VKRT_ERROR_NO_DEVICE, "device %u (%s) lacks Vulkan 1.2 or a compute queue",
                             desc->device_index, props.deviceName);
        vk->physical = devices[desc->device_index];
        return VKRT_OK;
    }
    int best_rank = -1;
    for (uint32_t i = 0; i < count; i++) {
        VkPhysicalDeviceProperties props;
        vkGetPhysicalDeviceProperties(devices[i], &props);
        if (!device_usable(devices[i], &props)) continue;
        int rank = device_rank(props.deviceType);
        if (rank > best_rank) {
            best_rank = rank;
            vk->physical = devices[i];
        }
    }
    if (best_rank < 0)
        return core_fail(vk->core, VKRT_ERROR_NO_DEVICE, "none of the %u Vulkan devices supports Vulkan 1.2 with a compute queue", count);
    return VKRT_OK;
}

uint32_t vk_naive_share(const VkPhysicalDeviceSubgroupProperties *subgroup)
{
    const VkSubgroupFeatureFlags needed =
        VK_SUBGROUP_FEATURE_BASIC_BIT | VK_SUBGROUP_FEATURE_VOTE_BIT | VK_SUBGROUP_FEATURE_BALLOT_BIT;
    const uint32_t size = subgroup->subgroupSize;
    if (!(subgroup->supportedStages & VK_SHADER_STAGE_COMPUTE_BIT) || (subgroup->supportedOperations & needed) != needed ||
        size == 0 || size > VKRT_TRACE_GROUP_SIZE || VKRT_TRACE_GROUP_SIZE % size != 0)
        return 1;
    uint32_t share = 1;
    while (share * 2 <= size && share * 2 <= VKRT_NAIVE_SHARE_MAX) share *= 2;
    return share;
}

static vkrt_result create_device(vk_context *vk)
{
    vkGetPhysicalDeviceProperties(vk->physical, &vk->properties);
    vkGetPhysicalDeviceMemoryProperties(vk->physical, &vk->memory);
    compute_queue_family(vk->physical, &vk->queue_family);

    uint32_t count = 0;
    vkGetPhysicalDeviceQueueFamilyProperties(vk->physical, &count, NULL);
    VkQueueFamilyProperties families[32];
    if (count > 32) count = 32;
    vkGetPhysicalDeviceQueueFamilyProperties(vk->physical, &count, families);
    vk->timestamps = families[vk->queue_family].timestampValidBits > 0 && vk->properties.limits.timestampPeriod > 0;
    vk->timestamp_period_ns = vk->properties.limits.timestampPeriod;
    /* lavapipe ends loops silently after 65,535 iterations per SIMD group; real GPUs have no
     * such limit, and their pipelines keep no budget code. */
    VkPhysicalDeviceMaintenance3Properties maintenance3 = {
        .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_MAINTENANCE_3_PROPERTIES };
    VkPhysicalDeviceDriverProperties driver = { .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_DRIVER_PROPERTIES,
                                                .pNext = &maintenance3 };
    VkPhysicalDeviceSubgroupProperties subgroup = { .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_SUBGROUP_PROPERTIES,
                                                    .pNext = &driver };
    VkPhysicalDeviceProperties2 props2 = { .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_PROPERTIES_2, .pNext = &subgroup };
    vkGetPhysicalDeviceProperties2(vk->physical, &props2);
    vk->max_allocation = maintenance3.maxMemoryAllocationSize;
    vk->naive_share = vk_naive_share(&subgroup);
    bool llvmpipe = driver.driverID == VK_DRIVER_ID_MESA_LLVMPIPE ||
                    vk->properties.deviceType == VK_PHYSICAL_DEVICE_TYPE_CPU;
    vk->trace_budget = llvmpipe ? VKRT_LAVAPIPE_BUDGET : 0;
    /* Doubles refine each hit's distance once per ray (refine_hit_distance in the shader); a
     * device without them keeps the float distance. */
    VkPhysicalDeviceFeatures supported;
    vkGetPhysicalDeviceFeatures(vk->physical, &supported);
    vk->float64 = supported.shaderFloat64 == VK_TRUE;
    /* Vulkan lets a device's float division be 2.5 ulps off and its square root more; C's and
     * lavapipe's round correctly. Elsewhere the shaders round them correctly with doubles
     * (shaders/rounding.glsl), so that the GPU's images equal the CPU backend's bit for bit. */
    vk->exact_rounding = vk->float64 && !llvmpipe;
    VkPhysicalDeviceFeatures enabled = { .shaderFloat64 = supported.shaderFloat64 };
    /* Buffer device addresses let a scene larger than maxStorageBufferRange be split into
     * pieces (lavapipe has them but not the non-uniform descriptor indexing an array of buffers
     * would need); scenes that fit one buffer never use them. */
    VkPhysicalDeviceVulkan12Features supported12 = { .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES };
    VkPhysicalDeviceFeatures2 features2 = { .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_FEATURES_2, .pNext = &supported12 };
    vkGetPhysicalDeviceFeatures2(vk->physical, &features2);
    vk->buffer_address = supported12.bufferDeviceAddress == VK_TRUE;
    VkPhysicalDeviceVulkan12Features enabled12 = { .sType = VK_STRUCTURE_TYPE_PHYSICAL_DEVICE_VULKAN_1_2_FEATURES,
                                                   .bufferDeviceAddress = supported12.bufferDeviceAddress };

    float priority = 1.0f;
    VkDeviceQueueCreateInfo queue = {
        .sType = VK_STRUCTURE_TYPE_DEVICE_QUEUE_CREATE_INFO,
        .queueFamilyIndex = vk->queue_family,
        .queueCount = 1,
        .pQueuePriorities = &priority,
    };
    VkDeviceCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_DEVICE_CREATE_INFO,
        .pNext = &enabled12,
        .queueCreateInfoCount = 1,
        .pQueueCreateInfos = &queue,
        .pEnabledFeatures = &enabled,
    };
    VkResult res = vkCreateDevice(vk->physical, &info, NULL, &vk->device);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateDevice");
    /* A driver may load more of itself for a device. */
    vkrt_result pinned = tls_pin_static_libraries(vk->core);
    if (pinned != VKRT_OK) return pinned;
    vkGetDeviceQueue(vk->device, vk->queue_family, 0, &vk->queue);

    VkCommandPoolCreateInfo pool = {
        .sType = VK_STRUCTURE_TYPE_COMMAND_POOL_CREATE_INFO,
        .flags = VK_COMMAND_POOL_CREATE_RESET_COMMAND_BUFFER_BIT,
        .queueFamilyIndex = vk->queue_family,
    };
    res = vkCreateCommandPool(vk->device, &pool, NULL, &vk->command_pool);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateCommandPool");
    return VKRT_OK;
}

/* The pipeline cache spares lavapipe's LLVM a recompile of every pipeline in every process.
 * A missing, unreadable or foreign cache file is not an error: the cache starts empty. */
static vkrt_result create_pipeline_cache(vk_context *vk, const char *path)
{
    void *data = NULL;
    size_t size = 0;
    if (path) {
        vk->pipeline_cache_path = core_strdup(vk->core, path);
        if (!vk->pipeline_cache_path) return core_fail(vk->core, VKRT_ERROR_OUT_OF_MEMORY, "out of memory");
        FILE *f = fopen(path, "rb");
        if (f) {
            if (fseek(f, 0, SEEK_END) == 0) {
                long n = ftell(f);
                if (n > 0 && n < (1L << 30) && fseek(f, 0, SEEK_SET) == 0) {
                    data = core_alloc(vk->core, (size_t)n);
                    if (data && fread(data, 1, (size_t)n, f) == (size_t)n) size = (size_t)n;
                }
            }
            fclose(f);
        }
    }
    VkPipelineCacheCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_PIPELINE_CACHE_CREATE_INFO,
        .initialDataSize = size,
        .pInitialData = size ? data : NULL,
    };
    VkResult res = vkCreatePipelineCache(vk->device, &info, NULL, &vk->pipeline_cache);
    if (res != VK_SUCCESS && size) {
        info.initialDataSize = 0; /* a corrupt cache file: start empty */
        info.pInitialData = NULL;
        res = vkCreatePipelineCache(vk->device, &info, NULL, &vk->pipeline_cache);
    }
    core_free(vk->core, data);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreatePipelineCache");
    return VKRT_OK;
}

/* Written to a temporary name and renamed, so concurrent processes never read half a file; the
 * name holds the process id (two processes may hold contexts at the same address). */
static void save_pipeline_cache(vk_context *vk)
{
    if (!vk->pipeline_cache || !vk->pipeline_cache_path) return;
    size_t size = 0;
    if (vkGetPipelineCacheData(vk->device, vk->pipeline_cache, &size, NULL) != VK_SUCCESS || size == 0) return;
    void *data = core_alloc(vk->core, size);
    if (!data) return;
    if (vkGetPipelineCacheData(vk->device, vk->pipeline_cache, &size, data) == VK_SUCCESS) {
        size_t n = strlen(vk->pipeline_cache_path) + 64;
        char *tmp = core_alloc(vk->core, n);
        if (tmp) {
            snprintf(tmp, n, "%s.tmp%ld.%p", vk->pipeline_cache_path, (long)getpid(), (void *)vk);
            FILE *f = fopen(tmp, "wb");
            if (f) {
                bool ok = fwrite(data, 1, size, f) == size;
                ok = (fclose(f) == 0) && ok;
                if (!ok || rename(tmp, vk->pipeline_cache_path) != 0) remove(tmp);
            }
            core_free(vk->core, tmp);
        }
    }
    core_free(vk->core, data);
}

vkrt_result vk_context_create(core *c, const vkrt_context_desc *desc, vk_context **out)
{
    *out = NULL;
    vk_context *vk = core_calloc_array(c, 1, sizeof *vk);
    if (!vk) return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory creating the Vulkan context");
    vk->core = c;
    vk->memory_budget = desc->device_memory_limit;
    vkrt_result r;
    if ((r = create_instance(vk, desc->validation)) != VKRT_OK) goto fail;
    if ((r = pick_device(vk, desc)) != VKRT_OK) goto fail;
    if ((r = create_device(vk)) != VKRT_OK) goto fail;
    if ((r = create_pipeline_cache(vk, desc->pipeline_cache_path)) != VKRT_OK) goto fail;
    *out = vk;
    return VKRT_OK;
fail:
    vk_context_destroy(vk);
    return r;
}

void vk_context_destroy(vk_context *vk)
{
    if (!vk) return;
    if (vk->device) {
        /* A lost device answers at once (VK_ERROR_DEVICE_LOST); a hung submission's objects can
         * only be freed once the device is idle. */
        vkDeviceWaitIdle(vk->device);
        if (vk->hung_fence) vkDestroyFence(vk->device, vk->hung_fence, NULL);
        if (vk->hung_commands) vkFreeCommandBuffers(vk->device, vk->command_pool, 1, &vk->hung_commands);
        vk_memory_recycled_release(vk);
        vk_pipelines_destroy(vk);
        save_pipeline_cache(vk);
        if (vk->pipeline_cache) vkDestroyPipelineCache(vk->device, vk->pipeline_cache, NULL);
        if (vk->command_pool) vkDestroyCommandPool(vk->device, vk->command_pool, NULL);
        vkDestroyDevice(vk->device, NULL);
    }
    if (vk->messenger) vk->destroy_messenger(vk->instance, vk->messenger, NULL);
    if (vk->instance) vkDestroyInstance(vk->instance, NULL);
    ray_bin_scratch_destroy(vk->core, vk->bin_scratch);
    core_free(vk->core, vk->pipeline_cache_path);
    core_free(vk->core, vk);
}

vkrt_result vk_devices_list(core *c, vkrt_device_info *out, uint32_t *inout_count)
{
    vk_context vk = { .core = c };
    vkrt_result r = create_instance(&vk, false);
    VkPhysicalDevice devices[MAX_DEVICES];
    uint32_t count = 0;
    if (r == VKRT_OK) r = enumerate(&vk, devices, &count);
    if (r == VKRT_OK) {
        if (!out) {
            *inout_count = count;
        } else {
            uint32_t n = count < *inout_count ? count : *inout_count;
            for (uint32_t i = 0; i < n; i++) {
                VkPhysicalDeviceProperties props;
                vkGetPhysicalDeviceProperties(devices[i], &props);
                vkrt_device_info *d = &out[i];
                memset(d, 0, sizeof *d);
                snprintf(d->name, sizeof d->name, "%s", props.deviceName);
                d->type = device_type(props.deviceType);
                d->vendor_id = props.vendorID;
                d->device_id = props.deviceID;
                d->api_version = props.apiVersion;
                d->max_storage_buffer_range = props.limits.maxStorageBufferRange;
                d->usable = device_usable(devices[i], &props);
            }
            *inout_count = n;
        }
    }
    if (vk.messenger) vk.destroy_messenger(vk.instance, vk.messenger, NULL);
    if (vk.instance) vkDestroyInstance(vk.instance, NULL);
    return r;
}
