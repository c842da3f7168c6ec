/* A scene's arrays on the device: the wide BVH and its triangles as texel buffers, the binary
 * BVH and the shading triangles as storage buffers (split into pieces reached through a piece
 * table where one buffer cannot hold them), and the surfaces, materials and textures the
 * shading modes read, each uploaded only once a call needs it. */
#ifndef VKRT_GPU_SCENE_H
#define VKRT_GPU_SCENE_H

#include "../shaders/vkrt_shared.h"
#include "bvh.h"
#include "vk_buffer.h"

/* One of a scene's large arrays on the device (nodes, triangles, surfaces): one storage buffer,
 * or, in a split scene, pieces of 2^split_shift elements each (the last one shorter), every
 * piece a buffer of its own that the shaders reach by its address in the piece table. */
typedef struct gpu_array {
    vk_buffer *pieces;         /* count of them (core allocator) */
    uint32_t count;
} gpu_array;

typedef struct gpu_scene {
    gpu_array nodes;           /* the binary BVH's nodes and */
    gpu_array tris;            /* the shading triangles (vkrt_gpu_tri): one-element
                                  placeholders until a call needs them (gpu_scene_upload_arrays),
                                  uploaded at once where the scene is traced without the wide
                                  arrays */
    gpu_array surfaces;        /* vkrt_gpu_surface per triangle, */
    vk_buffer materials;       /* the material table, */
    vk_buffer textures;        /* the texture table and */
    vk_buffer texels;          /* the texels: one-element placeholders until a render needs
                                  them (gpu_scene_upload_surfaces) */
    vk_buffer pieces;          /* the piece table (VKRT_PIECE_ARRAYS vkrt_gpu_address per piece);
                                  one zero entry when the scene is not split */
    uint32_t split_shift;      /* 0: one buffer per array; else log2 of the elements per piece
                                  (VKRT_SPEC_SPLIT of every pipeline that traces the scene) */
    bool surfaces_uploaded;
    bool nodes_uploaded, tris_uploaded;
    bool wide;                 /* the wide traversal's arrays are there (VKRT_SPEC_WIDE) */
    vk_texel_buffer wide_nodes; /* its nodes and */
    vk_texel_buffer trace_tris; /* triangles (one-texel placeholders without them) */
    double wide_pack_ms;       /* the host's collapse and packing of those arrays */
    uint32_t node_count;
    uint32_t tri_count;
    vkrt_gpu_node root;        /* the binary BVH's root, whose box gpu_trace_rays culls rays
                                  with (ray_cull.h); unused where node_count is 0 */
} gpu_scene;

/* Uploads the wide BVH and its triangles' corners as texel buffers where the wide traversal
 * can trace the scene (b->tri_count triangles, in BVH order), and the binary BVH's nodes and
 * the shading triangles only where it cannot: otherwise those wait for a call that reads them
 * (gpu_scene_upload_arrays). Where the triangles exceed what one buffer may hold (the device's
 * maxStorageBufferRange and maxMemoryAllocationSize, or the smaller vk->scene_buffer_limit),
 * every storage array of the scene is split into pieces; on a device without
 * bufferDeviceAddress that fails with VKRT_ERROR_LIMIT, naming the array and the limit. The
 * wide arrays are packed on the host on `threads` threads (the context's cpu_threads). */
vkrt_result gpu_scene_upload(vk_context *vk, const bvh *b, const vkrt_gpu_tri *tris, uint32_t threads, gpu_scene *out);
void gpu_scene_destroy(vk_context *vk, gpu_scene *s);

/* The binary arrays a call reads (gpu_trace_render_arrays, gpu_trace_rays_arrays). */
enum { GPU_ARRAY_NODES = 1u, GPU_ARRAY_TRIS = 2u };

/* Uploads those of `arrays` not yet on the device from the scene's host copies (the ones
 * gpu_scene_upload was given), replacing their placeholders; a no-op for those already there.
 * On failure the scene is as it was. */
vkrt_result gpu_scene_upload_arrays(vk_context *vk, gpu_scene *s, const bvh *b, const vkrt_gpu_tri *tris,
                                    uint32_t arrays);

/* What the scene holds on the device: the bytes of its memory allocations, and the storage
 * buffers of its binary nodes and shading triangles there (none until a call reads them; 2
 * once both are, more where the scene is split). */
void gpu_scene_usage(const gpu_scene *s, uint64_t *out_bytes, uint32_t *out_buffers);

/* The bytes of the arrays the scene's traversal reads (vkrt_scene_stats.traversal_bytes). */
uint64_t gpu_scene_traversal_bytes(const gpu_scene *s);

/* What gpu_scene_upload_surfaces uploads (counts of at least 1). */
typedef struct gpu_surface_data {
    const vkrt_gpu_surface *surfaces; /* surface_count of them, one per prim_id */
    uint32_t surface_count;           /* the mesh's triangles: fewer than the scene's tri_count
                                         where spatial splits copy triangles */
    const vkrt_gpu_material *materials;
    uint32_t material_count;
    const vkrt_gpu_texture *textures;
    uint32_t texture_count;
    const uint32_t *texels;           /* 2 words per texel */
    size_t texel_count;
} gpu_surface_data;

/* Uploads the surfaces, materials, textures and texels, replacing the placeholders; a no-op
 * once done. The modes that read them call this first, so scenes rendered only in the others
 * never hold them on the device. */
vkrt_result gpu_scene_upload_surfaces(vk_context *vk, gpu_scene *s, const gpu_surface_data *data);

#endif
