#include "gpu_integrate.h"

#include <assert.h>
#include <math.h>
#include <string.h>

#include "vk_pipeline.h"

/* A tile bounds the wavefront's buffers: 256x256 pixels fill the traversal's continuation
 * buffers (VKRT_RESUME_RAY_CHUNK slots) exactly. Each rectangle of a tile the pacer sizes is
 * one wavefront, through all its samples. */
#define WAVE_TILE 256u
_Static_assert(WAVE_TILE * WAVE_TILE <= VKRT_RESUME_RAY_CHUNK, "a wavefront tile must fit the continuation buffers");

/* The counters shade.comp's Active block holds: the first two are reset before each batch. */
typedef struct wave_counters {
    uint32_t active;      /* paths that go on after the batch */
    uint32_t queued;      /* entries of its output queue */
    uint32_t shadow_rays, bounce_rays;
} wave_counters;

typedef struct wave {
    vk_context *vk;
    const gpu_scene *scene;
    const gpu_integrate_params *params;
    gpu_wavefront_tracer *closest, *shadow;
    vk_buffer paths, accum, lights, lighting, counters, queue;
    uint32_t slots;
    VkDescriptorPool pool;
    VkDescriptorSet set;
    VkDescriptorSetLayout set_layout;
    VkPipelineLayout layout;
    double device_ms;
    gpu_pacer pacer;        /* sizes the rectangles (and naive traversal's passes) */
    uint32_t chunks;        /* naive-traversal chunks every ray meets (1 for BVH traversal) */
    gpu_wave_progress progress;
} wave;

static vkrt_result create_descriptor_set(wave *w)
{
    vk_context *vk = w->vk;
    VkDescriptorPoolSize size = { VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, VKRT_SHADE_BINDING_COUNT };
    vkrt_result r = vk_descriptor_set_create(vk, w->set_layout, &size, 1, &w->pool, &w->set);
    if (r != VKRT_OK) return r;
    const gpu_scene *s = w->scene;
    const VkBuffer buffers[VKRT_SHADE_BINDING_COUNT] = {
        [VKRT_SHADE_BINDING_TRIS] = s->tris.pieces[0].buffer,
        [VKRT_SHADE_BINDING_SURFACES] = s->surfaces.pieces[0].buffer,
        [VKRT_SHADE_BINDING_MATERIALS] = s->materials.buffer,
        [VKRT_SHADE_BINDING_TEXTURES] = s->textures.buffer,
        [VKRT_SHADE_BINDING_TEXELS] = s->texels.buffer,
        [VKRT_SHADE_BINDING_LIGHTS] = w->lights.buffer,
        [VKRT_SHADE_BINDING_PATHS] = w->paths.buffer,
        [VKRT_SHADE_BINDING_ACCUM] = w->accum.buffer,
        [VKRT_SHADE_BINDING_RAYS] = gpu_wavefront_rays(w->closest),
        [VKRT_SHADE_BINDING_HITS] = gpu_wavefront_hits(w->closest),
        [VKRT_SHADE_BINDING_SHADOW_RAYS] = gpu_wavefront_rays(w->shadow),
        [VKRT_SHADE_BINDING_SHADOW_HITS] = gpu_wavefront_hits(w->shadow),
        [VKRT_SHADE_BINDING_ACTIVE] = w->counters.buffer,
        [VKRT_SHADE_BINDING_LIGHTING] = w->lighting.buffer,
        [VKRT_SHADE_BINDING_QUEUE] = w->queue.buffer,
        [VKRT_SHADE_BINDING_PIECES] = s->pieces.buffer,
    };
    VkDescriptorBufferInfo infos[VKRT_SHADE_BINDING_COUNT];
    VkWriteDescriptorSet writes[VKRT_SHADE_BINDING_COUNT];
    for (uint32_t i = 0; i < VKRT_SHADE_BINDING_COUNT; i++) {
        infos[i] = (VkDescriptorBufferInfo){ buffers[i], 0, VK_WHOLE_SIZE };
        writes[i] = (VkWriteDescriptorSet){ .sType = VK_STRUCTURE_TYPE_WRITE_DESCRIPTOR_SET, .dstSet = w->set,
                                            .dstBinding = i, .descriptorCount = 1,
                                            .descriptorType = VK_DESCRIPTOR_TYPE_STORAGE_BUFFER, .pBufferInfo = &infos[i] };
    }
    vkUpdateDescriptorSets(vk->device, VKRT_SHADE_BINDING_COUNT, writes, 0, NULL);
    return VKRT_OK;
}

static void wave_destroy(wave *w)
{
    vk_context *vk = w->vk;
    if (w->pool) vkDestroyDescriptorPool(vk->device, w->pool, NULL);
    gpu_wavefront_tracer_destroy(vk, w->closest);
    gpu_wavefront_tracer_destroy(vk, w->shadow);
    vk_buffer_destroy(vk, &w->paths);
    vk_buffer_destroy(vk, &w->accum);
    vk_buffer_destroy(vk, &w->lights);
    vk_buffer_destroy(vk, &w->lighting);
    vk_buffer_destroy(vk, &w->counters);
    vk_buffer_destroy(vk, &w->queue);
}

static vkrt_result wave_create(wave *w, uint32_t slots)
{
    vk_context *vk = w->vk;
    const gpu_integrate_params *p = w->params;
    /* Host memory before the first pipeline (see gpu_wavefront_tracer_alloc). */
    w->closest = gpu_wavefront_tracer_alloc(vk);
    w->shadow = gpu_wavefront_tracer_alloc(vk);
    if (!w->closest || !w->shadow) return core_fail(vk->core, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for the wavefront");
    vk_trace_pipeline any;
    vkrt_result r = vk_shade_pipeline_get(
        vk, (vk_shade_variant){ VKRT_STAGE_CAMERA, p->mode, p->features, w->scene->split_shift }, &any);
    gpu_trace_rays_params trace = { .traversal = p->traversal, .intersector = p->intersector,
                                    .alpha_tested = p->alpha_tested, .textured = p->textured };
    if (r == VKRT_OK) r = gpu_wavefront_tracer_init(vk, w->closest, w->scene, &trace, slots);
    trace.any_hit = true;
    if (r == VKRT_OK) r = gpu_wavefront_tracer_init(vk, w->shadow, w->scene, &trace, slots);
    const VkBufferUsageFlags storage = VK_BUFFER_USAGE_STORAGE_BUFFER_BIT | VK_BUFFER_USAGE_TRANSFER_DST_BIT;
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (VkDeviceSize)slots * sizeof(vkrt_gpu_path), storage, VK_MEMORY_DEVICE, "vkrt paths",
                             &w->paths);
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (VkDeviceSize)slots * sizeof(vkrt_gpu_accum), storage, VK_MEMORY_READBACK,
                             "vkrt accumulation", &w->accum);
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (VkDeviceSize)slots * 2 * sizeof(uint32_t), storage, VK_MEMORY_DEVICE, "vkrt path queues",
                             &w->queue);
    w->slots = slots;
    const uint32_t light_count = p->lights->count ? p->lights->count : 1;
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, (VkDeviceSize)light_count * sizeof(vkrt_gpu_light), storage, VK_MEMORY_DEVICE,
                             "vkrt lights", &w->lights);
    if (r == VKRT_OK)
        r = vk_buffer_upload(vk, &w->lights, p->lights->lights, (VkDeviceSize)light_count * sizeof(vkrt_gpu_light));
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, sizeof(vkrt_gpu_lighting), storage, VK_MEMORY_DEVICE, "vkrt lighting", &w->lighting);
    if (r == VKRT_OK) r = vk_buffer_upload(vk, &w->lighting, &p->lighting, sizeof p->lighting);
    if (r == VKRT_OK)
        r = vk_buffer_create(vk, sizeof(wave_counters), storage, VK_MEMORY_READBACK, "vkrt wavefront counters",
                             &w->counters);
    if (r == VKRT_OK) {
        /* The ray counts start at zero. */
        const wave_counters zero = { 0 };
        r = vk_buffer_upload(vk, &w->counters, &zero, sizeof zero);
    }
    if (r == VKRT_OK) {
        w->set_layout = any.set_layout;
        w->layout = any.layout;
        r = create_descriptor_set(w);
    }
    return r;
}

/* Everything earlier in the queue (trace passes, stages, fills) is visible to what follows. */
static void record_full_barrier(VkCommandBuffer cmd)
{
    VkMemoryBarrier b = {
        .sType = VK_STRUCTURE_TYPE_MEMORY_BARRIER,
        .srcAccessMask = VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT | VK_ACCESS_HOST_WRITE_BIT,
        .dstAccessMask = VK_ACCESS_SHADER_READ_BIT | VK_ACCESS_SHADER_WRITE_BIT | VK_ACCESS_TRANSFER_WRITE_BIT |
                         VK_ACCESS_HOST_READ_BIT,
    };
    vkCmdPipelineBarrier(cmd,
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT,
                         VK_PIPELINE_STAGE_COMPUTE_SHADER_BIT | VK_PIPELINE_STAGE_TRANSFER_BIT | VK_PIPELINE_STAGE_HOST_BIT,
                         0, 1, &b, 0, NULL, 0, NULL);
}

/* One command buffer of stages over the tile `push` names. */
typedef struct stage_batch {
    VkCommandBuffer cmd;
    bool count_active;
} stage_batch;

static vkrt_result batch_begin(wave *w, stage_batch *b, bool count_active, bool clear_accum)
{
    vkrt_result r = vk_commands_begin(w->vk, &b->cmd);
    if (r != VKRT_OK) return r;
    b->count_active = count_active;
    record_full_barrier(b->cmd);
    if (clear_accum) vkCmdFillBuffer(b->cmd, w->accum.buffer, 0, VK_WHOLE_SIZE, 0);
    if (count_active) vkCmdFillBuffer(b->cmd, w->counters.buffer, 0, 2 * sizeof(uint32_t), 0);
    return VKRT_OK;
}

static vkrt_result batch_stage(wave *w, stage_batch *b, uint32_t stage, vkrt_gpu_push push, uint32_t arg)
{
    vk_trace_pipeline pipe;
    vkrt_result r = vk_shade_pipeline_get(
        w->vk, (vk_shade_variant){ stage, w->params->mode, w->params->features, w->scene->split_shift }, &pipe);
    if (r != VKRT_OK) return r;
    record_full_barrier(b->cmd);
    push.stage_arg = arg;
    vkCmdBindPipeline(b->cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipe.pipeline);
    vkCmdBindDescriptorSets(b->cmd, VK_PIPELINE_BIND_POINT_COMPUTE, pipe.layout, 0, 1, &w->set, 0, NULL);
    vkCmdPushConstants(b->cmd, pipe.layout, VK_SHADER_STAGE_COMPUTE_BIT, 0, sizeof push, &push);
    if (stage == VKRT_STAGE_CAMERA || stage == VKRT_STAGE_FINISH)
        vkCmdDispatch(b->cmd, (push.tile_width + VKRT_TRACE_GROUP_X - 1) / VKRT_TRACE_GROUP_X,
                      (push.tile_height + VKRT_TRACE_GROUP_Y - 1) / VKRT_TRACE_GROUP_Y, 1);
    else if (push.tri_total > 0)
        vkCmdDispatch(b->cmd, (push.tri_total + VKRT_TRACE_GROUP_SIZE - 1) / VKRT_TRACE_GROUP_SIZE, 1, 1);
    return VKRT_OK;
}

/* Submits and waits; *out (may be NULL) gets the counters the batch's stages made. The pacer
 * learns the time: a stage's cost is its pixels', whatever the traversal's chunks. */
static vkrt_result batch_submit(wave *w, stage_batch *b, vkrt_gpu_push push, wave_counters *out)
{
    record_full_barrier(b->cmd);
    const double t0 = core_now_ms();
    vkrt_result r = vk_commands_submit_wait(w->vk, b->cmd);
    if (r == VKRT_OK)
        gpu_pacer_report(&w->pacer, (uint64_t)push.tile_width * push.tile_height * w->chunks, core_now_ms() - t0);
    /* Progress and cancellation between every two submissions. */
    const gpu_wave_progress *p = &w->progress;
    if (r == VKRT_OK && p->progress && !p->progress(p->user, "trace", p->fraction))
        r = core_fail(w->vk->core, VKRT_ERROR_CANCELLED, "render cancelled by the progress callback");
    if (r == VKRT_OK && out) {
        r = vk_buffer_invalidate(w->vk, &w->counters);
        if (r == VKRT_OK) *out = *(const wave_counters *)w->counters.mapped;
    }
    return r;
}

/* One stage alone in a batch. */
static vkrt_result run_stage(wave *w, uint32_t stage, vkrt_gpu_push push, uint32_t arg)
{
    stage_batch b;
    vkrt_result r = batch_begin(w, &b, false, false);
    if (r == VKRT_OK && (r = batch_stage(w, &b, stage, push, arg)) != VKRT_OK) {
        vkFreeCommandBuffers(w->vk->device, w->vk->command_pool, 1, &b.cmd);
        return r;
    }
    return r == VKRT_OK ? batch_submit(w, &b, push, NULL) : r;
}

/* Records stages[0 .. count) into one batch and submits it. */
static vkrt_result run_stages(wave *w, const uint32_t *stages, const uint32_t *args, uint32_t count, vkrt_gpu_push push,
                              bool count_active, bool clear_accum, wave_counters *out)
{
    stage_batch b;
    vkrt_result r = batch_begin(w, &b, count_active, clear_accum);
    for (uint32_t i = 0; r == VKRT_OK && i < count; i++) r = batch_stage(w, &b, stages[i], push, args[i]);
    if (r != VKRT_OK) {
        if (b.cmd) vkFreeCommandBuffers(w->vk->device, w->vk->command_pool, 1, &b.cmd);
        return r;
    }
    return batch_submit(w, &b, push, out);
}

/* The push constants of a stage over the queue at offset `in` with `lanes` entries, writing the
 * queue at offset `out`. */
static vkrt_gpu_push queue_push(vkrt_gpu_push push, uint32_t in, uint32_t out, uint32_t lanes)
{
    push.tri_first = in;
    push.tri_end = out;
    push.tri_total = lanes;
    return push;
}

/* One sample of every pixel of the tile still sampling; *out_started: how many were. The
 * queue buffer holds two queues, swapped after each bounce. */
static vkrt_result run_sample(wave *w, vkrt_gpu_push push, bool first, uint32_t *out_started)
{
    const gpu_integrate_params *p = w->params;
    const uint32_t camera[] = { VKRT_STAGE_CAMERA }, zero[] = { 0 };
    uint32_t in = 0, out = w->slots;
    wave_counters c = { 0 };
    vkrt_result r = run_stages(w, camera, zero, 1, queue_push(push, 0, in, 0), true, first, &c);
    *out_started = c.queued;
    if (r != VKRT_OK || c.queued == 0) return r;
    uint32_t lanes = c.queued;
    if ((r = gpu_wavefront_trace(w->vk, w->closest, w->scene, lanes, &w->pacer, &w->progress, &w->device_ms)) != VKRT_OK) return r;
    if (p->mode == VKRT_MODE_PATH) {
        for (;;) {
            const uint32_t vertex[] = { VKRT_STAGE_VERTEX };
            if ((r = run_stages(w, vertex, zero, 1, queue_push(push, in, out, lanes), true, false, &c)) != VKRT_OK)
                return r;
            if ((r = gpu_wavefront_trace(w->vk, w->shadow, w->scene, lanes, &w->pacer, &w->progress, &w->device_ms)) != VKRT_OK) return r;
            /* Queued paths that ended with a shadow ray are resolved by FINISH: no lane is reused
             * after this pass. */
            if (c.active == 0) break;
            lanes = c.queued;
            uint32_t swap = in;
            in = out;
            out = swap;
            if ((r = gpu_wavefront_trace(w->vk, w->closest, w->scene, lanes, &w->pacer, &w->progress, &w->device_ms)) != VKRT_OK) return r;
        }
        return run_stage(w, VKRT_STAGE_FINISH, push, 0);
    }
    const vkrt_gpu_lighting *l = &p->lighting;
    const uint32_t shadows = p->mode == VKRT_MODE_AO ? l->ao_samples
                                                     : l->punctual_count + (l->emitter_pick > 0.0f ? 1u : 0u);
    const vkrt_gpu_push queued = queue_push(push, in, out, lanes);
    const uint32_t first_stage[] = { shadows ? VKRT_STAGE_HIT_SHADOW : VKRT_STAGE_HIT };
    if ((r = run_stages(w, first_stage, zero, 1, queued, false, false, NULL)) != VKRT_OK) return r;
    for (uint32_t k = 0; k < shadows; k++) {
        if ((r = gpu_wavefront_trace(w->vk, w->shadow, w->scene, lanes, &w->pacer, &w->progress, &w->device_ms)) != VKRT_OK) return r;
        r = k + 1 < shadows ? run_stage(w, VKRT_STAGE_SHADOW, queued, k + 1) : VKRT_OK;
        if (r != VKRT_OK) return r;
    }
    return run_stage(w, VKRT_STAGE_FINISH, push, 0);
}

/* The tile's accumulation as the CPU backend turns it into pixels (cpu_integrate_pixel). */
static void read_tile(const wave *w, vkrt_gpu_push push, float *out_rgba, trace_counts *counts)
{
    const gpu_integrate_params *p = w->params;
    const uint32_t width = p->camera.width;
    const vkrt_gpu_accum *acc = w->accum.mapped;
    for (uint32_t y = 0; y < push.tile_height; y++) {
        for (uint32_t x = 0; x < push.tile_width; x++) {
            const vkrt_gpu_accum *a = &acc[y * push.tile_width + x];
            size_t pixel = (size_t)(push.tile_y + y) * width + push.tile_x + x;
            float n = (float)(a->samples ? a->samples : 1), inv = 1.0f / n;
            float *o = out_rgba + pixel * 4;
            o[0] = a->sum.x * inv, o[1] = a->sum.y * inv, o[2] = a->sum.z * inv, o[3] = a->alpha;
            counts->samples += a->samples;
            if (p->out_error) {
                float mean = a->lum_sum / n;
                float var = n > 1.0f ? (a->lum_sq_sum - n * mean * mean) / (n - 1.0f) : 0.0f;
                p->out_error[pixel] = sqrtf((var > 0.0f ? var : 0.0f) / n);
            }
        }
    }
}

vkrt_result gpu_integrate_render(vk_context *vk, const gpu_scene *scene, const gpu_integrate_params *params,
                                 float *out_rgba, double *out_device_ms, trace_counts *out_counts)
{
    /* shade.comp reads the hit triangles' corners and normals, and the lights'. */
    assert(scene->tris_uploaded && scene->surfaces_uploaded);
    *out_device_ms = 0.0;
    *out_counts = (trace_counts){ 0 };
    const uint32_t width = params->camera.width, height = params->camera.height;
    const uint32_t tile_w = width < WAVE_TILE ? width : WAVE_TILE;
    const uint32_t tile_h = height < WAVE_TILE ? height : WAVE_TILE;
    const bool naive = params->traversal == VKRT_TRAVERSAL_NAIVE;
    wave w = { .vk = vk, .scene = scene, .params = params,
               .chunks = naive ? (scene->tri_count + VKRT_NAIVE_CHUNK_TRIS - 1) / VKRT_NAIVE_CHUNK_TRIS : 1,
               .progress = { params->progress, params->progress_user, 0.0f } };
    gpu_wavefront_pacer(vk, scene, naive, tile_w * tile_h, &w.pacer);
    vkrt_result r = wave_create(&w, tile_w * tile_h);
    const uint32_t tiles_x = (width + tile_w - 1) / tile_w, tiles_y = (height + tile_h - 1) / tile_h;
    const uint32_t tiles = tiles_x * tiles_y;
    const uint32_t spp = (params->features & VKRT_GPU_FEATURE_RANDOM) ? params->lighting.spp : 1u;
    const double pixels = (double)width * height;
    uint64_t done = 0;
    for (uint32_t t = 0; r == VKRT_OK && t < tiles; t++) {
        const uint32_t tx = (t % tiles_x) * tile_w, ty = (t / tiles_x) * tile_h;
        const uint32_t tw = width - tx < tile_w ? width - tx : tile_w, th = height - ty < tile_h ? height - ty : tile_h;
        for (uint32_t x = 0, y = 0; r == VKRT_OK && y < th;) {
            /* The pacer sizes each rectangle from what the last one's submissions took; its
             * samples all run at that size. */
            uint32_t rw, rh;
            gpu_pacer_rect(tw, th, x, y, gpu_pacer_items(&w.pacer, w.chunks), &rw, &rh);
            vkrt_gpu_push push = params->camera;
            push.tile_x = tx + x;
            push.tile_y = ty + y;
            push.tile_width = rw;
            push.tile_height = rh;
            for (uint32_t s = 0; r == VKRT_OK && s < spp; s++) {
                float fraction = (float)(((double)done + (double)rw * rh * s / spp) / pixels);
                w.progress.fraction = fraction;
                if (params->progress && !params->progress(params->progress_user, "trace", fraction)) {
                    r = core_fail(vk->core, VKRT_ERROR_CANCELLED, "render cancelled by the progress callback");
                    break;
                }
                uint32_t started = 0;
                r = run_sample(&w, push, s == 0, &started);
                if (started == 0) break;
            }
            if (r == VKRT_OK) r = vk_buffer_invalidate(vk, &w.accum);
            if (r == VKRT_OK) read_tile(&w, push, out_rgba, out_counts);
            done += (uint64_t)rw * rh;
            x += rw;
            if (x == tw) {
                x = 0;
                y += rh;
            }
        }
    }
    if (r == VKRT_OK && (r = vk_buffer_invalidate(vk, &w.counters)) == VKRT_OK) {
        const wave_counters *c = w.counters.mapped;
        out_counts->shadow_rays = c->shadow_rays;
        out_counts->bounce_rays = c->bounce_rays;
    }
    if (r == VKRT_OK && params->progress) params->progress(params->progress_user, "trace", 1.0f);
    *out_device_ms = w.device_ms;
    out_counts->submissions = w.pacer.submissions;
    out_counts->longest_submission_ms = w.pacer.longest_ms;
    wave_destroy(&w);
    return r;
}
