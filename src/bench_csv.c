#include "bench_csv.h"

#include <stdbool.h>
#include <stdlib.h>
#include <string.h>

vkrt_result bench_csv_begin(bench_csv *csv, const char *path, const char *header)
{
    *csv = (bench_csv){ .path = path };
    size_t n = strlen(path) + 16;
    if (!(csv->tmp = malloc(n))) return VKRT_ERROR_OUT_OF_MEMORY;
    snprintf(csv->tmp, n, "%s.tmp-vkrt", path);
    if (!(csv->f = fopen(csv->tmp, "w"))) {
        free(csv->tmp);
        csv->tmp = NULL;
        return VKRT_ERROR_IO;
    }
    fprintf(csv->f, "%s\n", header);
    return VKRT_OK;
}

vkrt_result bench_csv_end(bench_csv *csv)
{
    bool ok = !ferror(csv->f);
    ok = fclose(csv->f) == 0 && ok;
    if (ok) ok = rename(csv->tmp, csv->path) == 0;
    if (!ok) remove(csv->tmp);
    free(csv->tmp);
    *csv = (bench_csv){ 0 };
    return ok ? VKRT_OK : VKRT_ERROR_IO;
}
