#!/usr/bin/env python3
"""Error against run time for the irradiance cache, with brute force at equal times as the
baseline curve: sweeps -aa (0.3 .. 0.05) and -ad, writes a CSV and a PNG plot.

    python3 bench/sweep.py                       # Cornell box (shared), 256x256, -ab 1
    python3 bench/sweep.py --scene conference --size 320x240 --ab 1

The reference is `icrender reference` (brute force, progressive) at the same view and options,
rendered once and kept under bench/out/.
"""

import argparse
import csv
import os

import common

SCENES = {
    "cornell": os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"),
    "conference": os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"),
    "default": os.path.join(common.ROOT, "scenes", "cornell.gltf"),
    "corridor": os.path.join(common.ROOT, "scenes", "corridor.gltf"),
}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scene", default="cornell", help="cornell, conference, default, corridor, or a .gltf path")
    parser.add_argument("--size", default="256x256")
    parser.add_argument("--ab", default="1")
    parser.add_argument("--spp", default="4", help="pixel samples for every run (antialiasing)")
    parser.add_argument("--light-samples", default="4", help="shadow rays per shading point for every run")
    parser.add_argument("--accuracies", default="0.3,0.2,0.15,0.1,0.07,0.05")
    parser.add_argument("--divisions", default="256,512,1024")
    parser.add_argument("--brute-divisions", default="2,4,8,16,32,64", help="-ad of the brute-force runs")
    parser.add_argument("--noise", type=float, default=0.003, help="reference noise target")
    parser.add_argument("--out", default=os.path.join(common.ROOT, "bench", "out"))
    args = parser.parse_args()
    common.require("bench/sweep.py", ["matplotlib"])

    scene = SCENES.get(args.scene, args.scene)
    name = os.path.splitext(os.path.basename(scene))[0]
    width, height = args.size.split("x")
    os.makedirs(args.out, exist_ok=True)
    common.build()
    base = ["-x", width, "-y", height, "-ab", args.ab, "--spp", args.spp, "--light-samples", args.light_samples]
    ref = common.reference(scene, os.path.join(args.out, f"{name}-{args.size}-ab{args.ab}-reference.exr"),
                           base + ["-ad", "64"], noise=args.noise)
    work = common.scratch()
    rows = []
    for ad in args.divisions.split(","):
        for aa in args.accuracies.split(","):
            stats, errors = common.render(scene, os.path.join(work, "c.exr"), base + ["-aa", aa, "-ad", ad], ref)
            rows.append(("cache", aa, ad, stats["render_s"], stats["records_computed"], *errors["composite"], *errors["indirect"]))
            print(f"cache  -aa {aa:>5} -ad {ad:>5}: {stats['render_s']:7.2f} s  {stats['records_computed']:6d} records  relMSE {errors['composite'][1]:.3e}")
    for ad in args.brute_divisions.split(","):
        stats, errors = common.render(scene, os.path.join(work, "b.exr"), base + ["-aa", "0", "-ad", ad], ref)
        rows.append(("brute force", "0", ad, stats["render_s"], 0, *errors["composite"], *errors["indirect"]))
        print(f"brute  -ad {ad:>5}:            {stats['render_s']:7.2f} s                  relMSE {errors['composite'][1]:.3e}")

    csv_path = os.path.join(args.out, f"sweep-{name}.csv")
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["renderer", "aa", "ad", "time_s", "records", "rmse", "relmse", "indirect_rmse", "indirect_relmse"])
        w.writerows(rows)

    plt = common.ensure_module("matplotlib.pyplot", "matplotlib")
    fig, axes = plt.subplots(1, 2, figsize=(12, 5))
    for ax, column, what in ((axes[0], 6, "composite"), (axes[1], 8, "indirect diffuse layer")):
        for ad in args.divisions.split(","):
            pts = sorted((r[3], r[column]) for r in rows if r[0] == "cache" and r[2] == ad)
            ax.plot(*zip(*pts), "o-", label=f"irradiance cache -ad {ad} (-aa {args.accuracies})")
        pts = sorted((r[3], r[column]) for r in rows if r[0] == "brute force")
        ax.plot(*zip(*pts), "s--", color="black", label=f"brute force (-aa 0, -ad {args.brute_divisions})")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("render time (s)")
        ax.set_ylabel("relative MSE against the reference")
        ax.set_title(f"{name} {args.size}, -ab {args.ab}, {args.spp} spp: {what}")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    png_path = os.path.join(args.out, f"sweep-{name}.png")
    fig.savefig(png_path, dpi=110, bbox_inches="tight")
    print(f"wrote {csv_path} and {png_path}")


if __name__ == "__main__":
    main()
