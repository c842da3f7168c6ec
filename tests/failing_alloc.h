/* The out-of-memory tests' allocator: it counts the blocks it hands out and refuses one chosen
 * allocation, so that a test can fail each allocation of a call in turn and check that every
 * failure is answered with VKRT_ERROR_OUT_OF_MEMORY and leaks nothing. */
#ifndef VKRT_TEST_FAILING_ALLOC_H
#define VKRT_TEST_FAILING_ALLOC_H

#include <stdlib.h>

#include "vkrt.h"

typedef struct failing_allocator {
    long calls;      /* allocations counted: those of at least min_size bytes */
    long fail_at;    /* the 1-based counted allocation to refuse; 0: none */
    long live;       /* blocks allocated and not yet freed */
    size_t min_size; /* 0: every allocation counts (and may be refused) */
} failing_allocator;

static inline void *failing_alloc(void *user, size_t size)
{
    failing_allocator *f = user;
    if (size >= f->min_size && ++f->calls == f->fail_at) return NULL;
    void *p = malloc(size);
    if (p) f->live++;
    return p;
}

static inline void failing_free(void *user, void *pointer)
{
    failing_allocator *f = user;
    f->live--;
    free(pointer);
}

/* The vkrt_allocator that draws on f. */
static inline vkrt_allocator failing_allocator_use(failing_allocator *f)
{
    return (vkrt_allocator){ .alloc = failing_alloc, .free = failing_free, .user = f };
}

#endif
