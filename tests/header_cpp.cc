// vkrt.h compiles alone as C++17 with -pedantic -Wall -Wextra -Werror (tests/meson.build sets
// the flags) and links from C++: extern "C", no C-only constructs in the header.
#include "vkrt.h"

#include <cstdio>
#include <cstring>

int main()
{
    vkrt_context_desc desc = {};
    desc.backend = VKRT_BACKEND_CPU;
    desc.cpu_threads = 1;
    vkrt_context *ctx = nullptr;
    vkrt_result r = vkrt_context_create(&desc, &ctx);
    vkrt_render_desc render = {};
    render.mode = VKRT_MODE_DEPTH;
    bool ok = r == VKRT_OK && vkrt_version() == VKRT_VERSION && render.width == 0 &&
              std::strncmp(vkrt_result_string(VKRT_OK), "VKRT_OK", 7) == 0 &&
              std::strcmp(vkrt_context_device_name(ctx), "CPU reference") == 0;
    vkrt_context_destroy(ctx);
    if (!ok) std::fprintf(stderr, "header_cpp: %s\n", vkrt_result_string(r));
    return ok ? 0 : 1;
}
