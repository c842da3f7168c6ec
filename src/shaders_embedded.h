/* GLSL sources of shaders/, includes inlined, generated into the build by
 * scripts/embed_shaders.py. */
#ifndef VKRT_SHADERS_EMBEDDED_H
#define VKRT_SHADERS_EMBEDDED_H

extern const char vkrt_shader_trace_comp[];
/* The lighting modes' wavefront stages. */
extern const char vkrt_shader_shade_comp[];
/* Test only: copies every shared-struct field out, to check the std430 layout on the device. */
extern const char vkrt_shader_layout_check_comp[];
/* Test only: runs ray_offset() of trace_common.glsl, to compare it with the C one bit for bit. */
extern const char vkrt_shader_offset_check_comp[];
/* Test only: runs the emulated correctly rounded division and square root of rounding.glsl. */
extern const char vkrt_shader_rounding_check_comp[];

#endif
