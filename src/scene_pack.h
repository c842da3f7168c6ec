/* Packs a mesh into the triangle array the tracers read (vkrt_gpu_tri, in BVH order), and
 * the octahedral normal encoding it uses. The CPU tracer reads the same array as the GPU, so
 * both backends start from identical bits. */
#ifndef VKRT_SCENE_PACK_H
#define VKRT_SCENE_PACK_H

#include "../shaders/vkrt_shared.h"
#include "bvh.h"
#include "core.h"
#include "mesh.h"

/* tris must hold m->tri_count entries. */
void scene_pack_triangles(const mesh *m, const bvh *b, vkrt_gpu_tri *tris);

/* Texels in all of m's textures. */
size_t scene_texel_count(const mesh *m);

/* surfaces (m->tri_count, in load order: index = prim_id), materials (m->material_count),
 * textures (m->texture_count) and their texels, one after another (scene_texel_count, 2 words
 * each). */
void scene_pack_surfaces(const mesh *m, vkrt_gpu_surface *surfaces, vkrt_gpu_material *materials,
                         vkrt_gpu_texture *textures, uint32_t *texels);

/* Unit vector -> two 16-bit snorm values (x in the low half); decode is the exact inverse
 * used by the shader (normal_decode in shaders/trace_common.glsl). */
uint32_t normal_encode_oct(const float n[3]);
void normal_decode_oct(uint32_t packed, float n[3]);

#endif
