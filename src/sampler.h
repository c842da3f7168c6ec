/* The low-discrepancy sampler of the lighting modes: Owen-scrambled, shuffled Sobol' points
 * (Burley, "Practical Hash-based Owen Scrambling", JCGT 9(4), 2020), four dimensions at a time,
 * each group of four decorrelated from the others by its own seed ("padding"). A pixel's
 * samples 0 .. 2^k - 1 are a (0, 2)-sequence in every pair of its dimensions, so estimates
 * converge faster than with independent random numbers, and the seed makes every render
 * reproducible. Mirrors shaders/sampler.glsl bit for bit (integer arithmetic only until the
 * final conversion, which is exact). */
#ifndef VKRT_SAMPLER_H
#define VKRT_SAMPLER_H

#include <stdint.h>

/* The seed of pixel (x, y) of a render seeded with `seed`. */
uint32_t sampler_pixel_seed(uint32_t x, uint32_t y, uint32_t seed);

/* Sample `index` of the pixel, dimensions 4 * group .. 4 * group + 3, each in [0, 1). */
void sampler_get4(uint32_t pixel_seed, uint32_t index, uint32_t group, float out[4]);

#endif
