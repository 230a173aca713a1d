#!/usr/bin/env python3
"""The default build (the cache prepass) under mpirun, side by side with one threaded process:
every mode's wall time at several process counts on the paper's three scenes, and issue 53's
target case (conference room 640x360 -ab 2: `mpirun -np 3` against one process with 2 threads).

    python3 bench/default_build.py              # about 15 minutes on 2 idle cores
    python3 bench/default_build.py --quick      # a check that it runs (not a result)

Runs alternate (every configuration once, then again, ...), so a machine that slows down slows
them all alike. Wall time is what a user waits for; on this 2-core machine the ranks share the
cores, so `mpirun -np 3` (a master and two one-thread workers) is compared with one process with
2 threads: the same cores. For each scene and process count the modes are compared by their
median wall time with a percentile bootstrap interval over the repeats (as bench/paper.py does):
"faster" or "slower" when the whole interval of the difference lies on one side of zero, else
"within noise". Each run's statistics give the prepass's share of the time and the workers' time
waiting in the prepass's collectives (the rounds' barriers).

Writes docs/DEFAULT_BUILD.md and its CSVs under docs/default_build/.
"""

import argparse
import datetime
import json
import os
import random
import statistics
import subprocess
import time

import common

DOCS = os.path.join(common.ROOT, "docs")
OUT = os.path.join(DOCS, "default_build")
MODES = ["noshare", "centralised", "broadcast", "component"]
# name: (scene, options): the paper's scenes at sizes whose runs last a few seconds here.
SCENES = {
    "cornell": (os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"),
                ["-x", "256", "-y", "256", "-ab", "1", "-aa", "0.1"]),
    "corridor": (os.path.join(common.ROOT, "scenes", "corridor.gltf"),
                 ["-x", "256", "-y", "256", "-ab", "1", "-aa", "0.2"]),
    "conference": (os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"),
                   ["-x", "320", "-y", "180", "-ab", "2", "-aa", "0.2"]),
}
TARGET = ("conference", ["-x", "640", "-y", "360", "-ab", "2"])
MPI_ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_tcp_if_include="lo", OMPI_MCA_oob_tcp_if_include="lo")
BOOTSTRAP = 2000


def run(scene, options, mode, np, work):
    """One render; its wall time (seconds, measured here) and statistics."""
    out = os.path.join(work, "o.exr")
    stats_path = out + ".json"
    cmd = [common.BINARY, "render", scene, "-o", out, "-q", "--no-preview", "--overwrite", "--stats", stats_path]
    cmd += options
    if mode == "threads":
        cmd += ["--threads", str(np)]
    else:
        cmd = ["mpirun", "--oversubscribe", "-np", str(np)] + cmd + ["--mode", mode]
    start = time.perf_counter()
    result = subprocess.run(cmd, capture_output=True, text=True, env=MPI_ENV)
    wall = time.perf_counter() - start
    if result.returncode != 0:
        raise RuntimeError(f"failed: {' '.join(cmd)}\n{result.stderr}")
    with open(stats_path) as f:
        stats = json.load(f)
    workers = [r for r in stats.get("per_rank", []) if r.get("role") not in ("mc", "serial")]
    return {
        "wall_s": wall,
        "prepass_s": stats.get("prepass_s", 0.0),
        "render_s": stats.get("render_s", 0.0),
        "records": stats.get("prepass_records", 0),
        "rounds": stats.get("prepass_rounds", 0),
        # The workers' mean time in the prepass's collectives, and its share of their prepass.
        "pool_s": statistics.mean([r.get("prepass_pool_s", 0.0) for r in workers]) if workers else 0.0,
        "worker_prepass_s": statistics.mean([r.get("prepass_s", 0.0) for r in workers]) if workers else 0.0,
        "master_bytes_sent": next((r["bytes"] for r in stats.get("per_rank", []) if r.get("role") == "mc"), 0),
    }


def interval(a, b, rng):
    """Median of b less median of a (seconds; positive: a is faster) and its 95 % bootstrap
    interval over the repeats."""
    est = statistics.median(b) - statistics.median(a)
    boots = sorted(statistics.median([rng.choice(b) for _ in b]) - statistics.median([rng.choice(a) for _ in a])
                   for _ in range(BOOTSTRAP))
    return est, boots[int(0.025 * (BOOTSTRAP - 1))], boots[int(0.975 * (BOOTSTRAP - 1))]


def verdict(lo, hi):
    return "faster" if lo > 0 else "slower" if hi < 0 else "within noise"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="cornell,corridor,conference")
    parser.add_argument("--ranks", default="3,4,5")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--target-repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="one repeat, small images: a check, not a result")
    args = parser.parse_args()
    common.require("bench/default_build.py", commands=["mpirun"])
    common.build()
    os.makedirs(OUT, exist_ok=True)
    work = common.scratch()
    rng = random.Random(53)
    ranks = [int(r) for r in args.ranks.split(",")]
    repeats = 1 if args.quick else args.repeats
    scenes = {k: SCENES[k] for k in args.scenes.split(",")}
    if args.quick:
        scenes = {k: (s, ["-x", "96", "-y", "64"] + o[4:]) for k, (s, o) in scenes.items()}
    started = time.time()

    # The target case first: one process with 2 threads against mpirun -np 3 (component and
    # broadcast), alternating.
    t_scene, t_opts = TARGET
    t_path = SCENES[t_scene][0]
    if args.quick:
        t_opts = ["-x", "160", "-y", "90", "-ab", "2"]
    args.target_options = t_opts
    target = {"threads": [], "component": [], "broadcast": []}
    for _ in range(1 if args.quick else args.target_repeats):
        for label in target:
            np = 2 if label == "threads" else 3
            row = run(t_path, t_opts, label, np, work)
            target[label].append(row)
            print(f"[default_build] target {label:10s} {row['wall_s']:.2f} s (prepass {row['prepass_s']:.2f} s, "
                  f"workers in collectives {row['pool_s']:.2f} s)", flush=True)

    # Every mode at each process count on each scene, alternating.
    rows = []
    for rep in range(repeats):
        for name, (path, opts) in scenes.items():
            row = run(path, opts, "threads", 2, work)
            rows.append({"scene": name, "mode": "threads", "np": 1, "repeat": rep, **row})
            for np in ranks:
                for mode in MODES:
                    row = run(path, opts, mode, np, work)
                    rows.append({"scene": name, "mode": mode, "np": np, "repeat": rep, **row})
                    print(f"[default_build] {name} {mode} np {np}: {row['wall_s']:.2f} s", flush=True)
    common.write_csv(os.path.join(OUT, "runs.csv"), rows)
    target_rows = [{"label": k, "repeat": i, **r} for k, rs in target.items() for i, r in enumerate(rs)]
    common.write_csv(os.path.join(OUT, "target.csv"), target_rows)

    # Verdicts: at each scene and process count, the fastest mode by median, and component mode
    # against the best other mode.
    verdicts = []
    for name in scenes:
        threads = [r["wall_s"] for r in rows if r["scene"] == name and r["mode"] == "threads"]
        for np in ranks:
            walls = {m: [r["wall_s"] for r in rows if r["scene"] == name and r["mode"] == m and r["np"] == np]
                     for m in MODES}
            medians = {m: statistics.median(w) for m, w in walls.items()}
            best_other = min((m for m in MODES if m != "component"), key=lambda m: medians[m])
            est, lo, hi = interval(walls["component"], walls[best_other], rng)
            verdicts.append({
                "scene": name, "np": np, "fastest": min(medians, key=medians.get),
                **{f"{m}_s": round(medians[m], 3) for m in MODES},
                "threads_s": round(statistics.median(threads), 3),
                "best_other": best_other, "component_gain_s": round(est, 3),
                "gain_lo": round(lo, 3), "gain_hi": round(hi, 3),
                "verdict": "one run, no interval" if repeats < 2 else verdict(lo, hi),
            })
    common.write_csv(os.path.join(OUT, "verdicts.csv"), verdicts)
    write_page(args, target, verdicts, rows, ranks, repeats, time.time() - started)


def write_page(args, target, verdicts, rows, ranks, repeats, seconds):
    med = {k: statistics.median([r["wall_s"] for r in rs]) for k, rs in target.items()}
    lines = [
        "# The default build under mpirun",
        "",
        f"Written by `python3 bench/default_build.py{' --quick' if args.quick else ''}` on "
        f"{datetime.date.today().isoformat()} ({seconds / 60:.1f} min, {os.cpu_count()} cores); every run in "
        "[default_build/runs.csv](default_build/runs.csv), the target case in "
        "[default_build/target.csv](default_build/target.csv).",
        "",
        f"## The target case: conference room {' '.join(args.target_options)}, this machine's 2 cores",
        "",
        "| run | median wall s | ratio to 2 threads | prepass s | workers in collectives s | master bytes sent |",
        "|---|---|---|---|---|---|",
    ]
    names = {"threads": "one process, `--threads 2`", "component": "`mpirun -np 3 --mode component`",
             "broadcast": "`mpirun -np 3 --mode broadcast`"}
    for k, rs in target.items():
        lines.append(f"| {names[k]} | {med[k]:.2f} | {med[k] / med['threads']:.2f}x | "
                     f"{statistics.median([r['prepass_s'] for r in rs]):.2f} | "
                     f"{statistics.median([r['pool_s'] for r in rs]):.2f} | "
                     f"{int(statistics.median([r['master_bytes_sent'] for r in rs]))} |")
    lines += [
        "",
        f"Target: component within 1.15x of the 2-thread process ({med['component'] / med['threads']:.2f}x: "
        f"{'met' if med['component'] <= 1.15 * med['threads'] else 'not met'}), and no slower than broadcast "
        f"({med['component'] / med['broadcast']:.2f}x the time).",
        "",
        "## Every mode at 3 to 5 processes",
        "",
        f"Median wall seconds of {repeats} repeat(s); `mpirun -np N` is a master and N - 1 one-thread workers "
        "sharing the 2 cores; `threads` is one process with 2 threads. The verdict compares component mode with "
        "the fastest other mode (95 % bootstrap interval of the difference of medians).",
        "",
        "| scene | np | noshare | centralised | broadcast | component | 2 threads | fastest | component vs best other "
        "(s, interval) | verdict |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for v in verdicts:
        lines.append(f"| {v['scene']} | {v['np']} | {v['noshare_s']:.2f} | {v['centralised_s']:.2f} | "
                     f"{v['broadcast_s']:.2f} | {v['component_s']:.2f} | {v['threads_s']:.2f} | {v['fastest']} | "
                     f"{v['component_gain_s']:+.2f} ({v['gain_lo']:+.2f}..{v['gain_hi']:+.2f}) vs {v['best_other']} | "
                     f"{v['verdict']} |")
    faster = sum(v["verdict"] == "faster" for v in verdicts)
    slower = sum(v["verdict"] == "slower" for v in verdicts)
    lines += [
        "",
        f"Component mode faster than every other mode beyond noise at {faster} of {len(verdicts)} configurations, "
        f"slower beyond noise at {slower}, within noise at the rest.",
        "",
    ]
    with open(os.path.join(DOCS, "DEFAULT_BUILD.md"), "w") as f:
        f.write("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
