/* The services every module of the library shares: the allocator, the log and the detail
 * message of the last failure. A vkrt_context embeds one; modules that do not need Vulkan
 * (loaders, BVH builders, the CPU tracer) take only this, so tests can drive them alone. */
#ifndef VKRT_CORE_H
#define VKRT_CORE_H

#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#include "vkrt.h"

#define CORE_ERROR_SIZE 1024

typedef struct core {
    vkrt_allocator allocator;      /* patched: both functions set */
    vkrt_log_fn log;               /* may be NULL */
    void *log_user;
    /* Tests: a work pool starts at most this many threads in all, the caller included, as if
     * the others had failed to start (0, the default: no limit). */
    uint32_t test_thread_cap;
    /* Tests: the CPU tracer and the ray lists' plan run their baseline code even where the host
     * could run their x86-64-v3 build (cpu_trace_isa). */
    bool test_cpu_baseline;
    char last_error[CORE_ERROR_SIZE];
} core;

/* Fills a core from the user's choices; NULL functions become malloc/free. */
void core_init(core *c, const vkrt_allocator *allocator, vkrt_log_fn log, void *log_user);

/* All host memory of the library goes through these. core_alloc_array checks count * size
 * for overflow; every function returns NULL on failure (and records nothing: the caller knows
 * what it was allocating and reports it with core_fail). core_free(c, NULL) is a no-op. */
void *core_alloc(core *c, size_t size);
void *core_alloc_array(core *c, size_t count, size_t size);
void *core_calloc_array(core *c, size_t count, size_t size);
void core_free(core *c, void *pointer);
/* Shrinks a block from core_alloc to its first `size` bytes and returns it, perhaps moved. With
 * the default allocator this is realloc, which gives the tail back where the block lies and
 * touches none of it (glibc returns a large block's last pages to the system); a user's
 * allocator has no realloc, so the block is copied into a new one of the exact size. Where
 * that cannot be allocated the block is returned whole: a failed shrink only wastes memory. */
void *core_shrink(core *c, void *pointer, size_t size);
/* Asks the system to back a block of at least CORE_HUGE_PAGE_MIN bytes with huge pages where it
 * can (Linux: transparent huge pages, a hint the kernel may ignore); smaller blocks are left
 * alone. core_alloc does it for every block it returns, and vk_buffer for the mapped memory of
 * a CPU device (lavapipe), whose buffers are ordinary host memory. The library's large arrays (mesh
 * arrays, BVH nodes and references, packed triangles, wide nodes, the device's copies of them)
 * are written soon after they are allocated and then read all over: with 4 KiB pages the first
 * touch of each costs a page fault (a quarter of the time of loading and building the full
 * dragon on the shared test machine) and the reads miss the TLB. Embree's allocator gives its
 * large blocks the same hint (common/sys/alloc.cpp, os_madvise). */
#define CORE_HUGE_PAGE_MIN ((size_t)4 << 20)
void core_advise_huge_pages(void *pointer, size_t size);
/* Grows *array (of elements of elem_size) to hold at least `needed` elements, doubling.
 * Returns 0 on success, -1 on overflow or out of memory (the array is then unchanged). */
int core_grow(core *c, void **array, size_t *capacity, size_t needed, size_t elem_size);
/* A copy of s made with the allocator, or NULL. */
char *core_strdup(core *c, const char *s);

/* Records a failure detail, sends it to the log at error level and returns `result`, so a
 * failing path reads `return core_fail(c, VKRT_ERROR_IO, "%s: cannot open", path);`. */
#if defined(__GNUC__)
#define CORE_PRINTF(f, a) __attribute__((format(printf, f, a)))
#else
#define CORE_PRINTF(f, a)
#endif
vkrt_result core_fail(core *c, vkrt_result result, const char *format, ...) CORE_PRINTF(3, 4);
void core_log(core *c, vkrt_log_level level, const char *format, ...) CORE_PRINTF(3, 4);
void core_logv(core *c, vkrt_log_level level, const char *format, va_list args);
void core_clear_error(core *c);

/* Monotonic wall clock in milliseconds. */
double core_now_ms(void);

/* a / b rounded up (b > 0), without the overflow of (a + b - 1) / b. */
static inline uint32_t core_div_up(uint32_t a, uint32_t b) { return a / b + (a % b != 0); }

#endif
