/* Four coherent float rays through the 4-wide BVH together (a packet, one ray per float4
 * lane): each child box is tested against the four rays at once, so rays that enter the same
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
 * Packets as in Wald, Slusallek, Benthin, Wagner, "Interactive Rendering with Coherent Ray
 * Tracing", Eurographics 2001, here over a 4-wide tree: the hit children in order of the
 * nearest entry distance among their lanes. */

#define PACKET4_LANES 4
#define PACKET4_ALL 0xFu
/* As BVH4_STACK_SIZE: at most BVH4_WIDTH - 1 entries pushed per level. */
#define PACKET4_STACK_SIZE BVH4_STACK_SIZE

typedef struct packet4 {
    ray_f ray[PACKET4_LANES];   /* what the triangle tests read */
    hit_f best[PACKET4_LANES];  /* each lane's closest hit so far */
    float4 origin[3], inv_dir[3], tmin, best_t; /* per axis, lane l = ray l's; best_t: prune bounds */
    float4 parallel[3];         /* lanes whose inv_dir is infinite on the axis (slab()'s other branch) */
    bool any_parallel;
} packet4;

/* A subtree to visit for the lanes in mask, with each lane's entry distance. */
typedef struct packet4_item {
    float4 tnear;
    uint32_t first, count;      /* as bvh4_item */
    unsigned mask;
} packet4_item;

/* The lane constants that follow from p->inv_dir and the rays' tmax: no hit yet, the lanes
 * parallel to each axis, and per lane the prune bound of the closest hit so far
 * (prune_bound_f): what boxes and stack entries are held to. */
static void packet4_lanes_start(packet4 *p, const float tmax[PACKET4_LANES])
{
    for (int l = 0; l < PACKET4_LANES; l++) p->best[l] = (hit_f){ .t = tmax[l], .tri = NO_PRIM, .prim = NO_PRIM };
    for (int a = 0; a < 3; a++) p->parallel[a] = f4_eq(f4_abs(p->inv_dir[a]), f4_set1(INFINITY));
    p->any_parallel = f4_bits(f4_or(f4_or(p->parallel[0], p->parallel[1]), p->parallel[2])) != 0;
    p->best_t = f4_set(prune_bound_f(tmax[0]), prune_bound_f(tmax[1]), prune_bound_f(tmax[2]), prune_bound_f(tmax[3]));
}

/* Fills p's lane constants from p->ray (each as ray_setup_f made it). The vectors are put
 * together in registers: four scalar stores read back as one vector would each miss the
 * store forwarding. */
static void packet4_setup(packet4 *p)
{
    const ray_f *r = p->ray;
    p->origin[0] = f4_set(r[0].origin.x, r[1].origin.x, r[2].origin.x, r[3].origin.x);
    p->origin[1] = f4_set(r[0].origin.y, r[1].origin.y, r[2].origin.y, r[3].origin.y);
    p->origin[2] = f4_set(r[0].origin.z, r[1].origin.z, r[2].origin.z, r[3].origin.z);
    p->inv_dir[0] = f4_set(r[0].inv_dir.x, r[1].inv_dir.x, r[2].inv_dir.x, r[3].inv_dir.x);
    p->inv_dir[1] = f4_set(r[0].inv_dir.y, r[1].inv_dir.y, r[2].inv_dir.y, r[3].inv_dir.y);
    p->inv_dir[2] = f4_set(r[0].inv_dir.z, r[1].inv_dir.z, r[2].inv_dir.z, r[3].inv_dir.z);
    p->tmin = f4_set(r[0].tmin, r[1].tmin, r[2].tmin, r[3].tmin);
    const float tmax[PACKET4_LANES] = { r[0].tmax, r[1].tmax, r[2].tmax, r[3].tmax };
    packet4_lanes_start(p, tmax);
}

/* p from four buffer rays: each lane's ray as ray_from_buffer_f makes it and the lane
 * constants as packet4_setup makes them, bit for bit, but with the twelve reciprocals and
 * shears divided four lanes at a time (a division rounds alike at either width; one ray's six
 * scalar divisions and axis choice held 6% of a profile of the CPU's primary rays). False,
 * with p unusable, where one of the rays must miss (ray_from_buffer_f's checks). */
static bool packet4_load(const vkrt_ray rays[PACKET4_LANES], packet4 *p)
{
    float4 o[4], d[4];
    ray4_load(rays, o, d);
    if (f4_bits(ray4_valid(o, d)) != PACKET4_ALL) return false;
    const float4 one = f4_set1(1.0f), zero = f4_set1(0.0f);
    for (int a = 0; a < 3; a++) {
        p->origin[a] = o[a];
        p->inv_dir[a] = f4_div(one, d[a]);
    }
    p->tmin = o[3];
    /* ray_setup_f's watertight axes: kz that of the largest |dir| (the lower axis on a tie),
     * kx and ky from watertight_axes; then the shear. */
    const float4 ax = f4_abs(d[0]), ay = f4_abs(d[1]), az = f4_abs(d[2]);
    const float4 z_is_x = f4_and(f4_ge(ax, ay), f4_ge(ax, az)), z_is_y = f4_andnot(z_is_x, f4_ge(ay, az));
    const float4 dz = f4_select(z_is_x, d[0], f4_select(z_is_y, d[1], d[2]));
    const float4 next = f4_select(z_is_x, d[1], f4_select(z_is_y, d[2], d[0]));
    const float4 after = f4_select(z_is_x, d[2], f4_select(z_is_y, d[0], d[1]));
    const float4 flip = f4_lt(dz, zero);
    float shear[3][PACKET4_LANES], org[3][PACKET4_LANES], dir[3][PACKET4_LANES], inv[3][PACKET4_LANES],
        tmin[PACKET4_LANES], tmax[PACKET4_LANES];
    f4_store(shear[0], f4_div(f4_select(flip, after, next), dz));
    f4_store(shear[1], f4_div(f4_select(flip, next, after), dz));
    f4_store(shear[2], f4_div(one, dz));
    for (int a = 0; a < 3; a++) {
        f4_store(org[a], o[a]);
        f4_store(dir[a], d[a]);
        f4_store(inv[a], p->inv_dir[a]);
    }
    f4_store(tmin, o[3]);
    f4_store(tmax, f4_select(f4_eq(d[3], zero), f4_set1(INFINITY), d[3]));
    const unsigned x_bits = f4_bits(z_is_x), y_bits = f4_bits(z_is_y), flip_bits = f4_bits(flip);
    for (int l = 0; l < PACKET4_LANES; l++) {
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
    packet4_lanes_start(p, tmax);
    return true;
}

/* slab_f for the four lanes on one box plane pair (lo, hi broadcast). */
BVH4_INLINE void packet4_slab(const packet4 *p, int a, float4 lo, float4 hi, float4 *out_lo, float4 *out_hi)
{
    float4 t0 = f4_mul(f4_sub(lo, p->origin[a]), p->inv_dir[a]);
    float4 t1 = f4_mul(f4_sub(hi, p->origin[a]), p->inv_dir[a]);
    float4 l = f4_min(t1, t0), h = f4_max(t1, t0);
    if (p->any_parallel) {
        const float4 inf = f4_set1(INFINITY), minus_inf = f4_set1(-INFINITY), par = p->parallel[a];
        float4 inside = f4_and(f4_ge(p->origin[a], lo), f4_le(p->origin[a], hi));
        l = f4_select(par, f4_select(inside, minus_inf, inf), l);
        h = f4_select(par, f4_select(inside, inf, minus_inf), h);
    }
    *out_lo = l;
    *out_hi = h;
}

/* intersect_box_f of the box lo-hi for the four lanes: the lanes (within active) that enter
 * it, as a bit mask and as a lane mask in *out_hit, their entry distances in *out_tnear. */
BVH4_INLINE unsigned packet4_box(const packet4 *p, const float lo[3], const float hi[3], float4 active,
                                 float4 *out_tnear, float4 *out_hit)
{
    float4 lx, hx, ly, hy, lz, hz;
    packet4_slab(p, 0, f4_set1(lo[0]), f4_set1(hi[0]), &lx, &hx);
    packet4_slab(p, 1, f4_set1(lo[1]), f4_set1(hi[1]), &ly, &hy);
    packet4_slab(p, 2, f4_set1(lo[2]), f4_set1(hi[2]), &lz, &hz);
    float4 near = f4_max(f4_max(p->tmin, lz), f4_max(ly, lx));
    float4 far = f4_mul(f4_min(hz, f4_min(hy, hx)), f4_set1((float)VKRT_TFAR_WIDEN_FLOAT));
    far = f4_min(p->best_t, far);
    *out_tnear = near;
    *out_hit = f4_and(f4_le(near, far), active);
    return f4_bits(*out_hit);
}

/* The nearest entry distance among the lanes of entered (+inf for none). */
static inline float packet4_nearest(float4 tnear, float4 entered)
{
    return f4_min_lane(f4_select(entered, tnear, f4_set1(INFINITY)));
}

/* Each lane's closest (any_hit: first found) hit in p->best. */
static void trace_packet4_f(const cpu_trace_scene *s, vkrt_intersector isect, bool any_hit, packet4 *p)
{
    const bvh4 *w = s->wide;
    float4 root_tnear, entered;
    const unsigned active = packet4_box(p, w->root_lo, w->root_hi, f4_mask(PACKET4_ALL), &root_tnear, &entered);
    if (!active) return;
    unsigned done = 0; /* any_hit: lanes that have their hit */
    packet4_item stack[PACKET4_STACK_SIZE];
    uint32_t sp = 0;
    packet4_item item = { root_tnear, 0, 0, active };
    for (;;) {
        if (item.count != 0) {
            for (unsigned lanes = item.mask; lanes; lanes &= lanes - 1) {
                unsigned l = lowest_slot(lanes);
                if (test_leaf_f(isect, &p->ray[l], s, item.first, item.count, &p->best[l], any_hit)) done |= 1u << l;
            }
            p->best_t = f4_set(prune_bound_f(p->best[0].t), prune_bound_f(p->best[1].t), prune_bound_f(p->best[2].t),
                               prune_bound_f(p->best[3].t));
            if (done == active) return;
        } else {
            const bvh4_node *n = &w->nodes[item.first];
            prefetch_children(s, n);
            const float4 lanes = f4_mask(item.mask);
            packet4_item hits[BVH4_WIDTH];
            float key[BVH4_WIDTH];
            uint32_t count = 0;
            for (unsigned k = 0; k < BVH4_WIDTH && n->child[k] != BVH4_EMPTY; k++) {
                const float lo[3] = { n->lo[0][k], n->lo[1][k], n->lo[2][k] }, hi[3] = { n->hi[0][k], n->hi[1][k], n->hi[2][k] };
                float4 tnear;
                unsigned mask = packet4_box(p, lo, hi, lanes, &tnear, &entered);
                if (!mask) continue;
                /* Stable insertion by the nearest lane's entry distance. */
                float t = packet4_nearest(tnear, entered);
                packet4_item h = { tnear, n->child[k], n->count[k], mask };
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
                    if (sp < PACKET4_STACK_SIZE) stack[sp++] = hits[k]; /* never full: see BVH4_STACK_SIZE */
                item = hits[0];
                continue;
            }
        }
        /* The next entry with a lane still in it: one that has its hit, or whose box starts
         * beyond its closest hit found since, drops out. */
        unsigned live = 0;
        while (sp > 0 && !live) {
            item = stack[--sp];
            live = item.mask & ~done & f4_bits(f4_le(item.tnear, p->best_t));
        }
        if (!live) return;
        item.mask = live;
    }
}

/* Packets only for rays this close in direction (the cosine of the widest angle to the first
 * ray): neighbouring pixels of a camera are far closer, and the rays of an AO or shadow
 * sample, which share an origin, are far apart and would visit four times the boxes. */
#define PACKET4_MIN_COSINE 0.99f

/* Whether four rays are worth a packet: one origin (a camera's) and nearly one direction, so
 * they tend to enter the same boxes. Any four rays would give the same hits. Decided on the
 * rays as given, before any setup, since most rays that are not primary fail it. */
static bool packet4_coherent(const vkrt_ray rays[PACKET4_LANES])
{
    const float *a = rays[0].dir;
    float aa = a[0] * a[0] + a[1] * a[1] + a[2] * a[2];
    for (int l = 1; l < PACKET4_LANES; l++) {
        const float *b = rays[l].dir;
        if (rays[0].origin[0] != rays[l].origin[0] || rays[0].origin[1] != rays[l].origin[1] ||
            rays[0].origin[2] != rays[l].origin[2])
            return false;
        float ab = a[0] * b[0] + a[1] * b[1] + a[2] * b[2], bb = b[0] * b[0] + b[1] * b[1] + b[2] * b[2];
        if (!(ab > 0.0f && ab * ab >= PACKET4_MIN_COSINE * PACKET4_MIN_COSINE * aa * bb)) return false;
    }
    return true;
}
