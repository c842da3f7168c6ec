#include "sampler.h"

#include "../shaders/vkrt_shared.h"

static const uint32_t sobol_directions[128] = { VKRT_SOBOL_DIRECTIONS };

/* A 32-bit integer hash (Wellons' lowbias32, "Hash Prospector", 2018): every input bit moves
 * about half of the output bits. */
static uint32_t hash_u32(uint32_t x)
{
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

static uint32_t hash_combine(uint32_t seed, uint32_t v)
{
    return seed ^ (hash_u32(v) + 0x9e3779b9u + (seed << 6) + (seed >> 2));
}

static uint32_t reverse_bits(uint32_t x)
{
    x = ((x >> 1) & 0x55555555u) | ((x & 0x55555555u) << 1);
    x = ((x >> 2) & 0x33333333u) | ((x & 0x33333333u) << 2);
    x = ((x >> 4) & 0x0f0f0f0fu) | ((x & 0x0f0f0f0fu) << 4);
    x = ((x >> 8) & 0x00ff00ffu) | ((x & 0x00ff00ffu) << 8);
    return (x >> 16) | (x << 16);
}

/* Burley 2020, listing 2 (after Laine and Karras 2011): a hash in which each bit depends only
 * on the bits below it, so on reversed bits it is a nested uniform (Owen) scramble. */
static uint32_t laine_karras_permutation(uint32_t x, uint32_t seed)
{
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

static uint32_t nested_uniform_scramble(uint32_t x, uint32_t seed)
{
    return reverse_bits(laine_karras_permutation(reverse_bits(x), seed));
}

static uint32_t sobol(uint32_t index, uint32_t dim)
{
    uint32_t x = 0;
    for (uint32_t bit = 0; index != 0; bit++, index >>= 1)
        if (index & 1u) x ^= sobol_directions[dim * 32 + bit];
    return x;
}

uint32_t sampler_pixel_seed(uint32_t x, uint32_t y, uint32_t seed)
{
    return hash_combine(hash_combine(hash_u32(seed), x), y);
}

void sampler_get4(uint32_t pixel_seed, uint32_t index, uint32_t group, float out[4])
{
    uint32_t seed = hash_combine(pixel_seed, group);
    uint32_t shuffled = nested_uniform_scramble(index, seed);
    for (uint32_t d = 0; d < 4; d++) {
        uint32_t v = nested_uniform_scramble(sobol(shuffled, d), hash_combine(seed, d));
        /* The top 24 bits, so the float is exact and below 1. */
        out[d] = (float)(v >> 8) * (1.0f / 16777216.0f);
    }
}
