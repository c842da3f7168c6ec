/* `vkrt stress`: the numerical-stability suite of the command line. It builds its meshes in
 * memory, traces them through vkrt.h only (like main.c) on every backend and intersector, and
 * compares each with the CPU double-precision reference. */
#ifndef VKRT_STRESS_H
#define VKRT_STRESS_H

#include <stdbool.h>
#include <stdio.h>

#include "vkrt.h"

typedef struct stress_options {
    vkrt_context_desc context;     /* log, validation, device, threads, pipeline cache; its
                                      backend is ignored (see backend below) */
    vkrt_backend backend;          /* _DEFAULT: both GPU and CPU; else that one only */
    vkrt_intersector intersector;  /* _DEFAULT: both watertight and Moller-Trumbore */
    bool quick;                    /* fewer and smaller cases (the test suite's run) */
    FILE *out;                     /* the table; NULL: stdout */
} stress_options;

typedef struct stress_report {
    unsigned rows, failed_rows;    /* failed: watertight rows with leaks or over their limit */
    unsigned validation_messages;  /* summed over the contexts */
    char error[1024];              /* what failed when stress_run returns an error */
} stress_report;

/* Runs every case and prints the table. Returns VKRT_OK when the suite ran (out->failed_rows
 * says whether it passed), or the vkrt_result of the call that failed, with out->error naming
 * it. */
vkrt_result stress_run(const stress_options *options, stress_report *out);

#endif
