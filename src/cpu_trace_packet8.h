/* Eight coherent float rays through the 4-wide BVH together (a packet, one ray per float8
 * lane): each child box is tested against the eight rays at once, so rays that enter the same
 * nodes (primary rays of neighbouring pixels) share one fetch, one sort and one stack entry
 * per node. Included by src/cpu_trace.c after cpu_trace_bvh4.h.
 *
 * Same answers as the single-ray traversals: in lane l the box arithmetic is intersect_box_f's
 * for ray l, operation for operation (slab() included, its +-0 direction branch as a per-lane
 * select), against ray l's own closest hit so far; a leaf's triangles are tested for the lanes
 * that entered it with test_leaf_f on ray l, and the closest hit is chosen by hit_closer,
 * which the order of the visits does not change. A lane that entered no box of a subtree
 * tests nothing in it; an any-hit lane stops at its first hit while the others go on.
 *
 * Eight lanes, not four: a node's four box tests cost the same instructions for eight rays as
 * for four where float8 is one AVX register (the x86-64-v3 build), and the fetch, sort and
 * stack work is shared by twice the rays: 0.83-0.87x the time of four-ray packets on the standard
 * view's primary rays (docs/issue7.md, the thirty-third session). The baseline build's float8
 * is two SSE2 halves, the same bits.
 *
 * Packets as in Wald, Slusallek, Benthin, Wagner, "Interactive Rendering with Coherent Ray
 * Tracing", Eurographics 2001, here over a 4-wide tree: the hit children in order of the
 * nearest entry distance among their lanes. */

#define PACKET8_LANES 8
_Static_assert(PACKET8_LANES == CPU_TRACE_PACKET_LANES, "cpu_trace.h names the packets' width");
#define PACKET8_ALL 0xFFu
/* As BVH4_STACK_SIZE: at most BVH4_WIDTH - 1 entries pushed per level. */
#define PACKET8_STACK_SIZE BVH4_STACK_SIZE

typedef struct packet8 {
    ray_f ray[PACKET8_LANES];   /* what the triangle tests read */
    hit_f best[PACKET8_LANES];  /* each lane's closest hit so far */
    float8 origin[3], inv_dir[3], tmin, best_t; /* per axis, lane l = ray l's; best_t: prune bounds */
    float8 parallel[3];         /* lanes whose inv_dir is infinite on the axis (slab()'s other branch) */
    bool any_parallel;
} packet8;

/* A subtree to visit for the lanes in mask, with each lane's entry distance. */
typedef struct packet8_item {
    float8 tnear;
    uint32_t first, count;      /* as bvh4_item */
    unsigned mask;
} packet8_item;

/* Each lane's prune bound (prune_bound_f) of its closest hit so far, put together in
 * registers: eight scalar stores read back as one vector would each miss the store forwarding. */
static inline float8 packet8_prune_bounds(const hit_f best[PACKET8_LANES])
{
    return f8_set(prune_bound_f(best[0].t), prune_bound_f(best[1].t), prune_bound_f(best[2].t), prune_bound_f(best[3].t),
                  prune_bound_f(best[4].t), prune_bound_f(best[5].t), prune_bound_f(best[6].t), prune_bound_f(best[7].t));
}

/* The lane constants that follow from p->inv_dir and the rays' tmax: no hit yet, the lanes
 * parallel to each axis, and per lane the prune bound of the closest hit so far
 * (prune_bound_f): what boxes and stack entries are held to. */
static void packet8_lanes_start(packet8 *p, const float tmax[PACKET8_LANES])
{
    for (int l = 0; l < PACKET8_LANES; l++) p->best[l] = (hit_f){ .t = tmax[l], .tri = NO_PRIM, .prim = NO_PRIM };
    for (int a = 0; a < 3; a++) p->parallel[a] = f8_eq(f8_abs(p->inv_dir[a]), f8_set1(INFINITY));
    p->any_parallel = f8_bits(f8_or(f8_or(p->parallel[0], p->parallel[1]), p->parallel[2])) != 0;
    p->best_t = packet8_prune_bounds(p->best);
}

/* Fills p's lane constants from p->ray (each as ray_setup_f made it). The vectors are put
 * together in registers: eight scalar stores read back as one vector would each miss the
 * store forwarding. */
static void packet8_setup(packet8 *p)
{
    const ray_f *r = p->ray;
#define PACKET8_GATHER(field) f8_set(r[0].field, r[1].field, r[2].field, r[3].field, r[4].field, r[5].field, r[6].field, r[7].field)
    p->origin[0] = PACKET8_GATHER(origin.x);
    p->origin[1] = PACKET8_GATHER(origin.y);
    p->origin[2] = PACKET8_GATHER(origin.z);
    p->inv_dir[0] = PACKET8_GATHER(inv_dir.x);
    p->inv_dir[1] = PACKET8_GATHER(inv_dir.y);
    p->inv_dir[2] = PACKET8_GATHER(inv_dir.z);
    p->tmin = PACKET8_GATHER(tmin);
#undef PACKET8_GATHER
    float tmax[PACKET8_LANES];
    for (int l = 0; l < PACKET8_LANES; l++) tmax[l] = r[l].tmax;
    packet8_lanes_start(p, tmax);
}

/* p from eight buffer rays: each lane's ray as ray_from_buffer_f makes it and the lane
 * constants as packet8_setup makes them, bit for bit, but with the twelve reciprocals and
 * shears divided eight lanes at a time (a division rounds alike at either width; one ray's six
 * scalar divisions and axis choice held 6% of a profile of the CPU's primary rays). False,
 * with p unusable, where one of the rays must miss (ray_from_buffer_f's checks). */
static bool packet8_load(const vkrt_ray rays[PACKET8_LANES], packet8 *p)
{
    float4 o4[2][4], d4[2][4];
    for (int half = 0; half < 2; half++) {
        ray4_load(rays + 4 * half, o4[half], d4[half]);
        if (f4_bits(ray4_valid(o4[half], d4[half])) != 0xFu) return false;
    }
    float8 o[4], d[4];
    for (int a = 0; a < 4; a++) o[a] = f8_join(o4[0][a], o4[1][a]), d[a] = f8_join(d4[0][a], d4[1][a]);
    const float8 one = f8_set1(1.0f), zero = f8_set1(0.0f);
    for (int a = 0; a < 3; a++) {
        p->origin[a] = o[a];
        p->inv_dir[a] = f8_div(one, d[a]);
    }
    p->tmin = o[3];
    /* ray_setup_f's watertight axes: kz that of the largest |dir| (the lower axis on a tie),
     * kx and ky from watertight_axes; then the shear. */
    const float8 ax = f8_abs(d[0]), ay = f8_abs(d[1]), az = f8_abs(d[2]);
    const float8 z_is_x = f8_and(f8_ge(ax, ay), f8_ge(ax, az)), z_is_y = f8_andnot(z_is_x, f8_ge(ay, az));
    const float8 dz = f8_select(z_is_x, d[0], f8_select(z_is_y, d[1], d[2]));
    const float8 next = f8_select(z_is_x, d[1], f8_select(z_is_y, d[2], d[0]));
    const float8 after = f8_select(z_is_x, d[2], f8_select(z_is_y, d[0], d[1]));
    const float8 flip = f8_lt(dz, zero);
    float shear[3][PACKET8_LANES], org[3][PACKET8_LANES], dir[3][PACKET8_LANES], inv[3][PACKET8_LANES],
        tmin[PACKET8_LANES], tmax[PACKET8_LANES];
    f8_store(shear[0], f8_div(f8_select(flip, after, next), dz));
    f8_store(shear[1], f8_div(f8_select(flip, next, after), dz));
    f8_store(shear[2], f8_div(one, dz));
    for (int a = 0; a < 3; a++) {
        f8_store(org[a], o[a]);
        f8_store(dir[a], d[a]);
        f8_store(inv[a], p->inv_dir[a]);
    }
    f8_store(tmin, o[3]);
    f8_store(tmax, f8_select(f8_eq(d[3], zero), f8_set1(INFINITY), d[3]));
    const unsigned x_bits = f8_bits(z_is_x), y_bits = f8_bits(z_is_y), flip_bits = f8_bits(flip);
    for (int l = 0; l < PACKET8_LANES; l++) {
        ray_f *r = &p->ray[l];
        r->origin = (vec3_f){ org[0][l], org[1][l], org[2][l] };
        r->dir = (vec3_f){ dir[0][l], dir[1][l], dir[2][l] };
        r->inv_dir = (vec3_f){ inv[0][l], inv[1][l], inv[2][l] };
        r->tmin = tmin[l];
        r->tmax = tmax[l];
        r->kz = x_bits >> l & 1u ? 0u : (y_bits >> l & 1u ? 1u : 2u);
        watertight_axes(r->kz, flip_bits >> l & 1u, &r->kx, &r->ky);
        r->sx = shear[0][l];
        r->sy = shear[1][l];
        r->sz = shear[2][l];
    }
    packet8_lanes_start(p, tmax);
    return true;
}

/* slab_f for the eight lanes on one box plane pair (lo, hi broadcast). */
BVH4_INLINE void packet8_slab(const packet8 *p, int a, float8 lo, float8 hi, float8 *out_lo, float8 *out_hi)
{
    float8 t0 = f8_mul(f8_sub(lo, p->origin[a]), p->inv_dir[a]);
    float8 t1 = f8_mul(f8_sub(hi, p->origin[a]), p->inv_dir[a]);
    float8 l = f8_min(t1, t0), h = f8_max(t1, t0);
    if (p->any_parallel) {
        const float8 inf = f8_set1(INFINITY), minus_inf = f8_set1(-INFINITY), par = p->parallel[a];
        float8 inside = f8_and(f8_ge(p->origin[a], lo), f8_le(p->origin[a], hi));
        l = f8_select(par, f8_select(inside, minus_inf, inf), l);
        h = f8_select(par, f8_select(inside, inf, minus_inf), h);
    }
    *out_lo = l;
    *out_hi = h;
}

/* intersect_box_f of the box lo-hi for the eight lanes: the lanes (within active) that enter
 * it, as a bit mask and as a lane mask in *out_hit, their entry distances in *out_tnear. */
BVH4_INLINE unsigned packet8_box(const packet8 *p, const float lo[3], const float hi[3], float8 active,
                                 float8 *out_tnear, float8 *out_hit)
{
    float8 lx, hx, ly, hy, lz, hz;
    packet8_slab(p, 0, f8_set1(lo[0]), f8_set1(hi[0]), &lx, &hx);
    packet8_slab(p, 1, f8_set1(lo[1]), f8_set1(hi[1]), &ly, &hy);
    packet8_slab(p, 2, f8_set1(lo[2]), f8_set1(hi[2]), &lz, &hz);
    float8 near = f8_max(f8_max(p->tmin, lz), f8_max(ly, lx));
    float8 far = f8_mul(f8_min(hz, f8_min(hy, hx)), f8_set1((float)VKRT_TFAR_WIDEN_FLOAT));
    far = f8_min(p->best_t, far);
    *out_tnear = near;
    *out_hit = f8_and(f8_le(near, far), active);
    return f8_bits(*out_hit);
}

/* The nearest entry distance among the lanes of entered (+inf for none). */
static inline float packet8_nearest(float8 tnear, float8 entered)
{
    return f8_min_lane(f8_select(entered, tnear, f8_set1(INFINITY)));
}

/* Each lane's closest (any_hit: first found) hit in p->best. */
static void trace_packet8_f(const cpu_trace_scene *s, vkrt_intersector isect, bool any_hit, packet8 *p)
{
    const bvh4 *w = s->wide;
    float8 root_tnear, entered;
    const unsigned active = packet8_box(p, w->root_lo, w->root_hi, f8_mask(PACKET8_ALL), &root_tnear, &entered);
    if (!active) return;
    unsigned done = 0; /* any_hit: lanes that have their hit */
    packet8_item stack[PACKET8_STACK_SIZE];
    uint32_t sp = 0;
    packet8_item item = { root_tnear, 0, 0, active };
    for (;;) {
        if (item.count != 0) {
            for (unsigned lanes = item.mask; lanes; lanes &= lanes - 1) {
                unsigned l = lowest_slot(lanes);
                if (test_leaf_f(isect, &p->ray[l], s, item.first, item.count, &p->best[l], any_hit)) done |= 1u << l;
            }
            p->best_t = packet8_prune_bounds(p->best);
            if (done == active) return;
        } else {
            const bvh4_node *n = &w->nodes[item.first];
            prefetch_children(s, n);
            const float8 lanes = f8_mask(item.mask);
            packet8_item hits[BVH4_WIDTH];
            float key[BVH4_WIDTH];
            uint32_t count = 0;
            for (unsigned k = 0; k < BVH4_WIDTH && n->child[k] != BVH4_EMPTY; k++) {
                const float lo[3] = { n->lo[0][k], n->lo[1][k], n->lo[2][k] }, hi[3] = { n->hi[0][k], n->hi[1][k], n->hi[2][k] };
                float8 tnear;
                unsigned mask = packet8_box(p, lo, hi, lanes, &tnear, &entered);
                if (!mask) continue;
                /* Stable insertion by the nearest lane's entry distance. */
                float t = packet8_nearest(tnear, entered);
                packet8_item h = { tnear, n->child[k], n->count[k], mask };
                uint32_t at = count++;
                while (at > 0 && t < key[at - 1]) {
                    hits[at] = hits[at - 1];
                    key[at] = key[at - 1];
                    at--;
                }
                hits[at] = h;
                key[at] = t;
            }
            if (count) {
                for (uint32_t k = count - 1; k > 0; k--)
                    if (sp < PACKET8_STACK_SIZE) stack[sp++] = hits[k]; /* never full: see BVH4_STACK_SIZE */
                item = hits[0];
                continue;
            }
        }
        /* The next entry with a lane still in it: one that has its hit, or whose box starts
         * beyond its closest hit found since, drops out. */
        unsigned live = 0;
        while (sp > 0 && !live) {
            item = stack[--sp];
            live = item.mask & ~done & f8_bits(f8_le(item.tnear, p->best_t));
        }
        if (!live) return;
        item.mask = live;
    }
}

/* Packets only for rays this close in direction (the cosine of the widest angle to the first
 * ray): neighbouring pixels of a camera are far closer, and the rays of an AO or shadow
 * sample, which share an origin, are far apart and would visit several times the boxes. */
#define PACKET8_MIN_COSINE 0.99f

/* Whether eight rays are worth a packet: one origin (a camera's) and nearly one direction, so
 * they tend to enter the same boxes. Any eight rays would give the same hits. Decided on the
 * rays as given, before any setup, since most rays that are not primary fail it. */
static bool packet8_coherent(const vkrt_ray rays[PACKET8_LANES])
{
    const float *a = rays[0].dir;
    float aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
    for (int l = 1; l < PACKET8_LANES; l++) {
        const float *b = rays[l].dir;
        if (rays[0].origin[0] != rays[l].origin[0] || rays[0].origin[1] != rays[l].origin[1] ||
            rays[0].origin[2] != rays[l].origin[2])
            return false;
        float ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2], bb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
        if (!(ab > 0.0f && ab * ab >= PACKET8_MIN_COSINE * PACKET8_MIN_COSINE * aa * bb)) return false;
    }
    return true;
}
