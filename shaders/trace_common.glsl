/* The tracing algorithm shared by every variant of trace.comp. Each function mirrors the C
 * function of the same name in src/cpu_trace.c (or src/scene_pack.c for normal_decode), with
 * the arithmetic in the same order; change both together.
 *
 * Triangle test: Möller, Trumbore, "Fast, Minimum Storage Ray/Triangle Intersection", JGT
 * 2(1), 1997. Box test: Kay, Kajiya slab method with a reciprocal direction (Williams et al.,
 * JGT 10(1), 2005). Normals: octahedral, Cigolle et al., JCGT 3(2), 2014.
 *
 * `precise` keeps the device from fusing multiplies and adds differently in different
 * pipelines: BVH and naive traversal are separate pipelines that must produce bit-identical
 * distances and barycentrics for the same ray and triangle. */
#ifndef VKRT_TRACE_COMMON_GLSL
#define VKRT_TRACE_COMMON_GLSL

#define NO_PRIM 0xFFFFFFFFu
#define T_INFINITY uintBitsToFloat(0x7F800000u)

struct ray {
    vec3 origin;
    vec3 dir;
    vec3 inv_dir;
};

ray camera_ray(vkrt_gpu_push p, uint x, uint y)
{
    float sx = 2.0 * (float(x) + 0.5) / float(p.width) - 1.0;
    float sy = 1.0 - 2.0 * (float(y) + 0.5) / float(p.height);
    precise vec3 d = (p.forward + p.right * sx) + p.up * sy;
    precise float len2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
    precise vec3 dir = d * (1.0 / sqrt(len2));
    ray r;
    r.origin = p.eye;
    r.dir = dir;
    r.inv_dir = vec3(1.0) / dir;
    return r;
}

float dot3(vec3 a, vec3 b)
{
    precise float s = (a.x * b.x + a.y * b.y) + a.z * b.z;
    return s;
}

vec3 cross3(vec3 a, vec3 b)
{
    precise vec3 c = vec3(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
    return c;
}

bool intersect_triangle(ray r, vkrt_gpu_tri tri, out float out_t, out float out_u, out float out_v)
{
    out_t = 0.0;
    out_u = 0.0;
    out_v = 0.0;
    precise vec3 e1 = tri.v1 - tri.v0;
    precise vec3 e2 = tri.v2 - tri.v0;
    precise vec3 pvec = cross3(r.dir, e2);
    precise float det = dot3(e1, pvec);
    if (det == 0.0) return false;
    precise float inv_det = 1.0 / det;
    precise vec3 tvec = r.origin - tri.v0;
    precise float u = dot3(tvec, pvec) * inv_det;
    precise vec3 qvec = cross3(tvec, e1);
    precise float v = dot3(r.dir, qvec) * inv_det;
    precise float t = dot3(e2, qvec) * inv_det;
    /* Written as acceptance so a NaN from a nearly parallel ray is rejected too. */
    if (!(u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0)) return false;
    out_t = t;
    out_u = u;
    out_v = v;
    return true;
}

/* The shared closest-hit rule: nearer wins, and at equal distance the lower prim_id, so the
 * answer does not depend on the order triangles are visited (BVH vs naive, any builder). */
bool hit_closer(float t, uint prim, float best_t, uint best_prim)
{
    return t > 0.0 && (t < best_t || (t == best_t && prim < best_prim));
}

/* GLSL leaves min/max of a NaN open; these are its definitions written out, as in C. */
float f_min(float x, float y) { return y < x ? y : x; }
float f_max(float x, float y) { return x < y ? y : x; }

bool intersect_box(ray r, vec3 bmin, vec3 bmax, float best_t, out float out_tnear)
{
    vec3 t0 = (bmin - r.origin) * r.inv_dir;
    vec3 t1 = (bmax - r.origin) * r.inv_dir;
    vec3 tmin = vec3(f_min(t0.x, t1.x), f_min(t0.y, t1.y), f_min(t0.z, t1.z));
    vec3 tmax = vec3(f_max(t0.x, t1.x), f_max(t0.y, t1.y), f_max(t0.z, t1.z));
    float tnear = f_max(f_max(tmin.x, tmin.y), f_max(tmin.z, 0.0));
    float tfar = f_min(f_min(tmax.x, tmax.y), f_min(tmax.z, best_t));
    out_tnear = tnear;
    return tnear <= tfar;
}

/* Mirrors normal_decode_oct() in src/scene_pack.c. */
vec3 normal_decode(uint packed)
{
    vec2 f = unpackSnorm2x16(packed);
    vec3 n = vec3(f.x, f.y, 1.0 - abs(f.x) - abs(f.y));
    float t = -n.z > 0.0 ? -n.z : 0.0;
    n.x += n.x >= 0.0 ? -t : t;
    n.y += n.y >= 0.0 ? -t : t;
    return n * (1.0 / sqrt((n.x * n.x + n.y * n.y) + n.z * n.z));
}

/* rgb = interpolated unit vertex normal * 0.5 + 0.5. */
vec4 shade_normal(vkrt_gpu_tri tri, float u, float v)
{
    float w = 1.0 - u - v;
    vec3 n = (normal_decode(tri.n0) * w + normal_decode(tri.n1) * u) + normal_decode(tri.n2) * v;
    float len2 = (n.x * n.x + n.y * n.y) + n.z * n.z;
    /* Opposed vertex normals can cancel; the face normal is the only direction left. */
    n = len2 > 0.0 ? n * (1.0 / sqrt(len2)) : tri.face_n;
    return vec4(n * 0.5 + 0.5, 1.0);
}

#endif
