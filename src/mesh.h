/* A triangle soup in load order: what every loader produces and every BVH builder consumes.
 *
 * Triangle i is the i-th triangle of the file after triangulation (faces fanned from their
 * first corner, glTF primitives in mesh order, meshes instanced once per node of the default
 * scene, in depth-first node order). `id` mode reports this index. */
#ifndef VKRT_MESH_H
#define VKRT_MESH_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "../shaders/vkrt_shared.h"
#include "core.h"
#include "texture.h"
#include "vkrt.h"

/* mesh_primitive.material for the material mesh_add_material numbered `index`; 0 (a zeroed
 * primitive) is the default material (vkrt_material_default), added to the table on first use. */
#define MESH_MATERIAL(index) ((index) + 1u)

/* A texture of the mesh's materials, its texels encoded (texture_encode_rgba8). */
typedef struct mesh_texture {
    uint32_t width, height;
    uint32_t wrap;    /* wrap_u | wrap_v << 8 (VKRT_GPU_WRAP_*) */
    uint32_t *texels; /* 2 words per texel */
} mesh_texture;

typedef struct mesh {
    uint32_t tri_count;
    size_t tri_capacity;
    float *positions;        /* 9 floats per triangle: corners v0, v1, v2 */
    float *normals;          /* 9 floats per triangle: unit vertex normal at each corner */
    float *texcoords;        /* 6 floats per triangle: (u, v) at each corner, (0, 0) without */
    uint32_t *material_ids;  /* per triangle: index into materials */
    float bounds_min[3];     /* of all corners; valid when tri_count > 0 */
    float bounds_max[3];
    bool has_texcoords;      /* some primitive brought texture coordinates */
    vkrt_material *materials;
    uint32_t material_count;
    uint32_t material_capacity;
    bool has_default_material; /* the default material is in the table, at default_material */
    uint32_t default_material;
    uint32_t *material_textures; /* per material: its base colour texture, or VKRT_NO_TEXTURE */
    uint32_t *material_metallic_roughness_textures; /* per material, likewise (linear data) */
    uint32_t *material_emissive_textures;           /* per material, likewise */
    mesh_texture *textures;
    uint32_t texture_count;
    uint32_t texture_capacity;
    vkrt_light *lights;      /* the file's punctual lights (glTF KHR_lights_punctual), in the
                                mesh's coordinates: mesh_normalize moves them with the geometry */
    uint32_t light_count;
    uint32_t light_capacity;
} mesh;

/* One indexed primitive handed to mesh_append_indexed(). */
typedef struct mesh_primitive {
    const float *positions;  /* 3 floats per vertex */
    size_t vertex_count;
    const uint32_t *indices; /* 3 per triangle; NULL: vertices taken in order (non-indexed) */
    size_t index_count;      /* multiple of 3 (ignored when indices is NULL) */
    const float *normals;    /* 3 floats per vertex, or NULL: computed, angle-weighted */
    const float *transform;  /* column-major 4x4 applied to positions (normals by its inverse
                                transpose), or NULL for identity */
    const float *texcoords;  /* 2 floats per vertex, or NULL: (0, 0) */
    uint32_t material;       /* MESH_MATERIAL(index from mesh_add_material); 0: the default */
} mesh_primitive;

/* The textures of one material: each an index from mesh_add_texture, or VKRT_NO_TEXTURE. Start
 * from MESH_NO_TEXTURES: a zeroed struct names texture 0 three times. */
typedef struct mesh_material_textures {
    uint32_t base_color;         /* sRGB colour, linear alpha (TEXTURE_SRGB) */
    uint32_t metallic_roughness; /* roughness in G, metallic in B (TEXTURE_LINEAR) */
    uint32_t emissive;           /* sRGB colour (TEXTURE_SRGB) */
} mesh_material_textures;
#define MESH_NO_TEXTURES ((mesh_material_textures){ VKRT_NO_TEXTURE, VKRT_NO_TEXTURE, VKRT_NO_TEXTURE })

/* Adds a material to the table, with its textures (NULL: none; the texture pointers of material
 * are not read), and returns its index in *out_index. A non-finite factor, or one outside its
 * range (vkrt_material), or a texture index past the table fails with `invalid` (the caller's
 * code: a file's or an argument's fault) and a message naming `source` and `what`. */
vkrt_result mesh_add_material(core *c, mesh *m, const vkrt_material *material, const mesh_material_textures *textures,
                              vkrt_result invalid, const char *source, const char *what, uint32_t *out_index);

/* Adds a texture (its texels encoded from desc->rgba8 as `encoding` says) and returns its index
 * in *out_index. A side of 0 or over TEXTURE_MAX_SIDE, no pixels or an unknown wrap mode fails
 * with `invalid`. */
vkrt_result mesh_add_texture(core *c, mesh *m, const vkrt_texture_desc *desc, texture_encoding encoding,
                             vkrt_result invalid, const char *source, const char *what, uint32_t *out_index);

/* Decodes an image (PNG, JPEG, TGA or BMP, through stb_image) and adds it as a texture.
 * An image that cannot be decoded is a warning naming `name` (with `source` and `what`) and
 * *out_index = VKRT_NO_TEXTURE: only running out of memory fails. */
vkrt_result mesh_add_texture_image(core *c, mesh *m, const void *bytes, size_t size, vkrt_wrap wrap_u, vkrt_wrap wrap_v,
                                   texture_encoding encoding, const char *name, const char *source, const char *what,
                                   uint32_t *out_index);
/* The same for the image file at path; a missing or unreadable file is a warning too. */
vkrt_result mesh_add_texture_file(core *c, mesh *m, const char *path, vkrt_wrap wrap_u, vkrt_wrap wrap_v,
                                  texture_encoding encoding, const char *source, const char *what,
                                  uint32_t *out_index);

/* Appends a light to m->lights. A type other than directional or point, a non-finite vector or
 * colour, a negative colour or a directional light of zero direction fails with `invalid` and a
 * message naming `source` and `what`. */
vkrt_result mesh_add_light(core *c, mesh *m, const vkrt_light *light, vkrt_result invalid, const char *source,
                           const char *what);

/* Appends a primitive's triangles. Checks every coordinate (and texture coordinate) is
 * finite, the material exists, and every index is below vertex_count; `source` (the file name) and `what` (e.g. "mesh 2 primitive 0") name the
 * culprit in the failure message: VKRT_ERROR_INVALID_GEOMETRY or VKRT_ERROR_OUT_OF_MEMORY. */
vkrt_result mesh_append_indexed(core *c, mesh *m, const mesh_primitive *primitive,
                                const char *source, const char *what);

/* Loads .obj (tinyobjloader), .gltf or .glb (cgltf), chosen by content and extension. On
 * failure *m is left empty and the message names `path` and the problem. A file that parses
 * but holds no triangles is VKRT_ERROR_EMPTY_SCENE. */
vkrt_result mesh_load(core *c, const char *path, mesh *m);
vkrt_result mesh_load_obj(core *c, const char *path, mesh *m);
vkrt_result mesh_load_gltf(core *c, const char *path, mesh *m);

/* The built-in scene: a subdivided icosphere, a torus and a box on a ground plane. */
vkrt_result mesh_make_builtin(core *c, mesh *m);

/* The last step of every mesh producer (loaders, built-in scene), so all leave a mesh the same
 * way: with r == VKRT_OK the bounds are computed; otherwise the partly filled mesh is emptied,
 * so no caller ever sees part of a file. Returns r. */
vkrt_result mesh_finish(core *c, mesh *m, vkrt_result r);

/* Recomputes bounds_min/max from the corners. */
void mesh_update_bounds(mesh *m);
/* Moves the bounding-box centre to the origin and scales the largest extent to 1, so the
 * scene fits [-0.5, 0.5]^3. A scene of zero extent is only centred. Point lights move with the
 * geometry and their intensities scale by the square of the scale, so the irradiance they give
 * the surfaces stays the same; directional lights stay as they are. An extent beyond the float
 * range (coordinates of 3e38 and -3e38), or a light that would leave the float range, is
 * VKRT_ERROR_INVALID_GEOMETRY with a message naming `source` (the file), and the mesh is left
 * as it was. */
vkrt_result mesh_normalize(core *c, mesh *m, const char *source);

void mesh_destroy(core *c, mesh *m);

#endif
