/* tls_pin_static_libraries (src/tls_pin.c): a library that needs static TLS stays loaded after
 * its last dlclose, one with dynamic TLS is unloaded as before, and a failed allocation is
 * answered with VKRT_ERROR_OUT_OF_MEMORY, nothing pinned and nothing leaked.
 * Arguments: the paths of the two builds of tls_module.c (initial-exec, global-dynamic). */
#define _GNU_SOURCE /* RTLD_NOLOAD */
#include <dlfcn.h>

#include "check.h"
#include "core.h"
#include "failing_alloc.h"
#include "tls_pin.h"

static const char *static_module, *dynamic_module;

static bool still_loaded(const char *path)
{
    void *handle = dlopen(path, RTLD_NOW | RTLD_NOLOAD);
    if (handle) dlclose(handle);
    return handle != NULL;
}

/* Loads both modules and uses their TLS, as a driver would. */
static bool load_modules(void **st, void **dy)
{
    *st = dlopen(static_module, RTLD_NOW | RTLD_LOCAL);
    *dy = dlopen(dynamic_module, RTLD_NOW | RTLD_LOCAL);
    CHECK_MSG(*st && *dy, "dlopen: %s", dlerror());
    if (!*st || !*dy) return false;
    int (*bump_static)(void) = (int (*)(void))dlsym(*st, "tls_module_bump");
    int (*bump_dynamic)(void) = (int (*)(void))dlsym(*dy, "tls_module_bump");
    CHECK(bump_static && bump_dynamic);
    if (!bump_static || !bump_dynamic) return false;
    CHECK(bump_static() == 1 && bump_static() == 2 && bump_dynamic() == 1);
    return true;
}

static void out_of_memory_pins_nothing_and_leaks_nothing(void)
{
    void *st, *dy;
    if (!load_modules(&st, &dy)) return;
    failing_allocator counts = { .fail_at = 1 };
    core c;
    const vkrt_allocator allocator = failing_allocator_use(&counts);
    core_init(&c, &allocator, NULL, NULL);
    CHECK(tls_pin_static_libraries(&c) == VKRT_ERROR_OUT_OF_MEMORY);
    CHECK(strstr(c.last_error, "static TLS") != NULL);
    CHECK_EQ_U64(counts.live, 0);
    dlclose(st);
    dlclose(dy);
    /* Run first: the static module is not pinned yet, so it goes like the other. */
    CHECK_MSG(!still_loaded(static_module), "the static-TLS module was pinned although the list failed");
    CHECK_MSG(!still_loaded(dynamic_module), "dlclose did not unload the dynamic-TLS module");
}

static void static_tls_libraries_stay_loaded(void)
{
    void *st, *dy;
    if (!load_modules(&st, &dy)) return;
    failing_allocator counts = { 0 };
    core c;
    const vkrt_allocator allocator = failing_allocator_use(&counts);
    core_init(&c, &allocator, NULL, NULL);
    CHECK(tls_pin_static_libraries(&c) == VKRT_OK);
    /* The list goes through the context's allocator (a name and the array at least). */
    CHECK_MSG(counts.calls >= 2, "%ld allocations through the context's allocator", counts.calls);
    CHECK_EQ_U64(counts.live, 0);
    dlclose(st);
    dlclose(dy);
    CHECK_MSG(still_loaded(static_module), "the static-TLS module was unloaded");
    CHECK_MSG(!still_loaded(dynamic_module), "the dynamic-TLS module stayed loaded");
}

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: test_tls_pin STATIC_TLS_MODULE DYNAMIC_TLS_MODULE\n");
        return 2;
    }
    static_module = argv[1];
    dynamic_module = argv[2];
    RUN(out_of_memory_pins_nothing_and_leaks_nothing);
    RUN(static_tls_libraries_stay_loaded);
    return check_exit();
}
