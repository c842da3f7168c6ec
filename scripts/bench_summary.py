#!/usr/bin/env python3
"""The headline table of a `scripts/bench` run: one line per scene from bench.csv, the
default configuration (SAH BVH, watertight) on each backend, the work per ray, and the worst
error of any configuration against the double-precision reference.
Usage: bench_summary.py bench.csv > summary.md"""
import csv
import os
import sys


def main():
    rows = list(csv.DictReader(open(sys.argv[1], encoding="utf-8")))
    scenes = []
    for r in rows:
        if r["scene"] not in scenes:
            scenes.append(r["scene"])
    print("| scene | triangles | SAH build ms | SAH cost | GPU Mrays/s | CPU float Mrays/s | CPU double Mrays/s "
          "| boxes/ray | tests/ray | midpoint GPU Mrays/s | worst mismatched px | worst depth err |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")

    for scene in scenes:
        mine = [r for r in rows if r["scene"] == scene]

        def pick(builder, backend, precision):
            for r in mine:
                if (r["builder"], r["backend"], r["traversal"], r["intersector"], r["precision"]) == \
                        (builder, backend, "bvh", "watertight", precision):
                    return r
            return None

        gpu, cpu, dbl, mid = pick("sah", "gpu", "float"), pick("sah", "cpu", "float"), \
            pick("sah", "cpu", "double"), pick("midpoint", "gpu", "float")
        base = cpu or gpu
        name = "built-in" if scene == "built-in" else os.path.basename(scene)

        def rate(r):
            return f"{float(r['mrays_per_s']):.2f}" if r else "-"

        worst_px = max(int(r["mismatched_pixels"]) for r in mine)
        worst_depth = max(float(r["depth_rel_max"]) for r in mine)
        print(f"| {name} | {base['triangles']} | {float(base['build_ms']):.1f} | {float(base['sah_cost']):.2f} "
              f"| {rate(gpu)} | {rate(cpu)} | {rate(dbl)} | {float(base['boxes_per_ray']):.2f} "
              f"| {float(base['tests_per_ray']):.2f} | {rate(mid)} | {worst_px} | {worst_depth:.2e} |")


if __name__ == "__main__":
    main()
