#!/usr/bin/env python3
"""The parallel modes side by side (paper, Figures 3 and 7-10): every mode at several rank
counts on the Cornell box and the conference room; writes a CSV and PNG plots of aggregated
cache misses, aggregated time (T_amb + T_notamb, CPU seconds) and idle time against ranks.

    python3 bench/mpi_modes.py                      # defaults: small images, ranks 2 3 4 8
    python3 bench/mpi_modes.py --ranks 2,4,8,16 --size 512x384

On this 2-core machine the ranks are oversubscribed, so wall-clock speed-up means nothing here;
the aggregated figures do not depend on the number of cores (times are CPU time). On a machine
with as many cores as ranks the same command's wall times are the speed-up.
"""

import argparse
import csv
import json
import os
import subprocess

import common

SCENES = {
    "cornell": os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"),
    "conference": os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"),
    "corridor": os.path.join(common.ROOT, "scenes", "corridor.gltf"),
}


def mpirun(np, args):
    env = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_tcp_if_include="lo", OMPI_MCA_oob_tcp_if_include="lo")
    cmd = ["mpirun", "--oversubscribe", "-np", str(np), common.BINARY] + args
    result = subprocess.run(cmd, capture_output=True, text=True, env=env)
    if result.returncode != 0:
        raise RuntimeError(f"failed: {' '.join(cmd)}\n{result.stderr}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="cornell,conference")
    parser.add_argument("--modes", default="noshare,centralised,broadcast,component")
    parser.add_argument("--ranks", default="2,3,4,8")
    parser.add_argument("--size", default="128x96")
    parser.add_argument("--options", default="-ab 1 -aa 0.2 -ad 256 -as 64 --tile 16x16",
                        help="render options shared by every run")
    parser.add_argument("--out", default=os.path.join(common.ROOT, "bench", "out"))
    args = parser.parse_args()
    common.require("bench/mpi_modes.py", ["matplotlib"], ["mpirun"])
    os.makedirs(args.out, exist_ok=True)
    common.build()
    width, height = args.size.split("x")
    # The modes as the paper has them: records made as tiles render.
    base = ["-x", width, "-y", height] + common.PAPER_BUILD + args.options.split()
    work = common.scratch()
    rows = []
    for scene_name in args.scenes.split(","):
        scene = SCENES.get(scene_name, scene_name)
        out = os.path.join(work, "s.exr")
        stats, _ = common.render(scene, out, base + ["--threads", "1"])
        serial = stats
        rows.append((scene_name, "serial", 1, stats["render_s"], stats["records_computed"], stats["t_amb_s"],
                     stats["t_notamb_s"], 0.0, 0, 0))
        print(f"{scene_name:>10} serial       1 rank : {stats['records_computed']:6d} misses, "
              f"T_amb {stats['t_amb_s']:.2f} s, T_notamb {stats['t_notamb_s']:.2f} s")
        for mode in args.modes.split(","):
            for np in [int(r) for r in args.ranks.split(",")]:
                if mode == "component" and np < 3:
                    continue  # needs an MC, a PR and a PA
                stats_path = os.path.join(work, f"{scene_name}-{mode}-{np}.json")
                try:
                    mpirun(np, ["render", scene, "-o", os.path.join(work, "m.exr"), "--mode", mode, "-q", "--no-preview", "--overwrite",
                                "--stats", stats_path] + base)
                except RuntimeError as e:
                    print(f"{scene_name:>10} {mode:<12} {np} ranks: {str(e).splitlines()[-1]}")
                    continue
                with open(stats_path) as f:
                    s = json.load(f)
                rows.append((scene_name, mode, np, s["render_s"], s["records_computed"], s["t_amb_s"], s["t_notamb_s"],
                             s["idle_s"], s["messages"], s["bytes"]))
                print(f"{scene_name:>10} {mode:<12} {np} ranks: {s['records_computed']:6d} misses, "
                      f"T_amb {s['t_amb_s']:.2f} s, T_notamb {s['t_notamb_s']:.2f} s, idle {s['idle_s']:.2f} s, "
                      f"{s['messages']} messages, {s['bytes']} bytes")
    csv_path = os.path.join(args.out, "mpi-modes.csv")
    with open(csv_path, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["scene", "mode", "ranks", "render_s", "misses", "t_amb_s", "t_notamb_s", "idle_s", "messages", "bytes"])
        w.writerows(rows)

    plt = common.ensure_module("matplotlib.pyplot", "matplotlib")
    for scene_name in args.scenes.split(","):
        fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
        mine = [r for r in rows if r[0] == scene_name]
        serial = [r for r in mine if r[1] == "serial"]
        for mode in args.modes.split(","):
            pts = sorted(r for r in mine if r[1] == mode)
            if not pts:
                continue
            ranks = [r[2] for r in pts]
            axes[0].plot(ranks, [r[4] for r in pts], "o-", label=mode)
            axes[1].plot(ranks, [r[5] + r[6] for r in pts], "o-", label=mode)
            axes[2].plot(ranks, [100 * r[7] / max(r[5] + r[6] + r[7], 1e-9) for r in pts], "o-", label=mode)
        if serial:
            axes[0].axhline(serial[0][4], color="gray", ls=":", label="serial")
            axes[1].axhline(serial[0][5] + serial[0][6], color="gray", ls=":", label="serial")
        for ax, title in zip(axes, ["aggregated cache misses", "aggregated time T_amb + T_notamb (CPU s)",
                                    "idle time (% of aggregated time)"]):
            ax.set_xlabel("MPI ranks")
            ax.set_title(f"{scene_name}: {title}", fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
        png = os.path.join(args.out, f"mpi-modes-{scene_name}.png")
        fig.savefig(png, dpi=100, bbox_inches="tight")
        print(f"wrote {png}")
    print(f"wrote {csv_path}")


if __name__ == "__main__":
    main()
