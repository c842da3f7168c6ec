#include "bench_reference.h"

#include <errno.h>
#include <math.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <time.h>

/* Bumped whenever the file layout changes; the key of an old file then never matches. */
#define CACHE_MAGIC "VKRTREF1"
/* The key names the scene file, the view and every lighting setting: up to 64 lights of about
 * 120 characters each fit with room to spare. */
#define KEY_SIZE 16384

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}

/* Appends to the key; floats in C's hexadecimal notation, so equal keys mean equal bits. */
static void key_add(char *key, size_t *len, const char *fmt, ...)
{
    if (*len >= KEY_SIZE) return;
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(key + *len, KEY_SIZE - *len, fmt, ap);
    va_end(ap);
    if (n > 0) *len += (size_t)n < KEY_SIZE - *len ? (size_t)n : KEY_SIZE - *len;
}

static void key_add_floats(char *key, size_t *len, const char *name, const float *v, int n)
{
    key_add(key, len, " %s=", name);
    for (int i = 0; i < n; i++) key_add(key, len, "%s%a", i ? "," : "", (double)v[i]);
}

/* Everything that decides the reference image, on one line. */
static bool make_key(const bench_reference_desc *d, char *key, char *error, size_t error_size)
{
    const vkrt_render_desc *r = d->render;
    size_t len = 0;
    uint32_t v = vkrt_version();
    key_add(key, &len, "vkrt %u.%u.%u", v >> 22, (v >> 12) & 0x3ff, v & 0xfff);
    if (d->scene_path) {
        struct stat st;
        if (stat(d->scene_path, &st) != 0) {
            snprintf(error, error_size, "%s: %s", d->scene_path, strerror(errno));
            return false;
        }
        key_add(key, &len, " scene=%s size=%lld mtime=%lld.%09ld", d->scene_path, (long long)st.st_size,
                (long long)st.st_mtim.tv_sec, (long)st.st_mtim.tv_nsec);
    } else {
        key_add(key, &len, " scene=%s", d->scene_name);
    }
    key_add(key, &len, " world=%d size=%ux%u mode=%d isect=%d spp=%u seed=%u ao=%u,%a bounces=%u",
            (int)d->keep_world_coordinates, r->width, r->height, (int)r->mode, (int)r->intersector, r->spp, r->seed,
            r->ao_samples, (double)r->ao_distance, r->max_bounces);
    key_add_floats(key, &len, "eye", r->camera.eye, 3);
    key_add_floats(key, &len, "target", r->camera.target, 3);
    key_add_floats(key, &len, "up", r->camera.up, 3);
    key_add_floats(key, &len, "fov", &r->camera.fov_y_degrees, 1);
    key_add_floats(key, &len, "zenith", r->sky.zenith, 3);
    key_add_floats(key, &len, "horizon", r->sky.horizon, 3);
    for (uint32_t i = 0; i < r->light_count; i++) {
        key_add(key, &len, " light=%d", (int)r->lights[i].type);
        key_add_floats(key, &len, "at", r->lights[i].vector, 3);
        key_add_floats(key, &len, "rgb", r->lights[i].color, 3);
    }
    if (len >= KEY_SIZE - 1) {
        snprintf(error, error_size, "the reference's cache key exceeds %d characters", KEY_SIZE);
        return false;
    }
    for (size_t i = 0; i < len; i++)
        if (key[i] == '\n') key[i] = '?'; /* one line, whatever the file name holds */
    return true;
}

/* FNV-1a, 64 bits: the file name of a key. */
static uint64_t fnv1a(const char *s)
{
    uint64_t h = 0xcbf29ce484222325ull;
    for (; *s; s++) h = (h ^ (uint8_t)*s) * 0x100000001b3ull;
    return h;
}

/* mkdir -p: every missing directory of path. */
static bool make_dirs(const char *path)
{
    char buf[4096];
    if (snprintf(buf, sizeof buf, "%s", path) >= (int)sizeof buf) return false;
    for (char *p = buf + 1; *p; p++) {
        if (*p != '/') continue;
        *p = '\0';
        if (mkdir(buf, 0755) != 0 && errno != EEXIST) return false;
        *p = '/';
    }
    return mkdir(buf, 0755) == 0 || errno == EEXIST;
}

/* Reads the cached image of exactly this key; false when there is none (or it is damaged). */
static bool cache_read(const char *file, const char *key, float *rgba, size_t floats, double *noise)
{
    FILE *f = fopen(file, "rb");
    if (!f) return false;
    char *line = malloc(KEY_SIZE + 2);
    bool ok = line != NULL;
    ok = ok && fgets(line, KEY_SIZE + 2, f) && !strcmp(line, CACHE_MAGIC "\n");
    ok = ok && fgets(line, KEY_SIZE + 2, f) && !strncmp(line, key, strlen(key)) && !strcmp(line + strlen(key), "\n");
    ok = ok && fgets(line, KEY_SIZE + 2, f) && sscanf(line, "noise %la", noise) == 1 && isfinite(*noise);
    ok = ok && fread(rgba, sizeof *rgba, floats, f) == floats && fgetc(f) == EOF;
    free(line);
    fclose(f);
    return ok;
}

/* Writes the image beside the cache file and renames it over it; a failure leaves no file. */
static bool cache_write(const char *file, const char *key, const float *rgba, size_t floats, double noise)
{
    char tmp[4200];
    if (snprintf(tmp, sizeof tmp, "%s.tmp-vkrt", file) >= (int)sizeof tmp) return false;
    FILE *f = fopen(tmp, "wb");
    if (!f) return false;
    fprintf(f, "%s\n%s\nnoise %a\n", CACHE_MAGIC, key, noise);
    bool ok = fwrite(rgba, sizeof *rgba, floats, f) == floats && !ferror(f);
    ok = fclose(f) == 0 && ok;
    if (ok) ok = rename(tmp, file) == 0;
    if (!ok) remove(tmp);
    return ok;
}

vkrt_result bench_reference_get(const bench_reference_desc *d, float *out_rgba, bench_reference_info *out_info,
                                char *error, size_t error_size)
{
    *out_info = (bench_reference_info){ 0 };
    const vkrt_render_desc *r = d->render;
    size_t pixels = (size_t)r->width * r->height, floats = vkrt_render_floats(r->width, r->height);
    char *key = malloc(KEY_SIZE);
    float *err = malloc(pixels * sizeof *err);
    char file[4200] = "";
    vkrt_result res = key && err ? VKRT_OK : VKRT_ERROR_OUT_OF_MEMORY;
    if (res != VKRT_OK) snprintf(error, error_size, "out of memory for a %ux%u reference", r->width, r->height);
    if (res == VKRT_OK && !make_key(d, key, error, error_size)) res = VKRT_ERROR_IO;
    double t0 = now_ms();
    if (res == VKRT_OK && d->cache_dir) {
        snprintf(file, sizeof file, "%s/ref-%016llx.bin", d->cache_dir, (unsigned long long)fnv1a(key));
        out_info->cached = cache_read(file, key, out_rgba, floats, &out_info->noise);
    }
    if (res == VKRT_OK && !out_info->cached) {
        vkrt_render_desc rd = *r;
        rd.target_error = 0.0f; /* every pixel takes every sample */
        rd.all_features = false;
        rd.out_error = err;
        rd.progress = NULL;
        res = vkrt_render(d->cpu, d->scene, &rd, out_rgba, floats, NULL);
        if (res != VKRT_OK) snprintf(error, error_size, "reference render: %s", vkrt_context_last_error(d->cpu));
        double sum = 0.0;
        for (size_t p = 0; res == VKRT_OK && p < pixels; p++) sum += (double)err[p] * (double)err[p];
        out_info->noise = pixels ? sqrt(sum / (double)pixels) : 0.0;
        /* A cache that cannot be written costs the next run time, not this one its result. */
        if (res == VKRT_OK && d->cache_dir && make_dirs(d->cache_dir))
            cache_write(file, key, out_rgba, floats, out_info->noise);
    }
    out_info->ms = now_ms() - t0;
    free(key);
    free(err);
    return res;
}
