#!/usr/bin/env python3
"""The EXR's codecs side by side: file size and the time the render spends after its last pixel
(writing the EXR and the preview), for each `--compression`, on the conference room.

    python3 bench/compression.py             # about 3 minutes on 2 idle cores
    python3 bench/compression.py --quick     # a check that it runs (not a result)

Each codec renders the same frame twice: with every default layer in full floats, and as light
alone at half precision (`--aovs none --half`, the one use of dwaa, which is lossy on every
channel named like colour and so refused beside data layers); runs alternate codec by codec, so
a machine that slows down slows them all alike. "After the render"
is the process's wall time, measured here, less the render's own `wall_s` from --stats (which
ends when the last pixel is done). Sizes are the EXR's bytes. Writes docs/COMPRESSION.md and
docs/compression/runs.csv.
"""

import argparse
import datetime
import os
import statistics
import subprocess
import time

import common

CODECS = ["zip", "piz", "dwaa", "none"]
SCENE = os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf")
DOCS = os.path.join(common.ROOT, "docs")


# (name, options): every default layer at full precision; light alone at half precision.
VARIANTS = [("every default layer, float", []), ("light alone, half", ["--aovs", "none", "--half"])]


def codecs(variant):
    return [c for c in CODECS if c != "dwaa" or variant == VARIANTS[1][0]]


def run(codec, variant, size, work):
    out = os.path.join(work, f"{codec}.exr")
    options = ["-x", str(size[0]), "-y", str(size[1]), "-ab", "1", "-aa", "0.3", "--compression", codec]
    options += dict(VARIANTS)[variant]
    start = time.perf_counter()
    stats, _ = common.render(SCENE, out, options)
    wall = time.perf_counter() - start
    return {"codec": codec, "layers": variant, "width": size[0], "height": size[1], "process_s": round(wall, 3),
            "render_s": round(stats["wall_s"], 3), "after_s": round(wall - stats["wall_s"], 3),
            "exr_bytes": os.path.getsize(out)}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--quick", action="store_true", help="one small repeat: a check, not a result")
    args = parser.parse_args()
    common.build()
    work = common.scratch()
    size = (320, 180) if args.quick else (1920, 1080)
    repeats = 1 if args.quick else args.repeats
    started = time.time()
    rows = []
    for _ in range(repeats):
        for variant, _ in VARIANTS:
            for codec in codecs(variant):
                row = run(codec, variant, size, work)
                rows.append(row)
                print(f"[compression] {codec:>4}, {variant}: after the render "
                      f"{row['after_s']:.2f} s of {row['process_s']:.2f} s, {row['exr_bytes'] / 1e6:.1f} MB")
    folder = os.path.join(DOCS, "compression")
    os.makedirs(folder, exist_ok=True)
    common.write_csv(os.path.join(folder, "runs.csv"), rows)
    table = ["| codec | layers | EXR MB | after the render s (median) | of the process s | lossless |",
             "|---|---|---|---|---|---|"]
    for variant, _ in VARIANTS:
        for codec in codecs(variant):
            mine = [r for r in rows if r["codec"] == codec and r["layers"] == variant]
            lossless = "no" if codec == "dwaa" else "yes"
            table.append(f"| `{codec}` | {variant} | {statistics.median(r['exr_bytes'] for r in mine) / 1e6:.1f} "
                         f"| {statistics.median(r['after_s'] for r in mine):.2f} | "
                         f"{statistics.median(r['process_s'] for r in mine):.2f} | {lossless} |")
    cpu = os.cpu_count()
    lines = ["# The EXR's codecs", "",
             f"Written by `python3 bench/compression.py` on {datetime.date.today()} "
             f"({(time.time() - started) / 60:.1f} min, {cpu} cores){' with --quick: not a result' if args.quick else ''}; "
             "every run in [compression/runs.csv](compression/runs.csv).", "",
             f"The conference room at {size[0]}x{size[1]}, -ab 1 -aa 0.3: every default layer (light, albedo, "
             f"normal, depth, Cryptomatte) in full floats, and the light alone in half floats (`--aovs none "
             f"--half`); the median of {repeats} run(s) of each. \"After the render\" is the "
             "process's wall time less the render's own (`wall_s`): writing the EXR and the PNG preview.", ""]
    lines += table
    lines += ["", "`zip` is the default: lossless, and what Blender and Nuke write float layers with. See "
                  "[layers.md](layers.md) for what each codec keeps.", ""]
    with open(os.path.join(DOCS, "COMPRESSION.md"), "w") as f:
        f.write("\n".join(lines))
    print(f"wrote {os.path.join(DOCS, 'COMPRESSION.md')}")


if __name__ == "__main__":
    main()
