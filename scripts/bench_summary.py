#!/usr/bin/env python3
"""The headline table of a `scripts/bench` run: one line per scene from bench.csv, the
default configuration (SAH BVH, watertight) on each backend, the work per ray, and the worst
error of any configuration against the double-precision reference; with --embree embree.csv
(`vkrt bench --compare embree`), Embree's Mrays/s on the primary rays and vkrt's speed as a
ratio to it on primary rays and on AO rays (any hit), and the most rays any vkrt backend
answered differently from Embree.
Usage: bench_summary.py bench.csv [--embree embree.csv] > summary.md"""
import argparse
import csv
import os


def scene_name(scene):
    return "built-in" if scene == "built-in" else os.path.basename(scene)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("bench_csv")
    ap.add_argument("--embree", help="embree.csv of `vkrt bench --compare embree`")
    args = ap.parse_args()
    rows = list(csv.DictReader(open(args.bench_csv, encoding="utf-8")))
    embree = list(csv.DictReader(open(args.embree, encoding="utf-8"))) if args.embree else []
    scenes = []
    for r in rows:
        if r["scene"] not in scenes:
            scenes.append(r["scene"])
    head = ("| scene | triangles | SAH build ms | SAH cost | GPU Mrays/s | CPU float Mrays/s | CPU double Mrays/s "
            "| boxes/ray | tests/ray | midpoint GPU Mrays/s | SBVH cost | SBVH build ms | SBVH GPU Mrays/s "
            "| worst mismatched px | worst depth err |")
    rule = "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
    if embree:
        head += (" Embree Mrays/s | vkrt CPU/Embree primary | vkrt GPU/Embree primary | vkrt CPU/Embree AO any "
                 "| vkrt GPU/Embree AO any | mismatches vs Embree |")
        rule += "---|---|---|---|---|---|"
    print(head)
    print(rule)

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
        sbvh = pick("sbvh", "cpu", "float") or pick("sbvh", "gpu", "float")
        sbvh_gpu = pick("sbvh", "gpu", "float")
        base = cpu or gpu

        def rate(r):
            return f"{float(r['mrays_per_s']):.2f}" if r else "-"

        sbvh_cells = (f"{float(sbvh['sah_cost']):.2f} | {float(sbvh['build_ms']):.1f} | {rate(sbvh_gpu)}"
                      if sbvh else "- | - | -")
        worst_px = max(int(r["mismatched_pixels"]) for r in mine)
        worst_depth = max(float(r["depth_rel_max"]) for r in mine)
        line = (f"| {scene_name(scene)} | {base['triangles']} | {float(base['build_ms']):.1f} "
                f"| {float(base['sah_cost']):.2f} | {rate(gpu)} | {rate(cpu)} | {rate(dbl)} "
                f"| {float(base['boxes_per_ray']):.2f} | {float(base['tests_per_ray']):.2f} | {rate(mid)} "
                f"| {sbvh_cells} | {worst_px} | {worst_depth:.2e} |")
        if embree:
            theirs = [r for r in embree if r["scene"] == scene]

            def cmp(rays, query, engine, key):
                for r in theirs:
                    if (r["rays"], r["query"], r["engine"]) == (rays, query, engine):
                        return f"{float(r[key]):.2f}"
                return "-"

            worst = max((int(r["mismatches"]) for r in theirs), default=None)
            line += (f" {cmp('primary', 'closest', 'embree', 'mrays_per_s')} "
                     f"| {cmp('primary', 'closest', 'vkrt-cpu', 'ratio_to_embree')} "
                     f"| {cmp('primary', 'closest', 'vkrt-gpu', 'ratio_to_embree')} "
                     f"| {cmp('ao', 'any', 'vkrt-cpu', 'ratio_to_embree')} "
                     f"| {cmp('ao', 'any', 'vkrt-gpu', 'ratio_to_embree')} "
                     f"| {'-' if worst is None else worst} |")
        print(line)


if __name__ == "__main__":
    main()
