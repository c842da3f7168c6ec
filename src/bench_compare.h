/* `vkrt bench --compare embree`: vkrt_trace_rays on both backends and Embree 3 on exactly the
 * same rays and triangles, timed in one run. Built only with Embree (VKRT_HAVE_EMBREE). */
#ifndef VKRT_BENCH_COMPARE_H
#define VKRT_BENCH_COMPARE_H

#include "bench.h"

/* Rays and query per table row: the primary rays' closest hits, and from those hits' offset
 * points AO_RAYS_PER_HIT cosine-distributed rays up to AO_DISTANCE, closest and any hit. */
#define BENCH_COMPARE_AO_RAYS_PER_HIT 4
#define BENCH_COMPARE_AO_DISTANCE 0.5f /* as vkrt_render_desc.ao_distance's default */

/* Prints the comparison table (and the CSV at options->csv_path) for options' scene, view and
 * size; options->backend limits vkrt to one backend. Returns as bench_run(). */
vkrt_result bench_compare_run(const bench_options *options, bench_report *out);

#endif
