#!/usr/bin/env python3
"""A frame sequence's cost per frame: a camera walking through the conference room, rendered as
one `--frames` sequence (the irradiance cache carried from frame to frame) and frame by frame
in separate processes (each frame builds its own cache, as a farm task of one frame would).

The scene is authored at run time into bench/out/frames/: a copy of the shared conference
room's JSON with a camera node and an animation of it (five keys over four seconds, walking
down the room's long axis and turning a little), whose buffer is the shared conference.bin,
referenced where it lies (read with --allow-outside-refs; the scene is not copied), and the
animation's keys in a small .bin of its own.

    python3 bench/frames.py              # about 2 minutes on 2 cores

Prints, per frame, the render time (prepass and tiles) and the records made, carried and
alone, and writes bench/out/frames/frames.csv. Asserts nothing. Scenes where meshes and lights
move (the temporal cache): bench/frames_moving.py.
"""

import argparse
import json
import math
import os
import struct
import subprocess
import time

import common

SCENE = os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf")
OUT = os.path.join(common.ROOT, "bench", "out", "frames")
FPS = 24
# The walk: key time (s), camera position (x, y, z) in the room's units, and its heading: the
# turn about +Y from glTF's default view direction (-Z); 90 degrees looks down -X, along the room.
KEYS = [
    (0.0, (1550.0, 320.0, -190.0), 90.0),
    (1.0, (1350.0, 330.0, -260.0), 100.0),
    (2.0, (1150.0, 320.0, -150.0), 85.0),
    (3.0, (950.0, 310.0, -100.0), 75.0),
    (4.0, (750.0, 320.0, -200.0), 95.0),
]


def author_walk(path):
    """Writes the room with the animated camera to `path` (and its animation's .bin beside it)."""
    with open(SCENE) as f:
        doc = json.load(f)
    here = os.path.dirname(path)
    # The room's own buffer, where it is (relative, as glTF URIs are).
    shared_bin = os.path.join(os.path.dirname(SCENE), doc["buffers"][0]["uri"])
    doc["buffers"][0]["uri"] = os.path.relpath(shared_bin, here)
    times = [k[0] for k in KEYS]
    moves = [c for k in KEYS for c in k[1]]
    turns = []
    for _, _, heading in KEYS:
        half = math.radians(heading) / 2
        turns += [0.0, math.sin(half), 0.0, math.cos(half)]
    blob = b"".join(struct.pack(f"<{len(v)}f", *v) for v in (times, moves, turns))
    anim_bin = os.path.splitext(os.path.basename(path))[0] + "_anim.bin"
    with open(os.path.join(here, anim_bin), "wb") as f:
        f.write(blob)
    buffer = len(doc["buffers"])
    doc["buffers"].append({"uri": anim_bin, "byteLength": len(blob)})
    offset = 0
    accessors = []
    for values, kind, width in ((times, "SCALAR", 1), (moves, "VEC3", 3), (turns, "VEC4", 4)):
        length = 4 * len(values)
        doc["bufferViews"].append({"buffer": buffer, "byteOffset": offset, "byteLength": length})
        accessor = {"bufferView": len(doc["bufferViews"]) - 1, "componentType": 5126,
                    "count": len(values) // width, "type": kind}
        if kind == "SCALAR":
            accessor["min"], accessor["max"] = [min(values)], [max(values)]
        doc["accessors"].append(accessor)
        accessors.append(len(doc["accessors"]) - 1)
        offset += length
    doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": math.radians(60), "znear": 1.0}}]
    doc["nodes"].append({"name": "walker", "camera": 0, "translation": list(KEYS[0][1])})
    node = len(doc["nodes"]) - 1
    doc["scenes"][doc.get("scene", 0)]["nodes"].append(node)
    doc["animations"] = [{
        "name": "walk",
        "samplers": [{"input": accessors[0], "output": accessors[1], "interpolation": "LINEAR"},
                     {"input": accessors[0], "output": accessors[2], "interpolation": "LINEAR"}],
        "channels": [{"sampler": 0, "target": {"node": node, "path": "translation"}},
                     {"sampler": 1, "target": {"node": node, "path": "rotation"}}],
    }]
    with open(path, "w") as f:
        json.dump(doc, f)


def render(scene, frames, out, stats, options):
    """One icrender process; returns its wall time (load and BVH included)."""
    cmd = [common.BINARY, "render", scene, "--allow-outside-refs", "-q", "--no-preview", "--overwrite",
           "--fps", str(FPS), "-o", out, "--stats", stats] + frames + options
    start = time.monotonic()
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"icrender failed: {' '.join(cmd)}\n{result.stderr}")
    return time.monotonic() - start


def load(path):
    with open(path) as f:
        return json.load(f)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--first", type=int, default=24, help="first frame (default 24: one second in)")
    parser.add_argument("--count", type=int, default=5, help="frames (default 5)")
    parser.add_argument("--size", default="160x120", help="image size WxH (default 160x120)")
    parser.add_argument("--options", default="", help="more render options, e.g. \"-ab 2\"")
    args = parser.parse_args()
    common.require("bench/frames.py")
    common.build()
    os.makedirs(OUT, exist_ok=True)
    scene = os.path.join(OUT, "walk.gltf")
    author_walk(scene)
    width, height = args.size.split("x")
    options = ["-x", width, "-y", height] + args.options.split()
    last = args.first + args.count - 1
    numbers = range(args.first, last + 1)

    carried_wall = render(scene, ["--frames", f"{args.first}-{last}"], os.path.join(OUT, "seq.####.exr"),
                          os.path.join(OUT, "seq.json"), options)
    carried = {n: load(os.path.join(OUT, f"seq.{n:04d}.json")) for n in numbers}
    alone, alone_wall = {}, {}
    for n in numbers:
        alone_wall[n] = render(scene, ["--frame", str(n)], os.path.join(OUT, f"alone.{n:04d}.exr"),
                               os.path.join(OUT, f"alone.{n:04d}.json"), options)
        alone[n] = load(os.path.join(OUT, f"alone.{n:04d}.json"))

    first = carried[args.first]
    print(f"conference room walk, {args.size}, frames {args.first}-{last} at {FPS} fps "
          f"(camera {KEYS[1][1][0] - KEYS[0][1][0]:+.0f} units/s along x), options: {' '.join(options)}")
    print(f"scene load {first['load_s']:.2f} s, BVH {first['build_s']:.2f} s "
          f"(once for the sequence, once per frame alone)")
    header = (f"{'frame':>5}  {'carried s':>9} {'prepass s':>9} {'made':>6} {'before':>7}   "
              f"{'alone s':>8} {'prepass s':>9} {'made':>6}   {'carried/alone':>13}")
    print(header)
    rows = []
    for n in numbers:
        c, a = carried[n], alone[n]
        ratio = c["render_s"] / max(a["render_s"], 1e-9)
        print(f"{n:>5}  {c['render_s']:>9.2f} {c['prepass_s']:>9.2f} {c['records_computed']:>6} "
              f"{c['records_before']:>7}   {a['render_s']:>8.2f} {a['prepass_s']:>9.2f} "
              f"{a['records_computed']:>6}   {ratio:>13.2f}")
        rows.append({"frame": n, "carried_render_s": c["render_s"], "carried_prepass_s": c["prepass_s"],
                     "carried_records": c["records_computed"], "carried_records_before": c["records_before"],
                     "alone_render_s": a["render_s"], "alone_prepass_s": a["prepass_s"],
                     "alone_records": a["records_computed"], "alone_wall_s": alone_wall[n]})
    total_c = sum(carried[n]["render_s"] for n in numbers)
    total_a = sum(alone[n]["render_s"] for n in numbers)
    later_c = sum(carried[n]["render_s"] for n in numbers if n != args.first) / max(args.count - 1, 1)
    print(f"render time over all frames: carried {total_c:.2f} s, alone {total_a:.2f} s; "
          f"after the first frame a carried frame takes {later_c:.2f} s, "
          f"{later_c / max(first['render_s'], 1e-9):.2f} of the first")
    print(f"process wall time: the sequence {carried_wall:.2f} s, the frames alone {sum(alone_wall.values()):.2f} s")
    common.write_csv(os.path.join(OUT, "frames.csv"), rows)
    print(f"wrote {os.path.join(OUT, 'frames.csv')}")


if __name__ == "__main__":
    main()
