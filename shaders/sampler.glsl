/* Owen-scrambled, shuffled Sobol' points (Burley 2020). Mirrors src/sampler.c function for
 * function, integer arithmetic only until the final, exact conversion. */
#ifndef VKRT_SAMPLER_GLSL
#define VKRT_SAMPLER_GLSL

const uint sobol_directions[128] = uint[128](VKRT_SOBOL_DIRECTIONS);

uint hash_u32(uint x)
{
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

uint hash_combine(uint seed, uint v)
{
    return seed ^ (hash_u32(v) + 0x9e3779b9u + (seed << 6) + (seed >> 2));
}

uint laine_karras_permutation(uint x, uint seed)
{
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

uint nested_uniform_scramble(uint x, uint seed)
{
    return bitfieldReverse(laine_karras_permutation(bitfieldReverse(x), seed));
}

/* Up to 32 iterations (one per set bit position below the highest): bounded, so a stage's
 * loops stay far from lavapipe's limit. */
uint sobol(uint index, uint dim)
{
    uint x = 0u;
    for (uint bit = 0u; index != 0u; bit++, index >>= 1)
        if ((index & 1u) != 0u) x ^= sobol_directions[dim * 32u + bit];
    return x;
}

uint sampler_pixel_seed(uint x, uint y, uint seed)
{
    return hash_combine(hash_combine(hash_u32(seed), x), y);
}

vec4 sampler_get4(uint pixel_seed, uint index, uint group)
{
    uint seed = hash_combine(pixel_seed, group);
    uint shuffled = nested_uniform_scramble(index, seed);
    vec4 out_u;
    for (uint d = 0u; d < 4u; d++) {
        uint v = nested_uniform_scramble(sobol(shuffled, d), hash_combine(seed, d));
        out_u[d] = float(v >> 8) * (1.0 / 16777216.0);
    }
    return out_u;
}

#endif
