/* CSV files of the bench's tables, written beside their target and renamed over it, so an
 * interrupted run never leaves half a table where a previous run's whole one was. */
#ifndef VKRT_BENCH_CSV_H
#define VKRT_BENCH_CSV_H

#include <stdio.h>

#include "vkrt.h"

typedef struct bench_csv {
    FILE *f;          /* write the rows here between begin and end */
    char *tmp;        /* the temporary name beside the target */
    const char *path; /* the target (borrowed until bench_csv_end) */
} bench_csv;

/* Opens the temporary file and writes `header` (one line, without its newline). Returns
 * VKRT_ERROR_IO or VKRT_ERROR_OUT_OF_MEMORY with nothing left open on failure. */
vkrt_result bench_csv_begin(bench_csv *csv, const char *path, const char *header);
/* Closes the file and renames it over the target; on a write error removes it instead and
 * returns VKRT_ERROR_IO. */
vkrt_result bench_csv_end(bench_csv *csv);

#endif
