#include "gpu_pace.h"

#include "../shaders/vkrt_shared.h"

static uint64_t floor_pow2(uint64_t x)
{
    uint64_t p = 1;
    while (p <= x / 2) p *= 2;
    return p;
}

static uint64_t clamp_units(const gpu_pacer *p, uint64_t units)
{
    units = units < p->min_units ? p->min_units : units > p->max_units ? p->max_units : units;
    return floor_pow2(units);
}

void gpu_pacer_init(gpu_pacer *p, double target_ms, uint64_t min_units, uint64_t max_units, uint64_t start,
                    uint32_t grow_after)
{
    *p = (gpu_pacer){ .target_ms = target_ms, .min_units = min_units, .max_units = max_units,
                      .grow_after = grow_after ? grow_after : 1 };
    p->units = clamp_units(p, start);
}

void gpu_pacer_report(gpu_pacer *p, uint64_t units, double ms)
{
    p->submissions++;
    if (ms > p->longest_ms) p->longest_ms = ms;
    if (units == 0) return;
    /* What a submission of the full amount would have taken at this one's rate (a tile's last,
     * narrower piece says as much about the rate as a full one). */
    const double predicted = ms * (double)p->units / (double)units;
    if (predicted > p->target_ms) {
        const double fit = (double)p->units * p->target_ms / predicted;
        p->units = clamp_units(p, fit < 1.0 ? 1u : (uint64_t)fit);
        p->fast = 0;
    } else if (2.0 * predicted < p->target_ms) {
        if (++p->fast >= p->grow_after && p->units < p->max_units) {
            p->units *= 2;
            p->fast = 0;
        }
    } else {
        p->fast = 0;
    }
}

uint64_t gpu_pacer_items(const gpu_pacer *p, uint32_t chunks)
{
    if (chunks < 1) chunks = 1;
    return (p->units + chunks - 1) / chunks;
}

void gpu_pacer_rect(uint32_t tile_w, uint32_t tile_h, uint32_t x, uint32_t y, uint64_t pixels, uint32_t *out_w,
                    uint32_t *out_h)
{
    const uint32_t band = VKRT_TRACE_GROUP_Y;
    if (x == 0 && pixels >= (uint64_t)tile_w * band) {
        const uint64_t rows = pixels / tile_w / band * band;
        *out_w = tile_w;
        *out_h = rows < tile_h - y ? (uint32_t)rows : tile_h - y;
        return;
    }
    uint64_t cols = pixels / band / VKRT_TRACE_GROUP_X * VKRT_TRACE_GROUP_X;
    if (cols < VKRT_TRACE_GROUP_X) cols = VKRT_TRACE_GROUP_X;
    *out_w = cols < tile_w - x ? (uint32_t)cols : tile_w - x;
    *out_h = band < tile_h - y ? band : tile_h - y;
}
