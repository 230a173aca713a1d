#!/usr/bin/env python3
"""The renderer's ray rate against Embree's own on the same scene (issue 18's target: at -ab 2
at least 60 % of `icrender bench rays`).

    python3 bench/ray_rate.py                      # conference room and Sibenik, -ab 2
    python3 bench/ray_rate.py --scenes conference --repeats 5

For each scene, one thread throughout, alternating the two measurements --repeats times and
keeping each one's best (interference from other work only ever slows a run down):
  - Embree alone: `icrender bench rays --threads 1`, its incoherent rays (random origins in the
    scene's bounds, random directions: rays that cross the scene, as hemisphere rays do), and
    its hemisphere rays (cosine-distributed from the surfaces the view sees, as a record casts
    them: costlier for Embree than the incoherent ones, printed beside them);
  - the renderer: a render at the bench's quality (peers.py's highest conference setting) with
    --stats, its rays of every kind (primary, shadow, hemisphere) over the rendering thread's
    busy time (wall clock, as the Embree bench measures) and over its CPU time, and over the
    render's whole time (`render_s`), which also holds the prepass's serial steps between its
    rounds on the main thread (the records' shrink and fit, each round's merge): the busy time
    leaves those out.
The ratio is what the renderer keeps of Embree's rate; the rest is shading, light sampling,
the cache and hit reconstruction. Beside it, the ceiling: Embree alone on the renderer's own mix
of rays (its counts of each kind, each at Embree's rate for that kind), the rate the renderer
would have if it did nothing but trace, and the share of the render's time outside Embree that
60 % of the incoherent rate allows. Prints figures only; asserts nothing.
"""

import argparse
import json
import os
import re
import statistics
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

SCENES = {
    "conference": os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"),
    "sibenik": os.path.join(common.SHARED_SCENES, "sibenik_cathedral", "sibenik.gltf"),
    "cornell": os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"),
}
# -ar 64 alone (no view floor): the settings of the rates measured before --ic-min-pixels.
RENDER = "-x 320 -y 240 -ab 2 --lambertian -aa 0.1 -ad 512 -as 128 -ar 64 --ic-min-pixels 0 --spp 16 --threads 1".split()


def embree_rate(scene, seconds):
    """Embree's one-thread rates (Mrays/s) by kind: incoherent, hemisphere, primary, shadow."""
    out = subprocess.run([common.BINARY, "bench", "rays", scene, "--threads", "1", "--seconds", str(seconds)],
                         capture_output=True, text=True, check=True).stdout
    rates = {}
    for kind in ("incoherent", "hemisphere", "primary", "shadow"):
        match = re.search(rf"1 thread\(s\)\s.*?{kind} ([0-9.]+) Mrays/s", out)
        if not match:
            raise RuntimeError(f"bench rays printed no one-thread {kind} rate:\n{out}")
        rates[kind] = float(match.group(1))
    return rates


def mix_bound(rays, rates):
    """The rate (Mrays/s) at which Embree alone traces the renderer's rays, each kind at its own
    rate from `bench rays`: primary rays as primary, shadow as shadow, hemisphere (ambient) as
    hemisphere, specular as incoherent. What the renderer's rate would be with no shading, light
    sampling or cache work at all: the ceiling on its ratio to the incoherent rate."""
    # `continued`: a ray's further queries past a surface it passes through (alpha-masked or
    # see-through), as incoherent rays.
    kind_rate = {"primary": "primary", "shadow": "shadow", "ambient": "hemisphere", "specular": "incoherent",
                 "continued": "incoherent"}
    seconds = sum(rays.get(k, 0) / rates[r] for k, r in kind_rate.items())
    return sum(rays.get(k, 0) for k in kind_rate) / seconds if seconds > 0 else 0.0


def renderer_rate(scene, work):
    out = os.path.join(work, "ray-rate.exr")
    stats, _ = common.render(scene, out, RENDER)
    [thread] = stats["per_thread"]
    rays = stats["rays"]["total"]
    rates = (rays / thread["busy_s"] / 1e6, rays / thread["cpu_s"] / 1e6, rays / stats["render_s"] / 1e6)
    return rates, stats["rays"], thread["busy_s"]


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="conference,sibenik")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=3.0, help="Embree bench seconds per measurement")
    args = parser.parse_args()
    common.build()
    work = os.path.join(common.ROOT, "bench", "out", "ray_rate")
    os.makedirs(work, exist_ok=True)
    load = os.getloadavg()
    print(f"ray_rate: load average at start {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    for name in args.scenes.split(","):
        scene = SCENES[name]
        embree, wall, cpu, whole, busy, kinds = [], [], [], [], [], None
        for _ in range(args.repeats):
            embree.append(embree_rate(scene, args.seconds))
            (w, c, r), kinds, b = renderer_rate(scene, work)
            wall.append(w)
            cpu.append(c)
            whole.append(r)
            busy.append(b)
        # Each rate's best over the repeats.
        best = {k: max(e[k] for e in embree) for k in embree[0]}
        incoherent, hemisphere = best["incoherent"], best["hemisphere"]
        best_wall, best_cpu, best_whole = max(wall), max(cpu), max(whole)
        bound = mix_bound(kinds, best)
        runs = " ".join(f"{e['incoherent']:.2f}" for e in embree)
        print(f"ray_rate: {name}: Embree alone {incoherent:.2f} Mrays/s incoherent (runs {runs}); "
              f"renderer {best_wall:.2f} Mrays/s by busy time (runs {' '.join(f'{w:.2f}' for w in wall)}), "
              f"{best_cpu:.2f} by CPU time, the render's busy time {min(busy):.2f} s; rays {json.dumps(kinds)}")
        # The machine's speed drifts over minutes (other guests): each repeat's pair of runs,
        # back to back, gives a ratio of its own, and their median is steadier than the ratio
        # of the bests when the drift is slow.
        paired = sorted(w / e["incoherent"] for w, e in zip(wall, embree))
        median = statistics.median(paired)
        print(f"ray_rate: {name}: the renderer's rate is {best_wall / incoherent * 100:.0f} % of Embree's "
              f"({best_cpu / incoherent * 100:.0f} % by CPU time, {best_whole / incoherent * 100:.0f} % by the "
              f"render's whole time; target 60 %); repeat by repeat "
              f"{' '.join(f'{r * 100:.0f}' for r in paired)} %, median {median * 100:.0f} %")
        print(f"ray_rate: {name}: Embree alone on hemisphere rays from the surfaces the view sees "
              f"{hemisphere:.2f} Mrays/s ({hemisphere / incoherent * 100:.0f} % of its incoherent rate); "
              f"the renderer's rate is {best_wall / hemisphere * 100:.0f} % of that")
        print(f"ray_rate: {name}: Embree alone on the renderer's mix of rays (primary {best['primary']:.2f}, "
              f"shadow {best['shadow']:.2f}, hemisphere {hemisphere:.2f}, specular as incoherent) "
              f"{bound:.2f} Mrays/s = {bound / incoherent * 100:.0f} % of the incoherent rate: the renderer's "
              f"ceiling with no work but Embree's; it reaches {best_wall / bound * 100:.0f} % of it, its work "
              f"outside Embree {(1 - best_wall / bound) * 100:.0f} % of its time (at most "
              f"{max(0.0, 1 - 0.6 * incoherent / bound) * 100:.0f} % for 60 %)")


if __name__ == "__main__":
    main()
