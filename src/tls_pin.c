/* dl_iterate_phdr() and struct dl_phdr_info are GNU extensions; RTLD_NOLOAD and RTLD_NODELETE
 * too. */
#if defined(__linux__)
#define _GNU_SOURCE
#endif
#include "tls_pin.h"

#if defined(__linux__)
#include <dlfcn.h>
#include <elf.h>
#include <link.h>
#endif

#if defined(__linux__) && defined(RTLD_NODELETE) && defined(RTLD_NOLOAD) && defined(DF_STATIC_TLS)

/* The names of the libraries to pin, gathered first: dlopen is not called from inside
 * dl_iterate_phdr's callback, which runs under the dynamic linker's lock. */
typedef struct pin_list {
    core *c;
    char **names;
    size_t count, capacity;
    bool out_of_memory;
} pin_list;

static bool needs_static_tls(const struct dl_phdr_info *info)
{
    for (ElfW(Half) i = 0; i < info->dlpi_phnum; i++) {
        if (info->dlpi_phdr[i].p_type != PT_DYNAMIC) continue;
        const ElfW(Dyn) *d = (const ElfW(Dyn) *)(info->dlpi_addr + info->dlpi_phdr[i].p_vaddr);
        for (; d->d_tag != DT_NULL; d++)
            if (d->d_tag == DT_FLAGS) return (d->d_un.d_val & DF_STATIC_TLS) != 0;
    }
    return false;
}

static int gather(struct dl_phdr_info *info, size_t size, void *user)
{
    (void)size;
    pin_list *list = user;
    /* The program itself has no name here; it is never unloaded anyway. */
    if (!info->dlpi_name || !info->dlpi_name[0] || !needs_static_tls(info)) return 0;
    char *name = core_strdup(list->c, info->dlpi_name);
    if (!name || core_grow(list->c, (void **)&list->names, &list->capacity, list->count + 1, sizeof *list->names)) {
        core_free(list->c, name);
        list->out_of_memory = true;
        return 1; /* stops the walk */
    }
    list->names[list->count++] = name;
    return 0;
}

vkrt_result tls_pin_static_libraries(core *c)
{
    pin_list list = { .c = c };
    dl_iterate_phdr(gather, &list);
    for (size_t i = 0; i < list.count; i++) {
        /* NOLOAD: only a library still loaded; the flag outlives the handle, closed at once. */
        void *handle = dlopen(list.names[i], RTLD_LAZY | RTLD_NOLOAD | RTLD_NODELETE);
        if (handle) dlclose(handle);
        core_free(c, list.names[i]);
    }
    core_free(c, list.names);
    if (list.out_of_memory)
        return core_fail(c, VKRT_ERROR_OUT_OF_MEMORY, "out of memory listing the libraries that need static TLS");
    return VKRT_OK;
}

#else

vkrt_result tls_pin_static_libraries(core *c)
{
    (void)c;
    return VKRT_OK;
}

#endif
