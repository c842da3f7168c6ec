/* The two contexts the command line's suites (`vkrt stress`, `vkrt bench`) compare: the CPU
 * backend, which holds the double-precision reference, and the Vulkan backend. */
#ifndef VKRT_CLI_CONTEXTS_H
#define VKRT_CLI_CONTEXTS_H

#include <stdbool.h>
#include <stddef.h>

#include "vkrt.h"

/* Creates *cpu from desc (its backend ignored), and *gpu too when want_gpu (else NULL). On a
 * failure both are NULL, error says which backend failed and why, and the call's code returns. */
vkrt_result cli_contexts_create(const vkrt_context_desc *desc, bool want_gpu, vkrt_context **gpu, vkrt_context **cpu,
                                char *error, size_t error_size);

#endif
