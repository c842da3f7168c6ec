/* Whether the kernel was asked to back the mapping holding an address with transparent huge
 * pages (madvise MADV_HUGEPAGE, core_advise_huge_pages): its VmFlags in /proc/self/smaps hold
 * "hg". The flag is set by the advice alone, whether or not huge pages are then available, so
 * tests can check that the library gave it. */
#ifndef VKRT_TEST_HUGE_PAGES_H
#define VKRT_TEST_HUGE_PAGES_H

#include <inttypes.h>
#include <stdio.h>
#include <string.h>

/* 1: advised, 0: not, -1: no mapping holds p or /proc/self/smaps cannot be read. */
static inline int mapping_advised_huge(const void *p)
{
    FILE *f = fopen("/proc/self/smaps", "r");
    if (!f) return -1;
    char line[512];
    int found = -1;
    bool inside = false;
    const uintptr_t at = (uintptr_t)p;
    while (fgets(line, sizeof line, f)) {
        uintmax_t lo, hi;
        if (sscanf(line, "%jx-%jx ", &lo, &hi) == 2 && strchr(line, '-') < strchr(line, ' ')) {
            inside = at >= lo && at < hi;
        } else if (inside && strncmp(line, "VmFlags:", 8) == 0) {
            found = strstr(line, " hg") != NULL;
            break;
        }
    }
    fclose(f);
    return found;
}

#endif
