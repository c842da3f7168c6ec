/* `vkrt bench --modes`: run time against error for the lighting modes. For one scene and view,
 * shaded, ao and path at several samples per pixel, with adaptive target errors, and with
 * every feature compiled in against the specialised pipeline (what the skip saves), on both
 * backends; each row's image compared with a converged reference (bench_reference.h): RMSE,
 * relative MSE and PSNR. Uses vkrt.h only. */
#ifndef VKRT_BENCH_MODES_H
#define VKRT_BENCH_MODES_H

#include "bench.h"

/* The rows' samples per pixel: the full run's and --quick's. */
#define BENCH_MODES_SPP { 1, 4, 16, 64 }
#define BENCH_MODES_QUICK_SPP { 1, 4 }
/* Adaptive rows: these target errors, up to the largest spp of the run (quick: 16, as a pixel
 * takes 8 samples before it may stop). */
#define BENCH_MODES_TARGETS { 0.1f, 0.05f }
#define BENCH_MODES_QUICK_ADAPTIVE_SPP 16

/* Prints the table (and the CSV at options->csv_path); options->width and height default to
 * 128x128 (quick: 64x64), repeat to 3 (quick: 1). Returns as bench_run(). */
vkrt_result bench_modes_run(const bench_options *options, bench_report *out);

#endif
