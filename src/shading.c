/* See shading.h. Every function mirrors the one of the same name (without the sh_ prefix) in
 * shaders/shading.glsl. Papers: Heitz, "Understanding the Masking-Shadowing Function",
 * JCGT 3(2), 2014; Heitz, "Sampling the GGX Distribution of Visible Normals", JCGT 7(4), 2018;
 * Duff et al., "Building an Orthonormal Basis, Revisited", JCGT 6(1), 2017; Veach, Guibas,
 * "Optimally Combining Sampling Techniques", SIGGRAPH 1995 (the power heuristic). */
#include "shading.h"

#include <math.h>

#include "ray_offset.h"
#include "scene_pack.h"
#include "texture.h"

static sh_vec3 v3(float x, float y, float z) { return (sh_vec3){ x, y, z }; }
static sh_vec3 add(sh_vec3 a, sh_vec3 b) { return v3(a.x + b.x, a.y + b.y, a.z + b.z); }
static sh_vec3 sub(sh_vec3 a, sh_vec3 b) { return v3(a.x - b.x, a.y - b.y, a.z - b.z); }
static sh_vec3 mul(sh_vec3 a, sh_vec3 b) { return v3(a.x * b.x, a.y * b.y, a.z * b.z); }
static sh_vec3 scale(sh_vec3 a, float s) { return v3(a.x * s, a.y * s, a.z * s); }
static float dot(sh_vec3 a, sh_vec3 b) { return (a.x * b.x + a.y * b.y) + a.z * b.z; }
static sh_vec3 cross(sh_vec3 a, sh_vec3 b) { return v3(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y); }
static sh_vec3 normalize(sh_vec3 a) { return scale(a, 1.0f / sqrtf(dot(a, a))); }
static float max_f(float a, float b) { return a < b ? b : a; }
static float min_f(float a, float b) { return b < a ? b : a; }

float sh_luminance(sh_vec3 c)
{
    return (0.2126f * c.x + 0.7152f * c.y) + 0.0722f * c.z;
}

sh_vec3 sh_sky(const vkrt_gpu_lighting *l, sh_vec3 dir)
{
    float t = max_f(dir.y, 0.0f);
    return add(l->sky_horizon, scale(sub(l->sky_zenith, l->sky_horizon), t));
}

static sh_vec3 decode(uint32_t packed)
{
    float n[3];
    normal_decode_oct(packed, n);
    return v3(n[0], n[1], n[2]);
}

void sh_hit_geometry(const vkrt_gpu_tri *tri, float u, float v, sh_vec3 ray_dir, sh_vec3 *out_p, sh_vec3 *out_ng,
                     sh_vec3 *out_ns)
{
    float w = 1.0f - u - v;
    *out_p = add(add(scale(tri->v0, w), scale(tri->v1, u)), scale(tri->v2, v));
    sh_vec3 ng = tri->face_n;
    if (dot(ng, ray_dir) > 0.0f) ng = scale(ng, -1.0f);
    sh_vec3 n = add(add(scale(decode(tri->n0), w), scale(decode(tri->n1), u)), scale(decode(tri->n2), v));
    float len2 = dot(n, n);
    /* Opposed vertex normals can cancel; the face normal is the only direction left. */
    n = len2 > 0.0f ? scale(n, 1.0f / sqrtf(len2)) : ng;
    /* The shading normal on the side of the geometric one, so both see the same hemisphere. */
    if (dot(n, ng) < 0.0f) n = scale(n, -1.0f);
    *out_ng = ng;
    *out_ns = n;
}

static sh_vec3 texel_rgb(const sh_scene *s, uint32_t texture, float uv[2], float *out_alpha)
{
    float t[4];
    texture_sample(&s->textures[texture], s->texels, uv[0], uv[1], t);
    if (out_alpha) *out_alpha = t[3];
    return v3(t[0], t[1], t[2]);
}

sh_material sh_material_at(const sh_scene *s, uint32_t prim, float u, float v)
{
    const vkrt_gpu_surface *f = &s->surfaces[prim];
    const vkrt_gpu_material *g = &s->materials[f->material];
    sh_material m = { g->base_color, g->metallic, g->roughness, g->emissive };
    if (s->features & VKRT_GPU_FEATURE_TEXTURES) {
        float w = 1.0f - u - v;
        float uv[2] = { (f->u0 * w + f->u1 * u) + f->u2 * v, (f->v0 * w + f->v1 * u) + f->v2 * v };
        if (g->base_color_texture != VKRT_NO_TEXTURE) m.albedo = mul(m.albedo, texel_rgb(s, g->base_color_texture, uv, NULL));
        if (g->metallic_roughness_texture != VKRT_NO_TEXTURE) {
            sh_vec3 mr = texel_rgb(s, g->metallic_roughness_texture, uv, NULL);
            m.roughness = m.roughness * mr.y;
            m.metallic = m.metallic * mr.z;
        }
        if (g->emissive_texture != VKRT_NO_TEXTURE) m.emission = mul(m.emission, texel_rgb(s, g->emissive_texture, uv, NULL));
    }
    if (!(s->features & VKRT_GPU_FEATURE_SPECULAR)) m.metallic = 0.0f;
    return m;
}

/* An orthonormal basis (t, b, n) around the unit vector n (Duff et al. 2017). */
static void basis(sh_vec3 n, sh_vec3 *t, sh_vec3 *b)
{
    float sign = n.z >= 0.0f ? 1.0f : -1.0f;
    float a = -1.0f / (sign + n.z);
    float c = n.x * n.y * a;
    *t = v3(1.0f + sign * n.x * n.x * a, sign * c, -sign * n.x);
    *b = v3(c, sign + n.y * n.y * a, -n.y);
}

sh_vec3 sh_cosine_dir(sh_vec3 n, float u0, float u1)
{
    float r = sqrtf(u0);
    float phi = 2.0f * SHADING_PI * u1;
    float x = r * cosf(phi), y = r * sinf(phi);
    float z = sqrtf(max_f(0.0f, 1.0f - u0));
    sh_vec3 t, b;
    basis(n, &t, &b);
    return normalize(add(add(scale(t, x), scale(b, y)), scale(n, z)));
}

static sh_vec3 fresnel_schlick(sh_vec3 f0, float cos_theta)
{
    float k = 1.0f - min_f(max_f(cos_theta, 0.0f), 1.0f);
    float k2 = k * k;
    float k5 = k2 * k2 * k;
    return add(f0, scale(sub(v3(1.0f, 1.0f, 1.0f), f0), k5));
}

static float ggx_alpha(float roughness)
{
    return max_f(roughness * roughness, 1e-3f);
}

static float ggx_d(float a2, float n_h)
{
    float d = (n_h * n_h) * (a2 - 1.0f) + 1.0f;
    return a2 / (SHADING_PI * d * d);
}

/* Smith's Lambda for GGX (Heitz 2014, eq. 72). */
static float ggx_lambda(float a2, float n_v)
{
    float c2 = n_v * n_v;
    float t2 = max_f(1.0f - c2, 0.0f) / max_f(c2, 1e-12f);
    return 0.5f * (sqrtf(1.0f + a2 * t2) - 1.0f);
}

static bool is_mirror(const sh_material *m)
{
    return m->roughness < SHADING_MIRROR_ROUGHNESS;
}

/* The probability a BSDF sample takes the metal lobe. */
static float metal_probability(const sh_material *m)
{
    return m->metallic;
}

sh_vec3 sh_bsdf_eval(const sh_material *m, sh_vec3 ns, sh_vec3 ng, sh_vec3 wo, sh_vec3 wi, float *out_pdf)
{
    *out_pdf = 0.0f;
    float n_i = dot(ns, wi), n_o = dot(ns, wo);
    /* Light from below the geometric surface never reaches the side the ray came from. */
    if (dot(ng, wi) <= 0.0f || n_i <= 0.0f || n_o <= 0.0f) return v3(0.0f, 0.0f, 0.0f);
    float p_metal = metal_probability(m);
    sh_vec3 f = scale(m->albedo, (1.0f - m->metallic) * (1.0f / SHADING_PI));
    float pdf = (1.0f - p_metal) * n_i * (1.0f / SHADING_PI);
    if (m->metallic > 0.0f && !is_mirror(m)) {
        sh_vec3 h = normalize(add(wi, wo));
        float n_h = dot(ns, h), o_h = dot(wo, h);
        float a2 = ggx_alpha(m->roughness);
        a2 = a2 * a2;
        float d = ggx_d(a2, n_h);
        float lo = ggx_lambda(a2, n_o), li = ggx_lambda(a2, n_i);
        float g2 = 1.0f / (1.0f + lo + li);
        float g1 = 1.0f / (1.0f + lo);
        sh_vec3 spec = scale(fresnel_schlick(m->albedo, o_h), m->metallic * d * g2 / (4.0f * n_i * n_o));
        f = add(f, spec);
        pdf = pdf + p_metal * (g1 * d / (4.0f * n_o));
    }
    *out_pdf = pdf;
    return f;
}

/* A GGX visible normal for the view direction v in the local frame (z = normal), Heitz 2018. */
static sh_vec3 ggx_visible_normal(sh_vec3 v, float alpha, float u0, float u1)
{
    sh_vec3 vh = normalize(v3(alpha * v.x, alpha * v.y, v.z));
    float len2 = vh.x * vh.x + vh.y * vh.y;
    sh_vec3 t1 = len2 > 0.0f ? scale(v3(-vh.y, vh.x, 0.0f), 1.0f / sqrtf(len2)) : v3(1.0f, 0.0f, 0.0f);
    sh_vec3 t2 = cross(vh, t1);
    float r = sqrtf(u0);
    float phi = 2.0f * SHADING_PI * u1;
    float p1 = r * cosf(phi), p2 = r * sinf(phi);
    float s = 0.5f * (1.0f + vh.z);
    p2 = (1.0f - s) * sqrtf(max_f(0.0f, 1.0f - p1 * p1)) + s * p2;
    sh_vec3 nh = add(add(scale(t1, p1), scale(t2, p2)), scale(vh, sqrtf(max_f(0.0f, 1.0f - p1 * p1 - p2 * p2))));
    return normalize(v3(alpha * nh.x, alpha * nh.y, max_f(0.0f, nh.z)));
}

sh_bsdf_sample sh_bsdf_sample_dir(const sh_material *m, sh_vec3 ns, sh_vec3 ng, sh_vec3 wo, const float u[3])
{
    sh_bsdf_sample out = { .valid = false };
    float p_metal = metal_probability(m);
    if (u[2] < p_metal) {
        if (is_mirror(m)) {
            sh_vec3 wi = sub(scale(ns, 2.0f * dot(ns, wo)), wo);
            if (dot(ng, wi) <= 0.0f) return out;
            /* The delta lobe's weight: its Fresnel, over the probability of choosing it. */
            out.dir = wi;
            out.weight = scale(fresnel_schlick(m->albedo, dot(ns, wo)), m->metallic / p_metal);
            out.pdf = 0.0f;
            out.valid = true;
            return out;
        }
        sh_vec3 t, b;
        basis(ns, &t, &b);
        sh_vec3 lo = v3(dot(wo, t), dot(wo, b), dot(wo, ns));
        sh_vec3 hl = ggx_visible_normal(lo, ggx_alpha(m->roughness), u[0], u[1]);
        sh_vec3 h = add(add(scale(t, hl.x), scale(b, hl.y)), scale(ns, hl.z));
        out.dir = sub(scale(h, 2.0f * dot(wo, h)), wo);
    } else {
        out.dir = sh_cosine_dir(ns, u[0], u[1]);
    }
    float pdf;
    sh_vec3 f = sh_bsdf_eval(m, ns, ng, wo, out.dir, &pdf);
    if (!(pdf > 0.0f)) return out;
    out.weight = scale(f, dot(ns, out.dir) / pdf);
    out.pdf = pdf;
    out.valid = true;
    return out;
}

uint32_t sh_pick_light(const vkrt_gpu_light *lights, uint32_t first, uint32_t count, float u)
{
    /* The first entry whose cdf exceeds u (the last if rounding leaves u above every cdf). */
    uint32_t lo = first, hi = first + count - 1;
    while (lo < hi) {
        uint32_t mid = (lo + hi) / 2;
        if (lights[mid].cdf > u) hi = mid;
        else lo = mid + 1;
    }
    return lo;
}

sh_vec3 sh_offset(sh_vec3 p, sh_vec3 ng)
{
    return ray_offset(p, ng);
}

sh_light_sample sh_sample_light(const sh_scene *s, const vkrt_gpu_light *light, sh_vec3 p, sh_vec3 ng, float u0,
                                float u1)
{
    sh_light_sample out = { .valid = false };
    sh_vec3 origin = sh_offset(p, ng);
    if (light->type == VKRT_GPU_LIGHT_DIRECTIONAL) {
        out.wi = scale(light->vector, -1.0f);
        out.radiance = light->color;
        out.ray = (vkrt_gpu_ray){ origin, 0.0f, out.wi, 0.0f };
        out.pdf = 0.0f;
    } else if (light->type == VKRT_GPU_LIGHT_POINT) {
        sh_vec3 d = sub(light->vector, origin);
        float dist2 = dot(d, d);
        if (!(dist2 > 0.0f)) return out;
        out.wi = scale(d, 1.0f / sqrtf(dist2));
        out.radiance = scale(light->color, 1.0f / dist2);
        /* t in units of d: the light sits at t = 1. */
        out.ray = (vkrt_gpu_ray){ origin, 0.0f, d, 1.0f };
        out.pdf = 0.0f;
    } else {
        const vkrt_gpu_tri *tri = &s->tris[light->tri];
        /* Uniform on the triangle (Turk 1990): barycentrics from the square root of u0. */
        float r = sqrtf(u0);
        float b1 = r * (1.0f - u1), b2 = r * u1;
        sh_vec3 y = add(add(scale(tri->v0, 1.0f - b1 - b2), scale(tri->v1, b1)), scale(tri->v2, b2));
        sh_vec3 d = sub(y, origin);
        float dist2 = dot(d, d);
        if (!(dist2 > 0.0f)) return out;
        out.wi = scale(d, 1.0f / sqrtf(dist2));
        float cos_l = fabsf(dot(tri->face_n, out.wi));
        if (!(cos_l > 0.0f) || !(light->area > 0.0f)) return out;
        out.pdf = dist2 / (cos_l * light->area);
        sh_material m = sh_material_at(s, tri->prim_id, b1, b2);
        out.radiance = scale(m.emission, 1.0f / out.pdf);
        /* Short of the emitter, so it does not shadow itself. */
        out.ray = (vkrt_gpu_ray){ origin, 0.0f, d, 0.9999f };
    }
    out.valid = true;
    return out;
}

float sh_triangle_area(const vkrt_gpu_tri *tri)
{
    sh_vec3 e = cross(sub(tri->v1, tri->v0), sub(tri->v2, tri->v0));
    return 0.5f * sqrtf(dot(e, e));
}

float sh_emitter_power(const vkrt_gpu_tri *tri, sh_vec3 emissive)
{
    return SHADING_PI * sh_triangle_area(tri) * sh_luminance(emissive);
}

float sh_emitter_pdf(const sh_scene *s, const vkrt_gpu_tri *tri, sh_vec3 dir, float t)
{
    const vkrt_gpu_material *g = &s->materials[s->surfaces[tri->prim_id].material];
    float area = sh_triangle_area(tri);
    float cos_l = fabsf(dot(tri->face_n, dir));
    if (!(area > 0.0f) || !(cos_l > 0.0f)) return 0.0f;
    float pick = sh_emitter_power(tri, g->emissive) * s->lighting->pick_scale;
    return pick * (t * t) / (cos_l * area);
}

float sh_mis_weight(float a, float b)
{
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0f ? a2 / (a2 + b2) : 0.0f;
}
