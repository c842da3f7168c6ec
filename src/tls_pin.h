/* Keeps loaded, for the rest of the process, every shared library in it that needs static
 * thread-local storage: a Vulkan driver that does must not be unloaded and loaded again.
 *
 * Why: the Vulkan loader unloads the drivers when the last instance is destroyed and loads them
 * again with the next. glibc gives a library loaded at run time that needs static TLS (an
 * initial-exec model, flagged DF_STATIC_TLS) a block from a small reserve that its unloading does
 * not give back. NVIDIA's driver 580 is such a library (libnvidia-tls): on an H100, after a few
 * contexts had been created and destroyed one after another (test_api's out-of-memory sweep),
 * loading it failed ("cannot allocate memory in static TLS block"), the loader found no driver,
 * and every later context creation answered VKRT_ERROR_NO_DEVICE. Pinned, such a library is
 * loaded once. Libraries with dynamic TLS, whose blocks are given back, stay unloadable. */
#ifndef VKRT_TLS_PIN_H
#define VKRT_TLS_PIN_H

#include "core.h"

/* Marks every library now loaded that is flagged DF_STATIC_TLS as never to be unloaded
 * (RTLD_NODELETE). Cheap enough to call after each step that may load a driver (a few
 * microseconds). VKRT_ERROR_OUT_OF_MEMORY if the list of their names cannot be made; elsewhere
 * than glibc's dynamic linker it does nothing. */
vkrt_result tls_pin_static_libraries(core *c);

#endif
