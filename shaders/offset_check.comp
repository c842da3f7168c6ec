#version 460
// Runs ray_offset() of shaders/trace_common.glsl on a list of points and normals, so a test
// can compare the device's offset origins with ray_offset() of src/ray_offset.c bit for bit
// (tests/test_gpu.c, gpu_ray_offset_matches_c). The tracing shaders spawn secondary rays with
// this function; the CPU tracer with the C one.
#extension GL_GOOGLE_include_directive : require
#include "vkrt_shared.h"

layout(local_size_x = 64) in;
// trace_common.glsl reads the intersector's spec constant; its value does not matter here.
layout(constant_id = VKRT_SPEC_ISECT) const uint ISECT = VKRT_GPU_ISECT_WATERTIGHT;
layout(std430, set = 0, binding = 0) readonly buffer Inputs { float inputs[]; };   // p.xyz, n.xyz per case
layout(std430, set = 0, binding = 1) writeonly buffer Outputs { float outputs[]; }; // offset p.xyz per case
layout(push_constant) uniform Count { uint count; };

#include "trace_common.glsl"

void main()
{
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    vec3 p = vec3(inputs[6 * i], inputs[6 * i + 1], inputs[6 * i + 2]);
    vec3 n = vec3(inputs[6 * i + 3], inputs[6 * i + 4], inputs[6 * i + 5]);
    vec3 o = ray_offset(p, n);
    outputs[3 * i] = o.x;
    outputs[3 * i + 1] = o.y;
    outputs[3 * i + 2] = o.z;
}
