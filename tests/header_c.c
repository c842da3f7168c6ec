/* vkrt.h compiles alone as C11 with -pedantic -Wall -Wextra -Werror (tests/meson.build sets the
 * flags) and links: only the public header, a few of its symbols. */
#include "vkrt.h"

#include <stdio.h>
#include <string.h>

int main(void)
{
    vkrt_context_desc desc = { .backend = VKRT_BACKEND_CPU, .cpu_threads = 1 };
    vkrt_context *ctx = NULL;
    vkrt_result r = vkrt_context_create(&desc, &ctx);
    int ok = r == VKRT_OK && vkrt_version() == VKRT_VERSION && vkrt_render_floats(2, 3) == 24 &&
             strncmp(vkrt_result_string(VKRT_ERROR_CANCELLED), "VKRT_ERROR_CANCELLED", 20) == 0;
    vkrt_context_destroy(ctx);
    if (!ok) fprintf(stderr, "header_c: %s\n", vkrt_result_string(r));
    return ok ? 0 : 1;
}
