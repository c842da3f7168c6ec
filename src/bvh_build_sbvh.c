/* Spatial-split BVH builder (SBVH): vkrt's high-quality option (VKRT_BVH_BUILDER_SPATIAL_SAH).
 *
 * This implements M. Stich, H. Friedrich, A. Dietrich, "Spatial Splits in Bounding Volume
 * Hierarchies", High Performance Graphics 2009. Every node weighs two kinds of split by the
 * same surface area heuristic as the binned SAH builder (bvh_build_sah.c, whose object binning,
 * sweep and partition it reuses):
 * - an object split: the node's references binned by centroid, each going wholly to one side;
 * - a spatial split: the node's box cut by a plane at one of SBVH_BINS - 1 equal intervals on
 *   an axis, each reference going to the side(s) its triangle's part reaches, so a triangle that
 *   crosses the plane is referenced by both children, each with the box of its part only
 *   (triangles are clipped to the bins when they are binned, and to the plane when split).
 *   The SAH counts a reference on each side it enters.
 * A spatial split is tried only where the object split's children overlap by more than
 * SBVH_OVERLAP_ALPHA of the root's area (the paper's alpha), which keeps the duplicates few;
 * and "reference unsplitting" then sends a crossing reference wholly to one side where that
 * costs less than splitting it.
 *
 * What this changes downstream: a triangle may sit in several leaves (bvh.spatial_splits, the
 * order then longer than the mesh), and a leaf box bounds its triangles' parts, not their
 * corners. Traversal is unaffected: each copy is the same triangle, the closest-hit rule breaks
 * ties by prim_id, so a second copy never replaces the first, and the hit is the same
 * triangle with the same t, u and v as through any other BVH.
 *
 * Exactness of the clipped boxes: a clip computes the crossing of an edge and a plane in float,
 * whose coordinates off the plane's axis are within a few ulps of the true ones; each clipped
 * box is widened by SBVH_CLIP_ULPS ulps of the triangle's coordinates on those axes and then
 * intersected with the reference's previous box and the plane's half-space, both of which hold
 * the true part. So a box never misses a point of its triangle's part, and a ray that hits the
 * triangle there enters every box above it.
 *
 * Memory and layout: the references live in one array of ref_capacity (the reference budget,
 * SBVH_REFERENCE_BUDGET times the triangles) used as a stack: the node being split is always on
 * top; it is split in place (object) or by writing its left parts in place and its right parts
 * to a scratch array copied back above them (spatial), and the right child, now on top, is
 * built first while the left waits on the task stack. A leaf moves its triangle indices to the
 * order and gives its range back. A spatial split that would overrun the budget is not made.
 * A large mesh is built in two phases, the top serially and the subtrees below on threads
 * (SBVH_TASK_REFS). */
#include "bvh_build_sah.h"

#include <math.h>
#include <stdatomic.h>
#include <string.h>

/* Spatial bins a node's box is cut into on each axis, as the object split's bins. */
#define SBVH_BINS 32
/* A node of fewer references than SBVH_BINS gets as many bins as it has references, and at
 * least SBVH_MIN_BINS: deep in the tree triangles are about as large as their node, so each
 * spans most of its bins and is clipped in each. On dragon_200k the build took 0.74-0.75 s
 * instead of 1.12-1.15 s, at an SAH cost of 42.866 instead of 42.844. */
#define SBVH_MIN_BINS 4
/* Stich et al.'s alpha: spatial splits are tried where the object split's children overlap by
 * more than this fraction of the root's area. The paper's 1e-5 gives the full dragon an SAH
 * cost of 47.37 in 2.5 s; 1e-4 gave 47.52 in 1.8 s, 1e-3 47.74 in 1.1 s (the high-quality
 * builder keeps the quality). */
#define SBVH_OVERLAP_ALPHA 1e-5f
/* References at most 1.5 times the triangles: the scanned meshes of ../shared/models stay well
 * within it (at most 23.5% more, fandisk_13k), and memory stays bounded for any input. */
#define SBVH_REFERENCE_BUDGET_NUM 3
#define SBVH_REFERENCE_BUDGET_DEN 2
/* Above this many triangles the build has two phases: the nodes of more references than this,
 * serially, then the subtrees below, one a thread (desc->threads, work_pool.h), each from its
 * own copy of its references and with its share of the budget left. The decomposition depends
 * on the mesh alone, so the BVH is the same, bit for bit, on any number of threads. */
#define SBVH_TASK_REFS 8192
/* How far a clipped box is widened off the plane's axis, in ulps of the triangle's coordinates:
 * a crossing point's error is within about 4 (the top of the file). */
#define SBVH_CLIP_ULPS 8.0f

typedef struct sbvh_bin {
    float bmin[3], bmax[3];
    uint32_t entry, exit; /* references whose part starts / ends in this bin */
} sbvh_bin;

typedef struct sbvh_split {
    int axis, plane;     /* left: bins [0, plane) of axis; axis -1: none */
    float cost;          /* A(left) N(left) + A(right) N(right) */
    uint32_t left_n, right_n;
    float lmin[3], lmax[3], rmin[3], rmax[3];
} sbvh_split;

/* The spatial grid of a node: `bins` bins of equal width over its box on each axis. */
typedef struct sbvh_grid {
    float origin[3], width[3], scale[3]; /* scale 0: the axis cannot be cut */
    int bins;
} sbvh_grid;

static float area_of(const float *bmin, const float *bmax)
{
    float dx = bmax[0] - bmin[0], dy = bmax[1] - bmin[1], dz = bmax[2] - bmin[2];
    return 2.0f * (dx * dy + dy * dz + dz * dx);
}

static void box_grow(float *bmin, float *bmax, const float *omin, const float *omax)
{
    bvh_build_box_grow(bmin, bmax, omin, omax);
}

static bool box_valid(const float *bmin, const float *bmax)
{
    return bmin[0] <= bmax[0] && bmin[1] <= bmax[1] && bmin[2] <= bmax[2];
}

static int grid_bin(const sbvh_grid *g, int axis, float x)
{
    float f = (x - g->origin[axis]) * g->scale[axis];
    f = f > 0.0f ? f : 0.0f;
    f = f < (float)(g->bins - 1) ? f : (float)(g->bins - 1);
    return (int)f;
}

/* The plane between bins k - 1 and k: the same expression wherever a plane is used. */
static float grid_plane(const sbvh_grid *g, int axis, int k) { return g->origin[axis] + g->width[axis] * (float)k; }

static void grid_of(const vkrt_gpu_node *n, uint32_t count, sbvh_grid *g)
{
    g->bins = count < SBVH_MIN_BINS ? SBVH_MIN_BINS : count < SBVH_BINS ? (int)count : SBVH_BINS;
    const float lo[3] = { n->bmin.x, n->bmin.y, n->bmin.z }, hi[3] = { n->bmax.x, n->bmax.y, n->bmax.z };
    for (int a = 0; a < 3; a++) {
        float extent = hi[a] - lo[a];
        float scale = extent > 0.0f ? (float)g->bins / extent : 0.0f;
        bool usable = extent > 0.0f && isfinite(scale);
        g->origin[a] = lo[a];
        g->width[a] = usable ? extent / (float)g->bins : 0.0f;
        g->scale[a] = usable ? scale : 0.0f;
    }
}

static void add_point(float *bmin, float *bmax, const float *p)
{
    box_grow(bmin, bmax, p, p);
}

/* How far triangle p's clipped boxes are widened on each axis but `axis` (the plane's, whose
 * bounds are exact). */
static inline void clip_slack(const float *p, int axis, float *slack)
{
    for (int a = 0; a < 3; a++) {
        float magnitude = bvh_build_max_f(fabsf(p[a]), bvh_build_max_f(fabsf(p[3 + a]), fabsf(p[6 + a])));
        slack[a] = a == axis ? 0.0f : magnitude * SBVH_CLIP_ULPS * FLT_EPSILON + FLT_MIN;
    }
}

/* Grows bmin-bmax by the point where edge u-w crosses the plane at `plane` on `axis`, where it
 * crosses it strictly. */
static inline void add_crossing(const float *u, const float *w, int axis, float plane, float *bmin, float *bmax)
{
    if (!((u[axis] < plane && w[axis] > plane) || (u[axis] > plane && w[axis] < plane))) return;
    float t = (plane - u[axis]) / (w[axis] - u[axis]), q[3];
    for (int a = 0; a < 3; a++) q[a] = u[a] + t * (w[a] - u[a]);
    q[axis] = plane;
    add_point(bmin, bmax, q);
}

/* A part's box from its corners and crossings (bmin-bmax, empty where the part is): widened by
 * slack, then kept within [lo, hi] on `axis` and within the reference's box rmin-rmax, which
 * both hold the part. False where nothing is left. */
static inline bool finish_part(float *bmin, float *bmax, const float *slack, int axis, float lo, float hi,
                               const float *rmin, const float *rmax)
{
    if (!(bmin[0] <= bmax[0])) return false;
    for (int a = 0; a < 3; a++) {
        bmin[a] -= slack[a];
        bmax[a] += slack[a];
        if (a == axis) {
            bmin[a] = bvh_build_max_f(lo, bmin[a]);
            bmax[a] = bvh_build_min_f(hi, bmax[a]);
        }
        bmin[a] = bvh_build_max_f(rmin[a], bmin[a]);
        bmax[a] = bvh_build_min_f(rmax[a], bmax[a]);
    }
    return box_valid(bmin, bmax);
}

/* The box of the part of triangle p (9 floats) whose coordinate on `axis` is in [lo, hi],
 * within the reference box rmin-rmax; false where that part is empty. See the top of the file
 * for why the result never misses a point of the part. */
static bool clip_box(const float *p, int axis, float lo, float hi, const float *rmin, const float *rmax, float *omin,
                     float *omax)
{
    bvh_build_box_empty(omin, omax);
    for (int e = 0; e < 3; e++) {
        const float *u = p + 3 * e, *v = p + 3 * ((e + 1) % 3);
        if (u[axis] >= lo && u[axis] <= hi) add_point(omin, omax, u);
        add_crossing(u, v, axis, lo, omin, omax);
        add_crossing(u, v, axis, hi, omin, omax);
    }
    float slack[3];
    clip_slack(p, axis, slack);
    return finish_part(omin, omax, slack, axis, lo, hi, rmin, rmax);
}

static const float *tri_of(const mesh *m, const sah_ref *r)
{
    uint32_t tri;
    memcpy(&tri, &r->bmax[3], sizeof tri);
    return m->positions + (size_t)tri * 9;
}

/* Grows bins first..last of `axis` by the parts of reference r's triangle p that fall in each:
 * clip_box() for every bin, computed in one sweep. The triangle's corners sorted along the
 * axis, a plane between its lowest and highest corner crosses the long edge and one short
 * one, and a bin's part is bounded by its corners and the crossings at its two planes. */
static void bin_spanning(const float *p, const sah_ref *r, int axis, int first, int last, const sbvh_grid *g,
                         sbvh_bin *bins)
{
    const float *v[3] = { p, p + 3, p + 6 };
    for (int i = 0; i < 2; i++)
        for (int j = 0; j < 2 - i; j++)
            if (v[j + 1][axis] < v[j][axis]) {
                const float *t = v[j];
                v[j] = v[j + 1];
                v[j + 1] = t;
            }
    float slack[3];
    clip_slack(p, axis, slack);
    float lo_box[3], hi_box[3]; /* the crossings of the bin's lower plane */
    bvh_build_box_empty(lo_box, hi_box);
    for (int k = first; k <= last; k++) {
        float lo = k == first ? r->bmin[axis] : grid_plane(g, axis, k);
        float hi = k == last ? r->bmax[axis] : grid_plane(g, axis, k + 1);
        float bmin[3], bmax[3];
        bvh_build_box_empty(bmin, bmax);
        if (k > first) bvh_build_box_grow(bmin, bmax, lo_box, hi_box);
        for (int i = 0; i < 3; i++)
            if (v[i][axis] >= lo && v[i][axis] <= hi) add_point(bmin, bmax, v[i]);
        if (k < last) {
            /* The crossings of the plane at hi: on the long edge, and on the short edge on its
             * side of the middle corner. */
            bvh_build_box_empty(lo_box, hi_box);
            add_crossing(v[0], v[2], axis, hi, lo_box, hi_box);
            if (hi < v[1][axis]) add_crossing(v[0], v[1], axis, hi, lo_box, hi_box);
            else add_crossing(v[1], v[2], axis, hi, lo_box, hi_box);
            bvh_build_box_grow(bmin, bmax, lo_box, hi_box);
        }
        if (finish_part(bmin, bmax, slack, axis, lo, hi, r->bmin, r->bmax))
            box_grow(bins[k].bmin, bins[k].bmax, bmin, bmax);
    }
}

/* Bins references [r, end) into the spatial grid's bins of every axis, each clipped to the
 * bins it spans. */
static void spatial_bin(const mesh *m, const sah_ref *r, const sah_ref *end, const sbvh_grid *g,
                        sbvh_bin bins[3][SBVH_BINS])
{
    for (int a = 0; a < 3; a++) {
        for (int k = 0; k < g->bins; k++) {
            bvh_build_box_empty(bins[a][k].bmin, bins[a][k].bmax);
            bins[a][k].entry = bins[a][k].exit = 0;
        }
    }
    for (; r < end; r++) {
        for (int a = 0; a < 3; a++) {
            if (g->scale[a] == 0.0f) continue;
            int first = grid_bin(g, a, r->bmin[a]), last = grid_bin(g, a, r->bmax[a]);
            bins[a][first].entry++;
            bins[a][last].exit++;
            if (first == last) box_grow(bins[a][first].bmin, bins[a][first].bmax, r->bmin, r->bmax);
            else bin_spanning(tri_of(m, r), r, a, first, last, g, bins[a]);
        }
    }
}

/* The cheapest spatial split of the binned node; axis -1 where none has references on both
 * sides. */
static sbvh_split spatial_sweep(const sbvh_bin bins[3][SBVH_BINS], const sbvh_grid *g)
{
    sbvh_split best = { .axis = -1, .cost = INFINITY };
    for (int a = 0; a < 3; a++) {
        if (g->scale[a] == 0.0f) continue;
        float lmin[SBVH_BINS][3], lmax[SBVH_BINS][3], left_area[SBVH_BINS];
        uint32_t left_n[SBVH_BINS];
        float lo[3], hi[3];
        bvh_build_box_empty(lo, hi);
        uint32_t n = 0;
        for (int k = 0; k < g->bins - 1; k++) {
            box_grow(lo, hi, bins[a][k].bmin, bins[a][k].bmax);
            n += bins[a][k].entry;
            memcpy(lmin[k], lo, sizeof lo);
            memcpy(lmax[k], hi, sizeof hi);
            left_n[k] = n;
            left_area[k] = n ? area_of(lo, hi) : 0.0f;
        }
        bvh_build_box_empty(lo, hi);
        n = 0;
        for (int k = g->bins - 1; k >= 1; k--) {
            box_grow(lo, hi, bins[a][k].bmin, bins[a][k].bmax);
            n += bins[a][k].exit;
            uint32_t nl = left_n[k - 1];
            if (nl == 0 || n == 0 || !box_valid(lo, hi) || !box_valid(lmin[k - 1], lmax[k - 1])) continue;
            float cost = left_area[k - 1] * (float)nl + area_of(lo, hi) * (float)n;
            if (cost < best.cost) {
                best.cost = cost;
                best.axis = a;
                best.plane = k;
                best.left_n = nl;
                best.right_n = n;
                memcpy(best.lmin, lmin[k - 1], sizeof best.lmin);
                memcpy(best.lmax, lmax[k - 1], sizeof best.lmax);
                memcpy(best.rmin, lo, sizeof best.rmin);
                memcpy(best.rmax, hi, sizeof best.rmax);
            }
        }
    }
    return best;
}

static float grown_area(const float *bmin, const float *bmax, const sah_ref *r)
{
    float lo[3] = { bmin[0], bmin[1], bmin[2] }, hi[3] = { bmax[0], bmax[1], bmax[2] };
    box_grow(lo, hi, r->bmin, r->bmax);
    return area_of(lo, hi);
}

/* Splits references [first, first + count) at spatial split s: the left references stay at
 * first (in order, compacted), the right ones follow them (through scratch). Returns the number
 * on the left; *right_count the number on the right. */
static uint32_t spatial_partition(const mesh *m, sah_ref *refs, uint32_t first, uint32_t count, const sbvh_grid *g,
                                  const sbvh_split *s, sah_ref *scratch, uint32_t *right_count)
{
    const int a = s->axis;
    const float plane = grid_plane(g, a, s->plane);
    float lmin[3], lmax[3], rmin[3], rmax[3];
    memcpy(lmin, s->lmin, sizeof lmin);
    memcpy(lmax, s->lmax, sizeof lmax);
    memcpy(rmin, s->rmin, sizeof rmin);
    memcpy(rmax, s->rmax, sizeof rmax);
    uint32_t nl = s->left_n, nr = s->right_n;
    uint32_t left = 0, right = 0;
    for (uint32_t i = first; i < first + count; i++) {
        sah_ref r = refs[i];
        int lo_bin = grid_bin(g, a, r.bmin[a]), hi_bin = grid_bin(g, a, r.bmax[a]);
        bool to_left = hi_bin < s->plane, to_right = lo_bin >= s->plane;
        sah_ref lpart = r, rpart = r;
        if (!to_left && !to_right) {
            const float *p = tri_of(m, &r);
            bool has_left = clip_box(p, a, r.bmin[a], plane, r.bmin, r.bmax, lpart.bmin, lpart.bmax);
            bool has_right = clip_box(p, a, plane, r.bmax[a], r.bmin, r.bmax, rpart.bmin, rpart.bmax);
            if (has_left && has_right) {
                /* Reference unsplitting: the whole reference on one side where that is cheaper. */
                float split_cost = area_of(lmin, lmax) * (float)nl + area_of(rmin, rmax) * (float)nr;
                float left_cost = grown_area(lmin, lmax, &r) * (float)nl + area_of(rmin, rmax) * (float)(nr - 1);
                float right_cost = area_of(lmin, lmax) * (float)(nl - 1) + grown_area(rmin, rmax, &r) * (float)nr;
                if (left_cost < split_cost && left_cost <= right_cost) {
                    to_left = true;
                    box_grow(lmin, lmax, r.bmin, r.bmax);
                    nr--;
                } else if (right_cost < split_cost) {
                    to_right = true;
                    box_grow(rmin, rmax, r.bmin, r.bmax);
                    nl--;
                } else {
                    refs[first + left++] = lpart;
                    scratch[right++] = rpart;
                    continue;
                }
            } else if (has_left) {
                to_left = true;
            } else {
                to_right = true;
            }
        }
        if (to_left) refs[first + left++] = r;
        else scratch[right++] = r;
    }
    memcpy(refs + first + left, scratch, (size_t)right * sizeof *scratch);
    *right_count = right;
    return left;
}

/* Reports the references placed in leaves as a fraction of those placed and still to place,
 * never going back (a spatial split adds references to place). */
static bool report_progress(bvh_build_state *b, uint32_t used, float *reported)
{
    if (!b->progress || b->placed < b->report_at) return true;
    b->report_at = b->placed + b->report_step;
    float fraction = (float)((double)b->placed / ((double)b->placed + used));
    if (fraction > *reported) *reported = fraction;
    if (b->progress(b->progress_user, "bvh", *reported)) return true;
    b->cancelled = true;
    return false;
}

/* Makes task's node interior with children bounded by left and right over references
 * [first, first + left_count) and [first + left_count, first + left_count + right_count);
 * pushes the left child and makes *task the right one (on top of the reference stack). */
static void split_right_first(bvh_build_state *b, bvh_build_task *task, uint32_t left_count, uint32_t right_count,
                              const bvh_build_bounds *left, const bvh_build_bounds *right)
{
    uint32_t pair = b->node_count;
    b->node_count += 2;
    bvh_build_pair(b->nodes, task->node, pair, left, right);
    bvh_build_task l = { .node = pair, .first = task->first, .count = left_count, .depth = task->depth + 1 };
    memcpy(l.cmin, left->cmin, sizeof l.cmin);
    memcpy(l.cmax, left->cmax, sizeof l.cmax);
    b->stack[b->sp++] = l;
    task->node = pair + 1;
    task->first += left_count;
    task->count = right_count;
    task->depth++;
    memcpy(task->cmin, right->cmin, sizeof task->cmin);
    memcpy(task->cmax, right->cmax, sizeof task->cmax);
}

/* The overlap of two boxes as a fraction of area `root`, or 0 where they do not overlap. */
static float overlap_fraction(const bvh_build_bounds *l, const bvh_build_bounds *r, float root)
{
    float lo[3], hi[3];
    for (int a = 0; a < 3; a++) {
        lo[a] = bvh_build_max_f(l->bmin[a], r->bmin[a]);
        hi[a] = bvh_build_min_f(l->bmax[a], r->bmax[a]);
        if (!(lo[a] <= hi[a])) return 0.0f;
    }
    return root > 0.0f ? area_of(lo, hi) / root : 0.0f;
}

/* A subtree whose building is left to the parallel phase: its root node (allocated, with its
 * box) and task, and a copy of its references. */
typedef struct sbvh_subtree {
    bvh_build_task task;
    sah_ref *refs;               /* task.count of them; then, in the parallel phase, `cap` */
    uint32_t cap;                /* its reference budget */
    /* Its workspace, allocated on the calling thread (a user's allocator need not be
     * thread-safe) before the parallel phase. */
    sah_ref *scratch;
    sah_binning *bins;
    sbvh_bin (*spatial)[SBVH_BINS];
    /* What building it made: nodes (0 is the root), the triangle order, the deepest leaf. */
    vkrt_gpu_node *nodes;
    uint32_t node_count;
    uint32_t *order;
    uint32_t placed;
    uint32_t depth;
} sbvh_subtree;

/* What one build() call works with. Scratch, bins and spatial bins are its own: a thread each. */
typedef struct sbvh_work {
    const mesh *m;
    sah_ref *refs;
    sah_ref *scratch;            /* as many references as the largest node holds */
    sah_binning *bins;
    sbvh_bin (*spatial)[SBVH_BINS];
    uint32_t max_leaf;
    float root_area;             /* of the whole tree's root, which alpha is relative to */
    float reported;              /* the last progress fraction reported */
    /* The serial phase of a large build: nodes of at most defer_at references (> 0) become
     * subtrees of the parallel phase instead. */
    uint32_t defer_at;
    uint64_t deferred;           /* the references of the subtrees so far */
    sbvh_subtree *subtrees;
    size_t subtree_count, subtree_cap;
    bool out_of_memory;
} sbvh_work;

/* Moves task's references to a new subtree of w. False when out of memory (w says so). */
static bool defer_subtree(core *c, sbvh_work *w, const bvh_build_task *task)
{
    sah_ref *copy = core_alloc_array(c, task->count, sizeof *copy);
    if (!copy || core_grow(c, (void **)&w->subtrees, &w->subtree_cap, w->subtree_count + 1, sizeof *w->subtrees)) {
        core_free(c, copy);
        w->out_of_memory = true;
        return false;
    }
    memcpy(copy, w->refs + task->first, (size_t)task->count * sizeof *copy);
    w->subtrees[w->subtree_count++] = (sbvh_subtree){ .task = *task, .refs = copy };
    w->deferred += task->count;
    return true;
}

static void build(bvh_build_state *b, sbvh_work *w, bvh_build_task task)
{
    const mesh *m = w->m;
    sah_ref *refs = w->refs, *scratch = w->scratch;
    sah_binning *bins = w->bins;
    sbvh_bin (*spatial)[SBVH_BINS] = w->spatial;
    const uint32_t max_leaf = w->max_leaf;
    const float root_area = w->root_area;
    for (;;) {
        const vkrt_gpu_node *node = &b->nodes[task.node];
        const float nmin[3] = { node->bmin.x, node->bmin.y, node->bmin.z };
        const float nmax[3] = { node->bmax.x, node->bmax.y, node->bmax.z };
        bool leaf = task.count == 1 || task.depth >= VKRT_MAX_BVH_DEPTH;
        uint32_t left_count = 0, right_count = 0;
        bvh_build_bounds left, right;
        if (!leaf && task.count <= w->defer_at) {
            /* Built in the parallel phase; its references' room is free again, as a leaf's. */
            if (!defer_subtree(b->c, w, &task) || b->sp == 0) return;
            task = b->stack[--b->sp];
            continue;
        }
        if (!leaf) {
            /* The best object split, as the binned SAH builder finds it. */
            sah_grid g;
            sah_split s = { .axis = -1, .cost = INFINITY };
            bool binnable = bvh_build_sah_grid(&task, &g);
            if (binnable) {
                bvh_build_sah_bin(refs + task.first, refs + task.first + task.count, &g, bins);
                (void)bvh_build_sah_decide(bins, &g, node, task.count, max_leaf, &s);
                if (s.axis >= 0) bvh_build_sah_split_boxes(bins, &s, &left, &right);
            }
            /* The best spatial split, where the object split's children overlap. */
            sbvh_split sp = { .axis = -1, .cost = INFINITY };
            sbvh_grid sg;
            if (s.axis < 0 || overlap_fraction(&left, &right, root_area) > SBVH_OVERLAP_ALPHA) {
                grid_of(node, task.count, &sg);
                spatial_bin(m, refs + task.first, refs + task.first + task.count, &sg, spatial);
                sp = spatial_sweep(spatial, &sg);
                /* Within the budget (the references placed in leaves or left to subtrees, those
                 * below this node and the node's two sides), and not every reference on both sides (which would only
                 * copy the node into two smaller boxes, as often as the budget allows). */
                bool fits = sp.axis >= 0 &&
                            b->placed + w->deferred + task.first + sp.left_n + sp.right_n <= (uint64_t)b->ref_cap &&
                            (sp.left_n < task.count || sp.right_n < task.count);
                if (!fits || !(sp.cost < s.cost)) sp.axis = -1;
            }
            /* SAH's leaf rule with the cheaper split; a node over max_leaf is split wherever it can be. */
            const float area = area_of(nmin, nmax);
            float best_cost = sp.axis >= 0 ? sp.cost : s.cost;
            leaf = task.count <= max_leaf && !(area + best_cost < area * (float)task.count);
            if (!leaf && sp.axis >= 0) {
                left_count = spatial_partition(m, refs, task.first, task.count, &sg, &sp, scratch, &right_count);
                if (left_count != 0 && right_count != 0) {
                    bvh_build_sah_bounds(refs, task.first, left_count, &left);
                    bvh_build_sah_bounds(refs, task.first + left_count, right_count, &right);
                } else {
                    /* Unsplitting sent every reference to one side, unchanged: the object split's
                     * turn, by its own cost. */
                    sp.axis = -1;
                    leaf = task.count <= max_leaf && !(area + s.cost < area * (float)task.count);
                }
            }
            if (!leaf && sp.axis < 0) {
                if (s.axis >= 0) {
                    left_count = bvh_build_sah_partition(refs + task.first, refs + task.first + task.count, &g, &s,
                                                         &left, &right);
                } else if (!bvh_build_sah_median_split(refs, &task, &left_count, &left, &right)) {
                    left_count = 0;
                }
                right_count = task.count - left_count;
            }
            if (binnable) bvh_build_sah_binning_clear(bins);
            leaf = leaf || left_count == 0 || right_count == 0;
        }
        if (!leaf) {
            split_right_first(b, &task, left_count, right_count, &left, &right);
            continue;
        }
        vkrt_gpu_node *n = &b->nodes[task.node];
        n->left_first = (uint32_t)b->placed;
        n->tri_count = task.count;
        for (uint32_t k = 0; k < task.count; k++)
            memcpy(&b->order[b->placed + k], &refs[task.first + k].bmax[3], sizeof b->order[0]);
        if (task.depth > b->depth) b->depth = task.depth;
        b->placed += task.count;
        if (!report_progress(b, task.first, &w->reported) || b->sp == 0) return;
        task = b->stack[--b->sp];
    }
}

/* Sets each interior box to the union of its children's. A node's box is its references' when
 * its parent splits; clipping them for its own split may leave its children's union smaller
 * (by a clip's rounding), and every box exact is what the 4-wide collapse and its checks rely
 * on. Children come after their parent in the array, so one backward pass refits bottom-up. */
static void refit(vkrt_gpu_node *nodes, uint32_t count)
{
    for (uint32_t i = count; i-- > 0;) {
        vkrt_gpu_node *n = &nodes[i];
        if (n->tri_count) continue;
        const vkrt_gpu_node *l = &nodes[n->left_first], *r = &nodes[n->left_first + 1];
        n->bmin = (vkrt_float3){ bvh_build_min_f(r->bmin.x, l->bmin.x), bvh_build_min_f(r->bmin.y, l->bmin.y),
                                 bvh_build_min_f(r->bmin.z, l->bmin.z) };
        n->bmax = (vkrt_float3){ bvh_build_max_f(r->bmax.x, l->bmax.x), bvh_build_max_f(r->bmax.y, l->bmax.y),
                                 bvh_build_max_f(r->bmax.z, l->bmax.z) };
    }
}

/* The parallel phase: every subtree built by one thread (items of a work_pool job), then
 * merged into the serial phase's tree in the order the subtrees were made. */
typedef struct sbvh_job {
    core *c;
    const mesh *m;
    const vkrt_gpu_node *main_nodes; /* the serial phase's: each subtree's root box */
    sbvh_subtree *subtrees;
    uint32_t max_leaf;
    float root_area;
    uint64_t capacity;           /* the whole build's reference budget */
    uint64_t refs;               /* the references after the serial phase: placed and deferred */
    bvh_build_state *b;          /* the serial phase's state, for progress (calling thread) */
    uint64_t placed;             /* the serial phase's leaves' references */
    _Atomic uint64_t done;       /* the references of the subtrees built so far */
    float reported;
} sbvh_job;

static void subtree_free_workspace(core *c, sbvh_subtree *t)
{
    core_free(c, t->refs);
    core_free(c, t->scratch);
    core_free(c, t->bins);
    core_free(c, t->spatial);
    t->refs = t->scratch = NULL;
    t->bins = NULL;
    t->spatial = NULL;
}

static void subtree_free(core *c, sbvh_subtree *t)
{
    subtree_free_workspace(c, t);
    core_free(c, t->nodes);
    core_free(c, t->order);
    t->nodes = NULL;
    t->order = NULL;
}

/* Gives subtree t its budget (its references and its share of what the serial phase left of
 * the build's) and its workspace. False when out of memory. */
static bool subtree_prepare(core *c, const sbvh_job *j, sbvh_subtree *t)
{
    const uint32_t count = t->task.count;
    const uint64_t spare = j->capacity > j->refs ? j->capacity - j->refs : 0;
    t->cap = (uint32_t)(count + spare * count / j->refs);
    sah_ref *refs = core_alloc_array(c, t->cap, sizeof *refs);
    if (!refs) return false;
    memcpy(refs, t->refs, (size_t)count * sizeof *refs);
    core_free(c, t->refs);
    t->refs = refs;
    t->scratch = core_alloc_array(c, count, sizeof *t->scratch);
    t->bins = core_alloc_array(c, 1, sizeof *t->bins);
    t->spatial = core_alloc_array(c, 3, sizeof *t->spatial);
    t->nodes = core_alloc_array(c, 2 * (size_t)t->cap - 1, sizeof *t->nodes);
    t->order = core_alloc_array(c, t->cap, sizeof *t->order);
    return t->scratch && t->bins && t->spatial && t->nodes && t->order;
}

static void build_subtree_item(void *job, uint32_t item)
{
    sbvh_job *j = job;
    sbvh_subtree *t = &j->subtrees[item];
    bvh_build_state sb;
    memset(&sb, 0, offsetof(bvh_build_state, stack));
    sb.c = j->c;
    sb.tri_count = t->task.count;
    sb.ref_cap = t->cap;
    sb.node_cap = 2 * t->cap - 1;
    sb.refs = t->refs;
    sb.nodes = t->nodes;
    sb.order = t->order;
    sb.nodes[0] = j->main_nodes[t->task.node];
    sb.node_count = 1;
    bvh_build_task task = t->task;
    task.node = 0;
    task.first = 0;
    bvh_build_sah_binning_empty(t->bins);
    sbvh_work w = { .m = j->m, .refs = t->refs, .scratch = t->scratch, .bins = t->bins, .spatial = t->spatial,
                    .max_leaf = j->max_leaf, .root_area = j->root_area };
    build(&sb, &w, task);
    t->node_count = sb.node_count;
    t->placed = (uint32_t)sb.placed;
    t->depth = sb.depth;
    atomic_fetch_add(&j->done, t->task.count);
}

/* Progress on the calling thread between subtrees; false cancels the rest. */
static bool subtree_progress(void *job)
{
    sbvh_job *j = job;
    bvh_build_state *b = j->b;
    if (!b->progress) return true;
    float fraction = (float)((double)(j->placed + atomic_load(&j->done)) / (double)j->refs);
    if (fraction > j->reported) j->reported = fraction;
    if (b->progress(b->progress_user, "bvh", j->reported)) return true;
    b->cancelled = true;
    return false;
}

/* Appends every subtree to b's nodes and order: a subtree's root replaces its placeholder
 * node, its other nodes follow the tree's (children stay pairs after their parent), its
 * leaves' ranges move by where its order lands. */
static vkrt_result merge_subtrees(bvh_build_state *b, sbvh_subtree *subtrees, size_t count)
{
    uint64_t nodes = b->node_count, refs = b->placed;
    for (size_t i = 0; i < count; i++) {
        nodes += subtrees[i].node_count - 1;
        refs += subtrees[i].placed;
    }
    if (nodes > UINT32_MAX || refs > UINT32_MAX / 2)
        return core_fail(b->c, VKRT_ERROR_LIMIT, "the spatial-split BVH needs more than %u nodes", UINT32_MAX);
    vkrt_gpu_node *all_nodes = core_alloc_array(b->c, (size_t)nodes, sizeof *all_nodes);
    uint32_t *all_order = core_alloc_array(b->c, (size_t)refs, sizeof *all_order);
    if (!all_nodes || !all_order) {
        core_free(b->c, all_nodes);
        core_free(b->c, all_order);
        return core_fail(b->c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory merging the spatial-split BVH of %u triangles",
                         b->tri_count);
    }
    memcpy(all_nodes, b->nodes, (size_t)b->node_count * sizeof *all_nodes);
    memcpy(all_order, b->order, (size_t)b->placed * sizeof *all_order);
    uint32_t next_node = b->node_count, next_ref = (uint32_t)b->placed;
    for (size_t i = 0; i < count; i++) {
        const sbvh_subtree *t = &subtrees[i];
        /* Local node k > 0 lands at next_node + k - 1, the root at its placeholder. */
        for (uint32_t k = 0; k < t->node_count; k++) {
            vkrt_gpu_node n = t->nodes[k];
            n.left_first = n.tri_count ? n.left_first + next_ref : next_node + n.left_first - 1;
            all_nodes[k ? next_node + k - 1 : t->task.node] = n;
        }
        memcpy(all_order + next_ref, t->order, (size_t)t->placed * sizeof *all_order);
        next_node += t->node_count - 1;
        next_ref += t->placed;
        if (t->depth > b->depth) b->depth = t->depth;
    }
    core_free(b->c, b->nodes);
    core_free(b->c, b->order);
    b->nodes = all_nodes;
    b->node_count = b->node_cap = (uint32_t)nodes;
    b->order = all_order;
    b->placed = refs;
    b->ref_cap = (uint32_t)refs;
    return VKRT_OK;
}

/* The parallel phase on `threads` threads. On failure nothing of the subtrees is left. */
static vkrt_result build_subtrees(bvh_build_state *b, sbvh_work *w, uint32_t threads)
{
    sbvh_job j = { .c = b->c, .m = w->m, .main_nodes = b->nodes, .subtrees = w->subtrees, .max_leaf = w->max_leaf,
                   .root_area = w->root_area, .capacity = b->ref_cap, .refs = b->placed + w->deferred, .b = b,
                   .placed = b->placed, .reported = w->reported };
    atomic_init(&j.done, 0);
    vkrt_result r = VKRT_OK;
    for (size_t i = 0; i < w->subtree_count && r == VKRT_OK; i++)
        if (!subtree_prepare(b->c, &j, &w->subtrees[i]))
            r = core_fail(b->c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory building the spatial-split BVH of %u triangles",
                          b->tri_count);
    work_pool *pool = NULL;
    if (r == VKRT_OK) r = work_pool_create(b->c, threads, &pool);
    if (r == VKRT_OK) {
        work_pool_run(pool, (uint32_t)w->subtree_count, build_subtree_item, subtree_progress, &j);
        work_pool_destroy(pool);
        if (!b->cancelled) r = merge_subtrees(b, w->subtrees, w->subtree_count);
    }
    for (size_t i = 0; i < w->subtree_count; i++) subtree_free(b->c, &w->subtrees[i]);
    return r;
}

vkrt_result bvh_build_sbvh(core *c, const mesh *m, const bvh_build_desc *desc, bvh *out)
{
    uint64_t budget = (uint64_t)m->tri_count * SBVH_REFERENCE_BUDGET_NUM / SBVH_REFERENCE_BUDGET_DEN;
    uint32_t capacity = budget < UINT32_MAX / 2 ? (uint32_t)budget : UINT32_MAX / 2;
    bvh_build_state b;
    vkrt_result r = bvh_build_begin_capacity(&b, c, m, desc, sizeof(sah_ref), SAH_REF_TRI_OFFSET, capacity, out);
    if (r != VKRT_OK) return r;
    sbvh_work w = { .m = m, .refs = b.refs, .max_leaf = desc && desc->max_leaf_size ? desc->max_leaf_size
                                                                                     : SAH_DEFAULT_MAX_LEAF,
                    .defer_at = b.tri_count > SBVH_TASK_REFS ? SBVH_TASK_REFS : 0 };
    w.scratch = core_alloc_array(c, b.tri_count, sizeof *w.scratch);
    w.bins = core_alloc_array(c, 1, sizeof *w.bins);
    w.spatial = core_alloc_array(c, 3, sizeof *w.spatial);
    if (w.scratch && w.bins && w.spatial) {
        bvh_build_bounds root;
        bvh_build_sah_refs(m, b.refs, 0, b.tri_count, &root);
        w.root_area = area_of(root.bmin, root.bmax);
        bvh_build_sah_binning_empty(w.bins);
        bvh_build_task task;
        if (bvh_build_start(&b, &root, &task)) build(&b, &w, task);
    } else {
        w.out_of_memory = true;
    }
    core_free(c, w.scratch);
    core_free(c, w.bins);
    core_free(c, w.spatial);
    if (w.out_of_memory)
        r = core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory building the spatial-split BVH of %u triangles",
                      m->tri_count);
    if (r == VKRT_OK && !b.cancelled && w.subtree_count)
        r = build_subtrees(&b, &w, desc && desc->threads ? desc->threads : 1);
    for (size_t i = 0; i < w.subtree_count; i++) subtree_free(c, &w.subtrees[i]);
    core_free(c, w.subtrees);
    if (r != VKRT_OK) {
        bvh_build_abort(&b);
        memset(out, 0, sizeof *out);
        return r;
    }
    if (!b.cancelled && b.progress && !b.progress(b.progress_user, "bvh", 1.0f)) b.cancelled = true;
    if (!b.cancelled) refit(b.nodes, b.node_count);
    b.order_filled = true;
    b.tri_count = (uint32_t)b.placed;
    r = bvh_build_finish(&b, out);
    if (r == VKRT_OK) out->spatial_splits = true;
    return r;
}
