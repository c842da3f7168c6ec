/* The tracing algorithm shared by every variant of trace.comp. Each function mirrors the C
 * function of the same name in src/cpu_trace_real.h (its float instance, suffix _f),
 * src/scene_pack.c (normal_decode) or src/ray_offset.c, with the arithmetic in the same
 * order; change both together. trace.comp declares the spec constant ISECT before including
 * this file.
 *
 * Triangle tests: Woop, Benthin, Wald, "Watertight Ray/Triangle Intersection", JCGT 2(1), 2013
 * (the default); Möller, Trumbore, "Fast, Minimum Storage Ray/Triangle Intersection", JGT
 * 2(1), 1997. Box test: Kay, Kajiya slab method with a reciprocal direction (Williams et al.,
 * JGT 10(1), 2005), conservative as in Ize, "Robust BVH Ray Traversal", JCGT 2(2), 2013.
 * Normals: octahedral, Cigolle et al., JCGT 3(2), 2014. Secondary-ray origins: Wächter,
 * Binder, "A Fast and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems, 2019.
 *
 * `precise` keeps the device from fusing multiplies and adds differently in different
 * pipelines (BVH and naive traversal are separate pipelines that must produce bit-identical
 * distances and barycentrics for the same ray and triangle), and the C compiler (ISO C mode,
 * -ffp-contract=off) fuses nothing either. */
#ifndef VKRT_TRACE_COMMON_GLSL
#define VKRT_TRACE_COMMON_GLSL

/* Every division and square root below goes through div_rn and sqrt_rn, correctly rounded as
 * C's are on any device (rounding.glsl). */
#include "rounding.glsl"

#define NO_PRIM 0xFFFFFFFFu
#define T_INFINITY uintBitsToFloat(0x7F800000u)

struct ray {
    vec3 origin;
    vec3 dir;
    vec3 inv_dir;
    float tmin;  /* hits accepted for tmin < t < tmax */
    float tmax;
    uint kx;     /* watertight: kz the axis of the largest |dir|, kx, ky the others */
    uint ky;
    uint kz;
    float sx;    /* watertight: the shear taking dir to (0, 0, 1) */
    float sy;
    float sz;
};

ray ray_setup(vec3 origin, vec3 dir, float tmin, float tmax)
{
    ray r;
    r.origin = origin;
    r.dir = dir;
    r.inv_dir = div_rn(vec3(1.0), dir);
    r.tmin = tmin;
    r.tmax = tmax;
    float ax = abs(dir.x), ay = abs(dir.y), az = abs(dir.z);
    r.kz = ax >= ay && ax >= az ? 0u : (ay >= az ? 1u : 2u);
    r.kx = r.kz == 2u ? 0u : r.kz + 1u;
    r.ky = r.kx == 2u ? 0u : r.kx + 1u;
    if (dir[r.kz] < 0.0) {
        uint k = r.kx;
        r.kx = r.ky;
        r.ky = k;
    }
    float dz = dir[r.kz];
    r.sx = div_rn(dir[r.kx], dz);
    r.sy = div_rn(dir[r.ky], dz);
    r.sz = div_rn(1.0, dz);
    return r;
}

ray camera_ray(vkrt_gpu_push p, uint x, uint y)
{
    precise float sx = div_rn(2.0 * (float(x) + 0.5), float(p.width)) - 1.0;
    precise float sy = 1.0 - div_rn(2.0 * (float(y) + 0.5), float(p.height));
    precise vec3 d = (p.forward + p.right * sx) + p.up * sy;
    precise float len2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
    precise vec3 dir = d * div_rn(1.0, sqrt_rn(len2));
    return ray_setup(p.eye, dir, 0.0, T_INFINITY);
}

bool finite3(vec3 a)
{
    return abs(a.x) < T_INFINITY && abs(a.y) < T_INFINITY && abs(a.z) < T_INFINITY;
}

/* False for a ray that must miss: a non-finite origin or direction, or a zero direction.
 * tmax = 0 means +infinity. */
bool ray_from_buffer(vkrt_gpu_ray g, out ray r)
{
    r = ray_setup(g.origin, g.dir, g.tmin, g.tmax == 0.0 ? T_INFINITY : g.tmax);
    return finite3(g.origin) && finite3(g.dir) && !(g.dir.x == 0.0 && g.dir.y == 0.0 && g.dir.z == 0.0);
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

/* The outputs are written on a hit only. */
bool intersect_triangle_moller_trumbore(ray r, vkrt_gpu_tri tri, inout float out_t, inout float out_u, inout float out_v)
{
    precise vec3 e1 = tri.v1 - tri.v0;
    precise vec3 e2 = tri.v2 - tri.v0;
    precise vec3 pvec = cross3(r.dir, e2);
    precise float det = dot3(e1, pvec);
    if (det == 0.0) return false;
    precise float inv_det = div_rn(1.0, det);
    precise vec3 tvec = r.origin - tri.v0;
    precise float u = dot3(tvec, pvec) * inv_det;
    precise vec3 qvec = cross3(tvec, e1);
    precise float v = dot3(r.dir, qvec) * inv_det;
    precise float t = dot3(e2, qvec) * inv_det;
    /* Written as acceptance so a NaN from a nearly parallel ray is rejected too. */
    if (!(u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > r.tmin && t < r.tmax)) return false;
    out_t = t;
    out_u = u;
    out_v = v;
    return true;
}

/* Woop et al. 2013; see intersect_triangle_watertight_f in src/cpu_trace_real.h for why it is
 * watertight. Zero rule on the GPU: a zero edge value rejects nothing, so a ray through a
 * shared edge or vertex hits every triangle there (the lowest prim_id wins the tie). The CPU
 * float path re-evaluates zeros in double first (the paper's fallback; GPUs need not have
 * doubles): the two backends can then differ only for rays exactly through an edge. */
/* The outputs are written on a hit only. */
bool intersect_triangle_watertight(ray r, vkrt_gpu_tri tri, inout float out_t, inout float out_u, inout float out_v)
{
    precise vec3 a = tri.v0 - r.origin;
    precise vec3 b = tri.v1 - r.origin;
    precise vec3 c = tri.v2 - r.origin;
    float a_z = a[r.kz], b_z = b[r.kz], c_z = c[r.kz];
    precise float ax = a[r.kx] - r.sx * a_z;
    precise float ay = a[r.ky] - r.sy * a_z;
    precise float bx = b[r.kx] - r.sx * b_z;
    precise float by = b[r.ky] - r.sy * b_z;
    precise float cx = c[r.kx] - r.sx * c_z;
    precise float cy = c[r.ky] - r.sy * c_z;
    precise float eu = cx * by - cy * bx;
    precise float ev = ax * cy - ay * cx;
    precise float ew = bx * ay - by * ax;
    if ((eu < 0.0 || ev < 0.0 || ew < 0.0) && (eu > 0.0 || ev > 0.0 || ew > 0.0)) return false;
    precise float det = (eu + ev) + ew;
    if (det == 0.0) return false;
    precise float t_scaled = (eu * (r.sz * a_z) + ev * (r.sz * b_z)) + ew * (r.sz * c_z);
    precise float inv_det = div_rn(1.0, det);
    precise float t = t_scaled * inv_det;
    if (!(t > r.tmin && t < r.tmax)) return false;
    out_t = t;
    out_u = ev * inv_det;
    out_v = ew * inv_det;
    return true;
}

bool intersect_triangle(ray r, vkrt_gpu_tri tri, out float out_t, out float out_u, out float out_v)
{
    out_t = 0.0;
    out_u = 0.0;
    out_v = 0.0;
    if (ISECT == VKRT_GPU_ISECT_MOLLER_TRUMBORE) return intersect_triangle_moller_trumbore(r, tri, out_t, out_u, out_v);
    return intersect_triangle_watertight(r, tri, out_t, out_u, out_v);
}

#ifdef VKRT_HAS_FLOAT64
/* The distance of the closest hit recomputed in double as the intersection of an exact ray
 * with the triangle's plane: the pixel's ray generated in double (camera_ray_double), or a ray
 * of the buffer as given. Float edge functions lose digits where a ray grazes a triangle, and
 * a float ray is a few ulps off the pixel's; the plane distance of the exact ray in double has
 * neither error. Which triangle wins is decided in float; this runs once per ray.
 * vk_pipeline.c defines VKRT_HAS_FLOAT64 where the device has shaderFloat64 (lavapipe does);
 * elsewhere the float distance stands. Mirrors refine_hit_distance() in src/cpu_trace.c. */
float refine_hit_distance(dvec3 origin, dvec3 dir, double tmin, double tmax, vkrt_gpu_tri tri, float t)
{
    precise dvec3 v0 = dvec3(tri.v0);
    precise dvec3 e1 = dvec3(tri.v1) - v0, e2 = dvec3(tri.v2) - v0;
    precise dvec3 n = dvec3(e1.y * e2.z - e2.y * e1.z, e1.z * e2.x - e2.z * e1.x, e1.x * e2.y - e2.x * e1.y);
    precise double denom = (n.x * dir.x + n.y * dir.y) + n.z * dir.z;
    if (denom == 0.0LF) return t;
    precise dvec3 to_v0 = v0 - origin;
    precise double refined = ((n.x * to_v0.x + n.y * to_v0.y) + n.z * to_v0.z) / denom;
    return refined > tmin && refined < tmax ? float(refined) : t;
}

/* The pixel's ray as the CPU double reference generates it (camera_ray_d in
 * src/cpu_trace_real.h), from the same basis: the push constants' floats, exact in double. */
void camera_ray_double(vkrt_gpu_push p, uint x, uint y, out dvec3 origin, out dvec3 dir)
{
    precise double sx = 2.0LF * (double(x) + 0.5LF) / double(p.width) - 1.0LF;
    precise double sy = 1.0LF - 2.0LF * (double(y) + 0.5LF) / double(p.height);
    precise dvec3 d = (dvec3(p.forward) + dvec3(p.right) * sx) + dvec3(p.up) * sy;
    precise double len2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
    origin = dvec3(p.eye);
    dir = d * (1.0LF / sqrt(len2));
}
#endif

/* The shared closest-hit rule: nearer wins, and at equal distance the lower prim_id, so the
 * answer does not depend on the order triangles are visited (BVH vs naive, any builder). */
bool hit_closer(float t, uint prim, float best_t, uint best_prim)
{
    return t < best_t || (t == best_t && prim < best_prim);
}

/* GLSL leaves min/max of a NaN open; these are its definitions written out, as in C. */
float f_min(float x, float y) { return y < x ? y : x; }
float f_max(float x, float y) { return x < y ? y : x; }

/* One slab; a direction component of +0 or -0 (an infinite reciprocal) makes the slab every t
 * when the origin lies between the planes (bounds included) and empty otherwise, instead of
 * the NaN of 0 * inf. */
void slab(float o, float inv, float lo, float hi, out float out_lo, out float out_hi)
{
    precise float t0 = (lo - o) * inv;
    precise float t1 = (hi - o) * inv;
    bool parallel = abs(inv) == T_INFINITY;
    bool inside = o >= lo && o <= hi;
    out_lo = parallel ? (inside ? -T_INFINITY : T_INFINITY) : f_min(t0, t1);
    out_hi = parallel ? (inside ? T_INFINITY : -T_INFINITY) : f_max(t0, t1);
}

/* The farthest entry distance a box or stack entry may have and still be visited: best t plus
 * VKRT_PRUNE_SLACK of it. Mirrors prune_bound() in src/cpu_trace_real.h. */
float prune_bound(float best_t)
{
    precise float bound = best_t + abs(best_t) * VKRT_PRUNE_SLACK;
    return bound;
}

/* Ize 2013: the far end widened by 1 + 2 gamma(3) before it meets best_t (as prune_bound). */
bool intersect_box(ray r, vec3 bmin, vec3 bmax, float best_t, out float out_tnear)
{
    float lx, hx, ly, hy, lz, hz;
    slab(r.origin.x, r.inv_dir.x, bmin.x, bmax.x, lx, hx);
    slab(r.origin.y, r.inv_dir.y, bmin.y, bmax.y, ly, hy);
    slab(r.origin.z, r.inv_dir.z, bmin.z, bmax.z, lz, hz);
    float tnear = f_max(f_max(lx, ly), f_max(lz, r.tmin));
    precise float tfar = f_min(f_min(hx, hy), hz) * VKRT_TFAR_WIDEN_FLOAT;
    tfar = f_min(tfar, prune_bound(best_t));
    out_tnear = tnear;
    return tnear <= tfar;
}

/* Wächter, Binder 2019: p moved off its surface along n (the geometric normal, facing the
 * side the new ray leaves from) by VKRT_OFFSET_INT_SCALE ulps per unit of n in each
 * coordinate, or, within VKRT_OFFSET_ORIGIN of 0 where ulps are tiny, by
 * VKRT_OFFSET_FLOAT_SCALE * n. Mirrors ray_offset() in src/ray_offset.c. */
vec3 ray_offset(vec3 p, vec3 n)
{
    ivec3 of_i = ivec3(VKRT_OFFSET_INT_SCALE * n);
    vec3 p_i = vec3(intBitsToFloat(floatBitsToInt(p.x) + (p.x < 0.0 ? -of_i.x : of_i.x)),
                    intBitsToFloat(floatBitsToInt(p.y) + (p.y < 0.0 ? -of_i.y : of_i.y)),
                    intBitsToFloat(floatBitsToInt(p.z) + (p.z < 0.0 ? -of_i.z : of_i.z)));
    precise vec3 p_f = p + VKRT_OFFSET_FLOAT_SCALE * n;
    return vec3(abs(p.x) < VKRT_OFFSET_ORIGIN ? p_f.x : p_i.x, abs(p.y) < VKRT_OFFSET_ORIGIN ? p_f.y : p_i.y,
                abs(p.z) < VKRT_OFFSET_ORIGIN ? p_f.z : p_i.z);
}

/* Mirrors normal_decode_oct() in src/scene_pack.c. */
vec3 normal_decode(uint packed)
{
    vec2 f = unpackSnorm2x16(packed);
    vec3 n = vec3(f.x, f.y, 1.0 - abs(f.x) - abs(f.y));
    float t = -n.z > 0.0 ? -n.z : 0.0;
    n.x += n.x >= 0.0 ? -t : t;
    n.y += n.y >= 0.0 ? -t : t;
    precise float len2 = (n.x * n.x + n.y * n.y) + n.z * n.z;
    return n * div_rn(1.0, sqrt_rn(len2));
}

/* rgb = interpolated unit vertex normal * 0.5 + 0.5. */
vec4 shade_normal(vkrt_gpu_tri tri, float u, float v)
{
    precise float w = 1.0 - u - v;
    precise vec3 n = (normal_decode(tri.n0) * w + normal_decode(tri.n1) * u) + normal_decode(tri.n2) * v;
    precise float len2 = (n.x * n.x + n.y * n.y) + n.z * n.z;
    /* Opposed vertex normals can cancel; the face normal is the only direction left. */
    n = len2 > 0.0 ? n * div_rn(1.0, sqrt_rn(len2)) : tri.face_n;
    return vec4(n * 0.5 + 0.5, 1.0);
}

#endif
