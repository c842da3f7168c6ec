#version 460
// Copies every field of every struct in vkrt_shared.h to a flat word array, in declaration
// order, so a test can compare the std430 layout the shader sees with the C layout byte for
// byte (tests/test_gpu.c, gpu_shared_layouts_match_c).
#extension GL_GOOGLE_include_directive : require
#include "vkrt_shared.h"

layout(local_size_x = 1) in;
layout(std430, set = 0, binding = 0) readonly buffer Nodes { vkrt_gpu_node nodes[]; };
layout(std430, set = 0, binding = 1) readonly buffer Tris { vkrt_gpu_tri tris[]; };
layout(std430, set = 0, binding = 2) readonly buffer Hits { vkrt_gpu_hit hits[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Words { uint words[]; };
layout(std430, set = 0, binding = 4) readonly buffer Rays { vkrt_gpu_ray rays[]; };
layout(std430, set = 0, binding = 5) readonly buffer Resume { vkrt_gpu_resume states[]; };
layout(std430, set = 0, binding = 6) readonly buffer ResumeStack { vkrt_gpu_stack_entry entries[]; };
layout(std430, set = 0, binding = 7) readonly buffer Counters { vkrt_gpu_counters counters[]; };
layout(std430, set = 0, binding = 8) readonly buffer Surfaces { vkrt_gpu_surface surfaces[]; };
layout(std430, set = 0, binding = 9) readonly buffer Materials { vkrt_gpu_material materials[]; };
layout(std430, set = 0, binding = 10) readonly buffer Textures { vkrt_gpu_texture textures[]; };
layout(std430, set = 0, binding = 11) readonly buffer Lights { vkrt_gpu_light lights[]; };
layout(std430, set = 0, binding = 12) readonly buffer Lighting { vkrt_gpu_lighting lightings[]; };
layout(std430, set = 0, binding = 13) readonly buffer Paths { vkrt_gpu_path paths[]; };
layout(std430, set = 0, binding = 14) readonly buffer Accums { vkrt_gpu_accum accums[]; };
layout(std430, set = 0, binding = 15) readonly buffer Addresses { vkrt_gpu_address addresses[]; };
layout(push_constant) uniform PushBlock { vkrt_gpu_push p; };

uint k = 0;
void put(float v) { words[k++] = floatBitsToUint(v); }
void put(uint v) { words[k++] = v; }
void put(vec3 v) { put(v.x); put(v.y); put(v.z); }

void main()
{
    // Element 1 of each array, so the array stride is checked too.
    vkrt_gpu_node n = nodes[1];
    put(n.bmin); put(n.left_first); put(n.bmax); put(n.tri_count);
    vkrt_gpu_tri t = tris[1];
    put(t.v0); put(t.prim_id); put(t.v1); put(t.n0); put(t.v2); put(t.n1); put(t.face_n); put(t.n2);
    vkrt_gpu_hit h = hits[1];
    put(h.t); put(h.tri); put(h.u); put(h.v);
    vkrt_gpu_ray r = rays[1];
    put(r.origin); put(r.tmin); put(r.dir); put(r.tmax);
    put(p.eye); put(p.width); put(p.right); put(p.height); put(p.up); put(p.tile_x); put(p.forward);
    put(p.tile_y); put(p.tile_width); put(p.tile_height); put(p.tri_first); put(p.tri_end); put(p.tri_total);
    put(p.last_chunk); put(p.resume); put(p.stage_arg);
    vkrt_gpu_resume s = states[1];
    put(s.unfinished); put(s.node); put(s.tri_next); put(s.tri_end); put(s.sp); put(s.t); put(s.u); put(s.v);
    put(s.tri); put(s.prim); put(s.heat_nodes); put(s.heat_leaves); put(s.heat_tris); put(s.pad0); put(s.pad1);
    put(s.pad2);
    vkrt_gpu_stack_entry e = entries[1];
    put(e.node); put(e.word);
    vkrt_gpu_counters c = counters[1];
    put(c.nodes); put(c.leaves); put(c.tris); put(c.pad0);
    vkrt_gpu_surface f = surfaces[1];
    put(f.u0); put(f.v0); put(f.u1); put(f.v1); put(f.u2); put(f.v2); put(f.material); put(f.pad0);
    vkrt_gpu_material m = materials[1];
    put(m.base_color); put(m.alpha); put(m.emissive); put(m.metallic); put(m.roughness); put(m.base_color_texture);
    put(m.alpha_cutoff); put(m.metallic_roughness_texture); put(m.emissive_texture); put(m.pad0); put(m.pad1);
    put(m.pad2);
    vkrt_gpu_texture x = textures[1];
    put(x.first); put(x.width); put(x.height); put(x.wrap);
    vkrt_gpu_light l = lights[1];
    put(l.vector); put(l.type); put(l.color); put(l.cdf); put(l.tri); put(l.pick); put(l.area); put(l.pad0);
    vkrt_gpu_lighting g = lightings[1];
    put(g.sky_zenith); put(g.light_count); put(g.sky_horizon); put(g.punctual_count); put(g.ao_distance);
    put(g.ao_samples); put(g.max_bounces); put(g.target_error); put(g.pick_scale); put(g.emitter_pick);
    put(g.seed); put(g.spp);
    vkrt_gpu_path q = paths[1];
    put(q.throughput); put(q.flags); put(q.radiance); put(q.bsdf_pdf); put(q.position); put(q.depth); put(q.normal);
    put(q.tri); put(q.geo_normal); put(q.metallic); put(q.albedo); put(q.roughness); put(q.wo); put(q.shadow_lane);
    put(q.pending); put(q.rng_dim);
    vkrt_gpu_accum a = accums[1];
    put(a.sum); put(a.samples); put(a.lum_sum); put(a.lum_sq_sum); put(a.done); put(a.alpha);
    vkrt_gpu_address d = addresses[1];
    put(d.lo); put(d.hi);
}
