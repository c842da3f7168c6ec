#include "vkrt.h"

uint32_t vkrt_version(void)
{
    return VKRT_VERSION;
}

const char *vkrt_result_string(vkrt_result result)
{
    switch (result) {
#define VKRT_RESULT_CASE_(name, message) \
    case name: return #name ": " message;
        VKRT_RESULT_LIST(VKRT_RESULT_CASE_)
#undef VKRT_RESULT_CASE_
    default: return "VKRT_ERROR_UNKNOWN: unknown result code";
    }
}
