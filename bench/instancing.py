#!/usr/bin/env python3
"""What instancing saves on conference_x32.gltf (one room placed 32 times by node transforms):
load and BVH build time, peak memory, and ray rates, instanced and with --flatten (every
placement copied), beside the single room.

    python3 bench/instancing.py                  # x32 both ways and the single room, 3 repeats
    python3 bench/instancing.py --render         # also a 160x120 render of x32 both ways
    python3 bench/instancing.py --repeats 5 --seconds 2

Each configuration runs `icrender bench rays SCENE --threads 1` --repeats times, alternating
with the others, and keeps each figure's best (interference from other work only ever slows a
run down): load and BVH build seconds, the process's peak resident memory (the kernel's
figure for the whole process, from wait4), and one-thread rates of primary rays, shadow rays
and incoherent rays, per second of the tracing thread's CPU time (on a shared machine the wall
clock also counts the time other work held the core). Every run looks from the single room's automatic view, inside room (0, 0),
which x32 places where the single room is, so the primary rays are the same rays in all three;
the shadow rays are the single room's (from the surfaces the view sees to a point on the
emitter its light tree picks there, saved once with --save-shadow-rays and traced everywhere
with --shadow-rays), so they are the same rays too. The incoherent rays have random origins in
each scene's bounds (in x32 they cross 32 rooms: not the single room's rays). Prints figures
only; asserts nothing.
"""

import argparse
import json
import os
import re
import subprocess
import sys
import threading
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import common  # noqa: E402

ROOM = os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf")
X32 = os.path.join(common.SHARED_SCENES, "conference_room", "conference_x32.gltf")
# The single room's automatic view (`icrender/view` of a render of it), square.
VIEW = "-vp 1631.6924 323.75006 -193.58344 -vd -1 0 0 -vu 0 1 0 -vh 60 -vv 60".split()
CONFIGS = [
    ("single room", ROOM, []),
    ("x32 instanced", X32, []),
    ("x32 --flatten", X32, ["--flatten"]),
]


def measured(cmd):
    """Runs cmd to completion; returns (stdout, wall seconds, peak RSS bytes) or raises."""
    start = time.monotonic()
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    # wait4 reports the child's own resource usage (ru_maxrss in KiB on Linux); the pipes are
    # drained by threads so a large output cannot block the child.
    chunks = {"out": b"", "err": b""}

    def drain(name, stream):
        chunks[name] = stream.read()

    readers = [threading.Thread(target=drain, args=(n, s)) for n, s in (("out", proc.stdout), ("err", proc.stderr))]
    for r in readers:
        r.start()
    _, status, usage = os.wait4(proc.pid, 0)
    for r in readers:
        r.join()
    wall = time.monotonic() - start
    code = os.waitstatus_to_exitcode(status)
    proc.returncode = code
    if code != 0:
        raise RuntimeError(f"{' '.join(cmd)} failed ({code}):\n{chunks['err'].decode(errors='replace')}")
    return chunks["out"].decode(), wall, usage.ru_maxrss * 1024


def parse_bench(out):
    figures = {}
    for key, pattern in [
        ("load_s", r"^load\s+([0-9.]+) s"),
        ("build_s", r"^bvh build\s+([0-9.]+) s"),
        ("peak_after_build_mb", r"^peak memory\s+([0-9.]+) MB"),
        ("primary", r"1 thread\(s\)  per CPU second: primary ([0-9.]+) Mrays"),
        ("incoherent", r"1 thread\(s\)  per CPU second:.*incoherent ([0-9.]+) Mrays"),
        ("shadow", r"1 thread\(s\)  per CPU second:.*shadow ([0-9.]+) Mrays"),
        ("blocked", r"1 thread\(s\).*shadow [0-9.]+ Mrays/s \(([0-9]+)% blocked\)"),
    ]:
        match = re.search(pattern, out, re.MULTILINE)
        figures[key] = float(match.group(1)) if match else None
    match = re.search(r"^scene .*\((\d+) triangles, (\d+) stored", out, re.MULTILINE)
    if match:
        figures["triangles"], figures["stored"] = int(match.group(1)), int(match.group(2))
    return figures


def best(runs):
    """Best of each figure: least time and memory, highest rate."""
    out = {}
    for key in runs[0]:
        values = [r[key] for r in runs if r.get(key) is not None]
        if not values:
            out[key] = None
        elif key in ("primary", "incoherent", "shadow", "triangles", "stored", "blocked"):
            out[key] = max(values)
        else:
            out[key] = min(values)
    return out


def render(scene, out, extra):
    cmd = [common.BINARY, "render", scene, "-x", "160", "-y", "120", "-o", out, "-q", "--no-preview",
           "--overwrite"] + extra
    _, wall, peak = measured(cmd)
    return wall, peak


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=1.0, help="seconds per kind of ray and run")
    parser.add_argument("--render", action="store_true", help="also render x32 at 160x120 both ways and compare")
    parser.add_argument("--no-build", action="store_true", help="use the binary as it is")
    args = parser.parse_args()
    common.require("instancing.py")
    for scene in (ROOM, X32):
        if not os.path.exists(scene):
            sys.exit(f"instancing.py: {scene} not found (the shared scenes are expected beside the project)")
    if not args.no_build:
        common.build()

    work = common.scratch()
    shadow_rays = os.path.join(work, "shadow-rays.bin")
    measured([common.BINARY, "bench", "rays", ROOM, "--threads", "1", "--seconds", "0.01", "--save-shadow-rays",
              shadow_rays] + VIEW)
    runs = {name: [] for name, _, _ in CONFIGS}
    for repeat in range(args.repeats):
        for name, scene, extra in CONFIGS:
            cmd = [common.BINARY, "bench", "rays", scene, "--threads", "1", "--seconds", str(args.seconds),
                   "--shadow-rays", shadow_rays]
            out, wall, peak = measured(cmd + VIEW + extra)
            figures = parse_bench(out)
            figures["peak_mb"] = peak / 1e6
            figures["wall_s"] = wall
            runs[name].append(figures)
            print(f"  run {repeat + 1}/{args.repeats} {name}: load {figures['load_s']:.3f} s, "
                  f"build {figures['build_s']:.3f} s, peak {figures['peak_mb']:.0f} MB", file=sys.stderr)

    print(f"best of {args.repeats} runs, one thread, {args.seconds:g} s per kind of ray, rays per CPU second; machine: "
          f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.2f} at the end")
    header = ("", "triangles", "stored", "load s", "build s", "load+build s", "peak MB",
              "primary Mrays", "shadow Mrays", "blocked %", "incoherent Mrays")
    rows = []
    for name, _, _ in CONFIGS:
        b = best(runs[name])
        rows.append((name, b.get("triangles"), b.get("stored"), f"{b['load_s']:.3f}", f"{b['build_s']:.3f}",
                     f"{b['load_s'] + b['build_s']:.3f}", f"{b['peak_mb']:.0f}", f"{b['primary']:.2f}",
                     f"{b['shadow']:.2f}" if b["shadow"] else "-", f"{b['blocked']:.0f}" if b["blocked"] is not None else "-",
                     f"{b['incoherent']:.2f}"))
    widths = [max(len(str(r[i])) for r in rows + [header]) for i in range(len(header))]
    for r in [header] + rows:
        print("  ".join(str(v).rjust(w) if i else str(v).ljust(w) for i, (v, w) in enumerate(zip(r, widths))))
    room, inst, flat = (best(runs[n]) for n, _, _ in CONFIGS)
    print(f"x32 instanced against --flatten: load+build {flat['load_s'] + flat['build_s']:.2f} s -> "
          f"{inst['load_s'] + inst['build_s']:.2f} s, peak {flat['peak_mb']:.0f} MB -> {inst['peak_mb']:.0f} MB, "
          f"shadow rays {inst['shadow'] / flat['shadow']:.2f}x, primary {inst['primary'] / flat['primary']:.2f}x")
    print(f"x32 instanced against the single room (the same rays): primary {inst['primary'] / room['primary']:.2f}x, "
          f"shadow {inst['shadow'] / room['shadow']:.2f}x")

    if args.render:
        outputs = {}
        for name, extra in (("instanced", []), ("flattened", ["--flatten"])):
            out = os.path.join(work, f"x32-{name}.exr")
            wall, peak = render(X32, out, extra)
            outputs[name] = out
            print(f"x32 160x120 render {name}: {wall:.1f} s, peak {peak / 1e6:.0f} MB")
        result = subprocess.run([common.BINARY, "compare", outputs["instanced"], outputs["flattened"], "--json"],
                                capture_output=True, text=True, check=True)
        for e in json.loads(result.stdout):
            print(f"  {e['layer']:10} rmse {e['rmse']:.3e}  relMSE {e['rel_mse']:.3e}  (instanced against flattened)")


if __name__ == "__main__":
    main()
