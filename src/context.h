/* The objects behind the public handles. */
#ifndef VKRT_CONTEXT_H
#define VKRT_CONTEXT_H

#include "bvh.h"
#include "bvh_wide.h"
#include "core.h"
#include "gpu_trace.h"
#include "vk_context.h"

struct vkrt_context {
    core core;
    vkrt_backend backend;      /* resolved: GPU or CPU */
    uint32_t cpu_threads;      /* resolved: >= 1 */
    vk_context *vk;            /* NULL for the CPU backend */
};

struct vkrt_scene {
    vkrt_context *ctx;
    bvh bvh;                   /* nodes and triangle order */
    bvh4 wide;                 /* CPU backend: bvh collapsed 4-wide, what float traces read */
    vkrt_gpu_tri *tris;        /* packed in BVH order; the CPU backend traces these */
    vkrt_gpu_surface *surfaces; /* per triangle by prim_id: texture coordinates, material */
    vkrt_gpu_material *materials;
    uint32_t material_count;
    vkrt_gpu_texture *textures;
    uint32_t texture_count;
    uint32_t *texels;          /* 2 words per texel, every texture's in turn */
    size_t texel_count;
    bool alpha_tested;         /* some material has alpha_cutoff > 0 */
    bool has_metals;           /* some material has metallic > 0: the lighting modes' GGX code */
    vkrt_light *lights;        /* the file's punctual lights, in traced coordinates */
    uint32_t light_count;
    float radius;              /* of the scene's bounding sphere */
    gpu_scene gpu;             /* device copies (GPU backend) */
    vkrt_scene_stats stats;
};

#endif
