#!/usr/bin/env python3
"""Production resolution: the conference room from 720p to 8K at a cheap cache setting, every
default layer. For each size, the process's wall time, the render's own (`wall_s` of --stats,
which ends with the last pixel), the time after the render (writing the EXR and the PNG
preview) and its share, and the peak memory: the process's (the operating system's maximum
resident size) and at the end of the render (`peak_memory_bytes` of --stats).

    python3 bench/resolution.py            # about 8 minutes on 2 cores, under 1 GB of memory at 8K
    python3 bench/resolution.py --quick    # 720p and 1080p only: a check, not a result
    python3 bench/resolution.py --page-only 4.9   # the page again from the last runs (they took 4.9 min)

Writes docs/RESOLUTION.md, docs/resolution/runs.csv and docs/resolution/resolution.png. Needs
/usr/bin/time (GNU time) for the process's peak, and matplotlib for the plot.
"""

import argparse
import datetime
import os
import subprocess
import time

import common

SCENE = os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf")
SIZES = [("720p", 1280, 720), ("1080p", 1920, 1080), ("1440p", 2560, 1440), ("4K", 3840, 2160),
         ("8K", 7680, 4320)]
# Cheap: one bounce, a coarse cache, few hemisphere rays (the size, not the lighting, is measured).
OPTIONS = ["-ab", "1", "-aa", "0.4", "-ad", "128"]
DOCS = os.path.join(common.ROOT, "docs")
# The targets (docs page lists them against the measurement).
TARGET_4K_BYTES, TARGET_8K_BYTES, TARGET_AFTER_SHARE = 1e9, 1.5e9, 0.02
# The prepass's two pixel maps (the edges, the pixels needing samples): a bit each a pixel.
PIXEL_MAPS_BYTES = 0.25


def run(name, width, height, work):
    out = os.path.join(work, f"{name}.exr")
    stats_path = out + ".json"
    peak_path = out + ".peak"
    cmd = ["/usr/bin/time", "-f", "%M", "-o", peak_path, common.BINARY, "render", SCENE, "-o", out, "-q",
           "--overwrite", "--stats", stats_path, "-x", str(width), "-y", str(height)] + OPTIONS
    start = time.perf_counter()
    subprocess.run(cmd, check=True)
    wall = time.perf_counter() - start
    import json
    with open(stats_path) as f:
        stats = json.load(f)
    with open(peak_path) as f:
        peak_kb = int(f.read().split()[-1])
    render = stats["wall_s"]
    return {"size": name, "width": width, "height": height, "pixels": width * height,
            "process_s": round(wall, 2), "render_s": round(render, 2), "after_s": round(wall - render, 2),
            "after_pct": round(100 * (wall - render) / wall, 1), "peak_mb": round(peak_kb * 1024 / 1e6),
            "render_end_peak_mb": round((stats.get("peak_memory_bytes") or 0) / 1e6),
            "bytes_per_pixel": round(peak_kb * 1024 / (width * height)), "exr_mb": round(os.path.getsize(out) / 1e6, 1),
            "records": stats.get("cache_records", 0)}


def plot(rows, path):
    common.require("bench/resolution.py", modules=["matplotlib"])
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    mp = [r["pixels"] / 1e6 for r in rows]
    fig, (a, b) = plt.subplots(1, 2, figsize=(10, 3.8))
    a.plot(mp, [r["render_s"] for r in rows], "o-", label="render")
    a.plot(mp, [r["after_s"] for r in rows], "s-", label="after the render")
    a.set_xlabel("megapixels")
    a.set_ylabel("seconds")
    a.set_xscale("log")
    a.set_yscale("log")
    a.legend()
    a.set_title("time")
    b.plot(mp, [r["peak_mb"] for r in rows], "o-", label="process peak")
    b.plot(mp, [r["render_end_peak_mb"] for r in rows], "s-", label="at the render's end")
    b.axhline(TARGET_4K_BYTES / 1e6, color="gray", ls="--", lw=0.8, label="4K target (1 GB)")
    b.set_xlabel("megapixels")
    b.set_ylabel("MB")
    b.set_xscale("log")
    b.set_yscale("log")
    b.legend()
    b.set_title("peak memory")
    for axis in (a, b):
        for r, x in zip(rows, mp):
            axis.annotate(r["size"], (x, axis.get_ylim()[0]), fontsize=7, ha="center", va="bottom")
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)


def memory_verdict(rows):
    """The peaks fitted (least squares over the sizes) as a constant plus a share a record plus a
    share a pixel: what grows with the image beyond the records is the pixel's share, known to
    within its standard error (the records grow with the pixels, so the two shares are told
    apart only as far as the sizes' spread allows)."""
    import numpy as np
    design = np.array([[1.0, r["pixels"] / 1e6, r["records"] / 1e3] for r in rows])
    peaks = np.array([float(r["peak_mb"]) for r in rows])
    coefficients, *_ = np.linalg.lstsq(design, peaks, rcond=None)
    const, per_pixel, per_record = coefficients
    residuals = peaks - design @ coefficients
    dof = max(len(rows) - 3, 1)
    covariance = residuals @ residuals / dof * np.linalg.inv(design.T @ design)
    error = float(np.sqrt(covariance[1, 1]))
    sizes = ", ".join(r["size"] for r in rows)
    # Met when the fit cannot tell the pixel's share from the prepass's two pixel maps.
    met = per_pixel - 2 * error <= PIXEL_MAPS_BYTES
    return (f"- Memory beyond the records' share grows with the tiles and threads, not with the image: the peaks of "
            f"{sizes} fit {const:.0f} MB + {per_record:.2f} KB a record + {per_pixel:.2f} ± {error:.2f} bytes a pixel "
            f"(one standard error; the fit within {np.abs(residuals).max():.0f} MB of every peak), against the "
            f"200 bytes a pixel of a frame held whole; {'met' if met else 'not met'}: "
            f"{'no' if met else 'a'} share a pixel beyond the prepass's two pixel maps ({PIXEL_MAPS_BYTES} byte) "
            f"shows at two standard errors (at most {per_pixel + 2 * error:.1f} bytes a pixel).")


def page(rows, minutes, quick):
    """docs/RESOLUTION.md from the runs."""
    by = {r["size"]: r for r in rows}
    lines = ["# Production resolution", "",
             f"Written by `python3 bench/resolution.py` on {datetime.date.today()} "
             f"({minutes:.1f} min, {os.cpu_count()} cores)"
             f"{' with --quick: not a result' if quick else ''}; every run in "
             "[resolution/runs.csv](resolution/runs.csv).", "",
             f"The conference room, every default layer, `{' '.join(OPTIONS)}`, all cores, one run per size. "
             "Render: the render's own `wall_s`, to its last pixel; after: writing the EXR and the PNG "
             "preview; peak: the process's largest resident size (GNU time), and at the render's end.", "",
             "| size | pixels | process s | render s | after the render s | after % | peak MB | bytes a pixel | "
             "at the render's end MB | EXR MB |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['size']} ({r['width']}x{r['height']}) | {r['pixels']:,} | {r['process_s']} | {r['render_s']} | "
                     f"{r['after_s']} | {r['after_pct']} | {r['peak_mb']} | {r['bytes_per_pixel']} | "
                     f"{r['render_end_peak_mb']} | {r['exr_mb']} |")
    lines += ["", "![time and peak memory against the size](resolution/resolution.png)", "", "Targets:", ""]
    if "4K" in by:
        r = by["4K"]
        lines.append(f"- 4K, every default layer, peak at most 1 GB: {r['peak_mb']} MB, "
                     f"{'met' if r['peak_mb'] * 1e6 <= TARGET_4K_BYTES else 'not met'}.")
    if "8K" in by:
        r = by["8K"]
        lines.append(f"- 8K in at most 1.5 GB: {r['peak_mb']} MB, "
                     f"{'met' if r['peak_mb'] * 1e6 <= TARGET_8K_BYTES else 'not met'}.")
    if len(rows) >= 4:
        lines.append(memory_verdict(rows))
    worst = max(rows, key=lambda r: r["after_pct"])
    lines.append(f"- Time after the last tile at most 2% of the process's: {worst['after_pct']}% at {worst['size']} "
                 f"(the largest share), {'met' if worst['after_pct'] <= 100 * TARGET_AFTER_SHARE else 'not met'}.")
    lines.append("")
    with open(os.path.join(DOCS, "RESOLUTION.md"), "w") as f:
        f.write("\n".join(lines))
    print(f"wrote {os.path.join(DOCS, 'RESOLUTION.md')}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="720p and 1080p only: a check, not a result")
    parser.add_argument("--page-only", type=float, metavar="MINUTES",
                        help="write the page again from docs/resolution/runs.csv (the runs took MINUTES)")
    args = parser.parse_args()
    folder = os.path.join(DOCS, "resolution")
    if args.page_only is not None:
        rows = common.read_csv(os.path.join(folder, "runs.csv"))
        page(rows, args.page_only, args.quick)
        return
    common.require("bench/resolution.py", modules=["matplotlib"], commands=["/usr/bin/time"])
    common.build()
    work = common.scratch()
    started = time.time()
    rows = []
    for name, width, height in SIZES[:2] if args.quick else SIZES:
        row = run(name, width, height, work)
        rows.append(row)
        os.remove(os.path.join(work, f"{name}.exr"))
        print(f"[resolution] {name:>5} {width}x{height}: {row['process_s']:7.1f} s, render {row['render_s']:7.1f} s, "
              f"after {row['after_s']:5.1f} s ({row['after_pct']}%), peak {row['peak_mb']} MB "
              f"({row['bytes_per_pixel']} bytes a pixel), {row['render_end_peak_mb']} MB at the render's end")
    os.makedirs(folder, exist_ok=True)
    common.write_csv(os.path.join(folder, "runs.csv"), rows)
    plot(rows, os.path.join(folder, "resolution.png"))
    page(rows, (time.time() - started) / 60, args.quick)


if __name__ == "__main__":
    main()
