/* Materials, lights, the sky and the BSDF of the lighting modes: the GPU half of src/shading.c,
 * function for function (the same names without the sh_ prefix, the arithmetic in the same
 * order); see src/shading.h for the model and the papers. shade.comp declares the buffers
 * (materials, textures, texels, lights, lighting), the FEATURES constant and the scene's
 * arrays (scene_arrays.glsl: load_tri, load_surface) before including this file. */
#ifndef VKRT_SHADING_GLSL
#define VKRT_SHADING_GLSL

#define SHADING_MIRROR_ROUGHNESS 0.03
#define SHADING_PI 3.14159265358979

struct material_sample {
    vec3 albedo;
    float metallic;
    float roughness;
    vec3 emission;
};

struct bsdf_sample {
    vec3 dir;
    vec3 weight;
    float pdf;
    bool valid;
};

struct light_sample {
    vkrt_gpu_ray ray;
    vec3 wi;
    vec3 radiance;
    float pdf;
    bool valid;
};

float luminance(vec3 c)
{
    precise float l = (0.2126 * c.x + 0.7152 * c.y) + 0.0722 * c.z;
    return l;
}

vec3 sky(vec3 dir)
{
    float t = f_max(dir.y, 0.0);
    precise vec3 c = lighting.sky_horizon + (lighting.sky_zenith - lighting.sky_horizon) * t;
    return c;
}

void hit_geometry(vkrt_gpu_tri tri, float u, float v, vec3 ray_dir, out vec3 p, out vec3 ng, out vec3 ns)
{
    precise float w = 1.0 - u - v;
    precise vec3 pos = (tri.v0 * w + tri.v1 * u) + tri.v2 * v;
    p = pos;
    ng = tri.face_n;
    if (dot3(ng, ray_dir) > 0.0) ng = -ng;
    precise vec3 n = (normal_decode(tri.n0) * w + normal_decode(tri.n1) * u) + normal_decode(tri.n2) * v;
    float len2 = dot3(n, n);
    /* Opposed vertex normals can cancel; the face normal is the only direction left. */
    n = len2 > 0.0 ? n * (1.0 / sqrt(len2)) : ng;
    /* The shading normal on the side of the geometric one, so both see the same hemisphere. */
    if (dot3(n, ng) < 0.0) n = -n;
    ns = n;
}

material_sample material_at(uint prim, float u, float v)
{
    vkrt_gpu_surface f = load_surface(prim);
    vkrt_gpu_material g = materials[f.material];
    material_sample m = material_sample(g.base_color, g.metallic, g.roughness, g.emissive);
    if ((FEATURES & VKRT_GPU_FEATURE_TEXTURES) != 0u) {
        vec2 uv = surface_uv(f, u, v);
        if (g.base_color_texture != VKRT_NO_TEXTURE) m.albedo = m.albedo * sample_texture(textures[g.base_color_texture], uv).xyz;
        if (g.metallic_roughness_texture != VKRT_NO_TEXTURE) {
            vec3 mr = sample_texture(textures[g.metallic_roughness_texture], uv).xyz;
            m.roughness = m.roughness * mr.y;
            m.metallic = m.metallic * mr.z;
        }
        if (g.emissive_texture != VKRT_NO_TEXTURE) m.emission = m.emission * sample_texture(textures[g.emissive_texture], uv).xyz;
    }
    if ((FEATURES & VKRT_GPU_FEATURE_SPECULAR) == 0u) m.metallic = 0.0;
    return m;
}

void basis(vec3 n, out vec3 t, out vec3 b)
{
    float sign_z = n.z >= 0.0 ? 1.0 : -1.0;
    precise float a = -1.0 / (sign_z + n.z);
    precise float c = n.x * n.y * a;
    precise vec3 tt = vec3(1.0 + sign_z * n.x * n.x * a, sign_z * c, -sign_z * n.x);
    precise vec3 bb = vec3(c, sign_z + n.y * n.y * a, -n.y);
    t = tt;
    b = bb;
}

vec3 cosine_dir(vec3 n, float u0, float u1)
{
    float r = sqrt(u0);
    float phi = 2.0 * SHADING_PI * u1;
    float x = r * cos(phi), y = r * sin(phi);
    float z = sqrt(f_max(0.0, 1.0 - u0));
    vec3 t, b;
    basis(n, t, b);
    precise vec3 d = (t * x + b * y) + n * z;
    return d * (1.0 / sqrt(dot3(d, d)));
}

vec3 fresnel_schlick(vec3 f0, float cos_theta)
{
    float k = 1.0 - f_min(f_max(cos_theta, 0.0), 1.0);
    float k2 = k * k;
    float k5 = k2 * k2 * k;
    precise vec3 f = f0 + (vec3(1.0) - f0) * k5;
    return f;
}

float ggx_alpha(float roughness)
{
    return f_max(roughness * roughness, 1e-3);
}

float ggx_d(float a2, float n_h)
{
    precise float d = (n_h * n_h) * (a2 - 1.0) + 1.0;
    return a2 / (SHADING_PI * d * d);
}

float ggx_lambda(float a2, float n_v)
{
    float c2 = n_v * n_v;
    float t2 = f_max(1.0 - c2, 0.0) / f_max(c2, 1e-12);
    return 0.5 * (sqrt(1.0 + a2 * t2) - 1.0);
}

bool is_mirror(material_sample m)
{
    return m.roughness < SHADING_MIRROR_ROUGHNESS;
}

float metal_probability(material_sample m)
{
    return m.metallic;
}

vec3 bsdf_eval(material_sample m, vec3 ns, vec3 ng, vec3 wo, vec3 wi, out float out_pdf)
{
    out_pdf = 0.0;
    float n_i = dot3(ns, wi), n_o = dot3(ns, wo);
    /* Light from below the geometric surface never reaches the side the ray came from. */
    if (dot3(ng, wi) <= 0.0 || n_i <= 0.0 || n_o <= 0.0) return vec3(0.0);
    float p_metal = metal_probability(m);
    precise vec3 f = m.albedo * ((1.0 - m.metallic) * (1.0 / SHADING_PI));
    precise float pdf = (1.0 - p_metal) * n_i * (1.0 / SHADING_PI);
    if ((FEATURES & VKRT_GPU_FEATURE_SPECULAR) != 0u && m.metallic > 0.0 && !is_mirror(m)) {
        precise vec3 hs = wi + wo;
        vec3 h = hs * (1.0 / sqrt(dot3(hs, hs)));
        float n_h = dot3(ns, h), o_h = dot3(wo, h);
        float a2 = ggx_alpha(m.roughness);
        a2 = a2 * a2;
        float d = ggx_d(a2, n_h);
        float lo = ggx_lambda(a2, n_o), li = ggx_lambda(a2, n_i);
        float g2 = 1.0 / (1.0 + lo + li);
        float g1 = 1.0 / (1.0 + lo);
        precise vec3 spec = fresnel_schlick(m.albedo, o_h) * (m.metallic * d * g2 / (4.0 * n_i * n_o));
        f = f + spec;
        pdf = pdf + p_metal * (g1 * d / (4.0 * n_o));
    }
    out_pdf = pdf;
    return f;
}

vec3 ggx_visible_normal(vec3 v, float alpha, float u0, float u1)
{
    precise vec3 vs = vec3(alpha * v.x, alpha * v.y, v.z);
    vec3 vh = vs * (1.0 / sqrt(dot3(vs, vs)));
    float len2 = vh.x * vh.x + vh.y * vh.y;
    vec3 t1 = len2 > 0.0 ? vec3(-vh.y, vh.x, 0.0) * (1.0 / sqrt(len2)) : vec3(1.0, 0.0, 0.0);
    vec3 t2 = cross3(vh, t1);
    float r = sqrt(u0);
    float phi = 2.0 * SHADING_PI * u1;
    float p1 = r * cos(phi), p2 = r * sin(phi);
    float s = 0.5 * (1.0 + vh.z);
    p2 = (1.0 - s) * sqrt(f_max(0.0, 1.0 - p1 * p1)) + s * p2;
    precise vec3 nh = (t1 * p1 + t2 * p2) + vh * sqrt(f_max(0.0, 1.0 - p1 * p1 - p2 * p2));
    precise vec3 ne = vec3(alpha * nh.x, alpha * nh.y, f_max(0.0, nh.z));
    return ne * (1.0 / sqrt(dot3(ne, ne)));
}

bsdf_sample bsdf_sample_dir(material_sample m, vec3 ns, vec3 ng, vec3 wo, vec3 u)
{
    bsdf_sample o = bsdf_sample(vec3(0.0), vec3(0.0), 0.0, false);
    float p_metal = metal_probability(m);
    if ((FEATURES & VKRT_GPU_FEATURE_SPECULAR) != 0u && u.z < p_metal) {
        if (is_mirror(m)) {
            precise vec3 wi = ns * (2.0 * dot3(ns, wo)) - wo;
            if (dot3(ng, wi) <= 0.0) return o;
            o.dir = wi;
            o.weight = fresnel_schlick(m.albedo, dot3(ns, wo)) * (m.metallic / p_metal);
            o.pdf = 0.0;
            o.valid = true;
            return o;
        }
        vec3 t, b;
        basis(ns, t, b);
        vec3 lo = vec3(dot3(wo, t), dot3(wo, b), dot3(wo, ns));
        vec3 hl = ggx_visible_normal(lo, ggx_alpha(m.roughness), u.x, u.y);
        precise vec3 h = (t * hl.x + b * hl.y) + ns * hl.z;
        precise vec3 d = h * (2.0 * dot3(wo, h)) - wo;
        o.dir = d;
    } else {
        o.dir = cosine_dir(ns, u.x, u.y);
    }
    float pdf;
    vec3 f = bsdf_eval(m, ns, ng, wo, o.dir, pdf);
    if (!(pdf > 0.0)) return o;
    o.weight = f * (dot3(ns, o.dir) / pdf);
    o.pdf = pdf;
    o.valid = true;
    return o;
}

/* A binary search: at most 32 iterations. */
uint pick_light(uint first, uint count, float u)
{
    uint lo = first, hi = first + count - 1u;
    while (lo < hi) {
        uint mid = (lo + hi) / 2u;
        if (lights[mid].cdf > u) hi = mid;
        else lo = mid + 1u;
    }
    return lo;
}

float triangle_area(vkrt_gpu_tri tri)
{
    vec3 e = cross3(tri.v1 - tri.v0, tri.v2 - tri.v0);
    return 0.5 * sqrt(dot3(e, e));
}

float emitter_power(vkrt_gpu_tri tri, vec3 emissive)
{
    return SHADING_PI * triangle_area(tri) * luminance(emissive);
}

light_sample sample_light(vkrt_gpu_light light, vec3 p, vec3 ng, float u0, float u1)
{
    light_sample o = light_sample(vkrt_gpu_ray(vec3(0.0), 0.0, vec3(0.0), 0.0), vec3(0.0), vec3(0.0), 0.0, false);
    vec3 origin = ray_offset(p, ng);
    /* Each kind of light is compiled in only when the render has one. */
    const bool punctual = (FEATURES & VKRT_GPU_FEATURE_PUNCTUAL) != 0u;
    if (punctual && light.type == VKRT_GPU_LIGHT_DIRECTIONAL) {
        o.wi = -light.vector;
        o.radiance = light.color;
        o.ray = vkrt_gpu_ray(origin, 0.0, o.wi, 0.0);
        o.pdf = 0.0;
    } else if (punctual && light.type == VKRT_GPU_LIGHT_POINT) {
        precise vec3 d = light.vector - origin;
        float dist2 = dot3(d, d);
        if (!(dist2 > 0.0)) return o;
        o.wi = d * (1.0 / sqrt(dist2));
        o.radiance = light.color * (1.0 / dist2);
        o.ray = vkrt_gpu_ray(origin, 0.0, d, 1.0);
        o.pdf = 0.0;
    } else if ((FEATURES & VKRT_GPU_FEATURE_EMITTERS) != 0u) {
        vkrt_gpu_tri tri = load_tri(light.tri);
        float r = sqrt(u0);
        float b1 = r * (1.0 - u1), b2 = r * u1;
        precise vec3 y = (tri.v0 * (1.0 - b1 - b2) + tri.v1 * b1) + tri.v2 * b2;
        precise vec3 d = y - origin;
        float dist2 = dot3(d, d);
        if (!(dist2 > 0.0)) return o;
        o.wi = d * (1.0 / sqrt(dist2));
        float cos_l = abs(dot3(tri.face_n, o.wi));
        if (!(cos_l > 0.0) || !(light.area > 0.0)) return o;
        o.pdf = dist2 / (cos_l * light.area);
        material_sample m = material_at(tri.prim_id, b1, b2);
        o.radiance = m.emission * (1.0 / o.pdf);
        o.ray = vkrt_gpu_ray(origin, 0.0, d, 0.9999);
    } else {
        return o;
    }
    o.valid = true;
    return o;
}

float emitter_pdf(vkrt_gpu_tri tri, vec3 dir, float t)
{
    vkrt_gpu_material g = materials[load_surface(tri.prim_id).material];
    float area = triangle_area(tri);
    float cos_l = abs(dot3(tri.face_n, dir));
    if (!(area > 0.0) || !(cos_l > 0.0)) return 0.0;
    float pick = emitter_power(tri, g.emissive) * lighting.pick_scale;
    return pick * (t * t) / (cos_l * area);
}

float mis_weight(float a, float b)
{
    float a2 = a * a, b2 = b * b;
    return a2 + b2 > 0.0 ? a2 / (a2 + b2) : 0.0;
}

#endif
