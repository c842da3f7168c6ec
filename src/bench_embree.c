/* Embree 3 (Wald et al., "Embree: A Kernel Framework for Efficient CPU Ray Tracing", ACM TOG
 * 33(4), 2014) on vkrt's triangles and rays, for `vkrt bench --compare embree`. The scene is
 * one RTC_GEOMETRY_TYPE_TRIANGLE geometry holding the triangles in prim_id order, three
 * vertices each (not welded: vkrt traces each triangle's own corners too). Rays are traced one
 * at a time (rtcIntersect1, rtcOccluded1) from `threads` threads that take blocks of rays from
 * a shared counter, the way vkrt's CPU backend splits vkrt_trace_rays. */
#include "bench_embree.h"

#include <embree3/rtcore.h>
#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* Rays per block a thread takes at a time: vkrt's CPU backend takes 1024 (cpu_trace.c). */
#define RAY_BLOCK 1024
/* Beyond this, threads add nothing on any machine the bench runs on. */
#define MAX_THREADS 256

struct bench_embree {
    RTCDevice device;
    RTCScene scene;
    uint32_t threads;
    atomic_llong bytes, peak_bytes; /* the memory monitor's running total and its maximum */
    enum RTCError code;             /* the last error Embree's callback reported */
    char error[512];                /* and its message */
};

const char *bench_embree_version(void)
{
    return RTC_VERSION_STRING;
}

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

static void on_error(void *user, enum RTCError code, const char *message)
{
    bench_embree *e = user;
    e->code = code;
    snprintf(e->error, sizeof e->error, "Embree error %d: %s", (int)code, message ? message : "");
}

/* vkrt's code for an Embree error: memory, a CPU Embree cannot run on, or anything else. */
static vkrt_result result_of(enum RTCError code)
{
    switch (code) {
    case RTC_ERROR_OUT_OF_MEMORY: return VKRT_ERROR_OUT_OF_MEMORY;
    case RTC_ERROR_UNSUPPORTED_CPU: return VKRT_ERROR_UNSUPPORTED;
    default: return VKRT_ERROR_LIMIT;
    }
}

/* Called from Embree's threads: a running total of what it allocated, and its peak. */
static bool on_memory(void *user, ssize_t bytes, bool post)
{
    (void)post;
    bench_embree *e = user;
    long long now = atomic_fetch_add(&e->bytes, (long long)bytes) + (long long)bytes;
    long long peak = atomic_load(&e->peak_bytes);
    while (now > peak && !atomic_compare_exchange_weak(&e->peak_bytes, &peak, now)) {}
    return true;
}

void bench_embree_destroy(bench_embree *e)
{
    if (!e) return;
    if (e->scene) rtcReleaseScene(e->scene);
    if (e->device) rtcReleaseDevice(e->device);
    free(e);
}

vkrt_result bench_embree_create(const float *triangles, size_t count, uint32_t threads, bench_embree **out,
                                double *out_build_ms, uint64_t *out_bytes, char *error, size_t error_size)
{
    *out = NULL;
    if (count > UINT32_MAX / 3) {
        snprintf(error, error_size, "Embree: %zu triangles exceed 32-bit vertex indices", count);
        return VKRT_ERROR_LIMIT;
    }
    bench_embree *e = calloc(1, sizeof *e);
    if (!e) {
        snprintf(error, error_size, "out of memory for the Embree scene");
        return VKRT_ERROR_OUT_OF_MEMORY;
    }
    e->threads = threads < 1 ? 1 : threads > MAX_THREADS ? MAX_THREADS : threads;
    char config[64];
    snprintf(config, sizeof config, "threads=%u", e->threads);
    vkrt_result r = VKRT_ERROR_OUT_OF_MEMORY;
    if (!(e->device = rtcNewDevice(config))) {
        enum RTCError code = rtcGetDeviceError(NULL);
        snprintf(error, error_size, "rtcNewDevice(\"%s\") failed: Embree error %d", config, (int)code);
        r = result_of(code);
        goto fail;
    }
    rtcSetDeviceErrorFunction(e->device, on_error, e);
    rtcSetDeviceMemoryMonitorFunction(e->device, on_memory, e);
    e->scene = rtcNewScene(e->device);
    RTCGeometry g = rtcNewGeometry(e->device, RTC_GEOMETRY_TYPE_TRIANGLE);
    /* Embree reads vertex buffers 16 bytes at a time: the shared buffer it allocates pads the
     * last vertex. */
    float *v = g ? rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 3 * sizeof(float), 3 * count) : NULL;
    uint32_t *idx = g ? rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 3 * sizeof(uint32_t), count) : NULL;
    if (!e->scene || !v || !idx) {
        if (g) rtcReleaseGeometry(g);
        snprintf(error, error_size, "Embree scene: %s", e->error[0] ? e->error : "allocation failed");
        if (e->error[0]) r = result_of(e->code);
        goto fail;
    }
    memcpy(v, triangles, count * 9 * sizeof *v);
    for (size_t i = 0; i < 3 * count; i++) idx[i] = (uint32_t)i;
    rtcSetGeometryBuildQuality(g, RTC_BUILD_QUALITY_MEDIUM);
    rtcCommitGeometry(g);
    rtcAttachGeometry(e->scene, g); /* geomID 0 */
    rtcReleaseGeometry(g);          /* the scene holds it */
    rtcSetSceneFlags(e->scene, RTC_SCENE_FLAG_NONE);
    rtcSetSceneBuildQuality(e->scene, RTC_BUILD_QUALITY_MEDIUM);
    double t0 = now_ms();
    rtcCommitScene(e->scene);
    *out_build_ms = now_ms() - t0;
    if (e->error[0]) {
        snprintf(error, error_size, "rtcCommitScene: %s", e->error);
        r = result_of(e->code);
        goto fail;
    }
    *out_bytes = (uint64_t)atomic_load(&e->peak_bytes);
    *out = e;
    return VKRT_OK;
fail:
    bench_embree_destroy(e);
    return r;
}

typedef struct trace_job {
    const bench_embree *e;
    const vkrt_ray *rays;
    size_t count;
    bool any_hit;
    vkrt_hit *hits;
    atomic_size_t next_block;
} trace_job;

static void trace_one(const trace_job *j, size_t i)
{
    const vkrt_ray *r = &j->rays[i];
    struct RTCIntersectContext context;
    rtcInitIntersectContext(&context);
    struct RTCRayHit rh = { 0 };
    rh.ray.org_x = r->origin[0], rh.ray.org_y = r->origin[1], rh.ray.org_z = r->origin[2];
    rh.ray.dir_x = r->dir[0], rh.ray.dir_y = r->dir[1], rh.ray.dir_z = r->dir[2];
    rh.ray.tnear = r->tmin;
    rh.ray.tfar = r->tmax > 0.0f ? r->tmax : INFINITY;
    rh.ray.mask = UINT32_MAX;
    rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
    vkrt_hit *h = &j->hits[i];
    if (j->any_hit) {
        rtcOccluded1(j->e->scene, &context, &rh.ray);
        /* A hit sets tfar to -inf; the distance is not reported. */
        *h = rh.ray.tfar < 0.0f ? (vkrt_hit){ 0.0f, 0, 0.0f, 0.0f } : (vkrt_hit){ -1.0f, VKRT_NO_HIT, 0.0f, 0.0f };
        return;
    }
    rtcIntersect1(j->e->scene, &context, &rh);
    *h = rh.hit.geomID != RTC_INVALID_GEOMETRY_ID ? (vkrt_hit){ rh.ray.tfar, rh.hit.primID, rh.hit.u, rh.hit.v }
                                                  : (vkrt_hit){ -1.0f, VKRT_NO_HIT, 0.0f, 0.0f };
}

static void *trace_worker(void *arg)
{
    trace_job *j = arg;
    for (;;) {
        size_t first = atomic_fetch_add(&j->next_block, 1) * RAY_BLOCK;
        if (first >= j->count) return NULL;
        size_t end = first + RAY_BLOCK < j->count ? first + RAY_BLOCK : j->count;
        for (size_t i = first; i < end; i++) trace_one(j, i);
    }
}

vkrt_result bench_embree_trace(bench_embree *e, const vkrt_ray *rays, size_t count, bool any_hit, vkrt_hit *out_hits,
                               double *out_ms, char *error, size_t error_size)
{
    trace_job j = { .e = e, .rays = rays, .count = count, .any_hit = any_hit, .hits = out_hits };
    atomic_init(&j.next_block, 0);
    pthread_t workers[MAX_THREADS];
    uint32_t started = 0;
    double t0 = now_ms();
    /* The caller is one of the threads, as in vkrt's CPU backend. */
    while (started + 1 < e->threads && pthread_create(&workers[started], NULL, trace_worker, &j) == 0) started++;
    trace_worker(&j);
    for (uint32_t i = 0; i < started; i++) pthread_join(workers[i], NULL);
    *out_ms = now_ms() - t0;
    if (started + 1 < e->threads) {
        snprintf(error, error_size, "Embree trace: started %u of %u threads", started + 1, e->threads);
        return VKRT_ERROR_LIMIT;
    }
    if (e->error[0]) {
        snprintf(error, error_size, "Embree trace: %s", e->error);
        return result_of(e->code);
    }
    return VKRT_OK;
}
