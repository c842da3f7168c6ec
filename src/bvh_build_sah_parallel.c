/* The binned SAH builder on several threads, for meshes of more than SAH_TASK_REFS triangles.
 *
 * The two-phase scheme of I. Wald, "Fast Construction of SAH BVHs on the Intel Many
 * Integrated Core (MIC) Architecture", IEEE TVCG 18(1), 2012 (Embree's builders work the
 * same way): the top levels, where nodes are few and large, are split level by level with all
 * threads binning and partitioning fixed pieces of each node's references together; below
 * SAH_TASK_REFS references a node is a subtree that one thread builds serially
 * (bvh_build_sah_subtree()), largest subtrees first.
 *
 * The result does not depend on the thread count or on scheduling, bit for bit:
 * - the pieces are SAH_CHUNK_REFS references, not one per thread, and their bins and bounds
 *   are merged in piece order by the calling thread, so every split decision sees the same
 *   numbers;
 * - the top levels partition in place in two steps: each piece partitions itself, then the
 *   right-side references left of the node's split point trade places with the left-side
 *   ones right of it, the k-th of the one kind with the k-th of the other, so the order of
 *   references is a function of the decisions alone;
 * - every node of n references owns 2n - 2 node slots for its descendants, fixed before it
 *   is built: its children pair first, then the left child's slots, then the right child's.
 *   A subtree fills the start of its slots in the serial builder's depth-first order and
 *   leaves the rest unused; squeezing those holes out at the end gives exactly the node array
 *   of one thread building the same tree depth first (children adjacent, node 0 the root).
 *
 * Progress reports and the user's callback stay on the calling thread (work_pool.h); workers
 * poll for cancellation. The top levels place no triangle in a leaf; they report the progress
 * as it stands (0) after each pass over a level's pieces, so that the callback can cancel
 * there too. Every allocation is made on the calling thread between the workers'
 * jobs, and each can fail cleanly: the build then frees everything and returns
 * VKRT_ERROR_OUT_OF_MEMORY. */
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#include "bvh_build_sah.h"

/* Pieces of the top levels: large enough that a piece's bins (3.5 KB) are merged at a small
 * cost per reference, small enough that the smallest node split here has three to share. */
#define SAH_CHUNK_REFS 4096

/* A node of the top levels, or the root of a subtree. */
typedef struct top_node {
    bvh_build_task task;           /* task.node is its slot; its box is already there */
    uint32_t region;               /* its descendants' slots: 2 * count - 2 from here */
    uint32_t chunk0, chunks;       /* its pieces in the level's piece array */
    sah_grid grid;
    sah_split split;               /* axis -1 where it becomes a subtree */
    uint32_t left_count;
    bvh_build_bounds left, right;  /* of its children */
} top_node;

/* A piece of a top node's references. */
typedef struct sah_chunk {
    uint32_t node;                 /* its top node in the level */
    uint32_t first, count;
    bvh_build_bounds bounds[2];    /* of its references (setup) / of its left and right ones */
} sah_chunk;

/* References on the wrong side of their node's split point after the pieces partitioned
 * themselves: a run of right-side ones left of it, or of left-side ones right of it. */
typedef struct sah_run {
    uint32_t first, count;
} sah_run;

/* A position in a list of runs: reference `at` of run `run`. */
typedef struct run_cursor {
    uint32_t run, at;
} run_cursor;

/* Trades of places for one worker: `count` references of the level's misplaced right-side
 * runs from `right` on with as many of the left-side ones from `left` on. */
typedef struct sah_trade {
    run_cursor right, left;
    uint32_t count;
} sah_trade;

typedef struct subtree {
    bvh_build_task task;
    uint32_t region;
    uint32_t used;                 /* slots its build filled, from region on */
    uint32_t depth;                /* of its deepest leaf */
    uint32_t shift;                /* unused slots before it: its nodes move down this far */
} subtree;

/* A top node that was split, for renumbering its children at the end. */
typedef struct top_split {
    uint32_t slot, region, first;
    uint32_t pair;                 /* where its children go in the compacted array */
} top_split;

typedef struct sah_job {
    bvh_build_state *b;
    const mesh *m;
    uint32_t max_leaf;
    work_pool *pool;
    sah_ref *refs;
    top_node *level, *next;
    uint32_t level_count, next_count, level_cap;
    sah_chunk *chunks;
    sah_binning *chunk_bins;
    uint32_t chunk_count, chunk_cap;
    sah_run *misplaced[2];         /* right-side runs left of split points, left-side ones right */
    uint32_t misplaced_count[2];
    sah_trade *trades;
    uint32_t trade_count;
    subtree *subtrees;
    size_t subtree_count, subtree_cap;
    top_split *splits;
    size_t split_count, split_cap;
    _Atomic uint64_t placed;       /* triangles in the leaves of finished subtrees */
} sah_job;

/* ---- setup: references and root bounds ------------------------------------------------ */

static void setup_chunk(void *job, uint32_t i)
{
    sah_job *j = job;
    uint32_t first = i * SAH_CHUNK_REFS, n = j->b->tri_count - first;
    bvh_build_sah_refs(j->m, j->refs, first, n < SAH_CHUNK_REFS ? n : SAH_CHUNK_REFS, &j->chunks[i].bounds[0]);
}

static void bounds_merge(bvh_build_bounds *into, const bvh_build_bounds *from)
{
    bvh_build_box_grow(into->bmin, into->bmax, from->bmin, from->bmax);
    bvh_build_box_grow(into->cmin, into->cmax, from->cmin, from->cmax);
}

/* ---- top levels ------------------------------------------------------------------------- */

static void bin_chunk(void *job, uint32_t i)
{
    sah_job *j = job;
    const sah_chunk *k = &j->chunks[i];
    bvh_build_sah_binning_empty(&j->chunk_bins[i]);
    bvh_build_sah_bin(j->refs + k->first, j->refs + k->first + k->count, &j->level[k->node].grid, &j->chunk_bins[i]);
}

/* The first step of a split node's partition: each piece on its own, bounding both sides. */
static void partition_chunk(void *job, uint32_t i)
{
    sah_job *j = job;
    sah_chunk *k = &j->chunks[i];
    const top_node *t = &j->level[k->node];
    if (t->split.axis < 0) return;
    bvh_build_sah_partition(j->refs + k->first, j->refs + k->first + k->count, &t->grid, &t->split, &k->bounds[0],
                            &k->bounds[1]);
}

/* References left in the cursor's run. */
static uint32_t run_rest(const sah_run *runs, run_cursor c) { return runs[c.run].count - c.at; }

static void cursor_advance(const sah_run *runs, run_cursor *c, uint32_t n)
{
    while (n) {
        uint32_t step = run_rest(runs, *c) < n ? run_rest(runs, *c) : n;
        c->at += step;
        n -= step;
        if (c->at == runs[c->run].count) {
            c->run++;
            c->at = 0;
        }
    }
}

/* The second step: trades places between misplaced references of both sides. */
static void trade_chunk(void *job, uint32_t i)
{
    sah_job *j = job;
    sah_trade t = j->trades[i];
    const sah_run *right = j->misplaced[0], *left = j->misplaced[1];
    while (t.count) {
        uint32_t n = t.count;
        if (run_rest(right, t.right) < n) n = run_rest(right, t.right);
        if (run_rest(left, t.left) < n) n = run_rest(left, t.left);
        sah_ref *a = j->refs + right[t.right.run].first + t.right.at, *b = j->refs + left[t.left.run].first + t.left.at;
        for (uint32_t k = 0; k < n; k++) {
            sah_ref tmp = a[k];
            a[k] = b[k];
            b[k] = tmp;
        }
        t.count -= n;
        cursor_advance(right, &t.right, n);
        cursor_advance(left, &t.left, n);
    }
}

static uint32_t chunk_left_count(const sah_job *j, const top_node *t, uint32_t chunk)
{
    uint32_t n = 0;
    for (int k = 0; k < t->split.plane; k++) n += j->chunk_bins[chunk].count[t->split.axis][k];
    return n;
}

/* Lists the misplaced runs of split node t (from how many left-side references each piece
 * holds) and cuts their trades into jobs of SAH_CHUNK_REFS. */
static void plan_trades(sah_job *j, const top_node *t)
{
    uint32_t split_at = t->task.first + t->left_count;
    uint32_t first_run[2] = { j->misplaced_count[0], j->misplaced_count[1] };
    for (uint32_t c = 0; c < t->chunks; c++) {
        const sah_chunk *k = &j->chunks[t->chunk0 + c];
        uint32_t mid = k->first + chunk_left_count(j, t, t->chunk0 + c), end = k->first + k->count;
        if (mid < split_at) { /* right-side references of this piece lie left of the split */
            uint32_t stop = end < split_at ? end : split_at;
            if (stop > mid) j->misplaced[0][j->misplaced_count[0]++] = (sah_run){ mid, stop - mid };
        } else if (mid > split_at) { /* left-side ones lie right of it */
            uint32_t start = k->first > split_at ? k->first : split_at;
            if (mid > start) j->misplaced[1][j->misplaced_count[1]++] = (sah_run){ start, mid - start };
        }
    }
    uint32_t total = 0;
    for (uint32_t r = first_run[0]; r < j->misplaced_count[0]; r++) total += j->misplaced[0][r].count;
    /* Walk both lists in step, starting a job every SAH_CHUNK_REFS trades. */
    sah_trade at = { .right = { first_run[0], 0 }, .left = { first_run[1], 0 } };
    for (uint32_t done = 0; done < total;) {
        at.count = total - done < SAH_CHUNK_REFS ? total - done : SAH_CHUNK_REFS;
        j->trades[j->trade_count++] = at;
        done += at.count;
        cursor_advance(j->misplaced[0], &at.right, at.count);
        cursor_advance(j->misplaced[1], &at.left, at.count);
    }
}

static bool add_subtree(sah_job *j, const top_node *t)
{
    if (core_grow(j->b->c, (void **)&j->subtrees, &j->subtree_cap, j->subtree_count + 1, sizeof *j->subtrees) != 0)
        return false;
    j->subtrees[j->subtree_count++] = (subtree){ .task = t->task, .region = t->region };
    return true;
}

/* Chooses the split of each large node of the level from its pieces' bins; the others, and
 * those that bins cannot split well, become subtrees. */
static bool decide_level(sah_job *j)
{
    for (uint32_t n = 0; n < j->level_count; n++) {
        top_node *t = &j->level[n];
        if (!t->chunks) continue;
        sah_binning merged;
        bvh_build_sah_binning_empty(&merged);
        for (uint32_t c = t->chunk0; c < t->chunk0 + t->chunks; c++) bvh_build_sah_binning_merge(&merged, &j->chunk_bins[c]);
        sah_decision d = bvh_build_sah_decide(&merged, &t->grid, &j->b->nodes[t->task.node], t->task.count,
                                              j->max_leaf, &t->split);
        uint32_t left_count = 0;
        for (int k = 0; d == SAH_SPLIT && k < t->split.plane; k++) left_count += merged.count[t->split.axis][k];
        if (d != SAH_SPLIT || left_count == 0 || left_count == t->task.count) {
            /* A leaf or a median split: the subtree builder does both. */
            t->split.axis = -1;
            if (!add_subtree(j, t)) return false;
            continue;
        }
        t->left_count = left_count;
        bvh_build_sah_split_boxes(&merged, &t->split, &t->left, &t->right);
        plan_trades(j, t);
    }
    return true;
}

/* Gives each split node its children pair and makes them the next level. */
static bool split_level(sah_job *j)
{
    j->next_count = 0;
    for (uint32_t n = 0; n < j->level_count; n++) {
        top_node *t = &j->level[n];
        if (!t->chunks || t->split.axis < 0) continue;
        bvh_build_box_empty(t->left.cmin, t->left.cmax);
        bvh_build_box_empty(t->right.cmin, t->right.cmax);
        for (uint32_t c = t->chunk0; c < t->chunk0 + t->chunks; c++) {
            const sah_chunk *k = &j->chunks[c];
            bvh_build_box_grow(t->left.cmin, t->left.cmax, k->bounds[0].cmin, k->bounds[0].cmax);
            bvh_build_box_grow(t->right.cmin, t->right.cmax, k->bounds[1].cmin, k->bounds[1].cmax);
        }
        bvh_build_pair(j->b->nodes, t->task.node, t->region, &t->left, &t->right);
        if (core_grow(j->b->c, (void **)&j->splits, &j->split_cap, j->split_count + 1, sizeof *j->splits) != 0)
            return false;
        j->splits[j->split_count++] = (top_split){ .slot = t->task.node, .region = t->region, .first = t->task.first };
        const bvh_build_bounds *side[2] = { &t->left, &t->right };
        uint32_t first[2] = { t->task.first, t->task.first + t->left_count };
        uint32_t count[2] = { t->left_count, t->task.count - t->left_count };
        /* The left child's descendants take the slots after the pair, the right child's
         * follow them. */
        uint32_t region[2] = { t->region + 2, t->region + 2 * t->left_count };
        for (int s = 0; s < 2; s++) {
            top_node *child = &j->next[j->next_count++];
            memset(child, 0, sizeof *child);
            child->task = (bvh_build_task){ .node = t->region + (uint32_t)s, .first = first[s], .count = count[s],
                                            .depth = t->task.depth + 1 };
            memcpy(child->task.cmin, side[s]->cmin, sizeof child->task.cmin);
            memcpy(child->task.cmax, side[s]->cmax, sizeof child->task.cmax);
            child->region = region[s];
        }
    }
    return true;
}

/* Splits the top levels; every node left unsplit is added to j->subtrees. Returns false when
 * out of memory; a cancel by the progress callback returns true with j->b->cancelled set. */
static bool build_top(sah_job *j, const bvh_build_task *root)
{
    j->level_count = 1;
    memset(&j->level[0], 0, sizeof j->level[0]);
    j->level[0].task = *root;
    j->level[0].region = 1;
    while (j->level_count) {
        j->chunk_count = 0;
        j->misplaced_count[0] = j->misplaced_count[1] = 0;
        j->trade_count = 0;
        for (uint32_t n = 0; n < j->level_count; n++) {
            top_node *t = &j->level[n];
            t->chunks = 0;
            t->split.axis = -1;
            if (t->task.count <= SAH_TASK_REFS || t->task.depth >= VKRT_MAX_BVH_DEPTH ||
                !bvh_build_sah_grid(&t->task, &t->grid)) {
                if (!add_subtree(j, t)) return false;
                continue;
            }
            t->chunk0 = j->chunk_count;
            t->chunks = core_div_up(t->task.count, SAH_CHUNK_REFS);
            for (uint32_t c = 0; c < t->chunks; c++) {
                uint32_t first = c * SAH_CHUNK_REFS, n_left = t->task.count - first;
                j->chunks[j->chunk_count++] = (sah_chunk){ .node = n, .first = t->task.first + first,
                                                           .count = n_left < SAH_CHUNK_REFS ? n_left : SAH_CHUNK_REFS };
            }
        }
        if (!j->chunk_count) break;
        work_pool_run(j->pool, j->chunk_count, bin_chunk, NULL, j);
        if (!bvh_build_poll(j->b)) return true;
        if (!decide_level(j)) return false;
        work_pool_run(j->pool, j->chunk_count, partition_chunk, NULL, j);
        if (!bvh_build_poll(j->b)) return true;
        work_pool_run(j->pool, j->trade_count, trade_chunk, NULL, j);
        if (!bvh_build_poll(j->b)) return true;
        if (!split_level(j)) return false;
        top_node *swap = j->level;
        j->level = j->next;
        j->next = swap;
        j->level_count = j->next_count;
    }
    return true;
}

/* ---- subtrees ---------------------------------------------------------------------------- */

static void build_subtree_item(void *job, uint32_t i)
{
    sah_job *j = job;
    subtree *t = &j->subtrees[i];
    bvh_build_state s;
    bvh_build_subtree_state(j->b, t->region, &s);
    sah_binning bins;
    bvh_build_sah_binning_empty(&bins);
    bvh_build_sah_subtree(&s, j->refs, t->task, j->max_leaf, &bins, j->pool);
    t->used = s.node_count - t->region;
    t->depth = s.depth;
    atomic_fetch_add_explicit(&j->placed, s.placed, memory_order_relaxed);
}

static bool report_progress(void *job)
{
    sah_job *j = job;
    return bvh_build_progress(j->b, atomic_load_explicit(&j->placed, memory_order_relaxed));
}

/* Largest first, so no thread starts a big subtree when the others are about to finish. */
static int by_size_then_first(const void *pa, const void *pb)
{
    const subtree *a = pa, *b = pb;
    if (a->task.count != b->task.count) return a->task.count > b->task.count ? -1 : 1;
    return a->task.first < b->task.first ? -1 : a->task.first > b->task.first;
}

static int by_first(const void *pa, const void *pb)
{
    const subtree *a = pa, *b = pb;
    return a->task.first < b->task.first ? -1 : a->task.first > b->task.first;
}

static int by_region(const void *pa, const void *pb)
{
    const top_split *a = pa, *b = pb;
    return a->region < b->region ? -1 : a->region > b->region;
}

/* ---- the node array without its holes ------------------------------------------------------ */

/* The subtree whose references start at `first` (there is one for each split's first). */
static const subtree *subtree_at(const sah_job *j, uint32_t first)
{
    size_t lo = 0, hi = j->subtree_count;
    while (hi - lo > 1) {
        size_t mid = lo + (hi - lo) / 2;
        if (j->subtrees[mid].task.first <= first) lo = mid;
        else hi = mid;
    }
    return &j->subtrees[lo];
}

static void shift_children(vkrt_gpu_node *n, uint32_t shift)
{
    if (n->tri_count == 0) n->left_first -= shift;
}

/* Reads one subtree's part of the triangle order (bvh_build_finish() would on one thread). */
static void fill_subtree_order(void *job, uint32_t i)
{
    sah_job *j = job;
    const subtree *t = &j->subtrees[i];
    for (uint32_t k = t->task.first; k < t->task.first + t->task.count; k++)
        memcpy(&j->b->order[k], &j->refs[k].bmax[3], sizeof j->b->order[k]);
}

/* Squeezes the unused slots out of the node array: every node moves down by the unused slots
 * before it, and every interior node's children with it. In place, on the calling thread, in
 * ascending order of slots, which is safe because no node moves up; bvh_build_finish() then
 * gives back the array's tail without touching it (core_shrink). Copying the subtrees into a
 * new array of the exact size, one per worker, built the full dragon in the same time within
 * the noise, but it allocated 31 MB more and needed this path anyway for when it could not. */
static void compact(sah_job *j)
{
    bvh_build_state *b = j->b;
    vkrt_gpu_node *nodes = b->nodes;
    qsort(j->subtrees, j->subtree_count, sizeof *j->subtrees, by_first);
    uint32_t holes = 0;
    b->depth = 0;
    for (size_t i = 0; i < j->subtree_count; i++) {
        subtree *t = &j->subtrees[i];
        t->shift = holes;
        holes += 2 * t->task.count - 2 - t->used;
        if (t->depth > b->depth) b->depth = t->depth;
        shift_children(&nodes[t->task.node], t->shift); /* a subtree's root is in a top pair */
    }
    for (size_t i = 0; i < j->split_count; i++) {
        top_split *s = &j->splits[i];
        s->pair = s->region - subtree_at(j, s->first)->shift;
        nodes[s->slot].left_first = s->pair;
    }
    work_pool_run(j->pool, (uint32_t)j->subtree_count, fill_subtree_order, NULL, j);
    b->order_filled = true;
    /* Ascending source slots: merge the pairs of the splits with the subtrees' ranges (a root
     * built as one subtree has no splits, nor an array of them). */
    if (j->split_count > 1) qsort(j->splits, j->split_count, sizeof *j->splits, by_region);
    size_t si = 0, ti = 0;
    while (si < j->split_count || ti < j->subtree_count) {
        bool pair = ti == j->subtree_count || (si < j->split_count && j->splits[si].region < j->subtrees[ti].region);
        if (pair) {
            const top_split *s = &j->splits[si++];
            memmove(&nodes[s->pair], &nodes[s->region], 2 * sizeof *nodes);
            continue;
        }
        const subtree *t = &j->subtrees[ti++];
        for (uint32_t k = 0; k < t->used; k++) {
            vkrt_gpu_node *to = &nodes[t->region - t->shift + k];
            *to = nodes[t->region + k];
            shift_children(to, t->shift);
        }
    }
    b->node_count = b->node_cap - holes;
}

/* ---- entry ---------------------------------------------------------------------------------- */

static void job_free(sah_job *j)
{
    core *c = j->b->c;
    work_pool_destroy(j->pool);
    void *owned[] = { j->level, j->next, j->chunks, j->chunk_bins, j->misplaced[0], j->misplaced[1], j->trades,
                      j->subtrees, j->splits };
    for (size_t i = 0; i < sizeof owned / sizeof owned[0]; i++) core_free(c, owned[i]);
}

vkrt_result bvh_build_sah_parallel(bvh_build_state *b, const mesh *m, uint32_t max_leaf, uint32_t threads)
{
    core *c = b->c;
    uint32_t n = b->tri_count;
    sah_job j = { .b = b, .m = m, .max_leaf = max_leaf };
    j.refs = b->refs;
    atomic_init(&j.placed, 0);
    /* A level holds the children of nodes larger than SAH_TASK_REFS, so at most
     * 2 n / SAH_TASK_REFS; its pieces number at most one per SAH_CHUNK_REFS references plus
     * one per node (the last, partial piece); the setup's pieces fit in that too. */
    j.level_cap = 2 * (n / SAH_TASK_REFS) + 2;
    j.chunk_cap = n / SAH_CHUNK_REFS + n / SAH_TASK_REFS + 2;
    /* More threads than the root has pieces would find nothing to do at the top. */
    if (threads > n / SAH_CHUNK_REFS + 1) threads = n / SAH_CHUNK_REFS + 1;
    vkrt_result r = work_pool_create(c, threads, &j.pool);
    if (r != VKRT_OK) {
        bvh_build_abort(b);
        return r;
    }
    j.level = core_alloc_array(c, j.level_cap, sizeof *j.level);
    j.next = core_alloc_array(c, j.level_cap, sizeof *j.next);
    j.chunks = core_alloc_array(c, j.chunk_cap, sizeof *j.chunks);
    j.chunk_bins = core_alloc_array(c, j.chunk_cap, sizeof *j.chunk_bins);
    /* Each piece adds at most one misplaced run; the trades of a node come in jobs of
     * SAH_CHUNK_REFS, at most half its references, so they fit the pieces' bound too. */
    j.misplaced[0] = core_alloc_array(c, j.chunk_cap, sizeof *j.misplaced[0]);
    j.misplaced[1] = core_alloc_array(c, j.chunk_cap, sizeof *j.misplaced[1]);
    j.trades = core_alloc_array(c, j.chunk_cap, sizeof *j.trades);
    if (!j.level || !j.next || !j.chunks || !j.chunk_bins || !j.misplaced[0] || !j.misplaced[1] || !j.trades)
        goto out_of_memory;

    uint32_t setup_chunks = core_div_up(n, SAH_CHUNK_REFS);
    work_pool_run(j.pool, setup_chunks, setup_chunk, NULL, &j);
    bvh_build_bounds root;
    bvh_build_bounds_empty(&root);
    for (uint32_t i = 0; i < setup_chunks; i++) bounds_merge(&root, &j.chunks[i].bounds[0]);
    bvh_build_task task;
    if (!bvh_build_start(b, &root, &task)) {
        job_free(&j);
        return VKRT_OK; /* b->cancelled: bvh_build_finish() reports it */
    }
    if (!build_top(&j, &task)) goto out_of_memory;
    if (b->cancelled) {
        job_free(&j);
        return VKRT_OK;
    }

    qsort(j.subtrees, j.subtree_count, sizeof *j.subtrees, by_size_then_first);
    bool finished = work_pool_run(j.pool, (uint32_t)j.subtree_count, build_subtree_item, report_progress, &j);
    if (finished && !b->cancelled) {
        compact(&j);
        b->placed = n;
        bvh_build_progress(b, n);
    } else {
        b->cancelled = true;
    }
    job_free(&j);
    return VKRT_OK;

out_of_memory:
    job_free(&j);
    bvh_build_abort(b);
    return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory building the BVH of %u triangles on %u threads", n,
                     threads);
}
