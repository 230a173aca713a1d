#!/usr/bin/env python3
"""More samples in the pixels an edge crosses (`--edge-samples`): what they buy on the Cornell
box at the peers bench's cheapest settings and two at one sample a pixel, raw and denoised,
against a converged brute-force reference. Both of the peers bench's views, each setting with --edge-samples 0 (every pixel
--spp), 8 and 16, each render --repeats times (its fastest time kept; the image is the same).

    python3 bench/edges.py          # 45 minutes on 2 cores the first time (references), then 10; writes docs/EDGES.md

Second part: the renderer's defaults on the Cornell box, the conference room and Sibenik, with
--edge-samples 0, 4 and 8 and with more samples in every pixel instead (how `--edge-samples`'
default was chosen).

At a few samples a pixel the error left after the denoiser is mostly the edges' (a box filter
with one or two samples puts a pixel on one side of an edge whatever share the other side
covers), which the denoiser keeps as sharp as its guides show them; so the denoised curve met
icrender's raw curve at equal time only where edges were not most of the error (issue 21).
"At equal time" here: the raw curve's error at a run's time over the run's error (above 1: the
run is ahead), the raw curve being the lower envelope of the view's raw runs (each run that
beats every faster one, joined log-log; no figure outside its times): for a denoised run (its
time the render's plus the denoiser's) against every raw run, for a raw run with edge samples
against the raw runs without. Prints figures; asserts nothing.
"""

import argparse
import json
import math
import os
import subprocess
import sys

import common

SCENE = os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf")
SIZE = (256, 256)
# The peers bench's three cheapest Cornell box settings until 5 Dec (bench/peers.py, where the
# two-sample one is now one sample with 8 shadow rays and 4 edge samples: the fourth setting
# here at --edge-samples 8 is the closest), and two at one sample a pixel with more shadow rays (5 Dec: there the raw error levels off at the edges' without
# edge samples: 8.2e-4, 6.9e-4, 6.6e-4 with 8, 16, 32 shadow rays).
SETTINGS = [
    "-aa 0.3 -ad 64 -as 16 --spp 2 --light-samples 2 --emission-samples 32",
    "-aa 0.3 -ad 64 -as 16 --spp 4 --light-samples 2 --emission-samples 32",
    "-aa 0.2 -ad 128 -as 32 --spp 4 --light-samples 4 --emission-samples 64",
    "-aa 0.3 -ad 64 -as 16 --spp 1 --light-samples 8 --emission-samples 32",
    "-aa 0.3 -ad 64 -as 16 --spp 1 --light-samples 16 --emission-samples 32",
]
EDGE_SAMPLES = [0, 8, 16]
VIEWS = {
    "default": [],
    "corner": "--vp 0.75 1.65 0.9 --vd -0.75 -0.85 -1.4 --vu 0 1 0 --vh 75".split(),
}


# At the renderer's defaults (`--spp 1 --light-samples 16`, the default -aa/-ad), each scene's
# default view with --lambertian: what edge samples cost and buy there, against more samples in
# every pixel (the choice of `--edge-samples`' default).
DEFAULT_SCENES = {
    "cornell": (SCENE, (256, 256), 1),
    "conference": (os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"), (320, 240), 2),
    "sibenik": (os.path.join(common.SHARED_SCENES, "sibenik_cathedral", "sibenik.gltf"), (320, 240), 2),
}
DEFAULT_RUNS = [("--spp 1", 0), ("--spp 1", 4), ("--spp 1", 8), ("--spp 2", 0), ("--spp 2", 8), ("--spp 4", 0)]


def base(view):
    return ["-x", str(SIZE[0]), "-y", str(SIZE[1]), "-ab", "1", "--lambertian"] + VIEWS[view]


def run(out, view, setting, edges, repeats, scene=SCENE, options=None, denoise=True):
    """Fastest render (and denoiser) times over `repeats`: the statistics of the fastest."""
    best = None
    for _ in range(repeats):
        stats_path = out + ".json"
        cmd = [common.BINARY, "render", scene, "-o", out, "-q", "--no-preview", "--overwrite", "--stats",
               stats_path, "--edge-samples", str(edges)] + (["--denoise"] if denoise else []) \
            + (base(view) if options is None else options) + setting.split()
        subprocess.run(cmd, check=True, capture_output=True)
        with open(stats_path) as f:
            stats = json.load(f)
        if best is None or stats["render_s"] < best["render_s"]:
            best = stats
    return best


def envelope(points):
    """The runs (time, error) that beat every faster one, by time: the best curve they make."""
    best = []
    for t, e in sorted(points):
        if not best or e < best[-1][1]:
            best.append((t, e))
    return best


def at_time(curve, t):
    """The error along `curve` (an envelope) at time t, log-log between its runs; None outside
    its times."""
    if not curve or t < curve[0][0] or t > curve[-1][0]:
        return None
    for (t0, e0), (t1, e1) in zip(curve, curve[1:]):
        if t0 <= t <= t1:
            k = (math.log(t) - math.log(t0)) / (math.log(t1) - math.log(t0)) if t1 > t0 else 0.0
            return math.exp(math.log(e0) + k * (math.log(e1) - math.log(e0)))
    return curve[-1][1]


def ratio(curve, t, error):
    reached = at_time(curve, t)
    return f"{reached / error:.2f}x" if reached else "-"


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", default=os.path.join(common.ROOT, "bench", "out", "edges"))
    parser.add_argument("--docs", default=os.path.join(common.ROOT, "docs", "EDGES.md"))
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--reference-noise", type=float, default=0.003)
    args = parser.parse_args()
    common.build()
    os.makedirs(args.out, exist_ok=True)
    lines = [
        "# More samples where an edge crosses a pixel",
        "",
        "Generated by `python3 bench/edges.py` (do not edit). The Cornell box at "
        f"{SIZE[0]}x{SIZE[1]}, `-ab 1 --lambertian`, the peers bench's two views, its three cheapest "
        "settings and two at one sample a pixel with more shadow rays, each with `--edge-samples` 0, 8 "
        "and 16 and `--denoise`; relMSE of the composite "
        "(raw) and of the `denoised` layer against icrender's brute-force reference "
        f"(`icrender reference`, noise {args.reference_noise}); times are the fastest of {args.repeats} "
        "renders (`render_s`; denoised: plus the denoiser's `denoise_s`). Equal time: the raw curve's "
        "error at a run's time over the run's error (above 1: the run is ahead), the raw curve being "
        "the lower envelope of the view's raw runs (each run that beats every faster one, joined "
        "log-log; `-` outside its times): for a denoised run against every raw run, for a raw run "
        "with edge samples against the raw runs without.",
        "",
    ]
    for view in VIEWS:
        reference = common.reference(SCENE, os.path.join(args.out, f"reference-{view}.exr"),
                                     base(view), noise=args.reference_noise, max_seconds=600)
        rows = []
        for edges in EDGE_SAMPLES:
            for k, setting in enumerate(SETTINGS):
                out = os.path.join(args.out, f"{view}-{k}-{edges}.exr")
                stats = run(out, view, setting, edges, args.repeats)
                errors = common.compare(out, reference)
                raw_s, den_s = stats["render_s"], stats["render_s"] + stats["denoise_s"]
                rows.append((setting, edges, stats["edge_pixels"], raw_s, errors["composite"][1], den_s,
                             errors["denoised"][1]))
                print(f"edges: {view} setting {k} --edge-samples {edges}: edge pixels {stats['edge_pixels']}, "
                      f"raw {raw_s:.3f} s {errors['composite'][1]:.3e}, denoised {den_s:.3f} s "
                      f"{errors['denoised'][1]:.3e}", flush=True)
        raw = envelope([(r[3], r[4]) for r in rows])
        plain = envelope([(r[3], r[4]) for r in rows if r[1] == 0])
        lines += [f"## View: {view}", "",
                  "| settings | edge samples | edge pixels | raw s | raw relMSE | raw at equal time, against no edge samples "
                  "| denoised s | denoised relMSE | denoised at equal time, against every raw run |",
                  "|---|---|---|---|---|---|---|---|---|"]
        for setting, edges, pixels, raw_s, raw_e, den_s, den_e in rows:
            against_plain = ratio(plain, raw_s, raw_e) if edges else ""
            lines.append(f"| `{setting}` | {edges} | {pixels} | {raw_s:.3f} | {raw_e:.3e} | {against_plain} | "
                         f"{den_s:.3f} | {den_e:.3e} | {ratio(raw, den_s, den_e)} |")
        lines.append("")
    lines += defaults_section(args)
    with open(args.docs, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"edges: wrote {args.docs}")
    return 0


def scene_reference(name, scene, options, args):
    """The peers bench's icrender reference of the scene's default view when it exists (the same
    image: size, -ab, --lambertian, the automatic view), else one made the same way: brute
    force at -ad 16 and 4 samples a pixel with 4 shadow rays a pass (at the default -ad one
    pass took over a minute and 300 s left 6-12 % noise)."""
    peers = os.path.join(common.ROOT, "bench", "out", "peers", name, "reference-icrender.exr")
    if os.path.exists(peers):
        return peers
    return common.reference(scene, os.path.join(args.out, f"reference-{name}.exr"),
                            ["-ad", "16", "--spp", "4", "--light-samples", "4"] + options,
                            noise=0.004, max_seconds=300)


def defaults_section(args):
    """The renderer's defaults on the three scenes, with and without edge samples."""
    lines = ["## At the defaults, on three scenes", "",
             "Each scene's default view with `--lambertian` and otherwise the renderer's defaults "
             "(`--spp 1 --light-samples 16`, the default `-aa`/`-ad`), with `--edge-samples` 0, 4 and 8 "
             "and, for comparison, more samples in every pixel. References: `icrender reference` "
             "(the Cornell box's above; elsewhere the peers bench's, or made as it makes them: noise 0.004 "
             "or 300 s). Equal time: the "
             "curve of the runs without edge samples at a run's time over the run's error (above 1: "
             "the run is ahead; `-` outside their times).", "",
             "| scene | settings | edge samples | edge pixels | s | relMSE | at equal time, against no edge samples |",
             "|---|---|---|---|---|---|---|"]
    for name, (scene, (width, height), ab) in DEFAULT_SCENES.items():
        options = ["-x", str(width), "-y", str(height), "-ab", str(ab), "--lambertian"]
        reference = os.path.join(args.out, "reference-default.exr") if name == "cornell" else scene_reference(
            name, scene, options, args)
        rows = []
        for setting, edges in DEFAULT_RUNS:
            out = os.path.join(args.out, f"defaults-{name}-{setting.split()[-1]}-{edges}.exr")
            stats = run(out, "default", setting, edges, args.repeats, scene=scene, options=options, denoise=False)
            error = common.compare(out, reference)["composite"][1]
            rows.append((setting, edges, stats["edge_pixels"], stats["render_s"], error))
            print(f"edges: defaults, {name}, {setting} --edge-samples {edges}: edge pixels {stats['edge_pixels']}, "
                  f"{stats['render_s']:.3f} s, relMSE {error:.3e}", flush=True)
        plain = envelope([(r[3], r[4]) for r in rows if r[1] == 0])
        for setting, edges, pixels, seconds, error in rows:
            against = ratio(plain, seconds, error) if edges else ""
            lines.append(f"| {name} | `{setting}` | {edges} | {pixels} | {seconds:.3f} | {error:.3e} | {against} |")
    return lines + [""]


if __name__ == "__main__":
    sys.exit(main())
