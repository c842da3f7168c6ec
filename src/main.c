/* vkrt command-line program: a thin layer over vkrt.h. */
#include <errno.h>
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <time.h>
#include <unistd.h>

#include "bench.h"
#include "bench_modes.h"
#ifdef VKRT_HAVE_EMBREE
#include "bench_compare.h"
#endif
#include "camera.h"
#include "stress.h"
#include "vkrt.h"

/* Exit codes (documented in README and --help). */
enum {
    EXIT_OK = 0,
    EXIT_INTERNAL = 1,
    EXIT_USAGE = 2,
    EXIT_INPUT = 3,
    EXIT_DEVICE = 4,
    EXIT_VALIDATION = 5,
};

static int verbosity = 1; /* 0 quiet, 1 normal, 2 verbose */
/* The last error the library logged: the only detail left when creating a context fails. */
static char last_logged_error[1024];

static void on_log(void *user, vkrt_log_level level, const char *message)
{
    (void)user;
    /* Errors are printed once by the command from vkrt_context_last_error(). */
    if (level == VKRT_LOG_ERROR) {
        snprintf(last_logged_error, sizeof last_logged_error, "%s", message);
        if (strncmp(message, "Vulkan validation", 17) == 0) fprintf(stderr, "vkrt: %s\n", message);
        return;
    }
    if (level == VKRT_LOG_WARN && verbosity >= 1) fprintf(stderr, "vkrt: warning: %s\n", message);
    else if (level >= VKRT_LOG_INFO && verbosity >= 2) fprintf(stderr, "vkrt: %s\n", message);
}

static int exit_code_for(vkrt_result r)
{
    switch (r) {
    case VKRT_OK: return EXIT_OK;
    case VKRT_ERROR_INVALID_ARGUMENT: return EXIT_USAGE;
    case VKRT_ERROR_IO:
    case VKRT_ERROR_PARSE:
    case VKRT_ERROR_INVALID_GEOMETRY:
    case VKRT_ERROR_EMPTY_SCENE:
    case VKRT_ERROR_UNSUPPORTED: return EXIT_INPUT;
    case VKRT_ERROR_NO_DEVICE:
    case VKRT_ERROR_VULKAN:
    case VKRT_ERROR_OUT_OF_DEVICE_MEMORY:
    case VKRT_ERROR_DEVICE_LOST:
    case VKRT_ERROR_LIMIT: return EXIT_DEVICE;
    default: return EXIT_INTERNAL;
    }
}

static int fail(vkrt_context *ctx, vkrt_result r, const char *what)
{
    const char *detail = ctx ? vkrt_context_last_error(ctx) : last_logged_error;
    if (!detail || !detail[0]) detail = vkrt_result_string(r);
    if (what) fprintf(stderr, "vkrt: error: %s: %s\n", what, detail);
    else fprintf(stderr, "vkrt: error: %s\n", detail); /* the detail already names the file */
    return exit_code_for(r);
}

static const char usage_text[] =
    "usage: vkrt <command> [options]     (`vkrt <command> --help`: its options and examples)\n"
    "\n"
    "commands:\n"
    "  render [FILE]   trace FILE (.obj, .gltf, .glb; the built-in scene when none) to an image\n"
    "  info FILE       load FILE, build its BVH and print statistics\n"
    "  devices         list the Vulkan devices\n"
    "  bench [FILE]    time every configuration (backend, builder, traversal, intersector,\n"
    "                  precision) and measure its error against the double-precision reference\n"
    "  stress          numerical-stability suite: both backends and intersectors against the CPU\n"
    "                  double-precision reference, as a table; exit 1 when a watertight row fails\n"
    "\n"
    "examples:\n"
    "  vkrt render bunny.obj -o bunny.png --size 512x512\n"
    "  vkrt info dragon.glb\n"
    "  vkrt render --help\n"
    "\n";

static const char render_help[] =
    "usage: vkrt render [FILE] [options]\n"
    "Traces one ray per pixel through FILE (.obj, .gltf, .glb; the built-in scene when none) and\n"
    "writes the image. A progress bar with ETA appears on stderr for work over a second when\n"
    "stderr is a terminal (not in pipes, not with CI set, not with -q).\n"
    "\n"
    "options (defaults first):\n"
    "  -o, --output OUT          render.png; .png, .ppm (8-bit colour), .pfm (raw floats) or\n"
    "                            .hdr (raw values, Radiance RGBE)\n"
    "  --mode normal|depth|heatmap|id|albedo|uv|shaded|ao|path\n"
    "                            albedo: the material's base colour; uv: texture coordinates;\n"
    "                            shaded: direct light with hard shadows; ao: ambient occlusion;\n"
    "                            path: path tracing (the lighting modes write linear radiance)\n"
    "  --light dir:X,Y,Z:R,G,B   a directional light travelling along X,Y,Z with irradiance R,G,B\n"
    "  --light point:X,Y,Z:R,G,B a point light at X,Y,Z with intensity R,G,B (repeatable, up to 64;\n"
    "                            with no light, emitter or sky at all: a default key light and sky)\n"
    "  --sky R,G,B[:R,G,B]       sky radiance: constant, or zenith:horizon gradient (black)\n"
    "  --spp N                   samples per pixel (1 for shaded and ao, 16 for path)\n"
    "  --target-error E          adaptive: a pixel stops once its relative standard error is at\n"
    "                            most E (after 8 samples), or at --spp\n"
    "  --ao-samples N            ao: rays per hit per sample (4)\n"
    "  --ao-distance D           ao: occluders beyond D do not count (0.5)\n"
    "  --bounces N               path: bounces after the primary hit (8)\n"
    "  --seed N                  sampler seed (0); the same seed gives the same image\n"
    "  --heat nodes|leaves|tris  what heatmap counts per ray\n"
    "  --heat-max N              count at the top of the heat ramp (default: the image maximum)\n"
    "  --backend gpu|cpu         Vulkan compute, or the C reference tracer\n"
    "  --bvh sah|sbvh|midpoint   BVH builder (sbvh: with spatial splits)\n"
    "  --max-leaf N              largest SAH leaf (4)\n"
    "  --traverse bvh|naive      naive tests every triangle (identical image, slow)\n"
    "  --isect watertight|mt     triangle test: watertight (Woop et al. 2013) or Moller-Trumbore\n"
    "  --precision float|double  double: rays, boxes and triangle tests in double (--backend cpu)\n"
    "  --eye X,Y,Z               0,0,1.5\n"
    "  --target X,Y,Z            0,0,0\n"
    "  --up X,Y,Z                0,1,0\n"
    "  --fov DEG                 45 (vertical)\n"
    "  --size WxH                1024x1024\n"
    "  --no-normalize            keep world coordinates (default: scene scaled into [-0.5,0.5]^3)\n"
    "  --device N                Vulkan device N as listed by `vkrt devices` (default: the best)\n"
    "  --threads N               CPU backend and BVH build threads (default: one per core)\n"
    "  --device-memory MIB       the most device memory the GPU backend may hold, in MiB\n"
    "                            (default: the device's heaps)\n"
    "  --validation              enable the Vulkan validation layer; any message fails the run\n"
    "  --repeat N                render once to warm up (shader compilation), then N times, and\n"
    "                            report the median times\n"
    "  -v, --verbose             also report what the lighting modes compiled out, and why\n"
    "  --counters                also report BVH boxes entered, leaves entered and triangle tests\n"
    "                            per ray (the GPU counts in a pipeline variant of its own)\n"
    "  -q, --quiet / -v, --verbose\n"
    "\n"
    "examples:\n"
    "  vkrt render                                   built-in scene -> render.png\n"
    "  vkrt render bunny.obj -o bunny.png --size 512x512\n"
    "  vkrt render dragon.glb --mode heatmap --heat leaves --bvh midpoint -o heat.png\n"
    "  vkrt render bunny.obj --mode id -o ids.pfm --backend cpu\n"
    "  vkrt render bunny.obj --mode depth -o depth.hdr --eye 0.5,0.3,1.2 --fov 30\n"
    "  vkrt render dragon.glb --repeat 5 --validation -o /tmp/dragon.png   median timings\n"
    "  vkrt render dragon.glb --counters --bvh midpoint -o /tmp/d.png     traversal work per ray\n"
    "\n";

static const char info_help[] =
    "usage: vkrt info FILE [--bvh sah|sbvh|midpoint] [--max-leaf N] [--no-normalize] [--backend gpu]\n"
    "Loads FILE, builds its BVH on the CPU (no Vulkan device needed) and prints triangles, nodes,\n"
    "leaves, depth, SAH cost, load and build times, bytes, host and device memory per triangle,\n"
    "bounds and the leaf-size histogram.\n"
    "\n"
    "options:\n"
    "  --backend gpu             also upload the scene to the device and print the device memory\n"
    "                            it takes and its storage buffers (more than 2: split)\n"
    "  --bvh sah|sbvh|midpoint   BVH builder (sah; sbvh: with spatial splits)\n"
    "  --max-leaf N              largest SAH leaf (4)\n"
    "  --no-normalize            keep world coordinates (bounds as in the file)\n"
    "\n"
    "examples:\n"
    "  vkrt info bunny.obj\n"
    "  vkrt info dragon.glb --bvh midpoint           compare the SAH cost with the default\n"
    "  vkrt info dragon.glb --max-leaf 1 | grep depth\n"
    "  vkrt info dragon.glb --backend gpu           device bytes per triangle, measured\n"
    "\n";

static const char devices_help[] =
    "usage: vkrt devices\n"
    "Lists the Vulkan devices, numbered for `vkrt render --device N`, with type, Vulkan version\n"
    "and largest storage buffer; [unusable] marks a device without Vulkan 1.2 or compute.\n"
    "\n"
    "examples:\n"
    "  vkrt devices\n"
    "  vkrt render --device 1 -o render.png           render on the second device listed\n"
    "  VK_ICD_FILENAMES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json vkrt devices   lavapipe only\n"
    "\n";

static const char stress_help[] =
    "usage: vkrt stress [--quick] [--backend gpu|cpu] [--isect watertight|mt] [options]\n"
    "Builds meshes in memory (closed meshes with rays at shared edges and vertices, scales 1e-6 to\n"
    "1e6 and offsets to 1e6, degenerate geometry with every builder, +-0 directions, origins on\n"
    "surfaces, grazing rays, eyes inside), traces them on each backend with each intersector and\n"
    "compares every ray with the CPU double-precision reference. Prints a table: case, builder,\n"
    "backend, intersector, rays, leaks, mismatches, limit, max relative depth error, BVH depth.\n"
    "Exit 1 when a watertight row has a leak or more mismatches than its limit (mt rows are\n"
    "reported only).\n"
    "\n"
    "options:\n"
    "  --quick                   the reduced run of the test suite (seconds, not minutes)\n"
    "  --backend gpu|cpu         only that backend's rows (default: both)\n"
    "  --isect watertight|mt     only that intersector's rows (default: both)\n"
    "  --device N, --device-memory MIB, --threads N, --validation, -q, -v   as for render\n"
    "\n"
    "examples:\n"
    "  vkrt stress                                   every case (under a minute on lavapipe)\n"
    "  vkrt stress --quick --backend gpu             the reduced run, GPU rows only\n"
    "  vkrt stress --isect watertight | grep FAIL    the watertight rows that fail\n"
    "\n";

static const char bench_help[] =
    "usage: vkrt bench [FILE] [--quick] [--csv OUT.csv] [--size WxH] [--repeat N]\n"
    "                  [--compare embree | --modes [--ref-spp N] [--cache DIR]] [options]\n"
    "Renders one view of FILE (the built-in scene when none) with every configuration: backend\n"
    "(gpu, cpu), BVH builder (sah, midpoint, sbvh), traversal (bvh; naive where it costs at most 1e8\n"
    "ray-triangle tests), intersector (watertight, mt) and, on the CPU, precision (float, double).\n"
    "Each row: build time, SAH cost, bytes per triangle, trace time (median after a warm-up; GPU:\n"
    "device time from timestamp queries), total time of the call, Mrays/s, boxes, leaves and\n"
    "triangle tests per ray, and the error against the CPU double-precision reference: pixels\n"
    "that hit another surface (or miss), relative depth RMSE and maximum. Prints a markdown table.\n"
    "\n"
    "options (defaults first):\n"
    "  --quick                   64x64 and one timed render (the test suite's run)\n"
    "  --csv OUT.csv             also write the rows as CSV (atomically)\n"
    "  --size WxH                512x512\n"
    "  --repeat N                5 timed renders after the warm-up (--compare: also N\n"
    "                            builds of each engine's scene, in turn; their median)\n"
    "  --backend gpu|cpu         only that backend (default: both)\n"
    "  --compare embree          instead: the same primary and AO rays on the same triangles\n"
    "                            through vkrt_trace_rays (both backends) and Embree 3\n"
    "                            (rtcIntersect1, rtcOccluded1, as many threads as the CPU\n"
    "                            backend): Mrays/s, the vkrt/Embree ratio, hit checksums and\n"
    "                            mismatches (needs a build with libembree-dev)\n"
    "  --modes                   instead: shaded, ao and path at 1, 4, 16, 64 spp (quick: 1, 4),\n"
    "                            adaptive (target errors 0.1, 0.05) and with every feature\n"
    "                            compiled in, on both backends, at 128x128 (quick: 64x64), 3\n"
    "                            timed renders: time, samples taken, and RMSE, relMSE, PSNR\n"
    "                            against a converged CPU reference\n"
    "  --procedural N            instead of FILE: a rippled torus of about N triangles (the\n"
    "                            scaling series; exactly 2*R*C, R x C quads, C = 3R)\n"
    "  --max-spp N               --modes: the spp ladder 1, 4, 16, ... up to N (64; quick: 4)\n"
    "  --ref-spp N               the references' samples per pixel (1024; quick: 256)\n"
    "  --cache DIR               where references are kept between runs, keyed by scene and\n"
    "                            settings (~/.cache/vkrt/bench; empty: nowhere)\n"
    "  --bvh sah|sbvh|midpoint   --compare and --modes: the scene's BVH builder (sah)\n"
    "  --eye, --target, --up, --fov, --no-normalize, --device N, --device-memory MIB,\n"
    "  --threads N, --validation, -q   as for render\n"
    "\n"
    "examples:\n"
    "  vkrt bench                                    the built-in scene, every configuration\n"
    "  vkrt bench bunny.obj --compare embree         vkrt against Embree on the bunny\n"
    "  vkrt bench bunny.obj --compare embree --bvh sbvh   the same through spatial splits\n"
    "  vkrt bench --modes --csv modes.csv            the lighting modes' time against error\n"
    "  vkrt bench --procedural 1000000               a million procedural triangles\n"
    "  vkrt bench dragon.glb --csv dragon.csv        and the rows as CSV\n"
    "  vkrt bench bunny.obj --backend gpu --size 1024x1024 --repeat 9\n"
    "\n";

static const char help_footer[] =
    "exit codes: 0 success, 1 internal error, 2 usage, 3 bad input file, 4 device (Vulkan) error,\n"
    "            5 validation-layer messages (with --validation)\n"
    "environment: VKRT_PIPELINE_CACHE (pipeline cache file; default ~/.cache/vkrt/pipelines.bin),\n"
    "             VKRT_VALIDATION=1 (same as --validation)\n";

/* The help of `vkrt COMMAND --help`; the overview for no or an unknown command. */
static void print_help(FILE *f, const char *command)
{
    const char *text = usage_text;
    if (command && !strcmp(command, "render")) text = render_help;
    else if (command && !strcmp(command, "info")) text = info_help;
    else if (command && !strcmp(command, "devices")) text = devices_help;
    else if (command && !strcmp(command, "stress")) text = stress_help;
    else if (command && !strcmp(command, "bench")) text = bench_help;
    fputs(text, f);
    fputs(help_footer, f);
}

#define MAX_CLI_LIGHTS 64

typedef struct options {
    const char *command;
    vkrt_light lights[MAX_CLI_LIGHTS];
    const char *input;
    const char *output;
    vkrt_context_desc context;
    vkrt_scene_desc scene;
    vkrt_render_desc render;
    float heat_max;
    uint32_t repeat; /* timed renders after one warm-up; 0: a single render */
    bool quick;      /* stress, bench: the reduced run */
    const char *csv; /* bench: CSV output */
    bool compare_embree; /* bench: vkrt against Embree on the same rays */
    bool modes;          /* bench: the lighting modes against converged references */
    uint32_t reference_spp; /* bench --modes: the references' spp; 0: the default */
    uint32_t max_spp;       /* bench --modes: the top of the spp ladder; 0: the default */
    const char *cache_dir;  /* bench --modes: --cache; NULL: the default place */
    uint32_t procedural;    /* bench: --procedural N */
} options;

static bool parse_vec3(const char *s, float v[3])
{
    char *end;
    for (int i = 0; i < 3; i++) {
        errno = 0;
        double x = strtod(s, &end);
        if (end == s || errno || !isfinite(x)) return false;
        v[i] = (float)x;
        if (i < 2) {
            if (*end != ',') return false;
            s = end + 1;
        }
    }
    return *end == '\0';
}

static bool parse_u32(const char *s, uint32_t *out)
{
    char *end;
    errno = 0;
    unsigned long v = strtoul(s, &end, 10);
    if (end == s || *end || errno || v > UINT32_MAX || s[0] == '-') return false;
    *out = (uint32_t)v;
    return true;
}

static bool parse_float(const char *s, float *out)
{
    char *end;
    errno = 0;
    double v = strtod(s, &end);
    if (end == s || *end || errno || !isfinite(v)) return false;
    *out = (float)v;
    return true;
}

static bool parse_size(const char *s, uint32_t *w, uint32_t *h)
{
    char buf[64];
    const char *x = strchr(s, 'x');
    if (!x || (size_t)(x - s) >= sizeof buf) return false;
    memcpy(buf, s, (size_t)(x - s));
    buf[x - s] = '\0';
    return parse_u32(buf, w) && parse_u32(x + 1, h) && *w > 0 && *h > 0;
}

/* "dir:X,Y,Z:R,G,B" or "point:X,Y,Z:R,G,B". */
static bool parse_light(const char *s, vkrt_light *out)
{
    const char *rest;
    if (!strncmp(s, "dir:", 4)) out->type = VKRT_LIGHT_DIRECTIONAL, rest = s + 4;
    else if (!strncmp(s, "point:", 6)) out->type = VKRT_LIGHT_POINT, rest = s + 6;
    else return false;
    const char *colon = strchr(rest, ':');
    char vec[128];
    if (!colon || (size_t)(colon - rest) >= sizeof vec) return false;
    memcpy(vec, rest, (size_t)(colon - rest));
    vec[colon - rest] = '\0';
    return parse_vec3(vec, out->vector) && parse_vec3(colon + 1, out->color) && out->color[0] >= 0 &&
           out->color[1] >= 0 && out->color[2] >= 0;
}

/* "R,G,B" (constant) or "R,G,B:R,G,B" (zenith:horizon). */
static bool parse_sky(const char *s, vkrt_sky *out)
{
    const char *colon = strchr(s, ':');
    char first[128];
    size_t n = colon ? (size_t)(colon - s) : strlen(s);
    if (n >= sizeof first) return false;
    memcpy(first, s, n);
    first[n] = '\0';
    if (!parse_vec3(first, out->zenith)) return false;
    if (colon) {
        if (!parse_vec3(colon + 1, out->horizon)) return false;
    } else {
        memcpy(out->horizon, out->zenith, sizeof out->horizon);
    }
    for (int k = 0; k < 3; k++)
        if (out->zenith[k] < 0 || out->horizon[k] < 0) return false;
    return true;
}

static int usage_error(const char *fmt, const char *arg)
{
    fprintf(stderr, "vkrt: ");
    fprintf(stderr, fmt, arg);
    fprintf(stderr, "\n(run `vkrt --help` for usage)\n");
    return EXIT_USAGE;
}

#define NEED_VALUE()                                                                   \
    do {                                                                               \
        if (i + 1 >= argc) return usage_error("option %s needs a value", arg);         \
        value = argv[++i];                                                             \
    } while (0)

static int parse_args(int argc, char **argv, options *o)
{
    bool eye_given = false, target_given = false;
    for (int i = 2; i < argc; i++) {
        const char *arg = argv[i], *value = NULL;
        if (!strcmp(arg, "-o") || !strcmp(arg, "--output")) {
            NEED_VALUE();
            o->output = value;
        } else if (!strcmp(arg, "--mode")) {
            NEED_VALUE();
            if (!strcmp(value, "normal")) o->render.mode = VKRT_MODE_NORMAL;
            else if (!strcmp(value, "depth")) o->render.mode = VKRT_MODE_DEPTH;
            else if (!strcmp(value, "heatmap")) o->render.mode = VKRT_MODE_HEATMAP;
            else if (!strcmp(value, "id")) o->render.mode = VKRT_MODE_ID;
            else if (!strcmp(value, "albedo")) o->render.mode = VKRT_MODE_ALBEDO;
            else if (!strcmp(value, "uv")) o->render.mode = VKRT_MODE_UV;
            else if (!strcmp(value, "shaded")) o->render.mode = VKRT_MODE_SHADED;
            else if (!strcmp(value, "ao")) o->render.mode = VKRT_MODE_AO;
            else if (!strcmp(value, "path")) o->render.mode = VKRT_MODE_PATH;
            else return usage_error("unknown mode '%s' (normal, depth, heatmap, id, albedo, uv, shaded, ao, path)", value);
        } else if (!strcmp(arg, "--light")) {
            NEED_VALUE();
            if (o->render.light_count == MAX_CLI_LIGHTS) return usage_error("more than %s lights", "64");
            if (!parse_light(value, &o->lights[o->render.light_count]))
                return usage_error("bad --light '%s' (want dir:X,Y,Z:R,G,B or point:X,Y,Z:R,G,B, colours >= 0)", value);
            o->render.light_count++;
            o->render.lights = o->lights;
        } else if (!strcmp(arg, "--sky")) {
            NEED_VALUE();
            if (!parse_sky(value, &o->render.sky)) return usage_error("bad --sky '%s' (want R,G,B or R,G,B:R,G,B, >= 0)", value);
        } else if (!strcmp(arg, "--spp")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->render.spp) || !o->render.spp || o->render.spp > 65536)
                return usage_error("bad --spp '%s' (1 to 65536)", value);
        } else if (!strcmp(arg, "--target-error")) {
            NEED_VALUE();
            if (!parse_float(value, &o->render.target_error) || !(o->render.target_error > 0))
                return usage_error("bad --target-error '%s' (a relative error > 0, e.g. 0.05)", value);
        } else if (!strcmp(arg, "--ao-samples")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->render.ao_samples) || !o->render.ao_samples || o->render.ao_samples > 256)
                return usage_error("bad --ao-samples '%s' (1 to 256)", value);
        } else if (!strcmp(arg, "--ao-distance")) {
            NEED_VALUE();
            if (!parse_float(value, &o->render.ao_distance) || !(o->render.ao_distance > 0))
                return usage_error("bad --ao-distance '%s' (> 0)", value);
        } else if (!strcmp(arg, "--bounces")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->render.max_bounces) || !o->render.max_bounces || o->render.max_bounces > 64)
                return usage_error("bad --bounces '%s' (1 to 64)", value);
        } else if (!strcmp(arg, "--seed")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->render.seed)) return usage_error("bad --seed '%s'", value);
        } else if (!strcmp(arg, "--heat")) {
            NEED_VALUE();
            if (!strcmp(value, "nodes")) o->render.heat = VKRT_HEAT_NODES;
            else if (!strcmp(value, "leaves")) o->render.heat = VKRT_HEAT_LEAVES;
            else if (!strcmp(value, "tris")) o->render.heat = VKRT_HEAT_TRIS;
            else return usage_error("unknown heat kind '%s' (nodes, leaves, tris)", value);
        } else if (!strcmp(arg, "--heat-max")) {
            NEED_VALUE();
            if (!parse_float(value, &o->heat_max) || o->heat_max <= 0) return usage_error("bad --heat-max '%s'", value);
        } else if (!strcmp(arg, "--backend")) {
            NEED_VALUE();
            if (!strcmp(value, "gpu")) o->context.backend = VKRT_BACKEND_GPU;
            else if (!strcmp(value, "cpu")) o->context.backend = VKRT_BACKEND_CPU;
            else return usage_error("unknown backend '%s' (gpu, cpu)", value);
        } else if (!strcmp(arg, "--bvh")) {
            NEED_VALUE();
            if (!strcmp(value, "sah")) o->scene.builder = VKRT_BVH_BUILDER_BINNED_SAH;
            else if (!strcmp(value, "sbvh")) o->scene.builder = VKRT_BVH_BUILDER_SPATIAL_SAH;
            else if (!strcmp(value, "midpoint")) o->scene.builder = VKRT_BVH_BUILDER_MIDPOINT;
            else return usage_error("unknown BVH builder '%s' (sah, sbvh, midpoint)", value);
        } else if (!strcmp(arg, "--max-leaf")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->scene.max_leaf_size) || !o->scene.max_leaf_size)
                return usage_error("bad --max-leaf '%s'", value);
        } else if (!strcmp(arg, "--traverse")) {
            NEED_VALUE();
            if (!strcmp(value, "bvh")) o->render.traversal = VKRT_TRAVERSAL_BVH;
            else if (!strcmp(value, "naive")) o->render.traversal = VKRT_TRAVERSAL_NAIVE;
            else return usage_error("unknown traversal '%s' (bvh, naive)", value);
        } else if (!strcmp(arg, "--isect")) {
            NEED_VALUE();
            if (!strcmp(value, "watertight")) o->render.intersector = VKRT_INTERSECTOR_WATERTIGHT;
            else if (!strcmp(value, "mt")) o->render.intersector = VKRT_INTERSECTOR_MOLLER_TRUMBORE;
            else return usage_error("unknown intersector '%s' (watertight, mt)", value);
        } else if (!strcmp(arg, "--precision")) {
            NEED_VALUE();
            if (!strcmp(value, "float")) o->render.precision = VKRT_PRECISION_FLOAT;
            else if (!strcmp(value, "double")) o->render.precision = VKRT_PRECISION_DOUBLE;
            else return usage_error("unknown precision '%s' (float, double)", value);
        } else if (!strcmp(arg, "--eye")) {
            NEED_VALUE();
            eye_given = true;
            if (!parse_vec3(value, o->render.camera.eye)) return usage_error("bad --eye '%s' (want X,Y,Z)", value);
        } else if (!strcmp(arg, "--target")) {
            NEED_VALUE();
            target_given = true;
            if (!parse_vec3(value, o->render.camera.target)) return usage_error("bad --target '%s' (want X,Y,Z)", value);
        } else if (!strcmp(arg, "--up")) {
            NEED_VALUE();
            const float *up = o->render.camera.up;
            if (!parse_vec3(value, o->render.camera.up)) return usage_error("bad --up '%s' (want X,Y,Z)", value);
            /* The API reads a zero up as "the default (0, 1, 0)"; typed, it is a mistake. */
            if (up[0] == 0 && up[1] == 0 && up[2] == 0) return usage_error("bad --up '%s' (a direction, not zero)", value);
        } else if (!strcmp(arg, "--fov")) {
            NEED_VALUE();
            if (!parse_float(value, &o->render.camera.fov_y_degrees) || o->render.camera.fov_y_degrees <= 0 ||
                o->render.camera.fov_y_degrees >= 180)
                return usage_error("bad --fov '%s' (degrees, between 0 and 180)", value);
        } else if (!strcmp(arg, "--size")) {
            NEED_VALUE();
            if (!parse_size(value, &o->render.width, &o->render.height)) return usage_error("bad --size '%s' (want WxH)", value);
        } else if (!strcmp(arg, "--no-normalize")) {
            o->scene.keep_world_coordinates = true;
        } else if (!strcmp(arg, "--device")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->context.device_index)) return usage_error("bad --device '%s'", value);
            o->context.select_device = true;
        } else if (!strcmp(arg, "--threads")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->context.cpu_threads) || !o->context.cpu_threads) return usage_error("bad --threads '%s'", value);
        } else if (!strcmp(arg, "--device-memory")) {
            NEED_VALUE();
            uint32_t mib;
            if (!parse_u32(value, &mib) || !mib) return usage_error("bad --device-memory '%s' (MiB, at least 1)", value);
            o->context.device_memory_limit = (uint64_t)mib << 20;
        } else if (!strcmp(arg, "--repeat")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->repeat) || !o->repeat || o->repeat > 1000) return usage_error("bad --repeat '%s'", value);
        } else if (!strcmp(arg, "--csv")) {
            NEED_VALUE();
            o->csv = value;
        } else if (!strcmp(arg, "--compare")) {
            NEED_VALUE();
            if (strcmp(value, "embree")) return usage_error("unknown --compare '%s' (embree)", value);
#ifndef VKRT_HAVE_EMBREE
            return usage_error("--compare %s: this vkrt was built without Embree (install Debian's libembree-dev, "
                               "then `meson setup --reconfigure build`)", value);
#endif
            o->compare_embree = true;
        } else if (!strcmp(arg, "--procedural")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->procedural) || o->procedural < 18 || o->procedural > 100000000)
                return usage_error("bad --procedural '%s' (triangles, 18 to 100000000)", value);
        } else if (!strcmp(arg, "--modes")) {
            o->modes = true;
        } else if (!strcmp(arg, "--max-spp")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->max_spp) || !o->max_spp || o->max_spp > 65536)
                return usage_error("bad --max-spp '%s' (1 to 65536)", value);
        } else if (!strcmp(arg, "--ref-spp")) {
            NEED_VALUE();
            if (!parse_u32(value, &o->reference_spp) || !o->reference_spp || o->reference_spp > 65536)
                return usage_error("bad --ref-spp '%s' (1 to 65536)", value);
        } else if (!strcmp(arg, "--cache")) {
            NEED_VALUE();
            o->cache_dir = value;
        } else if (!strcmp(arg, "--counters")) {
            o->render.traversal_counters = true;
        } else if (!strcmp(arg, "--quick")) {
            o->quick = true;
        } else if (!strcmp(arg, "--validation")) {
            o->context.validation = true;
        } else if (!strcmp(arg, "-q") || !strcmp(arg, "--quiet")) {
            verbosity = 0;
        } else if (!strcmp(arg, "-v") || !strcmp(arg, "--verbose")) {
            verbosity = 2;
        } else if (!strcmp(arg, "-h") || !strcmp(arg, "--help")) {
            print_help(stdout, o->command);
            exit(EXIT_OK);
        } else if (arg[0] == '-' && arg[1]) {
            return usage_error("unknown option '%s'", arg);
        } else if (!o->input) {
            o->input = arg;
        } else {
            return usage_error("unexpected argument '%s' (one input file at most)", arg);
        }
    }
    /* The eye --help names as the default, which the API gives only to a camera whose eye and
     * target are equal (vkrt_camera): --target alone would otherwise look from the origin. */
    if (target_given && !eye_given) {
        o->render.camera.eye[0] = o->render.camera.eye[1] = 0.0f;
        o->render.camera.eye[2] = (float)CAMERA_DEFAULT_EYE_Z;
    }
    /* Typed points that are equal would be read as "the default view" and rendered from
     * (0, 0, 1.5) without a word; --eye 0,0,0 alone (the target's default is the origin) too. */
    const float *eye = o->render.camera.eye, *target = o->render.camera.target;
    if ((eye_given || target_given) && eye[0] == target[0] && eye[1] == target[1] && eye[2] == target[2]) {
        char point[96];
        snprintf(point, sizeof point, "%g,%g,%g", (double)eye[0], (double)eye[1], (double)eye[2]);
        return usage_error("--eye and --target are the same point (%s): the view has no direction", point);
    }
    return EXIT_OK;
}

/* The pipeline cache spares lavapipe's LLVM from recompiling every pipeline in every run. */
static const char *pipeline_cache_path(char *buf, size_t size)
{
    const char *env = getenv("VKRT_PIPELINE_CACHE");
    if (env) return env[0] ? env : NULL;
    const char *base = getenv("XDG_CACHE_HOME");
    const char *home = getenv("HOME");
    char dir[4096];
    if (base && base[0]) snprintf(dir, sizeof dir, "%s/vkrt", base);
    else if (home && home[0]) snprintf(dir, sizeof dir, "%s/.cache/vkrt", home);
    else return NULL;
    char parent[4096];
    snprintf(parent, sizeof parent, "%s", dir);
    char *slash = strrchr(parent, '/');
    if (slash) *slash = '\0';
    mkdir(parent, 0755);
    if (mkdir(dir, 0755) != 0 && errno != EEXIST) return NULL;
    snprintf(buf, size, "%s/pipelines.bin", dir);
    return buf;
}

static int check_validation(vkrt_context *ctx, const options *o)
{
    uint32_t n = vkrt_context_validation_messages(ctx);
    if (o->context.validation && n) {
        fprintf(stderr, "vkrt: error: the Vulkan validation layer reported %u message%s\n", n, n == 1 ? "" : "s");
        return EXIT_VALIDATION;
    }
    return EXIT_OK;
}

static const char *mode_name(vkrt_mode m)
{
    static const char *names[] = { "normal", "normal", "depth", "heatmap", "id", "albedo", "uv", "shaded", "ao", "path" };
    return names[m];
}

static bool known_image_extension(const char *path)
{
    const char *dot = strrchr(path, '.');
    return dot && !strchr(dot, '/') &&
           (!strcasecmp(dot, ".png") || !strcasecmp(dot, ".ppm") || !strcasecmp(dot, ".pfm") ||
            !strcasecmp(dot, ".hdr"));
}

/* A progress bar with ETA on stderr, driven by the library's progress callbacks: only where a
 * person watches (stderr a terminal, CI unset, not -q), and only once a call has run for a
 * second, so quick commands print nothing extra. One call (scene creation, a render) at a time;
 * the library reports progress from one thread. */
#define PROGRESS_DELAY_MS 1000.0 /* shorter work finishes before a bar would be read */
#define PROGRESS_REDRAW_MS 100.0 /* ten redraws a second keep a slow terminal from lagging */
#define PROGRESS_WIDTH 30

typedef struct progress_bar {
    bool enabled;
    bool shown;          /* a bar is on the line and must be cleared */
    double start_ms, drawn_ms;
} progress_bar;

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void progress_begin(progress_bar *b)
{
    const char *ci = getenv("CI");
    b->enabled = verbosity >= 1 && isatty(STDERR_FILENO) && !(ci && ci[0]);
    b->shown = false;
    b->start_ms = now_ms();
    b->drawn_ms = 0.0;
}

static void progress_end(progress_bar *b)
{
    if (b->shown) fputs("\r\033[K", stderr);
    b->shown = false;
}

static bool on_progress(void *user, const char *stage, float fraction)
{
    progress_bar *b = user;
    if (!b->enabled) return true;
    double t = now_ms(), elapsed = t - b->start_ms;
    if (elapsed < PROGRESS_DELAY_MS || (t - b->drawn_ms < PROGRESS_REDRAW_MS && fraction < 1.0f)) return true;
    if (!(fraction >= 0.0f)) fraction = 0.0f;
    if (fraction > 1.0f) fraction = 1.0f;
    int filled = (int)(fraction * PROGRESS_WIDTH);
    char eta[32] = "";
    if (fraction >= 0.01f && fraction < 1.0f)
        snprintf(eta, sizeof eta, "ETA %.0f s", ceil(elapsed * (1.0 - fraction) / fraction / 1e3));
    fprintf(stderr, "\r%-6s [%.*s%*s] %3.0f%% %6.1f s  %s\033[K", stage, filled, "##############################",
            PROGRESS_WIDTH - filled, "", fraction * 100.0f, elapsed / 1e3, eta);
    fflush(stderr);
    b->shown = true;
    b->drawn_ms = t;
    return true;
}

/* Why each lighting feature was or was not compiled in (-v). */
static void report_skips(const vkrt_scene *scene, const vkrt_render_desc *d, const vkrt_render_stats *stats)
{
    if (stats->naive_by_cost)
        fprintf(stderr, "vkrt: traversal: naive, chosen by the cost model (the BVH's SAH cost is not below the triangle count)\n");
    if (stats->rays_binned)
        fprintf(stderr, "vkrt: traversal: binned, the camera rays' triangle lists built on the host (a CPU device; README, "
                        "\"Binned traversal\"): %" PRIu64 " triangle tests, %.2f a ray\n",
                stats->binned_tests, (double)stats->binned_tests / (double)stats->rays_binned);
    if (d->mode < VKRT_MODE_SHADED) {
        fprintf(stderr, "vkrt: skipped: lights, shadows and random numbers (a primary mode); surfaces %s\n",
                d->mode == VKRT_MODE_ALBEDO || d->mode == VKRT_MODE_UV ? "read" : "not uploaded (this mode does not read them)");
        return;
    }
    vkrt_scene_stats ss;
    vkrt_scene_stats_get(scene, &ss);
    const struct {
        uint32_t bit;
        const char *why_not;
    } reasons[] = {
        { VKRT_FEATURE_TEXTURES, ss.textures ? "this mode reads no texture" : "no material has a texture" },
        { VKRT_FEATURE_PUNCTUAL, d->mode == VKRT_MODE_AO ? "ao ignores lights" : "no point or directional light" },
        { VKRT_FEATURE_EMITTERS, d->mode == VKRT_MODE_AO ? "ao ignores emission" : "no emissive triangle" },
        { VKRT_FEATURE_SKY, d->mode == VKRT_MODE_AO ? "ao ignores the sky" : "the sky is black" },
        { VKRT_FEATURE_SPECULAR, d->mode == VKRT_MODE_AO ? "ao reads no material" : "no material is metallic" },
        { VKRT_FEATURE_RANDOM, "shaded with only point and directional lights is exact in one sample" },
        { VKRT_FEATURE_ADAPTIVE, d->target_error > 0 ? "the render needs no sampling" : "no --target-error" },
    };
    for (size_t i = 0; i < sizeof reasons / sizeof reasons[0]; i++) {
        if (stats->features & reasons[i].bit) fprintf(stderr, "vkrt: compiled in: %s\n", vkrt_feature_name(reasons[i].bit));
        else fprintf(stderr, "vkrt: skipped: %s (%s)\n", vkrt_feature_name(reasons[i].bit), reasons[i].why_not);
    }
}

static int command_render(options *o)
{
    /* Refuse an unknown format before spending a render on it. */
    if (!known_image_extension(o->output))
        return usage_error("cannot tell the image format of '%s' (use .png, .ppm, .pfm or .hdr)", o->output);
    char cache_buf[4200];
    o->context.pipeline_cache_path = pipeline_cache_path(cache_buf, sizeof cache_buf);
    vkrt_context *ctx = NULL;
    vkrt_result r = vkrt_context_create(&o->context, &ctx);
    if (r != VKRT_OK)
        return fail(NULL, r, o->context.backend == VKRT_BACKEND_CPU ? "creating the CPU backend" : "creating the Vulkan backend");
    int code = EXIT_OK;
    vkrt_scene *scene = NULL;
    float *rgba = NULL;
    o->scene.path = o->input;
    progress_bar bar;
    o->scene.progress = o->render.progress = on_progress;
    o->scene.progress_user = o->render.progress_user = &bar;
    progress_begin(&bar);
    r = vkrt_scene_create(ctx, &o->scene, &scene);
    progress_end(&bar);
    if (r != VKRT_OK) {
        code = fail(ctx, r, o->input ? NULL : "built-in scene");
        goto done;
    }
    uint32_t w = o->render.width ? o->render.width : 1024, h = o->render.height ? o->render.height : 1024;
    size_t floats = vkrt_render_floats(w, h);
    rgba = floats ? malloc(floats * sizeof *rgba) : NULL;
    if (!rgba) {
        fprintf(stderr, "vkrt: error: out of memory for a %ux%u image\n", w, h);
        code = EXIT_INTERNAL;
        goto done;
    }
    vkrt_render_stats stats;
    double trace_ms[1001], total_ms[1001];
    uint32_t runs = o->repeat ? o->repeat + 1 : 1;
    for (uint32_t i = 0; i < runs; i++) {
        progress_begin(&bar);
        r = vkrt_render(ctx, scene, &o->render, rgba, floats, &stats);
        progress_end(&bar);
        if (r != VKRT_OK) {
            code = fail(ctx, r, "render");
            goto done;
        }
        trace_ms[i] = stats.trace_ms;
        total_ms[i] = stats.total_ms;
    }
    if (o->repeat) { /* the first run is the warm-up */
        stats.trace_ms = bench_median(trace_ms + 1, o->repeat);
        stats.total_ms = bench_median(total_ms + 1, o->repeat);
    }
    /* Validation findings fail the run before anything is written. */
    if ((code = check_validation(ctx, o)) != EXIT_OK) goto done;
    vkrt_image_view view = { rgba, w, h, o->render.mode, o->heat_max };
    r = vkrt_image_save(ctx, o->output, &view);
    if (r != VKRT_OK) {
        code = fail(ctx, r, "saving the image");
        goto done;
    }
    if (verbosity >= 1) {
        vkrt_scene_stats ss;
        vkrt_scene_stats_get(scene, &ss);
        fprintf(stderr, "vkrt: %s, %" PRIu64 " triangles, %ux%u %s on %s: trace %.1f ms, total %.1f ms%s -> %s\n",
                o->input ? o->input : "built-in scene", ss.triangles, w, h, mode_name(o->render.mode),
                vkrt_context_device_name(ctx), stats.trace_ms, stats.total_ms,
                o->repeat ? " (median after a warm-up)" : "", o->output);
        if (o->render.mode >= VKRT_MODE_SHADED)
            fprintf(stderr, "vkrt: %.2f samples per pixel, %" PRIu64 " shadow rays, %" PRIu64 " bounce rays, %u lights\n",
                    (double)stats.samples / ((double)w * h), stats.shadow_rays, stats.bounce_rays, stats.lights);
        if (verbosity >= 2) report_skips(scene, &o->render, &stats);
        if (verbosity >= 2 && stats.submissions)
            fprintf(stderr, "vkrt: %u device submissions, the longest %.1f ms (each is sized to about 100 ms)\n",
                    stats.submissions, stats.longest_submission_ms);
        if (o->render.traversal_counters) {
            double rays = (double)stats.rays;
            fprintf(stderr, "vkrt: per ray: %.2f boxes entered, %.2f leaves entered, %.2f triangle tests\n",
                    (double)stats.nodes_visited / rays, (double)stats.leaves_visited / rays,
                    (double)stats.tris_tested / rays);
        }
    }
done:
    free(rgba);
    vkrt_scene_destroy(scene);
    int vcode = check_validation(ctx, o);
    vkrt_context_destroy(ctx);
    return code != EXIT_OK ? code : vcode;
}

static int command_info(options *o)
{
    if (!o->input) return usage_error("%s", "info needs a FILE");
    vkrt_context *ctx = NULL;
    /* Statistics need no device; with --backend gpu the scene is also uploaded and its device
     * memory measured. */
    const bool on_device = o->context.backend == VKRT_BACKEND_GPU;
    if (!on_device) o->context.backend = VKRT_BACKEND_CPU;
    vkrt_result r = vkrt_context_create(&o->context, &ctx);
    if (r != VKRT_OK) return fail(NULL, r, "creating the context");
    vkrt_scene *scene = NULL;
    o->scene.path = o->input;
    progress_bar bar;
    o->scene.progress = on_progress;
    o->scene.progress_user = &bar;
    progress_begin(&bar);
    r = vkrt_scene_create(ctx, &o->scene, &scene);
    progress_end(&bar);
    if (r != VKRT_OK) {
        int code = fail(ctx, r, NULL);
        vkrt_context_destroy(ctx);
        return code;
    }
    vkrt_scene_stats s;
    vkrt_scene_stats_get(scene, &s);
    printf("file          %s\n", o->input);
    printf("builder       %s\n", o->scene.builder == VKRT_BVH_BUILDER_MIDPOINT      ? "midpoint"
                                  : o->scene.builder == VKRT_BVH_BUILDER_SPATIAL_SAH ? "sbvh"
                                                                                      : "sah");
    printf("triangles     %" PRIu64 "\n", s.triangles);
    if (s.bvh_references != s.triangles)
        printf("references    %" PRIu64 " (spatial splits: %.1f%% more than the triangles)\n", s.bvh_references,
               100.0 * ((double)s.bvh_references / (double)s.triangles - 1.0));
    printf("nodes         %" PRIu64 "\n", s.nodes);
    printf("leaves        %" PRIu64 "\n", s.leaves);
    printf("depth         %u\n", s.depth);
    printf("sah cost      %.3f (C_trav = C_isect = 1)\n", s.sah_cost);
    printf("load          %.1f ms\n", s.load_ms);
    printf("build         %.1f ms\n", s.build_ms);
    printf("bytes         %" PRIu64 " (nodes %" PRIu64 ", triangles %" PRIu64 "; %.1f per triangle)\n",
           s.node_bytes + s.triangle_bytes, s.node_bytes, s.triangle_bytes,
           s.triangles ? (double)(s.node_bytes + s.triangle_bytes) / (double)s.triangles : 0.0);
    printf("surfaces      %" PRIu64 " bytes (albedo, uv and the lighting modes): %u material%s, %u texture%s, %s\n",
           s.surface_bytes, s.materials, s.materials == 1 ? "" : "s", s.textures, s.textures == 1 ? "" : "s",
           s.has_texcoords ? "texture coordinates" : "no texture coordinates");
    if (s.alpha_tested) printf("alpha mask    some materials: every hit is alpha tested\n");
    printf("lights        %u point or directional from the file, %" PRIu64 " emissive triangle%s%s\n", s.lights,
           s.emissive_triangles, s.emissive_triangles == 1 ? "" : "s", s.has_metals ? "; metallic materials" : "");
    double per_tri = s.triangles ? 1.0 / (double)s.triangles : 0.0;
    printf("memory        host %.1f bytes per triangle; ", (double)s.host_bytes * per_tri);
    if (on_device)
        printf("device %.1f, %.1f more once a mode reads the surfaces\n", (double)s.device_bytes * per_tri,
               (double)s.surface_bytes * per_tri);
    else
        printf("device: --backend gpu measures it\n");
    /* Through the wide BVH the binary nodes and shading triangles wait on the host until a mode
     * reads them (normal and depth shading, the heat map, naive traversal, the lighting modes). */
    if (on_device && s.device_buffers)
        printf("device        %" PRIu64 " bytes on %s, the binary nodes and triangles in %u storage buffers%s\n",
               s.device_bytes, vkrt_context_device_name(ctx), s.device_buffers,
               s.device_buffers > 2 ? " (split: the triangles exceed one buffer of this device)" : "");
    else if (on_device)
        printf("device        %" PRIu64 " bytes on %s: the wide BVH alone, %.1f per triangle more once a mode reads "
               "the binary nodes and triangles\n",
               s.device_bytes, vkrt_context_device_name(ctx), (double)(s.node_bytes + s.triangle_bytes) * per_tri);
    printf("bounds        (%g, %g, %g) - (%g, %g, %g)\n", s.bounds_min[0], s.bounds_min[1], s.bounds_min[2],
           s.bounds_max[0], s.bounds_max[1], s.bounds_max[2]);
    printf("leaf sizes   ");
    for (int i = 0; i < VKRT_LEAF_HISTOGRAM_BINS; i++)
        if (s.leaf_histogram[i])
            printf(" %s%d:%" PRIu64, i == VKRT_LEAF_HISTOGRAM_BINS - 1 ? ">=" : "", i + 1, s.leaf_histogram[i]);
    printf("\n");
    vkrt_scene_destroy(scene);
    vkrt_context_destroy(ctx);
    return EXIT_OK;
}

static const char *device_type_name(vkrt_device_type t)
{
    switch (t) {
    case VKRT_DEVICE_INTEGRATED_GPU: return "integrated GPU";
    case VKRT_DEVICE_DISCRETE_GPU: return "discrete GPU";
    case VKRT_DEVICE_VIRTUAL_GPU: return "virtual GPU";
    case VKRT_DEVICE_CPU: return "CPU";
    default: return "other";
    }
}

static int command_devices(options *o)
{
    vkrt_device_info devices[16];
    uint32_t count = 16;
    vkrt_result r = vkrt_devices_list(&o->context, devices, &count);
    if (r != VKRT_OK) return fail(NULL, r, "listing Vulkan devices");
    for (uint32_t i = 0; i < count; i++) {
        const vkrt_device_info *d = &devices[i];
        printf("%u: %s (%s, Vulkan %u.%u.%u, storage buffers up to %" PRIu64 " MiB)%s\n", i, d->name,
               device_type_name(d->type), d->api_version >> 22, (d->api_version >> 12) & 0x3ff,
               d->api_version & 0xfff, d->max_storage_buffer_range >> 20, d->usable ? "" : " [unusable]");
    }
    return EXIT_OK;
}

/* How a suite (stress, bench) ended: its error, or validation messages where the layer was on. */
static int suite_exit_code(const options *o, vkrt_result r, const char *error, unsigned validation_messages)
{
    if (r != VKRT_OK) {
        fprintf(stderr, "vkrt: error: %s\n", error);
        return exit_code_for(r);
    }
    if (o->context.validation && validation_messages) {
        fprintf(stderr, "vkrt: error: the Vulkan validation layer reported %u message%s\n", validation_messages,
                validation_messages == 1 ? "" : "s");
        return EXIT_VALIDATION;
    }
    return EXIT_OK;
}

static int command_stress(options *o)
{
    if (o->input) return usage_error("stress takes no FILE ('%s')", o->input);
    char cache_buf[4200];
    stress_options so = { .context = o->context, .backend = o->context.backend,
                          .intersector = o->render.intersector, .quick = o->quick };
    so.context.pipeline_cache_path = pipeline_cache_path(cache_buf, sizeof cache_buf);
    stress_report report;
    vkrt_result r = stress_run(&so, &report);
    int code = suite_exit_code(o, r, report.error, report.validation_messages);
    if (code != EXIT_OK) return code;
    return report.failed_rows ? EXIT_INTERNAL : EXIT_OK;
}

/* Where `bench --modes` keeps its references: --cache (empty: nowhere), else the user's cache
 * directory, as for the pipeline cache. */
static const char *reference_cache_dir(const options *o, char *buf, size_t size)
{
    if (o->cache_dir) return o->cache_dir[0] ? o->cache_dir : NULL;
    const char *base = getenv("XDG_CACHE_HOME");
    const char *home = getenv("HOME");
    if (base && base[0]) snprintf(buf, size, "%s/vkrt/bench", base);
    else if (home && home[0]) snprintf(buf, size, "%s/.cache/vkrt/bench", home);
    else return NULL;
    return buf;
}

static int command_bench(options *o)
{
    if (o->modes && o->compare_embree) return usage_error("%s", "--modes and --compare are separate runs: give one");
    if (o->procedural && o->input) return usage_error("--procedural replaces the FILE ('%s'): give one", o->input);
    char cache_buf[4200], ref_buf[4200];
    bench_options bo = {
        .context = o->context, .backend = o->context.backend, .input = o->input,
        .procedural = o->procedural, .keep_world_coordinates = o->scene.keep_world_coordinates,
        .builder = o->scene.builder, .camera = o->render.camera,
        .width = o->render.width, .height = o->render.height, .repeat = o->repeat, .quick = o->quick,
        .csv_path = o->csv, .progress = verbosity >= 1 && !getenv("CI"), .reference_spp = o->reference_spp,
        .max_spp = o->max_spp,
        .cache_dir = reference_cache_dir(o, ref_buf, sizeof ref_buf),
    };
    bo.context.pipeline_cache_path = pipeline_cache_path(cache_buf, sizeof cache_buf);
    bench_report report;
    vkrt_result r;
#ifdef VKRT_HAVE_EMBREE
    if (o->compare_embree) r = bench_compare_run(&bo, &report);
    else
#endif
    if (o->modes) r = bench_modes_run(&bo, &report);
    else r = bench_run(&bo, &report);
    return suite_exit_code(o, r, report.error, report.validation_messages);
}

int main(int argc, char **argv)
{
    if (argc < 2 || !strcmp(argv[1], "-h") || !strcmp(argv[1], "--help") || !strcmp(argv[1], "help")) {
        print_help(argc < 2 ? stderr : stdout, NULL);
        return argc < 2 ? EXIT_USAGE : EXIT_OK;
    }
    if (!strcmp(argv[1], "--version")) {
        uint32_t v = vkrt_version();
        printf("vkrt %u.%u.%u\n", v >> 22, (v >> 12) & 0x3ff, v & 0xfff);
        return EXIT_OK;
    }
    options o = { .command = argv[1], .output = "render.png" };
    o.context.log = on_log;
    const char *env_validation = getenv("VKRT_VALIDATION");
    if (env_validation && env_validation[0] == '1') o.context.validation = true;
    int code = parse_args(argc, argv, &o);
    if (code != EXIT_OK) return code;
    if (!strcmp(o.command, "render")) return command_render(&o);
    if (!strcmp(o.command, "info")) return command_info(&o);
    if (!strcmp(o.command, "devices")) return command_devices(&o);
    if (!strcmp(o.command, "stress")) return command_stress(&o);
    if (!strcmp(o.command, "bench")) return command_bench(&o);
    return usage_error("unknown command '%s' (render, info, devices, bench, stress)", o.command);
}
