/* Triangle packing and the octahedral normal encoding.
 *
 * Octahedral normals follow Cigolle, Donow, Evangelakos, Mara, McGuire, Meyer, "A Survey of
 * Efficient Representations for Independent Unit Vectors", JCGT 3(2), 2014 ("oct32"): the
 * unit sphere is projected onto the octahedron |x| + |y| + |z| = 1, the lower half folded
 * over the upper, and the square stored as two 16-bit snorm values. Three vertex normals then
 * cost 12 bytes instead of 36, which keeps vkrt_gpu_tri at one 64-byte line. */
#include "scene_pack.h"

#include <math.h>
#include <string.h>

static float sign_not_zero(float v)
{
    return v >= 0.0f ? 1.0f : -1.0f;
}

/* Round to nearest, ties away from zero, like GLSL packSnorm2x16 (whose rounding the spec
 * leaves open; only the decoder has to match bit for bit). */
static uint32_t snorm16(float v)
{
    float c = v < -1.0f ? -1.0f : (v > 1.0f ? 1.0f : v);
    int32_t q = (int32_t)lroundf(c * 32767.0f);
    return (uint32_t)(uint16_t)(int16_t)q;
}

uint32_t normal_encode_oct(const float n[3])
{
    float l1 = fabsf(n[0]) + fabsf(n[1]) + fabsf(n[2]);
    /* A zero or non-finite normal has no direction; +z keeps the decoder's output unit. */
    if (!(l1 > 0.0f) || !isfinite(l1)) return snorm16(0.0f) | (snorm16(0.0f) << 16);
    float px = n[0] / l1, py = n[1] / l1;
    if (n[2] < 0.0f) {
        float fx = (1.0f - fabsf(py)) * sign_not_zero(px);
        float fy = (1.0f - fabsf(px)) * sign_not_zero(py);
        px = fx;
        py = fy;
    }
    return snorm16(px) | (snorm16(py) << 16);
}

/* Mirrors normal_decode() in shaders/trace_common.glsl: unpackSnorm2x16, unfold, normalize. */
void normal_decode_oct(uint32_t packed, float n[3])
{
    float fx = (float)(int16_t)(uint16_t)(packed & 0xFFFFu) / 32767.0f;
    float fy = (float)(int16_t)(uint16_t)(packed >> 16) / 32767.0f;
    fx = fx < -1.0f ? -1.0f : fx;
    fy = fy < -1.0f ? -1.0f : fy;
    float x = fx, y = fy, z = 1.0f - fabsf(fx) - fabsf(fy);
    float t = -z > 0.0f ? -z : 0.0f;
    x += x >= 0.0f ? -t : t;
    y += y >= 0.0f ? -t : t;
    float inv = 1.0f / sqrtf((x * x + y * y) + z * z);
    n[0] = x * inv;
    n[1] = y * inv;
    n[2] = z * inv;
}

void scene_pack_triangles(const mesh *m, const bvh *b, vkrt_gpu_tri *tris)
{
    for (uint32_t k = 0; k < b->tri_count; k++) {
        uint32_t src = b->tri_order[k];
        const float *p = m->positions + (size_t)src * 9;
        const float *nrm = m->normals + (size_t)src * 9;
        vkrt_gpu_tri *t = &tris[k];
        t->v0 = (vkrt_float3){ p[0], p[1], p[2] };
        t->v1 = (vkrt_float3){ p[3], p[4], p[5] };
        t->v2 = (vkrt_float3){ p[6], p[7], p[8] };
        t->prim_id = src;
        /* Double, so a thin but valid triangle does not lose its normal to cancellation. */
        double e1[3] = { (double)p[3] - p[0], (double)p[4] - p[1], (double)p[5] - p[2] };
        double e2[3] = { (double)p[6] - p[0], (double)p[7] - p[1], (double)p[8] - p[2] };
        double cx = e1[1] * e2[2] - e1[2] * e2[1];
        double cy = e1[2] * e2[0] - e1[0] * e2[2];
        double cz = e1[0] * e2[1] - e1[1] * e2[0];
        double len = sqrt(cx * cx + cy * cy + cz * cz);
        if (len > 0.0 && isfinite(len))
            t->face_n = (vkrt_float3){ (float)(cx / len), (float)(cy / len), (float)(cz / len) };
        else
            t->face_n = (vkrt_float3){ 0.0f, 0.0f, 0.0f };
        t->n0 = normal_encode_oct(nrm + 0);
        t->n1 = normal_encode_oct(nrm + 3);
        t->n2 = normal_encode_oct(nrm + 6);
    }
}

size_t scene_texel_count(const mesh *m)
{
    size_t n = 0;
    for (uint32_t i = 0; i < m->texture_count; i++) n += (size_t)m->textures[i].width * m->textures[i].height;
    return n;
}

void scene_pack_surfaces(const mesh *m, vkrt_gpu_surface *surfaces, vkrt_gpu_material *materials,
                         vkrt_gpu_texture *textures, uint32_t *texels)
{
    size_t first = 0;
    for (uint32_t i = 0; i < m->texture_count; i++) {
        const mesh_texture *t = &m->textures[i];
        size_t n = (size_t)t->width * t->height;
        textures[i] = (vkrt_gpu_texture){ (uint32_t)first, t->width, t->height, t->wrap };
        memcpy(texels + 2 * first, t->texels, n * 2 * sizeof(uint32_t));
        first += n;
    }
    for (uint32_t t = 0; t < m->tri_count; t++) {
        const float *uv = m->texcoords + (size_t)t * 6;
        surfaces[t] = (vkrt_gpu_surface){ uv[0], uv[1], uv[2], uv[3], uv[4], uv[5], m->material_ids[t], 0u };
    }
    for (uint32_t i = 0; i < m->material_count; i++) {
        const vkrt_material *x = &m->materials[i];
        materials[i] = (vkrt_gpu_material){
            .base_color = { x->base_color[0], x->base_color[1], x->base_color[2] },
            .alpha = x->base_color[3],
            .emissive = { x->emissive[0], x->emissive[1], x->emissive[2] },
            .metallic = x->metallic,
            .roughness = x->roughness,
            .base_color_texture = m->material_textures[i],
            .alpha_cutoff = x->alpha_cutoff,
            .metallic_roughness_texture = m->material_metallic_roughness_textures[i],
            .emissive_texture = m->material_emissive_textures[i],
        };
    }
}
