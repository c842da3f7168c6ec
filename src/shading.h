/* Materials, lights, the sky and the BSDF of the lighting modes, in C: the CPU tracer's half of
 * shaders/shading.glsl, function for function (same names, the arithmetic in the same order),
 * so the two backends compute the same estimator from the same sampler.
 *
 * Model: a metallic-roughness surface (glTF) as a mix of a Lambertian lobe (weight 1 -
 * metallic, albedo = base colour) and a GGX microfacet metal lobe (weight metallic, Fresnel
 * from F0 = base colour, Schlick's approximation; height-correlated Smith masking-shadowing,
 * Heitz 2014; visible-normal sampling, Heitz 2018); a metal lobe smoother than
 * SHADING_MIRROR_ROUGHNESS is a perfect mirror. Dielectrics have no specular coat, so a scene
 * without metals needs no GGX code at all. Emitters emit on both sides. */
#ifndef VKRT_SHADING_H
#define VKRT_SHADING_H

#include <stdbool.h>
#include <stdint.h>

#include "../shaders/vkrt_shared.h"

#define SHADING_MIRROR_ROUGHNESS 0.03f
#define SHADING_PI 3.14159265358979f

typedef vkrt_float3 sh_vec3;

/* The material at a hit, its textures applied. */
typedef struct sh_material {
    sh_vec3 albedo;
    float metallic, roughness;
    sh_vec3 emission;
} sh_material;

/* What one BSDF sample produced. */
typedef struct sh_bsdf_sample {
    sh_vec3 dir;    /* unit, leaving the surface */
    sh_vec3 weight; /* f * |cos| / pdf */
    float pdf;      /* solid angle; 0 for the mirror (a delta lobe) */
    bool valid;     /* false: the sample went below the surface, the path ends */
} sh_bsdf_sample;

/* The scene's surfaces as shading reads them. */
typedef struct sh_scene {
    const vkrt_gpu_tri *tris;
    const vkrt_gpu_surface *surfaces;
    const vkrt_gpu_material *materials;
    const vkrt_gpu_texture *textures;
    const uint32_t *texels;
    const vkrt_gpu_light *lights;
    const vkrt_gpu_lighting *lighting;
    uint32_t features; /* VKRT_GPU_FEATURE_* */
} sh_scene;

float sh_luminance(sh_vec3 c);
sh_vec3 sh_sky(const vkrt_gpu_lighting *l, sh_vec3 dir);

/* The hit point, unit geometric normal and shading normal of triangle `tri` at barycentrics
 * (u, v), both normals turned to face -ray_dir. */
void sh_hit_geometry(const vkrt_gpu_tri *tri, float u, float v, sh_vec3 ray_dir, sh_vec3 *out_p, sh_vec3 *out_ng,
                     sh_vec3 *out_ns);
sh_material sh_material_at(const sh_scene *s, uint32_t prim, float u, float v);

sh_vec3 sh_bsdf_eval(const sh_material *m, sh_vec3 ns, sh_vec3 ng, sh_vec3 wo, sh_vec3 wi, float *out_pdf);
sh_bsdf_sample sh_bsdf_sample_dir(const sh_material *m, sh_vec3 ns, sh_vec3 ng, sh_vec3 wo, const float u[3]);
sh_vec3 sh_cosine_dir(sh_vec3 n, float u0, float u1);

/* The light table entry whose cdf interval holds u, among entries [first, first + count). */
uint32_t sh_pick_light(const vkrt_gpu_light *lights, uint32_t first, uint32_t count, float u);

/* A light sample seen from p: the shadow ray (origin offset along ng, direction to the light,
 * tmax in units of that direction), the radiance arriving times 1 / pdf (solid angle), and the
 * pdf (0 for point and directional lights, which no BSDF sample can hit). */
typedef struct sh_light_sample {
    vkrt_gpu_ray ray;
    sh_vec3 wi;         /* unit direction to the light */
    sh_vec3 radiance;   /* incident radiance / pdf, pick probability excluded */
    float pdf;          /* solid angle, pick excluded; 0: delta */
    bool valid;
} sh_light_sample;
sh_light_sample sh_sample_light(const sh_scene *s, const vkrt_gpu_light *light, sh_vec3 p, sh_vec3 ng,
                                float u0, float u1);

/* The solid-angle pdf with which next-event estimation would have chosen the emissive
 * triangle `tri` hit at distance t along a unit direction dir (pick included). */
float sh_emitter_pdf(const sh_scene *s, const vkrt_gpu_tri *tri, sh_vec3 dir, float t);

/* Area of a triangle, as the light table and sh_emitter_pdf compute it. */
float sh_triangle_area(const vkrt_gpu_tri *tri);
/* The power next-event estimation picks an emissive triangle by (its emitted flux, up to a
 * constant factor shared with the point and directional lights' estimates). */
float sh_emitter_power(const vkrt_gpu_tri *tri, sh_vec3 emissive);

/* Power heuristic (beta = 2) weight of a sample with pdf a against one with pdf b. */
float sh_mis_weight(float a, float b);

/* The offset origin of a ray leaving p on the side of ng. */
sh_vec3 sh_offset(sh_vec3 p, sh_vec3 ng);

#endif
