#version 460
// Runs the correctly rounded division and square root of shaders/rounding.glsl, in their
// emulated form whatever the device, on a list of operands, so that a test can compare them
// with C's / and sqrtf bit for bit (tests/test_gpu.c, gpu_emulated_rounding_matches_c). Real
// GPUs run this form; lavapipe, whose own operators round correctly, runs it only here and
// where a test asks for it. Besides div_rn and sqrt_rn themselves, the correction step is run
// on a first guess one ulp below and one ulp above the device's, as a device whose double
// division or root is a little off would give it.
#extension GL_GOOGLE_include_directive : require
#define VKRT_HAS_FLOAT64 1
#define VKRT_EXACT_ROUNDING 1
#include "rounding.glsl"

layout(local_size_x = 64) in;
layout(std430, set = 0, binding = 0) readonly buffer Inputs { float inputs[]; };   // a, b per case
layout(std430, set = 0, binding = 1) writeonly buffer Outputs { float outputs[]; }; // 6 per case
layout(push_constant) uniform Count { uint count; };

float step_off(float x, int ulps)
{
    return uintBitsToFloat(uint(int(floatBitsToUint(x)) + ulps));
}

void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    float a = inputs[2 * i], b = inputs[2 * i + 1];
    float x = abs(a), y = abs(b);
    float q = float(double(x) / double(y)), s = float(sqrt(double(x)));
    outputs[6 * i] = div_rn(a, b);
    outputs[6 * i + 1] = sqrt_rn(a);
    outputs[6 * i + 2] = round_quotient(x, y, step_off(q, -1));
    outputs[6 * i + 3] = round_quotient(x, y, step_off(q, 1));
    outputs[6 * i + 4] = round_root(x, step_off(s, -1));
    outputs[6 * i + 5] = round_root(x, step_off(s, 1));
}
