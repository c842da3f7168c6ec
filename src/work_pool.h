/* A fixed set of worker threads that run the numbered items of one job at a time, the calling
 * thread among them; used by the BVH builder, the GPU scene's wide packing and the CPU
 * tracer. The calling thread alone calls the job's `between` hook (for progress reports and
 * cancellation), so user callbacks never run on a worker. Internal; the pool itself makes no
 * allocation after creation. */
#ifndef VKRT_WORK_POOL_H
#define VKRT_WORK_POOL_H

#include <stdbool.h>
#include <stdint.h>

#include "core.h"

typedef struct work_pool work_pool;

/* Runs item `item` of a job; items of one job may run concurrently, in any order. */
typedef void (*work_item_fn)(void *job, uint32_t item);
/* Called on the calling thread after each item it ran and whenever a worker finishes one
 * while it waits; returning false cancels the items that have not started. */
typedef bool (*work_between_fn)(void *job);

/* Creates a pool that runs jobs on `threads` threads in all (the caller and threads - 1
 * workers; 0 counts as 1). A worker that fails to start is not an error: the pool runs with
 * the ones that did, down to the caller alone. Returns VKRT_ERROR_OUT_OF_MEMORY when the pool
 * cannot be allocated. Ownership: destroy *out with work_pool_destroy(). */
vkrt_result work_pool_create(core *c, uint32_t threads, work_pool **out);
/* Threads that run jobs, the caller included (>= 1). */
uint32_t work_pool_threads(const work_pool *p);
/* Runs items 0 .. items - 1 of a job and returns when none is running. Returns false when
 * `between` (may be NULL) cancelled it; the items not started then never run. */
bool work_pool_run(work_pool *p, uint32_t items, work_item_fn fn, work_between_fn between, void *job);
/* True once the running job is cancelled: lets a long item stop early. Any thread. */
bool work_pool_cancelled(const work_pool *p);
/* Stops and joins the workers. NULL is a no-op. */
void work_pool_destroy(work_pool *p);

#endif
