/* `vkrt bench --compare embree`: the same rays on the same triangles through vkrt_trace_rays
 * (CPU and GPU backends) and Embree 3, so vkrt's speed has a published yardstick measured in
 * the same run on the same machine. Uses vkrt.h and bench_embree.h only.
 *
 * The triangles are the scene's as vkrt traces them (vkrt_scene_triangles_get, in prim_id
 * order, so Embree's primID is vkrt's prim_id). The rays: the primary rays of the view
 * (vkrt_camera_rays: pixel centres, bit for bit what vkrt_render traces), then, from each of
 * their closest hits on vkrt's CPU backend, BENCH_COMPARE_AO_RAYS_PER_HIT cosine-distributed
 * rays about the geometric normal from vkrt_ray_offset's origin, up to
 * BENCH_COMPARE_AO_DISTANCE: what the ao mode traces, as one array every engine gets. Each
 * engine's time is the wall-clock time of the whole call (threads started and joined; on the
 * GPU also the upload of the rays and the readback of the hits), the median of `repeat` calls
 * after a warm-up; its checksums (hits, sum of t) and its hits ray by ray are compared with
 * Embree's. */
#include "bench_compare.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "bench_csv.h"
#include "bench_embree.h"
#include "bench_scene.h"
#include "cli_contexts.h"

/* Two closest hits on different triangles are still the same point when their distances agree
 * this closely (relative; with an absolute floor for the short AO distances): a ray through a
 * shared edge may name either triangle. On the same triangle they are the same hit whatever
 * the distances: vkrt refines its distances in double, Embree reports float ones, which differ
 * most on grazing rays (the t_rel_max column). */
#define SAME_T_REL 1e-5
#define SAME_T_ABS 1e-7

typedef enum query { QUERY_PRIMARY, QUERY_AO_CLOSEST, QUERY_AO_ANY, QUERY_COUNT } query;
typedef enum engine { ENGINE_EMBREE, ENGINE_VKRT_CPU, ENGINE_VKRT_GPU, ENGINE_COUNT } engine;

static const char *query_rays(query q) { return q == QUERY_PRIMARY ? "primary" : "ao"; }
static const char *query_name(query q) { return q == QUERY_AO_ANY ? "any" : "closest"; }
static const char *engine_name(engine e)
{
    return e == ENGINE_EMBREE ? "embree" : e == ENGINE_VKRT_CPU ? "vkrt-cpu" : "vkrt-gpu";
}

typedef struct crow {
    query q;
    engine e;
    size_t rays;
    double build_ms, bytes_per_tri;
    double trace_ms, mrays, ratio; /* ratio: Mrays/s over Embree's for the same rays and query */
    double device_ms;              /* vkrt-gpu: the median of the calls' device times (vkrt_trace_stats);
                                      negative for the other engines */
    uint64_t hits;
    double sum_t;                  /* closest queries only */
    uint64_t mismatches;           /* rays whose answer differs from Embree's */
    double t_rel_max;              /* the largest relative difference of t from Embree's where both
                                      hit (closest queries) */
} crow;

typedef struct compare {
    const bench_options *o;
    bench_scene source;
    bench_report *report;
    FILE *out;
    vkrt_context *gpu, *cpu;
    vkrt_scene *scene[ENGINE_COUNT];   /* [ENGINE_VKRT_CPU], [ENGINE_VKRT_GPU] */
    vkrt_scene_stats stats[ENGINE_COUNT];
    bench_embree *embree;
    double embree_build_ms;
    uint64_t embree_bytes;
    uint32_t width, height, repeat, threads;
    vkrt_ray *rays[2];                 /* primary, ao */
    size_t ray_count[2];
    vkrt_hit *hits[ENGINE_COUNT];      /* the last query's, per engine */
    crow rows[QUERY_COUNT * ENGINE_COUNT];
    unsigned row_count;
    char gpu_skipped[1200];            /* why vkrt-gpu was not run (a scene beyond its limits) */
} compare;

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* Embree always; vkrt's backends as options->backend says. The CPU scene is loaded either way:
 * the triangles and the AO rays come from it. */
static bool engine_runs(const compare *c, engine e)
{
    if (e == ENGINE_VKRT_CPU) return c->o->backend != VKRT_BACKEND_GPU;
    return e == ENGINE_EMBREE || c->scene[e] != NULL;
}

/* splitmix64's finaliser: independent uniform numbers from a ray's index, the same in every
 * run and on every machine. */
static uint64_t mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
}

static float uniform(uint64_t key)
{
    return (float)(mix64(key * 0x9E3779B97F4A7C15ull + 1) >> 40) * 0x1p-24f;
}

/* The AO rays from the closest hits of the primary rays (on vkrt's triangles). */
static vkrt_result make_ao_rays(compare *c, const vkrt_hit *primary, const float *tris)
{
    size_t n = c->ray_count[0];
    vkrt_ray *ao = malloc(n * BENCH_COMPARE_AO_RAYS_PER_HIT * sizeof *ao);
    if (!ao) return VKRT_ERROR_OUT_OF_MEMORY;
    size_t count = 0;
    for (size_t i = 0; i < n; i++) {
        const vkrt_hit *h = &primary[i];
        if (h->prim_id == VKRT_NO_HIT) continue;
        const float *v = tris + (size_t)h->prim_id * 9;
        float w = 1.0f - h->u - h->v, p[3], e1[3], e2[3], ng[3];
        for (int a = 0; a < 3; a++) {
            p[a] = v[a] * w + v[3 + a] * h->u + v[6 + a] * h->v; /* as the lighting modes' hit point */
            e1[a] = v[3 + a] - v[a];
            e2[a] = v[6 + a] - v[a];
        }
        ng[0] = e1[1] * e2[2] - e1[2] * e2[1];
        ng[1] = e1[2] * e2[0] - e1[0] * e2[2];
        ng[2] = e1[0] * e2[1] - e1[1] * e2[0];
        float len = sqrtf(ng[0] * ng[0] + ng[1] * ng[1] + ng[2] * ng[2]);
        if (!(len > 0.0f)) continue;
        const float *d = c->rays[0][i].dir;
        float facing = ng[0] * d[0] + ng[1] * d[1] + ng[2] * d[2] > 0.0f ? -1.0f / len : 1.0f / len;
        for (int a = 0; a < 3; a++) ng[a] *= facing;
        float origin[3];
        vkrt_ray_offset(p, ng, origin);
        /* An orthonormal basis about ng: Duff et al., "Building an Orthonormal Basis, Revisited",
         * JCGT 6(1), 2017. */
        float sign = copysignf(1.0f, ng[2]), ia = -1.0f / (sign + ng[2]), b = ng[0] * ng[1] * ia;
        const float t[3] = { 1.0f + sign * ng[0] * ng[0] * ia, sign * b, -sign * ng[0] };
        const float bt[3] = { b, sign + ng[1] * ng[1] * ia, -ng[1] };
        for (int k = 0; k < BENCH_COMPARE_AO_RAYS_PER_HIT; k++) {
            uint64_t key = (uint64_t)i * BENCH_COMPARE_AO_RAYS_PER_HIT + (uint64_t)k;
            float u1 = uniform(2 * key), u2 = uniform(2 * key + 1);
            float r = sqrtf(u1), phi = 6.2831853f * u2, x = r * cosf(phi), y = r * sinf(phi), z = sqrtf(fmaxf(0.0f, 1.0f - u1));
            vkrt_ray *o = &ao[count++];
            *o = (vkrt_ray){ .tmax = BENCH_COMPARE_AO_DISTANCE };
            memcpy(o->origin, origin, sizeof origin);
            for (int a = 0; a < 3; a++) o->dir[a] = t[a] * x + bt[a] * y + ng[a] * z;
        }
    }
    c->rays[1] = ao;
    c->ray_count[1] = count;
    return VKRT_OK;
}

/* One call of engine e on query q's rays into out; *ms: its wall-clock time; *device_ms: the
 * GPU's device time of it (vkrt-gpu), else -1. */
static vkrt_result trace(compare *c, engine e, query q, vkrt_hit *out, double *ms, double *device_ms)
{
    const vkrt_ray *rays = c->rays[q != QUERY_PRIMARY];
    size_t n = c->ray_count[q != QUERY_PRIMARY];
    bool any_hit = q == QUERY_AO_ANY;
    *device_ms = -1.0;
    if (e == ENGINE_EMBREE)
        return bench_embree_trace(c->embree, rays, n, any_hit, out, ms, c->report->error, sizeof c->report->error);
    vkrt_context *ctx = e == ENGINE_VKRT_CPU ? c->cpu : c->gpu;
    vkrt_trace_stats stats = { 0 };
    double t0 = now_ms();
    vkrt_result r = vkrt_trace_rays(ctx, c->scene[e], &(vkrt_trace_desc){ .any_hit = any_hit, .out_stats = &stats },
                                    rays, n, out);
    *ms = now_ms() - t0;
    if (e == ENGINE_VKRT_GPU) *device_ms = stats.trace_ms;
    if (r != VKRT_OK)
        snprintf(c->report->error, sizeof c->report->error, "vkrt_trace_rays (%s, %s %s rays): %s", engine_name(e),
                 query_rays(q), query_name(q), vkrt_context_last_error(ctx));
    return r;
}

/* Rays where w's engine (hits a) and Embree (ref) disagree: a hit against a miss, or (closest
 * hits) another triangle at another distance; and the largest relative difference of t. */
static void compare_hits(const vkrt_hit *a, const vkrt_hit *ref, size_t n, bool any_hit, crow *w)
{
    for (size_t i = 0; i < n; i++) {
        bool hit = a[i].prim_id != VKRT_NO_HIT, ref_hit = ref[i].prim_id != VKRT_NO_HIT;
        if (hit != ref_hit) {
            w->mismatches++;
            continue;
        }
        if (!hit || any_hit) continue;
        double diff = fabs((double)a[i].t - (double)ref[i].t);
        if (a[i].prim_id != ref[i].prim_id && diff > SAME_T_REL * (double)ref[i].t + SAME_T_ABS) {
            w->mismatches++;
            continue;
        }
        w->t_rel_max = fmax(w->t_rel_max, diff / (double)ref[i].t);
    }
}

/* Each engine's figures for query q. The engines take turns, call by call (warm-ups first),
 * so a change of the machine's load during the run slows all of them alike and the ratios
 * stay fair. */
static vkrt_result measure_query(compare *c, query q)
{
    crow *rows = &c->rows[c->row_count];
    engine order[ENGINE_COUNT];
    unsigned n = 0;
    for (engine e = 0; e < ENGINE_COUNT; e++) {
        if (!engine_runs(c, e)) continue;
        crow *w = &rows[n];
        order[n++] = e;
        *w = (crow){ .q = q, .e = e, .rays = c->ray_count[q != QUERY_PRIMARY] };
        if (e == ENGINE_EMBREE) {
            w->build_ms = c->embree_build_ms;
            w->bytes_per_tri = (double)c->embree_bytes / (double)c->stats[ENGINE_VKRT_CPU].triangles;
        } else {
            const vkrt_scene_stats *s = &c->stats[e];
            w->build_ms = s->build_ms;
            w->bytes_per_tri = (double)s->traversal_bytes / (double)s->triangles;
        }
    }
    double ms[ENGINE_COUNT][1001], device_ms[ENGINE_COUNT][1001];
    for (uint32_t i = 0; i <= c->repeat; i++) /* call 0: the warm-up */
        for (unsigned k = 0; k < n; k++) {
            vkrt_result r = trace(c, order[k], q, c->hits[order[k]], &ms[k][i], &device_ms[k][i]);
            if (r != VKRT_OK) return r;
        }
    const crow *embree = &rows[0]; /* ENGINE_EMBREE always runs, first */
    for (unsigned k = 0; k < n; k++) {
        crow *w = &rows[k];
        w->trace_ms = bench_median(ms[k] + 1, c->repeat);
        w->device_ms = bench_median(device_ms[k] + 1, c->repeat);
        w->mrays = w->trace_ms > 0.0 ? (double)w->rays / (w->trace_ms * 1e3) : 0.0;
        w->ratio = embree->mrays > 0.0 ? w->mrays / embree->mrays : 0.0;
        for (size_t i = 0; i < w->rays; i++) {
            const vkrt_hit *h = &c->hits[order[k]][i];
            if (h->prim_id == VKRT_NO_HIT) continue;
            w->hits++;
            if (q != QUERY_AO_ANY) w->sum_t += (double)h->t;
        }
        if (k) compare_hits(c->hits[order[k]], c->hits[ENGINE_EMBREE], w->rays, q == QUERY_AO_ANY, w);
    }
    c->row_count += n;
    return VKRT_OK;
}

static void print_header(const compare *c)
{
    const vkrt_scene_stats *s = &c->stats[ENGINE_VKRT_CPU];
    fprintf(c->out, "vkrt bench --compare embree: %s (%llu triangles), %ux%u; Embree %s and vkrt's CPU backend (%s "
                    "code) on %u thread%s, GPU %s;\nmedian of %u timed call%s after a warm-up, wall-clock time of the whole call "
                    "(on the GPU with the upload of the rays and the readback of the hits, and on a CPU device the host's "
                    "triangle lists for rays that share an origin; device ms: the median of the same calls' device time, "
                    "timestamps around the trace dispatches);\nprimary rays through the "
                    "pixel centres, then %d cosine-distributed AO rays per primary hit from vkrt_ray_offset origins, "
                    "up to distance %g\n\n",
            bench_scene_name(&c->source), (unsigned long long)s->triangles, c->width, c->height,
            bench_embree_version(), vkrt_cpu_code(), c->threads, c->threads == 1 ? "" : "s",
            c->gpu ? vkrt_context_device_name(c->gpu) : "not run", c->repeat, c->repeat == 1 ? "" : "s",
            BENCH_COMPARE_AO_RAYS_PER_HIT, (double)BENCH_COMPARE_AO_DISTANCE);
    if (c->gpu_skipped[0]) fprintf(c->out, "%s\n\n", c->gpu_skipped);
    if (s->alpha_tested)
        fprintf(c->out, "alpha-masked materials: vkrt passes through masked texels, Embree sees every triangle; the "
                        "checksums differ by design\n\n");
    fprintf(c->out, "| rays | query | engine | rays traced | build ms | bytes/tri | trace ms | device ms | Mrays/s "
                    "| vkrt/Embree | hits | sum of t | mismatches | max t diff |\n"
                    "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
}

static void print_row(const compare *c, const crow *w)
{
    char sum[32] = "-", device[32] = "-";
    if (w->q != QUERY_AO_ANY) snprintf(sum, sizeof sum, "%.6e", w->sum_t);
    if (w->device_ms >= 0.0) snprintf(device, sizeof device, "%.2f", w->device_ms);
    fprintf(c->out, "| %s | %s | %s | %zu | %.1f | %.1f | %.2f | %s | %.2f | %.2f | %llu | %s | %llu | %.1e |\n",
            query_rays(w->q), query_name(w->q), engine_name(w->e), w->rays, w->build_ms, w->bytes_per_tri, w->trace_ms,
            device, w->mrays, w->ratio, (unsigned long long)w->hits, sum, (unsigned long long)w->mismatches,
            w->t_rel_max);
    fflush(c->out);
}

static vkrt_result write_csv(const compare *c, const char *path)
{
    bench_csv csv;
    vkrt_result r = bench_csv_begin(&csv, path, "scene,triangles,width,height,threads,rays,query,engine,ray_count,"
                                                "build_ms,bytes_per_triangle,trace_ms,mrays_per_s,ratio_to_embree,"
                                                "hits,sum_t,mismatches,t_rel_max,device_ms");
    if (r != VKRT_OK) return r;
    for (unsigned i = 0; i < c->row_count; i++) {
        const crow *w = &c->rows[i];
        char sum[32] = "", device[32] = "";
        if (w->q != QUERY_AO_ANY) snprintf(sum, sizeof sum, "%.9e", w->sum_t);
        if (w->device_ms >= 0.0) snprintf(device, sizeof device, "%.4f", w->device_ms);
        fprintf(csv.f, "\"%s\",%llu,%u,%u,%u,%s,%s,%s,%zu,%.4f,%.3f,%.4f,%.6f,%.6f,%llu,%s,%llu,%.3e,%s\n",
                bench_scene_name(&c->source), (unsigned long long)c->stats[ENGINE_VKRT_CPU].triangles,
                c->width, c->height, c->threads, query_rays(w->q), query_name(w->q), engine_name(w->e), w->rays,
                w->build_ms, w->bytes_per_tri, w->trace_ms, w->mrays, w->ratio, (unsigned long long)w->hits, sum,
                (unsigned long long)w->mismatches, w->t_rel_max, device);
    }
    return bench_csv_end(&csv);
}

/* Engine e's scene (a vkrt backend) made from the run's source; *out stays NULL where the GPU
 * scene is beyond the device, skipped (skipped_size bytes) then says why. */
static vkrt_result create_scene(compare *c, engine e, vkrt_scene **out, char *skipped, size_t skipped_size)
{
    vkrt_scene_desc d = bench_scene_desc(&c->source);
    return bench_scene_create(e == ENGINE_VKRT_CPU ? c->cpu : c->gpu, e == ENGINE_VKRT_GPU ? BENCH_GPU_BACKEND_ROWS : NULL,
                              &d, out, skipped, skipped_size, c->report->error, sizeof c->report->error);
}

/* The builds timed again until each engine has c->repeat of them, the engines taking turns
 * build by build (Embree, the CPU scene, the GPU scene), and the median of each engine's kept as
 * its build time: a single build of the full dragon measured 0.86-1.24x Embree's from one run to
 * the next on a two-core host, where the traces' medians vary far less. Each extra scene is
 * made from the same source and destroyed at once. */
static vkrt_result time_builds(compare *c, const float *triangles, size_t tri_count)
{
    if (c->repeat < 2) return VKRT_OK;
    double *ms = malloc((size_t)ENGINE_COUNT * c->repeat * sizeof *ms);
    if (!ms) {
        snprintf(c->report->error, sizeof c->report->error, "out of memory timing %u builds", c->repeat);
        return VKRT_ERROR_OUT_OF_MEMORY;
    }
    bool timed[ENGINE_COUNT] = { false };
    for (engine e = 0; e < ENGINE_COUNT; e++) {
        timed[e] = e == ENGINE_EMBREE || c->scene[e] != NULL;
        ms[(size_t)e * c->repeat] = e == ENGINE_EMBREE ? c->embree_build_ms : c->stats[e].build_ms;
    }
    vkrt_result r = VKRT_OK;
    for (uint32_t k = 1; r == VKRT_OK && k < c->repeat; k++) {
        for (engine e = 0; r == VKRT_OK && e < ENGINE_COUNT; e++) {
            if (!timed[e]) continue;
            double *slot = &ms[(size_t)e * c->repeat + k];
            if (e == ENGINE_EMBREE) {
                bench_embree *again = NULL;
                uint64_t bytes = 0;
                r = bench_embree_create(triangles, tri_count, c->threads, &again, slot, &bytes, c->report->error,
                                        sizeof c->report->error);
                bench_embree_destroy(again);
                continue;
            }
            vkrt_scene *again = NULL;
            char skipped[sizeof c->gpu_skipped];
            r = create_scene(c, e, &again, skipped, sizeof skipped);
            vkrt_scene_stats st = { 0 };
            if (r == VKRT_OK && !again) {
                /* The device had room for one GPU scene, not two: keep the first build's time. */
                timed[e] = false;
                continue;
            }
            if (r == VKRT_OK) r = vkrt_scene_stats_get(again, &st);
            *slot = st.build_ms;
            vkrt_scene_destroy(again);
        }
    }
    for (engine e = 0; r == VKRT_OK && e < ENGINE_COUNT; e++) {
        if (!timed[e]) continue;
        const double median = bench_median(&ms[(size_t)e * c->repeat], c->repeat);
        if (e == ENGINE_EMBREE) c->embree_build_ms = median;
        else c->stats[e].build_ms = median;
    }
    free(ms);
    return r;
}

/* vkrt's scenes, the triangles they trace (checked equal on both backends) and Embree's scene
 * of them. */
static vkrt_result load(compare *c)
{
    for (engine e = ENGINE_VKRT_CPU; e <= ENGINE_VKRT_GPU; e++) {
        vkrt_context *ctx = e == ENGINE_VKRT_CPU ? c->cpu : c->gpu;
        if (!ctx) continue;
        vkrt_result r = create_scene(c, e, &c->scene[e], c->gpu_skipped, sizeof c->gpu_skipped);
        if (r != VKRT_OK) return r;
        if (c->scene[e]) vkrt_scene_stats_get(c->scene[e], &c->stats[e]);
    }
    const bool gpu = c->scene[ENGINE_VKRT_GPU] != NULL;
    size_t n = c->stats[ENGINE_VKRT_CPU].triangles * 9;
    float *tris[2] = { malloc(n * sizeof(float)), gpu ? malloc(n * sizeof(float)) : NULL };
    vkrt_result r = tris[0] && (tris[1] || !gpu) ? VKRT_OK : VKRT_ERROR_OUT_OF_MEMORY;
    if (r == VKRT_OK) r = vkrt_scene_triangles_get(c->scene[ENGINE_VKRT_CPU], tris[0], n);
    if (r == VKRT_OK && gpu) r = vkrt_scene_triangles_get(c->scene[ENGINE_VKRT_GPU], tris[1], n);
    if (r != VKRT_OK) {
        snprintf(c->report->error, sizeof c->report->error, "the scene's triangles: %s", vkrt_result_string(r));
    } else if (gpu && memcmp(tris[0], tris[1], n * sizeof(float)) != 0) {
        snprintf(c->report->error, sizeof c->report->error, "the CPU and GPU scenes hold different triangles");
        r = VKRT_ERROR_INVALID_GEOMETRY;
    }
    if (r == VKRT_OK)
        r = bench_embree_create(tris[0], n / 9, c->threads, &c->embree, &c->embree_build_ms, &c->embree_bytes,
                                c->report->error, sizeof c->report->error);
    if (r == VKRT_OK) r = time_builds(c, tris[0], n / 9);
    /* The primary rays, and their closest hits on the CPU backend for the AO rays. */
    size_t pixels = (size_t)c->width * c->height;
    if (r == VKRT_OK && !(c->rays[0] = malloc(pixels * sizeof *c->rays[0]))) r = VKRT_ERROR_OUT_OF_MEMORY;
    if (r == VKRT_OK && (r = vkrt_camera_rays(c->cpu, &c->o->camera, c->width, c->height, c->rays[0], pixels)) != VKRT_OK)
        snprintf(c->report->error, sizeof c->report->error, "%s", vkrt_context_last_error(c->cpu));
    c->ray_count[0] = pixels;
    vkrt_hit *primary = r == VKRT_OK ? malloc(pixels * sizeof *primary) : NULL;
    if (r == VKRT_OK && !primary) r = VKRT_ERROR_OUT_OF_MEMORY;
    if (r == VKRT_OK &&
        (r = vkrt_trace_rays(c->cpu, c->scene[ENGINE_VKRT_CPU], NULL, c->rays[0], pixels, primary)) != VKRT_OK)
        snprintf(c->report->error, sizeof c->report->error, "%s", vkrt_context_last_error(c->cpu));
    if (r == VKRT_OK) r = make_ao_rays(c, primary, tris[0]);
    size_t most = c->ray_count[0] > c->ray_count[1] ? c->ray_count[0] : c->ray_count[1];
    for (engine e = 0; r == VKRT_OK && e < ENGINE_COUNT; e++)
        if (!(c->hits[e] = malloc((most ? most : 1) * sizeof *c->hits[e]))) r = VKRT_ERROR_OUT_OF_MEMORY;
    if (r == VKRT_ERROR_OUT_OF_MEMORY && !c->report->error[0])
        snprintf(c->report->error, sizeof c->report->error, "out of memory for %zu rays", pixels);
    free(primary);
    free(tris[0]);
    free(tris[1]);
    return r;
}

static vkrt_result run_rows(compare *c)
{
    print_header(c);
    const bool progress = c->o->progress && isatty(STDERR_FILENO);
    for (query q = 0; q < QUERY_COUNT; q++) {
        if (progress) fprintf(stderr, "\rbench --compare: %d/%d %s rays, %s hits   ", q + 1, QUERY_COUNT, query_rays(q), query_name(q));
        unsigned first = c->row_count;
        vkrt_result r = measure_query(c, q);
        if (r != VKRT_OK) return r;
        for (unsigned i = first; i < c->row_count; i++) print_row(c, &c->rows[i]);
    }
    if (progress) fprintf(stderr, "\r%60s\r", "");
    return VKRT_OK;
}

vkrt_result bench_compare_run(const bench_options *o, bench_report *out)
{
    memset(out, 0, sizeof *out);
    compare c = { .o = o, .report = out, .out = o->out ? o->out : stdout };
    c.width = o->width ? o->width : o->quick ? 64 : 512;
    c.height = o->height ? o->height : o->quick ? 64 : 512;
    c.repeat = o->repeat ? o->repeat : o->quick ? 1 : 5;
    if (c.repeat > 1000) c.repeat = 1000;
    /* Embree gets the threads vkrt's CPU backend uses: the context's, or one per online core. */
    long cores = sysconf(_SC_NPROCESSORS_ONLN);
    c.threads = o->context.cpu_threads ? o->context.cpu_threads : cores > 0 ? (uint32_t)cores : 1;
    vkrt_result r = cli_contexts_create(&o->context, o->backend != VKRT_BACKEND_CPU, &c.gpu, &c.cpu, out->error,
                                        sizeof out->error);
    if (r == VKRT_OK) r = bench_scene_init(&c.source, o, out->error, sizeof out->error);
    if (r == VKRT_OK) r = load(&c);
    if (r == VKRT_OK) r = run_rows(&c);
    if (r == VKRT_OK && o->csv_path && (r = write_csv(&c, o->csv_path)) != VKRT_OK)
        snprintf(out->error, sizeof out->error, "%s: %s", o->csv_path, vkrt_result_string(r));
    out->rows = c.row_count;
    out->validation_messages = vkrt_context_validation_messages(c.gpu) + vkrt_context_validation_messages(c.cpu);
    for (engine e = 0; e < ENGINE_COUNT; e++) {
        vkrt_scene_destroy(c.scene[e]);
        free(c.hits[e]);
    }
    free(c.rays[0]);
    free(c.rays[1]);
    bench_embree_destroy(c.embree);
    bench_scene_free(&c.source);
    vkrt_context_destroy(c.gpu);
    vkrt_context_destroy(c.cpu);
    return r;
}
