/* A C view of tinyobjloader's callback parser (tiny_obj_loader.h is C++). The parser calls
 * back once per statement in file order; nothing is kept, and no C++ exception leaves
 * tinyobj_shim_parse(). `mtllib` files are read by tinyobjloader's own .mtl parser from the
 * directory given to tinyobj_shim_parse (a missing one only warns). */
#ifndef TINYOBJ_SHIM_H
#define TINYOBJ_SHIM_H

#include <stdbool.h>
#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* One corner of an `f` statement as written: 1-based, negative = relative to the end of
 * the list so far, 0 = absent (or not a number). */
typedef struct tinyobj_shim_corner {
    int v, vt, vn;
} tinyobj_shim_corner;

/* One material of an .mtl file (the fields vkrt uses; tinyobjloader's defaults where absent). */
typedef struct tinyobj_shim_material {
    const char *name;
    float diffuse[3];             /* Kd */
    float specular[3];            /* Ks */
    float emission[3];            /* Ke */
    float shininess;              /* Ns */
    float dissolve;               /* d (1 - Tr): 1 opaque */
    float metallic;               /* Pm (the PBR extension), 0 where absent */
    float roughness;              /* Pr (the PBR extension), valid with has_roughness */
    bool has_roughness;           /* the material states Pr (0, a mirror, is also the default) */
    const char *diffuse_texture;  /* map_Kd, relative to the .obj's directory; "" for none */
    const char *emissive_texture; /* map_Ke, likewise */
} tinyobj_shim_material;

typedef struct tinyobj_shim_callbacks {
    void *user;
    void (*vertex)(void *user, float x, float y, float z);          /* `v`  */
    void (*normal)(void *user, float x, float y, float z);          /* `vn` */
    void (*texcoord)(void *user, float u, float v);                 /* `vt` */
    void (*face)(void *user, const tinyobj_shim_corner *corners, size_t count); /* `f`, count >= 1 */
    void (*group)(void *user);                                      /* `o` or `g` */
    /* `mtllib`: every material read so far, in order (pointers valid during the call). */
    void (*materials)(void *user, const tinyobj_shim_material *materials, size_t count);
    void (*use_material)(void *user, int index);                    /* `usemtl`; -1: unknown name */
} tinyobj_shim_callbacks;

typedef enum tinyobj_shim_status {
    TINYOBJ_SHIM_OK = 0,
    TINYOBJ_SHIM_PARSE_ERROR,   /* tinyobjloader rejected the text; message says why */
    TINYOBJ_SHIM_OUT_OF_MEMORY,
    TINYOBJ_SHIM_INTERNAL_ERROR /* any other exception; message holds what() */
} tinyobj_shim_status;

/* Parses size bytes of OBJ text (borrowed for the call; need not end in NUL); `mtllib` files
 * are read from material_dir (ending in '/'; NULL: materials are not read). On failure a
 * NUL-terminated reason goes into message (message_size bytes, may be 0). */
tinyobj_shim_status tinyobj_shim_parse(const char *text, size_t size, const char *material_dir,
                                       const tinyobj_shim_callbacks *callbacks, char *message, size_t message_size);

#ifdef __cplusplus
}
#endif

#endif
