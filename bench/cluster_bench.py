#!/usr/bin/env python3
"""The parallel modes on a cluster made of network namespaces (tests/cluster/testbed.sh): every
rank on a host of its own, every message over TCP through a veth link and a bridge, the links
unshaped or capped (tc tbf) at 1 Gbit/s (the paper's cluster) or 100 Mbit/s. Writes one CSV and
one PNG of wall time, aggregated cache misses, idle time and bytes against the link speed.

    sudo python3 bench/cluster_bench.py                  # defaults: about 5 minutes on 2 cores
    sudo python3 bench/cluster_bench.py --ranks 4,8,16 --size 256x192 --links unshaped,1gbit,100mbit,10mbit

Needs root (namespaces, links, tc); says so and exits with code 77 otherwise. On a machine with
fewer cores than ranks the ranks share the cores, so wall times mix the network's cost with
oversubscription; misses, idle time and bytes are what the links change. `bytes` is what the
ranks report sending; `kernel_bytes` is what the kernel counted on their hosts' links over the
whole mpirun (TCP/IP headers, ACKs and mpirun's own control traffic included).

Each link setting's message cost is measured too (`icrender bench messages` between hosts 0 and
1: latency and bandwidth, in cluster-links.csv), and at the end every run is simulated by the
cluster-scale simulation (bench/cluster_sim.py, bench/icsim.py) with those measured costs, its
prediction error printed per run and in all (cluster-validation.csv).
"""

import argparse
import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time

import cluster_sim
import common

TESTBED = os.path.join(common.ROOT, "tests", "cluster", "testbed.sh")
SKIP = 77
SCENES = {
    "cornell": os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"),
    "conference": os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"),
    "corridor": os.path.join(common.ROOT, "scenes", "corridor.gltf"),
}
ENV = dict(os.environ, ICR_TESTBED_ID="icrbench", ICR_TESTBED_OWNER=str(os.getpid()))


def testbed(*args, check=True, **kwargs):
    result = subprocess.run(["bash", TESTBED] + [str(a) for a in args], env=ENV, capture_output=True, text=True,
                            **kwargs)
    if result.returncode == SKIP:
        print(f"cluster_bench: {result.stderr.strip()}")
        sys.exit(SKIP)
    if check and result.returncode != 0:
        raise RuntimeError(f"testbed.sh {' '.join(map(str, args))}: {result.stderr.strip()}")
    return result


def tx_bytes():
    """Bytes each host has sent on its link so far."""
    return [int(line.split()[2]) for line in testbed("counters").stdout.splitlines()]


def up(hosts, link):
    testbed("up", hosts, *([] if link == "unshaped" else ["--rate", link]))


def run_mode(scene, mode, ranks, base, work, timeout):
    out = os.path.join(work, "m.exr")
    stats_path = os.path.join(work, "m.json")
    for path in (out, stats_path):
        if os.path.exists(path):
            os.remove(path)
    before = tx_bytes()
    start = time.monotonic()
    cmd = ["bash", TESTBED, "mpirun", "-np", str(ranks), common.BINARY, "render", scene, "-o", out, "--mode", mode,
           "-q", "--no-preview", "--stats", stats_path, "--timeout", str(timeout)] + base + common.RASTER_ORDER
    try:
        result = subprocess.run(cmd, env=ENV, capture_output=True, text=True, timeout=timeout + 60)
    except subprocess.TimeoutExpired:
        return None, f"no end after {timeout + 60} s"
    elapsed = time.monotonic() - start
    after = tx_bytes()
    if result.returncode != 0 or not os.path.exists(stats_path):
        lines = [l for l in (result.stderr or "").splitlines() if l.strip()]
        return None, lines[-1] if lines else f"exit code {result.returncode}"
    with open(stats_path) as f:
        s = json.load(f)
    kernel = sum(a - b for a, b in zip(after[:ranks], before[:ranks]))
    workers = [r for r in s.get("per_rank", []) if r.get("role") != "mc"]
    return {"mpirun_s": elapsed, "wall_s": s["wall_s"], "render_s": s["render_s"], "misses": s["records_computed"],
            "idle_s": s["idle_s"], "messages": s["messages"], "bytes": s["bytes"], "kernel_bytes": kernel,
            "aggregated_s": sum(r["t_amb_s"] + r["t_notamb_s"] for r in workers),
            "requests_sent": s.get("requests_sent", 0)}, None


def measure_link(link):
    """Latency and bandwidth between hosts 0 and 1 as MPI sees them (`icrender bench messages`)."""
    result = testbed("mpirun", "-np", 2, common.BINARY, "bench", "messages", check=False, timeout=120)
    if result.returncode != 0:
        print(f"cluster_bench: link {link}: message cost not measured: {result.stderr.strip()[-200:]}")
        return None
    cost = json.loads(result.stdout.strip().splitlines()[-1])
    print(f"{'link':>10} {link:>9}: latency {cost['latency_s'] * 1e6:7.1f} us, bandwidth "
          f"{cost['bandwidth_bytes_per_s'] / 1e6:8.1f} MB/s (icrender bench messages, host 0 <-> host 1)")
    return {"link": link, "latency_s": cost["latency_s"], "bandwidth_bytes_per_s": cost["bandwidth_bytes_per_s"]}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="cornell,conference")
    parser.add_argument("--modes", default="noshare,centralised,broadcast,component")
    parser.add_argument("--ranks", default="4,8")
    parser.add_argument("--links", default="unshaped,1gbit,100mbit",
                        help="link settings: 'unshaped' or a tc rate (1gbit, 100mbit, ...)")
    parser.add_argument("--size", default="192x144")
    parser.add_argument("--options", default="-ab 1 -aa 0.2 -ad 256 -as 64 --tile 16x16",
                        help="render options shared by every run")
    parser.add_argument("--timeout", type=int, default=120, help="the master's --timeout, seconds")
    parser.add_argument("--out", default=os.path.join(common.ROOT, "bench", "out"))
    parser.add_argument("--docs", default=os.path.join(common.ROOT, "docs", "cluster"),
                        help="where the CSVs and the plot are kept in the repository (copies of --out's)")
    args = parser.parse_args()
    common.require("bench/cluster_bench.py", ["matplotlib"], ["mpirun", "ip"])
    # A termination still tears the test bed down (the finally below).
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    os.makedirs(args.out, exist_ok=True)
    common.build()
    width, height = args.size.split("x")
    base = ["-x", width, "-y", height] + args.options.split()
    ranks = [int(r) for r in args.ranks.split(",")]
    scenes = args.scenes.split(",")
    links = args.links.split(",")
    work = common.scratch()
    rows = []
    fields = ["scene", "link", "mode", "ranks", "mpirun_s", "wall_s", "render_s", "misses", "idle_s", "messages",
              "bytes", "kernel_bytes", "aggregated_s", "requests_sent", "status"]
    link_rows = []

    for scene_name in scenes:
        scene = SCENES.get(scene_name, scene_name)
        stats, _ = common.render(scene, os.path.join(work, "s.exr"), base + ["--threads", "1"] + common.RASTER_ORDER)
        rows.append({"scene": scene_name, "link": "-", "mode": "serial", "ranks": 1, "mpirun_s": "",
                     "wall_s": stats["wall_s"], "render_s": stats["render_s"], "misses": stats["records_computed"],
                     "idle_s": 0.0, "messages": 0, "bytes": 0, "kernel_bytes": 0,
                     "aggregated_s": stats["t_amb_s"] + stats["t_notamb_s"], "requests_sent": 0, "status": "ok"})
        print(f"{scene_name:>10} serial: {stats['records_computed']} misses, {stats['render_s']:.2f} s")

    started = time.monotonic()
    try:
        for link in links:
            up(max(ranks), link)
            measured = measure_link(link)
            if measured:
                link_rows.append(measured)
            for scene_name in scenes:
                scene = SCENES.get(scene_name, scene_name)
                for mode in args.modes.split(","):
                    for np in ranks:
                        result, error = run_mode(scene, mode, np, base, work, args.timeout)
                        row = {"scene": scene_name, "link": link, "mode": mode, "ranks": np}
                        if result is None:
                            print(f"{scene_name:>10} {link:>9} {mode:<12} {np} ranks: FAILED: {error}")
                            rows.append(dict(row, status=f"failed: {error}"))
                            # Whatever the failed run left on the hosts goes with a fresh bed.
                            up(max(ranks), link)
                            continue
                        rows.append(dict(row, status="ok", **result))
                        print(f"{scene_name:>10} {link:>9} {mode:<12} {np} ranks: wall {result['wall_s']:6.2f} s "
                              f"(render {result['render_s']:5.2f} s, mpirun {result['mpirun_s']:5.2f} s), "
                              f"{result['misses']:6d} misses, idle {result['idle_s']:6.2f} s, "
                              f"{result['bytes'] / 1e6:7.3f} MB reported, {result['kernel_bytes'] / 1e6:7.3f} MB on "
                              f"the links")
    finally:
        testbed("down", check=False)
    print(f"runs on the test bed: {time.monotonic() - started:.0f} s")

    csv_path = os.path.join(args.out, "cluster-bench.csv")
    with open(csv_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    links_path = os.path.join(args.out, "cluster-links.csv")
    with open(links_path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=["link", "latency_s", "bandwidth_bytes_per_s"])
        w.writeheader()
        w.writerows(link_rows)
    settings_path = os.path.join(args.out, "cluster-bench.json")
    with open(settings_path, "w") as f:
        json.dump({"size": args.size, "options": args.options}, f)

    plt = common.ensure_module("matplotlib.pyplot", "matplotlib")
    metrics = [("wall_s", "wall time (s)"), ("misses", "aggregated cache misses"),
               ("idle_s", "aggregated idle time (s)"), ("bytes", "bytes sent (MB)")]
    fig, axes = plt.subplots(len(scenes), len(metrics), figsize=(4.2 * len(metrics), 3.6 * len(scenes)),
                             squeeze=False)
    colours = dict(zip(args.modes.split(","), ["tab:blue", "tab:orange", "tab:green", "tab:red", "tab:purple"]))
    styles = ["o-", "s--", "^:", "d-."]
    for i, scene_name in enumerate(scenes):
        mine = [r for r in rows if r["scene"] == scene_name and r["status"] == "ok"]
        serial = [r for r in mine if r["mode"] == "serial"]
        for j, (key, title) in enumerate(metrics):
            ax = axes[i][j]
            for mode in args.modes.split(","):
                for k, np in enumerate(ranks):
                    pts = [(links.index(r["link"]), r[key]) for r in mine if r["mode"] == mode and r["ranks"] == np]
                    if not pts:
                        continue
                    pts.sort()
                    scale = 1e-6 if key == "bytes" else 1.0
                    ax.plot([p[0] for p in pts], [p[1] * scale for p in pts], styles[k % len(styles)],
                            color=colours.get(mode), label=f"{mode} {np}")
            if key == "misses" and serial:
                ax.axhline(serial[0]["misses"], color="gray", ls=":", label="serial")
            ax.set_xticks(range(len(links)))
            ax.set_xticklabels(links)
            ax.set_title(f"{scene_name}: {title}", fontsize=9)
            ax.grid(True, alpha=0.3)
            if i == 0 and j == 0:
                ax.legend(fontsize=6, ncol=2)
    fig.suptitle(f"icrender modes on the namespace cluster, {args.size}, ranks {args.ranks}", fontsize=10)
    png = os.path.join(args.out, "cluster-bench.png")
    fig.savefig(png, dpi=100, bbox_inches="tight")
    print(f"wrote {csv_path}")
    print(f"wrote {png}")

    # The cluster-scale simulation fed with the measured message costs: its prediction error.
    check, note = cluster_sim.validate(csv_path, links_path, settings_path, args.out)
    validation = os.path.join(args.out, "cluster-validation.csv")
    common.write_csv(validation, check)
    print(note)
    print(f"wrote {validation}")
    os.makedirs(args.docs, exist_ok=True)
    for path in (csv_path, png, links_path, validation):
        if os.path.exists(path):
            shutil.copy(path, args.docs)
    print(f"copied the CSVs and the plot to {args.docs}")


if __name__ == "__main__":
    main()
