/* The GPU against the CPU double-precision reference on every mesh of ../shared/models (every
 * .obj, .gltf and .glb that loads; those that do not are skipped, except meshes/ where all
 * must load): 256x256 renders in normal, depth and id modes agree on at least 99.99% of the
 * pixels of each file. A pixel agrees when both miss, or both hit with depths within 1e-6
 * relative, normals within 1e-3 and the same triangle id, or another id at that same depth:
 * a pixel centre on an edge shared by two triangles (the box diagonals of pywavefront/box),
 * or on triangles that overlap (the fan of a non-convex polygon, tinyobjloader/issue-319-002),
 * may go either way in float and in double, and is the same hit. Strict id agreement is
 * printed too, with the other figures (README "Accuracy"). */
#include <dirent.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#include "check.h"
#include "vkrt.h"

#define SIZE 256 /* 65536 pixels: 99.99% allows six to differ */
#define MIN_AGREEMENT 0.9999
#define NORMAL_TOLERANCE 1e-3
#define DEPTH_TOLERANCE 1e-6

static vkrt_context *gpu, *cpu;
static unsigned validation_logged;

static void on_log(void *user, vkrt_log_level level, const char *message)
{
    (void)user;
    if (level == VKRT_LOG_ERROR && strstr(message, "validation")) {
        fprintf(stderr, "  [vkrt] %s\n", message);
        validation_logged++;
    }
}

typedef struct path_list {
    char **paths;
    size_t count, cap;
} path_list;

static bool wanted(const char *name)
{
    const char *dot = strrchr(name, '.');
    return dot && (!strcmp(dot, ".obj") || !strcmp(dot, ".gltf") || !strcmp(dot, ".glb"));
}

static void collect(const char *dir, path_list *list)
{
    DIR *d = opendir(dir);
    if (!d) return;
    struct dirent *e;
    while ((e = readdir(d)) != NULL) {
        if (e->d_name[0] == '.') continue;
        size_t n = strlen(dir) + strlen(e->d_name) + 2;
        char *path = malloc(n);
        if (!path) break;
        snprintf(path, n, "%s/%s", dir, e->d_name);
        struct stat st;
        if (stat(path, &st) == 0 && S_ISDIR(st.st_mode)) {
            collect(path, list);
            free(path);
        } else if (wanted(e->d_name) && (list->count < list->cap ||
                                         (list->paths = realloc(list->paths, (list->cap = list->cap * 2 + 64) * sizeof *list->paths)))) {
            list->paths[list->count++] = path;
        } else {
            free(path);
        }
    }
    closedir(d);
}

static int compare_paths(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

static bool render(vkrt_context *ctx, vkrt_scene *s, vkrt_mode mode, vkrt_precision precision, float *rgba)
{
    vkrt_render_desc d = { .width = SIZE, .height = SIZE, .mode = mode, .precision = precision };
    vkrt_result r = vkrt_render(ctx, s, &d, rgba, vkrt_render_floats(SIZE, SIZE), NULL);
    CHECK_MSG(r == VKRT_OK, "render: %s", vkrt_context_last_error(ctx));
    return r == VKRT_OK;
}

typedef struct totals {
    size_t files, skipped, pixels, agree, id_agree, normal_agree, depth_agree, hits;
    double max_rel_depth, max_normal, worst_share;
    char worst[512];
} totals;

static void gpu_agrees_with_double_reference_on(const char *path, totals *t)
{
    vkrt_scene *sc = NULL, *sg = NULL;
    vkrt_result r = vkrt_scene_create(cpu, &(vkrt_scene_desc){ .path = path }, &sc);
    if (r != VKRT_OK) {
        bool must_load = strstr(path, "/meshes/") != NULL;
        CHECK_MSG(!must_load, "%s: %s", path, vkrt_context_last_error(cpu));
        printf("skip %s (%s)\n", path + strlen(VKRT_MODELS_DIR) + 1, vkrt_result_string(r));
        t->skipped++;
        return;
    }
    r = vkrt_scene_create(gpu, &(vkrt_scene_desc){ .path = path }, &sg);
    CHECK_MSG(r == VKRT_OK, "%s loads on the CPU but not on the GPU: %s", path, vkrt_context_last_error(gpu));
    const size_t n = vkrt_render_floats(SIZE, SIZE);
    float *img[6];
    for (int i = 0; i < 6; i++) img[i] = malloc(n * sizeof(float));
    const vkrt_mode modes[3] = { VKRT_MODE_ID, VKRT_MODE_NORMAL, VKRT_MODE_DEPTH };
    bool ok = sg != NULL;
    for (int m = 0; m < 3 && ok; m++)
        ok = render(gpu, sg, modes[m], VKRT_PRECISION_FLOAT, img[2 * m]) &&
             render(cpu, sc, modes[m], VKRT_PRECISION_DOUBLE, img[2 * m + 1]);
    if (ok) {
        size_t agree = 0, ids = 0, normals = 0, depths = 0, hits = 0;
        double max_rel = 0, max_normal = 0;
        for (size_t p = 0; p < (size_t)SIZE * SIZE; p++) {
            const float *gi = img[0] + 4 * p, *ci = img[1] + 4 * p, *gn = img[2] + 4 * p, *cn = img[3] + 4 * p;
            float gd = img[4][4 * p], cd = img[5][4 * p];
            bool id_ok = gi[0] == ci[0];
            double nd = 0;
            for (int k = 0; k < 3; k++) nd = fmax(nd, 2.0 * fabs((double)gn[k] - (double)cn[k])); /* rgb = n / 2 + 1/2 */
            bool normal_ok = nd <= NORMAL_TOLERANCE && gn[3] == cn[3];
            bool depth_ok = (gd >= 0) == (cd >= 0);
            if (gd >= 0 && cd >= 0) {
                double rel = fabs((double)gd - (double)cd) / (double)cd;
                max_rel = fmax(max_rel, rel);
                depth_ok = rel < DEPTH_TOLERANCE;
                hits++;
            }
            if (gn[3] == cn[3]) max_normal = fmax(max_normal, nd);
            /* Another triangle at the same distance along the same ray: the same point, on an edge
             * shared by two triangles or where triangles overlap (the fan of a non-convex polygon
             * folds over itself), and either is the closest hit; its normal may differ. */
            bool same_point = gd >= 0 && cd >= 0 && depth_ok;
            ids += id_ok;
            normals += normal_ok;
            depths += depth_ok;
            agree += (id_ok && normal_ok && depth_ok) || (!id_ok && same_point);
        }
        size_t pixels = (size_t)SIZE * SIZE;
        double share = (double)agree / (double)pixels;
        printf("%-64s hits %5zu  agree %5zu = %7.3f%%  same ids %5zu  normals %5zu  depths %5zu  max rel depth %.2e  max normal %.2e\n",
               path + strlen(VKRT_MODELS_DIR) + 1, hits, agree, 100.0 * share, ids, normals, depths, max_rel, max_normal);
        CHECK_MSG(share >= MIN_AGREEMENT, "%s: the GPU agrees with the double reference on %.3f%% of pixels", path,
                  100.0 * share);
        t->files++;
        t->pixels += pixels;
        t->agree += agree;
        t->id_agree += ids;
        t->normal_agree += normals;
        t->depth_agree += depths;
        t->hits += hits;
        t->max_rel_depth = fmax(t->max_rel_depth, max_rel);
        t->max_normal = fmax(t->max_normal, max_normal);
        if (t->files == 1 || share < t->worst_share) {
            t->worst_share = share;
            snprintf(t->worst, sizeof t->worst, "%s", path + strlen(VKRT_MODELS_DIR) + 1);
        }
    }
    for (int i = 0; i < 6; i++) free(img[i]);
    vkrt_scene_destroy(sg);
    vkrt_scene_destroy(sc);
}

static void gpu_agrees_with_double_reference_on_every_model(void)
{
    path_list list = { 0 };
    collect(VKRT_MODELS_DIR, &list);
    CHECK_MSG(list.count > 0, "no models under %s", VKRT_MODELS_DIR);
    qsort(list.paths, list.count, sizeof *list.paths, compare_paths);
    totals t = { 0 };
    for (size_t i = 0; i < list.count; i++) {
        gpu_agrees_with_double_reference_on(list.paths[i], &t);
        free(list.paths[i]);
    }
    free(list.paths);
    printf("\n%zu files traced (%zu skipped: they do not load), %dx%d pixels each (counts above are of\n"
           "those), %zu pixels in all, %zu hit on both:\n", t.files,
           t.skipped, SIZE, SIZE, t.pixels, t.hits);
    printf("  pixels agreeing in all three modes: %.4f%% (same ids %.4f%%, normals %.4f%%, depths %.4f%%)\n",
           100.0 * (double)t.agree / (double)t.pixels, 100.0 * (double)t.id_agree / (double)t.pixels,
           100.0 * (double)t.normal_agree / (double)t.pixels, 100.0 * (double)t.depth_agree / (double)t.pixels);
    printf("  max relative depth error %.3g, max normal difference %.3g; lowest agreement %.4f%% (%s)\n",
           t.max_rel_depth, t.max_normal, 100.0 * t.worst_share, t.worst);
}

int main(void)
{
    setvbuf(stdout, NULL, _IOLBF, 0); /* the figures in order with the check messages */
    int code = check_contexts(on_log, &gpu, &cpu);
    if (code) return code;
    RUN(gpu_agrees_with_double_reference_on_every_model);
    CHECK_EQ_U64(vkrt_context_validation_messages(gpu), 0);
    CHECK_EQ_U64(validation_logged, 0);
    vkrt_context_destroy(cpu);
    vkrt_context_destroy(gpu);
    return check_exit();
}
