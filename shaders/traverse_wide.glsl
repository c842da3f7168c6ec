/* Traversal of the wide BVH (VKRT_SPEC_WIDE; layouts in vkrt_shared.h), read through texel
 * buffers. One step tests a node's four child boxes from one read of its four texels and visits
 * the nearest child next; the others become the lane's group, taken nearest first, and the group
 * they replace goes onto the stack as one entry (a group is a node and the order of its children
 * left). A leaf's triangles follow each other in the triangle array up to the one marked
 * VKRT_TRACE_TRI_LAST. The answers are trace_bvh's: the box test is intersect_box's
 * conservative one four at a time, so no box the ray enters is culled, and the triangle test and
 * the closest-hit rule (hit_closer) are the same functions, so the visiting order decides
 * nothing but the time. Heat and counters stay with trace_bvh: they count the binary BVH's
 * steps, which the CPU reference counts too.
 *
 * The loop has the shape of trace_bvh's: one flat loop, budgeted in the same way
 * (VKRT_SPEC_BUDGET: iterations) with the same continuation state (the group saved on the
 * stack). Each of its steps takes a group from the stack where the lane has none, visits a node,
 * tests one triangle (the first of a leaf together with the step that reached it) and hands the
 * group's nearest child to a free stage; an iteration runs WIDE_STEPS of them after taking a new
 * ray where the lane's is done.
 *
 * Included by trace.comp after test_triangle_data, mark_finished, load_wide_ray, load_wide_tri,
 * store_slot_tri and the next_slot counter. */
#ifndef VKRT_TRAVERSE_WIDE_GLSL
#define VKRT_TRAVERSE_WIDE_GLSL

#define NO_TRI 0xFFFFFFFFu
#define NO_KEY 0xFFFFFFFFu

/* f_min and f_max of trace_common.glsl, per component: x where y is NaN (a comparison with NaN
 * is false), so a NaN in y leaves x as it was. */
vec4 f_min4(vec4 x, vec4 y) { return mix(x, y, lessThan(y, x)); }
vec4 f_max4(vec4 x, vec4 y) { return mix(x, y, lessThan(x, y)); }

/* A float's bits reordered so that unsigned order is the floats' order (no NaN here). */
uvec4 order_key(vec4 f)
{
    uvec4 b = floatBitsToUint(f);
    return mix(~b, b | 0x80000000u, greaterThanEqual(f, vec4(0.0)));
}

float key_float(uint k)
{
    return uintBitsToFloat((k & 0x80000000u) != 0u ? k & 0x7FFFFFFFu : ~k);
}

void sort2(inout uint a, inout uint b)
{
    uint lo = min(a, b);
    b = max(a, b);
    a = lo;
}

/* Four slots' quantised coordinates (a byte each) decoded as wide_pack.c's dequantise() does. */
vec4 dequantise(float origin, float scale, uint bytes)
{
    precise vec4 v = origin + vec4((uvec4(bytes) >> uvec4(0u, 8u, 16u, 24u)) & 0xFFu) * scale;
    return v;
}

/* One axis of four boxes: the distances where the ray crosses their near and far planes. The
 * near plane is the low one for a ray going up the axis and the high one for a ray going down
 * (inv < 0, -0 included: its reciprocal is -infinity), which is the order slab()'s f_min and
 * f_max find (subtracting o and multiplying by inv keep or reverse the planes' order), so the
 * distances are intersect_box's own, from one comparison a ray instead of a min and a max a box.
 * A ray parallel to the axis (inv = +-infinity) gets -infinity or +infinity by the side its
 * origin lies on, as slab() has it, and NaN (0 * infinity) for an origin on a plane, where
 * slab() counts it inside: visit_wide_node skips a NaN, which leaves that bound open. The
 * branch-free handling this replaced (an isnan test and two selects a plane) was 3% of the
 * trace loop's instructions. */
void planes4(float o, float inv, float origin, float scale, uint lo_bytes, uint hi_bytes, out vec4 t_near,
             out vec4 t_far)
{
    bool down = inv < 0.0;
    precise vec4 near_t = (dequantise(origin, scale, down ? hi_bytes : lo_bytes) - o) * inv;
    precise vec4 far_t = (dequantise(origin, scale, down ? lo_bytes : hi_bytes) - o) * inv;
    t_near = near_t;
    t_far = far_t;
}

/* A wide node's four texels: its frame, the quantised planes of its four child boxes, and
 * their references (layout in vkrt_shared.h). */
struct wide_node {
    uvec4 frame;
    uvec4 q_a;
    uvec4 q_b;
    uvec4 children;
};

wide_node load_wide_node(uint node)
{
    int base = int(node * VKRT_WIDE_NODE_TEXELS);
    return wide_node(imageLoad(wide_nodes, base), imageLoad(wide_nodes, base + 1), imageLoad(wide_nodes, base + 2),
                     imageLoad(wide_nodes, base + 3));
}

/* Tests the four child boxes of wide node n: returns the entry distances of those the ray
 * enters, nearest first, each an order_key with the slot in its two low bits (clearing those
 * bits moves a distance towards -infinity, so the distance read back is never beyond the box
 * and prunes conservatively), and NO_KEY for each box missed, last. */
uvec4 visit_wide_node(ray r, wide_node n, float best_t)
{
    uvec4 frame = n.frame, q_a = n.q_a, q_b = n.q_b, children = n.children;
    vec3 origin = uintBitsToFloat(frame.xyz);
    vec3 scale = uintBitsToFloat(((uvec3(frame.w) >> uvec3(0u, 8u, 16u)) & 0xFFu) << 23u);
    vec4 nx, fx, ny, fy, nz, fz;
    planes4(r.origin.x, r.inv_dir.x, origin.x, scale.x, q_a.x, q_a.w, nx, fx);
    planes4(r.origin.y, r.inv_dir.y, origin.y, scale.y, q_a.y, q_b.x, ny, fy);
    planes4(r.origin.z, r.inv_dir.z, origin.z, scale.z, q_a.z, q_b.y, nz, fz);
    /* From tmin, never NaN, so that f_max4 skips a NaN near distance. f_min4 skips a NaN far
     * distance too, but for fx, which it keeps: tfar is NaN then, and the closest hit's bound
     * takes its place below, no tighter than the box's. So no box is culled that the ray
     * enters. A ray parallel to an axis outside a box's slab enters it only where its other far
     * distances and that bound are +infinity: a box visited needlessly, never one culled. */
    vec4 tnear = f_max4(f_max4(f_max4(vec4(r.tmin), nx), ny), nz);
    precise vec4 tfar = f_min4(f_min4(fx, fy), fz) * VKRT_TFAR_WIDEN_FLOAT;
    vec4 bound = vec4(prune_bound(best_t));
    tfar = mix(bound, tfar, lessThan(tfar, bound));
    bvec4 entered = bvec4(uvec4(lessThanEqual(tnear, tfar)) & uvec4(notEqual(children, uvec4(VKRT_WIDE_NO_CHILD))));
    uvec4 k = mix(uvec4(NO_KEY), (order_key(tnear) & ~3u) | uvec4(0u, 1u, 2u, 3u), entered);
    /* A sorting network of four. */
    sort2(k.x, k.y);
    sort2(k.z, k.w);
    sort2(k.x, k.z);
    sort2(k.y, k.w);
    sort2(k.y, k.z);
    return k;
}

/* Rays one invocation traces (VKRT_WIDE_RAYS_PER_LANE): a lane whose ray is done takes its
 * next one within the same loop, so the eight lanes of a SIMD group stay busy until the group's
 * rays are all done instead of idling beside the longest one (most primary rays of a view miss
 * the mesh or end in a few steps). One for the camera: a pixel is its invocation's only ray. */
const bool WIDE_REFILL = RAYGEN != VKRT_GPU_RAYGEN_CAMERA;
const uint WIDE_RAYS = WIDE_REFILL ? VKRT_WIDE_RAYS_PER_LANE : 1u;

/* The ray buffer's index of the k-th ray of ray slot `slot`: a slot is an invocation's worth of
 * rays (WIDE_RAYS) that follow each other in the buffer, so a lane reads its rays from one 1 KB
 * run (which the CPU's prefetchers follow; the host has just written them, from another core)
 * and the finish writes their hits to one 512-byte run. Slots used to take their rays a
 * workgroup's worth at a time, neighbouring slots neighbouring rays, each lane's 64 rays apart:
 * a slot's own run traced 0.96-0.98x the time (in-process pairs, the full dragon and
 * dragon_200k). */
uint wide_ray_index(uint slot, uint k)
{
    return slot * WIDE_RAYS + k;
}

#define NO_SLOT 0xFFFFFFFFu

/* The next ray slot nobody has taken (the slots of a pass's dispatch, each taken once), for a
 * lane whose slot is done, or NO_SLOT where this lane takes no more: in a resume pass (the
 * pass's first already took every slot), or once `steps` are half the budget, so that the
 * slots taken are likely to finish within it. lavapipe's threads each take a fixed half of a
 * dispatch's workgroups: with each invocation keeping to its own slot, a thread whose half
 * held the harder rays (the mesh rather than the sky), or whose core the machine's other
 * guests slowed, worked on alone while the other idled (the two were 74% and 84% busy);
 * taking the next free slot keeps both busy to the end (91-94%). */
uint take_ray_slot(uint steps)
{
    if (BUDGET != 0u && (p.resume != 0u || steps >= BUDGET / 2u)) return NO_SLOT;
    return atomicAdd(next_slot, 1u);
}

/* A lane's group: the children of one node (group_node) that the ray enters and no stage has
 * taken yet, as visit_wide_node's sort keys nearest first, NO_KEY past the last. Siblings come
 * from it, in registers, rather than through the stack: a visit stores at most one entry, the
 * group it replaces, where the children pushed one by one took up to three. lavapipe stores a
 * private array a lane at a time (a load, a conditional move on the lane's mask bit and a
 * store for each of the eight), and every push in the loop's code costs all of that in every
 * step whether a lane pushes or not (one more push: 1.06-1.08x the time, in-process pairs on
 * dragon_200k). Against single entries, groups took 0.92-0.94x the time on closest-hit AO rays,
 * 0.97-0.99x on primary rays and 0.99-1.03x on any-hit AO rays (docs/issue7.md, the
 * twenty-third session).
 *
 * On the stack a group is its node and one word: the front key with its low ten bits cleared
 * (a distance moved towards -infinity: it prunes conservatively, and stands for every child
 * of the group, all at least as far), the four slots in order, two bits each, and how many
 * follow the first (bits 8 and 9). */
uint group_encode(uvec4 keys)
{
    uint more = uint(keys.y != NO_KEY) + uint(keys.z != NO_KEY) + uint(keys.w != NO_KEY);
    uint order = (keys.x & 3u) | (keys.y & 3u) << 2 | (keys.z & 3u) << 4 | (keys.w & 3u) << 6;
    return (keys.x & ~0x3FFu) | order | more << 8;
}

uvec4 group_decode(uint word)
{
    uint front = word & ~0x3FFu, more = (word >> 8) & 3u;
    return uvec4(front | (word & 3u), more > 0u ? front | ((word >> 2) & 3u) : NO_KEY,
                 more > 1u ? front | ((word >> 4) & 3u) : NO_KEY, more > 2u ? front | ((word >> 6) & 3u) : NO_KEY);
}

/* The lane's group onto the stack. A macro, not a function: GLSL passes arrays by copy. Never
 * full: the group a visit of node N pushes is always a proper ancestor's of N, and each entry
 * under it a proper ancestor's of the one above, one a level (N descends from the group's node;
 * a pop replaces an emptied group by an ancestor's). So a lane holds fewer entries than the
 * wide BVH has levels, one more once a suspension pushes its group, and the host keeps the
 * levels within the stack (wide_traversal_fits). */
#define WIDE_PUSH_GROUP()                                       \
    if (sp < VKRT_TRAVERSAL_STACK_SIZE) {                       \
        stack_node[sp] = group_node;                            \
        stack_word[sp] = group_encode(group);                   \
        sp++;                                                   \
    }

/* Steps a loop iteration runs (1 or 2: WIDE_STEP, written out that many times) where lanes
 * take new rays. The iteration's other work (the hit word's store, the test for a finished
 * ray, the refill, the loop's own bookkeeping) runs for all eight lanes of a SIMD group in every
 * iteration, whether a lane needs it or not, so the steps share it; a lane whose ray ends in
 * an iteration's first step idles for the rest of it, which costs most on rays of few steps.
 * Measured against one step an iteration (dragon_11k to the full dragon, 1024x1024): two
 * steps 0.86-0.96x the time on AO rays and 0.92-1.00x on primary rays; four 0.85-0.94x on AO
 * rays but up to 1.10x on primary rays; six no better than four, eight 1.1-1.5x slower
 * (docs/issue7.md, the thirteenth session). Two is the most that slows no query. The camera's
 * rays take no new ray: one step. Written out rather than as an inner loop, so that there is
 * one loop, whose iterations the budget bounds as lavapipe counts them. */
const uint WIDE_STEPS = WIDE_REFILL ? 2u : 1u;

/* One step of trace_wide's loop: a group taken from the stack where the lane has none, a
 * triangle tested and a node visited where the lane has them, and the group's front handed to
 * a free stage. A macro, not a function, for the stack arrays (as WIDE_PUSH_GROUP); the loop
 * runs it WIDE_STEPS times an iteration. */
#define WIDE_STEP()                                                                              \
    {                                                                                            \
        float bound = prune_bound(best.t);                                                       \
        /* A leaf held while another leaf's triangles were being tested, dropped if it starts    \
         * beyond the closest hit found since (it cannot improve it). */                         \
        if (tri == NO_TRI && held != NO_NODE) {                                                  \
            if (!(held_tnear > bound)) tri = held & ~VKRT_WIDE_LEAF;                             \
            held = NO_NODE;                                                                      \
        }                                                                                        \
        if (group.x == NO_KEY && sp > 0u) {                                                      \
            sp--;                                                                                \
            group_node = stack_node[sp];                                                         \
            group = group_decode(stack_word[sp]);                                                \
        }                                                                                        \
        /* Every step runs both stages where it has work for them: lavapipe executes the whole   \
         * loop body for all eight lanes of a SIMD group anyway, so a step that tests a triangle \
         * and visits a node costs what one doing either costs. The reads come first (node 0 and \
         * triangle 0 for an idle stage), so that the node's wait on memory overlaps the         \
         * triangle's: read inside its stage, after the triangle test, the node was fetched only \
         * once the test's hundreds of instructions had passed through the CPU's reorder window. \
         * 5-9% less time on any-hit AO rays, the same on others (in-process A/B). */            \
        wide_node visited = load_wide_node(node == NO_NODE ? 0u : node);                         \
        int group_texel = int(group_node * VKRT_WIDE_NODE_TEXELS + 3u);                          \
        uvec4 group_children = imageLoad(wide_nodes, group_texel);                               \
        bool last;                                                                               \
        vkrt_gpu_tri tested = load_wide_tri(tri == NO_TRI ? 0u : tri, last);                     \
        if (tri != NO_TRI) {                                                                     \
            test_triangle_data(r, tri, tested, best);                                            \
            tri = last ? NO_TRI : tri + 1u;                                                      \
            /* An occlusion query is answered by the first hit. */                               \
            if (ANYHIT != 0u && best.prim != NO_PRIM) {                                          \
                if (!WIDE_REFILL) break;                                                         \
                sp = 0u;                                                                         \
                tri = NO_TRI;                                                                    \
                node = NO_NODE;                                                                  \
                held = NO_NODE;                                                                  \
                group = uvec4(NO_KEY);                                                           \
            }                                                                                    \
        }                                                                                        \
        if (node != NO_NODE) {                                                                   \
            /* The nearest child entered to the node stage, or to the triangle stage or the held \
             * leaf where free; the rest, with the nearest where no stage took it, become the    \
             * lane's group, the group it had onto the stack. */                                 \
            uvec4 keys = visit_wide_node(r, visited, best.t);                                    \
            uint nearest = visited.children[keys.x & 3u];                                        \
            bool interior = (nearest & VKRT_WIDE_LEAF) == 0u, taken = keys.x != NO_KEY;          \
            if (taken && !interior) {                                                            \
                if (tri == NO_TRI) {                                                             \
                    tri = nearest & ~VKRT_WIDE_LEAF;                                             \
                } else if (held == NO_NODE) {                                                    \
                    held = nearest;                                                              \
                    held_tnear = key_float(keys.x & ~3u);                                        \
                } else {                                                                         \
                    taken = false;                                                               \
                }                                                                                \
            }                                                                                    \
            uvec4 rest = taken ? uvec4(keys.yzw, NO_KEY) : keys;                                 \
            if (rest.x != NO_KEY) {                                                              \
                if (group.x != NO_KEY) WIDE_PUSH_GROUP();                                        \
                group_node = node;                                                               \
                group = rest;                                                                    \
                group_children = visited.children;                                               \
            }                                                                                    \
            node = taken && interior ? nearest : NO_NODE;                                        \
        }                                                                                        \
        /* The group's front to a free stage, or the whole group dropped where the front starts  \
         * beyond the closest hit (the rest start no nearer). */                                 \
        if (group.x != NO_KEY) {                                                                 \
            uint front = group_children[group.x & 3u];                                           \
            float front_tnear = key_float(group.x & ~3u);                                        \
            bool leaf = (front & VKRT_WIDE_LEAF) != 0u, taken = true;                            \
            if (front_tnear > bound) {                                                           \
                group = uvec4(NO_KEY);                                                           \
                taken = false;                                                                   \
            } else if (!leaf && node == NO_NODE) {                                               \
                node = front;                                                                    \
            } else if (leaf && tri == NO_TRI) {                                                  \
                tri = front & ~VKRT_WIDE_LEAF;                                                   \
            } else if (leaf && held == NO_NODE) {                                                \
                held = front;                                                                    \
                held_tnear = front_tnear;                                                        \
            } else {                                                                             \
                taken = false;                                                                   \
            }                                                                                    \
            if (taken) group = uvec4(group.yzw, NO_KEY);                                         \
        }                                                                                        \
    }

/* The closest (or, ANYHIT, any) hit of r, as trace_bvh finds it; with WIDE_RAYS > 1 the hits of
 * ray slot `rays`' rays from its k-th on (r is that one, `valid` whether it may hit anything),
 * then of the slots take_ray_slot gives, each ray's triangle stored by store_slot_tri.
 * Returns false where the budget stopped it (the state is then in continuation slot `slot`). */
bool trace_wide(ray r, bool valid, uint slot, uint rays, uint k, inout hit best)
{
    uint stack_node[VKRT_TRAVERSAL_STACK_SIZE];
    uint stack_word[VKRT_TRAVERSAL_STACK_SIZE];
    uint sp = 0u, node = valid ? 0u : NO_NODE, tri = NO_TRI;
    uint group_node = 0u;
    uvec4 group = uvec4(NO_KEY);
    /* The next leaf, held out of the stack while another leaf's triangles are being tested, so
     * that the nodes under it stay within reach of the node stage. */
    uint held = NO_NODE;
    float held_tnear = 0.0;
    if (BUDGET != 0u && p.resume != 0u) {
        vkrt_gpu_resume s = states[slot];
        node = s.node;
        tri = s.tri_next;
        sp = s.sp;
        held = s.heat_nodes;
        held_tnear = uintBitsToFloat(s.heat_leaves);
        if (WIDE_REFILL) {
            rays = s.heat_tris;
            k = s.tri_end;
            valid = load_wide_ray(wide_ray_index(rays, k), r);
        }
        best = hit(s.t, s.u, s.v, s.tri, s.prim);
        for (uint i = 0u; i < sp; i++) {
            vkrt_gpu_stack_entry e = saved_stack[slot * VKRT_TRAVERSAL_STACK_SIZE + i];
            stack_node[i] = e.node;
            stack_word[i] = e.word;
        }
    }
    uint steps = 0u;
    bool suspended = false;
    for (;;) {
        if (BUDGET != 0u) {
            if (steps == BUDGET) {
                suspended = true;
                break;
            }
            steps++;
        }
        /* The ray's closest triangle so far, stored by every lane in every iteration, not by
         * the lanes whose ray has just ended: lavapipe stores a lane at a time, branching on
         * each lane's bit of the mask, and a mask that changes from one iteration to the next
         * mispredicts those branches (5% of a primary-ray trace's time). A ray's last store is
         * the one made in the iteration that finds it done, below. */
        if (WIDE_REFILL) store_slot_tri(rays, k, best);
        if (node == NO_NODE && tri == NO_TRI && sp == 0u && held == NO_NODE && group.x == NO_KEY) {
            if (!WIDE_REFILL) break;
            /* This ray is done: the lane takes its next one (of its slot, or of the next slot
             * free), and visits its root below. */
            k++;
            if (k == WIDE_RAYS) {
                k = 0u;
                rays = take_ray_slot(steps);
            }
            uint index = rays == NO_SLOT ? NO_SLOT : wide_ray_index(rays, k);
            if (index >= p.tile_width) break;
            valid = load_wide_ray(index, r);
            best = hit(r.tmax, 0.0, 0.0, NO_PRIM, NO_PRIM);
            node = valid ? 0u : NO_NODE;
        }
        WIDE_STEP();
        if (WIDE_STEPS == 2u) {
            WIDE_STEP();
        }
    }
    /* Saved after the loop, as trace_bvh does (an `if` inside it would cost every iteration). */
    if (BUDGET != 0u && suspended) {
        /* The barycentrics are not saved where the finish tests each ray's triangle again for
         * them (WIDE_REFILL): saving them kept them, and a select of each at every triangle
         * test, alive through the loop, 6% of its instructions. */
        float u = WIDE_REFILL ? 0.0 : best.u, v = WIDE_REFILL ? 0.0 : best.v;
        /* The group onto the stack, where the resume's first step takes it back. */
        if (group.x != NO_KEY) WIDE_PUSH_GROUP();
        states[slot] = vkrt_gpu_resume(1u, node, tri, k, sp, best.t, u, v, best.tri, best.prim, held,
                                       floatBitsToUint(held_tnear), rays, 0u, 0u, 0u);
        for (uint i = 0u; i < sp; i++)
            saved_stack[slot * VKRT_TRAVERSAL_STACK_SIZE + i] = vkrt_gpu_stack_entry(stack_node[i], stack_word[i]);
        atomicAdd(unfinished, 1u);
        return false;
    }
    mark_finished(slot);
    return true;
}

#endif
