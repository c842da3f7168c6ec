/* vkrt: a ray tracer for triangle meshes, with a Vulkan compute backend and a C reference.
 *
 * Usage in short:
 *
 *     vkrt_context *ctx;
 *     if (vkrt_context_create(&(vkrt_context_desc){ 0 }, &ctx) != VKRT_OK) ...
 *     vkrt_scene *scene;
 *     vkrt_scene_create(ctx, &(vkrt_scene_desc){ .path = "bunny.obj" }, &scene);
 *     float *rgba = malloc(vkrt_render_floats(512, 512) * sizeof *rgba);
 *     vkrt_render(ctx, scene, &(vkrt_render_desc){ .width = 512, .height = 512 }, rgba, ...);
 *     vkrt_image_save(ctx, "out.png", &(vkrt_image_view){ rgba, 512, 512, VKRT_MODE_NORMAL });
 *
 * Conventions:
 * - Every desc field's zero value is its default; `(desc){ 0 }` is always valid.
 * - Every fallible call returns a vkrt_result; products come out through the last `out_`
 *   parameter, which is set to NULL (or zero) on failure. vkrt_context_last_error() then
 *   holds a message naming what was wrong (the file, the field, the Vulkan call).
 * - Objects are created and destroyed in pairs; destroying NULL is a no-op.
 * - The library never prints, exits or reads environment variables: messages go to the
 *   log callback of the context, if one is given.
 * - Thread-safety: calls on the same object are not thread-safe unless noted; different
 *   contexts may be used from different threads at once.
 * - Device failures: VKRT_ERROR_OUT_OF_DEVICE_MEMORY leaves the context usable (free something
 *   and retry); VKRT_ERROR_DEVICE_LOST is final: every later call on the context that needs the
 *   device fails with it at once, and the context (and its scenes) can only be destroyed.
 */
#ifndef VKRT_H
#define VKRT_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define VKRT_VERSION_MAJOR 0
#define VKRT_VERSION_MINOR 1
#define VKRT_VERSION_PATCH 0
/* Packed as (major << 22) | (minor << 12) | patch, like VK_MAKE_API_VERSION. */
#define VKRT_VERSION ((VKRT_VERSION_MAJOR << 22) | (VKRT_VERSION_MINOR << 12) | VKRT_VERSION_PATCH)

/* The version the library was built as (compare with VKRT_VERSION of the header). */
uint32_t vkrt_version(void);

/* Result codes. The X-macro keeps the enum and vkrt_result_string() in one list. */
#define VKRT_RESULT_LIST(X)                                                                \
    X(VKRT_OK, "success")                                                                  \
    X(VKRT_ERROR_INVALID_ARGUMENT, "invalid argument")                                     \
    X(VKRT_ERROR_OUT_OF_MEMORY, "out of memory")                                           \
    X(VKRT_ERROR_IO, "file could not be read or written")                                  \
    X(VKRT_ERROR_PARSE, "malformed mesh file")                                             \
    X(VKRT_ERROR_INVALID_GEOMETRY, "invalid geometry (NaN/Inf coordinate, bad index)")     \
    X(VKRT_ERROR_EMPTY_SCENE, "the scene has no triangles")                                \
    X(VKRT_ERROR_UNSUPPORTED, "the file needs a feature vkrt does not support")            \
    X(VKRT_ERROR_NO_DEVICE, "no suitable Vulkan device")                                   \
    X(VKRT_ERROR_VULKAN, "Vulkan call failed")                                             \
    X(VKRT_ERROR_OUT_OF_DEVICE_MEMORY, "out of device memory")                             \
    X(VKRT_ERROR_LIMIT, "the scene exceeds a limit of the device or of vkrt")              \
    X(VKRT_ERROR_CANCELLED, "cancelled by the progress callback")                          \
    X(VKRT_ERROR_DEVICE_LOST, "the Vulkan device was lost (reset, hung or removed)")

typedef enum vkrt_result {
#define VKRT_RESULT_ENUM_(name, message) name,
    VKRT_RESULT_LIST(VKRT_RESULT_ENUM_)
#undef VKRT_RESULT_ENUM_
    VKRT_RESULT_COUNT_
} vkrt_result;

/* "VKRT_ERROR_IO: file could not be read or written"; never NULL. */
const char *vkrt_result_string(vkrt_result result);

typedef enum vkrt_log_level { VKRT_LOG_ERROR, VKRT_LOG_WARN, VKRT_LOG_INFO, VKRT_LOG_DEBUG } vkrt_log_level;
/* Receives one complete message, without a trailing newline. May be called from worker
 * threads of the CPU backend, never from two at once. */
typedef void (*vkrt_log_fn)(void *user, vkrt_log_level level, const char *message);
/* fraction in [0, 1]; return false to cancel (the call then returns VKRT_ERROR_CANCELLED). */
typedef bool (*vkrt_progress_fn)(void *user, const char *stage, float fraction);

/* Memory for every host allocation of a context and the objects made with it. */
typedef struct vkrt_allocator {
    void *(*alloc)(void *user, size_t size); /* NULL (default): malloc; 16-byte aligned */
    void (*free)(void *user, void *pointer); /* NULL (default): free; never given NULL */
    void *user;
} vkrt_allocator;

typedef enum vkrt_backend {
    VKRT_BACKEND_DEFAULT = 0, /* the GPU backend */
    VKRT_BACKEND_GPU,         /* Vulkan compute on the chosen device (lavapipe where no GPU) */
    VKRT_BACKEND_CPU          /* the C reference tracer, multi-threaded over tiles; no Vulkan */
} vkrt_backend;

typedef struct vkrt_context_desc {
    vkrt_backend backend;            /* default: VKRT_BACKEND_GPU */
    vkrt_log_fn log;                 /* NULL (default): the library prints nothing */
    void *log_user;
    vkrt_allocator allocator;        /* all zero (default): malloc/free */
    bool validation;                 /* false (default): no Vulkan validation layer; when true,
                                        the layer must be present, and every message it sends
                                        is logged and counted */
    bool select_device;              /* false (default): the best device (discrete > integrated
                                        > virtual > CPU); true: device_index */
    uint32_t device_index;           /* with select_device: 0-based, in the order of
                                        vkrt_devices_list() */
    uint32_t cpu_threads;            /* 0 (default): one per online core; the CPU backend's
                                        tracing threads, and on both backends the threads that
                                        build a scene's BVH (and pack the GPU's wide BVH) */
    const char *pipeline_cache_path; /* NULL (default): no cache on disk; else read at creation
                                        and written back at destruction (copied) */
    uint64_t device_memory_limit;    /* 0 (default): the device's memory heaps; else the bytes of
                                        device memory the GPU backend may hold at once: an
                                        allocation past it fails with
                                        VKRT_ERROR_OUT_OF_DEVICE_MEMORY, as past a heap. The
                                        context keeps up to 64 MiB of its calls' freed working
                                        memory for the next calls, within this limit too */
} vkrt_context_desc;

typedef struct vkrt_context vkrt_context;

/* Creates a context: for the GPU backend, a Vulkan instance, device and compute queue.
 * Returns VKRT_ERROR_NO_DEVICE where no Vulkan device (or no loader) exists, with the reason
 * sent to the log. Ownership: the caller destroys *out_ctx with vkrt_context_destroy(). */
vkrt_result vkrt_context_create(const vkrt_context_desc *desc, vkrt_context **out_ctx);
void vkrt_context_destroy(vkrt_context *ctx);
/* Detail of the last failure of a call on ctx ("" if none). Valid until the next call. */
const char *vkrt_context_last_error(const vkrt_context *ctx);
/* Validation-layer messages (warnings and errors) received so far; 0 without validation. */
uint32_t vkrt_context_validation_messages(const vkrt_context *ctx);
/* The device the context runs on ("CPU reference" for the CPU backend). */
const char *vkrt_context_device_name(const vkrt_context *ctx);
/* The machine code the CPU backend traces with on this host: "x86-64-v3" (the tracer's AVX2
 * build, where the library has one and the host can run it) or "baseline" (SSE2). Both give
 * the same bits. */
const char *vkrt_cpu_code(void);

typedef enum vkrt_device_type {
    VKRT_DEVICE_OTHER = 0,
    VKRT_DEVICE_INTEGRATED_GPU,
    VKRT_DEVICE_DISCRETE_GPU,
    VKRT_DEVICE_VIRTUAL_GPU,
    VKRT_DEVICE_CPU
} vkrt_device_type;

typedef struct vkrt_device_info {
    char name[256];
    vkrt_device_type type;
    uint32_t vendor_id, device_id;
    uint32_t api_version;          /* VK_MAKE_API_VERSION packing */
    uint64_t max_storage_buffer_range;
    bool usable;                   /* supports Vulkan 1.2 and a compute queue */
} vkrt_device_info;

/* Lists the Vulkan devices. out may be NULL to query the count; otherwise *inout_count is its
 * capacity on input and the number written on output. desc supplies the log and allocator
 * (NULL: defaults). Returns VKRT_ERROR_NO_DEVICE when no Vulkan loader or driver answers. */
vkrt_result vkrt_devices_list(const vkrt_context_desc *desc, vkrt_device_info *out, uint32_t *inout_count);

/* ---- scenes ------------------------------------------------------------------------- */

typedef enum vkrt_bvh_builder {
    VKRT_BVH_BUILDER_DEFAULT = 0, /* binned SAH */
    VKRT_BVH_BUILDER_MIDPOINT,    /* the seed's: centroid midpoint on alternating axes */
    VKRT_BVH_BUILDER_BINNED_SAH,  /* surface area heuristic over 32 bins per axis */
    VKRT_BVH_BUILDER_SPATIAL_SAH  /* binned SAH plus spatial splits (SBVH): a triangle that
                                     crosses a split is referenced by both sides, each bounding
                                     its part; a lower SAH cost for a slower build and up to 1.5x
                                     the triangle references (vkrt_scene_stats.bvh_references) */
} vkrt_bvh_builder;

/* How a texture repeats outside [0, 1] (glTF's sampler wrap modes). */
typedef enum vkrt_wrap {
    VKRT_WRAP_REPEAT = 0, /* default */
    VKRT_WRAP_CLAMP,      /* clamp to the edge texels */
    VKRT_WRAP_MIRROR      /* mirrored repeat */
} vkrt_wrap;

/* An image a material reads: 8-bit RGBA, colour sRGB-encoded as PNG and JPEG store it (a
 * metallic-roughness texture holds linear data instead, as in glTF), alpha linear, rows top to
 * bottom (texture coordinate (0, 0) is the top-left corner, as in glTF); sampled bilinearly at
 * texel centres. */
typedef struct vkrt_texture_desc {
    const uint8_t *rgba8;  /* width * height * 4 bytes (borrowed for the vkrt_scene_create call) */
    uint32_t width, height;/* each 1 .. 16384 */
    vkrt_wrap wrap_u, wrap_v;
} vkrt_texture_desc;

/* How a surface looks, in the glTF 2.0 metallic-roughness model (factors; all linear). The
 * `albedo` mode shows the base colour; lighting modes shade with all of it. */
typedef struct vkrt_material {
    float base_color[4]; /* RGB reflectance and alpha, each in [0, 1] */
    float metallic;      /* [0, 1]: 0 dielectric, 1 metal */
    float roughness;     /* [0, 1]: 0 mirror-smooth, 1 fully rough */
    float emissive[3];   /* emitted radiance, >= 0 */
    const vkrt_texture_desc *base_color_texture; /* NULL (default): none; else its texel at
                                                    the hit's texture coordinates multiplies
                                                    base_color (borrowed for the call) */
    float alpha_cutoff;  /* 0 (default): opaque, alpha ignored by visibility; in (0, 1]: alpha
                            MASK (glTF): where alpha (base_color[3] times the texture's) is
                            below it the surface is not there and rays pass through */
    const vkrt_texture_desc *metallic_roughness_texture; /* NULL (default): none; else, at the
                                                    hit's texture coordinates, its G multiplies
                                                    roughness and its B metallic; linear data,
                                                    not sRGB (borrowed for the call) */
    const vkrt_texture_desc *emissive_texture;   /* NULL (default): none; else its texel (sRGB)
                                                    multiplies emissive (borrowed for the call) */
} vkrt_material;

/* The material of a mesh that names none: grey diffuse (base colour 0.8, alpha 1, metallic
 * 0, roughness 1, no emission), glTF's default with a grey instead of a white base. */
vkrt_material vkrt_material_default(void);

/* One mesh held in memory by the caller (all arrays borrowed for the vkrt_scene_create call). */
typedef struct vkrt_mesh_desc {
    const float *positions;       /* 3 floats per vertex; must be finite */
    uint32_t vertex_count;
    const uint32_t *indices;      /* 3 per triangle, each < vertex_count; NULL: non-indexed, the
                                     vertices taken three at a time */
    uint32_t index_count;         /* a multiple of 3 (ignored when indices is NULL) */
    const float *normals;         /* 3 floats per vertex; NULL (default): computed,
                                     angle-weighted */
    const float *transform;       /* column-major 4x4 placing the mesh in the scene; NULL
                                     (default): identity */
    const float *texcoords;       /* 2 floats per vertex (u, v), finite; NULL (default): (0, 0) */
    const vkrt_material *material;/* NULL (default): vkrt_material_default() */
} vkrt_mesh_desc;

typedef struct vkrt_scene_desc {
    const char *path;             /* .obj, .gltf or .glb (borrowed for the call); NULL
                                     (default): `meshes` when mesh_count > 0, else the built-in
                                     procedural scene */
    const vkrt_mesh_desc *meshes; /* in-memory meshes, used when path is NULL; triangle ids
                                     count through them in order (borrowed for the call) */
    uint32_t mesh_count;
    bool keep_world_coordinates;  /* false (default): centre the bounding box on the origin and
                                     scale its largest extent to 1 */
    vkrt_bvh_builder builder;     /* default: binned SAH */
    uint32_t max_leaf_size;       /* 0 (default): 4; binned SAH splits any larger leaf */
    vkrt_progress_fn progress;    /* NULL (default): none */
    void *progress_user;
} vkrt_scene_desc;

typedef struct vkrt_scene vkrt_scene;

/* Loads a mesh (or makes the built-in scene), builds its BVH and, for the GPU backend,
 * uploads what its traversal reads (the other arrays wait until a call reads them; split
 * across storage buffers where the triangles exceed one: see vkrt_scene_stats.device_bytes and
 * device_buffers). Bad input returns VKRT_ERROR_IO, _PARSE, _INVALID_GEOMETRY,
 * _EMPTY_SCENE or _UNSUPPORTED with a message naming the file and the problem; a device that
 * cannot hold the scene VKRT_ERROR_OUT_OF_DEVICE_MEMORY, or VKRT_ERROR_LIMIT where it cannot
 * split it. The scene belongs to ctx and must be destroyed before it. */
vkrt_result vkrt_scene_create(vkrt_context *ctx, const vkrt_scene_desc *desc, vkrt_scene **out_scene);
void vkrt_scene_destroy(vkrt_scene *scene);

#define VKRT_LEAF_HISTOGRAM_BINS 17 /* leaves holding 1..16 triangles, then 17 or more */

typedef struct vkrt_scene_stats {
    uint64_t triangles;
    uint64_t nodes, leaves;
    uint32_t depth;                /* edges on the longest root-to-leaf path */
    uint32_t max_leaf_triangles;
    uint64_t leaf_histogram[VKRT_LEAF_HISTOGRAM_BINS]; /* [i]: leaves with i + 1 triangles */
    double sah_cost;               /* C_trav = C_isect = 1, relative to the root's area */
    double load_ms, build_ms;      /* wall-clock times of parsing and BVH construction */
    uint64_t node_bytes, triangle_bytes; /* the binary BVH's nodes and the shading triangles
                                            (on the device once a call reads them); the CPU
                                            backend's nodes include its 4-wide BVH */
    float bounds_min[3], bounds_max[3];  /* of the scene as traced */
    uint32_t materials;            /* materials in the table: the file's (or the meshes') that
                                      triangles use, and the default where one names none */
    uint32_t textures;             /* textures read (all kinds) */
    bool has_texcoords;            /* some triangle has texture coordinates */
    bool alpha_tested;             /* some material is alpha-masked: every hit is alpha tested
                                      (a pipeline variant of its own; others pay nothing) */
    uint64_t surface_bytes;        /* texture coordinates and material per triangle, the
                                      material table and the textures: on the device only once a
                                      render needs them (albedo and uv modes) */
    uint64_t host_bytes;           /* what the scene holds in host memory: nodes, triangles,
                                      their BVH order and the surfaces, on either backend */
    uint32_t lights;               /* the file's point and directional lights (glTF
                                      KHR_lights_punctual) */
    uint64_t emissive_triangles;   /* triangles whose material emits: the area lights */
    bool has_metals;               /* some material is metallic (the lighting modes' GGX code) */
    uint64_t device_bytes;         /* GPU backend: the device memory the scene holds now, as
                                      allocated: the 4-wide BVH and its triangles (the piece
                                      table of a split scene); the binary nodes and shading
                                      triangles once a call reads them (normal and depth modes
                                      the triangles; the heat map, traversal counters, naive
                                      traversal and the lighting modes the nodes too, or the
                                      triangles alone where they trace through the wide BVH);
                                      the surfaces once a render has uploaded them. A scene
                                      beyond the wide BVH's limits holds the binary arrays from
                                      the start. 0 on the CPU backend */
    uint32_t device_buffers;       /* GPU backend: storage buffers holding the binary nodes and
                                      the shading triangles: 0 before a call reads them, 1 or 2
                                      after (as above), more where the triangles exceed what one
                                      buffer of the device may hold (maxStorageBufferRange) and
                                      the scene is split across buffers; 0 on the CPU backend */
    uint64_t traversal_bytes;      /* the arrays a ray's traversal reads, what to set against
                                      another tracer's acceleration structure: GPU backend, the
                                      4-wide BVH and its triangles (40 bytes each) on the device
                                      (the binary nodes and triangles where the scene keeps to
                                      them: beyond the wide BVH's limits); CPU backend, its nodes
                                      and triangles */
    uint64_t bvh_references;       /* triangles in the BVH's leaves, counted once per leaf:
                                      `triangles`, plus the copies of spatial splits
                                      (VKRT_BVH_BUILDER_SPATIAL_SAH) */
} vkrt_scene_stats;

vkrt_result vkrt_scene_stats_get(const vkrt_scene *scene, vkrt_scene_stats *out_stats);

/* The triangles as the tracers see them (in the scene's traced coordinates: normalised unless
 * keep_world_coordinates), 9 floats each (corners v0, v1, v2 as x, y, z), in prim_id order:
 * for handing exactly the same geometry to another tracer.
 * out_positions must hold out_floats >= 9 * vkrt_scene_stats.triangles floats (borrowed for
 * the call). */
vkrt_result vkrt_scene_triangles_get(const vkrt_scene *scene, float *out_positions, size_t out_floats);

/* ---- rendering ---------------------------------------------------------------------- */

typedef enum vkrt_mode {
    VKRT_MODE_DEFAULT = 0, /* normal */
    VKRT_MODE_NORMAL,      /* rgb = shading normal * 0.5 + 0.5; a = 1 on a hit, 0 on a miss */
    VKRT_MODE_DEPTH,       /* r = distance to the hit along the unit ray, -1 on a miss */
    VKRT_MODE_HEATMAP,     /* r = boxes entered / leaves entered / triangles tested (vkrt_heat) */
    VKRT_MODE_ID,          /* r = triangle index in the loaded file (exact), -1 on a miss */
    VKRT_MODE_ALBEDO,      /* rgba = the hit material's base colour (linear) and alpha; 0 on a miss */
    VKRT_MODE_UV,          /* rg = texture coordinates interpolated at the hit, b = 0, a = 1 on a
                              hit; 0 on a miss */
    /* The lighting modes: rgb = linear radiance (the mean of the pixel's samples), a = 1 where
     * the primary ray hit a surface, 0 where it sees the sky. Primary rays go through the pixel
     * centre, as in every mode; the samples differ in what happens after the first hit. */
    VKRT_MODE_SHADED,      /* direct light: emission, every point and directional light with a hard
                              shadow (an any-hit shadow ray each), one sample of the emissive
                              triangles per spp, and the sky as unshadowed ambient light */
    VKRT_MODE_AO,          /* ambient occlusion: the fraction of ao_samples cosine-distributed rays
                              per sample that meet nothing within ao_distance, in grey */
    VKRT_MODE_PATH         /* unidirectional path tracing: Lambertian and GGX (metallic) BSDFs,
                              perfect mirrors, next-event estimation with multiple importance
                              sampling, Russian roulette */
} vkrt_mode;

/* A light added by the render (vkrt_render_desc.lights), besides the scene's own (glTF
 * KHR_lights_punctual lights and emissive triangles). */
typedef enum vkrt_light_type {
    VKRT_LIGHT_DIRECTIONAL = 0, /* a light at infinity, like the sun */
    VKRT_LIGHT_POINT            /* a point; its light falls off with the square of the distance */
} vkrt_light_type;

typedef struct vkrt_light {
    vkrt_light_type type;
    float vector[3]; /* directional: the direction the light travels (need not be unit); point: its
                        position, in the scene's traced coordinates */
    float color[3];  /* linear RGB, >= 0. directional: irradiance on a surface facing it; point:
                        radiant intensity (irradiance at distance 1) */
} vkrt_light;

/* Radiance arriving from directions no surface blocks: a gradient from `horizon` (directions at
 * and below the horizon, y <= 0) to `zenith` (straight up, +y), linear in the direction's y; a
 * constant sky has zenith == horizon. All zero: black. */
typedef struct vkrt_sky {
    float zenith[3];
    float horizon[3];
} vkrt_sky;

/* Features of the lighting modes (vkrt_render_stats.features): each is compiled into the GPU
 * pipeline and run on the CPU only when the scene and the render use it. */
#define VKRT_FEATURE_TEXTURES 1u  /* some material has a texture: uv interpolation and sampling */
#define VKRT_FEATURE_PUNCTUAL 2u  /* point or directional lights: a shadow ray to each */
#define VKRT_FEATURE_EMITTERS 4u  /* emissive triangles: emission and area-light sampling */
#define VKRT_FEATURE_SKY 8u       /* a sky that is not black */
#define VKRT_FEATURE_SPECULAR 16u /* some material is metallic: the GGX and mirror code */
#define VKRT_FEATURE_RANDOM 32u   /* random numbers (every lighting render but `shaded` with only
                                     point and directional lights, which is exact in one sample) */
#define VKRT_FEATURE_ADAPTIVE 64u /* adaptive sampling (vkrt_render_desc.target_error) */
#define VKRT_FEATURE_ALL 127u

/* "textures", "punctual lights", ...; "" for anything but one VKRT_FEATURE_* bit. */
const char *vkrt_feature_name(uint32_t feature);

typedef enum vkrt_traversal {
    VKRT_TRAVERSAL_DEFAULT = 0, /* BVH */
    VKRT_TRAVERSAL_BVH,         /* iterative, explicit stack, nearer child first */
    VKRT_TRAVERSAL_NAIVE        /* every triangle; must give the identical image */
} vkrt_traversal;

typedef enum vkrt_heat {
    VKRT_HEAT_DEFAULT = 0, /* nodes */
    VKRT_HEAT_NODES,       /* BVH boxes the ray enters */
    VKRT_HEAT_LEAVES,      /* leaf boxes the ray enters (the seed's figures) */
    VKRT_HEAT_TRIS         /* triangles tested */
} vkrt_heat;

typedef enum vkrt_intersector {
    VKRT_INTERSECTOR_DEFAULT = 0,    /* watertight */
    VKRT_INTERSECTOR_WATERTIGHT,     /* Woop, Benthin and Wald 2013: no ray slips between two
                                        triangles that share an edge or a vertex */
    VKRT_INTERSECTOR_MOLLER_TRUMBORE /* the seed's; kept so the difference can be measured */
} vkrt_intersector;

typedef enum vkrt_precision {
    VKRT_PRECISION_DEFAULT = 0, /* float */
    VKRT_PRECISION_FLOAT,
    VKRT_PRECISION_DOUBLE       /* CPU backend only: rays, boxes and triangle tests in double,
                                   from the same scene: the reference for every error figure */
} vkrt_precision;

typedef struct vkrt_camera {
    float eye[3];          /* eye == target (e.g. all zero, the default): eye (0, 0, 1.5) and
                              target (0, 0, 0), framing the normalised scene */
    float target[3];
    float up[3];           /* all zero (default): (0, 1, 0) */
    float fov_y_degrees;   /* 0 (default): 45; vertical field of view, in (0, 180) */
} vkrt_camera;

typedef struct vkrt_render_desc {
    uint32_t width, height;   /* 0 (default): 1024; one ray through each pixel centre, row 0
                                 at the top */
    vkrt_camera camera;
    vkrt_mode mode;           /* default: normal */
    vkrt_traversal traversal; /* default: BVH */
    vkrt_heat heat;           /* heatmap mode only; default: nodes */
    vkrt_intersector intersector; /* default: watertight */
    vkrt_precision precision; /* default: float; double needs the CPU backend */
    bool traversal_counters;  /* false (default): none; true: fill the traversal counters of
                                 vkrt_render_stats (the GPU then traces with a pipeline variant
                                 that writes them out, a little slower; primary modes only) */
    /* The lighting modes (shaded, ao, path); other modes ignore these fields. When no light of
     * any kind reaches the render (no lights here or in the scene, no emissive triangle, a
     * black sky), a default rig is used: a directional key light from above the camera's
     * right shoulder and a dim blue-grey sky. */
    const vkrt_light *lights; /* borrowed for the call; NULL with light_count 0 (default): none */
    uint32_t light_count;
    vkrt_sky sky;             /* all zero (default): black */
    uint32_t spp;             /* samples per pixel, 0 (default): 1 for shaded and ao, 16 for path;
                                 at most 65536 */
    uint32_t ao_samples;      /* ao: rays per hit per sample, 0 (default): 4; at most 256 */
    float ao_distance;        /* ao: occluders farther than this do not count; 0 (default): 0.5 */
    uint32_t max_bounces;     /* path: bounces after the primary hit, 0 (default): 8; at most 64 */
    uint32_t seed;            /* the sampler's scramble seed; the same seed, scene and settings give
                                 the same image on a backend */
    float target_error;       /* adaptive sampling: 0 (default): off, every pixel takes spp
                                 samples; > 0: a pixel stops once the estimated relative standard
                                 error of its mean luminance is at most this (after at least 8
                                 samples), or at spp; a pixel that sees the sky stops after one */
    bool all_features;        /* false (default): the pipeline is specialised to the features the
                                 scene uses; true: every feature compiled in (for testing that a
                                 specialisation changes nothing) */
    uint32_t extra_features;  /* 0 (default); else VKRT_FEATURE_* bits compiled in (and run on the
                                 CPU) although the scene does not need them: one skip at a time,
                                 for measuring what it saves (vkrt bench --modes) */
    float *out_error;         /* NULL (default), or width * height floats (borrowed): each pixel's
                                 estimated standard error of its mean luminance (lighting modes) */
    vkrt_progress_fn progress;/* NULL (default): none; GPU: called between every two device
                                 submissions (each sized to about 100 ms); CPU: between tiles */
    void *progress_user;
} vkrt_render_desc;

typedef struct vkrt_render_stats {
    double trace_ms;   /* GPU: device time of the trace dispatches (timestamp queries), with
                          the host's listing where the binned traversal took the camera rays
                          (rays_binned); CPU: wall-clock time of the tracing threads */
    double total_ms;   /* wall-clock time of the whole call, upload and readback included */
    uint64_t rays;
    /* With vkrt_render_desc.traversal_counters (else 0), summed over every ray: BVH boxes
     * entered (the root's included), how many of those were leaves, and ray-triangle tests
     * (naive traversal: 0, 0 and triangles x rays). Divide by rays for per-ray figures; the
     * heatmap modes show the same counts per pixel. */
    uint64_t nodes_visited;
    uint64_t leaves_visited;
    uint64_t tris_tested;
    /* Lighting modes: */
    uint32_t features;        /* VKRT_FEATURE_* bits the render used (compiled in on the GPU) */
    uint32_t lights;          /* entries of the light table: punctual lights, then emitters */
    uint64_t samples;         /* samples taken over all pixels (below width * height * spp with
                                 adaptive sampling) */
    uint64_t shadow_rays;     /* shadow and AO rays traced (any-hit) */
    uint64_t bounce_rays;     /* extension rays traced after the primary ones (closest-hit) */
    bool naive_by_cost;       /* the default traversal chose naive: the scene's SAH cost (C_trav =
                                 C_isect = 1) was not below its triangle count */
    uint32_t submissions;     /* GPU: device submissions the render took; each is sized to take
                                 about 100 ms (progress and cancellation come between them) */
    double longest_submission_ms; /* GPU: wall-clock time of the longest of them, from submission to
                                 its fence (the first use of a pipeline includes its compilation
                                 on drivers that compile at first dispatch, such as lavapipe) */
    uint64_t rays_binned;     /* GPU backend on a CPU device, the modes that shade closest hits
                                 (not the heat map, not with traversal_counters): camera rays
                                 traced through triangle lists built on the host instead of the
                                 BVH (README, "Binned traversal"), the same image; 0 elsewhere */
    uint64_t binned_tests;    /* with rays_binned: the entries of those rays' lists summed, a
                                 ray-triangle test each (the binned traversal tests no box) */
} vkrt_render_stats;

/* Floats vkrt_render() writes for an image of width x height: 4 per pixel (RGBA), rows top
 * to bottom. 0 when the product overflows size_t. */
size_t vkrt_render_floats(uint32_t width, uint32_t height);

/* Traces one primary ray per pixel and writes raw values (see vkrt_mode) into out_rgba.
 * out_rgba must hold out_floats >= vkrt_render_floats(width, height) floats (borrowed for the
 * call). stats may be NULL. Returns VKRT_ERROR_CANCELLED when the progress callback says so
 * (out_rgba is then incomplete), VKRT_ERROR_OUT_OF_DEVICE_MEMORY or VKRT_ERROR_DEVICE_LOST (see
 * the conventions above). */
vkrt_result vkrt_render(vkrt_context *ctx, vkrt_scene *scene, const vkrt_render_desc *desc,
                        float *out_rgba, size_t out_floats, vkrt_render_stats *out_stats);

/* ---- arbitrary rays ------------------------------------------------------------------ */

/* A ray, 32 bytes (the layout of vkrt_gpu_ray in shaders/vkrt_shared.h). Hits are accepted
 * for tmin < t < tmax; tmax = 0 (the zero default) means +infinity. dir need not be unit:
 * t is in units of |dir|. */
typedef struct vkrt_ray {
    float origin[3];
    float tmin;
    float dir[3];
    float tmax;
} vkrt_ray;

/* The closest hit of one ray. A miss has t = -1 and prim_id = VKRT_NO_HIT. */
#define VKRT_NO_HIT UINT32_MAX
typedef struct vkrt_hit {
    float t;
    uint32_t prim_id;         /* triangle index in the loaded scene */
    float u, v;               /* barycentrics of v1 and v2 */
} vkrt_hit;

/* What one vkrt_trace_rays() call did (vkrt_trace_desc.out_stats). */
typedef struct vkrt_trace_stats {
    double trace_ms;          /* GPU: device time of the trace dispatches (timestamp queries; 0
                                 where the device has none); CPU: wall-clock time of the tracing
                                 threads */
    double total_ms;          /* wall-clock time of the whole call: on the GPU with the rays'
                                 upload, the hits' readback and the waits for the device */
    uint64_t rays;            /* the call's rays */
    uint64_t rays_culled;     /* GPU backend on a CPU device (lavapipe), BVH traversal: rays that
                                 cannot enter the scene's box, answered on the host as misses
                                 without reaching the device (with rays_binned, those whose
                                 triangle list is empty); 0 elsewhere */
    uint64_t rays_binned;     /* GPU backend on a CPU device, closest hits: rays that share one
                                 origin, traced through triangle lists built on the host instead
                                 of the BVH (README, "Binned traversal"), with the same hits: those
                                 whose list is not empty, the rest culled; 0 elsewhere */
    uint64_t binned_tests;    /* with rays_binned: the entries of those rays' lists summed, a
                                 ray-triangle test each (the binned traversal tests no box) */
    uint32_t submissions;     /* GPU: device submissions the call took */
} vkrt_trace_stats;

typedef struct vkrt_trace_desc {
    vkrt_traversal traversal;     /* default: BVH */
    bool any_hit;                 /* false (default): the closest hit; true: occlusion queries, the
                                     first hit found in (tmin, tmax), not necessarily the closest
                                     (its t, prim_id, u, v are those of that hit); fewer nodes are
                                     visited */
    vkrt_intersector intersector; /* default: watertight */
    vkrt_precision precision;     /* default: float; double needs the CPU backend */
    vkrt_progress_fn progress;    /* NULL (default): none; called between submissions (GPU) or
                                     blocks of rays (CPU) */
    void *progress_user;
    vkrt_trace_stats *out_stats;  /* NULL (default): none; else written when the call returns
                                     VKRT_OK */
} vkrt_trace_desc;

/* The primary rays vkrt_render() traces for an image of width x height seen by camera (NULL:
 * the default view), one per pixel centre, rows top to bottom, bit for bit the rays of every
 * backend's float trace (tmin = tmax = 0; dir not unit): for tracing them with vkrt_trace_rays()
 * or handing them to another tracer. width and height must be 1 .. 65536; out_rays must hold
 * out_count >= width * height rays (borrowed for the call). A bad camera fails as in
 * vkrt_render(). */
vkrt_result vkrt_camera_rays(vkrt_context *ctx, const vkrt_camera *camera, uint32_t width, uint32_t height,
                             vkrt_ray *out_rays, size_t out_count);

/* The origin of a secondary ray leaving the surface point p on the side of normal n, as the
 * lighting modes offset theirs (Waechter and Binder 2019: a fixed number of ulps along n, so
 * the ray cannot hit the surface it leaves yet starts as near it as float allows). n must be
 * the unit geometric normal turned to the side the ray leaves from. */
void vkrt_ray_offset(const float p[3], const float n[3], float out_origin[3]);

/* Traces `count` rays (borrowed for the call) and writes their closest hits to out_hits
 * (count entries). Closest-hit ties break towards the lower prim_id, so every traversal and
 * backend agrees. Rays with a non-finite origin or direction, or a zero direction, miss. */
vkrt_result vkrt_trace_rays(vkrt_context *ctx, vkrt_scene *scene, const vkrt_trace_desc *desc,
                            const vkrt_ray *rays, size_t count, vkrt_hit *out_hits);

/* ---- images ------------------------------------------------------------------------- */

typedef struct vkrt_image_view {
    const float *rgba;       /* as written by vkrt_render() (borrowed for the call) */
    uint32_t width, height;
    vkrt_mode mode;          /* how raw values become colours in 8-bit formats */
    float heat_max;          /* heatmap: the count drawn at the top of the ramp; 0 (default):
                                the image's maximum */
} vkrt_image_view;

/* Writes an image, the format chosen by the extension: .png (8-bit colour: normals as RGB,
 * depth as grey, ids as distinct colours, heat on a colour ramp, albedo and the lighting modes'
 * linear radiance clamped to [0, 1] and sRGB-encoded), .pfm (the raw 32-bit floats,
 * RGB, for exact comparisons), .hdr (Radiance RGBE: the raw RGB values with an 8-bit shared
 * mantissa, negatives such as a miss's -1 stored as 0) or .ppm (8-bit, like .png). Any other
 * extension returns VKRT_ERROR_INVALID_ARGUMENT. The file is written to a temporary
 * name beside the target and renamed, so a failure never leaves a half-written file. */
vkrt_result vkrt_image_save(vkrt_context *ctx, const char *path, const vkrt_image_view *image);

#ifdef __cplusplus
}
#endif

#endif /* VKRT_H */
