/* Texture coordinates and bilinear texture sampling, shared by trace.comp and shade.comp; the
 * including shader declares the `texels` buffer first. Mirrors src/texture.c and surface_uv()
 * in src/cpu_trace.c. */
#ifndef VKRT_TEXTURE_GLSL
#define VKRT_TEXTURE_GLSL

/* Texture coordinates interpolated with the hit's barycentrics (u: corner 1, v: corner 2).
 * Mirrors surface_uv() in src/cpu_trace.c. */
vec2 surface_uv(vkrt_gpu_surface f, float u, float v)
{
    precise float w = 1.0 - u - v;
    precise float s = (f.u0 * w + f.u1 * u) + f.u2 * v;
    precise float t = (f.v0 * w + f.v1 * u) + f.v2 * v;
    return vec2(s, t);
}

/* The sampling of src/texture.c, function for function: a coordinate brought into one period
 * of its wrap mode, texel indices wrapped (without GLSL's undefined % of negatives), four
 * texels fetched and blended bilinearly. */
float wrap_coordinate(float u, uint mode)
{
    if (!(abs(u) < 1e30)) return 0.0;
    if (mode == VKRT_GPU_WRAP_CLAMP) return u < -1.0 ? -1.0 : (u > 2.0 ? 2.0 : u);
    precise float r = mode == VKRT_GPU_WRAP_MIRROR ? u - 2.0 * floor(u * 0.5) : u - floor(u);
    return r;
}

int wrap_index(int i, int n, uint mode)
{
    if (mode == VKRT_GPU_WRAP_CLAMP) return i < 0 ? 0 : (i >= n ? n - 1 : i);
    if (mode == VKRT_GPU_WRAP_MIRROR) {
        int k = i < 0 ? i + 2 * n : (i >= 2 * n ? i - 2 * n : i);
        return k < n ? k : 2 * n - 1 - k;
    }
    return i < 0 ? i + n : (i >= n ? i - n : i);
}

vec4 fetch_texel(vkrt_gpu_texture t, int x, int y)
{
    uvec2 p = texels[t.first + uint(y) * t.width + uint(x)];
    return vec4(unpackHalf2x16(p.x), unpackHalf2x16(p.y));
}

vec4 sample_texture(vkrt_gpu_texture t, vec2 uv)
{
    int w = int(t.width), h = int(t.height);
    uint wrap_u = t.wrap & 0xFFu, wrap_v = t.wrap >> 8;
    precise float x = wrap_coordinate(uv.x, wrap_u) * float(w) - 0.5;
    precise float y = wrap_coordinate(uv.y, wrap_v) * float(h) - 0.5;
    float x0 = floor(x), y0 = floor(y);
    precise float fx = x - x0, fy = y - y0;
    int ix = int(x0), iy = int(y0);
    int xa = wrap_index(ix, w, wrap_u), xb = wrap_index(ix + 1, w, wrap_u);
    int ya = wrap_index(iy, h, wrap_v), yb = wrap_index(iy + 1, h, wrap_v);
    vec4 c00 = fetch_texel(t, xa, ya), c10 = fetch_texel(t, xb, ya);
    vec4 c01 = fetch_texel(t, xa, yb), c11 = fetch_texel(t, xb, yb);
    precise vec4 top = c00 * (1.0 - fx) + c10 * fx;
    precise vec4 bottom = c01 * (1.0 - fx) + c11 * fx;
    precise vec4 result = top * (1.0 - fy) + bottom * fy;
    return result;
}

#endif
