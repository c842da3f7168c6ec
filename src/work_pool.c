/* Worker threads for the numbered items of one job at a time; see work_pool.h. */
#include "work_pool.h"

#include <pthread.h>
#include <stdatomic.h>
#include <string.h>

struct work_pool {
    core *c;
    uint32_t workers_started;
    pthread_t *workers;
    pthread_mutex_t lock;
    pthread_cond_t wake;   /* to workers: a job was posted, or the pool stops */
    pthread_cond_t idle;   /* to the caller: a worker finished an item or left the job */
    bool stopping;
    uint64_t generation;   /* jobs posted so far; a worker joins each new one once */
    uint32_t busy;         /* workers inside the current job */
    uint32_t finished;     /* items workers finished since the caller last looked */
    work_item_fn fn;       /* the current job */
    void *job;
    uint32_t items;
    atomic_uint next;      /* the next item to claim */
    atomic_bool cancel;
};

/* Claims and runs items until none is left or the job is cancelled. */
static void run_items(work_pool *p, work_item_fn fn, void *job, uint32_t items, bool is_worker)
{
    for (;;) {
        if (atomic_load_explicit(&p->cancel, memory_order_relaxed)) return;
        uint32_t i = atomic_fetch_add_explicit(&p->next, 1, memory_order_relaxed);
        if (i >= items) return;
        fn(job, i);
        if (is_worker) {
            pthread_mutex_lock(&p->lock);
            p->finished++;
            pthread_cond_signal(&p->idle);
            pthread_mutex_unlock(&p->lock);
        }
    }
}

static void *worker_main(void *arg)
{
    work_pool *p = arg;
    uint64_t seen = 0;
    pthread_mutex_lock(&p->lock);
    for (;;) {
        while (!p->stopping && p->generation == seen) pthread_cond_wait(&p->wake, &p->lock);
        if (p->stopping) break;
        /* Joining under the lock: the caller posts the next job only when no worker is busy,
         * so the fields read here belong to the job this worker counts itself into. */
        seen = p->generation;
        p->busy++;
        work_item_fn fn = p->fn;
        void *job = p->job;
        uint32_t items = p->items;
        pthread_mutex_unlock(&p->lock);
        run_items(p, fn, job, items, true);
        pthread_mutex_lock(&p->lock);
        p->busy--;
        pthread_cond_signal(&p->idle);
    }
    pthread_mutex_unlock(&p->lock);
    return NULL;
}

vkrt_result work_pool_create(core *c, uint32_t threads, work_pool **out)
{
    *out = NULL;
    work_pool *p = core_alloc(c, sizeof *p);
    if (!p) return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for a pool of %u threads", threads);
    memset(p, 0, sizeof *p);
    p->c = c;
    atomic_init(&p->next, 0);
    atomic_init(&p->cancel, false);
    uint32_t helpers = threads > 1 ? threads - 1 : 0;
    if (helpers) {
        p->workers = core_alloc_array(c, helpers, sizeof *p->workers);
        if (!p->workers) {
            core_free(c, p);
            return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory for a pool of %u threads", threads);
        }
        /* Without the lock and both conditions no worker can start; the caller then runs
         * every item, as it does when a thread fails to start. */
        bool synced = false;
        if (pthread_mutex_init(&p->lock, NULL) == 0) {
            if (pthread_cond_init(&p->wake, NULL) == 0) {
                if (pthread_cond_init(&p->idle, NULL) == 0) synced = true;
                else pthread_cond_destroy(&p->wake);
            }
            if (!synced) pthread_mutex_destroy(&p->lock);
        }
        /* The test cap stops the loop where a failing pthread_create would. */
        const uint32_t startable = c->test_thread_cap && c->test_thread_cap - 1 < helpers ? c->test_thread_cap - 1 : helpers;
        while (synced && p->workers_started < startable &&
               pthread_create(&p->workers[p->workers_started], NULL, worker_main, p) == 0)
            p->workers_started++;
        if (p->workers_started < helpers)
            core_log(c, VKRT_LOG_WARN, "started %u of %u worker threads; the calling thread does the rest",
                     p->workers_started, helpers);
        if (synced && p->workers_started == 0) {
            pthread_cond_destroy(&p->idle);
            pthread_cond_destroy(&p->wake);
            pthread_mutex_destroy(&p->lock);
        }
    }
    *out = p;
    return VKRT_OK;
}

uint32_t work_pool_threads(const work_pool *p) { return p->workers_started + 1; }

bool work_pool_run(work_pool *p, uint32_t items, work_item_fn fn, work_between_fn between, void *job)
{
    if (!items) return true;
    if (p->workers_started) {
        pthread_mutex_lock(&p->lock);
        /* A worker that joined the last job late may still be claiming from its counter. */
        while (p->busy) pthread_cond_wait(&p->idle, &p->lock);
        p->fn = fn;
        p->job = job;
        p->items = items;
        p->finished = 0;
        atomic_store_explicit(&p->next, 0, memory_order_relaxed);
        atomic_store_explicit(&p->cancel, false, memory_order_relaxed);
        p->generation++;
        pthread_cond_broadcast(&p->wake);
        pthread_mutex_unlock(&p->lock);
    } else {
        atomic_store_explicit(&p->next, 0, memory_order_relaxed);
        atomic_store_explicit(&p->cancel, false, memory_order_relaxed);
    }
    bool cancelled = false;
    for (;;) {
        if (atomic_load_explicit(&p->cancel, memory_order_relaxed)) break;
        uint32_t i = atomic_fetch_add_explicit(&p->next, 1, memory_order_relaxed);
        if (i >= items) break;
        fn(job, i);
        if (between && !between(job)) {
            cancelled = true;
            atomic_store_explicit(&p->cancel, true, memory_order_relaxed);
        }
    }
    if (p->workers_started) {
        /* Every item is claimed; wait for the workers still running one, reporting as they
         * finish. The lock also makes their results visible to the caller. */
        pthread_mutex_lock(&p->lock);
        while (p->busy) {
            if (between && p->finished && !cancelled) {
                p->finished = 0;
                pthread_mutex_unlock(&p->lock);
                if (!between(job)) {
                    cancelled = true;
                    atomic_store_explicit(&p->cancel, true, memory_order_relaxed);
                }
                pthread_mutex_lock(&p->lock);
                continue;
            }
            pthread_cond_wait(&p->idle, &p->lock);
        }
        pthread_mutex_unlock(&p->lock);
    }
    return !cancelled;
}

bool work_pool_cancelled(const work_pool *p)
{
    return atomic_load_explicit(&((work_pool *)p)->cancel, memory_order_relaxed);
}

void work_pool_destroy(work_pool *p)
{
    if (!p) return;
    if (p->workers_started) {
        pthread_mutex_lock(&p->lock);
        p->stopping = true;
        pthread_cond_broadcast(&p->wake);
        pthread_mutex_unlock(&p->lock);
        for (uint32_t i = 0; i < p->workers_started; i++) pthread_join(p->workers[i], NULL);
        pthread_cond_destroy(&p->idle);
        pthread_cond_destroy(&p->wake);
        pthread_mutex_destroy(&p->lock);
    }
    core_free(p->c, p->workers);
    core_free(p->c, p);
}
