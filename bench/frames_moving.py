#!/usr/bin/env python3
"""Animated scenes: a crate pushed across the conference room, and a lamp carried through it,
rendered as one `--frames` sequence (the temporal irradiance cache: records kept where the move
cannot have changed them) and frame by frame alone. Writes docs/FRAMES.md and its CSV under
docs/frames/.

The scenes are authored at run time into bench/out/frames_moving/: a copy of the shared
conference room's JSON with a still camera, and either a 60-unit crate (a new mesh, white)
sliding and turning along the floor, or a point light carried down the room at head height. The
room's own buffer is referenced where it lies (--allow-outside-refs; nothing is copied); the
crate's vertices and the animations' keys are in a small .bin of their own.

Per frame it measures:
- ghost: the 4x4 relMSE of the sequence's frame against the same frame rendered alone at
  --spp 4 (the issue's measure; a frame alone at the default --spp is given beside it: the
  noise any frame has against that reference);
- flicker: the relMSE between consecutive frames over the pixels whose surface is more than
  FAR units from the crate's path (sequence, and frames alone for comparison);
- cost: each frame's render seconds (prepass and pixels) and pose seconds (meshes placed again,
  BVH built again), and the records kept, dropped and made.

    python3 bench/frames_moving.py            # about 8 minutes on 2 cores
    python3 bench/frames_moving.py --quick    # 3 frames, about 4 minutes
"""

import argparse
import datetime
import json
import math
import os
import struct
import time

import common
import frames as walk

import numpy as np  # noqa: E402

SCENE = os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf")
OUT = os.path.join(common.ROOT, "bench", "out", "frames_moving")
DOCS = os.path.join(common.ROOT, "docs")
FPS = walk.FPS
# The still camera: at the room's east end, head height, looking west down its length.
CAMERA = (1550.0, 320.0, -190.0)
HEADING = 90.0
# The crate: its side, and its path over one second (x, y, z of its centre on the floor; it
# turns a quarter turn on the way).
CRATE = 60.0
CRATE_PATH = [(1150.0, 0.0, -150.0), (750.0, 0.0, -250.0)]
# The lamp: a point light carried at head height down the room (intensity in the file's units).
LAMP_PATH = [(1300.0, 250.0, -200.0), (500.0, 250.0, -100.0)]
LAMP_INTENSITY = 2.0e5
# Flicker is measured on surfaces farther than this from the crate's path (the room's units).
FAR = 400.0


def quaternion_y(degrees):
    half = math.radians(degrees) / 2
    return [0.0, math.sin(half), 0.0, math.cos(half)]


def cube():
    """A closed cube of side CRATE standing on y = 0, faces outwards: positions, indices."""
    h = CRATE / 2
    corners = [(x, y, z) for z in (-h, h) for y in (0.0, CRATE) for x in (-h, h)]
    # Corner index: x bit 0, y bit 1, z bit 2. Counter-clockwise seen from outside.
    faces = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 4, 6, 2), (1, 3, 7, 5), (2, 6, 7, 3), (0, 1, 5, 4)]
    indices = [i for a, b, c, d in faces for i in (a, b, c, a, c, d)]
    return [c for p in corners for c in p], indices


class Blob:
    """The scene's own small buffer: accessors appended to the room's glTF document."""

    def __init__(self, doc, uri):
        self.doc, self.uri, self.data = doc, uri, b""
        self.buffer = len(doc["buffers"])
        doc["buffers"].append({"uri": uri, "byteLength": 0})

    def accessor(self, values, kind, component=5126, target=None, bounds=False):
        fmt = "f" if component == 5126 else "I"
        data = struct.pack(f"<{len(values)}{fmt}", *values)
        view = {"buffer": self.buffer, "byteOffset": len(self.data), "byteLength": len(data)}
        if target:
            view["target"] = target
        self.data += data
        self.doc["bufferViews"].append(view)
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4}[kind]
        acc = {"bufferView": len(self.doc["bufferViews"]) - 1, "componentType": component,
               "count": len(values) // width, "type": kind}
        if bounds:
            acc["min"] = [min(values[i::width]) for i in range(width)]
            acc["max"] = [max(values[i::width]) for i in range(width)]
        self.doc["accessors"].append(acc)
        return len(self.doc["accessors"]) - 1

    def write(self, here):
        with open(os.path.join(here, self.uri), "wb") as f:
            f.write(self.data)
        self.doc["buffers"][self.buffer]["byteLength"] = len(self.data)


def author(path, what):
    """The room with the still camera and `what` ("crate" or "lamp") animated over one second."""
    with open(SCENE) as f:
        doc = json.load(f)
    here = os.path.dirname(path)
    shared_bin = os.path.join(os.path.dirname(SCENE), doc["buffers"][0]["uri"])
    doc["buffers"][0]["uri"] = os.path.relpath(shared_bin, here)
    blob = Blob(doc, os.path.splitext(os.path.basename(path))[0] + ".bin")
    roots = doc["scenes"][doc.get("scene", 0)]["nodes"]
    doc["cameras"] = [{"type": "perspective", "perspective": {"yfov": math.radians(60), "znear": 1.0}}]
    doc["nodes"].append({"name": "camera", "camera": 0, "translation": list(CAMERA),
                         "rotation": quaternion_y(HEADING)})
    roots.append(len(doc["nodes"]) - 1)
    times = blob.accessor([0.0, 1.0], "SCALAR", bounds=True)
    if what == "crate":
        positions, indices = cube()
        pos = blob.accessor(positions, "VEC3", target=34962, bounds=True)
        idx = blob.accessor(indices, "SCALAR", component=5125, target=34963)
        doc["materials"].append({"name": "crate", "pbrMetallicRoughness": {
            "baseColorFactor": [0.8, 0.8, 0.8, 1.0], "metallicFactor": 0.0, "roughnessFactor": 1.0}})
        doc["meshes"].append({"name": "crate", "primitives": [
            {"attributes": {"POSITION": pos}, "indices": idx, "material": len(doc["materials"]) - 1}]})
        doc["nodes"].append({"name": "crate", "mesh": len(doc["meshes"]) - 1,
                             "translation": list(CRATE_PATH[0])})
        channels = [("translation", blob.accessor([c for p in CRATE_PATH for c in p], "VEC3")),
                    ("rotation", blob.accessor(quaternion_y(0) + quaternion_y(90), "VEC4"))]
    else:
        doc.setdefault("extensionsUsed", []).append("KHR_lights_punctual")
        doc.setdefault("extensions", {})["KHR_lights_punctual"] = {
            "lights": [{"type": "point", "color": [1.0, 0.9, 0.8], "intensity": LAMP_INTENSITY}]}
        doc["nodes"].append({"name": "lamp", "translation": list(LAMP_PATH[0]),
                             "extensions": {"KHR_lights_punctual": {"light": 0}}})
        channels = [("translation", blob.accessor([c for p in LAMP_PATH for c in p], "VEC3"))]
    node = len(doc["nodes"]) - 1
    roots.append(node)
    doc["animations"] = [{
        "name": f"move {what}",
        "samplers": [{"input": times, "output": out, "interpolation": "LINEAR"} for _, out in channels],
        "channels": [{"sampler": i, "target": {"node": node, "path": p}} for i, (p, _) in enumerate(channels)],
    }]
    blob.write(here)
    with open(path, "w") as f:
        json.dump(doc, f)


def render(scene, frames, out, stats, options):
    """One icrender process (as bench/frames.py runs it, with the position layer); returns its wall
    time."""
    return walk.render(scene, frames, out, stats, options + ["--aovs", "position"])


def read(path):
    """The composite (h, w, 3) and the surface positions (h, w, 3) of an EXR."""
    exr = common.ensure_module("OpenEXR")
    channels = exr.File(path).channels()
    rgb = channels["RGBA"].pixels[..., :3].astype(np.float64)
    position = np.stack([channels[f"position.{a}"].pixels for a in "XYZ"], axis=-1).astype(np.float64)
    return rgb, position


def relmse(a, b, mask=None):
    """relMSE (eps 0.01, as `icrender compare`), over the pixels `mask` keeps."""
    e = (a - b) ** 2 / (b * b + 0.01)
    return float(np.mean(e[mask] if mask is not None else e))


def blocks(a):
    h, w = a.shape[0] // 4 * 4, a.shape[1] // 4 * 4
    return a[:h, :w].reshape(h // 4, 4, w // 4, 4, 3).mean(axis=(1, 3))


def far_from_path(position, path, origin_free=True):
    """Pixels whose surface lies farther than FAR from the segment `path` (the background's
    zero positions count as near: they are not surfaces)."""
    a, b = np.array(path[0]), np.array(path[1])
    ab = b - a
    t = np.clip(((position - a) @ ab) / (ab @ ab), 0.0, 1.0)
    nearest = a + t[..., None] * ab
    distance = np.linalg.norm(position - nearest, axis=-1)
    return (distance > FAR) & np.any(position != 0.0, axis=-1)


# The cases: (label, scene, options added to the command line's).
CASES = [("crate", "crate", []), ("crate -ab 2", "crate", ["-ab", "2"]), ("lamp", "lamp", [])]


def run_case(label, what, numbers, options):
    scene = os.path.join(OUT, f"{what}.gltf")
    author(scene, what)
    first, last = numbers[0], numbers[-1]
    tag = label.replace(" ", "")
    seq_wall = render(scene, ["--frames", f"{first}-{last}"], os.path.join(OUT, f"{tag}.seq.####.exr"),
                      os.path.join(OUT, f"{tag}.seq.####.json"), options)
    rows = []
    path = CRATE_PATH if what == "crate" else LAMP_PATH
    previous = None
    for n in numbers:
        alone_exr = os.path.join(OUT, f"{tag}.alone.{n:04d}.exr")
        ref_exr = os.path.join(OUT, f"{tag}.ref.{n:04d}.exr")
        alone_wall = render(scene, ["--frame", str(n)], alone_exr, alone_exr.replace(".exr", ".json"), options)
        render(scene, ["--frame", str(n), "--spp", "4"], ref_exr, ref_exr.replace(".exr", ".json"), options)
        seq = walk.load(os.path.join(OUT, f"{tag}.seq.{n:04d}.json"))
        alone = walk.load(alone_exr.replace(".exr", ".json"))
        (s_rgb, position), (a_rgb, _), (r_rgb, _) = (
            read(os.path.join(OUT, f"{tag}.seq.{n:04d}.exr")), read(alone_exr), read(ref_exr))
        row = {
            "case": label, "frame": n,
            "seq_render_s": seq["render_s"], "seq_pose_s": seq.get("pose_s", 0.0),
            "remade": seq.get("records_remade", 0),
            "kept": seq["records_before"], "dropped": seq.get("records_invalidated", 0),
            "made": seq["records_computed"] - seq.get("records_remade", 0),
            "grid_sites_kept": seq.get("last_bounce_sites_kept", 0),
            "grid_sites_sampled": seq.get("last_bounce_sites_sampled", 0),
            "alone_render_s": alone["render_s"], "alone_wall_s": alone_wall, "alone_made": alone["records_computed"],
            "seq_vs_ref_4x4": relmse(blocks(s_rgb), blocks(r_rgb)),
            "alone_vs_ref_4x4": relmse(blocks(a_rgb), blocks(r_rgb)),
        }
        if previous is not None:
            far = far_from_path(position, path)
            row["far_pixels"] = int(far.sum())
            row["seq_flicker"] = relmse(s_rgb, previous[0], far)
            row["alone_flicker"] = relmse(a_rgb, previous[1], far)
        previous = (s_rgb, a_rgb)
        rows.append(row)
        print(f"{label} frame {n}: seq {row['seq_render_s']:.2f}+{row['seq_pose_s']:.2f} s "
              f"(kept {row['kept']}, dropped {row['dropped']}, remade {row['remade']}, made {row['made']}), "
              f"alone {row['alone_render_s']:.2f} s; "
              f"4x4 relMSE vs spp 4: seq {row['seq_vs_ref_4x4']:.2e}, alone {row['alone_vs_ref_4x4']:.2e}; "
              f"flicker seq {row.get('seq_flicker', float('nan')):.2e} alone {row.get('alone_flicker', float('nan')):.2e}",
              flush=True)
    return rows, seq_wall


def summary(rows):
    first, later = rows[0], rows[1:]
    later_cost = sum(r["seq_render_s"] + r["seq_pose_s"] for r in later) / max(len(later), 1)
    return {
        "first_s": first["seq_render_s"],
        "later_s": later_cost,
        "later_share": later_cost / max(first["seq_render_s"], 1e-9),
        "worst_ghost": max(r["seq_vs_ref_4x4"] for r in rows),
        "worst_alone": max(r["alone_vs_ref_4x4"] for r in rows),
        "worst_flicker": max((r["seq_flicker"] for r in later), default=float("nan")),
        "worst_alone_flicker": max((r["alone_flicker"] for r in later), default=float("nan")),
    }


def write_page(args, cases, seconds):
    os.makedirs(os.path.join(DOCS, "frames"), exist_ok=True)
    rows = [r for case_rows, _ in cases.values() for r in case_rows]
    common.write_csv(os.path.join(DOCS, "frames", "moving.csv"), rows)
    today = datetime.date.today().isoformat()
    lines = [
        "# Animated scenes: the temporal irradiance cache",
        "",
        f"Written by `python3 bench/frames_moving.py{' --quick' if args.quick else ''}` on {today} "
        f"({seconds / 60:.1f} min, 2 cores); every frame in [frames/moving.csv](frames/moving.csv). "
        "How the cache decides what to keep: [rendering.md](rendering.md#frames-animations).",
        "",
        f"The conference room, {args.size}, {' '.join(args.options.split()) or 'default settings'} "
        "(and -ab 2 where the case says), "
        f"frames {args.first}-{args.first + args.count - 1} at {FPS} fps, seen by a still camera: "
        f"`crate`, a {CRATE:.0f}-unit crate pushed {math.dist(*CRATE_PATH):.0f} units a second along the floor "
        f"(turning a quarter turn); `lamp`, a point light carried {math.dist(*LAMP_PATH):.0f} units a second "
        "down the room. Each frame of the sequence against the same frame rendered alone at `--spp 4` "
        "(ghost, 4x4 relMSE; target 2e-3); consecutive frames over the surfaces more than "
        f"{FAR:.0f} units from the path (flicker, relMSE; target 1e-4); the frames after the first "
        "against the first (cost; target half).",
        "",
        "| case | first frame s | later frames s (mean, pose included) | later / first | "
        "worst ghost 4x4 | "
        "alone at default spp, worst 4x4 | worst flicker | alone, worst flicker |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for what, (case_rows, _) in cases.items():
        s = summary(case_rows)
        lines.append(f"| {what} | {s['first_s']:.2f} | {s['later_s']:.2f} | {s['later_share']:.2f} | "
                     f"{s['worst_ghost']:.2e} | {s['worst_alone']:.2e} | {s['worst_flicker']:.2e} | "
                     f"{s['worst_alone_flicker']:.2e} |")
    lines += ["", "Per frame (kept, dropped, remade, made: records kept from the last frame, dropped by the "
              "moves, made again at their own points, made by the prepass; grid sites: the last-bounce grid's "
              "sites taken from the last frame and sampled afresh):", "",
              "| case | frame | render s | pose s | kept | dropped | remade | made | grid sites kept / sampled | "
              "alone s | ghost 4x4 | alone 4x4 | flicker | alone flicker |",
              "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        flick = f"{r['seq_flicker']:.2e}" if "seq_flicker" in r else "-"
        aflick = f"{r['alone_flicker']:.2e}" if "alone_flicker" in r else "-"
        lines.append(f"| {r['case']} | {r['frame']} | {r['seq_render_s']:.2f} | {r['seq_pose_s']:.2f} | "
                     f"{r['kept']} | {r['dropped']} | {r['remade']} | {r['made']} | "
                     f"{r['grid_sites_kept']} / {r['grid_sites_sampled']} | "
                     f"{r['alone_render_s']:.2f} | {r['seq_vs_ref_4x4']:.2e} | "
                     f"{r['alone_vs_ref_4x4']:.2e} | {flick} | {aflick} |")
    with open(os.path.join(DOCS, "FRAMES.md"), "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {os.path.join(DOCS, 'FRAMES.md')}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--first", type=int, default=6, help="first frame (default 6)")
    parser.add_argument("--count", type=int, default=6, help="frames (default 6)")
    parser.add_argument("--size", default="320x180", help="image size WxH (default 320x180)")
    parser.add_argument("--options", default="", help="more render options, e.g. \"-ab 2\"")
    parser.add_argument("--quick", action="store_true", help="3 frames")
    parser.add_argument("--cases", default=",".join(c[0] for c in CASES),
                        help="which cases, comma-separated (default all: " + ", ".join(c[0] for c in CASES) + ")")
    args = parser.parse_args()
    if args.quick:
        args.count = 3
    common.require("bench/frames_moving.py", modules=("numpy", "OpenEXR"))
    common.build()
    os.makedirs(OUT, exist_ok=True)
    start = time.monotonic()
    width, height = args.size.split("x")
    options = ["-x", width, "-y", height] + args.options.split()
    numbers = list(range(args.first, args.first + args.count))
    wanted = args.cases.split(",")
    cases = {label: run_case(label, what, numbers, options + extra) for label, what, extra in CASES if label in wanted}
    write_page(args, cases, time.monotonic() - start)


if __name__ == "__main__":
    main()
