/* GPU data layouts shared by the C library (src/) and the GLSL shaders (shaders/).
 *
 * One definition for both sides, so the byte layout of a node or a triangle can never drift
 * between the host that writes a buffer and the shader that reads it. Every struct is laid out
 * for std430 and checked with _Static_assert on the C side; the shader test reads every field
 * back on the device to check the same offsets at run time.
 *
 * Rule for new fields: only uint32_t, int32_t, float, and a vec3 immediately followed by a
 * 4-byte scalar (a C float[3] is 12 bytes where std430 aligns vec3 to 16). */
#ifndef VKRT_SHARED_H
#define VKRT_SHARED_H

#ifdef __STDC_VERSION__ /* C side; glslang never defines this */
#include <stddef.h>
#include <stdint.h>
typedef struct vkrt_float3 { float x, y, z; } vkrt_float3;
#define VKRT_FLOAT3 vkrt_float3
#define VKRT_UINT uint32_t
#define VKRT_STRUCT(name) typedef struct name name; struct name
#else /* GLSL side */
#define VKRT_FLOAT3 vec3
#define VKRT_UINT uint
#define VKRT_STRUCT(name) struct name
#endif

/* Workgroup shape: lavapipe packs 8 invocations along x into one SIMD group, so x is a
 * multiple of 8 (8x8 measured fastest with 16x8 and 64x1; 4x4 was 2-8x slower). */
#define VKRT_TRACE_GROUP_X 8
#define VKRT_TRACE_GROUP_Y 8

/* Descriptor bindings of trace.comp (set 0). */
#define VKRT_BINDING_NODES 0
#define VKRT_BINDING_TRIS 1
#define VKRT_BINDING_IMAGE 2
#define VKRT_BINDING_HITS 3
#define VKRT_BINDING_RAYS 4
#define VKRT_BINDING_RESUME 5          /* vkrt_gpu_resume per pixel of a tile / ray of a chunk */
#define VKRT_BINDING_RESUME_STACK 6    /* VKRT_TRAVERSAL_STACK_SIZE vkrt_gpu_stack_entry per slot */
#define VKRT_BINDING_UNFINISHED 7      /* two uints: invocations that stopped at the budget, and
                                          the next ray slot a wide trace takes (both cleared
                                          before every pass) */
#define VKRT_BINDING_COUNTERS 8        /* vkrt_gpu_counters per pixel of a tile (VKRT_SPEC_COUNTERS) */
#define VKRT_BINDING_SURFACES 9        /* vkrt_gpu_surface per triangle, by prim_id (albedo, uv) */
#define VKRT_BINDING_MATERIALS 10      /* vkrt_gpu_material table (albedo) */
#define VKRT_BINDING_TEXTURES 11       /* vkrt_gpu_texture table (albedo) */
#define VKRT_BINDING_TEXELS 12         /* every texture's texels: linear RGBA as 4 halves (uvec2) */
#define VKRT_BINDING_PIECES 13         /* vkrt_gpu_address piece table of a split scene (VKRT_SPEC_SPLIT) */
/* Bindings 14 .. 20 are storage texel buffers, the wide traversal's arrays (RGBA32UI but for
 * the last four, R32UI) and the binned traversal's lists: */
#define VKRT_BINDING_WIDE_NODES 14     /* the wide BVH (VKRT_SPEC_WIDE), read only */
#define VKRT_BINDING_TRACE_TRIS 15     /* its triangles, whole, read only */
#define VKRT_BINDING_RAY_TEXELS 16     /* a view of the rays buffer, a ray two texels, read only */
#define VKRT_BINDING_HIT_WORDS 17      /* an R32UI view of the hits buffer, a hit four texels */
#define VKRT_BINDING_SLOT_TRIS 18      /* R32UI: each ray slot's closest triangles so far, a slot's
                                          VKRT_WIDE_RAYS_PER_LANE words together (wide ray traces) */
#define VKRT_BINDING_RAY_LISTS 19      /* R32UI: each ray's first entry in LIST_TRIS and entry count
                                          (binned traversal, src/ray_bin.h) */
#define VKRT_BINDING_LIST_TRIS 20      /* R32UI: the rays' lists of triangles (wide array indices) */
#define VKRT_BINDING_TEXEL_FIRST VKRT_BINDING_WIDE_NODES
#define VKRT_BINDING_TEXEL_COUNT 7     /* the texel buffers, bindings 14 .. 20 */
#define VKRT_BINDING_COUNT 21          /* bindings 0 .. 20: the image one, the texel buffers,
                                          storage buffers the rest */

/* Descriptor bindings of shade.comp (set 0): the lighting modes' wavefront stages. The ray and
 * hit buffers are the ones trace.comp reads and writes in its wavefront variant. */
#define VKRT_SHADE_BINDING_TRIS 0
#define VKRT_SHADE_BINDING_SURFACES 1
#define VKRT_SHADE_BINDING_MATERIALS 2
#define VKRT_SHADE_BINDING_TEXTURES 3
#define VKRT_SHADE_BINDING_TEXELS 4
#define VKRT_SHADE_BINDING_LIGHTS 5      /* vkrt_gpu_light table */
#define VKRT_SHADE_BINDING_PATHS 6       /* vkrt_gpu_path per pixel of a tile */
#define VKRT_SHADE_BINDING_ACCUM 7       /* vkrt_gpu_accum per pixel of a tile */
#define VKRT_SHADE_BINDING_RAYS 8        /* extension rays, traced closest-hit */
#define VKRT_SHADE_BINDING_HITS 9        /* their hits (tri = triangle array index) */
#define VKRT_SHADE_BINDING_SHADOW_RAYS 10 /* shadow and AO rays, traced any-hit */
#define VKRT_SHADE_BINDING_SHADOW_HITS 11
#define VKRT_SHADE_BINDING_ACTIVE 12     /* one uint: pixels sampling / paths still going */
#define VKRT_SHADE_BINDING_LIGHTING 13   /* one vkrt_gpu_lighting */
#define VKRT_SHADE_BINDING_QUEUE 14      /* two queues of a tile's pixel slots (uint), in and out */
#define VKRT_SHADE_BINDING_PIECES 15     /* as VKRT_BINDING_PIECES */
#define VKRT_SHADE_BINDING_COUNT 16

/* Specialization constant ids: features a render does not use are compiled out instead of
 * branched over (lavapipe pays nearly full price for an `if` that is false everywhere). */
#define VKRT_SPEC_MODE 0
#define VKRT_SPEC_TRAVERSAL 1
#define VKRT_SPEC_HEAT 2
#define VKRT_SPEC_RAYGEN 3
#define VKRT_SPEC_ISECT 4
#define VKRT_SPEC_BUDGET 5 /* BVH loop iterations per dispatch; 0 = unlimited (no budget code) */
#define VKRT_SPEC_COUNTERS 6 /* 1: each pixel's traversal counts written out; 0: no counting code */
#define VKRT_SPEC_ALPHA 7 /* 1: the scene has alpha-masked materials, hits are alpha tested */
#define VKRT_SPEC_ANYHIT 8 /* 1: stop at the first hit in (tmin, tmax) (shadow and AO rays) */
#define VKRT_SPEC_TEXTURES 9 /* 1: some material has a texture (albedo mode, alpha test); 0: none
                                is sampled, the texture code compiled out */
#define VKRT_SPEC_SPLIT 10 /* 0: the scene's arrays each in one buffer; else log2 of the elements per
                             piece of a split scene, read through the piece table */
#define VKRT_SPEC_WIDE 11 /* 1: traverse the wide BVH through the texel buffers (a scene in one
                             buffer, no heat or counters: those count the binary BVH's steps) */
#define VKRT_SPEC_FINISH 12 /* 1 (with WIDE, a ray buffer): the pass after a wide trace, which turns
                               each ray's recorded triangle into its hit (distance, barycentrics) */

/* Specialization constants of shade.comp: the stage, the mode, and one switch per feature, so
 * a scene pays only for what it uses (vkrt_render_stats.features lists those compiled in). */
#define VKRT_SPEC_SHADE_STAGE 0
#define VKRT_SPEC_SHADE_MODE 1
#define VKRT_SPEC_SHADE_FEATURES 2 /* VKRT_FEATURE_* bits */
#define VKRT_SPEC_SHADE_SPLIT 3    /* as VKRT_SPEC_SPLIT */

/* Values of the specialization constants; the C side asserts they equal the public enums. */
#define VKRT_GPU_MODE_NORMAL 1
#define VKRT_GPU_MODE_DEPTH 2
#define VKRT_GPU_MODE_HEATMAP 3
#define VKRT_GPU_MODE_ID 4
#define VKRT_GPU_MODE_ALBEDO 5
#define VKRT_GPU_MODE_UV 6
#define VKRT_GPU_MODE_SHADED 7
#define VKRT_GPU_MODE_AO 8
#define VKRT_GPU_MODE_PATH 9
#define VKRT_GPU_TRAVERSAL_BVH 1
#define VKRT_GPU_TRAVERSAL_NAIVE 2
#define VKRT_GPU_TRAVERSAL_BINNED 3 /* rays that share an origin, each testing the triangles the
                                       host listed for it (src/ray_bin.h); a CPU device only */
#define VKRT_GPU_HEAT_NODES 1
#define VKRT_GPU_HEAT_LEAVES 2
#define VKRT_GPU_HEAT_TRIS 3
#define VKRT_GPU_RAYGEN_CAMERA 1 /* one primary ray per pixel of a tile, into the image */
#define VKRT_GPU_RAYGEN_BUFFER 2 /* the rays of the rays buffer, closest hits into the hits buffer */
#define VKRT_GPU_RAYGEN_WAVEFRONT 3 /* as BUFFER, but the hit names the triangle array index (for
                                       shade.comp) and the distance is not refined */
#define VKRT_GPU_ISECT_WATERTIGHT 1
#define VKRT_GPU_ISECT_MOLLER_TRUMBORE 2

/* Ray mode: rays traced per submission (and the size of the ray and hit buffers): 2^18 rays
 * are 4,096 workgroups of 64, far below the 65,535 a dispatch may have, and keep a
 * naive-traversal chunk of one submission to seconds on lavapipe. */
#define VKRT_RAY_CHUNK 262144u
#define VKRT_TRACE_GROUP_SIZE (VKRT_TRACE_GROUP_X * VKRT_TRACE_GROUP_Y)

/* Conservative traversal (Ize, "Robust BVH Ray Traversal", JCGT 2(2), 2013): the far end of
 * every slab interval is scaled by 1 + 2 gamma(3), gamma(n) = n eps / (1 - n eps), so
 * rounding in (bound - origin) * (1 / dir) can never cull a box the exact ray enters.
 * eps = 2^-24: 1 + 2 gamma(3) = 1 + 3 * 2^-23 (1 + 3 * 2^-24 + ...), rounded up to the next
 * float, 1 + 4 * 2^-23. The double reference uses eps = 2^-53, rounded up the same way. */
#define VKRT_TFAR_WIDEN_FLOAT 1.000000476837158203125
#define VKRT_TFAR_WIDEN_DOUBLE 1.000000000000000888178419700125232338905334472656250

/* Ties at the closest hit (two triangles sharing an edge or a vertex that the ray passes,
 * both at the same float t) go to the lower prim_id whatever the traversal order, but only if
 * both triangles get tested: a box is culled or a stack entry dropped only when it starts
 * beyond best t plus this fraction of it, so the rounding of a box's entry distance, which can
 * come out a few ulps above the t of a triangle lying on its face, never hides the winner of a
 * tie (the slack admits only boxes whose entry is within 1.5e-5 of the hit). */
#define VKRT_PRUNE_SLACK (1.0 / 65536.0)

/* Secondary-ray origins (ray_offset in src/ray_offset.c and shaders/trace_common.glsl; Wächter,
 * Binder, Ray Tracing Gems ch. 6, 2019): 256 ulps per unit of normal covers the error of a hit
 * point computed from barycentrics in float; below 1/32 in magnitude a coordinate's ulps get
 * too small, and a fixed 1/65536 per unit of normal is used instead. */
#define VKRT_OFFSET_ORIGIN (1.0 / 32.0)
#define VKRT_OFFSET_FLOAT_SCALE (1.0 / 65536.0)
#define VKRT_OFFSET_INT_SCALE 256.0

/* Traversal stack entries. With the nearer child visited first and the farther one pushed,
 * the stack never holds more entries than the tree is deep, and every builder caps its depth
 * at VKRT_MAX_BVH_DEPTH (a node that deep becomes a leaf). */
#define VKRT_MAX_BVH_DEPTH 64
#define VKRT_TRAVERSAL_STACK_SIZE VKRT_MAX_BVH_DEPTH

/* Naive traversal tests at most this many triangles per dispatch: lavapipe silently stops a
 * loop after 65,535 iterations per group of 8 invocations, so larger scenes are split into
 * chunks whose closest hits are merged through the hit buffer. */
#define VKRT_NAIVE_CHUNK_TRIS 8192u
/* Naive traversal reads a chunk's triangles this many at a time at most, one a lane of a
 * subgroup, and every lane tests them all (trace_naive_chunk in shaders/trace.comp, which
 * unrolls that many tests); the device's share is vk_naive_share's, VKRT_NAIVE_SHARE in the
 * shaders. */
#define VKRT_NAIVE_SHARE_MAX 8u

/* Loop budget of lavapipe (Mesa's llvmpipe): it silently ends every loop of a shader once
 * 65,535 iterations in all have run per SIMD group of 8 invocations (one counter shared by
 * every loop, lp_exec_mask_function_init), with no error. BVH traversal is one flat loop of
 * node steps and triangle tests that stops after this many iterations per dispatch, saves its
 * state and is resumed by the next dispatch; half the limit leaves room for the state's load
 * and save loops (VKRT_TRAVERSAL_STACK_SIZE each). Devices without the limit get 0. */
#define VKRT_LAVAPIPE_BUDGET 32768u

/* Ray mode with a budget: rays per submission, so the continuation buffers stay well under
 * lavapipe's 128 MiB maxStorageBufferRange where they are largest, with a slot per ray (the
 * binary traversal's: 64 bytes of state plus VKRT_TRAVERSAL_STACK_SIZE 8-byte entries, 36 MiB
 * in all; the wide traversal keeps a slot per invocation of VKRT_WIDE_RAYS_PER_LANE rays, a
 * VKRT_WIDE_RAYS_PER_LANE-th of that). A 256x256 tile has as many pixels. */
#define VKRT_RESUME_RAY_CHUNK 65536u

/* Stages of shade.comp, in the order one sample of a tile runs them (vkrt_gpu_push.stage_arg
 * carries the light or AO ray index of VKRT_STAGE_SHADOW). A pixel's sample index is the count
 * of samples its accumulation holds. CAMERA and FINISH run over every pixel of the tile; the
 * others over a queue of the pixels still tracing (compaction: a dispatch and a trace pass
 * cost what the live paths need, not the tile), each queued path's rays and hits at its lane,
 * its index in the queue. The push constants say where: tri_first is the input queue's offset in
 * the queue buffer, tri_end the output queue's, tri_total the lanes of the input queue. */
#define VKRT_STAGE_CAMERA 1  /* primary rays of the pixels still sampling */
#define VKRT_STAGE_HIT 2     /* closest hits: emission, the sky on a miss, the vertex stored */
#define VKRT_STAGE_SHADOW 3  /* one shadow or AO ray from the stored vertex */
#define VKRT_STAGE_BOUNCE 4  /* path: the next direction sampled from the BSDF */
#define VKRT_STAGE_FINISH 5  /* the last shadow ray resolved, the sample accumulated (the host
                                reads the tile's accumulation buffer after its last sample) */
/* Stages fused into one dispatch where they always follow each other, so a path's state is
 * loaded and stored once instead of once per stage (lavapipe's storage buffers are slow). */
#define VKRT_STAGE_VERTEX 6  /* path: HIT, SHADOW 0 and BOUNCE */
#define VKRT_STAGE_HIT_SHADOW 7 /* shaded, ao: HIT and SHADOW 0 */

/* Features of the lighting modes, each compiled into shade.comp only when the scene and the
 * render use it (the same bits as VKRT_FEATURE_* in vkrt.h). */
#define VKRT_GPU_FEATURE_TEXTURES 1u   /* some material has a texture: uv interpolation, sampling */
#define VKRT_GPU_FEATURE_PUNCTUAL 2u   /* point or directional lights: shadow rays to them */
#define VKRT_GPU_FEATURE_EMITTERS 4u   /* emissive triangles: emission, area-light sampling */
#define VKRT_GPU_FEATURE_SKY 8u        /* a sky that is not black */
#define VKRT_GPU_FEATURE_SPECULAR 16u  /* some material is metallic: GGX and mirror code */
#define VKRT_GPU_FEATURE_RANDOM 32u    /* the render needs random numbers (not shaded with only
                                          punctual lights) */
#define VKRT_GPU_FEATURE_ADAPTIVE 64u  /* adaptive sampling: per-pixel error estimates */
#define VKRT_GPU_FEATURE_ALL 127u

/* Light types (vkrt_gpu_light.type). */
#define VKRT_GPU_LIGHT_DIRECTIONAL 0u
#define VKRT_GPU_LIGHT_POINT 1u
#define VKRT_GPU_LIGHT_TRIANGLE 2u

/* Sobol' direction numbers of the first four dimensions (Joe, Kuo 2008; dimension 0 is van der
 * Corput's), 32 per dimension, highest bit first: the sampler (src/sampler.c and
 * shaders/sampler.glsl) reads this one table on both sides. */
#define VKRT_SOBOL_DIRECTIONS \
    0x80000000u, 0x40000000u, 0x20000000u, 0x10000000u, 0x08000000u, 0x04000000u, 0x02000000u, 0x01000000u, \
    0x00800000u, 0x00400000u, 0x00200000u, 0x00100000u, 0x00080000u, 0x00040000u, 0x00020000u, 0x00010000u, \
    0x00008000u, 0x00004000u, 0x00002000u, 0x00001000u, 0x00000800u, 0x00000400u, 0x00000200u, 0x00000100u, \
    0x00000080u, 0x00000040u, 0x00000020u, 0x00000010u, 0x00000008u, 0x00000004u, 0x00000002u, 0x00000001u, \
    0x80000000u, 0xc0000000u, 0xa0000000u, 0xf0000000u, 0x88000000u, 0xcc000000u, 0xaa000000u, 0xff000000u, \
    0x80800000u, 0xc0c00000u, 0xa0a00000u, 0xf0f00000u, 0x88880000u, 0xcccc0000u, 0xaaaa0000u, 0xffff0000u, \
    0x80008000u, 0xc000c000u, 0xa000a000u, 0xf000f000u, 0x88008800u, 0xcc00cc00u, 0xaa00aa00u, 0xff00ff00u, \
    0x80808080u, 0xc0c0c0c0u, 0xa0a0a0a0u, 0xf0f0f0f0u, 0x88888888u, 0xccccccccu, 0xaaaaaaaau, 0xffffffffu, \
    0x80000000u, 0xc0000000u, 0x60000000u, 0x90000000u, 0xe8000000u, 0x5c000000u, 0x8e000000u, 0xc5000000u, \
    0x68800000u, 0x9cc00000u, 0xee600000u, 0x55900000u, 0x80680000u, 0xc09c0000u, 0x60ee0000u, 0x90550000u, \
    0xe8808000u, 0x5cc0c000u, 0x8e606000u, 0xc5909000u, 0x6868e800u, 0x9c9c5c00u, 0xeeee8e00u, 0x5555c500u, \
    0x8000e880u, 0xc0005cc0u, 0x60008e60u, 0x9000c590u, 0xe8006868u, 0x5c009c9cu, 0x8e00eeeeu, 0xc5005555u, \
    0x80000000u, 0xc0000000u, 0x20000000u, 0x50000000u, 0xf8000000u, 0x74000000u, 0xa2000000u, 0x93000000u, \
    0xd8800000u, 0x25400000u, 0x59e00000u, 0xe6d00000u, 0x78080000u, 0xb40c0000u, 0x82020000u, 0xc3050000u, \
    0x208f8000u, 0x51474000u, 0xfbea2000u, 0x75d93000u, 0xa0858800u, 0x914e5400u, 0xdbe79e00u, 0x25db6d00u, \
    0x58800080u, 0xe54000c0u, 0x79e00020u, 0xb6d00050u, 0x800800f8u, 0xc00c0074u, 0x200200a2u, 0x50050093u

/* Scenes beyond one storage buffer (VKRT_SPEC_SPLIT != 0): the triangle, node and surface arrays
 * are cut into pieces of 2^VKRT_SPEC_SPLIT elements, each a buffer of its own that the shaders
 * reach by its device address. Piece k of array a has its address at entry
 * VKRT_PIECE_ARRAYS * k + a of the piece table; element i is element i % 2^split of piece
 * i / 2^split. One shift for all three arrays: the triangles (64 bytes) are the largest of them
 * and set it, so a node or surface piece is half a triangle piece. */
#define VKRT_PIECE_TRIS 0
#define VKRT_PIECE_NODES 1
#define VKRT_PIECE_SURFACES 2
#define VKRT_PIECE_ARRAYS 3

/* Miss value written to the id and depth channels. */
#define VKRT_MISS (-1.0)

/* BVH node, 32 bytes: two per 64-byte cache line.
 * Interior node: tri_count == 0, children at left_first and left_first + 1.
 * Leaf: triangles [left_first, left_first + tri_count) of the triangle array. */
VKRT_STRUCT(vkrt_gpu_node) {
    VKRT_FLOAT3 bmin;      /* offset  0 */
    VKRT_UINT left_first;  /* offset 12 */
    VKRT_FLOAT3 bmax;      /* offset 16 */
    VKRT_UINT tri_count;   /* offset 28 */
};

/* Triangle, 64 bytes, in BVH order: the three corners, the unit face normal, the index of the
 * triangle in the loaded file (what `id` mode shows) and the three unit vertex normals, each
 * octahedrally encoded as two 16-bit snorm values (error below 1e-4 rad). */
VKRT_STRUCT(vkrt_gpu_tri) {
    VKRT_FLOAT3 v0;        /* offset  0 */
    VKRT_UINT prim_id;     /* offset 12 */
    VKRT_FLOAT3 v1;        /* offset 16 */
    VKRT_UINT n0;          /* offset 28 */
    VKRT_FLOAT3 v2;        /* offset 32 */
    VKRT_UINT n1;          /* offset 44 */
    VKRT_FLOAT3 face_n;    /* offset 48 */
    VKRT_UINT n2;          /* offset 60 */
};

/* The wide traversal's arrays (VKRT_SPEC_WIDE), read as RGBA32UI texels: texel fetches ran
 * 1.3-1.6x faster than storage-buffer loads of the same traversal on lavapipe.
 * A node is the 4-wide node of src/bvh_wide.h in VKRT_WIDE_NODE_TEXELS texels, 64 bytes, one
 * cache line (lavapipe's traversal waits on memory: 112-byte nodes straddling three lines
 * traced 10-13% slower than 128-byte ones on two): its boxes quantised to 8 bits per plane
 * (Ylitie, Karras, Laine, "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide
 * BVHs", HPG 2017), rounded outwards so that a decoded box holds the true one:
 *   texel 0: the frame's origin x, y, z (float bits) and the biased exponents of its
 *            power-of-two scales, a byte per axis (a coordinate is origin + q * scale);
 *   texel 1: q of lo.x, lo.y, lo.z and hi.x, texel 2: of hi.y, hi.z (a byte per slot), 0, 0;
 *   texel 3: the child references: a node index, VKRT_WIDE_LEAF | first triangle, or
 *            VKRT_WIDE_NO_CHILD.
 * A triangle is VKRT_WIDE_TRI_WORDS words, in the triangle array's order, packed without gaps
 * (two triangles in five texels): its corners' x, y, z float bits, then its prim_id with
 * VKRT_TRACE_TRI_LAST set on each leaf's last triangle (a leaf reference names only its
 * first). A triangle is read as the three texels from VKRT_WIDE_TRI_FIRST_TEXEL, which an odd
 * one starts half-way into. 40 bytes a triangle against vkrt_gpu_tri's 64; the normals are
 * read from the triangle array once per ray, at the closest hit. (Corner indices into
 * deduplicated corners took 24 bytes, but each test read the indices, then the corners:
 * whole triangles traced AO rays 5-9% faster on dragon_200k and the full dragon.) */
#define VKRT_WIDE_TRI_WORDS 10
#define VKRT_WIDE_TRI_FIRST_TEXEL(i) (2u * (i) + (i) / 2u)
#define VKRT_WIDE_NODE_TEXELS 4
#define VKRT_WIDE_LEAF 0x80000000u
#define VKRT_WIDE_NO_CHILD 0xFFFFFFFFu
#define VKRT_TRACE_TRI_LAST 0x80000000u
/* Rays each invocation of the wide traversal takes from a ray buffer, one after the other
 * (trace_wide in shaders/traverse_wide.glsl): a dispatch of n rays has n / 32 invocations. 32
 * traced 9% faster than 8 (in-process A/B, primary and AO rays on dragon_200k) with the same
 * instruction count; 64 was 5% slower again on primary rays. */
#define VKRT_WIDE_RAYS_PER_LANE 32u

/* Closest hit of one pixel or ray, carried between naive-traversal chunk dispatches. 16 bytes.
 * Ray mode: the last dispatch writes the public vkrt_hit in place (t = -1 and
 * tri = 0xFFFFFFFF on a miss, else tri = the hit triangle's prim_id). */
VKRT_STRUCT(vkrt_gpu_hit) {
    float t;               /* offset  0; +inf while nothing was hit */
    VKRT_UINT tri;         /* offset  4; index into the triangle array (BVH order) */
    float u;               /* offset  8; barycentrics of the hit */
    float v;               /* offset 12 */
};

/* BVH traversal state of an invocation that used up its budget (VKRT_SPEC_BUDGET), read back
 * by the resume dispatch, 64 bytes. The ray itself is not saved: it is recomputed from the
 * pixel or re-read from the ray buffer, bit for bit the same. */
VKRT_STRUCT(vkrt_gpu_resume) {
    VKRT_UINT unfinished;  /* offset  0; 1: resume from here, 0: done (or never stopped) */
    VKRT_UINT node;        /* offset  4; node to visit next, 0xFFFFFFFF: pop the stack */
    VKRT_UINT tri_next;    /* offset  8; next triangle of the current leaf */
    VKRT_UINT tri_end;     /* offset 12; one past its last (tri_next == tri_end: no leaf) */
    VKRT_UINT sp;          /* offset 16; stack entries saved */
    float t;               /* offset 20; closest hit so far (t = ray tmax: none) */
    float u;               /* offset 24 */
    float v;               /* offset 28 */
    VKRT_UINT tri;         /* offset 32; triangle array index of the hit */
    VKRT_UINT prim;        /* offset 36; its prim_id, 0xFFFFFFFF: none */
    VKRT_UINT heat_nodes;  /* offset 40; heat counters so far (the wide traversal, which counts
                              nothing: its held leaf, and that leaf's entry distance's bits in
                              heat_leaves; tri_end: the ray in progress of the ray slot in
                              heat_tris) */
    VKRT_UINT heat_leaves; /* offset 44 */
    VKRT_UINT heat_tris;   /* offset 48 */
    VKRT_UINT pad0;        /* offset 52; to 64 bytes, one cache line */
    VKRT_UINT pad1;        /* offset 56 */
    VKRT_UINT pad2;        /* offset 60 */
};

/* What one primary ray's BVH traversal did (VKRT_SPEC_COUNTERS), 16 bytes: the boxes it
 * entered (the root's included), how many of those were leaves, and its ray-triangle tests:
 * the heat map's three counts. */
VKRT_STRUCT(vkrt_gpu_counters) {
    VKRT_UINT nodes;       /* offset  0 */
    VKRT_UINT leaves;      /* offset  4 */
    VKRT_UINT tris;        /* offset  8 */
    VKRT_UINT pad0;        /* offset 12 */
};

/* What a triangle's surface carries besides its geometry, 32 bytes, indexed by prim_id (load
 * order): the texture coordinates of its corners and its material. Read only by the modes
 * that need them, and uploaded only then. */
VKRT_STRUCT(vkrt_gpu_surface) {
    float u0;              /* offset  0 */
    float v0;              /* offset  4 */
    float u1;              /* offset  8 */
    float v1;              /* offset 12 */
    float u2;              /* offset 16 */
    float v2;              /* offset 20 */
    VKRT_UINT material;    /* offset 24; index into the material table */
    VKRT_UINT pad0;        /* offset 28 */
};

/* A material (vkrt_material), 64 bytes. */
VKRT_STRUCT(vkrt_gpu_material) {
    VKRT_FLOAT3 base_color; /* offset  0; linear RGB */
    float alpha;            /* offset 12 */
    VKRT_FLOAT3 emissive;   /* offset 16 */
    float metallic;         /* offset 28 */
    float roughness;        /* offset 32 */
    VKRT_UINT base_color_texture; /* offset 36; index into the texture table, VKRT_NO_TEXTURE: none */
    float alpha_cutoff;     /* offset 40; > 0: alpha MASK (vkrt_material.alpha_cutoff) */
    VKRT_UINT metallic_roughness_texture; /* offset 44; glTF: roughness in G, metallic in B, each
                                             multiplying its factor; VKRT_NO_TEXTURE: none */
    VKRT_UINT emissive_texture; /* offset 48; multiplies emissive; VKRT_NO_TEXTURE: none */
    VKRT_UINT pad0;         /* offset 52 */
    VKRT_UINT pad1;         /* offset 56 */
    VKRT_UINT pad2;         /* offset 60 */
};

#define VKRT_NO_TEXTURE 0xFFFFFFFFu
/* Texture wrap modes (vkrt_wrap). */
#define VKRT_GPU_WRAP_REPEAT 0
#define VKRT_GPU_WRAP_CLAMP 1
#define VKRT_GPU_WRAP_MIRROR 2

/* A texture, 16 bytes: its texels start at `first` of the texel buffer, rows top to bottom. */
VKRT_STRUCT(vkrt_gpu_texture) {
    VKRT_UINT first;       /* offset  0; in texels */
    VKRT_UINT width;       /* offset  4 */
    VKRT_UINT height;      /* offset  8 */
    VKRT_UINT wrap;        /* offset 12; wrap_u | wrap_v << 8 (VKRT_GPU_WRAP_*) */
};

/* A light of the lighting modes, 48 bytes. The table holds the render's punctual lights, then
 * the scene's emissive triangles; next-event estimation picks one entry with probability
 * `pick` (its share of the estimated power, the cumulative sum in `cdf`). */
VKRT_STRUCT(vkrt_gpu_light) {
    VKRT_FLOAT3 vector;    /* offset  0; directional: unit direction the light travels; point:
                              position; triangle: unused */
    VKRT_UINT type;        /* offset 12; VKRT_GPU_LIGHT_* */
    VKRT_FLOAT3 color;     /* offset 16; directional: irradiance facing it; point: intensity
                              (W/sr); triangle: emitted radiance */
    float cdf;             /* offset 28; sum of `pick` of this entry and all before it */
    VKRT_UINT tri;         /* offset 32; triangle: its index in the triangle array */
    float pick;            /* offset 36; probability next-event estimation picks this light */
    float area;            /* offset 40; triangle: its area */
    VKRT_UINT pad0;        /* offset 44 */
};

/* What lights a render besides its light table, 64 bytes, in a buffer of its own. */
VKRT_STRUCT(vkrt_gpu_lighting) {
    VKRT_FLOAT3 sky_zenith;  /* offset  0; radiance from straight up (+y) */
    VKRT_UINT light_count;   /* offset 12; entries in the table */
    VKRT_FLOAT3 sky_horizon; /* offset 16; radiance at and below the horizon */
    VKRT_UINT punctual_count;/* offset 28; the first entries: directional and point lights */
    float ao_distance;       /* offset 32; ao: occluders beyond this distance do not count */
    VKRT_UINT ao_samples;    /* offset 36; ao: rays per hit per sample */
    VKRT_UINT max_bounces;   /* offset 40; path: bounces after the primary hit */
    float target_error;      /* offset 44; adaptive: relative standard error to stop at */
    float pick_scale;        /* offset 48; an emissive triangle's pick = its power * pick_scale */
    float emitter_pick;      /* offset 52; sum of the emissive triangles' picks */
    VKRT_UINT seed;          /* offset 56; the sampler's scramble seed */
    VKRT_UINT spp;           /* offset 60; samples per pixel at most */
};

/* The state of one pixel's path between wavefront stages, 128 bytes. */
VKRT_STRUCT(vkrt_gpu_path) {
    VKRT_FLOAT3 throughput;  /* offset  0; product of BSDF * cos / pdf so far */
    VKRT_UINT flags;         /* offset 12; VKRT_PATH_* */
    VKRT_FLOAT3 radiance;    /* offset 16; this sample's radiance so far */
    float bsdf_pdf;          /* offset 28; solid-angle pdf of the last bounce (MIS), 0: delta */
    VKRT_FLOAT3 position;    /* offset 32; the stored vertex */
    VKRT_UINT depth;         /* offset 44; vertices so far, the primary hit's is 1 */
    VKRT_FLOAT3 normal;      /* offset 48; shading normal, facing the incoming ray */
    VKRT_UINT tri;           /* offset 60; triangle array index of the vertex */
    VKRT_FLOAT3 geo_normal;  /* offset 64; geometric normal, facing the incoming ray */
    float metallic;          /* offset 76 */
    VKRT_FLOAT3 albedo;      /* offset 80; base colour at the vertex */
    float roughness;         /* offset 92 */
    VKRT_FLOAT3 wo;          /* offset 96; unit direction back along the incoming ray */
    VKRT_UINT shadow_lane;   /* offset 108; where its pending shadow ray was traced */
    VKRT_FLOAT3 pending;     /* offset 112; the shadow ray's contribution if it is unoccluded */
    VKRT_UINT rng_dim;       /* offset 124; next sampler dimension */
};

#define VKRT_PATH_ACTIVE 1u   /* the path goes on */
#define VKRT_PATH_VERTEX 2u   /* a vertex is stored (the last ray hit a surface) */
#define VKRT_PATH_PENDING 4u  /* a shadow ray's contribution waits for its visibility */
#define VKRT_PATH_PRIMARY_HIT 8u /* the primary ray hit a surface (alpha of the pixel) */
/* The extension ray's direction is -wo from the moment the ray is made (CAMERA, BOUNCE), so a
 * stage never reads the ray buffer that the same dispatch writes for the next pass. */

/* One pixel's accumulated samples, 32 bytes: the radiance sum, and the luminance sum and sum
 * of squares from which adaptive sampling estimates the error of the mean. */
VKRT_STRUCT(vkrt_gpu_accum) {
    VKRT_FLOAT3 sum;         /* offset  0 */
    VKRT_UINT samples;       /* offset 12 */
    float lum_sum;           /* offset 16 */
    float lum_sq_sum;        /* offset 20 */
    VKRT_UINT done;          /* offset 24; 1: the pixel takes no more samples */
    float alpha;             /* offset 28; 1 when the primary ray hit */
};

/* A buffer device address (VkDeviceAddress) as two words, 8 bytes: GLSL makes a buffer
 * reference of the uvec2 (GL_EXT_buffer_reference_uvec2), so no shader needs 64-bit integers. */
VKRT_STRUCT(vkrt_gpu_address) {
    VKRT_UINT lo;          /* offset  0 */
    VKRT_UINT hi;          /* offset  4 */
};

/* One saved traversal stack entry, 8 bytes: a pushed node and a word, the float bits of the
 * distance its box starts (the binary traversal) or the group's sort word (the wide one:
 * group_encode in shaders/traverse_wide.glsl). Bits rather than a float: the group's word may
 * read as a NaN or a denormal, which a device need not copy intact. */
VKRT_STRUCT(vkrt_gpu_stack_entry) {
    VKRT_UINT node;        /* offset  0 */
    VKRT_UINT word;        /* offset  4 */
};

/* A ray for arbitrary-ray tracing (vkrt_trace_rays), 32 bytes, identical to vkrt_ray. */
VKRT_STRUCT(vkrt_gpu_ray) {
    VKRT_FLOAT3 origin;    /* offset  0 */
    float tmin;            /* offset 12 */
    VKRT_FLOAT3 dir;       /* offset 16 */
    float tmax;            /* offset 28; 0 means +infinity */
};

/* Push constants of trace.comp, 96 bytes (Vulkan guarantees 128).
 * Primary ray through pixel (x, y), with sx = 2 (x + 0.5) / width - 1 and
 * sy = 1 - 2 (y + 0.5) / height: normalize(forward + sx * right + sy * up).
 * Ray mode (VKRT_GPU_RAYGEN_BUFFER): tile_width is the number of rays in the buffers, the
 * camera and the other tile fields are unused; the tri_* fields and last_chunk as for images. */
VKRT_STRUCT(vkrt_gpu_push) {
    VKRT_FLOAT3 eye;       /* offset  0 */
    VKRT_UINT width;       /* offset 12; whole image */
    VKRT_FLOAT3 right;     /* offset 16; camera right scaled by tan(fov/2) * aspect */
    VKRT_UINT height;      /* offset 28 */
    VKRT_FLOAT3 up;        /* offset 32; camera up scaled by tan(fov/2) */
    VKRT_UINT tile_x;      /* offset 44; pixel origin of this dispatch */
    VKRT_FLOAT3 forward;   /* offset 48; unit view direction */
    VKRT_UINT tile_y;      /* offset 60 */
    VKRT_UINT tile_width;  /* offset 64 */
    VKRT_UINT tile_height; /* offset 68 */
    VKRT_UINT tri_first;   /* offset 72; naive traversal: first triangle of this chunk */
    VKRT_UINT tri_end;     /* offset 76; naive traversal: one past the last of this chunk */
    VKRT_UINT tri_total;   /* offset 80; triangles in the scene */
    VKRT_UINT last_chunk;  /* offset 84; naive traversal: 1 when this chunk writes the image */
    VKRT_UINT resume;      /* offset 88; BVH with a budget: 1 continues saved traversals */
    VKRT_UINT stage_arg;   /* offset 92; shade.comp: the light or
                              AO ray of a SHADOW stage */
};

#ifdef __STDC_VERSION__
_Static_assert(sizeof(vkrt_float3) == 12, "vkrt_float3 must be three packed floats");
_Static_assert(sizeof(vkrt_gpu_node) == 32, "vkrt_gpu_node must match std430");
_Static_assert(offsetof(vkrt_gpu_node, left_first) == 12, "vkrt_gpu_node.left_first must match std430");
_Static_assert(offsetof(vkrt_gpu_node, bmax) == 16, "vkrt_gpu_node.bmax must match std430");
_Static_assert(offsetof(vkrt_gpu_node, tri_count) == 28, "vkrt_gpu_node.tri_count must match std430");
_Static_assert(sizeof(vkrt_gpu_tri) == 64, "vkrt_gpu_tri must match std430");
_Static_assert(offsetof(vkrt_gpu_tri, prim_id) == 12, "vkrt_gpu_tri.prim_id must match std430");
_Static_assert(offsetof(vkrt_gpu_tri, v1) == 16, "vkrt_gpu_tri.v1 must match std430");
_Static_assert(offsetof(vkrt_gpu_tri, n0) == 28, "vkrt_gpu_tri.n0 must match std430");
_Static_assert(offsetof(vkrt_gpu_tri, v2) == 32, "vkrt_gpu_tri.v2 must match std430");
_Static_assert(offsetof(vkrt_gpu_tri, n1) == 44, "vkrt_gpu_tri.n1 must match std430");
_Static_assert(offsetof(vkrt_gpu_tri, face_n) == 48, "vkrt_gpu_tri.face_n must match std430");
_Static_assert(offsetof(vkrt_gpu_tri, n2) == 60, "vkrt_gpu_tri.n2 must match std430");
_Static_assert(sizeof(vkrt_gpu_hit) == 16, "vkrt_gpu_hit must match std430");
_Static_assert(sizeof(vkrt_gpu_ray) == 32, "vkrt_gpu_ray must match std430");
_Static_assert(offsetof(vkrt_gpu_ray, dir) == 16, "vkrt_gpu_ray.dir must match std430");
_Static_assert(sizeof(vkrt_gpu_resume) == 64, "vkrt_gpu_resume must match std430");
_Static_assert(offsetof(vkrt_gpu_resume, t) == 20, "vkrt_gpu_resume.t must match std430");
_Static_assert(offsetof(vkrt_gpu_resume, heat_tris) == 48, "vkrt_gpu_resume.heat_tris must match std430");
_Static_assert(sizeof(vkrt_gpu_address) == 8, "vkrt_gpu_address must match std430");
_Static_assert(offsetof(vkrt_gpu_address, hi) == 4, "vkrt_gpu_address.hi must match std430");
_Static_assert(sizeof(vkrt_gpu_stack_entry) == 8, "vkrt_gpu_stack_entry must match std430");
_Static_assert(offsetof(vkrt_gpu_stack_entry, word) == 4, "vkrt_gpu_stack_entry.word must match std430");
_Static_assert(VKRT_NAIVE_CHUNK_TRIS <= VKRT_LAVAPIPE_BUDGET, "a naive chunk's loop must fit lavapipe's loop limit");
_Static_assert(sizeof(vkrt_gpu_counters) == 16, "vkrt_gpu_counters must match std430");
_Static_assert(sizeof(vkrt_gpu_surface) == 32, "vkrt_gpu_surface must match std430");
_Static_assert(sizeof(vkrt_gpu_material) == 64, "vkrt_gpu_material must match std430");
_Static_assert(offsetof(vkrt_gpu_material, emissive_texture) == 48, "vkrt_gpu_material.emissive_texture must match std430");
_Static_assert(sizeof(vkrt_gpu_light) == 48, "vkrt_gpu_light must match std430");
_Static_assert(offsetof(vkrt_gpu_light, color) == 16, "vkrt_gpu_light.color must match std430");
_Static_assert(sizeof(vkrt_gpu_lighting) == 64, "vkrt_gpu_lighting must match std430");
_Static_assert(sizeof(vkrt_gpu_path) == 128, "vkrt_gpu_path must match std430");
_Static_assert(offsetof(vkrt_gpu_path, pending) == 112, "vkrt_gpu_path.pending must match std430");
_Static_assert(sizeof(vkrt_gpu_accum) == 32, "vkrt_gpu_accum must match std430");
_Static_assert(sizeof(vkrt_gpu_texture) == 16, "vkrt_gpu_texture must match std430");
_Static_assert(offsetof(vkrt_gpu_material, emissive) == 16, "vkrt_gpu_material.emissive must match std430");
_Static_assert(sizeof(vkrt_gpu_push) == 96, "vkrt_gpu_push must match the push-constant range");
_Static_assert(offsetof(vkrt_gpu_push, right) == 16, "vkrt_gpu_push.right must match std430");
_Static_assert(offsetof(vkrt_gpu_push, up) == 32, "vkrt_gpu_push.up must match std430");
_Static_assert(offsetof(vkrt_gpu_push, forward) == 48, "vkrt_gpu_push.forward must match std430");
_Static_assert(offsetof(vkrt_gpu_push, tile_width) == 64, "vkrt_gpu_push.tile_width must match std430");
_Static_assert(offsetof(vkrt_gpu_push, last_chunk) == 84, "vkrt_gpu_push.last_chunk must match std430");
_Static_assert(offsetof(vkrt_gpu_push, resume) == 88, "vkrt_gpu_push.resume must match std430");
#endif

#endif /* VKRT_SHARED_H */
