/* Minimal test assertions: each failure prints file, line, the expression and the values,
 * and the test keeps going so one run shows every broken fact; main returns check_exit(). */
#ifndef VKRT_CHECK_H
#define VKRT_CHECK_H

#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "vkrt.h"

static int check_failures;
static unsigned check_validation_logged; /* check_gpu_log */

#define CHECK(x)                                                                        \
    do {                                                                                \
        if (!(x)) {                                                                     \
            fprintf(stderr, "%s:%d: CHECK(%s) failed\n", __FILE__, __LINE__, #x);       \
            check_failures++;                                                           \
        }                                                                               \
    } while (0)

#define CHECK_MSG(x, ...)                                                               \
    do {                                                                                \
        if (!(x)) {                                                                     \
            fprintf(stderr, "%s:%d: CHECK(%s) failed: ", __FILE__, __LINE__, #x);       \
            fprintf(stderr, __VA_ARGS__);                                               \
            fputc('\n', stderr);                                                        \
            check_failures++;                                                           \
        }                                                                               \
    } while (0)

#define CHECK_EQ_U64(a, b)                                                              \
    do {                                                                                \
        uint64_t check_a_ = (uint64_t)(a), check_b_ = (uint64_t)(b);                    \
        if (check_a_ != check_b_) {                                                     \
            fprintf(stderr, "%s:%d: CHECK_EQ_U64(%s, %s) failed: %" PRIu64 " != %" PRIu64 "\n", \
                    __FILE__, __LINE__, #a, #b, check_a_, check_b_);                    \
            check_failures++;                                                           \
        }                                                                               \
    } while (0)

#define CHECK_NEAR(a, b, eps)                                                           \
    do {                                                                                \
        double check_a_ = (double)(a), check_b_ = (double)(b);                          \
        if (!(fabs(check_a_ - check_b_) <= (double)(eps))) {                            \
            fprintf(stderr, "%s:%d: CHECK_NEAR(%s, %s, %s) failed: %.9g vs %.9g\n",      \
                    __FILE__, __LINE__, #a, #b, #eps, check_a_, check_b_);              \
            check_failures++;                                                           \
        }                                                                               \
    } while (0)

/* Runs one test function, named as the fact it checks. */
#define RUN(test)                                                                       \
    do {                                                                                \
        int check_before_ = check_failures;                                             \
        test();                                                                         \
        fprintf(stderr, "%s %s\n", check_failures == check_before_ ? "ok  " : "FAIL", #test); \
    } while (0)

static inline int check_exit(void);

/* The end of a GPU test: no validation message was counted or logged; both contexts destroyed. */
static inline int check_gpu_finish(vkrt_context *gpu, vkrt_context *cpu)
{
    CHECK_EQ_U64(vkrt_context_validation_messages(gpu), 0);
    vkrt_context_destroy(gpu);
    vkrt_context_destroy(cpu);
    CHECK_EQ_U64(check_validation_logged, 0);
    return check_exit();
}

static inline int check_exit(void)
{
    if (check_failures) fprintf(stderr, "%d check(s) failed\n", check_failures);
    return check_failures ? 1 : 0;
}

/* The log of a GPU test: warnings and errors printed, and messages of the validation layer
 * counted (any one fails the test in check_gpu_finish). */

static inline void check_gpu_log(void *user, vkrt_log_level level, const char *message)
{
    (void)user;
    if (level <= VKRT_LOG_WARN) {
        fprintf(stderr, "  [vkrt %s] %s\n", level == VKRT_LOG_ERROR ? "error" : "warning", message);
        if (strstr(message, "validation")) check_validation_logged++;
    }
}

/* The two contexts of a GPU test: the GPU (validation on, the pipeline cache meson names) and
 * the CPU reference. Returns 0 with both set; otherwise the exit code: 77 (skipped) when no
 * Vulkan device exists outside CI, 1 for any other failure. */
static inline int check_contexts(vkrt_log_fn log, vkrt_context **gpu, vkrt_context **cpu)
{
    vkrt_context_desc desc = { .backend = VKRT_BACKEND_GPU, .log = log, .validation = true };
    desc.pipeline_cache_path = getenv("VKRT_PIPELINE_CACHE");
    vkrt_result r = vkrt_context_create(&desc, gpu);
    if (r == VKRT_ERROR_NO_DEVICE && !getenv("CI")) {
        fprintf(stderr, "no Vulkan device: skipped (in CI this fails)\n");
        return 77;
    }
    if (r != VKRT_OK) {
        fprintf(stderr, "cannot create the GPU context: %s\n", vkrt_result_string(r));
        return 1;
    }
    fprintf(stderr, "device: %s\n", vkrt_context_device_name(*gpu));
    r = vkrt_context_create(&(vkrt_context_desc){ .backend = VKRT_BACKEND_CPU, .log = log }, cpu);
    if (r != VKRT_OK) {
        fprintf(stderr, "cannot create the CPU context: %s\n", vkrt_result_string(r));
        vkrt_context_destroy(*gpu);
        return 1;
    }
    return 0;
}

/* Path of ../shared/models relative to the source tree; meson passes VKRT_MODELS_DIR. */
#ifndef VKRT_MODELS_DIR
#define VKRT_MODELS_DIR "../shared/models"
#endif
#ifndef VKRT_TEST_DATA_DIR
#define VKRT_TEST_DATA_DIR "tests/data"
#endif

#endif
