/* Triangle lists for rays that share one origin: see ray_bin.h. The plan:
 *   - serially, the shared origin from the first rays, and the axis from a sample of them;
 *   1. rays: each one's projection (a, b) onto the plane at distance 1 along the axis, whether
 *      it may enter the scene's box (within the box's projection, or the box test), the origin
 *      check, the angle check, and their bounds, which the grid spans; in the first STEP_RAYS
 *      of each item (of a large set), the least steps between rays in turn: where the rays lie
 *      on a lattice (a camera's pixel centres), the grid has a cell a lattice point
 *      (lattice_grid);
 *   2. rays: each one's grid cell, and where in their cells the rays lie;
 *   3. off a lattice, cells, an item a range of them: each cell's bounds of its rays'
 *      projections;
 *   4. triangles, eight at a time: each one's projection, widened, the cells its box may reach
 *      by where the rays lie in theirs (none for a triangle between a lattice's points), and a
 *      count in every cell whose rays' bounds its box and edges may hold; on a lattice, where
 *      every cell's rays lie in one small box about its centre, that box against the edges in
 *      the grid's units, eight triangles together (raster_spans8). Each item its own counters,
 *      and its own range of triangles, taken a chunk at a time (tri_segment_first);
 *   - the counts become each item's write positions (a scan, each item a range of cells);
 * and ray_bin_fill:
 *   5. triangles: each entry written at its position, in the cells the count noted (a triangle
 *      over more than 64 cells projected and tested again).
 * Triangles go to items in ranges, so a cell's list is in the triangles' order. */
#include "ray_bin.h"

#include <math.h>
#include <stdatomic.h>
#include <string.h>

#include "cpu_trace.h"
#include "float4.h"
#include "float8.h"
#include "ray4.h"
#include "ray_cull.h"
#include "work_pool.h"

enum { RAY_ITEM = 16384 }; /* rays a work item of the ray passes */
/* A chunk of the count: about 1/TRI_CHUNKS_PER_ITEM of an item's triangles, at least
 * TRI_CHUNK_MIN. */
enum { TRI_CHUNKS_PER_ITEM = 16, TRI_CHUNK_MIN = 1024 };

/* A projected triangle box is widened by this times (its corners' largest |v - o| over their
 * smallest depth) times (1 + a^2 + b^2) at its farthest corner. The intersection test's sheared
 * coordinates are good to a few ulps of |v - o| (Woop et al. 2013, section 4), an angle of that
 * over the depth; d tan / d angle is 1 + tan^2. 2^-18 is 64 float ulps: some sixteen times what
 * the watertight test can be off by. */
#define WIDEN_ULPS 0x1p-18

typedef struct frame {
    double o[3];       /* the shared origin */
    double f[3];       /* unit axis */
    double r[3], u[3]; /* unit, orthogonal to f and to each other */
    float4 o4[3], f4[3], r4[3], u4[3]; /* each component in all four lanes, for the triangles */
} frame;

typedef struct grid {
    float a0, b0;    /* the rays' smallest projections */
    float sa, sb;    /* cells per unit */
    uint32_t gx, gy; /* cells across and down */
    uint32_t stride; /* cells a row in memory: gx rounded up to a multiple of 4, the cells past
                        gx empty, so that a row's cells come in aligned blocks of four */
    uint32_t cells;  /* stride * gy */
} grid;

/* What one item of the ray pass found. */
typedef struct ray_item_result {
    double bounds[4]; /* a min, a max, b min, b max */
    uint32_t valid;
    float step[2]; /* the least |difference| of a and of b past their rounding between rays in
                      turn */
    float offset[4]; /* of the rays' cells pass: where in their cells the rays lie, in cells (a
                        min, a max, b min, b max of c - x of rays_cell4's c and column x, and of
                        b's c and row) */
    bool origin_differs, wide_angle;
    bool tmin_positive; /* a ray that gets a cell starts past its origin (tmin > 0): no culling */
} ray_item_result;

/* The plan's larger arrays, each with the bytes it holds, kept between calls where the caller
 * asks: this host hands memory a process frees back to the VM's host, and clearing the pages
 * again took 15 ms of the full dragon's 60 ms plan for a million rays. */
enum {
    ARRAY_RAY_RESULTS,
    ARRAY_RAY_AB,
    ARRAY_RAY_CELL,
    ARRAY_CELL_BOUNDS,
    ARRAY_CELL_START,
    ARRAY_COUNTS,
    ARRAY_TRI_CELL,
    ARRAY_TRI_CELLS,
    ARRAY_TRI_WIDTH,
    ARRAY_DEPTHS,
    ARRAY_TRI_NEAR,
    ARRAYS
};

struct ray_bin_scratch {
    void *array[ARRAYS];
    size_t bytes[ARRAYS];
};

/* At most this much scratch is kept for the next call. */
#define KEEP_BYTES ((size_t)192 << 20)

struct ray_bin_job {
    bool x86_64_v3;            /* planned by the x86-64-v3 build, whose fill takes it */
    work_pool *pool;
    ray_bin_scratch *scratch;
    ray_bin_scratch **keep;    /* where the scratch goes back (NULL: freed) */
    const vkrt_ray *rays;      /* NULL: the camera's */
    const vkrt_gpu_push *camera;
    uint32_t ray_count;
    const vkrt_gpu_tri *tris;
    uint32_t tri_count;
    const vkrt_gpu_node *box;  /* the scene's: rays that cannot enter it get no cell */
    uint32_t items;            /* of the cell and triangle passes: the pool's threads */
    double min_cos2;           /* the square of the smallest cosine of a ray's angle to the axis */
    frame fr;
    /* The box's projection's bounds, widened (box_projection): a min, a max, b min, b max. */
    float4 box_rect[4];
    grid g;
    /* The least and greatest offset of any ray within its cell, in cells (ray_item_result's):
     * a box reaches a cell's rays only where it reaches that part of the cell. On a lattice of
     * rays (lattice_grid) every ray lies at its cell's centre, and a small triangle between
     * them spans no cell. */
    float offset_min[2], offset_max[2];
    /* On a lattice the rays of cell (x, y) lie in the box of centre (x, y) + ray_centre and half
     * widths ray_half (from the offsets), and the count tests that box against a triangle's edges
     * in the grid's units (cells_raster4): no cell's bounds are read, nor found. */
    bool raster;
    float ray_centre[2], ray_half[2];
    /* On a lattice, where every ray starts at the origin (tmin 0): the lists leave out a triangle
     * wherever it lies wholly behind a triangle that every ray of the cell surely hits, which
     * then takes every such ray's closest hit before it (occlusion culling). Depths are
     * distances along the axis in 65,535 steps over the scene's box (depth_z0 on, depth_scale
     * steps a unit), sixteen bits a cell: half the memory of a float's, which the count and the
     * fill read at random. */
    bool cull;
    float depth_z0, depth_scale;
    uint16_t *depths;          /* per triangle item, a cell each: 65,535 less the farthest step of
                                  the nearest triangle that a ray of the cell surely hits (0:
                                  none found); item 0's the items' together once the scan has
                                  run */
    uint16_t *tri_near;        /* the step no point of the triangle is nearer than */
    ray_item_result *ray_results;
    float *ray_ab;             /* 2 a ray; NaN for a ray that gets no cell */
    uint32_t *ray_cell;
    /* Each cell's bounds of its rays' projections (min > max where it has none), in blocks of
     * four cells: a min, a max, b min and b max of the four, so that a block is four loads from
     * one cache line. */
    float (*cell_block)[4][4]; /* not on a lattice (raster) */
    uint32_t *cell_start;      /* cells + 1 */
    uint32_t *counts;          /* per triangle item, a cell each: its count, then its write
                                  position (item i's at i * cells) */
    uint32_t *tri_cell;        /* the first cell of its span */
    uint64_t *tri_cells;       /* the cells of a span of up to 64 whose rays may hit it (bit
                                  width dy + dx: dy rows below tri_cell, dx right of it) */
    uint8_t *tri_width;        /* the span's width, 0 where it holds over 64 cells: the fill
                                  tests those again */
    uint64_t cell_budget;      /* cells the count may visit before the lists count as too long */
    atomic_uint_fast64_t visited; /* cells the count's chunks visited, those done so far */
    atomic_bool stop;          /* an item found that the lists cannot be built: the rest stop
                                  (so where a corner lies behind the origin and the budget runs
                                  out as well, which the plan reports depends on the threads) */
    uint32_t tri_chunk;        /* triangles a chunk of the count (tri_segment_first) */
    atomic_uint *segment_taken; /* per segment: its chunks taken so far */
    uint32_t *tri_first, *tri_end; /* per triangle item: the triangles it counted (and fills) */
    bool *item_over;           /* a triangle item passed the budget */
    uint64_t *range_sum;       /* per cell item: its cells' entries, then its first entry */
    uint32_t *range_longest;   /* per cell item: its longest list */
    bool *item_behind;         /* a corner lay on or behind the origin's plane */
    uint32_t *entries;
};

static double dot(const double a[3], const double b[3]) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

/* Written out: the library's baseline x86-64 build calls libm for fmin, fmax and floor, and a
 * triangle's projection takes some thirty of them. No NaN reaches these. */
static double min_d(double x, double y) { return x < y ? x : y; }
static double max_d(double x, double y) { return x > y ? x : y; }
static double abs_d(double x) { return x < 0.0 ? -x : x; }

static bool finite3(const float v[3]) { return isfinite(v[0]) && isfinite(v[1]) && isfinite(v[2]); }

/* As the shaders' ray_from_buffer decides it: such a ray misses everything. */
static bool ray_valid(const vkrt_ray *r)
{
    return finite3(r->origin) && finite3(r->dir) && !(r->dir[0] == 0.0f && r->dir[1] == 0.0f && r->dir[2] == 0.0f);
}

/* Ray i of the plan: of the array, or the camera's through pixel (i % width, i / width), made
 * as it is read (cpu_trace_camera_ray: the shader's own, bit for bit). */
static vkrt_ray job_ray(const vkrt_ray *rays, const vkrt_gpu_push *camera, uint32_t i)
{
    if (rays) return rays[i];
    const vkrt_gpu_ray g = cpu_trace_camera_ray(camera, i % camera->width, i / camera->width);
    vkrt_ray r;
    memcpy(&r, &g, sizeof r); /* one layout (api.c asserts it) */
    return r;
}

static uint32_t ray_item_end(const ray_bin_job *j, uint32_t item)
{
    const uint64_t end = (uint64_t)(item + 1) * RAY_ITEM;
    return end < j->ray_count ? (uint32_t)end : j->ray_count;
}

/* The rays' lattice steps (lattice_grid) are sought in the first STEP_RAYS of every ray item
 * where the rays are many, in all of them where they are fewer than STEP_ALL: two rows of a
 * 1024-wide camera's rays in every sixteen, so that a mesh seen in a band of the image has some
 * (the steps are found only between rays in turn that may enter the scene's box, and the rows'
 * step only where two rows of them meet); an eighth of the rays. */
enum { STEP_RAYS = RAY_ITEM / 8, STEP_ALL = 8 * RAY_ITEM };

/* Four rays' (a and b, NaN where they got no cell; those of `keep`) differences from the last
 * ray before each that got a cell (last[], carried on), folded into steps[] where they pass
 * the projections' rounding (some ulps of 1 + |a| + |b|, here 2^-14 of it): rays of one row or
 * column of a lattice differ by that alone. */
static void lattice_steps4(const float av[4], const float bv[4], unsigned keep, float last[2], float4 steps[2])
{
    float before[2][4];
    for (uint32_t k = 0; k < 4; k++) {
        before[0][k] = last[0];
        before[1][k] = last[1];
        last[0] = keep >> k & 1u ? av[k] : last[0];
        last[1] = keep >> k & 1u ? bv[k] : last[1];
    }
    const float *now[2] = { av, bv };
    for (int axis = 0; axis < 2; axis++) {
        const float4 v = f4_load(now[axis]), p = f4_load(before[axis]);
        const float4 d = f4_abs(f4_sub(v, p));
        const float4 noise = f4_mul(f4_set1(0x1p-14f), f4_add(f4_set1(1.0f), f4_add(f4_abs(v), f4_abs(p))));
        steps[axis] = f4_min(steps[axis], f4_select(f4_gt(d, noise), d, f4_set1(INFINITY)));
    }
}

/* Four rays at a time in float4: the projection, the test that keeps rays that cannot enter
 * the scene's box from the device, and for those that may, the origin check and the angle
 * check. Float rounding of a projection is a few ulps of it, as of the triangles' corners: the
 * widening's 64 hold both. */
static void rays_project_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const frame *fr = &j->fr;
    float4 lo_a = f4_set1(INFINITY), hi_a = f4_set1(-INFINITY), lo_b = lo_a, hi_b = hi_a;
    ray_item_result res = { .valid = 0 };
    float last[2] = { NAN, NAN };
    float4 steps[2] = { f4_set1(INFINITY), f4_set1(INFINITY) };
    const float4 min_cos2 = f4_set1((float)j->min_cos2), zero = f4_set1(0.0f), inf = f4_set1(INFINITY);
    for (uint32_t i = item * RAY_ITEM, end = ray_item_end(j, item); i < end; i += 4) {
        const uint32_t lanes = end - i < 4 ? end - i : 4;
        vkrt_ray tail[4];
        const vkrt_ray *r = j->rays ? &j->rays[i] : tail;
        if (lanes < 4 || !j->rays) {
            for (uint32_t k = 0; k < 4; k++) tail[k] = job_ray(j->rays, j->camera, k < lanes ? i + k : i);
            r = tail;
        }
        float4 o[4], d[4];
        ray4_load(r, o, d);
        const float4 dx = d[0], dy = d[1], dz = d[2];
        const float4 z = f4_add(f4_add(f4_mul(dx, fr->f4[0]), f4_mul(dy, fr->f4[1])), f4_mul(dz, fr->f4[2]));
        const float4 len2 = f4_add(f4_add(f4_mul(dx, dx), f4_mul(dy, dy)), f4_mul(dz, dz));
        /* cos of the angle to the axis >= min_cos, squared: no square root. */
        const unsigned near_axis = f4_bits(f4_and(f4_gt(z, zero), f4_ge(f4_mul(z, z), f4_mul(min_cos2, len2))));
        const float4 inv_z = f4_div(f4_set1(1.0f), z);
        const float4 a = f4_mul(f4_add(f4_add(f4_mul(dx, fr->r4[0]), f4_mul(dy, fr->r4[1])), f4_mul(dz, fr->r4[2])), inv_z);
        const float4 b = f4_mul(f4_add(f4_add(f4_mul(dx, fr->u4[0]), f4_mul(dy, fr->u4[1])), f4_mul(dz, fr->u4[2])), inv_z);
        /* Only rays that may enter the scene's box get a cell: the grid spans them alone, and the
         * rays that miss the box (37% of the standard view's) take none. A ray from the shared
         * origin with a finite direction ahead of it may enter the box only where its projection
         * lies within the box's (box_projection); the box test (ray_cull.h, which turns away the
         * rays that are not valid too) answers the others, and the rays within it at too wide
         * an angle, which would turn the lists down. A ray that gets a cell without entering the
         * box only costs its list's tests, which find what the box test would have: nothing. */
        const unsigned same = f4_bits(f4_and(f4_and(f4_eq(o[0], fr->o4[0]), f4_eq(o[1], fr->o4[1])), f4_eq(o[2], fr->o4[2])));
        const unsigned ahead = f4_bits(f4_and(f4_and(f4_lt(f4_abs(dx), inf), f4_lt(f4_abs(dy), inf)),
                                              f4_and(f4_lt(f4_abs(dz), inf), f4_gt(z, zero))));
        const unsigned within = f4_bits(f4_and(f4_and(f4_ge(a, j->box_rect[0]), f4_le(a, j->box_rect[1])),
                                               f4_and(f4_ge(b, j->box_rect[2]), f4_le(b, j->box_rect[3]))));
        const unsigned lane_mask = (1u << lanes) - 1, quick = same & ahead;
        const unsigned full = lane_mask & (~quick | (within & ~near_axis));
        const unsigned enters = ((quick & within & ~full) | (full ? ray_cull_test4(r, j->box) & full : 0u)) & lane_mask;
        res.origin_differs |= (enters & ~same) != 0;
        res.wide_angle |= (enters & ~near_axis) != 0;
        const unsigned keep = enters & near_axis;
        for (uint32_t k = 0; k < lanes; k++) res.tmin_positive |= (keep >> k & 1u) && r[k].tmin > 0.0f;
        const float4 kept = f4_mask(keep);
        const float4 nan = f4_set1(NAN);
        float av[4], bv[4];
        f4_store(av, f4_select(kept, a, nan));
        f4_store(bv, f4_select(kept, b, nan));
        for (uint32_t k = 0; k < lanes; k++) {
            j->ray_ab[2 * (i + k)] = av[k];
            j->ray_ab[2 * (i + k) + 1] = bv[k];
        }
        if (j->ray_count < STEP_ALL || i - item * RAY_ITEM < STEP_RAYS) lattice_steps4(av, bv, keep, last, steps);
        lo_a = f4_min(lo_a, f4_select(kept, a, f4_set1(INFINITY)));
        hi_a = f4_max(hi_a, f4_select(kept, a, f4_set1(-INFINITY)));
        lo_b = f4_min(lo_b, f4_select(kept, b, f4_set1(INFINITY)));
        hi_b = f4_max(hi_b, f4_select(kept, b, f4_set1(-INFINITY)));
        res.valid += (uint32_t)__builtin_popcount(keep);
    }
    float lanes4[4][4];
    f4_store(lanes4[0], lo_a);
    f4_store(lanes4[1], hi_a);
    f4_store(lanes4[2], lo_b);
    f4_store(lanes4[3], hi_b);
    res.bounds[0] = res.bounds[2] = INFINITY;
    res.bounds[1] = res.bounds[3] = -INFINITY;
    for (int k = 0; k < 4; k++) {
        res.bounds[0] = min_d(res.bounds[0], lanes4[0][k]);
        res.bounds[1] = max_d(res.bounds[1], lanes4[1][k]);
        res.bounds[2] = min_d(res.bounds[2], lanes4[2][k]);
        res.bounds[3] = max_d(res.bounds[3], lanes4[3][k]);
    }
    res.step[0] = f4_min_lane(steps[0]);
    res.step[1] = f4_min_lane(steps[1]);
    j->ray_results[item] = res;
}

/* A projected coordinate in the grid's units along one axis: c = (x - x0) * scale. The rays'
 * cells and offsets and the triangles' spans take it from here alike, so that it is monotonic
 * between them (a box's lo <= a ray's a gives c(lo) <= c(a)). */
static float4 grid_coord4(float4 x, float x0, float scale) { return f4_mul(f4_sub(x, f4_set1(x0)), f4_set1(scale)); }

/* Four rays' cells into cell[0], cell[step], cell[2 step] and cell[3 step]: of c = (a - a0) sa
 * its column, of b's its row, clamped to the grid (truncation is floor from 0 up; MAXPS gives
 * 0 for a NaN, never a conversion of NaN to an integer: a ray without a cell has NaN, and gets
 * RAY_BIN_NO_CELL). Monotonic in a and b, so a box's cells from its ends' cells hold every
 * point's within it. And where in its cell each ray lies, folded into lo and hi (a, b): c less
 * the column or row, exactly (c lies in [x, 2x], Sterbenz, or x is 0). */
static void rays_cell4(const grid *g, float4 a, float4 b, uint32_t *cell, uint32_t step, float4 lo[2], float4 hi[2])
{
    const float4 zero = f4_set1(0.0f), has = f4_eq(a, a);
    const float4 ca = grid_coord4(a, g->a0, g->sa), cb = grid_coord4(b, g->b0, g->sb);
    const float4 x = f4_trunc(f4_min(f4_max(ca, zero), f4_set1((float)(g->gx - 1))));
    const float4 y = f4_trunc(f4_min(f4_max(cb, zero), f4_set1((float)(g->gy - 1))));
    const float4 fa = f4_sub(ca, x), fb = f4_sub(cb, y);
    lo[0] = f4_min(lo[0], f4_select(has, fa, f4_set1(INFINITY)));
    hi[0] = f4_max(hi[0], f4_select(has, fa, f4_set1(-INFINITY)));
    lo[1] = f4_min(lo[1], f4_select(has, fb, f4_set1(INFINITY)));
    hi[1] = f4_max(hi[1], f4_select(has, fb, f4_set1(-INFINITY)));
    int32_t xs[4], ys[4];
    f4_truncate(x, xs);
    f4_truncate(y, ys);
    const unsigned with = f4_bits(has);
    for (uint32_t k = 0; k < 4; k++)
        cell[k * step] = with >> k & 1u ? (uint32_t)ys[k] * g->stride + (uint32_t)xs[k] : RAY_BIN_NO_CELL;
}

static void rays_cell_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const grid *g = &j->g;
    float4 lo[2] = { f4_set1(INFINITY), f4_set1(INFINITY) }, hi[2] = { f4_set1(-INFINITY), f4_set1(-INFINITY) };
    uint32_t i = item * RAY_ITEM;
    const uint32_t end = ray_item_end(j, item);
    for (; end - i >= 8; i += 8) {
        /* Eight rays' (a, b) pairs as four rows, transposed: the even rays' a and b, the odd
         * rays' a and b. */
        float4 rows[4];
        for (int k = 0; k < 4; k++) rows[k] = f4_load(&j->ray_ab[2 * i + 4 * k]);
        f4_transpose(rows);
        rays_cell4(g, rows[0], rows[1], &j->ray_cell[i], 2, lo, hi);
        rays_cell4(g, rows[2], rows[3], &j->ray_cell[i + 1], 2, lo, hi);
    }
    for (; i < end; i++) {
        uint32_t cell[4];
        rays_cell4(g, f4_set1(j->ray_ab[2 * i]), f4_set1(j->ray_ab[2 * i + 1]), cell, 1, lo, hi);
        j->ray_cell[i] = cell[0];
    }
    float *offset = j->ray_results[item].offset;
    offset[0] = f4_min_lane(lo[0]);
    offset[1] = -f4_min_lane(f4_sub(f4_set1(0.0f), hi[0]));
    offset[2] = f4_min_lane(lo[1]);
    offset[3] = -f4_min_lane(f4_sub(f4_set1(0.0f), hi[1]));
}

static uint32_t cell_item_first(const ray_bin_job *j, uint32_t item)
{
    /* Whole blocks of four: an item clears and bounds its own (cells is a multiple of 4). */
    return (uint32_t)((uint64_t)j->g.cells * item / j->items) & ~3u;
}

/* Each item owns a range of whole blocks of cells and reads every ray's cell: no two items
 * write one block. */
static void cells_bound_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const uint32_t first = cell_item_first(j, item), end = cell_item_first(j, item + 1);
    for (uint32_t b = first / 4; b < end / 4; b++)
        for (int k = 0; k < 4; k++) {
            j->cell_block[b][0][k] = j->cell_block[b][2][k] = INFINITY;
            j->cell_block[b][1][k] = j->cell_block[b][3][k] = -INFINITY;
        }
    for (uint32_t i = 0; i < j->ray_count; i++) {
        const uint32_t c = j->ray_cell[i];
        if (c < first || c >= end) continue; /* RAY_BIN_NO_CELL too */
        float(*b)[4] = j->cell_block[c / 4];
        const uint32_t k = c % 4;
        const float x = j->ray_ab[2 * i], y = j->ray_ab[2 * i + 1];
        b[0][k] = x < b[0][k] ? x : b[0][k];
        b[1][k] = x > b[1][k] ? x : b[1][k];
        b[2][k] = y < b[2][k] ? y : b[2][k];
        b[3][k] = y > b[3][k] ? y : b[3][k];
    }
}

/* The scan's first half: the entries of the item's range of cells, and its longest list. A
 * block of four cells at a time (an item's range is whole blocks), which the compiler keeps in
 * vector registers. */
static void cells_sum_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const uint32_t cells = j->g.cells, first = cell_item_first(j, item), end = cell_item_first(j, item + 1);
    uint64_t sum = 0, longest = 0;
    for (uint32_t c = first; c < end; c += 4) {
        uint64_t n[4] = { 0, 0, 0, 0 };
        for (uint32_t i = 0; i < j->items; i++)
            for (int k = 0; k < 4; k++) n[k] += j->counts[(size_t)i * cells + c + k];
        for (int k = 0; k < 4; k++) {
            sum += n[k];
            longest = n[k] > longest ? n[k] : longest;
        }
    }
    j->range_sum[item] = sum;
    j->range_longest[item] = longest > UINT32_MAX ? UINT32_MAX : (uint32_t)longest;
}

/* The scan's second half, once the totals passed the limits: each cell's first entry, and each
 * triangle item's write position in it. The items of a pair (tri_segment_first) write from the
 * end of the first one's part, the first backwards over its triangles from the last, the second
 * forwards: whatever each leaves out (occlusion culling), the pair's entries lie together, in
 * the triangles' order. Most cells of a view hold no entry (three in four of the standard
 * view's): a block of four without one writes its first entries alone, its positions left at 0
 * (the fill reads no position of a cell without entries). Culling, the items' depths go into
 * item 0's. */
static void cells_place_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const uint32_t cells = j->g.cells, first = cell_item_first(j, item), end = cell_item_first(j, item + 1);
    uint32_t at = (uint32_t)j->range_sum[item];
    for (uint32_t c = first; c < end; c += 4) {
        uint32_t any = 0;
        for (uint32_t i = 0; i < j->items; i++)
            for (int k = 0; k < 4; k++) any |= j->counts[(size_t)i * cells + c + k];
        if (!any) {
            for (int k = 0; k < 4; k++) j->cell_start[c + k] = at;
            continue;
        }
        for (uint32_t k = 0; k < 4; k++) {
            j->cell_start[c + k] = at;
            for (uint32_t i = 0; i < j->items; i += 2) {
                uint32_t *count = &j->counts[(size_t)i * cells + c + k];
                const uint32_t n = count[0], m = i + 1 < j->items ? count[cells] : 0;
                count[0] = at + n;
                if (i + 1 < j->items) count[cells] = at + n;
                at += n + m;
            }
            if (j->cull)
                for (uint32_t i = 1; i < j->items; i++) {
                    const uint16_t d = j->depths[(size_t)i * cells + c + k];
                    if (d > j->depths[c + k]) j->depths[c + k] = d;
                }
        }
    }
}

/* Eight projected triangles as the cells test them, a lane each: the widened box, the cells it
 * spans and, where a triangle is wide enough for its orientation to be sure, its three edges
 * moved outwards by the widening and the rounding of these tests (inward normals n and offsets
 * c: a point p may lie in the triangle only where n . p >= c for all three; elsewhere n = 0 and
 * c = -infinity, which every cell passes). A detailed mesh's triangle covers about half its
 * box: the edges took 2.5 times fewer entries than boxes alone on the dragons. */
typedef struct projected8 {
    float box[4][8];        /* a min, a max, b min, b max */
    int32_t span[4][8];     /* the box's first and last column, first and last row */
    float across[2][8];     /* the span's columns and rows (not over 0 where it holds no cell) */
    float nx[3][8], ny[3][8], c[3][8];
    /* The edges moved inwards as c is outwards: a point p with n . p >= c_in for all three lies
     * in the triangle with every ray of its cell (+infinity where the edges are not sure). */
    float c_in[3][8];
    /* Culling: the steps of depth no point of the triangle is nearer than, and 65,535 less the
     * step none is farther than. */
    int32_t near_step[8], far_key[8];
} projected8;

/* grid_coord4 eight lanes at a time: the same bits lane for lane. */
static float8 grid_coord8(float8 x, float x0, float scale) { return f8_mul(f8_sub(x, f8_set1(x0)), f8_set1(scale)); }

/* The first and last cell columns (or rows) whose rays boxes from x to y (projected, eight at a
 * time) may reach, clamped to the grid: cell k's rays lie at k + offset_min .. k + offset_max
 * in the grid's units (grid_coord4's c), so k from c(x) - offset_max up to
 * c(y) - offset_min, with room for the rounding of these differences (eight ulps of them, and
 * 2^-8 of a cell). The last is first - 1 (or -1) where no cell is reached; a NaN counts as 0 (a
 * corner all but on the origin's plane, which the plan turns away): MAXPS gives its second
 * operand for it. The first also as a float (first_f), and the cells from first to last
 * (across). */
static void spans_of8(float8 x, float8 y, float x0, float scale, uint32_t cells, float offset_min,
                      float offset_max, int32_t first[8], int32_t last[8], float8 *first_f, float across[8])
{
    const float8 zero = f8_set1(0.0f), top = f8_set1((float)(cells - 1)), one = f8_set1(1.0f);
    const float8 dx = f8_sub(grid_coord8(x, x0, scale), f8_set1(offset_max));
    const float8 dy = f8_sub(grid_coord8(y, x0, scale), f8_set1(offset_min));
    const float8 slack_x = f8_add(f8_set1(0x1p-8f), f8_mul(f8_abs(dx), f8_set1(0x1p-20f)));
    const float8 slack_y = f8_add(f8_set1(0x1p-8f), f8_mul(f8_abs(dy), f8_set1(0x1p-20f)));
    const float8 v = f8_sub(dx, slack_x), w = f8_add(dy, slack_y);
    const float8 vc = f8_min(f8_max(v, zero), top), wc = f8_min(f8_max(w, zero), top);
    const float8 down = f8_trunc(vc); /* vc >= 0: its floor */
    *first_f = f8_add(down, f8_and(f8_lt(down, vc), one));
    const float8 last_f = f8_select(f8_lt(w, zero), f8_set1(-1.0f), f8_trunc(wc));
    f8_truncate(*first_f, first);
    f8_truncate(last_f, last);
    f8_store(across, f8_add(f8_sub(last_f, *first_f), one));
}

/* The edges of eight triangles of corners (px, py) (a lane each), into out's nx, ny and c: inward
 * normals n and offsets c such that a point p may lie in the triangle only where n . p >= c for
 * all three. A corner may be off by tol (per axis); the edges move outwards by that and by
 * `grow` more (per axis: a box of rays of half widths grow about p may reach the triangle). Where
 * a triangle is too thin for its orientation to be sure, n = 0 and c = -infinity, which every
 * point passes. */
static void edges8(const float8 px[3], const float8 py[3], float8 tol_x, float8 tol_y, float8 grow_x, float8 grow_y,
                   projected8 *out)
{
    float8 ex[3], ey[3], perimeter = f8_set1(0.0f);
    for (int k = 0; k < 3; k++) {
        ex[k] = f8_sub(px[(k + 1) % 3], px[k]);
        ey[k] = f8_sub(py[(k + 1) % 3], py[k]);
        perimeter = f8_add(perimeter, f8_add(f8_abs(ex[k]), f8_abs(ey[k])));
    }
    /* (P1 - P0) x (P2 - P0), twice the signed area; every height over four tolerances, so that
     * no rounding of the corners can turn the triangle over. */
    const float8 area2 = f8_sub(f8_mul(ey[0], ex[2]), f8_mul(ex[0], ey[2]));
    const float8 edges = f8_gt(f8_abs(area2), f8_mul(f8_mul(f8_set1(4.0f), f8_max(tol_x, tol_y)), perimeter));
    const float8 side = f8_select(f8_gt(area2, f8_set1(0.0f)), f8_set1(1.0f), f8_set1(-1.0f));
    const float8 out_x = f8_add(tol_x, grow_x), out_y = f8_add(tol_y, grow_y);
    for (int k = 0; k < 3; k++) {
        const float8 nx = f8_mul(f8_sub(f8_set1(0.0f), ey[k]), side), ny = f8_mul(ex[k], side);
        const float8 c = f8_sub(f8_add(f8_mul(nx, px[k]), f8_mul(ny, py[k])),
                                f8_add(f8_mul(out_x, f8_abs(nx)), f8_mul(out_y, f8_abs(ny))));
        f8_store(out->nx[k], f8_and(edges, nx));
        f8_store(out->ny[k], f8_and(edges, ny));
        f8_store(out->c[k], f8_select(edges, c, f8_set1(-INFINITY)));
        const float8 c_in = f8_add(f8_add(f8_mul(nx, px[k]), f8_mul(ny, py[k])),
                                   f8_add(f8_mul(out_x, f8_abs(nx)), f8_mul(out_y, f8_abs(ny))));
        f8_store(out->c_in[k], f8_select(edges, c_in, f8_set1(INFINITY)));
    }
}

/* Each component of a frame's float4 (the same in all four lanes) in all eight. */
static float8 wide8(float4 x) { return f8_join(x, x); }

/* Triangles t .. t + 7 (a lane past `end` repeats triangle t) projected, widened (WIDEN_ULPS)
 * and given their edges, in float. Eight at a time through float8 (one AVX register in the
 * x86-64-v3 build: half the instructions of four at a time, the same bits): a triangle's three
 * corners are rows of vkrt_gpu_tri, four of which transpose into x, y and z. Float rounding of
 * the projection is a few ulps of the same terms the widening's 64 are. The edges are in the
 * projection's units, or on a lattice (raster) in the grid's from the span's first cell's rays'
 * centre. Returns the mask of lanes with a corner on or behind the origin's plane. */
static unsigned project_triangles(const ray_bin_job *j, uint32_t t, uint32_t end, projected8 *out)
{
    const frame *fr = &j->fr;
    const float inf = INFINITY;
    float8 lo_a = f8_set1(inf), hi_a = f8_set1(-inf), lo_b = f8_set1(inf), hi_b = f8_set1(-inf);
    float8 far = f8_set1(0.0f), min_z = f8_set1(inf), max_z = f8_set1(0.0f), max_tan2 = f8_set1(0.0f);
    float8 front = f8_eq(far, far);
    const vkrt_gpu_tri *tri[8];
    for (uint32_t k = 0; k < 8; k++) tri[k] = &j->tris[t + k < end ? t + k : t];
    /* The frame's origin and axes in all eight lanes. */
    const float4 *frame4[4] = { fr->o4, fr->f4, fr->r4, fr->u4 };
    float8 axes[4][3];
    for (int a = 0; a < 4; a++)
        for (int k = 0; k < 3; k++) axes[a][k] = wide8(frame4[a][k]);
    const float8 *o = axes[0], *f = axes[1], *r = axes[2], *u = axes[3];
    float8 pa[3], pb[3];
    for (int corner = 0; corner < 3; corner++) {
        float4 rows[2][4];
        for (int k = 0; k < 8; k++) {
            const vkrt_float3 *v = corner == 0 ? &tri[k]->v0 : corner == 1 ? &tri[k]->v1 : &tri[k]->v2;
            rows[k / 4][k % 4] = f4_load(&v->x); /* x, y, z and the word after them */
        }
        f4_transpose(rows[0]);
        f4_transpose(rows[1]);
        const float8 px = f8_sub(f8_join(rows[0][0], rows[1][0]), o[0]);
        const float8 py = f8_sub(f8_join(rows[0][1], rows[1][1]), o[1]);
        const float8 pz = f8_sub(f8_join(rows[0][2], rows[1][2]), o[2]);
        const float8 z = f8_add(f8_add(f8_mul(px, f[0]), f8_mul(py, f[1])), f8_mul(pz, f[2]));
        front = f8_and(front, f8_gt(z, f8_set1(0.0f)));
        const float8 inv_z = f8_div(f8_set1(1.0f), z);
        const float8 a = f8_mul(f8_add(f8_add(f8_mul(px, r[0]), f8_mul(py, r[1])), f8_mul(pz, r[2])), inv_z);
        const float8 b = f8_mul(f8_add(f8_add(f8_mul(px, u[0]), f8_mul(py, u[1])), f8_mul(pz, u[2])), inv_z);
        pa[corner] = a;
        pb[corner] = b;
        lo_a = f8_min(lo_a, a);
        hi_a = f8_max(hi_a, a);
        lo_b = f8_min(lo_b, b);
        hi_b = f8_max(hi_b, b);
        far = f8_max(far, f8_max(f8_abs(px), f8_max(f8_abs(py), f8_abs(pz))));
        min_z = f8_min(min_z, z);
        max_z = f8_max(max_z, z);
        max_tan2 = f8_max(max_tan2, f8_add(f8_mul(a, a), f8_mul(b, b)));
    }
    const float8 widen =
        f8_mul(f8_mul(f8_set1((float)WIDEN_ULPS), f8_div(far, min_z)), f8_add(f8_set1(1.0f), max_tan2));
    const float8 box[4] = { f8_sub(lo_a, widen), f8_add(hi_a, widen), f8_sub(lo_b, widen), f8_add(hi_b, widen) };
    const grid *g = &j->g;
    for (int k = 0; k < 4; k++) f8_store(out->box[k], box[k]);
    /* A corner's depth in float is off by a few ulps of its coordinates (far); the room, 2^-14
     * of far, also keeps a culled triangle's hits beyond any rounding of the closer one's
     * distance. */
    const float8 room = f8_mul(far, f8_set1(0x1p-14f));
    if (j->cull) {
        /* In steps, a step more each way than their rounding. */
        const float8 z0 = f8_set1(j->depth_z0), scale = f8_set1(j->depth_scale), zero = f8_set1(0.0f);
        const float8 top = f8_set1(65535.0f), one = f8_set1(1.0f);
        const float8 near = f8_max(f8_mul(f8_sub(f8_sub(min_z, room), z0), scale), zero);
        const float8 far_steps = f8_min(f8_max(f8_mul(f8_sub(f8_add(max_z, room), z0), scale), zero), top);
        const float8 near_step = f8_max(f8_sub(f8_trunc(f8_min(near, top)), one), zero);
        const float8 far_step = f8_min(f8_add(f8_add(f8_trunc(far_steps), one), one), top);
        f8_truncate(near_step, out->near_step);
        f8_truncate(f8_sub(top, far_step), out->far_key);
    } else {
        memset(out->near_step, 0, sizeof out->near_step);
        memset(out->far_key, 0, sizeof out->far_key);
    }
    float8 first_x, first_y;
    spans_of8(box[0], box[1], g->a0, g->sa, g->gx, j->offset_min[0], j->offset_max[0], out->span[0], out->span[1],
              &first_x, out->across[0]);
    spans_of8(box[2], box[3], g->b0, g->sb, g->gy, j->offset_min[1], j->offset_max[1], out->span[2], out->span[3],
              &first_y, out->across[1]);
    const float8 zero = f8_set1(0.0f);
    if (!j->raster) {
        /* Distances within `tolerance` of the triangle count as inside: the widening, and the
         * rounding of the edge terms (a few ulps of the coordinates' size), with room. */
        float8 reach = f8_set1(1.0f);
        for (int k = 0; k < 3; k++) reach = f8_max(reach, f8_max(f8_abs(pa[k]), f8_abs(pb[k])));
        const float8 tolerance = f8_add(widen, f8_mul(f8_set1(0x1p-19f), reach));
        edges8(pa, pb, tolerance, tolerance, zero, zero, out);
    } else {
        /* The corners in the grid's units (grid_coord8, as grid_coord4 found the rays' cells),
         * from the centre of the rays' box in the span's first cell: the cells' rays then lie at
         * whole steps (dx, dy) from it, within ray_half. A corner's widening scales by the grid's
         * cells per unit. The grid coordinates of a corner and of a ray are off by their
         * rounding, under 2^-23 of their size, which no point of the triangle passes the
         * corners' (reach); the edge terms' rounding is some ulps of the corners' distance from
         * the centre (near). */
        float8 lx[3], ly[3], reach = f8_set1(1.0f), near = f8_set1(1.0f);
        const float8 cx = f8_add(first_x, f8_set1(j->ray_centre[0])), cy = f8_add(first_y, f8_set1(j->ray_centre[1]));
        for (int k = 0; k < 3; k++) {
            const float8 gx = grid_coord8(pa[k], g->a0, g->sa), gy = grid_coord8(pb[k], g->b0, g->sb);
            reach = f8_max(reach, f8_max(f8_abs(gx), f8_abs(gy)));
            lx[k] = f8_sub(gx, cx);
            ly[k] = f8_sub(gy, cy);
            near = f8_max(near, f8_max(f8_abs(lx[k]), f8_abs(ly[k])));
        }
        const float8 rounding = f8_add(f8_mul(f8_set1(0x1p-20f), reach), f8_mul(f8_set1(0x1p-18f), near));
        const float8 tol_x = f8_add(f8_mul(widen, f8_set1(g->sa)), rounding);
        const float8 tol_y = f8_add(f8_mul(widen, f8_set1(g->sb)), rounding);
        edges8(lx, ly, tol_x, tol_y, f8_set1(j->ray_half[0]), f8_set1(j->ray_half[1]), out);
    }
    return ~f8_bits(front) & 0xFFu;
}

/* The count's items share the triangles out as they go, so that a thread held up (two cores
 * of a shared host, where the standard view's count took one item 3.7 ms longer than the other
 * in half the calls of the full dragon, 12 ms in a quarter) leaves its work to the other; and
 * each item's triangles stay one range, the ranges in the items' order, so that a cell's list
 * is in the triangles' order whoever counted them. The items go in pairs, each pair a segment of
 * the triangles (the last item alone where they are odd in number, on half as many): the first
 * takes the segment's chunks from its start on, the second from its end back, until they meet. */
static uint32_t tri_segment_first(const ray_bin_job *j, uint32_t segment)
{
    const uint64_t item = 2ull * segment;
    return (uint32_t)((uint64_t)j->tri_count * (item < j->items ? item : j->items) / j->items);
}

/* One lane of a projected8, the triangle the cells test, in all four lanes; and its span. */
typedef struct tri_test {
    float4 box[4];
    float4 nx[3], ny[3], c[3];
    float4 c_in[3];   /* projected8's, the edges moved inwards */
    uint16_t far_key; /* projected8's, culling */
    uint32_t x0, x1, y0, y1;
} tri_test;

static void tri_test_of(const projected8 *p, uint32_t lane, tri_test *t)
{
    for (int k = 0; k < 4; k++) t->box[k] = f4_set1(p->box[k][lane]);
    for (int k = 0; k < 3; k++) {
        t->nx[k] = f4_set1(p->nx[k][lane]);
        t->ny[k] = f4_set1(p->ny[k][lane]);
        t->c[k] = f4_set1(p->c[k][lane]);
        t->c_in[k] = f4_set1(p->c_in[k][lane]);
    }
    t->far_key = (uint16_t)p->far_key[lane];
    t->x0 = (uint32_t)p->span[0][lane];
    t->x1 = (uint32_t)p->span[1][lane];
    t->y0 = (uint32_t)p->span[2][lane];
    t->y1 = (uint32_t)p->span[3][lane];
}

/* Which of the four cells of block `block` may hold rays that hit triangle t: bit k for its
 * cell k. A cell may
 * where the box of its rays' projections meets the triangle's, and no edge of it has the whole
 * box outside: n . p is largest over the box at the corner whose coordinates n's signs pick,
 * max(n.x a min, n.x a max) + max(n.y b min, n.y b max). Four cells at a time without a branch:
 * a row of a span a mask at a time. */
static unsigned cells_may_hit4(const ray_bin_job *j, size_t block, const tri_test *t)
{
    const float(*b)[4] = j->cell_block[block];
    const float4 lo_a = f4_load(b[0]), hi_a = f4_load(b[1]), lo_b = f4_load(b[2]), hi_b = f4_load(b[3]);
    float4 in = f4_and(f4_and(f4_le(lo_a, t->box[1]), f4_ge(hi_a, t->box[0])),
                       f4_and(f4_le(lo_b, t->box[3]), f4_ge(hi_b, t->box[2])));
    for (int k = 0; k < 3; k++) {
        const float4 x = f4_max(f4_mul(t->nx[k], lo_a), f4_mul(t->nx[k], hi_a));
        const float4 y = f4_max(f4_mul(t->ny[k], lo_b), f4_mul(t->ny[k], hi_b));
        in = f4_and(in, f4_ge(f4_add(x, y), t->c[k]));
    }
    return f4_bits(in);
}

/* Which of four cells (dx, dy) from the first of t's span, on a lattice (raster), pass t's edges
 * in the grid's units (project_triangles) moved to offsets c (t's c, or c_in for the cells whose
 * rays surely hit it): bit k for lane k's. t's box goes unread: the spans hold it. */
static unsigned cells_raster4(const tri_test *t, const float4 c[3], float4 dx, float4 dy)
{
    float4 in = f4_eq(dx, dx);
    for (int k = 0; k < 3; k++) in = f4_and(in, f4_ge(f4_add(f4_mul(t->nx[k], dx), f4_mul(t->ny[k], dy)), c[k]));
    return f4_bits(in);
}

/* On a lattice, the cells of row y, columns x0 .. x1 (at most 64), that pass t's edges moved to
 * offsets c: bit x - x0, the bits past x1 left in. */
static uint64_t row_raster(const tri_test *t, const float4 c[3], uint32_t y, uint32_t x0, uint32_t x1)
{
    uint64_t bits = 0;
    const float4 dy = f4_set1((float)(y - t->y0)), steps = f4_set(0.0f, 1.0f, 2.0f, 3.0f);
    for (uint32_t x = x0; x <= x1; x += 4)
        bits |= (uint64_t)cells_raster4(t, c, f4_add(f4_set1((float)(x - t->x0)), steps), dy) << (x - x0);
    return bits;
}

/* The cells of row y, columns x0 .. x1 (at most 64), that may hold rays that hit t: bit
 * x - x0. */
static uint64_t row_may_hit(const ray_bin_job *j, const tri_test *t, uint32_t y, uint32_t x0, uint32_t x1)
{
    uint64_t bits = 0;
    if (j->raster) {
        bits = row_raster(t, t->c, y, x0, x1);
    } else {
        /* From the block that holds x0: its cells before x0 shifted out. */
        const size_t row = (size_t)y * j->g.stride;
        bits = cells_may_hit4(j, (row + x0) / 4, t) >> (x0 % 4);
        for (uint32_t x = (x0 | 3u) + 1; x <= x1; x += 4)
            bits |= (uint64_t)cells_may_hit4(j, (row + x) / 4, t) << (x - x0);
    }
    const uint32_t width = x1 - x0 + 1;
    return width >= 64 ? bits : bits & ((1ull << width) - 1);
}

/* ceil(2^16 / w) for spans w = 1 .. 64 cells wide: bit b of a span's mask lies (b * it) >> 16
 * rows down, exactly for b < 64 (b / w is short of the next integer by 1 / w at least, the
 * rounding adds under 64 / 2^16), without a division an entry. */
#define SPAN_RECIP(w) ((65536u + (w) - 1u) / (w))
#define SPAN_RECIP8(w) SPAN_RECIP(w), SPAN_RECIP(w + 1u), SPAN_RECIP(w + 2u), SPAN_RECIP(w + 3u), \
    SPAN_RECIP(w + 4u), SPAN_RECIP(w + 5u), SPAN_RECIP(w + 6u), SPAN_RECIP(w + 7u)
static const uint32_t span_recip[65] = { 0, SPAN_RECIP8(1u), SPAN_RECIP8(9u), SPAN_RECIP8(17u), SPAN_RECIP8(25u),
                                         SPAN_RECIP8(33u), SPAN_RECIP8(41u), SPAN_RECIP8(49u), SPAN_RECIP8(57u) };

/* The cell of bit `bit` of a span `width` cells wide, from its first cell. */
static uint32_t span_cell(uint32_t bit, uint32_t width, uint32_t stride)
{
    const uint32_t dy = (bit * span_recip[width]) >> 16;
    return dy * stride + (bit - dy * width);
}

/* Culling: a cell whose rays surely hit a triangle keeps the nearest such triangle's depth (the
 * greatest key, 65,535 less its farthest step). */
static void keep_nearer(uint16_t *depth, uint16_t key) { *depth = key > *depth ? key : *depth; }

/* Counts triangle t (test `s`) into the cells whose rays may hit it; false where *visited
 * passes `budget`. Culling (depths not NULL), the cells of its rows whose rays surely hit it
 * keep its depth. */
static bool count_triangle(ray_bin_job *j, uint32_t t, const tri_test *s, uint32_t *count, uint16_t *depths,
                           uint64_t *visited, uint64_t budget)
{
    const grid *g = &j->g;
    const uint32_t width = s->x1 - s->x0 + 1, height = s->y1 - s->y0 + 1;
    const uint32_t first = s->y0 * g->stride + s->x0;
    j->tri_cell[t] = first;
    if ((uint64_t)width * height <= 64) {
        /* A detailed mesh's triangles span up to 64 cells (the long thin ones of a decimated
         * mesh many in one direction): the cells whose rays may hit noted for the fill (bit
         * width dy + dx), which then neither projects nor tests again. */
        uint64_t cells = 0;
        for (uint32_t dy = 0; dy < height; dy++) cells |= row_may_hit(j, s, s->y0 + dy, s->x0, s->x1) << (dy * width);
        /* One loop over the span's cells, not one a row: most rows hold none. */
        for (uint64_t left = cells; left; left &= left - 1)
            count[first + span_cell((uint32_t)__builtin_ctzll(left), width, g->stride)]++;
        j->tri_cells[t] = cells;
        j->tri_width[t] = (uint8_t)width;
        *visited += (uint64_t)width * height;
        return true;
    }
    j->tri_width[t] = 0;
    /* A triangle that covers much of the view visits every cell there: a scene of many such is
     * no case for lists. */
    *visited += (uint64_t)width * height;
    if (*visited > budget) return false;
    for (uint32_t y = s->y0; y <= s->y1; y++)
        for (uint32_t x0 = s->x0; x0 <= s->x1; x0 += 64) {
            const uint32_t x1 = s->x1 - x0 < 64 ? s->x1 : x0 + 63;
            const size_t row_first = (size_t)y * g->stride + x0;
            const uint64_t may = row_may_hit(j, s, y, x0, x1);
            for (uint64_t row = may; row; row &= row - 1) count[row_first + __builtin_ctzll(row)]++;
            if (!depths) continue;
            /* Culling (a lattice's): the cells whose rays surely hit it, as count_raster8's. */
            for (uint64_t sure = row_raster(s, s->c_in, y, x0, x1) & may; sure; sure &= sure - 1)
                keep_nearer(&depths[row_first + __builtin_ctzll(sure)], s->far_key);
        }
    return true;
}

/* The 8 x 8 bit matrix of bit 8 r + c at row r, column c, transposed (Hacker's Delight, 7-3). */
static uint64_t transpose_bits8(uint64_t x)
{
    uint64_t t = (x ^ (x >> 7)) & 0x00AA00AA00AA00AAull;
    x ^= t ^ (t << 7);
    t = (x ^ (x >> 14)) & 0x0000CCCC0000CCCCull;
    x ^= t ^ (t << 14);
    t = (x ^ (x >> 28)) & 0x00000000F0F0F0F0ull;
    return x ^ t ^ (t << 28);
}

/* On a lattice (raster), the cells of the spans of p's lanes (lane k's w[k] wide and n[k] cells,
 * at most 64; none where n[k] is 0) that pass their edges: as count_triangle's masks (bit
 * width dy + dx), into cells[].
 * The eight triangles go together, a cell of each a step, so that a span's shape takes no
 * branch: most of a detailed mesh's are of one to four cells, in no order. */
static void raster_spans8(const projected8 *p, float8 w, float8 n, uint64_t cells[8], uint64_t inner[8])
{
    /* The most cells of a lane: n's largest, the least of -n. */
    const uint32_t most = (uint32_t)-f8_min_lane(f8_sub(f8_set1(0.0f), n));
    for (uint32_t k = 0; k < 8; k++) cells[k] = inner[k] = 0;
    float8 nx[3], ny[3], c[3], c_in[3];
    for (int k = 0; k < 3; k++) {
        nx[k] = f8_load(p->nx[k]);
        ny[k] = f8_load(p->ny[k]);
        c[k] = f8_load(p->c[k]);
        c_in[k] = f8_load(p->c_in[k]);
    }
    const float8 one = f8_set1(1.0f);
    float8 dx = f8_set1(0.0f), dy = dx, at = dx;
    uint64_t steps = 0, steps_in = 0;
    for (uint32_t i = 0; i < most; i++) {
        /* cells_raster4's test, a lane a triangle; and whether the cell's rays surely hit it. */
        const float8 span = f8_lt(at, n);
        float8 in = span, sure = span;
        for (int k = 0; k < 3; k++) {
            const float8 e = f8_add(f8_mul(nx[k], dx), f8_mul(ny[k], dy));
            in = f8_and(in, f8_ge(e, c[k]));
            sure = f8_and(sure, f8_ge(e, c_in[k]));
        }
        /* A byte a step; each eight steps' bytes turned into a byte a lane. */
        steps |= (uint64_t)f8_bits(in) << (i % 8 * 8);
        steps_in |= (uint64_t)f8_bits(sure) << (i % 8 * 8);
        if (i % 8 == 7 || i + 1 == most) {
            const uint64_t lanes = transpose_bits8(steps), lanes_in = transpose_bits8(steps_in);
            for (uint32_t k = 0; k < 8; k++) {
                cells[k] |= (lanes >> (k * 8) & 0xFFu) << (i / 8 * 8);
                inner[k] |= (lanes_in >> (k * 8) & 0xFFu) << (i / 8 * 8);
            }
            steps = steps_in = 0;
        }
        at = f8_add(at, one);
        dx = f8_add(dx, one);
        const float8 wrap = f8_ge(dx, w);
        dx = f8_andnot(wrap, dx);
        dy = f8_add(dy, f8_and(wrap, one));
    }
}

/* On a lattice (raster): counts the eight triangles of p (t8 .. t8 + lanes - 1) into `count`,
 * as count_triangle does; false where *visited passes `budget`. Without a branch a triangle but
 * for the rare one over more than 64 cells (count_triangle's) and for its cells past the first. */
static bool count_raster8(ray_bin_job *j, uint32_t t8, uint32_t lanes, const projected8 *p, uint32_t *count,
                          uint16_t *depths, uint64_t *visited, uint64_t budget)
{
    const uint32_t stride = j->g.stride;
    /* The spans' shapes in float (exact: a grid's side is at most 2^22 cells), without a branch
     * or a store a lane: between the rays (no column or no row) no cell, so width 1 and none. */
    const float8 one = f8_set1(1.0f), zero = f8_set1(0.0f);
    const float8 across = f8_load(p->across[0]), down = f8_load(p->across[1]);
    const float8 has = f8_and(f8_mask((1u << lanes) - 1), f8_and(f8_gt(across, zero), f8_gt(down, zero)));
    const float8 n = f8_mul(across, down);
    const float8 small_mask = f8_and(has, f8_le(n, f8_set1(64.0f)));
    const unsigned small = f8_bits(small_mask), big = f8_bits(has) & ~small;
    const float8 w = f8_select(has, across, one), n_small = f8_and(small_mask, n);
    int32_t widths[8], spans[8];
    f8_truncate(w, widths);
    f8_truncate(n_small, spans);
    uint64_t cells[8], inner[8];
    raster_spans8(p, w, n_small, cells, inner);
    for (uint32_t k = 0; k < lanes; k++) {
        const uint32_t t = t8 + k;
        if (j->cull) j->tri_near[t] = (uint16_t)p->near_step[k];
        if (big >> k & 1u) {
            tri_test s;
            tri_test_of(p, k, &s);
            if (!count_triangle(j, t, &s, count, depths, visited, budget)) return false;
            continue;
        }
        const uint32_t cell0 = small >> k & 1u ? (uint32_t)p->span[2][k] * stride + (uint32_t)p->span[0][k] : 0u;
        uint64_t left = cells[k];
        /* The first cell without a branch (most triangles have one or none): none adds 0. */
        const uint32_t width = (uint32_t)widths[k];
        const uint32_t at = cell0 + span_cell((uint32_t)__builtin_ctzll(left | 1ull << 63), width, stride);
        count[left ? at : cell0] += left != 0;
        for (left &= left - 1; left; left &= left - 1)
            count[cell0 + span_cell((uint32_t)__builtin_ctzll(left), width, stride)]++;
        if (j->cull && inner[k]) {
            /* The cells whose rays surely hit it: none finds its closest hit farther away. */
            const uint16_t key = (uint16_t)p->far_key[k];
            for (uint64_t sure = inner[k]; sure; sure &= sure - 1)
                keep_nearer(&depths[cell0 + span_cell((uint32_t)__builtin_ctzll(sure), width, stride)], key);
        }
        j->tri_cell[t] = cell0;
        j->tri_cells[t] = cells[k];
        j->tri_width[t] = (uint8_t)width;
        *visited += (uint32_t)spans[k];
    }
    return true;
}

/* Counts triangles first .. end - 1 into `count`; false, with the item's flag set, where the
 * lists cannot be built. */
static bool count_range(ray_bin_job *j, uint32_t item, uint32_t first, uint32_t end, uint32_t *count, uint16_t *depths)
{
    const uint64_t before = atomic_load_explicit(&j->visited, memory_order_relaxed);
    const uint64_t budget = j->cell_budget > before ? j->cell_budget - before : 0;
    uint64_t visited = 0;
    for (uint32_t t8 = first; t8 < end; t8 += 8) {
        projected8 p;
        const uint32_t lanes = end - t8 < 8 ? end - t8 : 8;
        if (project_triangles(j, t8, end, &p) & ((1u << lanes) - 1)) {
            j->item_behind[item] = true;
            return false;
        }
        if (j->raster) {
            if (!count_raster8(j, t8, lanes, &p, count, depths, &visited, budget)) {
                j->item_over[item] = true;
                return false;
            }
            continue;
        }
        for (uint32_t lane = 0; lane < lanes; lane++) {
            if (p.span[1][lane] < p.span[0][lane] || p.span[3][lane] < p.span[2][lane]) {
                /* Between the rays: no cell. */
                j->tri_cell[t8 + lane] = 0;
                j->tri_cells[t8 + lane] = 0;
                j->tri_width[t8 + lane] = 1;
                continue;
            }
            tri_test s;
            tri_test_of(&p, lane, &s);
            if (!count_triangle(j, t8 + lane, &s, count, NULL, &visited, budget)) {
                j->item_over[item] = true;
                return false;
            }
        }
    }
    if (atomic_fetch_add_explicit(&j->visited, visited, memory_order_relaxed) + visited > j->cell_budget) {
        j->item_over[item] = true;
        return false;
    }
    return true;
}

static void tris_count_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    uint32_t *count = j->counts + (size_t)item * j->g.cells;
    memset(count, 0, (size_t)j->g.cells * sizeof *count);
    uint16_t *depths = j->cull ? j->depths + (size_t)item * j->g.cells : NULL;
    if (depths) memset(depths, 0, (size_t)j->g.cells * sizeof *depths);
    const uint32_t segment = item / 2, start = tri_segment_first(j, segment), end = tri_segment_first(j, segment + 1);
    const uint32_t chunks = core_div_up(end - start, j->tri_chunk);
    const bool backwards = item % 2;
    uint32_t taken = 0; /* this item's chunks */
    while (!atomic_load_explicit(&j->stop, memory_order_relaxed) &&
           atomic_fetch_add_explicit(&j->segment_taken[segment], 1, memory_order_relaxed) < chunks) {
        /* The segment's chunks taken by both come to at most its chunks: no chunk twice. */
        const uint32_t chunk = backwards ? chunks - 1 - taken : taken;
        taken++;
        const uint32_t first = start + chunk * j->tri_chunk;
        const uint32_t last = end - first > j->tri_chunk ? first + j->tri_chunk : end;
        if (!count_range(j, item, first, last, count, depths)) {
            atomic_store_explicit(&j->stop, true, memory_order_relaxed);
            break;
        }
    }
    const uint32_t edge = start + (backwards ? chunks - taken : taken) * j->tri_chunk;
    j->tri_first[item] = backwards ? (edge < end ? edge : end) : start;
    j->tri_end[item] = backwards ? end : (edge < end ? edge : end);
}

/* Triangle t's entry in `cell`, at the position the item's `at` holds there (the first item of a
 * pair writing backwards, the second forwards), unless culling leaves it out: its nearest step
 * (near) past the farthest of the nearest triangle the cell's rays surely hit (65,535 less the
 * cell's depth). */
static void fill_entry(const ray_bin_job *j, uint32_t *at, uint32_t cell, uint32_t near, bool backwards, uint32_t t)
{
    if (j->cull && near + j->depths[cell] > 65535u) return;
    j->entries[backwards ? --at[cell] : at[cell]++] = t;
}

static void tris_fill_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const grid *g = &j->g;
    uint32_t *at = j->counts + (size_t)item * g->cells;
    /* The first item of a pair backwards from its last triangle, the second forwards
     * (cells_place_item). */
    const bool backwards = item % 2 == 0;
    const uint32_t first = j->tri_first[item], end = j->tri_end[item];
    for (uint32_t n = 0; n < end - first; n++) {
        const uint32_t t = backwards ? end - 1 - n : first + n;
        const uint32_t width = j->tri_width[t];
        const uint32_t near = j->cull ? j->tri_near[t] : 0;
        if (width) {
            /* The cells the count noted, in its order. */
            for (uint64_t cells = j->tri_cells[t]; cells; cells &= cells - 1)
                fill_entry(j, at, j->tri_cell[t] + span_cell((uint32_t)__builtin_ctzll(cells), width, g->stride), near,
                           backwards, t);
            continue;
        }
        /* Projected again: lane 0 of eight copies of t, the same bits as its lane in the count. */
        projected8 p;
        project_triangles(j, t, t + 1, &p);
        tri_test s;
        tri_test_of(&p, 0, &s);
        for (uint32_t y = s.y0; y <= s.y1; y++)
            for (uint32_t x0 = s.x0; x0 <= s.x1; x0 += 64) {
                const uint32_t x1 = s.x1 - x0 < 64 ? s.x1 : x0 + 63;
                const uint32_t row_first = y * g->stride + x0;
                for (uint64_t row = row_may_hit(j, &s, y, x0, x1); row; row &= row - 1)
                    fill_entry(j, at, row_first + (uint32_t)__builtin_ctzll(row), near, backwards, t);
            }
    }
}

/* With more than two items, each cell's pairs' entries moved up behind the first pair's, where
 * the culled ones left gaps: each item a range of cells. */
static void cells_join_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const uint32_t cells = j->g.cells, first = cell_item_first(j, item), end = cell_item_first(j, item + 1);
    for (uint32_t c = first; c < end; c++) {
        if (j->cell_start[c] == j->cell_start[c + 1]) continue;
        uint32_t *pair_end = &j->counts[(size_t)cells + c], at = *pair_end;
        for (uint32_t i = 2; i < j->items; i += 2) {
            const uint32_t from = j->counts[(size_t)i * cells + c];
            const uint32_t to = i + 1 < j->items ? j->counts[(size_t)(i + 1) * cells + c] : j->cell_start[c + 1];
            memmove(&j->entries[at], &j->entries[from], (size_t)(to - from) * sizeof *j->entries);
            at += to - from;
        }
        *pair_end = at;
    }
}

/* Entering rays shared_origin checks before the ray pass, which checks them all. */
enum { ORIGIN_CHECKS = 256 };

/* The origin of the first ray checked that may enter the scene's box, where the next such rays
 * checked share it (the ray pass checks them all: this turns most other sets away at once);
 * the first valid ray's where none of the rays may (the ray pass then finds whether any does).
 * As the ray pass, it asks one origin only of rays that may enter the box. The rays are read
 * spread over the set, ORIGIN_CHECKS apart at first, then each round one on from the last:
 * every ray in the end, but where they come a scan line at a time, as a camera's do, a view's
 * first rows that pass above the box had been tested one by one first, on one thread (3-5 ms
 * of a full dragon call in the standard view, whose first 200 rows miss its box). False where
 * no ray is valid. */
static bool shared_origin(const vkrt_ray *rays, const vkrt_gpu_push *camera, uint32_t count, const vkrt_gpu_node *box,
                          double o[3])
{
    vkrt_ray first, first_valid;
    bool found = false, found_valid = false;
    const uint32_t step = count / ORIGIN_CHECKS + 1;
    uint32_t checked = 0;
    for (uint32_t round = 0; round < step && checked < ORIGIN_CHECKS; round++)
        for (uint64_t i = round; i < count && checked < ORIGIN_CHECKS; i += step) {
            const vkrt_ray r = job_ray(rays, camera, (uint32_t)i);
            if (!ray_valid(&r)) continue;
            if (!found_valid) first_valid = r;
            found_valid = true;
            if (!cpu_trace_ray_enters_box(&r, box)) continue;
            if (!found) first = r;
            else if (memcmp(r.origin, first.origin, sizeof r.origin) != 0) return false;
            found = true;
            checked++;
        }
    if (!found) first = first_valid;
    if (!found && !found_valid) return false;
    for (int k = 0; k < 3; k++) o[k] = first.origin[k];
    return true;
}

/* Rays make_frame reads for a first row, and the fewest that make one. */
enum { ROW_SEARCH = 1u << 14, ROW_MIN = 8 };

/* The projection of d onto the plane at distance 1 along f, less f; false where d is not ahead. */
static bool row_point(const vkrt_ray *ray, const double f[3], double out[3])
{
    const double d[3] = { ray->dir[0], ray->dir[1], ray->dir[2] }, z = dot(d, f);
    if (!ray_valid(ray) || !(z > 0.0)) return false;
    for (int k = 0; k < 3; k++) out[k] = d[k] / z - f[k];
    return true;
}

/* r (left 0 where the rays start with no row): from the first ray's projection to the last's
 * of the run that steps on along the first two's direction. */
static void first_row_direction(const vkrt_ray *rays, const vkrt_gpu_push *camera, uint32_t count, const double f[3],
                                double r[3])
{
    double p0[3], p1[3], step[3];
    const vkrt_ray r0 = job_ray(rays, camera, 0), r1 = job_ray(rays, camera, count > 1 ? 1 : 0);
    if (count < ROW_MIN || !row_point(&r0, f, p0) || !row_point(&r1, f, p1)) return;
    for (int k = 0; k < 3; k++) step[k] = p1[k] - p0[k];
    double last[3], along = dot(step, step);
    memcpy(last, p1, sizeof last);
    uint32_t i = 2;
    for (; i < count && i < ROW_SEARCH; i++) {
        const vkrt_ray ri = job_ray(rays, camera, i);
        double p[3], d[3];
        if (!row_point(&ri, f, p)) break;
        for (int k = 0; k < 3; k++) d[k] = p[k] - p0[k];
        const double a = dot(d, step);
        if (!(a > along)) break;
        along = a;
        memcpy(last, p, sizeof last);
    }
    if (i < ROW_MIN || !(along > 0.0)) return;
    for (int k = 0; k < 3; k++) r[k] = last[k] - p0[k];
    const double off = dot(r, f); /* rounding's */
    for (int k = 0; k < 3; k++) r[k] -= off * f[k];
}

/* The axis f: the mean unit direction of up to RAY_BIN_AXIS_SAMPLES valid rays spread over the
 * set; r and u complete the frame, r along the rays' first row (first_row_direction) or from
 * the world axis least along f. False where the directions cancel out. */
static bool make_frame(const vkrt_ray *rays, const vkrt_gpu_push *camera, uint32_t count, frame *fr)
{
    double sum[3] = { 0.0, 0.0, 0.0 };
    /* In pairs from both ends: a camera's rays i and count - 1 - i mirror each other, so its
     * axis comes out its forward direction, and its pixel centres a regular grid (make_grid). */
    const uint32_t step = count / RAY_BIN_AXIS_SAMPLES + 1;
    for (uint32_t i = 0; i <= (count - 1) / 2; i += step)
        for (int end = 0; end < 2; end++) {
            if (end && count - 1 - i == i) break;
            const vkrt_ray r = job_ray(rays, camera, end ? count - 1 - i : i);
            if (!ray_valid(&r)) continue;
            const double d[3] = { r.dir[0], r.dir[1], r.dir[2] };
            const double len = sqrt(dot(d, d));
            for (int k = 0; k < 3; k++) sum[k] += d[k] / len;
        }
    const double len = sqrt(dot(sum, sum));
    if (!(len > 0.0) || !isfinite(len)) return false;
    for (int k = 0; k < 3; k++) fr->f[k] = sum[k] / len;
    const double *f = fr->f;
    /* r along the first row of rays, where they start with one: a camera's pixels in turn,
     * whose projections step along r until the next row turns back. Then a runs along the
     * camera's rows and b down its columns, and its pixel centres lie on a lattice of the two
     * (lattice_grid); the row's ends give r to the directions' rounding over the row's width,
     * where two neighbours would give it over a pixel's step (some 1e-4 of an angle). Else r
     * comes from the world axis least along f. */
    double r[3] = { 0.0, 0.0, 0.0 };
    first_row_direction(rays, camera, count, f, r);
    if (!(sqrt(dot(r, r)) > 0x1p-20)) {
        int least = 0;
        for (int k = 1; k < 3; k++)
            if (abs_d(f[k]) < abs_d(f[least])) least = k;
        double axis[3] = { 0.0, 0.0, 0.0 };
        axis[least] = 1.0;
        r[0] = axis[1] * f[2] - axis[2] * f[1];
        r[1] = axis[2] * f[0] - axis[0] * f[2];
        r[2] = axis[0] * f[1] - axis[1] * f[0];
    }
    const double rl = sqrt(dot(r, r));
    for (int k = 0; k < 3; k++) fr->r[k] = r[k] / rl;
    fr->u[0] = f[1] * fr->r[2] - f[2] * fr->r[1];
    fr->u[1] = f[2] * fr->r[0] - f[0] * fr->r[2];
    fr->u[2] = f[0] * fr->r[1] - f[1] * fr->r[0];
    for (int k = 0; k < 3; k++) {
        fr->o4[k] = f4_set1((float)fr->o[k]); /* the rays' float origin: exact */
        fr->f4[k] = f4_set1((float)fr->f[k]);
        fr->r4[k] = f4_set1((float)fr->r[k]);
        fr->u4[k] = f4_set1((float)fr->u[k]);
    }
    return true;
}

/* Whether every corner of the box lies in front of the origin's plane (and so every triangle
 * within it); if so, the bounds of the box's projection (its eight corners', in double), widened
 * by far more than the rays' float projections can be off by (a few ulps of the coordinates'
 * size, WIDEN_ULPS), or than the box test's own tolerance lets a ray that just misses the box
 * pass. */
static bool box_projection(const frame *fr, const vkrt_gpu_node *box, float4 rect[4])
{
    const float lo[3] = { box->bmin.x, box->bmin.y, box->bmin.z }, hi[3] = { box->bmax.x, box->bmax.y, box->bmax.z };
    double bounds[4] = { INFINITY, -INFINITY, INFINITY, -INFINITY }, reach = 1.0;
    for (int corner = 0; corner < 8; corner++) {
        double p[3];
        for (int k = 0; k < 3; k++) p[k] = (double)((corner >> k) & 1 ? hi[k] : lo[k]) - fr->o[k];
        const double z = dot(p, fr->f);
        if (!(z > 0.0)) return false;
        const double a = dot(p, fr->r) / z, b = dot(p, fr->u) / z;
        bounds[0] = min_d(bounds[0], a);
        bounds[1] = max_d(bounds[1], a);
        bounds[2] = min_d(bounds[2], b);
        bounds[3] = max_d(bounds[3], b);
        reach = max_d(reach, max_d(abs_d(a), abs_d(b)));
    }
    /* A projection's error grows with 1 + a^2 + b^2, as the triangles' widening does. */
    const double margin = 0x1p-14 * reach * reach;
    for (int k = 0; k < 4; k++) rect[k] = f4_set1((float)(bounds[k] + (k % 2 ? margin : -margin)));
    return true;
}

/* Where the rays' projections lie on a regular lattice, as a camera's pixel centres do seen
 * along its forward direction, a grid of a cell a lattice point, each point at its cell's
 * centre: then a triangle box reaches only the cells whose centres it holds (the count's spans,
 * from the rays' offsets in their cells), and one between the points none. The lattice's steps
 * are the least differences between rays in turn (a camera's neighbours in a row, and its
 * rows); false where the bounds are no whole number of them, or the cells would be too many. */
static bool lattice_grid(const double bounds[4], const float step[2], uint32_t rays, grid *out)
{
    double n[2];
    for (int k = 0; k < 2; k++) {
        const double w = bounds[2 * k + 1] - bounds[2 * k];
        if (!(step[k] > 0.0f) || !(step[k] < INFINITY) || !(w / step[k] < (double)rays)) return false;
        n[k] = floor(w / step[k] + 0.5);
        if (!(abs_d(w / step[k] - n[k]) <= 0.25)) return false;
    }
    if ((n[0] + 1.0) * (n[1] + 1.0) > 2.0 * rays + 64.0) return false;
    const uint32_t gx = (uint32_t)n[0] + 1, gy = (uint32_t)n[1] + 1, stride = (gx + 3) & ~3u;
    const double wa = bounds[1] - bounds[0], wb = bounds[3] - bounds[2];
    const double sa = wa > 0.0 ? n[0] / wa : 1.0 / step[0], sb = wb > 0.0 ? n[1] / wb : 1.0 / step[1];
    *out = (grid){ .a0 = (float)(bounds[0] - 0.5 / sa), .b0 = (float)(bounds[2] - 0.5 / sb), .gx = gx, .gy = gy,
                   .stride = stride, .cells = stride * gy, .sa = (float)sa, .sb = (float)sb };
    return true;
}

/* A grid of about one square cell a ray over the rays' projections. */
static grid make_grid(const double bounds[4], uint32_t rays)
{
    const double wa = bounds[1] - bounds[0], wb = bounds[3] - bounds[2];
    const double side = wa * wb > 0.0 ? sqrt(wa * wb / rays) : max_d(wa, wb) / rays;
    uint32_t gx = 1, gy = 1;
    if (side > 0.0) {
        gx = (uint32_t)min_d(ceil(wa / side), (double)rays);
        gy = (uint32_t)min_d(ceil(wb / side), (double)rays);
        gx = gx ? gx : 1;
        gy = gy ? gy : 1;
        while ((uint64_t)gx * gy > 2ull * rays + 64) {
            gx = (gx + 1) / 2;
            gy = (gy + 1) / 2;
        }
    }
    /* The largest projection maps past the last cell, where rays_cell4 clamps it. */
    const uint32_t stride = (gx + 3) & ~3u;
    return (grid){ .a0 = (float)bounds[0], .b0 = (float)bounds[2], .gx = gx, .gy = gy, .stride = stride,
                   .cells = stride * gy,
                   .sa = wa > 0.0 ? (float)(gx / wa) : 0.0f, .sb = wb > 0.0 ? (float)(gy / wb) : 0.0f };
}


/* Array `which` of the scratch, holding at least count * size bytes (its contents undefined):
 * kept where it is large enough, else allocated anew. NULL when out of memory. */
static void *scratch_array(core *c, ray_bin_scratch *s, int which, size_t count, size_t size)
{
    const size_t bytes = (count ? count : 1) * size;
    if (s->bytes[which] >= bytes) return s->array[which];
    core_free(c, s->array[which]);
    s->bytes[which] = 0;
    if (!(s->array[which] = core_alloc_array(c, count ? count : 1, size))) return NULL;
    s->bytes[which] = bytes;
    return s->array[which];
}

static void job_destroy(core *c, ray_bin_job *j)
{
    if (!j) return;
    work_pool_destroy(j->pool);
    size_t kept = 0;
    for (int a = 0; j->scratch && a < ARRAYS; a++) kept += j->scratch->bytes[a];
    if (j->keep && !*j->keep && kept <= KEEP_BYTES) *j->keep = j->scratch;
    else ray_bin_scratch_destroy(c, j->scratch);
    core_free(c, j->item_over);
    core_free(c, j->segment_taken);
    core_free(c, j->tri_first);
    core_free(c, j->tri_end);
    core_free(c, j->item_behind);
    core_free(c, j->range_sum);
    core_free(c, j->range_longest);
    core_free(c, j);
}

/* The passes up to the lists' places (see the top of the file). */
static ray_bin_outcome plan(core *c, ray_bin_job *j, ray_bin_limits limits, ray_bins *out, bool *ok)
{
    if (!make_frame(j->rays, j->camera, j->ray_count, &j->fr)) return RAY_BIN_WIDE_ANGLE;
    if (!box_projection(&j->fr, j->box, j->box_rect)) return RAY_BIN_BEHIND;
    const double min_cos = cos(RAY_BIN_MAX_ANGLE_DEG * (3.14159265358979323846 / 180.0));
    j->min_cos2 = min_cos * min_cos;
    const uint32_t ray_items = core_div_up(j->ray_count, RAY_ITEM);
    ray_bin_scratch *m = j->scratch;
    if (!(*ok = (j->ray_results = scratch_array(c, m, ARRAY_RAY_RESULTS, ray_items, sizeof *j->ray_results)) &&
                (j->ray_ab = scratch_array(c, m, ARRAY_RAY_AB, j->ray_count, 2 * sizeof *j->ray_ab)) &&
                (j->ray_cell = scratch_array(c, m, ARRAY_RAY_CELL, j->ray_count, sizeof *j->ray_cell)) &&
                (j->item_over = core_calloc_array(c, j->items, sizeof *j->item_over)) &&
                (j->segment_taken = core_calloc_array(c, j->items, sizeof *j->segment_taken)) &&
                (j->tri_first = core_calloc_array(c, j->items, sizeof *j->tri_first)) &&
                (j->tri_end = core_calloc_array(c, j->items, sizeof *j->tri_end)) &&
                (j->item_behind = core_calloc_array(c, j->items, sizeof *j->item_behind)) &&
                (j->range_sum = core_calloc_array(c, j->items, sizeof *j->range_sum)) &&
                (j->range_longest = core_calloc_array(c, j->items, sizeof *j->range_longest)) &&
                (j->tri_cell = scratch_array(c, m, ARRAY_TRI_CELL, j->tri_count, sizeof *j->tri_cell)) &&
                (j->tri_cells = scratch_array(c, m, ARRAY_TRI_CELLS, j->tri_count, sizeof *j->tri_cells)) &&
                (j->tri_width = scratch_array(c, m, ARRAY_TRI_WIDTH, j->tri_count, sizeof *j->tri_width))))
        return RAY_BIN_TOO_LONG;
    work_pool_run(j->pool, ray_items, rays_project_item, NULL, j);
    double bounds[4] = { INFINITY, -INFINITY, INFINITY, -INFINITY };
    uint32_t valid = 0;
    float step[2] = { INFINITY, INFINITY };
    bool tmin_positive = false;
    for (uint32_t i = 0; i < ray_items; i++) {
        const ray_item_result *res = &j->ray_results[i];
        tmin_positive |= res->tmin_positive;
        if (res->origin_differs) return RAY_BIN_ORIGINS_DIFFER;
        if (res->wide_angle) return RAY_BIN_WIDE_ANGLE;
        bounds[0] = min_d(bounds[0], res->bounds[0]);
        bounds[1] = max_d(bounds[1], res->bounds[1]);
        bounds[2] = min_d(bounds[2], res->bounds[2]);
        bounds[3] = max_d(bounds[3], res->bounds[3]);
        valid += res->valid;
        for (int k = 0; k < 2; k++) step[k] = res->step[k] < step[k] ? res->step[k] : step[k];
    }
    if (!valid) return RAY_BIN_NONE_ENTER;
    const bool lattice = lattice_grid(bounds, step, valid, &j->g);
    if (!lattice) j->g = make_grid(bounds, valid);
    const uint32_t cells = j->g.cells;
    *ok = (j->cell_start = scratch_array(c, m, ARRAY_CELL_START, (size_t)cells + 1, sizeof *j->cell_start)) &&
          (j->counts = scratch_array(c, m, ARRAY_COUNTS, (size_t)cells * j->items, sizeof *j->counts));
    if (!*ok) return RAY_BIN_TOO_LONG;
    work_pool_run(j->pool, ray_items, rays_cell_item, NULL, j);
    for (int k = 0; k < 2; k++) {
        j->offset_min[k] = INFINITY;
        j->offset_max[k] = -INFINITY;
    }
    for (uint32_t i = 0; i < ray_items; i++)
        for (int k = 0; k < 2; k++) {
            const float *offset = j->ray_results[i].offset;
            j->offset_min[k] = offset[2 * k] < j->offset_min[k] ? offset[2 * k] : j->offset_min[k];
            j->offset_max[k] = offset[2 * k + 1] > j->offset_max[k] ? offset[2 * k + 1] : j->offset_max[k];
        }
    /* Found on one: every ray near its cell's centre (a lattice grid that missed the rays' own
     * lattice would spread them over their cells, and the spans gain nothing). */
    const bool on_lattice = lattice && j->offset_min[0] > 0.25f && j->offset_max[0] < 0.75f &&
                            j->offset_min[1] > 0.25f && j->offset_max[1] < 0.75f;
    /* There the box of a cell's rays (ray_centre, ray_half) is a small part of it, and takes the
     * place of its rays' bounds: a cell without rays, where the rays that miss the scene's box
     * begin, may then list a triangle near the box's edge that no ray of it tests. Not where a
     * step of dx or dy in float would no longer be exact. */
    j->raster = on_lattice && j->g.gx <= (1u << 22) && j->g.gy <= (1u << 22);
    /* A ray that starts past its origin may pass a triangle that hides others from the origin. */
    j->cull = j->raster && !tmin_positive;
    if (j->cull) {
        /* The scene's box's depths along the axis: 65,534 steps over them. */
        double z[2] = { INFINITY, -INFINITY };
        const float lo[3] = { j->box->bmin.x, j->box->bmin.y, j->box->bmin.z };
        const float hi[3] = { j->box->bmax.x, j->box->bmax.y, j->box->bmax.z };
        for (int corner = 0; corner < 8; corner++) {
            double p[3];
            for (int k = 0; k < 3; k++) p[k] = (double)((corner >> k) & 1 ? hi[k] : lo[k]) - j->fr.o[k];
            z[0] = min_d(z[0], dot(p, j->fr.f));
            z[1] = max_d(z[1], dot(p, j->fr.f));
        }
        j->depth_z0 = (float)z[0];
        j->depth_scale = (float)(65534.0 / max_d(z[1] - z[0], 1e-30));
    }
    if (j->cull &&
        !(*ok = (j->depths = scratch_array(c, m, ARRAY_DEPTHS, (size_t)cells * j->items, sizeof *j->depths)) &&
                (j->tri_near = scratch_array(c, m, ARRAY_TRI_NEAR, j->tri_count, sizeof *j->tri_near))))
        return RAY_BIN_TOO_LONG;
    if (j->raster) {
        for (int k = 0; k < 2; k++) {
            /* The offsets lie within 0.25 .. 0.75: both differences from the centre are exact
             * (Sterbenz); 2^-20 for good measure. */
            j->ray_centre[k] = 0.5f * (j->offset_min[k] + j->offset_max[k]);
            const float above = j->offset_max[k] - j->ray_centre[k], below = j->ray_centre[k] - j->offset_min[k];
            j->ray_half[k] = (above > below ? above : below) + 0x1p-20f;
        }
    } else {
        if (!(*ok = (j->cell_block = scratch_array(c, m, ARRAY_CELL_BOUNDS, cells / 4, sizeof *j->cell_block)) != NULL))
            return RAY_BIN_TOO_LONG;
        work_pool_run(j->pool, j->items, cells_bound_item, NULL, j);
    }
    /* Every entry costs a cell visit, and few visits find nothing on a mesh of small triangles;
     * far more visits than entries allowed means big triangles everywhere. */
    j->cell_budget = 8ull * limits.max_entries + cells + 1;
    /* Chunks enough for a thread held up to leave work to the other, not so small that taking
     * one costs (a multiple of four: projections four at a time). */
    j->tri_chunk = (core_div_up(j->tri_count, j->items * TRI_CHUNKS_PER_ITEM) + 3u) & ~3u;
    if (j->tri_chunk < TRI_CHUNK_MIN) j->tri_chunk = TRI_CHUNK_MIN;
    for (uint32_t i = 0; i < j->items; i++) atomic_init(&j->segment_taken[i], 0);
    atomic_init(&j->visited, 0);
    atomic_init(&j->stop, false);
    work_pool_run(j->pool, j->items, tris_count_item, NULL, j);
    for (uint32_t i = 0; i < j->items; i++)
        if (j->item_behind[i]) return RAY_BIN_BEHIND;
    for (uint32_t i = 0; i < j->items; i++)
        if (j->item_over[i]) return RAY_BIN_TOO_LONG;
    /* The scan, in parallel: each item's range of cells summed, the ranges' starts, then each
     * range's positions from its start. */
    work_pool_run(j->pool, j->items, cells_sum_item, NULL, j);
    uint64_t total = 0;
    uint32_t longest = 0;
    for (uint32_t i = 0; i < j->items; i++) {
        const uint64_t sum = j->range_sum[i];
        j->range_sum[i] = total;
        total += sum;
        if (j->range_longest[i] > longest) longest = j->range_longest[i];
    }
    /* Past the limit the positions would no longer fit 32 bits. */
    if (total > limits.max_entries || longest > limits.max_list) return RAY_BIN_TOO_LONG;
    work_pool_run(j->pool, j->items, cells_place_item, NULL, j);
    j->cell_start[cells] = (uint32_t)total;
    *out = (ray_bins){ .ray_cell = j->ray_cell, .cell_start = j->cell_start, .cell_first = j->counts,
                       .cell_end = j->items > 1 ? j->counts + cells : j->cell_start + 1,
                       .entry_count = (uint32_t)total, .longest = longest, .on_lattice = on_lattice, .culled = j->cull };
    return RAY_BIN_BUILT;
}

/* This file is compiled twice where the compiler can target x86-64-v3 (meson.build), as
 * src/cpu_trace.c is: once for the baseline (SSE2, every x86-64), and once with
 * VKRT_RAY_BIN_X86_64_V3 and -march=x86-64-v3, which makes only the plan and the fill below with
 * that suffix (the float4 code in three-operand AVX encodings, BMI's bit scans: 0.93-0.95x the
 * time of the full dragon's plan and fill). Contraction into FMA stays off, so both builds give the
 * same lists. ray_bin_plan and ray_bin_plan_camera run the v3 code where the CPU tracer does
 * (cpu_trace_isa), and ray_bin_fill the fill of the build that planned. */
#ifdef VKRT_RAY_BIN_X86_64_V3
#define RAY_BIN_ENTRY(name) name##_x86_64_v3
#else
#define RAY_BIN_ENTRY(name) name##_baseline
#endif

vkrt_result RAY_BIN_ENTRY(ray_bin_plan_rays)(core *c, ray_bin_scratch **keep, const vkrt_ray *rays,
                                             const vkrt_gpu_push *camera, uint32_t ray_count,
                                             const vkrt_gpu_tri *tris, uint32_t tri_count, const vkrt_gpu_node *box,
                                             ray_bin_limits limits, uint32_t threads, ray_bins *out,
                                             ray_bin_outcome *out_outcome);
void RAY_BIN_ENTRY(ray_bin_fill)(ray_bins *b, uint32_t *entries);

/* ray_bin_plan and ray_bin_plan_camera: the rays of the array, else the camera's. */
vkrt_result RAY_BIN_ENTRY(ray_bin_plan_rays)(core *c, ray_bin_scratch **keep, const vkrt_ray *rays,
                                             const vkrt_gpu_push *camera, uint32_t ray_count,
                                             const vkrt_gpu_tri *tris, uint32_t tri_count, const vkrt_gpu_node *box,
                                             ray_bin_limits limits, uint32_t threads, ray_bins *out,
                                             ray_bin_outcome *out_outcome)
{
    memset(out, 0, sizeof *out);
    *out_outcome = RAY_BIN_ORIGINS_DIFFER;
    double origin[3];
    if (!shared_origin(rays, camera, ray_count, box, origin)) return VKRT_OK;
    ray_bin_job *j = core_calloc_array(c, 1, sizeof *j);
    bool ok = j != NULL;
    if (ok) {
        *j = (ray_bin_job){ .rays = rays, .camera = camera, .ray_count = ray_count, .tris = tris,
                            .tri_count = tri_count, .box = box, .keep = keep };
#ifdef VKRT_RAY_BIN_X86_64_V3
        j->x86_64_v3 = true;
#endif
        memcpy(j->fr.o, origin, sizeof origin);
        /* The kept scratch is this call's until ray_bins_destroy hands it back. */
        if (keep && *keep) {
            j->scratch = *keep;
            *keep = NULL;
        } else {
            j->scratch = core_calloc_array(c, 1, sizeof *j->scratch);
        }
        ok = j->scratch && work_pool_create(c, threads, &j->pool) == VKRT_OK;
    }
    ray_bin_outcome outcome = RAY_BIN_TOO_LONG;
    if (ok) {
        j->items = work_pool_threads(j->pool);
        outcome = plan(c, j, limits, out, &ok);
    }
    if (!ok || outcome != RAY_BIN_BUILT) {
        job_destroy(c, j);
        memset(out, 0, sizeof *out);
        if (!ok)
            return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory listing %u triangles for %u rays", tri_count,
                             ray_count);
        *out_outcome = outcome;
        return VKRT_OK;
    }
    out->job = j;
    *out_outcome = RAY_BIN_BUILT;
    return VKRT_OK;
}

void RAY_BIN_ENTRY(ray_bin_fill)(ray_bins *b, uint32_t *entries)
{
    ray_bin_job *j = b->job;
    j->entries = entries;
    work_pool_run(j->pool, j->items, tris_fill_item, NULL, j);
    if (j->items > 2) work_pool_run(j->pool, j->items, cells_join_item, NULL, j);
    /* The pool's threads are idle from here on. */
    work_pool_destroy(j->pool);
    j->pool = NULL;
}

#ifndef VKRT_RAY_BIN_X86_64_V3
#ifdef VKRT_HAVE_RAY_BIN_X86_64_V3
vkrt_result ray_bin_plan_rays_x86_64_v3(core *c, ray_bin_scratch **keep, const vkrt_ray *rays,
                                        const vkrt_gpu_push *camera, uint32_t ray_count, const vkrt_gpu_tri *tris,
                                        uint32_t tri_count, const vkrt_gpu_node *box, ray_bin_limits limits,
                                        uint32_t threads, ray_bins *out, ray_bin_outcome *out_outcome);
void ray_bin_fill_x86_64_v3(ray_bins *b, uint32_t *entries);
#endif

static vkrt_result plan_rays(core *c, ray_bin_scratch **keep, const vkrt_ray *rays, const vkrt_gpu_push *camera,
                             uint32_t ray_count, const vkrt_gpu_tri *tris, uint32_t tri_count, const vkrt_gpu_node *box,
                             ray_bin_limits limits, uint32_t threads, ray_bins *out, ray_bin_outcome *out_outcome)
{
#ifdef VKRT_HAVE_RAY_BIN_X86_64_V3
    if (cpu_trace_isa(c) == CPU_TRACE_X86_64_V3)
        return ray_bin_plan_rays_x86_64_v3(c, keep, rays, camera, ray_count, tris, tri_count, box, limits, threads, out,
                                           out_outcome);
#endif
    return ray_bin_plan_rays_baseline(c, keep, rays, camera, ray_count, tris, tri_count, box, limits, threads, out,
                                      out_outcome);
}

vkrt_result ray_bin_plan(core *c, ray_bin_scratch **keep, const vkrt_ray *rays, uint32_t ray_count,
                         const vkrt_gpu_tri *tris, uint32_t tri_count, const vkrt_gpu_node *box,
                         ray_bin_limits limits, uint32_t threads, ray_bins *out, ray_bin_outcome *out_outcome)
{
    return plan_rays(c, keep, rays, NULL, ray_count, tris, tri_count, box, limits, threads, out, out_outcome);
}

vkrt_result ray_bin_plan_camera(core *c, ray_bin_scratch **keep, const vkrt_gpu_push *camera,
                                const vkrt_gpu_tri *tris, uint32_t tri_count, const vkrt_gpu_node *box,
                                ray_bin_limits limits, uint32_t threads, ray_bins *out, ray_bin_outcome *out_outcome)
{
    return plan_rays(c, keep, NULL, camera, camera->width * camera->height, tris, tri_count, box, limits, threads,
                     out, out_outcome);
}

void ray_bin_fill(ray_bins *b, uint32_t *entries)
{
#ifdef VKRT_HAVE_RAY_BIN_X86_64_V3
    if (b->job->x86_64_v3) {
        ray_bin_fill_x86_64_v3(b, entries);
        return;
    }
#endif
    ray_bin_fill_baseline(b, entries);
}

void ray_bin_scratch_destroy(core *c, ray_bin_scratch *s)
{
    if (!s) return;
    for (int a = 0; a < ARRAYS; a++) core_free(c, s->array[a]);
    core_free(c, s);
}

size_t ray_bin_compact(const ray_bins *b, const vkrt_ray *rays, size_t first, size_t count, size_t room,
                       vkrt_ray *out_rays, uint32_t *out_index, vkrt_hit *out_hits, size_t *out_read)
{
    const vkrt_hit miss = cpu_trace_miss();
    size_t copied = 0;
    for (size_t i = 0; i < count; i++) {
        uint32_t list[2];
        ray_bin_list(b, (uint32_t)(first + i), list);
        if (!list[1]) {
            out_hits[i] = miss;
            continue;
        }
        if (copied == room) {
            *out_read = i;
            return copied;
        }
        out_rays[copied] = rays[i];
        out_index[copied++] = (uint32_t)i;
    }
    *out_read = count;
    return copied;
}

void ray_bins_destroy(core *c, ray_bins *b)
{
    job_destroy(c, b->job);
    memset(b, 0, sizeof *b);
}
#endif /* !VKRT_RAY_BIN_X86_64_V3 */
