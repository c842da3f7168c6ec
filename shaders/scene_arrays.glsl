/* The scene's triangle, node and surface arrays, each read through one function, so that a
 * scene split across buffers (VKRT_SPEC_SPLIT, see vkrt_shared.h) and one in a single buffer
 * per array share every caller. With SPLIT = 0, the specialisation of every scene that fits
 * one buffer, the functions are the plain array reads and the piece code is compiled out; a
 * split scene pays one read of the piece table per element.
 *
 * The including shader declares, before including this file: the spec constant SPLIT, the
 * Tris and Surfaces blocks (`tris`, `surfaces`), the piece table (`pieces`, an array of
 * vkrt_gpu_address) and, with VKRT_SCENE_NODES defined, the Nodes block (`nodes`). Where the
 * device has no buffer device addresses (VKRT_HAS_BUFFER_ADDRESS undefined) scenes are never
 * split, and the piece code is left out of the module. */
#ifndef VKRT_SCENE_ARRAYS_GLSL
#define VKRT_SCENE_ARRAYS_GLSL

#ifdef VKRT_HAS_BUFFER_ADDRESS
/* Element addresses are a piece's base (aligned as any storage buffer) plus a multiple of the
 * 32- or 64-byte element: 16-byte aligned, as std430 vec3 loads want. */
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer TriPiece {
    vkrt_gpu_tri elements[];
};
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer SurfacePiece {
    vkrt_gpu_surface elements[];
};
#ifdef VKRT_SCENE_NODES
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer NodePiece {
    vkrt_gpu_node elements[];
};
#endif

/* The device address of the piece of array `array` (VKRT_PIECE_*) that holds element i. */
uvec2 piece_address(uint i, uint array)
{
    vkrt_gpu_address a = pieces[VKRT_PIECE_ARRAYS * (i >> SPLIT) + array];
    return uvec2(a.lo, a.hi);
}

/* Element i's index within its piece. */
uint piece_index(uint i)
{
    return i & ((1u << SPLIT) - 1u);
}
#endif

vkrt_gpu_tri load_tri(uint i)
{
#ifdef VKRT_HAS_BUFFER_ADDRESS
    if (SPLIT != 0u) return TriPiece(piece_address(i, VKRT_PIECE_TRIS)).elements[piece_index(i)];
#endif
    return tris[i];
}

vkrt_gpu_surface load_surface(uint i)
{
#ifdef VKRT_HAS_BUFFER_ADDRESS
    if (SPLIT != 0u) return SurfacePiece(piece_address(i, VKRT_PIECE_SURFACES)).elements[piece_index(i)];
#endif
    return surfaces[i];
}

#ifdef VKRT_SCENE_NODES
vkrt_gpu_node load_node(uint i)
{
#ifdef VKRT_HAS_BUFFER_ADDRESS
    if (SPLIT != 0u) return NodePiece(piece_address(i, VKRT_PIECE_NODES)).elements[piece_index(i)];
#endif
    return nodes[i];
}
#endif

#endif /* VKRT_SCENE_ARRAYS_GLSL */
