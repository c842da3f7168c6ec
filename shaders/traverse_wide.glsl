/* Traversal of the wide BVH (VKRT_SPEC_WIDE; layouts in vkrt_shared.h), read through texel
 * buffers. One step tests a node's four child boxes from one read of its four texels, visits the
 * nearest child next and pushes the others farthest first, so the stack pops them nearest
 * first; a leaf's triangles follow each other in the triangle array up to the one marked
 * VKRT_TRACE_TRI_LAST. The answers are trace_bvh's: the box test is intersect_box's
 * conservative one four at a time, so no box the ray enters is culled, and the triangle test and
 * the closest-hit rule (hit_closer) are the same functions, so the visiting order decides
 * nothing but the time. Heat and counters stay with trace_bvh: they count the binary BVH's
 * steps, which the CPU reference counts too.
 *
 * The loop has the shape of trace_bvh's: one flat loop, budgeted in the same way
 * (VKRT_SPEC_BUDGET: iterations) with the same continuation state. Each of its steps pops a
 * stack entry, visits a node, or tests one triangle (the first of a leaf together with the
 * step that reached it); an iteration runs WIDE_STEPS of them after taking a new ray where the
 * lane's is done.
 *
 * Included by trace.comp after test_triangle_data, mark_finished, load_wide_ray, load_wide_tri,
 * store_slot_tri and the next_slot counter. */
#ifndef VKRT_TRAVERSE_WIDE_GLSL
#define VKRT_TRAVERSE_WIDE_GLSL

#define NO_TRI 0xFFFFFFFFu

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
 * branch-free handling this replaced (an isnan test and two selects a plane) was 3.5% of the
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

/* Tests the four child boxes of wide node n: returns how many the ray enters and, in keys,
 * their entry distances nearest first, each an order_key with the slot in its two low bits
 * (clearing those bits moves a distance towards -infinity, so the distance read back is never
 * beyond the box and prunes conservatively). Missed slots sort last. */
uint visit_wide_node(ray r, wide_node n, float best_t, out uvec4 keys)
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
    uvec4 k = mix(uvec4(0xFFFFFFFFu), (order_key(tnear) & ~3u) | uvec4(0u, 1u, 2u, 3u), entered);
    /* A sorting network of four. */
    sort2(k.x, k.y);
    sort2(k.z, k.w);
    sort2(k.x, k.z);
    sort2(k.y, k.w);
    sort2(k.y, k.z);
    keys = k;
    return uint(entered.x) + uint(entered.y) + uint(entered.z) + uint(entered.w);
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

/* Pushes the child of the slot in sort key `key` (visit_wide_node) with its entry distance. A
 * macro, not a function: GLSL passes arrays by copy. */
#define WIDE_PUSH_SLOT(key)                                     \
    if (sp < VKRT_TRAVERSAL_STACK_SIZE) {                       \
        stack_ref[sp] = children[(key) & 3u];                   \
        stack_tnear[sp] = key_float((key) & ~3u);               \
        sp++;                                                   \
    }

/* The nearest child entered (the slot in sort key keys.x of the visited node's `children`, if
 * `entered`) to the node stage, to the triangle stage or the held leaf where free, or onto the
 * stack. */
#define WIDE_TAKE_NEAREST(keys, entered)                        \
    {                                                           \
        uint nearest = children[keys.x & 3u];                   \
        if (entered > 0u) {                                     \
            if ((nearest & VKRT_WIDE_LEAF) == 0u) {             \
                node = nearest;                                 \
            } else if (tri == NO_TRI) {                         \
                tri = nearest & ~VKRT_WIDE_LEAF;                \
            } else if (held == NO_NODE) {                       \
                held = nearest;                                 \
                held_tnear = key_float(keys.x & ~3u);           \
            } else {                                            \
                WIDE_PUSH_SLOT(keys.x);                         \
            }                                                   \
        }                                                       \
    }

/* How any-hit rays push a visit's farther children: three entries stored by every lane in
 * every step, at the stack's top whether or not the lane visited a node or entered that many
 * children, and the stack pointer moved past those it entered (the stack order is the
 * conditional pushes': farthest lowest), instead of up to three pushes under masks that change
 * from step to step. lavapipe stores a private array a lane at a time, each lane's entry
 * loaded, kept or replaced by a conditional move on its mask bit, and stored back (no branch:
 * LLVM 15's code read on this host), so a full mask saves no mispredictions; what it does save
 * was measured, not explained. In-process pairs: 0.92-0.98x the time on any-hit AO rays (seven
 * runs, dragon_200k and the full dragon); closest-hit rays, for which the same stores took
 * 1.01-1.07x, keep the conditional pushes. The entries past the pointer are dead, and the
 * arrays have WIDE_PUSH_ROOM entries beyond VKRT_TRAVERSAL_STACK_SIZE for a lane whose stack is
 * full (never: the host keeps the wide BVH within a third of the stack's levels). */
const bool PUSH_FARTHER_ALWAYS = ANYHIT != 0u;
const uint WIDE_PUSH_ROOM = PUSH_FARTHER_ALWAYS ? 3u : 0u;
#define WIDE_PUSH_FARTHER_ALWAYS(keys, entered)                                              \
    {                                                                                        \
        uint farthest = entered > 3u ? keys.w : (entered > 2u ? keys.z : keys.y);            \
        uint second = entered > 3u ? keys.z : keys.y;                                        \
        stack_ref[sp] = children[farthest & 3u];                                             \
        stack_tnear[sp] = key_float(farthest & ~3u);                                         \
        stack_ref[sp + 1u] = children[second & 3u];                                          \
        stack_tnear[sp + 1u] = key_float(second & ~3u);                                      \
        stack_ref[sp + 2u] = children[keys.y & 3u];                                          \
        stack_tnear[sp + 2u] = key_float(keys.y & ~3u);                                      \
        sp = min(sp + (entered > 1u ? entered - 1u : 0u), uint(VKRT_TRAVERSAL_STACK_SIZE));   \
    }

/* Steps a loop iteration runs (1 or 2: WIDE_STEP, written out that many times) where lanes
 * take new rays. The iteration's other work (the hit word's store, the test for a finished
 * ray, the refill, the loop's own bookkeeping) runs for all eight lanes of a SIMD group in every
 * iteration, whether a lane needs it or not, so the steps share it; a lane whose ray ends in
 * an iteration's first step idles for the rest of it, which costs most on rays of few steps.
 * Measured against one step an iteration (dragon_11k to the full dragon, 1024x1024): two
 * steps 0.86-0.96x the time on AO rays and 0.92-1.00x on primary rays; four 0.85-0.94x on AO
 * rays but up to 1.10x on primary rays; six no better than four, eight 1.1-1.5x slower (README,
 * issue 7's thirteenth session). Two is the most that slows no query. The camera's rays take
 * no new ray: one step. Written out rather than as an inner loop, so that there is one loop,
 * whose iterations the budget bounds as lavapipe counts them. */
const uint WIDE_STEPS = WIDE_REFILL ? 2u : 1u;

/* One step of trace_wide's loop: one stack entry popped, and a triangle tested and a node
 * visited where the lane has them. A macro, not a function, for the stack arrays (as
 * WIDE_PUSH_SLOT); the loop runs it WIDE_STEPS times an iteration. */
#define WIDE_STEP()                                                                              \
    {                                                                                            \
        /* One stack entry a step: dropped if it starts beyond the closest hit found since (it   \
         * cannot improve it), else taken by whichever stage is free for it, a leaf waiting on   \
         * top while another leaf's triangles are being tested. */                               \
        if (tri == NO_TRI && held != NO_NODE) {                                                  \
            if (!(held_tnear > prune_bound(best.t))) tri = held & ~VKRT_WIDE_LEAF;               \
            held = NO_NODE;                                                                      \
        }                                                                                        \
        if (sp > 0u) {                                                                           \
            uint top = stack_ref[sp - 1u];                                                       \
            float top_tnear = stack_tnear[sp - 1u];                                              \
            bool leaf = (top & VKRT_WIDE_LEAF) != 0u;                                            \
            if (top_tnear > prune_bound(best.t)) {                                               \
                sp--;                                                                            \
            } else if (leaf && tri == NO_TRI) {                                                  \
                tri = top & ~VKRT_WIDE_LEAF;                                                     \
                sp--;                                                                            \
            } else if (leaf && held == NO_NODE) {                                                \
                held = top;                                                                      \
                held_tnear = top_tnear;                                                          \
                sp--;                                                                            \
            } else if (!leaf && node == NO_NODE) {                                               \
                node = top;                                                                      \
                sp--;                                                                            \
            }                                                                                    \
        }                                                                                        \
        /* Every step runs both stages where it has work for them: lavapipe executes the whole   \
         * loop body for all eight lanes of a SIMD group anyway, so a step that tests a triangle \
         * and visits a node costs what one doing either costs. Both stages' reads come first    \
         * (node 0 and triangle 0 for an idle stage), so that the node's wait on memory overlaps \
         * the triangle's: read inside its stage, after the triangle test, the node was fetched  \
         * only once the test's hundreds of instructions had passed through the CPU's reorder    \
         * window. 5-9% less time on any-hit AO rays, the same on others (in-process A/B). */    \
        wide_node visited = load_wide_node(node == NO_NODE ? 0u : node);                         \
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
            }                                                                                    \
        }                                                                                        \
        if (PUSH_FARTHER_ALWAYS) {                                                               \
            /* Every lane, visiting a node or not (lavapipe computes the visit for all eight     \
             * anyway): a lane without one enters no child and moves no entry onto its stack. */ \
            uvec4 keys, children = visited.children;                                             \
            uint entered = visit_wide_node(r, visited, best.t, keys);                            \
            if (node == NO_NODE) entered = 0u;                                                   \
            WIDE_PUSH_FARTHER_ALWAYS(keys, entered);                                             \
            if (node != NO_NODE) {                                                               \
                node = NO_NODE;                                                                  \
                WIDE_TAKE_NEAREST(keys, entered);                                                \
            }                                                                                    \
        } else if (node != NO_NODE) {                                                            \
            uvec4 keys, children = visited.children;                                             \
            uint entered = visit_wide_node(r, visited, best.t, keys);                            \
            node = NO_NODE;                                                                      \
            /* The farther children on the stack, farthest first; the nearest to a free stage,   \
             * or on top of them. Never full: the host keeps the wide BVH within a third of the  \
             * stack's levels. */                                                                \
            if (entered > 3u) WIDE_PUSH_SLOT(keys.w);                                            \
            if (entered > 2u) WIDE_PUSH_SLOT(keys.z);                                            \
            if (entered > 1u) WIDE_PUSH_SLOT(keys.y);                                            \
            WIDE_TAKE_NEAREST(keys, entered);                                                    \
        }                                                                                        \
    }

/* The closest (or, ANYHIT, any) hit of r, as trace_bvh finds it; with WIDE_RAYS > 1 the hits of
 * ray slot `rays`' rays from its k-th on (r is that one, `valid` whether it may hit anything),
 * then of the slots take_ray_slot gives, each ray's triangle stored by store_slot_tri.
 * Returns false where the budget stopped it (the state is then in continuation slot `slot`). */
bool trace_wide(ray r, bool valid, uint slot, uint rays, uint k, inout hit best)
{
    uint stack_ref[VKRT_TRAVERSAL_STACK_SIZE + WIDE_PUSH_ROOM];
    float stack_tnear[VKRT_TRAVERSAL_STACK_SIZE + WIDE_PUSH_ROOM];
    uint sp = 0u, node = valid ? 0u : NO_NODE, tri = NO_TRI;
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
            stack_ref[i] = e.node;
            stack_tnear[i] = e.tnear;
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
        if (node == NO_NODE && tri == NO_TRI && sp == 0u && held == NO_NODE) {
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
        states[slot] = vkrt_gpu_resume(1u, node, tri, k, sp, best.t, u, v, best.tri, best.prim, held,
                                       floatBitsToUint(held_tnear), rays, 0u, 0u, 0u);
        for (uint i = 0u; i < sp; i++)
            saved_stack[slot * VKRT_TRAVERSAL_STACK_SIZE + i] = vkrt_gpu_stack_entry(stack_ref[i], stack_tnear[i]);
        atomicAdd(unfinished, 1u);
        return false;
    }
    mark_finished(slot);
    return true;
}

#endif
