/* The light table of a lighting render: the render's and the scene's point and directional
 * lights, then every emissive triangle, each with the probability that next-event estimation
 * picks it (its share of the estimated power), plus the sky and the mode's settings. Built
 * once per render, read by both backends. */
#ifndef VKRT_LIGHTS_H
#define VKRT_LIGHTS_H

#include "../shaders/vkrt_shared.h"
#include "core.h"
#include "vkrt.h"

typedef struct light_table_desc {
    const vkrt_light *render_lights; /* vkrt_render_desc.lights (validated here) */
    uint32_t render_light_count;
    const vkrt_light *scene_lights;  /* the file's (validated by the loader) */
    uint32_t scene_light_count;
    vkrt_sky sky;
    const vkrt_gpu_tri *tris;        /* in BVH order */
    uint32_t tri_count;              /* positions; more than prim_count where spatial splits put
                                        a triangle in several leaves (each is one light) */
    uint32_t prim_count;             /* the mesh's triangles: prim_id < prim_count */
    const vkrt_gpu_surface *surfaces;
    const vkrt_gpu_material *materials;
    float scene_radius;              /* of the scene's bounding sphere: what a directional light
                                        can deliver power to */
} light_table_desc;

typedef struct light_table {
    vkrt_gpu_light *lights;          /* count entries, at least one allocated */
    uint32_t count;
    vkrt_gpu_lighting lighting;      /* sky, counts, pick_scale, emitter_pick; the caller fills
                                        the mode's fields */
    bool default_rig;                /* nothing lit the scene: the default key light and sky */
} light_table;

/* Fails with VKRT_ERROR_INVALID_ARGUMENT naming vkrt_render_desc.lights[i] or .sky for a
 * non-finite or negative colour, an unknown type or a zero direction; or out of memory. */
vkrt_result light_table_build(core *c, const light_table_desc *d, light_table *out);
void light_table_destroy(core *c, light_table *t);

#endif
