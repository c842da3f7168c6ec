/* The trace pipeline: GLSL embedded in the library compiled to SPIR-V through glslang's C API
 * (once per context), one descriptor set layout and pipeline layout, and one compute pipeline
 * per specialisation (mode, traversal, heat, ray source, intersector, budget, counters, alpha,
 * any-hit, split, wide, finish), created on first use and kept. */
#ifndef VKRT_VK_PIPELINE_H
#define VKRT_VK_PIPELINE_H

#include <stddef.h>
#include <stdint.h>

#include "vk_context.h"

typedef struct vk_trace_variant {
    uint32_t mode;       /* VKRT_GPU_MODE_* */
    uint32_t traversal;  /* VKRT_GPU_TRAVERSAL_* */
    uint32_t heat;       /* VKRT_GPU_HEAT_* */
    uint32_t raygen;     /* VKRT_GPU_RAYGEN_* */
    uint32_t isect;      /* VKRT_GPU_ISECT_* */
    uint32_t budget;     /* BVH loop iterations per dispatch, 0: unlimited (VKRT_SPEC_BUDGET) */
    uint32_t counters;   /* 1: write each pixel's traversal counts (VKRT_SPEC_COUNTERS) */
    uint32_t alpha;      /* 1: alpha-test hits (VKRT_SPEC_ALPHA) */
    uint32_t anyhit;     /* 1: stop at the first hit (VKRT_SPEC_ANYHIT) */
    uint32_t textures;   /* 1: the scene has textures (VKRT_SPEC_TEXTURES) */
    uint32_t split;      /* the scene's gpu_scene.split_shift (VKRT_SPEC_SPLIT) */
    uint32_t wide;       /* 1: the wide BVH through texel buffers (VKRT_SPEC_WIDE) */
    uint32_t finish;     /* 1: a wide ray trace's finish pass (VKRT_SPEC_FINISH) */
} vk_trace_variant;

typedef struct vk_trace_pipeline {
    VkDescriptorSetLayout set_layout;
    VkPipelineLayout layout;
    VkPipeline pipeline;
    VkPipeline finish;   /* a wide ray trace's finish pass, to dispatch after it; else NULL */
} vk_trace_pipeline;

/* Returns the pipeline for a variant (and for a wide ray trace its finish pass's), compiling
 * the shader and creating the layouts the first time. A shader that fails to compile is
 * VKRT_ERROR_VULKAN with glslang's log as detail. */
vkrt_result vk_trace_pipeline_get(vk_context *vk, vk_trace_variant variant, vk_trace_pipeline *out);

/* A pipeline of shade.comp (the lighting modes' stages). */
typedef struct vk_shade_variant {
    uint32_t stage;      /* VKRT_STAGE_* */
    uint32_t mode;       /* VKRT_GPU_MODE_SHADED, _AO or _PATH */
    uint32_t features;   /* VKRT_GPU_FEATURE_* */
    uint32_t split;      /* the scene's gpu_scene.split_shift (VKRT_SPEC_SHADE_SPLIT) */
} vk_shade_variant;

/* As vk_trace_pipeline_get, for shade.comp (its own module, set layout and pipeline layout). */
vkrt_result vk_shade_pipeline_get(vk_context *vk, vk_shade_variant variant, vk_trace_pipeline *out);

/* A descriptor pool holding exactly one set of `layout` with the given pool sizes, and that set.
 * On failure the caller still destroys *out_pool (VK_NULL_HANDLE where it was not made). */
vkrt_result vk_descriptor_set_create(vk_context *vk, VkDescriptorSetLayout layout, const VkDescriptorPoolSize *sizes,
                                     uint32_t size_count, VkDescriptorPool *out_pool, VkDescriptorSet *out_set);

/* `source` as it is compiled for this device: the defines of its features after the #version
 * line (VKRT_HAS_FLOAT64, VKRT_HAS_BUFFER_ADDRESS, VKRT_EXACT_ROUNDING). Freed with core_free;
 * NULL when out of memory. */
char *vk_shader_source(vk_context *vk, const char *source);
/* GLSL -> SPIR-V for a compute shader. On success *out_words is allocated with the core
 * allocator (the caller frees it) and *out_count holds its 32-bit words. */
vkrt_result vk_compile_glsl(core *c, const char *name, const char *source, uint32_t **out_words, size_t *out_count);

void vk_pipelines_destroy(vk_context *vk);

#endif
