/* `vkrt bench`: for one scene and one view, every configuration timed, its traversal work
 * counted and its images compared with the CPU double-precision reference. Uses vkrt.h only.
 *
 * Timing: one warm-up render (lavapipe compiles a pipeline at its first dispatch), then the
 * median of `repeat` renders in `normal` mode without counters. GPU trace time is device time
 * from timestamp queries; "total" is the whole vkrt_render call, upload and readback included.
 * Counters and errors come from separate renders, so they never slow the timed ones. */
#include "bench.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench_csv.h"
#include "bench_scene.h"
#include "cli_contexts.h"

/* Naive traversal is benchmarked where it costs at most this many ray-triangle tests per
 * render (about a second on lavapipe); beyond, only its cost per ray is known: triangles. */
#define NAIVE_MAX_TESTS 1e8
/* A pixel whose id differs from the reference's is still the same hit when its depth is
 * within this relative distance (a shared edge, overlapping triangles): as test_reference. */
#define SAME_POINT_DEPTH 1e-6

/* The builders the table compares, by index: binned SAH (the default, whose scene renders the
 * reference), the seed's midpoint split, and spatial splits. */
#define BUILDERS 3
static const vkrt_bvh_builder builder_at[BUILDERS] = { VKRT_BVH_BUILDER_DEFAULT, VKRT_BVH_BUILDER_MIDPOINT,
                                                       VKRT_BVH_BUILDER_SPATIAL_SAH };

static int builder_index(vkrt_bvh_builder b)
{
    return b == VKRT_BVH_BUILDER_MIDPOINT ? 1 : b == VKRT_BVH_BUILDER_SPATIAL_SAH ? 2 : 0;
}

typedef struct config {
    vkrt_bvh_builder builder;
    vkrt_backend backend;
    vkrt_traversal traversal;
    vkrt_intersector intersector;
    vkrt_precision precision;
} config;

typedef struct row {
    config c;
    vkrt_scene_stats scene;
    double trace_ms, total_ms, mrays;
    double nodes_per_ray, leaves_per_ray, tris_per_ray;
    bool binned;                   /* the timed renders took the binned traversal (GPU, a CPU device) */
    uint64_t mismatched;           /* pixels: hit against miss, or another triangle elsewhere */
    double depth_rmse, depth_max;  /* relative, over pixels both hit */
} row;

typedef struct bench {
    const bench_options *o;
    bench_scene source;
    bench_report *report;
    FILE *out;
    vkrt_context *gpu, *cpu;
    vkrt_scene *scenes[BUILDERS][2]; /* [builder: sah, midpoint, sbvh][backend: gpu, cpu] */
    uint32_t width, height, repeat;
    size_t pixels;
    float *image;              /* scratch, one render */
    float *ref_id, *ref_depth; /* the CPU double reference (watertight, SAH BVH) */
    row *rows;
    unsigned row_count, row_cap;
    char gpu_skipped[1200];    /* why the GPU rows were not run (a scene beyond its limits) */
} bench;

static const char *builder_name(vkrt_bvh_builder b)
{
    static const char *const names[BUILDERS] = { "sah", "midpoint", "sbvh" };
    return names[builder_index(b)];
}
static const char *backend_name(vkrt_backend b) { return b == VKRT_BACKEND_CPU ? "cpu" : "gpu"; }
static const char *traversal_name(vkrt_traversal t) { return t == VKRT_TRAVERSAL_NAIVE ? "naive" : "bvh"; }

/* A row's traversal as the table shows it: "bvh, binned" where the library took the camera rays
 * through the host's lists instead of the BVH asked for (README, "Binned traversal"; its trace
 * ms holds the listing, its counts are the lists' tests). The CSV keeps "bvh" and says so in a
 * column of its own. */
static const char *row_traversal(const row *w) { return w->binned ? "bvh, binned" : traversal_name(w->c.traversal); }
static const char *isect_name(vkrt_intersector i) { return i == VKRT_INTERSECTOR_MOLLER_TRUMBORE ? "mt" : "watertight"; }
static const char *precision_name(vkrt_precision p) { return p == VKRT_PRECISION_DOUBLE ? "double" : "float"; }

static int compare_doubles(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

double bench_median(double *values, uint32_t n)
{
    qsort(values, n, sizeof *values, compare_doubles);
    return n % 2 ? values[n / 2] : 0.5 * (values[n / 2 - 1] + values[n / 2]);
}

static vkrt_scene *scene_of(const bench *b, const config *c)
{
    return b->scenes[builder_index(c->builder)][c->backend == VKRT_BACKEND_CPU];
}

static vkrt_context *context_of(const bench *b, const config *c)
{
    return c->backend == VKRT_BACKEND_CPU ? b->cpu : b->gpu;
}

/* One render of configuration c in `mode` into out (or the scratch image). */
static vkrt_result render(bench *b, const config *c, vkrt_mode mode, bool counters, float *out, vkrt_render_stats *stats)
{
    vkrt_render_desc d = {
        .width = b->width, .height = b->height, .camera = b->o->camera, .mode = mode, .traversal = c->traversal,
        .intersector = c->intersector, .precision = c->precision, .traversal_counters = counters,
    };
    vkrt_context *ctx = context_of(b, c);
    vkrt_result r = vkrt_render(ctx, scene_of(b, c), &d, out ? out : b->image, b->pixels * 4, stats);
    if (r != VKRT_OK)
        snprintf(b->report->error, sizeof b->report->error, "render (%s %s %s %s %s): %s", builder_name(c->builder),
                 backend_name(c->backend), traversal_name(c->traversal), isect_name(c->intersector),
                 precision_name(c->precision), vkrt_context_last_error(ctx));
    return r;
}

/* Mismatched pixels and relative depth errors of an id and a depth image against the reference. */
static void compare_with_reference(const bench *b, const float *id, const float *depth, row *out)
{
    double sum_sq = 0.0;
    uint64_t both = 0;
    for (size_t p = 0; p < b->pixels; p++) {
        float d = depth[4 * p], ref = b->ref_depth[4 * p];
        bool hit = d >= 0.0f, ref_hit = ref >= 0.0f;
        if (hit != ref_hit) {
            out->mismatched++;
            continue;
        }
        if (!hit) continue;
        double rel = fabs((double)d - (double)ref) / (double)ref;
        if (id[4 * p] != b->ref_id[4 * p] && rel > SAME_POINT_DEPTH) {
            out->mismatched++; /* another triangle, elsewhere along the ray */
            continue;
        }
        both++;
        sum_sq += rel * rel;
        out->depth_max = fmax(out->depth_max, rel);
    }
    out->depth_rmse = both ? sqrt(sum_sq / (double)both) : 0.0;
}

static vkrt_result measure(bench *b, const config *c, row *out)
{
    memset(out, 0, sizeof *out);
    out->c = *c;
    vkrt_scene_stats_get(scene_of(b, c), &out->scene);
    double trace[1001], total[1001];
    vkrt_render_stats st;
    vkrt_result r = VKRT_OK;
    for (uint32_t i = 0; i <= b->repeat && r == VKRT_OK; i++) { /* render 0: the warm-up */
        r = render(b, c, VKRT_MODE_NORMAL, false, NULL, &st);
        trace[i] = st.trace_ms;
        total[i] = st.total_ms;
        out->binned = st.rays_binned > 0;
    }
    /* The counts of the traversal the timed renders took: the binned traversal's from their own
     * statistics (its lists' entries, no box), the BVH's from a render that counts (the
     * counters keep a render to the BVH). */
    if (r == VKRT_OK && !out->binned) r = render(b, c, VKRT_MODE_NORMAL, true, NULL, &st);
    if (r != VKRT_OK) return r;
    out->trace_ms = bench_median(trace + 1, b->repeat);
    out->total_ms = bench_median(total + 1, b->repeat);
    out->mrays = out->trace_ms > 0.0 ? (double)b->pixels / (out->trace_ms * 1e3) : 0.0;
    out->nodes_per_ray = (double)st.nodes_visited / (double)st.rays;
    out->leaves_per_ray = (double)st.leaves_visited / (double)st.rays;
    out->tris_per_ray = (double)(out->binned ? st.binned_tests : st.tris_tested) / (double)st.rays;
    float *id = malloc(b->pixels * 4 * sizeof *id);
    if (!id) {
        snprintf(b->report->error, sizeof b->report->error, "out of memory for a %ux%u image", b->width, b->height);
        return VKRT_ERROR_OUT_OF_MEMORY;
    }
    r = render(b, c, VKRT_MODE_ID, false, id, NULL);
    if (r == VKRT_OK) r = render(b, c, VKRT_MODE_DEPTH, false, NULL, NULL);
    if (r == VKRT_OK) compare_with_reference(b, id, b->image, out);
    free(id);
    return r;
}

static void print_header(const bench *b, const vkrt_scene_stats *s)
{
    fprintf(b->out, "vkrt bench: %s (%llu triangles), %ux%u, %s; median of %u timed render%s after a warm-up;\n"
                    "errors against the CPU double-precision reference (watertight, SAH BVH)\n\n",
            bench_scene_name(&b->source), (unsigned long long)s->triangles, b->width, b->height,
            b->gpu ? vkrt_context_device_name(b->gpu) : "CPU only", b->repeat, b->repeat == 1 ? "" : "s");
    fprintf(b->out, "| builder | backend | traversal | isect | precision | build ms | SAH cost | bytes/tri | trace ms "
                    "| total ms | Mrays/s | boxes/ray | leaves/ray | tests/ray | mismatched px | depth RMSE | max depth err |\n"
                    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
}

static void print_row(const bench *b, const row *w)
{
    const vkrt_scene_stats *s = &w->scene;
    fprintf(b->out, "| %s | %s | %s | %s | %s | %.1f | %.2f | %.1f | %.2f | %.2f | %.2f | %.2f | %.2f | %.2f | %llu | %.2e | %.2e |\n",
            builder_name(w->c.builder), backend_name(w->c.backend), row_traversal(w),
            isect_name(w->c.intersector), precision_name(w->c.precision), s->build_ms, s->sah_cost,
            (double)(s->node_bytes + s->triangle_bytes) / (double)s->triangles, w->trace_ms, w->total_ms, w->mrays,
            w->nodes_per_ray, w->leaves_per_ray, w->tris_per_ray, (unsigned long long)w->mismatched, w->depth_rmse,
            w->depth_max);
    fflush(b->out);
}

/* The rows as CSV. */
static vkrt_result write_csv(const bench *b, const char *path)
{
    bench_csv csv;
    vkrt_result r = bench_csv_begin(&csv, path, "scene,triangles,width,height,builder,backend,traversal,intersector,"
                                                "precision,build_ms,sah_cost,bytes_per_triangle,trace_ms,total_ms,"
                                                "mrays_per_s,boxes_per_ray,leaves_per_ray,tests_per_ray,"
                                                "mismatched_pixels,depth_rel_rmse,depth_rel_max,binned");
    if (r != VKRT_OK) return r;
    for (unsigned i = 0; i < b->row_count; i++) {
        const row *w = &b->rows[i];
        const vkrt_scene_stats *s = &w->scene;
        fprintf(csv.f, "\"%s\",%llu,%u,%u,%s,%s,%s,%s,%s,%.4f,%.6f,%.3f,%.4f,%.4f,%.6f,%.4f,%.4f,%.4f,%llu,%.6e,%.6e,%d\n",
                bench_scene_name(&b->source), (unsigned long long)s->triangles, b->width, b->height,
                builder_name(w->c.builder), backend_name(w->c.backend), traversal_name(w->c.traversal),
                isect_name(w->c.intersector), precision_name(w->c.precision), s->build_ms, s->sah_cost,
                (double)(s->node_bytes + s->triangle_bytes) / (double)s->triangles, w->trace_ms, w->total_ms,
                w->mrays, w->nodes_per_ray, w->leaves_per_ray, w->tris_per_ray, (unsigned long long)w->mismatched,
                w->depth_rmse, w->depth_max, w->binned ? 1 : 0);
    }
    return bench_csv_end(&csv);
}

static vkrt_result load_scene(bench *b, int builder, int backend)
{
    vkrt_context *ctx = backend ? b->cpu : b->gpu;
    if (!ctx) return VKRT_OK;
    vkrt_scene_desc d = bench_scene_desc(&b->source);
    d.builder = builder_at[builder];
    /* The first GPU scene decides whether the GPU runs at all; the others only their own rows. */
    const char *gpu_rows = backend        ? NULL
                           : builder == 1 ? "the GPU rows of the midpoint BVH were"
                           : builder == 2 ? "the GPU rows of the spatial-split BVH were"
                                          : BENCH_GPU_BACKEND_ROWS;
    return bench_scene_create(ctx, gpu_rows, &d, &b->scenes[builder][backend], b->gpu_skipped, sizeof b->gpu_skipped,
                              b->report->error, sizeof b->report->error);
}

/* Every builder's CPU scene, and the GPU scene of the first: the GPU holds one builder's scene
 * at a time (use_gpu_scene), since two of a large scene overflow lavapipe's 2 GiB heap (1e7
 * triangles: 1.0 GB with the SAH BVH, 1.3 GB with the midpoint one). */
static vkrt_result load_scenes(bench *b)
{
    vkrt_result r = VKRT_OK;
    for (int k = 0; k < BUILDERS && r == VKRT_OK; k++) r = load_scene(b, k, 1);
    if (r == VKRT_OK) r = load_scene(b, 0, 0);
    return r;
}

/* Makes the GPU scene of config c's builder the one the GPU holds. Where it does not fit the
 * device, its rows are skipped with a note (gpu_skipped) and the scene stays NULL. */
static vkrt_result use_gpu_scene(bench *b, const config *c)
{
    const int k = builder_index(c->builder);
    if (c->backend != VKRT_BACKEND_GPU || b->scenes[k][0]) return VKRT_OK;
    for (int other = 0; other < BUILDERS; other++) {
        vkrt_scene_destroy(b->scenes[other][0]);
        b->scenes[other][0] = NULL;
    }
    return load_scene(b, k, 0);
}

static vkrt_result run_configs(bench *b)
{
    vkrt_scene_stats s;
    vkrt_scene_stats_get(b->scenes[0][1], &s);
    const bool naive = (double)s.triangles * (double)b->pixels <= NAIVE_MAX_TESTS;
    config all[BUILDERS * 16];
    unsigned n = 0;
    for (int k = 0; k < BUILDERS; k++)
        for (int m = 0; m < 2; m++)
            for (int t = 0; t < 2; t++)
                for (int i = 0; i < 2; i++)
                    for (int p = 0; p < 2; p++) {
                        config c = { builder_at[k],
                                     m ? VKRT_BACKEND_CPU : VKRT_BACKEND_GPU,
                                     t ? VKRT_TRAVERSAL_NAIVE : VKRT_TRAVERSAL_BVH,
                                     i ? VKRT_INTERSECTOR_MOLLER_TRUMBORE : VKRT_INTERSECTOR_WATERTIGHT,
                                     p ? VKRT_PRECISION_DOUBLE : VKRT_PRECISION_FLOAT };
                        /* The CPU context exists whatever --backend says (it renders the
                         * reference); its rows run only where asked for. */
                        if (m ? !b->cpu || b->o->backend == VKRT_BACKEND_GPU : !b->scenes[0][0])
                            continue; /* backend not run */
                        if (p && !m) continue;                                 /* doubles: CPU only */
                        if (t && (k || !naive)) continue; /* naive ignores the builder; too slow */
                        all[n++] = c;
                    }
    print_header(b, &s);
    b->rows = calloc(n, sizeof *b->rows);
    if (!b->rows) return VKRT_ERROR_OUT_OF_MEMORY;
    const bool progress = b->o->progress && isatty(STDERR_FILENO);
    bool gpu_full = false, gpu_ran = false;
    for (unsigned i = 0; i < n; i++) {
        if (gpu_full && all[i].backend == VKRT_BACKEND_GPU) continue;
        if (progress)
            fprintf(stderr, "\rbench: %u/%u %s %s %s %s %s   ", i + 1, n, builder_name(all[i].builder),
                    backend_name(all[i].backend), traversal_name(all[i].traversal), isect_name(all[i].intersector),
                    precision_name(all[i].precision));
        vkrt_result r = use_gpu_scene(b, &all[i]);
        if (r != VKRT_OK) return r;
        if (!scene_of(b, &all[i])) continue; /* beyond the device: gpu_skipped says so */
        r = measure(b, &all[i], &b->rows[b->row_count]);
        if ((r == VKRT_ERROR_OUT_OF_DEVICE_MEMORY || r == VKRT_ERROR_LIMIT) && all[i].backend == VKRT_BACKEND_GPU) {
            /* The scene fit the device, but a render's own arrays did not (a normal render adds
             * the 64-byte shading triangles to the traversal's arrays): the GPU's rows stop
             * here with a note, as for a scene beyond the device. */
            size_t at = strlen(b->gpu_skipped);
            snprintf(b->gpu_skipped + at, sizeof b->gpu_skipped - at, "%s%s not run: %s", at ? "\n" : "",
                     gpu_ran ? "the GPU backend's remaining rows were" : BENCH_GPU_BACKEND_ROWS,
                     vkrt_context_last_error(b->gpu));
            b->report->error[0] = '\0';
            gpu_full = true;
            continue;
        }
        if (r != VKRT_OK) return r;
        gpu_ran |= all[i].backend == VKRT_BACKEND_GPU;
        print_row(b, &b->rows[b->row_count++]);
    }
    if (progress) fprintf(stderr, "\r%60s\r", "");
    if (b->gpu_skipped[0]) fprintf(b->out, "\n%s\n", b->gpu_skipped);
    if (!naive)
        fprintf(b->out, "\nnaive traversal not run: %.3g ray-triangle tests per render (limit %.0e); it tests every "
                        "triangle, %llu per ray\n",
                (double)s.triangles * (double)b->pixels, NAIVE_MAX_TESTS, (unsigned long long)s.triangles);
    return VKRT_OK;
}

vkrt_result bench_run(const bench_options *o, bench_report *out)
{
    memset(out, 0, sizeof *out);
    bench b = { .o = o, .report = out, .out = o->out ? o->out : stdout };
    b.width = o->width ? o->width : o->quick ? 64 : 512;
    b.height = o->height ? o->height : o->quick ? 64 : 512;
    b.repeat = o->repeat ? o->repeat : o->quick ? 1 : 5;
    if (b.repeat > 1000) b.repeat = 1000;
    b.pixels = (size_t)b.width * b.height;
    vkrt_result r = cli_contexts_create(&o->context, o->backend != VKRT_BACKEND_CPU, &b.gpu, &b.cpu, out->error,
                                        sizeof out->error);
    if (r != VKRT_OK) return r;
    b.image = malloc(b.pixels * 4 * sizeof *b.image);
    b.ref_id = malloc(b.pixels * 4 * sizeof *b.ref_id);
    b.ref_depth = malloc(b.pixels * 4 * sizeof *b.ref_depth);
    if (!b.image || !b.ref_id || !b.ref_depth) {
        snprintf(out->error, sizeof out->error, "out of memory for %ux%u images", b.width, b.height);
        r = VKRT_ERROR_OUT_OF_MEMORY;
    }
    if (r == VKRT_OK) r = bench_scene_init(&b.source, o, out->error, sizeof out->error);
    if (r == VKRT_OK) r = load_scenes(&b);
    const config reference = { VKRT_BVH_BUILDER_DEFAULT, VKRT_BACKEND_CPU, VKRT_TRAVERSAL_BVH,
                               VKRT_INTERSECTOR_WATERTIGHT, VKRT_PRECISION_DOUBLE };
    if (r == VKRT_OK) r = render(&b, &reference, VKRT_MODE_ID, false, b.ref_id, NULL);
    if (r == VKRT_OK) r = render(&b, &reference, VKRT_MODE_DEPTH, false, b.ref_depth, NULL);
    if (r == VKRT_OK) r = run_configs(&b);
    if (r == VKRT_OK && o->csv_path && (r = write_csv(&b, o->csv_path)) != VKRT_OK)
        snprintf(out->error, sizeof out->error, "%s: %s", o->csv_path, vkrt_result_string(r));
    out->rows = b.row_count;
    out->validation_messages = vkrt_context_validation_messages(b.gpu) + vkrt_context_validation_messages(b.cpu);
    for (int k = 0; k < BUILDERS; k++)
        for (int m = 0; m < 2; m++) vkrt_scene_destroy(b.scenes[k][m]);
    bench_scene_free(&b.source);
    free(b.rows);
    free(b.image);
    free(b.ref_id);
    free(b.ref_depth);
    vkrt_context_destroy(b.gpu);
    vkrt_context_destroy(b.cpu);
    return r;
}
