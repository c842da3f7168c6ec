#include "vk_pipeline.h"

#include <glslang/Include/glslang_c_interface.h>
#include <glslang/Public/resource_limits_c.h>
#include <stdio.h>
#include <string.h>

#include "../shaders/vkrt_shared.h"
#include "shaders_embedded.h"

/* Images: (5 modes + 3 heat kinds) x 2 traversals x 2 intersectors x counters on or off x
 * alpha test on or off; rays: 2 x 2 x 2 more, each with any-hit on or off, and the wavefront's. */
#define MAX_VARIANTS 256
/* Stages x modes x the feature combinations one context meets in practice. */
#define MAX_SHADE_VARIANTS 256

typedef struct vk_pipelines {
    VkShaderModule trace_module;
    VkDescriptorSetLayout set_layout;
    VkPipelineLayout layout;
    uint32_t count;
    vk_trace_variant variants[MAX_VARIANTS];
    VkPipeline pipelines[MAX_VARIANTS];
    VkShaderModule shade_module;       /* compiled on the first lighting render */
    VkDescriptorSetLayout shade_set_layout;
    VkPipelineLayout shade_layout;
    uint32_t shade_count;
    vk_shade_variant shade_variants[MAX_SHADE_VARIANTS];
    VkPipeline shade_pipelines[MAX_SHADE_VARIANTS];
} vk_pipelines;

vkrt_result vk_compile_glsl(core *c, const char *name, const char *source, uint32_t **out_words, size_t *out_count)
{
    *out_words = NULL;
    *out_count = 0;
    const glslang_input_t input = {
        .language = GLSLANG_SOURCE_GLSL,
        .stage = GLSLANG_STAGE_COMPUTE,
        .client = GLSLANG_CLIENT_VULKAN,
        .client_version = GLSLANG_TARGET_VULKAN_1_2,
        .target_language = GLSLANG_TARGET_SPV,
        .target_language_version = GLSLANG_TARGET_SPV_1_5,
        .code = source,
        .default_version = 460,
        .default_profile = GLSLANG_NO_PROFILE,
        .messages = GLSLANG_MSG_DEFAULT_BIT | GLSLANG_MSG_SPV_RULES_BIT | GLSLANG_MSG_VULKAN_RULES_BIT,
        .resource = glslang_default_resource(),
    };
    /* glslang counts process initialisations, so paired calls are safe from several contexts. */
    glslang_initialize_process();
    vkrt_result r = VKRT_OK;
    glslang_program_t *program = NULL;
    glslang_shader_t *shader = glslang_shader_create(&input);
    if (!shader) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "glslang could not create shader %s", name);
        goto done;
    }
    if (!glslang_shader_preprocess(shader, &input) || !glslang_shader_parse(shader, &input)) {
        r = core_fail(c, VKRT_ERROR_VULKAN, "shader %s does not compile: %s", name, glslang_shader_get_info_log(shader));
        goto done;
    }
    program = glslang_program_create();
    glslang_program_add_shader(program, shader);
    if (!glslang_program_link(program, GLSLANG_MSG_SPV_RULES_BIT | GLSLANG_MSG_VULKAN_RULES_BIT)) {
        r = core_fail(c, VKRT_ERROR_VULKAN, "shader %s does not link: %s", name, glslang_program_get_info_log(program));
        goto done;
    }
    glslang_spv_options_t options = { .disable_optimizer = false, .validate = true };
    glslang_program_SPIRV_generate_with_options(program, GLSLANG_STAGE_COMPUTE, &options);
    const char *messages = glslang_program_SPIRV_get_messages(program);
    if (messages && messages[0]) core_log(c, VKRT_LOG_DEBUG, "shader %s: %s", name, messages);
    size_t count = glslang_program_SPIRV_get_size(program);
    uint32_t *words = core_alloc_array(c, count, sizeof *words);
    if (!words) {
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for the SPIR-V of %s", name);
        goto done;
    }
    glslang_program_SPIRV_get(program, words);
    *out_words = words;
    *out_count = count;
done:
    if (program) glslang_program_delete(program);
    if (shader) glslang_shader_delete(shader);
    glslang_finalize_process();
    return r;
}

/* A set of bindings 0 .. count - 1: the storage image at image_binding, storage texel buffers
 * from texel_first on, storage buffers the rest (UINT32_MAX: none of that kind); and a
 * pipeline layout with the push constants. */
static vkrt_result create_layout_pair(vk_context *vk, uint32_t count, uint32_t image_binding, uint32_t texel_first,
                                      VkDescriptorSetLayout *out_set, VkPipelineLayout *out_layout)
{
    VkDescriptorSetLayoutBinding bindings[VKRT_BINDING_COUNT > VKRT_SHADE_BINDING_COUNT ? VKRT_BINDING_COUNT
                                                                                         : VKRT_SHADE_BINDING_COUNT];
    for (uint32_t i = 0; i < count; i++)
        bindings[i] = (VkDescriptorSetLayoutBinding){ i,
                                                      i == image_binding  ? VK_DESCRIPTOR_TYPE_STORAGE_IMAGE
                                                      : i >= texel_first  ? VK_DESCRIPTOR_TYPE_STORAGE_TEXEL_BUFFER
                                                                          : VK_DESCRIPTOR_TYPE_STORAGE_BUFFER,
                                                      1, VK_SHADER_STAGE_COMPUTE_BIT, NULL };
    VkDescriptorSetLayoutCreateInfo set_info = {
        .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_LAYOUT_CREATE_INFO,
        .bindingCount = count,
        .pBindings = bindings,
    };
    VkResult res = vkCreateDescriptorSetLayout(vk->device, &set_info, NULL, out_set);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateDescriptorSetLayout");
    VkPushConstantRange push = { .stageFlags = VK_SHADER_STAGE_COMPUTE_BIT, .size = sizeof(vkrt_gpu_push) };
    VkPipelineLayoutCreateInfo layout_info = {
        .sType = VK_STRUCTURE_TYPE_PIPELINE_LAYOUT_CREATE_INFO,
        .setLayoutCount = 1,
        .pSetLayouts = out_set,
        .pushConstantRangeCount = 1,
        .pPushConstantRanges = &push,
    };
    res = vkCreatePipelineLayout(vk->device, &layout_info, NULL, out_layout);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreatePipelineLayout");
    return VKRT_OK;
}

static vkrt_result create_layouts(vk_context *vk, vk_pipelines *p)
{
    return create_layout_pair(vk, VKRT_BINDING_COUNT, VKRT_BINDING_IMAGE, VKRT_BINDING_TEXEL_FIRST, &p->set_layout,
                              &p->layout);
}

/* A shader with "#define VKRT_HAS_FLOAT64" and "#define VKRT_HAS_BUFFER_ADDRESS" after its
 * #version line where the device has doubles and buffer device addresses: the Float64 and
 * PhysicalStorageBufferAddresses capabilities may only appear in a module for a device that
 * enabled them, and a specialization constant cannot remove a capability. And with
 * "#define VKRT_EXACT_ROUNDING" where the device's own division and square root may round
 * otherwise than C's (shaders/rounding.glsl). VKRT_NAIVE_SHARE is always defined (a GLSL #if
 * may not name an undefined macro); above 1 the module uses subgroup operations, which the
 * device then has (vk_naive_share). NULL when out of memory. */
char *vk_shader_source(vk_context *vk, const char *source)
{
    char share[48];
    snprintf(share, sizeof share, "#define VKRT_NAIVE_SHARE %u\n", (unsigned)vk->naive_share);
    const char *const defines[] = {
        vk->float64 ? "#define VKRT_HAS_FLOAT64 1\n" : "",
        vk->buffer_address ? "#define VKRT_HAS_BUFFER_ADDRESS 1\n" : "",
        vk->exact_rounding ? "#define VKRT_EXACT_ROUNDING 1\n" : "",
        share,
    };
    const char *version = strstr(source, "#version");
    const char *after = version ? strchr(version, '\n') : NULL;
    size_t head = after ? (size_t)(after + 1 - source) : 0;
    size_t extra = 0;
    for (size_t i = 0; head && i < sizeof defines / sizeof defines[0]; i++) extra += strlen(defines[i]);
    size_t length = strlen(source);
    char *text = core_alloc_array(vk->core, length + extra + 1, 1);
    if (!text) return NULL;
    memcpy(text, source, head);
    size_t at = head;
    for (size_t i = 0; head && i < sizeof defines / sizeof defines[0]; i++) {
        memcpy(text + at, defines[i], strlen(defines[i]));
        at += strlen(defines[i]);
    }
    memcpy(text + at, source + head, length - head + 1);
    return text;
}

/* GLSL (the device's flavour, vk_shader_source) -> SPIR-V words, allocated with the core allocator. */
static vkrt_result compile_shader(vk_context *vk, const char *name, const char *text, uint32_t **out_words, size_t *out_count)
{
    char *source = vk_shader_source(vk, text);
    if (!source) return core_fail(vk->core, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for the source of %s", name);
    vkrt_result r = vk_compile_glsl(vk->core, name, source, out_words, out_count);
    core_free(vk->core, source);
    return r;
}

/* A shader module from SPIR-V words; the words are freed either way. */
static vkrt_result module_from_words(vk_context *vk, uint32_t *words, size_t count, VkShaderModule *out)
{
    VkShaderModuleCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_SHADER_MODULE_CREATE_INFO,
        .codeSize = count * sizeof *words,
        .pCode = words,
    };
    VkResult res = vkCreateShaderModule(vk->device, &info, NULL, out);
    core_free(vk->core, words);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateShaderModule");
    return VKRT_OK;
}

static vkrt_result create_module(vk_context *vk, const char *name, const char *text, VkShaderModule *out)
{
    uint32_t *words;
    size_t count;
    vkrt_result r = compile_shader(vk, name, text, &words, &count);
    if (r != VKRT_OK) return r;
    return module_from_words(vk, words, count, out);
}

static vkrt_result ensure_base(vk_context *vk)
{
    if (vk->pipelines) return VKRT_OK;
    vk_pipelines *p = core_calloc_array(vk->core, 1, sizeof *p);
    if (!p) return core_fail(vk->core, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for pipelines");
    vk->pipelines = p;
    vkrt_result r = create_layouts(vk, p);
    if (r == VKRT_OK) r = create_module(vk, "trace.comp", vkrt_shader_trace_comp, &p->trace_module);
    if (r != VKRT_OK) vk_pipelines_destroy(vk);
    return r;
}

/* A compute pipeline of `module` with the specialization constants `entries` read from `data`,
 * through the context's pipeline cache. */
static vkrt_result create_pipeline(vk_context *vk, VkShaderModule module, VkPipelineLayout layout,
                                   const VkSpecializationMapEntry *entries, uint32_t entry_count, const void *data,
                                   size_t size, const char *label, VkPipeline *out)
{
    VkSpecializationInfo spec = {
        .mapEntryCount = entry_count,
        .pMapEntries = entries,
        .dataSize = size,
        .pData = data,
    };
    VkComputePipelineCreateInfo info = {
        .sType = VK_STRUCTURE_TYPE_COMPUTE_PIPELINE_CREATE_INFO,
        .stage = {
            .sType = VK_STRUCTURE_TYPE_PIPELINE_SHADER_STAGE_CREATE_INFO,
            .stage = VK_SHADER_STAGE_COMPUTE_BIT,
            .module = module,
            .pName = "main",
            .pSpecializationInfo = &spec,
        },
        .layout = layout,
    };
    VkResult res = vkCreateComputePipelines(vk->device, vk->pipeline_cache, 1, &info, NULL, out);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateComputePipelines");
    vk_label(vk, VK_OBJECT_TYPE_PIPELINE, (uint64_t)*out, label);
    return VKRT_OK;
}

/* The pipeline of one variant, found among those made or made now. */
static vkrt_result variant_pipeline(vk_context *vk, vk_trace_variant variant, VkPipeline *out)
{
    vk_pipelines *p = vk->pipelines;
    for (uint32_t i = 0; i < p->count; i++) {
        if (memcmp(&p->variants[i], &variant, sizeof variant) == 0) {
            *out = p->pipelines[i];
            return VKRT_OK;
        }
    }
    if (p->count == MAX_VARIANTS) return core_fail(vk->core, VKRT_ERROR_LIMIT, "too many pipeline variants");

    const VkSpecializationMapEntry entries[] = {
        { VKRT_SPEC_MODE, offsetof(vk_trace_variant, mode), sizeof(uint32_t) },
        { VKRT_SPEC_TRAVERSAL, offsetof(vk_trace_variant, traversal), sizeof(uint32_t) },
        { VKRT_SPEC_HEAT, offsetof(vk_trace_variant, heat), sizeof(uint32_t) },
        { VKRT_SPEC_RAYGEN, offsetof(vk_trace_variant, raygen), sizeof(uint32_t) },
        { VKRT_SPEC_ISECT, offsetof(vk_trace_variant, isect), sizeof(uint32_t) },
        { VKRT_SPEC_BUDGET, offsetof(vk_trace_variant, budget), sizeof(uint32_t) },
        { VKRT_SPEC_COUNTERS, offsetof(vk_trace_variant, counters), sizeof(uint32_t) },
        { VKRT_SPEC_ALPHA, offsetof(vk_trace_variant, alpha), sizeof(uint32_t) },
        { VKRT_SPEC_ANYHIT, offsetof(vk_trace_variant, anyhit), sizeof(uint32_t) },
        { VKRT_SPEC_TEXTURES, offsetof(vk_trace_variant, textures), sizeof(uint32_t) },
        { VKRT_SPEC_SPLIT, offsetof(vk_trace_variant, split), sizeof(uint32_t) },
        { VKRT_SPEC_WIDE, offsetof(vk_trace_variant, wide), sizeof(uint32_t) },
        { VKRT_SPEC_FINISH, offsetof(vk_trace_variant, finish), sizeof(uint32_t) },
    };
    VkPipeline pipeline;
    vkrt_result r = create_pipeline(vk, p->trace_module, p->layout, entries, sizeof entries / sizeof entries[0],
                                    &variant, sizeof variant, variant.finish ? "vkrt trace finish" : "vkrt trace",
                                    &pipeline);
    if (r != VKRT_OK) return r;
    p->variants[p->count] = variant;
    p->pipelines[p->count++] = pipeline;
    *out = pipeline;
    return VKRT_OK;
}

vkrt_result vk_trace_pipeline_get(vk_context *vk, vk_trace_variant variant, vk_trace_pipeline *out)
{
    vkrt_result r = ensure_base(vk);
    if (r != VKRT_OK) return r;
    vk_pipelines *p = vk->pipelines;
    out->set_layout = p->set_layout;
    out->layout = p->layout;
    out->finish = VK_NULL_HANDLE;
    if ((r = variant_pipeline(vk, variant, &out->pipeline)) != VKRT_OK) return r;
    /* The binned traversal writes its hits whole (trace_buffer_ray_binned). */
    if (!variant.wide || variant.raygen == VKRT_GPU_RAYGEN_CAMERA || variant.finish ||
        variant.traversal == VKRT_GPU_TRAVERSAL_BINNED)
        return VKRT_OK;
    /* The finish tests one recorded triangle a ray: the budget and the any-hit rule do not
     * apply, so the trace variants that differ only there share it. */
    vk_trace_variant finish = variant;
    finish.finish = 1;
    finish.budget = 0;
    finish.anyhit = 0;
    return variant_pipeline(vk, finish, &out->finish);
}

vkrt_result vk_shade_pipeline_get(vk_context *vk, vk_shade_variant variant, vk_trace_pipeline *out)
{
    /* shade.comp is compiled before the shared state is made, so a host allocation that fails
     * leaves nothing behind: after ensure_base only Vulkan objects are created. */
    uint32_t *words = NULL;
    size_t count = 0;
    vkrt_result r = VKRT_OK;
    if (!vk->pipelines || !vk->pipelines->shade_module)
        if ((r = compile_shader(vk, "shade.comp", vkrt_shader_shade_comp, &words, &count)) != VKRT_OK) return r;
    if ((r = ensure_base(vk)) != VKRT_OK) {
        core_free(vk->core, words);
        return r;
    }
    vk_pipelines *p = vk->pipelines;
    if (!p->shade_module) {
        if (!p->shade_layout &&
            (r = create_layout_pair(vk, VKRT_SHADE_BINDING_COUNT, UINT32_MAX, UINT32_MAX, &p->shade_set_layout,
                                    &p->shade_layout)) != VKRT_OK) {
            core_free(vk->core, words);
            return r;
        }
        if ((r = module_from_words(vk, words, count, &p->shade_module)) != VKRT_OK) return r;
    }
    out->set_layout = p->shade_set_layout;
    out->layout = p->shade_layout;
    for (uint32_t i = 0; i < p->shade_count; i++) {
        if (memcmp(&p->shade_variants[i], &variant, sizeof variant) == 0) {
            out->pipeline = p->shade_pipelines[i];
            return VKRT_OK;
        }
    }
    if (p->shade_count == MAX_SHADE_VARIANTS) return core_fail(vk->core, VKRT_ERROR_LIMIT, "too many shade pipeline variants");
    const VkSpecializationMapEntry entries[] = {
        { VKRT_SPEC_SHADE_STAGE, offsetof(vk_shade_variant, stage), sizeof(uint32_t) },
        { VKRT_SPEC_SHADE_MODE, offsetof(vk_shade_variant, mode), sizeof(uint32_t) },
        { VKRT_SPEC_SHADE_FEATURES, offsetof(vk_shade_variant, features), sizeof(uint32_t) },
        { VKRT_SPEC_SHADE_SPLIT, offsetof(vk_shade_variant, split), sizeof(uint32_t) },
    };
    VkPipeline pipeline;
    r = create_pipeline(vk, p->shade_module, p->shade_layout, entries, sizeof entries / sizeof entries[0], &variant,
                        sizeof variant, "vkrt shade", &pipeline);
    if (r != VKRT_OK) return r;
    p->shade_variants[p->shade_count] = variant;
    p->shade_pipelines[p->shade_count++] = pipeline;
    out->pipeline = pipeline;
    return VKRT_OK;
}

vkrt_result vk_descriptor_set_create(vk_context *vk, VkDescriptorSetLayout layout, const VkDescriptorPoolSize *sizes,
                                     uint32_t size_count, VkDescriptorPool *out_pool, VkDescriptorSet *out_set)
{
    VkDescriptorPoolCreateInfo pool_info = {
        .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_POOL_CREATE_INFO,
        .maxSets = 1,
        .poolSizeCount = size_count,
        .pPoolSizes = sizes,
    };
    VkResult res = vkCreateDescriptorPool(vk->device, &pool_info, NULL, out_pool);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkCreateDescriptorPool");
    VkDescriptorSetAllocateInfo alloc = {
        .sType = VK_STRUCTURE_TYPE_DESCRIPTOR_SET_ALLOCATE_INFO,
        .descriptorPool = *out_pool,
        .descriptorSetCount = 1,
        .pSetLayouts = &layout,
    };
    res = vkAllocateDescriptorSets(vk->device, &alloc, out_set);
    if (res != VK_SUCCESS) return vk_fail(vk, res, "vkAllocateDescriptorSets");
    return VKRT_OK;
}

void vk_pipelines_destroy(vk_context *vk)
{
    vk_pipelines *p = vk->pipelines;
    if (!p) return;
    for (uint32_t i = 0; i < p->count; i++) vkDestroyPipeline(vk->device, p->pipelines[i], NULL);
    for (uint32_t i = 0; i < p->shade_count; i++) vkDestroyPipeline(vk->device, p->shade_pipelines[i], NULL);
    if (p->shade_module) vkDestroyShaderModule(vk->device, p->shade_module, NULL);
    if (p->shade_layout) vkDestroyPipelineLayout(vk->device, p->shade_layout, NULL);
    if (p->shade_set_layout) vkDestroyDescriptorSetLayout(vk->device, p->shade_set_layout, NULL);
    if (p->trace_module) vkDestroyShaderModule(vk->device, p->trace_module, NULL);
    if (p->layout) vkDestroyPipelineLayout(vk->device, p->layout, NULL);
    if (p->set_layout) vkDestroyDescriptorSetLayout(vk->device, p->set_layout, NULL);
    core_free(vk->core, p);
    vk->pipelines = NULL;
}
