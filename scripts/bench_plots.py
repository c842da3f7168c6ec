#!/usr/bin/env python3
"""The plots of a `scripts/bench` run, as PNG files beside its CSV files (matplotlib, Debian's
python3-matplotlib, drawing off-screen):

- error_vs_time.png: per scene, the lighting modes' RMSE against trace time on log-log axes
  (modes.csv), each mode's Pareto front (no other row of that mode is both faster and more
  accurate) drawn as a line; a mode whose images are exact (RMSE 0) is said so, not drawn;
- mrays_vs_triangles.png: Mrays/s against triangle count (bench.csv), SAH BVH on each backend
  and naive traversal where it ran, log-log: a BVH's cost grows like log n, naive like n;
- builders.png: BVH build time and SAH cost against triangle count per builder (bench.csv),
  with Embree's rtcCommitScene time beside vkrt's builds (embree.csv);
- embree_ratio.png: vkrt's Mrays/s over Embree's per scene and query (embree.csv).

Usage: bench_plots.py OUTDIR   (reads OUTDIR/bench.csv, modes.csv, embree.csv where present)"""
import csv
import math
import os
import sys

import matplotlib

matplotlib.use("Agg")  # files only: no display on a build machine
import matplotlib.pyplot as plt  # noqa: E402

MODE_COLOURS = {"shaded": "tab:orange", "ao": "tab:blue", "path": "tab:green"}
BACKEND_MARKERS = {"gpu": "o", "cpu": "s"}
DPI = 110  # readable in README at GitHub's column width without huge files


def read(outdir, name):
    path = os.path.join(outdir, name)
    return list(csv.DictReader(open(path, encoding="utf-8"))) if os.path.exists(path) else []


def scene_name(scene):
    return "built-in" if scene == "built-in" else os.path.splitext(os.path.basename(scene))[0]


def scenes_of(rows):
    seen = []
    for r in rows:
        if r["scene"] not in seen:
            seen.append(r["scene"])
    return seen


def pareto(points):
    """The points no other point beats on both time and error, fastest first."""
    front, best = [], math.inf
    for t, e in sorted(points):
        if e < best:
            front.append((t, e))
            best = e
    return front


def error_vs_time(modes, path):
    scenes = scenes_of(modes)
    cols = min(4, len(scenes))
    rows = (len(scenes) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.2 * cols, 3.6 * rows), squeeze=False)
    for ax, scene in zip(axes.flat, scenes):
        mine = [r for r in modes if r["scene"] == scene]
        exact = []
        for mode, colour in MODE_COLOURS.items():
            rs = [r for r in mine if r["mode"] == mode]
            drawn = [r for r in rs if float(r["rmse"]) > 0]
            if rs and not drawn:
                exact.append(mode)
            for backend, marker in BACKEND_MARKERS.items():
                for adaptive in (False, True):
                    pts = [r for r in drawn if r["backend"] == backend and (float(r["target_error"]) > 0) == adaptive
                           and r["features"] == "specialised"]
                    ax.scatter([float(r["trace_ms"]) for r in pts], [float(r["rmse"]) for r in pts], marker=marker,
                               s=28, facecolors="none" if adaptive else colour, edgecolors=colour, linewidths=1.2)
            front = pareto([(float(r["trace_ms"]), float(r["rmse"])) for r in drawn if r["features"] == "specialised"])
            if front:
                ax.plot([p[0] for p in front], [p[1] for p in front], color=colour, linewidth=1.2, label=f"{mode} front")
            noise = [float(r["reference_noise"]) for r in rs if float(r["reference_noise"]) > 0]
            if noise:
                ax.axhline(noise[0], color=colour, linestyle=":", linewidth=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        title = f"{scene_name(scene)} ({mine[0]['triangles']} tris, {mine[0]['width']}x{mine[0]['height']})"
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("trace ms (log)", fontsize=8)
        ax.set_ylabel("RMSE (log)", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
        if exact:
            ax.text(0.02, 0.02, ", ".join(exact) + ": exact (RMSE 0), not drawn", transform=ax.transAxes, fontsize=7)
    for ax in list(axes.flat)[len(scenes):]:
        ax.axis("off")
    handles = [plt.Line2D([], [], color=c, label=f"{m}: Pareto front") for m, c in MODE_COLOURS.items()]
    handles += [plt.Line2D([], [], marker=mk, linestyle="", color="grey", label=b) for b, mk in BACKEND_MARKERS.items()]
    handles += [plt.Line2D([], [], marker="o", linestyle="", markerfacecolor="none", color="grey", label="adaptive"),
                plt.Line2D([], [], linestyle=":", color="grey", label="reference's own error")]
    fig.legend(handles=handles, loc="lower center", ncol=len(handles) if cols > 2 else 4, fontsize=8, frameon=False)
    fig.suptitle("Lighting modes: error against time (1 to 64 spp, adaptive 0.1 and 0.05)", fontsize=11)
    fig.tight_layout(rect=(0, 0.05 if cols > 2 else 0.1, 1, 0.96))
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def procedural(r):
    return r["scene"].startswith("procedural-")


def plot_series(ax, rows, x, y, colour, label, style="-", marker="o"):
    """The procedural series as a line (one shape at every size), the meshes as points beside it:
    different shapes, so a line through them would draw the shapes' differences as a trend."""
    series = [r for r in rows if procedural(r)]
    meshes = [r for r in rows if not procedural(r)]
    if series:
        ax.plot([x(r) for r in series], [y(r) for r in series], style, marker=marker, color=colour,
                label=f"{label}, procedural")
    if meshes:
        ax.plot([x(r) for r in meshes], [y(r) for r in meshes], linestyle="", marker=marker, markerfacecolor="none",
                color=colour, label=f"{label}, meshes")


def default_rows(bench, backend, traversal="bvh", builder="sah", precision="float"):
    out = [r for r in bench if (r["builder"], r["backend"], r["traversal"], r["intersector"], r["precision"]) ==
           (builder, backend, traversal, "watertight", precision)]
    return sorted(out, key=lambda r: int(r["triangles"]))


def mrays_vs_triangles(bench, path):
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    for backend, colour in (("gpu", "tab:purple"), ("cpu", "tab:red")):
        for traversal, style in (("bvh", "-"), ("naive", "--")):
            rs = default_rows(bench, backend, traversal)
            if not rs:
                continue
            plot_series(ax, rs, lambda r: int(r["triangles"]), lambda r: float(r["mrays_per_s"]), colour,
                        f"{backend} {traversal}", style)
            for r in [r for r in rs if not procedural(r)] if traversal == "bvh" and backend == "cpu" else []:
                ax.annotate(scene_name(r["scene"]), (int(r["triangles"]), float(r["mrays_per_s"])), fontsize=6,
                            xytext=(3, 3), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("triangles (log)")
    ax.set_ylabel("Mrays/s (log)")
    ax.set_title("Primary rays, SAH BVH (watertight, float) against naive traversal", fontsize=10)
    ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def builders(bench, embree, path):
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    for builder, colour in (("sah", "tab:blue"), ("midpoint", "tab:gray"), ("sbvh", "tab:green")):
        rs = default_rows(bench, "cpu", builder=builder)
        plot_series(left, rs, lambda r: int(r["triangles"]), lambda r: float(r["build_ms"]), colour, f"vkrt {builder}")
        plot_series(right, rs, lambda r: int(r["triangles"]), lambda r: float(r["sah_cost"]), colour, f"vkrt {builder}")
    rs = sorted([r for r in embree if r["engine"] == "embree" and r["rays"] == "primary"], key=lambda r: int(r["triangles"]))
    if rs:
        plot_series(left, rs, lambda r: int(r["triangles"]), lambda r: float(r["build_ms"]), "tab:red",
                    f"Embree 3 medium, {rs[0]['threads']} threads", marker="^")
    for ax in (left, right):
        ax.set_xscale("log")
        ax.set_xlabel("triangles (log)")
        ax.grid(True, which="both", linewidth=0.3, alpha=0.5)
        ax.legend(fontsize=7)
    left.set_yscale("log")
    left.set_ylabel("build ms (log)")
    left.set_title("BVH build time", fontsize=10)
    right.set_ylabel("SAH cost (C_trav = C_isect = 1)")
    right.set_title("SAH cost per builder", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def embree_ratio(embree, path):
    scenes = sorted(scenes_of(embree), key=lambda s: int(next(r for r in embree if r["scene"] == s)["triangles"]))
    series = [(rays, query, engine) for rays, query in (("primary", "closest"), ("ao", "closest"), ("ao", "any"))
              for engine in ("vkrt-cpu", "vkrt-gpu")]
    colours = ["tab:red", "tab:purple", "salmon", "plum", "darkred", "indigo"]
    fig, ax = plt.subplots(figsize=(min(12.0, max(6.4, 0.9 * len(scenes) + 2)), 4.6))
    width = 0.8 / len(series)
    for k, (key, colour) in enumerate(zip(series, colours)):
        vals = []
        for scene in scenes:
            r = [r for r in embree if r["scene"] == scene and (r["rays"], r["query"], r["engine"]) == key]
            vals.append(float(r[0]["ratio_to_embree"]) if r else 0.0)
        ax.bar([i + (k - len(series) / 2 + 0.5) * width for i in range(len(scenes))], vals, width, color=colour,
               label=f"{key[2]} {key[0]} {key[1]}")
    ax.axhline(1.0, color="black", linewidth=0.8)
    ax.set_xticks(range(len(scenes)))
    ax.set_xticklabels([f"{scene_name(s)}\n{next(r for r in embree if r['scene'] == s)['triangles']} tris"
                        for s in scenes], fontsize=7, rotation=25, ha="right")
    ax.set_ylabel("vkrt Mrays/s / Embree Mrays/s")
    threads = embree[0]["threads"] if embree else "?"
    ax.set_title(f"vkrt against Embree 3 on the same rays ({threads} threads; 1 = as fast)", fontsize=10)
    ax.legend(fontsize=7, ncol=6, loc="upper center", bbox_to_anchor=(0.5, -0.3), frameon=False)
    ax.set_ylim(0, max(1.1, ax.get_ylim()[1]))
    ax.grid(True, axis="y", linewidth=0.3, alpha=0.5)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    plt.close(fig)


def main():
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    outdir = sys.argv[1]
    bench, modes, embree = read(outdir, "bench.csv"), read(outdir, "modes.csv"), read(outdir, "embree.csv")
    made = []
    if modes:
        error_vs_time(modes, os.path.join(outdir, "error_vs_time.png"))
        made.append("error_vs_time.png")
    if bench:
        mrays_vs_triangles(bench, os.path.join(outdir, "mrays_vs_triangles.png"))
        builders(bench, embree, os.path.join(outdir, "builders.png"))
        made += ["mrays_vs_triangles.png", "builders.png"]
    if embree:
        embree_ratio(embree, os.path.join(outdir, "embree_ratio.png"))
        made.append("embree_ratio.png")
    print("bench_plots: " + ", ".join(os.path.join(outdir, m) for m in made), file=sys.stderr)


if __name__ == "__main__":
    main()
