/* `vkrt bench --modes`: the lighting modes' run time against their error.
 *
 * Every row renders the same view with seed 0; its reference is the same render on the CPU
 * backend at options->reference_spp samples per pixel with another seed (REFERENCE_SEED), so
 * the reference's noise is independent of the row's and adds its own (small) variance to the
 * row's error: the header prints that floor. Timing as in bench.c: a warm-up render at one
 * sample (lavapipe compiles each pipeline variant at its first dispatch), then the median of
 * `repeat` renders; trace time is device time on the GPU (timestamp queries) and the tracing
 * threads' on the CPU, total time the whole vkrt_render call. Rows that are compared (a mode
 * and spp on both backends, specialised and with every feature) take turns render by render. */
#include "bench_modes.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "bench_csv.h"
#include "bench_reference.h"
#include "bench_scene.h"
#include "cli_contexts.h"

/* Independent of the rows' seed 0 (any other value would do). */
#define REFERENCE_SEED 0x9E3779B9u
/* relMSE = mean of (x - ref)^2 / (ref^2 + REL_MSE_EPS): the epsilon keeps black pixels of the
 * reference from dominating (the convention of Rousselle et al., "Adaptive rendering with
 * non-local means filtering", SIGGRAPH Asia 2012). */
#define REL_MSE_EPS 1e-2
/* The rows with every feature compiled in: this spp in the full run, the largest in quick. */
#define FEATURE_ROWS_SPP 16
/* Timed renders per row at most (the median of --repeat). */
#define MAX_REPEAT 1000

typedef struct mrow {
    vkrt_mode mode;
    vkrt_backend backend;
    uint32_t spp;
    float target_error;     /* 0: every pixel takes spp samples */
    uint32_t forced;        /* 0: the specialised pipeline; VKRT_FEATURE_ALL: every feature
                               compiled in (all_features); one bit: that feature alone
                               (extra_features), so each skip is measured on its own */
    uint32_t features;      /* VKRT_FEATURE_* the render used */
    double spp_taken;       /* samples per pixel actually taken (adaptive: fewer) */
    double trace_ms, total_ms, mrays;
    double rmse, rel_mse, psnr;
} mrow;

typedef struct reference {
    float *rgba;
    bench_reference_info info;
    uint32_t spp;
} reference;

typedef struct modes {
    const bench_options *o;
    bench_scene source;
    bench_report *report;
    FILE *out;
    vkrt_context *gpu, *cpu;
    vkrt_scene *scene[2];   /* [gpu, cpu] */
    uint32_t width, height, repeat;
    size_t pixels, floats;
    float *image;
    reference ref[3];       /* shaded, ao, path */
    mrow *rows;
    unsigned row_count, row_cap;
    char gpu_skipped[1200]; /* why the GPU rows were not run (a scene beyond its limits) */
} modes;

static const vkrt_mode MODES[3] = { VKRT_MODE_SHADED, VKRT_MODE_AO, VKRT_MODE_PATH };

static const char *mode_name(vkrt_mode m)
{
    return m == VKRT_MODE_SHADED ? "shaded" : m == VKRT_MODE_AO ? "ao" : "path";
}

static const char *backend_name(vkrt_backend b) { return b == VKRT_BACKEND_CPU ? "cpu" : "gpu"; }

static vkrt_render_desc render_desc(const modes *m, vkrt_mode mode, uint32_t spp)
{
    return (vkrt_render_desc){ .width = m->width, .height = m->height, .camera = m->o->camera, .mode = mode, .spp = spp };
}

/* RMSE, relative MSE and PSNR (peak 1, of linear radiance) of the RGB of img against ref. */
static void image_errors(const float *img, const float *ref, size_t pixels, mrow *w)
{
    double se = 0.0, rel = 0.0;
    for (size_t p = 0; p < pixels; p++)
        for (int k = 0; k < 3; k++) {
            double x = img[4 * p + k], r = ref[4 * p + k], d = x - r;
            se += d * d;
            rel += d * d / (r * r + REL_MSE_EPS);
        }
    double n = 3.0 * (double)pixels, mse = se / n;
    w->rmse = sqrt(mse);
    w->rel_mse = rel / n;
    w->psnr = mse > 0.0 ? -10.0 * log10(mse) : INFINITY;
}

static vkrt_result grow_rows(modes *m, unsigned n)
{
    if (m->row_count + n <= m->row_cap) return VKRT_OK;
    unsigned cap = m->row_cap ? 2 * m->row_cap : 32;
    while (cap < m->row_count + n) cap *= 2;
    mrow *rows = realloc(m->rows, cap * sizeof *rows);
    if (!rows) return VKRT_ERROR_OUT_OF_MEMORY;
    m->rows = rows;
    m->row_cap = cap;
    return VKRT_OK;
}

static vkrt_result render(modes *m, const mrow *w, uint32_t spp, vkrt_render_stats *st)
{
    vkrt_context *ctx = w->backend == VKRT_BACKEND_CPU ? m->cpu : m->gpu;
    vkrt_render_desc d = render_desc(m, w->mode, spp);
    d.target_error = w->target_error;
    d.all_features = w->forced == VKRT_FEATURE_ALL;
    d.extra_features = w->forced == VKRT_FEATURE_ALL ? 0 : w->forced;
    vkrt_result r = vkrt_render(ctx, m->scene[w->backend == VKRT_BACKEND_CPU], &d, m->image, m->floats, st);
    if (r != VKRT_OK)
        snprintf(m->report->error, sizeof m->report->error, "render (%s %s, %u spp): %s", mode_name(w->mode),
                 backend_name(w->backend), spp, vkrt_context_last_error(ctx));
    return r;
}

/* The rows' feature column: "specialised", "all", or "+" and the one feature forced in. */
static const char *forced_name(uint32_t forced)
{
    switch (forced) {
    case 0: return "specialised";
    case VKRT_FEATURE_ALL: return "all";
    case VKRT_FEATURE_TEXTURES: return "+textures";
    case VKRT_FEATURE_PUNCTUAL: return "+punctual";
    case VKRT_FEATURE_EMITTERS: return "+emitters";
    case VKRT_FEATURE_SKY: return "+sky";
    case VKRT_FEATURE_SPECULAR: return "+specular";
    case VKRT_FEATURE_RANDOM: return "+random";
    case VKRT_FEATURE_ADAPTIVE: return "+adaptive";
    default: return "?";
    }
}

/* The most rows one group can have: 2 backends x (specialised, all, 7 single features). */
#define MAX_GROUP_ROWS 18

/* The rows of one mode and spp (or target error): each backend, and where asked each with
 * every feature compiled in and (full run) each feature the scene does not use compiled in
 * alone. Each warms up with a one-sample render of its own pipeline variant (lavapipe compiles
 * it then), then they take turns render by render, so a change of the machine's load during
 * the group slows all of them alike and their ratios stay fair. */
static vkrt_result measure_group(modes *m, vkrt_mode mode, uint32_t spp, float target, bool with_all_features,
                                 const vkrt_backend *backends, unsigned backend_count)
{
    vkrt_result r = grow_rows(m, MAX_GROUP_ROWS);
    if (r != VKRT_OK) return r;
    mrow *rows = &m->rows[m->row_count];
    unsigned n = 0;
    for (unsigned k = 0; k < backend_count; k++)
        rows[n++] = (mrow){ .mode = mode, .backend = backends[k], .spp = spp, .target_error = target };
    vkrt_render_stats st;
    for (unsigned k = 0; k < n && r == VKRT_OK; k++) {
        r = render(m, &rows[k], 1, &st);
        rows[k].features = st.features;
    }
    if (r != VKRT_OK) return r;
    if (with_all_features) {
        /* The features the specialised pipeline leaves out, as the first backend's render found. */
        const uint32_t unused = VKRT_FEATURE_ALL & ~rows[0].features;
        for (unsigned k = 0; k < backend_count; k++) {
            rows[n++] = (mrow){ .mode = mode, .backend = backends[k], .spp = spp, .target_error = target,
                                .forced = VKRT_FEATURE_ALL };
            for (uint32_t bit = 1; !m->o->quick && bit & VKRT_FEATURE_ALL; bit <<= 1)
                if (unused & bit)
                    rows[n++] = (mrow){ .mode = mode, .backend = backends[k], .spp = spp, .target_error = target,
                                        .forced = bit };
        }
        for (unsigned k = backend_count; k < n && r == VKRT_OK; k++) r = render(m, &rows[k], 1, &st);
    }
    static double trace[MAX_GROUP_ROWS][MAX_REPEAT], total[MAX_GROUP_ROWS][MAX_REPEAT];
    for (uint32_t i = 0; i < m->repeat && r == VKRT_OK; i++)
        for (unsigned k = 0; k < n && r == VKRT_OK; k++) {
            if ((r = render(m, &rows[k], spp, &st)) != VKRT_OK) break;
            trace[k][i] = st.trace_ms;
            total[k][i] = st.total_ms;
            mrow *w = &rows[k];
            w->features = st.features;
            w->spp_taken = (double)st.samples / (double)m->pixels;
            w->mrays = (double)(st.rays + st.shadow_rays + st.bounce_rays); /* rays, per second below */
            image_errors(m->image, m->ref[mode - VKRT_MODE_SHADED].rgba, m->pixels, w);
        }
    if (r != VKRT_OK) return r;
    for (unsigned k = 0; k < n; k++) {
        mrow *w = &rows[k];
        w->trace_ms = bench_median(trace[k], m->repeat);
        w->total_ms = bench_median(total[k], m->repeat);
        w->mrays = w->trace_ms > 0.0 ? w->mrays / (w->trace_ms * 1e3) : 0.0;
    }
    m->row_count += n;
    return VKRT_OK;
}

static void format_psnr(double psnr, char *buf, size_t size)
{
    if (isinf(psnr)) snprintf(buf, size, "inf");
    else snprintf(buf, size, "%.2f", psnr);
}

static void print_row(const modes *m, const mrow *w)
{
    char target[16] = "-", psnr[16];
    if (w->target_error > 0.0f) snprintf(target, sizeof target, "%g", (double)w->target_error);
    format_psnr(w->psnr, psnr, sizeof psnr);
    fprintf(m->out, "| %s | %s | %u | %s | %s | %.2f | %.2f | %.2f | %.2f | %.3e | %.3e | %s |\n", mode_name(w->mode),
            backend_name(w->backend), w->spp, target, forced_name(w->forced), w->spp_taken,
            w->trace_ms, w->total_ms, w->mrays, w->rmse, w->rel_mse, psnr);
    fflush(m->out);
}

static vkrt_result write_csv(const modes *m, const char *path, uint64_t triangles)
{
    bench_csv csv;
    vkrt_result r = bench_csv_begin(&csv, path, "scene,triangles,width,height,mode,backend,spp,target_error,features,"
                                                "feature_bits,spp_taken,trace_ms,total_ms,mrays_per_s,rmse,rel_mse,"
                                                "psnr_db,reference_spp,reference_noise");
    if (r != VKRT_OK) return r;
    for (unsigned i = 0; i < m->row_count; i++) {
        const mrow *w = &m->rows[i];
        const reference *ref = &m->ref[w->mode - VKRT_MODE_SHADED];
        char psnr[16];
        format_psnr(w->psnr, psnr, sizeof psnr);
        fprintf(csv.f, "\"%s\",%llu,%u,%u,%s,%s,%u,%g,%s,%u,%.4f,%.4f,%.4f,%.6f,%.6e,%.6e,%s,%u,%.6e\n",
                bench_scene_name(&m->source), (unsigned long long)triangles, m->width, m->height,
                mode_name(w->mode), backend_name(w->backend), w->spp, (double)w->target_error,
                forced_name(w->forced), w->features, w->spp_taken, w->trace_ms, w->total_ms, w->mrays,
                w->rmse, w->rel_mse, psnr, ref->spp, ref->info.noise);
    }
    return bench_csv_end(&csv);
}

/* The three references, from the cache or rendered (minutes at full size). */
static vkrt_result make_references(modes *m, bool progress)
{
    uint32_t spp = m->o->reference_spp ? m->o->reference_spp : m->o->quick ? 256 : 1024;
    for (int k = 0; k < 3; k++) {
        reference *ref = &m->ref[k];
        if (!(ref->rgba = malloc(m->floats * sizeof *ref->rgba))) return VKRT_ERROR_OUT_OF_MEMORY;
        vkrt_render_desc rd = render_desc(m, MODES[k], spp);
        rd.seed = REFERENCE_SEED;
        ref->spp = spp;
        if (progress) fprintf(stderr, "\rbench --modes: the %s reference, %u spp on the CPU   ", mode_name(MODES[k]), spp);
        bench_reference_desc d = { .cpu = m->cpu, .scene = m->scene[1], .scene_path = m->o->input,
                                   .scene_name = bench_scene_name(&m->source),
                                   .keep_world_coordinates = m->o->keep_world_coordinates, .render = &rd,
                                   .cache_dir = m->o->cache_dir };
        vkrt_result r = bench_reference_get(&d, ref->rgba, &ref->info, m->report->error, sizeof m->report->error);
        if (r != VKRT_OK) return r;
    }
    if (progress) fprintf(stderr, "\r%70s\r", "");
    return VKRT_OK;
}

static void print_header(const modes *m, uint64_t triangles)
{
    fprintf(m->out, "vkrt bench --modes: %s (%llu triangles), %ux%u, %s; median of %u timed render%s after a warm-up;\n"
                    "errors of linear RGB against a converged reference (CPU, another seed; relMSE epsilon %g, PSNR "
                    "peak 1):\n",
            bench_scene_name(&m->source), (unsigned long long)triangles, m->width, m->height,
            m->gpu ? vkrt_context_device_name(m->gpu) : "CPU only", m->repeat, m->repeat == 1 ? "" : "s", REL_MSE_EPS);
    for (int k = 0; k < 3; k++) {
        const reference *ref = &m->ref[k];
        fprintf(m->out, "  %s: %u spp, its own estimated error %.2e, %s in %.1f s\n", mode_name(MODES[k]), ref->spp,
                ref->info.noise, ref->info.cached ? "read from the cache" : "rendered", ref->info.ms / 1e3);
    }
    if (m->gpu_skipped[0]) fprintf(m->out, "%s\n", m->gpu_skipped);
    fprintf(m->out, "\n| mode | backend | spp | target error | features | spp taken | trace ms | total ms | Mrays/s "
                    "| RMSE | relMSE | PSNR dB |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n");
}

/* What compiling every feature in, or one feature alone, costs against the specialised
 * pipeline: row pairs of one mode, backend and spp. */
static void print_feature_savings(const modes *m)
{
    bool any = false;
    for (unsigned i = 0; i < m->row_count; i++) {
        const mrow *forced = &m->rows[i];
        if (!forced->forced) continue;
        for (unsigned j = 0; j < m->row_count; j++) {
            const mrow *sp = &m->rows[j];
            if (sp->forced || sp->target_error != forced->target_error || sp->mode != forced->mode ||
                sp->backend != forced->backend || sp->spp != forced->spp)
                continue;
            if (!any)
                fprintf(m->out, "\nfeatures compiled in although unused, against the specialised pipeline (trace time):\n");
            any = true;
            fprintf(m->out, "  %s %s %u spp, %s: %.2f ms against %.2f ms (%.2fx)\n", mode_name(forced->mode),
                    backend_name(forced->backend), forced->spp, forced_name(forced->forced), forced->trace_ms,
                    sp->trace_ms, sp->trace_ms > 0.0 ? forced->trace_ms / sp->trace_ms : 0.0);
        }
    }
}

static vkrt_result run_rows(modes *m)
{
    static const uint32_t full_spp[] = BENCH_MODES_SPP, quick_spp[] = BENCH_MODES_QUICK_SPP;
    static const float targets[] = BENCH_MODES_TARGETS;
    /* The ladder: powers of 4 up to --max-spp, or the default rungs. */
    uint32_t ladder[10];
    const uint32_t *spps = m->o->quick ? quick_spp : full_spp;
    unsigned spp_count = m->o->quick ? sizeof quick_spp / sizeof *quick_spp : sizeof full_spp / sizeof *full_spp;
    if (m->o->max_spp) {
        spp_count = 0;
        for (uint32_t spp = 1; spp <= m->o->max_spp && spp_count < 10; spp *= 4) ladder[spp_count++] = spp;
        spps = ladder;
    }
    const unsigned target_count = sizeof targets / sizeof *targets;
    const uint32_t adaptive_spp = m->o->quick ? BENCH_MODES_QUICK_ADAPTIVE_SPP : spps[spp_count - 1];
    const uint32_t feature_spp = m->o->quick ? spps[spp_count - 1] : FEATURE_ROWS_SPP;
    vkrt_backend backends[2];
    unsigned nb = 0;
    if (m->scene[0]) backends[nb++] = VKRT_BACKEND_GPU;
    if (m->o->backend != VKRT_BACKEND_GPU) backends[nb++] = VKRT_BACKEND_CPU;
    const unsigned groups = spp_count + target_count;
    const bool progress = m->o->progress && isatty(STDERR_FILENO);
    for (int k = 0; k < 3; k++) {
        for (unsigned g = 0; g < groups; g++) {
            /* the spp rows (one of them with every feature compiled in too), then the adaptive ones */
            uint32_t spp = g < spp_count ? spps[g] : adaptive_spp;
            float target = g < spp_count ? 0.0f : targets[g - spp_count];
            if (progress)
                fprintf(stderr, "\rbench --modes: %u/%u %s %u spp%s   ", k * groups + g + 1, 3 * groups,
                        mode_name(MODES[k]), spp, target > 0.0f ? " adaptive" : "");
            unsigned first = m->row_count;
            vkrt_result r = measure_group(m, MODES[k], spp, target, target == 0.0f && spp == feature_spp, backends, nb);
            if (r != VKRT_OK) return r;
            for (unsigned i = first; i < m->row_count; i++) print_row(m, &m->rows[i]);
        }
    }
    if (progress) fprintf(stderr, "\r%70s\r", "");
    print_feature_savings(m);
    return VKRT_OK;
}

vkrt_result bench_modes_run(const bench_options *o, bench_report *out)
{
    memset(out, 0, sizeof *out);
    modes m = { .o = o, .report = out, .out = o->out ? o->out : stdout };
    m.width = o->width ? o->width : o->quick ? 64 : 128;
    m.height = o->height ? o->height : o->quick ? 64 : 128;
    m.repeat = o->repeat ? o->repeat : o->quick ? 1 : 3;
    if (m.repeat > MAX_REPEAT) m.repeat = MAX_REPEAT;
    m.pixels = (size_t)m.width * m.height;
    m.floats = vkrt_render_floats(m.width, m.height);
    vkrt_result r = cli_contexts_create(&o->context, o->backend != VKRT_BACKEND_CPU, &m.gpu, &m.cpu, out->error,
                                        sizeof out->error);
    if (r == VKRT_OK) r = bench_scene_init(&m.source, o, out->error, sizeof out->error);
    if (r == VKRT_OK && !(m.image = malloc(m.floats * sizeof *m.image))) {
        snprintf(out->error, sizeof out->error, "out of memory for a %ux%u image", m.width, m.height);
        r = VKRT_ERROR_OUT_OF_MEMORY;
    }
    for (int k = 0; k < 2 && r == VKRT_OK; k++) {
        vkrt_context *ctx = k ? m.cpu : m.gpu;
        if (!ctx) continue;
        vkrt_scene_desc d = bench_scene_desc(&m.source);
        r = bench_scene_create(ctx, k ? NULL : BENCH_GPU_BACKEND_ROWS, &d, &m.scene[k], m.gpu_skipped,
                               sizeof m.gpu_skipped, out->error, sizeof out->error);
    }
    vkrt_scene_stats s = { 0 };
    if (r == VKRT_OK) vkrt_scene_stats_get(m.scene[1], &s);
    if (r == VKRT_OK) r = make_references(&m, o->progress && isatty(STDERR_FILENO));
    if (r == VKRT_OK) print_header(&m, s.triangles);
    if (r == VKRT_OK) r = run_rows(&m);
    if (r == VKRT_ERROR_OUT_OF_MEMORY && !out->error[0]) snprintf(out->error, sizeof out->error, "out of memory");
    if (r == VKRT_OK && o->csv_path && (r = write_csv(&m, o->csv_path, s.triangles)) != VKRT_OK)
        snprintf(out->error, sizeof out->error, "%s: %s", o->csv_path, vkrt_result_string(r));
    out->rows = m.row_count;
    out->validation_messages = vkrt_context_validation_messages(m.gpu) + vkrt_context_validation_messages(m.cpu);
    for (int k = 0; k < 3; k++) free(m.ref[k].rgba);
    vkrt_scene_destroy(m.scene[0]);
    vkrt_scene_destroy(m.scene[1]);
    bench_scene_free(&m.source);
    free(m.rows);
    free(m.image);
    vkrt_context_destroy(m.gpu);
    vkrt_context_destroy(m.cpu);
    return r;
}
