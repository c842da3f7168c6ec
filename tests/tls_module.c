/* A shared library with a thread-local counter, built twice by tests/meson.build for
 * test_tls_pin: with the initial-exec TLS model, which makes the linker flag it DF_STATIC_TLS
 * (as NVIDIA's libnvidia-tls is), and with the global-dynamic model, which does not. */
/* Exported whatever visibility the project compiles with: the test looks it up by name. */
__attribute__((visibility("default"))) int tls_module_bump(void);

static __thread int tls_module_counter;

__attribute__((visibility("default"))) int tls_module_bump(void)
{
    return ++tls_module_counter;
}
