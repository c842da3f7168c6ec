#include "cli_contexts.h"

#include <stdio.h>

vkrt_result cli_contexts_create(const vkrt_context_desc *desc, bool want_gpu, vkrt_context **gpu, vkrt_context **cpu,
                                char *error, size_t error_size)
{
    *gpu = *cpu = NULL;
    vkrt_context_desc cd = *desc;
    cd.backend = VKRT_BACKEND_CPU;
    vkrt_result r = vkrt_context_create(&cd, cpu);
    if (r != VKRT_OK) {
        snprintf(error, error_size, "creating the CPU backend: %s", vkrt_result_string(r));
        return r;
    }
    if (!want_gpu) return VKRT_OK;
    cd.backend = VKRT_BACKEND_GPU;
    if ((r = vkrt_context_create(&cd, gpu)) != VKRT_OK) {
        snprintf(error, error_size, "creating the Vulkan backend: %s", vkrt_result_string(r));
        vkrt_context_destroy(*cpu);
        *cpu = NULL;
    }
    return r;
}
