#include "lights.h"

#include <math.h>
#include <string.h>

#include "shading.h"

#define VKRT_PI_D 3.14159265358979323846

static bool finite3(const float v[3])
{
    return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]);
}

static bool nonnegative3(const float v[3])
{
    return v[0] >= 0.0f && v[1] >= 0.0f && v[2] >= 0.0f;
}

static vkrt_result check_light(core *c, const vkrt_light *l, uint32_t i)
{
    if (l->type != VKRT_LIGHT_DIRECTIONAL && l->type != VKRT_LIGHT_POINT)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.lights[%u].type has no valid value (%d)", i,
                         (int)l->type);
    if (!finite3(l->vector))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.lights[%u].vector is not finite", i);
    if (!finite3(l->color) || !nonnegative3(l->color))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT,
                         "vkrt_render_desc.lights[%u].color must be finite and >= 0 (%g, %g, %g)", i, l->color[0],
                         l->color[1], l->color[2]);
    if (l->type == VKRT_LIGHT_DIRECTIONAL && l->vector[0] == 0.0f && l->vector[1] == 0.0f && l->vector[2] == 0.0f)
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.lights[%u]: a directional light needs a non-zero direction", i);
    return VKRT_OK;
}

/* A punctual light's entry and its estimated power: a point light's flux (4 pi I), a
 * directional light's flux through the disc the scene's bounding sphere shows it. */
static double punctual_entry(const vkrt_light *l, float scene_radius, vkrt_gpu_light *out)
{
    vkrt_float3 color = { l->color[0], l->color[1], l->color[2] };
    double lum = sh_luminance(color);
    if (l->type == VKRT_LIGHT_DIRECTIONAL) {
        double len = sqrt((double)l->vector[0] * l->vector[0] + (double)l->vector[1] * l->vector[1] +
                          (double)l->vector[2] * l->vector[2]);
        *out = (vkrt_gpu_light){ .type = VKRT_GPU_LIGHT_DIRECTIONAL, .color = color,
                                 .vector = { (float)(l->vector[0] / len), (float)(l->vector[1] / len),
                                             (float)(l->vector[2] / len) } };
        return lum * VKRT_PI_D * (double)scene_radius * scene_radius;
    }
    *out = (vkrt_gpu_light){ .type = VKRT_GPU_LIGHT_POINT, .color = color,
                             .vector = { l->vector[0], l->vector[1], l->vector[2] } };
    return lum * 4.0 * VKRT_PI_D;
}

static bool black(const float v[3])
{
    return v[0] == 0.0f && v[1] == 0.0f && v[2] == 0.0f;
}

/* The power of the triangle at position t of the BVH order as a light, 0 where it emits nothing
 * or, with `seen` (one flag per prim_id), where an earlier position held the same triangle (a
 * spatial split's copy): a triangle is one light however many leaves hold it. */
static float position_power(const light_table_desc *d, uint32_t t, uint8_t *seen)
{
    const vkrt_gpu_material *m = &d->materials[d->surfaces[d->tris[t].prim_id].material];
    float p = sh_emitter_power(&d->tris[t], m->emissive);
    if (!(p > 0.0f) || !seen) return p;
    if (seen[d->tris[t].prim_id]) return 0.0f;
    seen[d->tris[t].prim_id] = 1;
    return p;
}

vkrt_result light_table_build(core *c, const light_table_desc *d, light_table *out)
{
    memset(out, 0, sizeof *out);
    for (uint32_t i = 0; i < d->render_light_count; i++) {
        vkrt_result r = check_light(c, &d->render_lights[i], i);
        if (r != VKRT_OK) return r;
    }
    if (!finite3(d->sky.zenith) || !nonnegative3(d->sky.zenith) || !finite3(d->sky.horizon) ||
        !nonnegative3(d->sky.horizon))
        return core_fail(c, VKRT_ERROR_INVALID_ARGUMENT, "vkrt_render_desc.sky: colours must be finite and >= 0");
    uint8_t *seen = NULL;
    if (d->tri_count > d->prim_count) {
        seen = core_calloc_array(c, d->prim_count, 1);
        if (!seen)
            return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory listing the emitters of %u triangles",
                             d->prim_count);
    }
    uint32_t emitters = 0;
    for (uint32_t t = 0; t < d->tri_count; t++) emitters += position_power(d, t, seen) > 0.0f;
    vkrt_sky sky = d->sky;
    /* Nothing lights the scene: a key light from above the camera's right shoulder (the
     * default camera looks down -z) and a dim sky, so a render of any mesh shows its shape. */
    static const vkrt_light key = { VKRT_LIGHT_DIRECTIONAL, { -0.45f, -0.75f, -0.5f }, { 2.2f, 2.1f, 2.0f } };
    const bool default_rig = d->render_light_count == 0 && d->scene_light_count == 0 && emitters == 0 &&
                             black(sky.zenith) && black(sky.horizon);
    if (default_rig) sky = (vkrt_sky){ { 0.30f, 0.36f, 0.45f }, { 0.12f, 0.12f, 0.13f } };
    const uint32_t punctual = default_rig ? 1 : d->render_light_count + d->scene_light_count;
    const uint64_t count = (uint64_t)punctual + emitters;
    if (count > UINT32_MAX - 1) {
        core_free(c, seen);
        return core_fail(c, VKRT_ERROR_LIMIT, "%llu lights are more than vkrt supports", (unsigned long long)count);
    }
    out->lights = core_alloc_array(c, count ? count : 1, sizeof *out->lights);
    double *power = core_alloc_array(c, count ? count : 1, sizeof *power);
    if (!out->lights || !power) {
        core_free(c, seen);
        core_free(c, power);
        light_table_destroy(c, out);
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for a table of %llu lights", (unsigned long long)count);
    }
    uint32_t n = 0;
    if (default_rig) {
        power[n] = punctual_entry(&key, d->scene_radius, &out->lights[n]);
        n++;
    }
    for (uint32_t i = 0; !default_rig && i < d->render_light_count; i++, n++)
        power[n] = punctual_entry(&d->render_lights[i], d->scene_radius, &out->lights[n]);
    for (uint32_t i = 0; !default_rig && i < d->scene_light_count; i++, n++)
        power[n] = punctual_entry(&d->scene_lights[i], d->scene_radius, &out->lights[n]);
    if (seen) memset(seen, 0, d->prim_count);
    for (uint32_t t = 0; t < d->tri_count; t++) {
        const vkrt_gpu_material *m = &d->materials[d->surfaces[d->tris[t].prim_id].material];
        float p = position_power(d, t, seen);
        if (!(p > 0.0f)) continue;
        out->lights[n] = (vkrt_gpu_light){ .type = VKRT_GPU_LIGHT_TRIANGLE, .color = m->emissive, .tri = t,
                                           .area = sh_triangle_area(&d->tris[t]) };
        power[n++] = p;
    }
    core_free(c, seen);
    double total = 0.0;
    for (uint32_t i = 0; i < n; i++) total += power[i];
    /* Lights of zero power (black ones) are never picked; if all are black, none is. */
    double running = 0.0, emitter_total = 0.0;
    for (uint32_t i = 0; i < n; i++) {
        running += power[i];
        out->lights[i].pick = total > 0.0 ? (float)(power[i] / total) : 0.0f;
        out->lights[i].cdf = total > 0.0 ? (float)(running / total) : 0.0f;
        if (i >= punctual) emitter_total += power[i];
    }
    if (n > 0 && total > 0.0) out->lights[n - 1].cdf = 1.0f;
    core_free(c, power);
    out->count = n;
    out->default_rig = default_rig;
    out->lighting = (vkrt_gpu_lighting){
        .sky_zenith = { sky.zenith[0], sky.zenith[1], sky.zenith[2] },
        .sky_horizon = { sky.horizon[0], sky.horizon[1], sky.horizon[2] },
        .light_count = n,
        .punctual_count = punctual,
        .pick_scale = total > 0.0 ? (float)(1.0 / total) : 0.0f,
        .emitter_pick = total > 0.0 ? (float)(emitter_total / total) : 0.0f,
    };
    return VKRT_OK;
}

void light_table_destroy(core *c, light_table *t)
{
    core_free(c, t->lights);
    memset(t, 0, sizeof *t);
}
