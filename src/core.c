/* madvise() and MADV_HUGEPAGE are not POSIX; glibc shows them with _DEFAULT_SOURCE. */
#if defined(__linux__)
#define _DEFAULT_SOURCE
#endif
#include "core.h"

#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#if defined(__linux__)
#include <sys/mman.h>
#endif

static void *default_alloc(void *user, size_t size)
{
    (void)user;
    return malloc(size);
}

static void default_free(void *user, void *pointer)
{
    (void)user;
    free(pointer);
}

void core_init(core *c, const vkrt_allocator *allocator, vkrt_log_fn log, void *log_user)
{
    memset(c, 0, sizeof *c);
    if (allocator && allocator->alloc && allocator->free) c->allocator = *allocator;
    else c->allocator = (vkrt_allocator){ .alloc = default_alloc, .free = default_free };
    c->log = log;
    c->log_user = log_user;
}

/* Only whole 4 KiB pages inside the block are advised: the pages around it may belong to other
 * allocations. A refusal (no THP, memory that is not anonymous, such as a GPU's mapped memory)
 * changes nothing, so the result is ignored. */
void core_advise_huge_pages(void *pointer, size_t size)
{
#if defined(__linux__) && defined(MADV_HUGEPAGE)
    const uintptr_t page = 4096;
    uintptr_t first = ((uintptr_t)pointer + page - 1) & ~(page - 1);
    uintptr_t end = ((uintptr_t)pointer + size) & ~(page - 1);
    if (size >= CORE_HUGE_PAGE_MIN && end > first) (void)madvise((void *)first, end - first, MADV_HUGEPAGE);
#else
    (void)pointer;
    (void)size;
#endif
}

void *core_alloc(core *c, size_t size)
{
    /* No object may be larger than PTRDIFF_MAX: a larger request is a size that wrapped (a file's
     * -20 read as 2^64 - 20), which malloc would fail anyway. A user's allocator, or a
     * sanitizer's, which aborts instead, never sees it. */
    if (size > PTRDIFF_MAX) return NULL;
    /* A zero-byte request still returns a unique pointer, so NULL always means failure. */
    void *p = c->allocator.alloc(c->allocator.user, size ? size : 1);
    if (p) core_advise_huge_pages(p, size);
    return p;
}

void *core_alloc_array(core *c, size_t count, size_t size)
{
    if (size && count > SIZE_MAX / size) return NULL;
    return core_alloc(c, count * size);
}

void *core_calloc_array(core *c, size_t count, size_t size)
{
    void *p = core_alloc_array(c, count, size);
    if (p) memset(p, 0, count * size);
    return p;
}

void core_free(core *c, void *pointer)
{
    if (pointer) c->allocator.free(c->allocator.user, pointer);
}

void *core_shrink(core *c, void *pointer, size_t size)
{
    if (!pointer) return NULL;
    if (c->allocator.alloc == default_alloc) {
        void *shrunk = realloc(pointer, size ? size : 1);
        return shrunk ? shrunk : pointer;
    }
    void *exact = core_alloc(c, size);
    if (!exact) return pointer;
    memcpy(exact, pointer, size);
    core_free(c, pointer);
    return exact;
}

int core_grow(core *c, void **array, size_t *capacity, size_t needed, size_t elem_size)
{
    if (needed <= *capacity) return 0;
    size_t cap = *capacity ? *capacity : 16;
    while (cap < needed) {
        if (cap > SIZE_MAX / 2) return -1;
        cap *= 2;
    }
    void *grown = core_alloc_array(c, cap, elem_size);
    if (!grown) return -1;
    if (*array) {
        memcpy(grown, *array, *capacity * elem_size);
        core_free(c, *array);
    }
    *array = grown;
    *capacity = cap;
    return 0;
}

char *core_strdup(core *c, const char *s)
{
    size_t n = strlen(s) + 1;
    char *copy = core_alloc(c, n);
    if (copy) memcpy(copy, s, n);
    return copy;
}

void core_logv(core *c, vkrt_log_level level, const char *format, va_list args)
{
    if (!c->log) return;
    char message[CORE_ERROR_SIZE];
    vsnprintf(message, sizeof message, format, args);
    c->log(c->log_user, level, message);
}

void core_log(core *c, vkrt_log_level level, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    core_logv(c, level, format, args);
    va_end(args);
}

vkrt_result core_fail(core *c, vkrt_result result, const char *format, ...)
{
    va_list args;
    va_start(args, format);
    vsnprintf(c->last_error, sizeof c->last_error, format, args);
    va_end(args);
    if (c->log) c->log(c->log_user, VKRT_LOG_ERROR, c->last_error);
    return result;
}

void core_clear_error(core *c)
{
    c->last_error[0] = '\0';
}

double core_now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec * 1e3 + (double)ts.tv_nsec * 1e-6;
}
