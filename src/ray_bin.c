/* Triangle lists for rays that share one origin: see ray_bin.h. The plan:
 *   - serially, the shared origin from the first rays, and the axis from a sample of them;
 *   1. rays: validity, the origin check, the angle check, each one's projection (a, b) onto the
 *      plane at distance 1 along the axis, and their bounds, which the grid spans;
 *   2. rays: each one's grid cell;
 *   3. cells, an item a range of them: each cell's bounds of its rays' projections;
 *   4. triangles: each one's projected box, widened, and in every cell it overlaps whose rays'
 *      bounds it overlaps, a count (each item its own counters: no atomics);
 *   - serially, the counts become each item's write positions;
 * and ray_bin_fill:
 *   5. triangles: each entry written at its position, in the cells the count noted (a box
 *      over more than 2x2 cells tested again).
 * Triangles go to items in ranges, so a cell's list is in the triangles' order. */
#include "ray_bin.h"

#include <math.h>
#include <string.h>

#include "float4.h"
#include "work_pool.h"

enum { RAY_ITEM = 16384 }; /* rays a work item of the ray passes */

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
} grid;

/* What one item of the ray pass found. */
typedef struct ray_item_result {
    double bounds[4]; /* a min, a max, b min, b max */
    uint32_t valid;
    bool origin_differs, wide_angle;
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
    ARRAY_TRI_BOX,
    ARRAY_TRI_CELL,
    ARRAY_TRI_CELLS,
    ARRAYS
};

struct ray_bin_scratch {
    void *array[ARRAYS];
    size_t bytes[ARRAYS];
};

/* At most this much scratch is kept for the next call. */
#define KEEP_BYTES ((size_t)192 << 20)

struct ray_bin_job {
    work_pool *pool;
    ray_bin_scratch *scratch;
    ray_bin_scratch **keep;    /* where the scratch goes back (NULL: freed) */
    const vkrt_ray *rays;
    uint32_t ray_count;
    const vkrt_gpu_tri *tris;
    uint32_t tri_count;
    uint32_t items;            /* of the cell and triangle passes: the pool's threads */
    double min_cos2;           /* the square of the smallest cosine of a ray's angle to the axis */
    frame fr;
    grid g;
    ray_item_result *ray_results;
    float *ray_ab;             /* 2 a ray; NaN for a ray that is not valid */
    uint32_t *ray_cell;
    float (*cell_bounds)[4];   /* of its rays' projections; a min > a max where it has none */
    uint32_t *cell_start;      /* cells + 1 */
    uint32_t *counts;          /* per triangle item, a cell each: its count, then its write
                                  position (item i's at i * cells) */
    float (*tri_box)[4];       /* widened projected box, rounded outwards (a wide span's only) */
    uint32_t *tri_cell;        /* the first cell of its span */
    uint8_t *tri_cells;        /* the cells of a span of up to 2x2 its box's rays overlap (bit 0
                                  the first, 1 the one right of it, 2 below, 3 below right), or
                                  TRI_WIDE_SPAN */
    uint64_t cell_budget;      /* cells a triangle item may visit before the lists count as too long */
    bool *item_over;           /* a triangle item passed its budget */
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

static uint32_t ray_item_end(const ray_bin_job *j, uint32_t item)
{
    const uint64_t end = (uint64_t)(item + 1) * RAY_ITEM;
    return end < j->ray_count ? (uint32_t)end : j->ray_count;
}

static void rays_project_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    ray_item_result res = { .bounds = { INFINITY, -INFINITY, INFINITY, -INFINITY } };
    for (uint32_t i = item * RAY_ITEM, end = ray_item_end(j, item); i < end; i++) {
        const vkrt_ray *r = &j->rays[i];
        j->ray_ab[2 * i] = j->ray_ab[2 * i + 1] = NAN;
        if (!ray_valid(r)) continue;
        res.origin_differs |= r->origin[0] != j->fr.o[0] || r->origin[1] != j->fr.o[1] || r->origin[2] != j->fr.o[2];
        const double d[3] = { r->dir[0], r->dir[1], r->dir[2] };
        const double z = dot(d, j->fr.f);
        /* cos of the angle >= min_cos, squared: no square root. */
        if (!(z > 0.0 && z * z >= j->min_cos2 * dot(d, d))) {
            res.wide_angle = true;
            continue;
        }
        const double inv_z = 1.0 / z;
        const float a = (float)(dot(d, j->fr.r) * inv_z), b = (float)(dot(d, j->fr.u) * inv_z);
        j->ray_ab[2 * i] = a;
        j->ray_ab[2 * i + 1] = b;
        res.bounds[0] = min_d(res.bounds[0], a);
        res.bounds[1] = max_d(res.bounds[1], a);
        res.bounds[2] = min_d(res.bounds[2], b);
        res.bounds[3] = max_d(res.bounds[3], b);
        res.valid++;
    }
    j->ray_results[item] = res;
}

/* The cell column or row of a projected coordinate, clamped to the grid: monotonic in x, so a
 * box's cells from its ends' cells hold every point's within it. */
static uint32_t cell_of(float x, float x0, float scale, uint32_t cells)
{
    const float c = (x - x0) * scale;
    /* Truncation is floor from 0 up. */
    return c <= 0.0f ? 0 : c >= (float)(cells - 1) ? cells - 1 : (uint32_t)c;
}

static void rays_cell_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const grid *g = &j->g;
    for (uint32_t i = item * RAY_ITEM, end = ray_item_end(j, item); i < end; i++) {
        const float a = j->ray_ab[2 * i], b = j->ray_ab[2 * i + 1];
        j->ray_cell[i] = isnan(a) ? RAY_BIN_NO_CELL
                                  : cell_of(b, g->b0, g->sb, g->gy) * g->gx + cell_of(a, g->a0, g->sa, g->gx);
    }
}

static uint32_t cell_item_first(const ray_bin_job *j, uint32_t item)
{
    return (uint32_t)((uint64_t)j->g.gx * j->g.gy * item / j->items);
}

/* Each item owns a range of cells and reads every ray's cell: no two items write one cell. */
static void cells_bound_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const uint32_t first = cell_item_first(j, item), end = cell_item_first(j, item + 1);
    for (uint32_t c = first; c < end; c++) {
        float *b = j->cell_bounds[c];
        b[0] = b[2] = INFINITY;
        b[1] = b[3] = -INFINITY;
    }
    for (uint32_t i = 0; i < j->ray_count; i++) {
        const uint32_t c = j->ray_cell[i];
        if (c < first || c >= end) continue; /* RAY_BIN_NO_CELL too */
        float *b = j->cell_bounds[c];
        const float x = j->ray_ab[2 * i], y = j->ray_ab[2 * i + 1];
        b[0] = x < b[0] ? x : b[0];
        b[1] = x > b[1] ? x : b[1];
        b[2] = y < b[2] ? y : b[2];
        b[3] = y > b[3] ? y : b[3];
    }
}

/* The projected boxes of triangles t .. t + 3 (a lane past `end` repeats triangle t), widened
 * (WIDEN_ULPS), in float: box[0] the lanes' a minima, box[1] a maxima, box[2] and box[3] b's.
 * Four triangles a time through float4: a triangle's three corners are rows of vkrt_gpu_tri,
 * four of which transpose into x, y and z. Float rounding of the projection is a few ulps of
 * the same terms the widening's 64 are. Returns the mask of lanes with a corner on or behind
 * the origin's plane. */
static unsigned project_triangles(const ray_bin_job *j, uint32_t t, uint32_t end, float4 box[4])
{
    const frame *fr = &j->fr;
    const float inf = INFINITY;
    float4 lo_a = f4_set1(inf), hi_a = f4_set1(-inf), lo_b = f4_set1(inf), hi_b = f4_set1(-inf);
    float4 far = f4_set1(0.0f), min_z = f4_set1(inf), max_tan2 = f4_set1(0.0f), front = f4_eq(far, far);
    const vkrt_gpu_tri *tri[4];
    for (uint32_t k = 0; k < 4; k++) tri[k] = &j->tris[t + k < end ? t + k : t];
    for (int corner = 0; corner < 3; corner++) {
        float4 rows[4];
        for (int k = 0; k < 4; k++) {
            const vkrt_float3 *v = corner == 0 ? &tri[k]->v0 : corner == 1 ? &tri[k]->v1 : &tri[k]->v2;
            rows[k] = f4_load(&v->x); /* x, y, z and the word after them */
        }
        f4_transpose(rows);
        const float4 px = f4_sub(rows[0], fr->o4[0]), py = f4_sub(rows[1], fr->o4[1]), pz = f4_sub(rows[2], fr->o4[2]);
        const float4 z = f4_add(f4_add(f4_mul(px, fr->f4[0]), f4_mul(py, fr->f4[1])), f4_mul(pz, fr->f4[2]));
        front = f4_and(front, f4_gt(z, f4_set1(0.0f)));
        const float4 inv_z = f4_div(f4_set1(1.0f), z);
        const float4 a = f4_mul(f4_add(f4_add(f4_mul(px, fr->r4[0]), f4_mul(py, fr->r4[1])), f4_mul(pz, fr->r4[2])), inv_z);
        const float4 b = f4_mul(f4_add(f4_add(f4_mul(px, fr->u4[0]), f4_mul(py, fr->u4[1])), f4_mul(pz, fr->u4[2])), inv_z);
        lo_a = f4_min(lo_a, a);
        hi_a = f4_max(hi_a, a);
        lo_b = f4_min(lo_b, b);
        hi_b = f4_max(hi_b, b);
        far = f4_max(far, f4_max(f4_abs(px), f4_max(f4_abs(py), f4_abs(pz))));
        min_z = f4_min(min_z, z);
        max_tan2 = f4_max(max_tan2, f4_add(f4_mul(a, a), f4_mul(b, b)));
    }
    const float4 widen =
        f4_mul(f4_mul(f4_set1((float)WIDEN_ULPS), f4_div(far, min_z)), f4_add(f4_set1(1.0f), max_tan2));
    box[0] = f4_sub(lo_a, widen);
    box[1] = f4_add(hi_a, widen);
    box[2] = f4_sub(lo_b, widen);
    box[3] = f4_add(hi_b, widen);
    return ~f4_bits(front) & 15u;
}

static uint32_t tri_item_first(const ray_bin_job *j, uint32_t item)
{
    return (uint32_t)((uint64_t)j->tri_count * item / j->items);
}

static bool boxes_overlap(const float cell[4], const float box[4])
{
    return (cell[0] <= box[1]) & (cell[1] >= box[0]) & (cell[2] <= box[3]) & (cell[3] >= box[2]);
}

/* The cells a box covers, columns x0 .. x1 and rows y0 .. y1. */
typedef struct cell_span {
    uint32_t x0, x1, y0, y1;
} cell_span;

static cell_span span_of(const grid *g, const float box[4])
{
    return (cell_span){ cell_of(box[0], g->a0, g->sa, g->gx), cell_of(box[1], g->a0, g->sa, g->gx),
                        cell_of(box[2], g->b0, g->sb, g->gy), cell_of(box[3], g->b0, g->sb, g->gy) };
}

/* tri_cells of a triangle whose span is wider than 2x2 cells: the fill tests its box again. */
#define TRI_WIDE_SPAN 0xFFu

static void tris_count_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const grid *g = &j->g;
    uint32_t *count = j->counts + (size_t)item * g->gx * g->gy;
    memset(count, 0, (size_t)g->gx * g->gy * sizeof *count);
    uint64_t visited = 0;
    const uint32_t first = tri_item_first(j, item), end = tri_item_first(j, item + 1);
    for (uint32_t t4 = first; t4 < end; t4 += 4) {
        float4 box4[4];
        const uint32_t lanes = end - t4 < 4 ? end - t4 : 4;
        if (project_triangles(j, t4, end, box4) & ((1u << lanes) - 1)) {
            j->item_behind[item] = true;
            return;
        }
        float lane_box[4][4];
        for (int k = 0; k < 4; k++) f4_store(lane_box[k], box4[k]);
        for (uint32_t lane = 0; lane < lanes; lane++) {
        const uint32_t t = t4 + lane;
        const float box[4] = { lane_box[0][lane], lane_box[1][lane], lane_box[2][lane], lane_box[3][lane] };
        const cell_span s = span_of(g, box);
        if (s.x1 - s.x0 <= 1 && s.y1 - s.y0 <= 1) {
            /* Most triangles of a detailed mesh span one or two cells each way: the four cells
             * counted without a branch, those outside the span masked (each loop's exit, a
             * different count for each triangle, was the pass's costliest branch), and noted
             * for the fill, which then neither projects nor tests again. */
            const uint32_t right = s.x1 - s.x0, down = s.y1 - s.y0;
            const uint32_t c00 = s.y0 * g->gx + s.x0, c01 = c00 + right, c10 = c00 + down * g->gx, c11 = c10 + right;
            const uint32_t in00 = boxes_overlap(j->cell_bounds[c00], box);
            const uint32_t in01 = right & boxes_overlap(j->cell_bounds[c01], box);
            const uint32_t in10 = down & boxes_overlap(j->cell_bounds[c10], box);
            const uint32_t in11 = right & down & boxes_overlap(j->cell_bounds[c11], box);
            count[c00] += in00;
            count[c01] += in01;
            count[c10] += in10;
            count[c11] += in11;
            j->tri_cell[t] = c00;
            j->tri_cells[t] = (uint8_t)(in00 | in01 << 1 | in10 << 2 | in11 << 3);
            visited += 4;
            continue;
        }
        memcpy(j->tri_box[t], box, sizeof box);
        j->tri_cells[t] = TRI_WIDE_SPAN;
        /* A triangle that covers much of the view visits every cell there: a scene of many such
         * is no case for lists. */
        visited += (uint64_t)(s.x1 - s.x0 + 1) * (s.y1 - s.y0 + 1);
        if (visited > j->cell_budget) {
            j->item_over[item] = true;
            return;
        }
        for (uint32_t y = s.y0; y <= s.y1; y++)
            for (uint32_t x = s.x0; x <= s.x1; x++) {
                const uint32_t c = y * g->gx + x;
                count[c] += boxes_overlap(j->cell_bounds[c], box);
            }
        }
    }
}

static void tris_fill_item(void *job, uint32_t item)
{
    ray_bin_job *j = job;
    const grid *g = &j->g;
    uint32_t *at = j->counts + (size_t)item * g->gx * g->gy;
    const uint32_t step[4] = { 0, 1, g->gx, g->gx + 1 };
    for (uint32_t t = tri_item_first(j, item), end = tri_item_first(j, item + 1); t < end; t++) {
        const uint32_t cells = j->tri_cells[t];
        if (cells != TRI_WIDE_SPAN) {
            for (int k = 0; k < 4; k++)
                if (cells >> k & 1) {
                    const uint32_t c = j->tri_cell[t] + step[k];
                    j->entries[at[c]++] = t;
                }
            continue;
        }
        const float *box = j->tri_box[t];
        const cell_span s = span_of(g, box);
        for (uint32_t y = s.y0; y <= s.y1; y++)
            for (uint32_t x = s.x0; x <= s.x1; x++) {
                const uint32_t c = y * g->gx + x;
                if (boxes_overlap(j->cell_bounds[c], box)) j->entries[at[c]++] = t;
            }
    }
}

/* The first valid ray's origin, where the first few valid rays share it (the ray pass checks
 * them all: this turns most other sets away at once); else false. */
static bool shared_origin(const vkrt_ray *rays, uint32_t count, double o[3])
{
    const vkrt_ray *first = NULL;
    for (uint32_t i = 0, checked = 0; i < count && checked < 256; i++) {
        const vkrt_ray *r = &rays[i];
        if (!ray_valid(r)) continue;
        if (!first) first = r;
        else if (memcmp(r->origin, first->origin, sizeof r->origin) != 0) return false;
        checked++;
    }
    if (!first) return false;
    for (int k = 0; k < 3; k++) o[k] = first->origin[k];
    return true;
}

/* The axis f: the mean unit direction of up to RAY_BIN_AXIS_SAMPLES valid rays spread over the
 * set; r and u complete the frame, r from the world axis least along f. False where the
 * directions cancel out. */
static bool make_frame(const vkrt_ray *rays, uint32_t count, frame *fr)
{
    double sum[3] = { 0.0, 0.0, 0.0 };
    const uint32_t step = count / RAY_BIN_AXIS_SAMPLES + 1;
    for (uint32_t i = 0; i < count; i += step) {
        if (!ray_valid(&rays[i])) continue;
        const double d[3] = { rays[i].dir[0], rays[i].dir[1], rays[i].dir[2] };
        const double len = sqrt(dot(d, d));
        for (int k = 0; k < 3; k++) sum[k] += d[k] / len;
    }
    const double len = sqrt(dot(sum, sum));
    if (!(len > 0.0) || !isfinite(len)) return false;
    for (int k = 0; k < 3; k++) fr->f[k] = sum[k] / len;
    int least = 0;
    for (int k = 1; k < 3; k++)
        if (abs_d(fr->f[k]) < abs_d(fr->f[least])) least = k;
    double axis[3] = { 0.0, 0.0, 0.0 };
    axis[least] = 1.0;
    const double *f = fr->f;
    const double r[3] = { axis[1] * f[2] - axis[2] * f[1], axis[2] * f[0] - axis[0] * f[2],
                          axis[0] * f[1] - axis[1] * f[0] };
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

/* Every corner of the box in front of the origin's plane (and so every triangle within it). */
static bool box_in_front(const frame *fr, const float box_min[3], const float box_max[3])
{
    for (int corner = 0; corner < 8; corner++) {
        double p[3];
        for (int k = 0; k < 3; k++) p[k] = (double)((corner >> k) & 1 ? box_max[k] : box_min[k]) - fr->o[k];
        if (!(dot(p, fr->f) > 0.0)) return false;
    }
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
    /* The largest projection maps past the last cell, where cell_of clamps it. */
    return (grid){ .a0 = (float)bounds[0], .b0 = (float)bounds[2], .gx = gx, .gy = gy,
                   .sa = wa > 0.0 ? (float)(gx / wa) : 0.0f, .sb = wb > 0.0 ? (float)(gy / wb) : 0.0f };
}

void ray_bin_scratch_destroy(core *c, ray_bin_scratch *s)
{
    if (!s) return;
    for (int a = 0; a < ARRAYS; a++) core_free(c, s->array[a]);
    core_free(c, s);
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
    core_free(c, j->item_behind);
    core_free(c, j);
}

/* The passes up to the lists' places (see the top of the file). */
static ray_bin_outcome plan(core *c, ray_bin_job *j, const float box_min[3], const float box_max[3],
                            ray_bin_limits limits, ray_bins *out, bool *ok)
{
    if (!make_frame(j->rays, j->ray_count, &j->fr)) return RAY_BIN_WIDE_ANGLE;
    if (!box_in_front(&j->fr, box_min, box_max)) return RAY_BIN_BEHIND;
    const double min_cos = cos(RAY_BIN_MAX_ANGLE_DEG * (3.14159265358979323846 / 180.0));
    j->min_cos2 = min_cos * min_cos;
    const uint32_t ray_items = core_div_up(j->ray_count, RAY_ITEM);
    ray_bin_scratch *m = j->scratch;
    if (!(*ok = (j->ray_results = scratch_array(c, m, ARRAY_RAY_RESULTS, ray_items, sizeof *j->ray_results)) &&
                (j->ray_ab = scratch_array(c, m, ARRAY_RAY_AB, j->ray_count, 2 * sizeof *j->ray_ab)) &&
                (j->ray_cell = scratch_array(c, m, ARRAY_RAY_CELL, j->ray_count, sizeof *j->ray_cell)) &&
                (j->item_over = core_calloc_array(c, j->items, sizeof *j->item_over)) &&
                (j->item_behind = core_calloc_array(c, j->items, sizeof *j->item_behind)) &&
                (j->tri_box = scratch_array(c, m, ARRAY_TRI_BOX, j->tri_count, sizeof *j->tri_box)) &&
                (j->tri_cell = scratch_array(c, m, ARRAY_TRI_CELL, j->tri_count, sizeof *j->tri_cell)) &&
                (j->tri_cells = scratch_array(c, m, ARRAY_TRI_CELLS, j->tri_count, sizeof *j->tri_cells))))
        return RAY_BIN_TOO_LONG;
    work_pool_run(j->pool, ray_items, rays_project_item, NULL, j);
    double bounds[4] = { INFINITY, -INFINITY, INFINITY, -INFINITY };
    uint32_t valid = 0;
    for (uint32_t i = 0; i < ray_items; i++) {
        const ray_item_result *res = &j->ray_results[i];
        if (res->origin_differs) return RAY_BIN_ORIGINS_DIFFER;
        if (res->wide_angle) return RAY_BIN_WIDE_ANGLE;
        bounds[0] = min_d(bounds[0], res->bounds[0]);
        bounds[1] = max_d(bounds[1], res->bounds[1]);
        bounds[2] = min_d(bounds[2], res->bounds[2]);
        bounds[3] = max_d(bounds[3], res->bounds[3]);
        valid += res->valid;
    }
    j->g = make_grid(bounds, valid);
    const uint32_t cells = j->g.gx * j->g.gy;
    *ok = (j->cell_bounds = scratch_array(c, m, ARRAY_CELL_BOUNDS, cells, sizeof *j->cell_bounds)) &&
          (j->cell_start = scratch_array(c, m, ARRAY_CELL_START, (size_t)cells + 1, sizeof *j->cell_start)) &&
          (j->counts = scratch_array(c, m, ARRAY_COUNTS, (size_t)cells * j->items, sizeof *j->counts));
    if (!*ok) return RAY_BIN_TOO_LONG;
    work_pool_run(j->pool, ray_items, rays_cell_item, NULL, j);
    work_pool_run(j->pool, j->items, cells_bound_item, NULL, j);
    /* Every entry costs a cell visit, and few visits find nothing on a mesh of small triangles;
     * far more visits than entries allowed means big triangles everywhere. */
    j->cell_budget = (8ull * limits.max_entries + cells) / j->items + 1;
    work_pool_run(j->pool, j->items, tris_count_item, NULL, j);
    for (uint32_t i = 0; i < j->items; i++)
        if (j->item_behind[i]) return RAY_BIN_BEHIND;
    for (uint32_t i = 0; i < j->items; i++)
        if (j->item_over[i]) return RAY_BIN_TOO_LONG;
    uint64_t total = 0;
    uint32_t longest = 0;
    for (uint32_t cell = 0; cell < cells; cell++) {
        const uint64_t first = total;
        j->cell_start[cell] = (uint32_t)first;
        for (uint32_t i = 0; i < j->items; i++) {
            uint32_t *count = &j->counts[(size_t)i * cells + cell];
            const uint32_t n = *count;
            *count = (uint32_t)total;
            total += n;
        }
        if (total - first > longest) longest = (uint32_t)(total - first);
        /* Past the limit the positions no longer fit 32 bits: stop before they wrap. */
        if (total > limits.max_entries || longest > limits.max_list) return RAY_BIN_TOO_LONG;
    }
    j->cell_start[cells] = (uint32_t)total;
    *out = (ray_bins){ .ray_count = j->ray_count, .ray_cell = j->ray_cell, .cell_start = j->cell_start,
                       .entry_count = (uint32_t)total, .longest = longest };
    return RAY_BIN_BUILT;
}

vkrt_result ray_bin_plan(core *c, ray_bin_scratch **keep, const vkrt_ray *rays, uint32_t ray_count,
                         const vkrt_gpu_tri *tris, uint32_t tri_count, const float box_min[3], const float box_max[3],
                         ray_bin_limits limits, uint32_t threads, ray_bins *out, ray_bin_outcome *out_outcome)
{
    memset(out, 0, sizeof *out);
    *out_outcome = RAY_BIN_ORIGINS_DIFFER;
    double origin[3];
    if (!shared_origin(rays, ray_count, origin)) return VKRT_OK;
    ray_bin_job *j = core_calloc_array(c, 1, sizeof *j);
    bool ok = j != NULL;
    if (ok) {
        *j = (ray_bin_job){ .rays = rays, .ray_count = ray_count, .tris = tris, .tri_count = tri_count, .keep = keep };
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
        outcome = plan(c, j, box_min, box_max, limits, out, &ok);
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

void ray_bin_fill(ray_bins *b, uint32_t *entries)
{
    ray_bin_job *j = b->job;
    j->entries = entries;
    work_pool_run(j->pool, j->items, tris_fill_item, NULL, j);
    /* The pool's threads are idle from here on. */
    work_pool_destroy(j->pool);
    j->pool = NULL;
}

void ray_bins_destroy(core *c, ray_bins *b)
{
    job_destroy(c, b->job);
    memset(b, 0, sizeof *b);
}
