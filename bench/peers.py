#!/usr/bin/env python3
"""icrender against the path tracers a user would pick instead, Mitsuba 3 and Blender Cycles,
at equal error: error against a converged reference as a function of render time, all on the
same cores in the same run.

    python3 bench/peers.py                          # Cornell box, conference room, Sibenik, two views each
    python3 bench/peers.py --scenes cornell --views default   # one scene, one view
    python3 bench/peers.py --references-only        # make the references ahead (untimed)
    python3 bench/peers.py --scenes cornell --repeats 3 --peer-spp 4,8,16,32,64

For each scene and view, under bench/out/peers/SCENE/ (SCENE-VIEW/ for a second view):
  1. icrender renders once to fix the view (its EXR's icrender/view), and that view is given
     to every renderer;
  2. the converged reference is made twice, by icrender's brute force (`icrender reference`)
     and by Mitsuba at high spp, all with `--lambertian` semantics (every material a two-sided
     Lambertian of its base colour, textures kept, emitters unchanged); the bench prints how
     far apart they are and stops if their means differ by more than 1% (one of them has a
     bug); errors are measured against the mean of the two;
  3. Mitsuba 3 (`path`, max_depth = -ab + 2) and Cycles (max bounces = -ab, raw and with
     OpenImageDenoise) render at --peer-spp, icrender at its sweep of -aa / -ad / --spp, each
     run with --denoise, so that its raw composite is the curve `icrender` (at render_s) and
     its `denoised` layer the curve `icrender+oidn` (at render_s plus the denoiser's denoise_s);
     each pass over all renderers is repeated --repeats times back to back, and the fastest
     time of each run is kept (the machine is shared; errors do not change between repeats);
  4. writes docs/peers/peers-SCENE[-VIEW].csv and .png (relMSE, relMSE of 4x4-averaged pixels as in
     DESIGN.md, and RMSE, against wall time and against CPU time over the cores), and prints the
     targets of issue 18 on each measure, and issue 21's: icrender+oidn against icrender raw and
     against Cycles + OIDN.

Times: icrender's render_s, Mitsuba's mi.render, Cycles' render after a warm-up render that
built its BVH (persistent data): rendering alone, without loading or BVH building, for all.
On a shared machine the wall time depends on what else runs; CPU time over the cores (thread
CPU time for icrender, the process's for the peers) is what the wall time would be on idle
cores with perfect scaling, and is reported beside it. The conference room and Sibenik run the
peers at 4 .. 64 spp by default (--peer-spp-large): a sweep to 256 spp there takes many minutes.
Peers are bench tools, installed with pip when missing; never dependencies of the renderer.
"""

import argparse
import contextlib
import csv
import io
import json
import math
import os
import subprocess
import sys
import time

import common

# Checked before anything is imported or rendered (the flags leave a peer out).
common.require(
    "bench/peers.py",
    ["numpy", "matplotlib", "OpenEXR"]
    + ([] if "--no-mitsuba" in sys.argv else ["mitsuba"])
    + ([] if "--no-cycles" in sys.argv else ["bpy"]),
)

import numpy as np  # noqa: E402

HERE = os.path.dirname(os.path.abspath(__file__))

from peer_scenes import SCENES  # noqa: E402

# A view is given with its horizontal angle only (-vh): icrender then makes the vertical one
# that keeps the pixels square. The path tracers render square pixels only; with both -vh and
# -vv at another aspect than the image's, icrender's image would be stretched against theirs
# (the conference corner view once had -vh 74 -vv 60 at 320x240: the references' means differed
# by 1.9 %, a framing 1.8 % taller in icrender's).


def log(message):
    print(f"peers: {message}", flush=True)


def read_rgb(path, scratch=None, layer=None):
    """An EXR's R, G, B (the composite, or `layer`'s) as an (height, width, 3) float64 array."""
    exr = common.ensure_module("OpenEXR")
    channels = exr.File(path).channels()
    for name in ((layer,) if layer else ("RGBA", "RGB")):
        if name in channels:
            return channels[name].pixels[..., :3].astype(np.float64)
    raise RuntimeError(f"{path}: no {layer or 'RGB'} channels (has {', '.join(channels)})")


def exr_attribute(path, name):
    """A string attribute of an EXR's header, or "" where it has none."""
    value = common.ensure_module("OpenEXR").File(path).header().get(name)
    return value if isinstance(value, str) else ""


def errors(image, reference):
    """relMSE (eps 0.01, as `icrender compare`), the same of 4x4-averaged pixels, RMSE, means."""
    def rel(a, b):
        return float(np.mean((a - b) ** 2 / (b * b + 0.01)))

    def blocks(a):
        h, w = a.shape[0] // 4 * 4, a.shape[1] // 4 * 4
        return a[:h, :w].reshape(h // 4, 4, w // 4, 4, 3).mean(axis=(1, 3))

    return {"relmse": rel(image, reference), "relmse_4x4": rel(blocks(image), blocks(reference)),
            "rmse": float(np.sqrt(np.mean((image - reference) ** 2))), "mean": float(image.mean())}


def run_peer(script, job, folder):
    """Runs a peer script in its own process; returns its JSON lines."""
    path = os.path.join(folder, f"job-{os.path.basename(script)}.json")
    with open(path, "w") as f:
        json.dump(job, f)
    result = subprocess.run([sys.executable, os.path.join(HERE, script), path], capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"{script} failed:\n{result.stderr[-3000:]}")
    return [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]


def icrender_view(scene, base, folder):
    out = os.path.join(folder, "view.exr")
    common.render(scene, out, base + ["--spp", "1", "-aa", "0.5", "-ad", "16"])
    info = subprocess.run(["oiiotool", "--info", "-v", out], capture_output=True, text=True, check=True).stdout
    for line in info.splitlines():
        if "icrender/view:" in line:
            view = line.split(":", 1)[1].strip().strip('"')
            square_pixels(view, base)
            return view
    raise RuntimeError(f"{out} has no icrender/view attribute")


def square_pixels(view, base):
    """Stops the bench on a view whose pixels are not square at the image's size (see the
    note under SCENES): the path tracers would frame another image."""
    words = view.split()
    h, v = float(words[words.index("-vh") + 1]), float(words[words.index("-vv") + 1])
    width, height = int(base[base.index("-x") + 1]), int(base[base.index("-y") + 1])
    aspect = math.tan(math.radians(h) / 2) / math.tan(math.radians(v) / 2) * height / width
    if abs(aspect - 1.0) > 1e-3:
        sys.exit(f"peers: view '{view}' at {width}x{height} has pixels {aspect:.4f} times as wide as "
                 f"high; give -vh alone (icrender fits -vv to square pixels), as the path tracers need")


def references(name, cfg, base, view, folder, args, scratch):
    """Both converged references, their agreement, and the mean of the two."""
    width, height = cfg["size"]

    def stale(path):
        """A cached reference of another image size (the scene's size changed since) is made anew."""
        if os.path.exists(path) and read_rgb(path).shape[:2] != (height, width):
            log(f"{name}: {path} is not {width}x{height}: making it again")
            os.remove(path)
        return not os.path.exists(path)

    ours = os.path.join(folder, "reference-icrender.exr")
    noise = args.reference_noise or cfg["reference_noise"]
    target = ["--noise", str(noise), "--max-seconds", str(cfg["reference_seconds"])]
    if not stale(ours) and " ".join(target) not in exr_attribute(ours, "icrender/command"):
        log(f"{name}: {ours} was made to another noise target or time: making it again ({' '.join(target)})")
        os.remove(ours)
    if not os.path.exists(ours):
        log(f"{name}: icrender reference (brute force, to {noise} noise or {cfg['reference_seconds']} s)")
        subprocess.run([common.BINARY, "reference", cfg["file"], "-o", ours, "-q", "--no-preview"] + target
                       + ["-ad", "16", "--spp", "4", "--light-samples", "4"] + base, check=True)
    # Mitsuba's reference is the noisier of the two, and the mean's error adds to every
    # renderer's measured error (a quarter of the two references' relMSE apart). At 4096 spp on
    # the Cornell box and 512 elsewhere it was most of what separated them (relMSE apart 4.6e-5,
    # 7.0e-3 and 2.0e-2 on the Cornell box, the conference room and Sibenik's aisle, where
    # icrender's best runs measured 3.7e-5, 4.2e-3 and 8.3e-3): a floor under the best errors.
    spp = args.reference_spp or cfg["mitsuba_reference_spp"]
    theirs = os.path.join(folder, f"reference-mitsuba-{spp}spp.exr")
    if stale(theirs):
        log(f"{name}: Mitsuba reference at {spp} spp")
        job = dict(scene=cfg["file"], view=view, width=width, height=height, ab=cfg["ab"],
                   spp=[spp], out=folder, prefix="reference")
        [row] = run_peer("peer_mitsuba.py", job, folder)
        os.replace(row["exr"], theirs)
    a, b = read_rgb(ours, scratch), read_rgb(theirs, scratch)
    apart = errors(a, b)
    difference = abs(apart["mean"] - b.mean()) / b.mean()
    log(f"{name}: references: icrender mean {a.mean():.5f}, Mitsuba mean {b.mean():.5f} "
        f"({difference * 100:.2f}% apart), relMSE between them {apart['relmse']:.2e} "
        f"(4x4: {apart['relmse_4x4']:.2e}), RMSE {apart['rmse']:.2e}")
    if difference > 0.01:
        sys.exit(f"peers: {name}: the two references' means differ by {difference * 100:.2f}% (> 1%): "
                 f"icrender's brute force and Mitsuba do not render the same scene; one of them has a bug "
                 f"({ours} against {theirs})")
    return 0.5 * (a + b), {"reference_gap_percent": difference * 100, "reference_relmse": apart["relmse"]}


def label(name, view):
    """A scene's name with its view's, as the outputs are named: the default view is the scene."""
    return name if view == "default" else f"{name}-{view}"


def measure(name, view_name, cfg, args):
    folder = os.path.join(args.out, label(name, view_name))
    os.makedirs(folder, exist_ok=True)
    scratch = common.scratch()
    width, height = cfg["size"]
    base = ["-x", str(width), "-y", str(height), "-ab", str(cfg["ab"]), "--lambertian"] + cfg["views"][view_name]
    view = icrender_view(cfg["file"], base, folder)
    log(f"{name}: view {view}")
    reference, agreement = references(name, cfg, base, view, folder, args, scratch)
    if args.references_only:
        return []
    peer_spp = [int(s) for s in (args.peer_spp if name == "cornell" else args.peer_spp_large).split(",")]
    job = dict(scene=cfg["file"], view=view, width=width, height=height, ab=cfg["ab"], spp=peer_spp, out=folder,
               prefix="run", denoised_spp=[s for s in peer_spp if s <= args.max_denoised_spp])
    times, images = {}, {}
    denoise = [] if args.no_denoise else ["--denoise", "--denoise-quality", args.denoise_quality]
    for repeat in range(args.repeats):
        log(f"{name}: pass {repeat + 1} of {args.repeats}")
        for k, options in enumerate(cfg["icrender"]):
            words = options.split()
            spp = int(words[words.index("--spp") + 1])
            key = ("icrender", options, spp)
            out = os.path.join(folder, f"run-icrender-{k}.exr")
            # The same seed in every pass: the repeats are for the time, and the image (and so
            # the error) measured is the same whichever pass wrote it last.
            stats, _ = common.render(cfg["file"], out, base + words + denoise + ["--seed", "1"])
            cpu = stats["t_amb_s"] + stats["t_notamb_s"]
            times.setdefault(key, []).append((stats["render_s"], cpu))
            images.setdefault(key, (out, None))
            if denoise:
                # The same render, its `denoised` layer (the raw emission plus the denoised light
                # layers), at the render's time plus the denoiser's; the denoiser runs on every
                # core, so its CPU time is its wall time times the cores.
                extra = stats["denoise_s"]
                times.setdefault(("icrender+oidn",) + key[1:], []).append(
                    (stats["render_s"] + extra, cpu + extra * os.cpu_count()))
                images.setdefault(("icrender+oidn",) + key[1:], (out, "denoised"))
        if not args.no_mitsuba:
            for row in run_peer("peer_mitsuba.py", job, folder):
                key = ("mitsuba", "path, independent sampler", row["spp"])
                times.setdefault(key, []).append((row["seconds"], row["cpu_seconds"]))
                images.setdefault(key, (row["exr"], None))
        if not args.no_cycles:
            for row in run_peer("peer_cycles.py", job, folder):
                key = ("cycles+oidn" if row["denoised"] else "cycles", "CPU", row["spp"])
                times.setdefault(key, []).append((row["seconds"], row["cpu_seconds"]))
                images.setdefault(key, (row["exr"], None))
    rows = []
    for key, ts in times.items():
        path, layer = images[key]
        e = errors(read_rgb(path, scratch, layer), reference)
        # The fastest wall time of the repeats, and CPU time over the cores (what the wall time
        # would be on idle cores with perfect scaling: the measure a loaded machine cannot spoil).
        rows.append(dict(scene=name, renderer=key[0], settings=key[1], spp=key[2], seconds=min(t for t, _ in ts),
                         cpu_seconds=min(c for _, c in ts), core_seconds=min(c for _, c in ts) / os.cpu_count(),
                         seconds_all=" ".join(f"{t:.3f}" for t, _ in ts), **e, **agreement))
    rows.sort(key=lambda r: (r["renderer"], r["seconds"]))
    # Each renderer at its most samples should have converged near the reference: a mean 1% off
    # there is a scene translated wrongly or a bug (Cycles' smooth normals were caught this way).
    ref_mean = float(reference.mean())
    for renderer in sorted({r["renderer"] for r in rows}):
        top = max((r for r in rows if r["renderer"] == renderer), key=lambda r: r["spp"])
        gap = (top["mean"] - ref_mean) / ref_mean
        if abs(gap) > 0.01:
            log(f"{name}: WARNING: {renderer} at {top['spp']} spp has mean {top['mean']:.5f}, {gap * 100:+.2f}% from "
                f"the reference's {ref_mean:.5f}: it does not render the same scene (a bug, here or there)")
    return rows


CLOCKS = {"seconds": "wall time (s, fastest repeat)", "core_seconds": "CPU time / cores (s)"}


def interpolate_time(rows, error, metric, clock):
    """The time a renderer's curve first reaches `error` (log-log interpolation), or None."""
    pts = sorted((r[clock], r[metric]) for r in rows)
    best = float("inf")
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 >= error >= e1 and e0 > e1:
            f = (np.log(e0) - np.log(error)) / (np.log(e0) - np.log(e1))
            best = min(best, float(np.exp(np.log(t0) + f * (np.log(t1) - np.log(t0)))))
    for t, e in pts:
        if e <= error:
            best = min(best, t)
    return None if best == float("inf") else best


def error_at(rows, t, metric, clock):
    """A renderer's error at time t, log-log interpolated between its runs; None outside them."""
    pts = sorted((r[clock], r[metric]) for r in rows)
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if t0 <= t <= t1 and t1 > t0:
            f = (np.log(t) - np.log(t0)) / (np.log(t1) - np.log(t0))
            return float(np.exp(np.log(e0) + f * (np.log(e1) - np.log(e0))))
    return pts[0][1] if len(pts) == 1 and pts[0][0] == t else None


def frontier(rows, metric, clock):
    """The runs no other run beats: none as fast or faster has a lower error. A renderer with
    several knobs (icrender's settings) has runs in time order whose errors go up and down;
    its frontier is what a user who picks the best setting for a time budget gets."""
    best, kept = float("inf"), []
    for r in sorted(rows, key=lambda r: (r[clock], r[metric])):
        if r[metric] < best:
            kept.append(r)
            best = r[metric]
    return kept


def targets(name, rows, metric, clock, peer_names=("mitsuba", "cycles", "cycles+oidn"), horizon=30.0,
            ours_name="icrender", on_frontiers=False):
    """Prints (and returns as (worst time, ratio there, first time at or above it or None))
    the target for one scene, error measure and clock against the best of
    `peer_names`: icrender's curve below the best peer's at every time from icrender's fastest
    run to `horizon` seconds (aim: 2x below). At each time where icrender's curve and some
    peer's were both measured, the best peer's error over icrender's (log-log interpolated);
    a time before a peer's fastest run leaves that peer out. `on_frontiers`: every curve
    through its `frontier` only (the tag says so)."""
    ours = [r for r in rows if r["renderer"] == ours_name]
    peers = {p: [r for r in rows if r["renderer"] == p] for p in peer_names}
    peers = {p: rs for p, rs in peers.items() if rs}
    if not ours or not peers:
        return
    if on_frontiers:
        ours = frontier(ours, metric, clock)
        peers = {p: frontier(rs, metric, clock) for p, rs in peers.items()}
        rows = ours + [r for rs in peers.values() for r in rs]
    tag = f"{name} [{ours_name}, {metric}, {clock}, vs {'/'.join(peers)}{', frontiers' if on_frontiers else ''}]"
    first = min(r[clock] for r in ours)
    compared = []
    for t in sorted({r[clock] for r in rows if first <= r[clock] <= horizon}):
        e_ours = error_at(ours, t, metric, clock)
        e_peer = min((e for e in (error_at(rs, t, metric, clock) for rs in peers.values()) if e), default=None)
        if e_ours is not None and e_peer is not None:
            compared.append((t, e_peer / e_ours, e_ours, e_peer))
    if not compared:
        log(f"{tag}: no time where icrender and a peer were both measured")
        return
    t, ratio, e_ours, e_peer = min(compared, key=lambda c: c[1])
    verdict = "met" if ratio > 1 else "missed"
    aim = "and 2x below" if ratio >= 2 else "not 2x below"
    losses = [c[0] for c in compared if c[1] <= 1]
    span = f"{compared[0][0]:.2f} .. {compared[-1][0]:.2f} s"
    log(f"{tag}: 'below the best peer at every time' ({span}): {verdict} ({aim}); worst at {t:.2f} s: {ours_name} "
        f"{e_ours:.2e}, best peer {e_peer:.2e} (peer error / ours {ratio:.2f})"
        + (f"; {ours_name} at or above it from {losses[0]:.2f} s" if losses else ""))
    return t, ratio, (losses[0] if losses else None)


def report_targets(name, rows):
    """The targets on every measure and clock, against all peers and against the raw path
    tracers alone (no denoiser)."""
    for peer_names in (("mitsuba", "cycles", "cycles+oidn"), ("mitsuba", "cycles")):
        for clock in CLOCKS:
            for metric in ("relmse", "relmse_4x4", "rmse"):
                targets(name, rows, metric, clock, peer_names)
    # Issue 21: icrender with its denoiser against its own raw curve and against Cycles + OIDN.
    for peer_names in (("icrender",), ("cycles+oidn",), ("mitsuba", "cycles", "cycles+oidn")):
        for clock in CLOCKS:
            for metric in ("relmse", "relmse_4x4", "rmse"):
                targets(name, rows, metric, clock, peer_names, ours_name="icrender+oidn")
    # The denoised curve against the raw one again, each through its frontier only: icrender's
    # settings in time order are not a curve of one knob, and between two runs of one kind the
    # other curve may pass through a run of another (a 4-sample setting between one-sample ones).
    for clock in CLOCKS:
        for metric in ("relmse", "relmse_4x4"):
            targets(name, rows, metric, clock, ("icrender",), ours_name="icrender+oidn", on_frontiers=True)


# The names of the views in docs/benchmarks.md's tables, in their order (`--tables`).
TABLE_VIEWS = [("cornell", "default", "Cornell box, -ab 1"), ("cornell", "corner", "Cornell box, inside corner"),
                ("conference", "default", "conference room, -ab 2"),
                ("conference", "corner", "conference room, high corner"),
                ("sibenik", "default", "Sibenik, -ab 2"), ("sibenik", "aisle", "Sibenik, aisle")]


def read_rows(path):
    """A view's rows as `measure` made them, from its CSV in docs/peers."""
    with open(path) as f:
        return [{k: (v if k in ("scene", "renderer", "settings", "seconds_all") else int(v) if k == "spp" else float(v))
                 for k, v in r.items()} for r in csv.DictReader(f)]


def verdict_cell(name, rows, metric, peer_names, ours_name):
    """One cell of docs/benchmarks.md's tables: `targets`' verdict (CPU time over the cores), as
    "below at every time, at least Rx" or "above from T s, Rx at T s"."""
    # `targets` prints its line as well: not part of the tables.
    with contextlib.redirect_stdout(io.StringIO()):
        verdict = targets(name, rows, metric, "core_seconds", peer_names, ours_name=ours_name)
    if verdict is None:
        return "not measured"
    at, ratio, losing_from = verdict
    if ratio > 1:
        return f"below at every time, at least {ratio:.2f}x"
    return f"above from {losing_from:.2f} s, {ratio:.2f}x at {at:.2f} s"


def time_ratio(rows, metric, clock, peer_names, ours_name="icrender", horizon=30.0):
    """Issue 58's measure, time at equal error: for each run on icrender's frontier from its
    fastest to `horizon` seconds, its time over the time the fastest of `peer_names` takes to
    reach the same error (log-log interpolated along each peer's frontier). Returns the worst
    (largest) ratio with that run's time and error, or None. Where no peer run reached the error,
    the peers' slowest run stands in for the time they would take: the ratio is then an upper
    bound."""
    ours = [r for r in frontier([r for r in rows if r["renderer"] == ours_name], metric, clock)
            if r[clock] <= horizon]
    peers = [frontier([r for r in rows if r["renderer"] == p], metric, clock) for p in peer_names]
    peers = [rs for rs in peers if rs]
    if not ours or not peers:
        return None
    slowest = max(r[clock] for rs in peers for r in rs)
    worst = None
    for run in ours:
        reach = [t for t in (interpolate_time(rs, run[metric], metric, clock) for rs in peers) if t is not None]
        ratio = run[clock] / (min(reach) if reach else slowest)
        if worst is None or ratio > worst[0]:
            worst = (ratio, run[clock], run[metric], bool(reach))
    return worst


def time_ratio_cell(rows, metric, peer_names):
    """One cell of the third table: the worst time ratio (CPU time over the cores) and where."""
    worst = time_ratio(rows, metric, "core_seconds", peer_names)
    if worst is None:
        return "not measured"
    ratio, at, error, reached = worst
    bound = "" if reached else " (at most: no peer run reached it)"
    return f"{ratio:.2f}x{bound} at {at:.2f} s ({error:.1e})"


# The page that holds the two tables, between these markers (the rest of the page is prose).
TABLES_PAGE = os.path.join(common.ROOT, "docs", "benchmarks.md")
TABLES_BEGIN = "<!-- peers-tables:begin -->"
TABLES_END = "<!-- peers-tables:end -->"


def write_tables(page, tables):
    """Replaces what lies between the markers of `page` with `tables`; a page without both
    markers is an error, so the tables never land where no one reads them."""
    with open(page) as f:
        text = f.read()
    begin, end = text.find(TABLES_BEGIN), text.find(TABLES_END)
    if begin < 0 or end < begin:
        sys.exit(f"{page}: no {TABLES_BEGIN} ... {TABLES_END} block to write the tables into")
    text = text[:begin + len(TABLES_BEGIN)] + "\n" + tables + "\n" + text[end:]
    with open(page, "w") as f:
        f.write(text)


def tables_markdown(plots):
    """docs/benchmarks.md's three tables (issue 18's verdicts against the peers, issue 21's of the
    denoised curve, issue 58's time at equal error), from the CSVs in `plots`, as Markdown."""
    third = ["| scene, view | relMSE: time over the best peer's, worst | 4x4 relMSE: time over the best peer's, "
             "worst |", "|---|---|---|"]
    first = ["| scene, view | relMSE vs raw path tracers | relMSE vs every peer | 4x4 relMSE vs raw | "
             "4x4 relMSE vs every peer |", "|---|---|---|---|---|"]
    second = ["| scene, view | relMSE vs icrender raw | relMSE vs Cycles + OIDN | 4x4 relMSE vs icrender raw | "
              "4x4 relMSE vs Cycles + OIDN |", "|---|---|---|---|---|"]
    for name, view, title in TABLE_VIEWS:
        rows = read_rows(os.path.join(plots, f"peers-{label(name, view)}.csv"))
        against_peers = [verdict_cell(label(name, view), rows, metric, peers, "icrender")
                         for metric in ("relmse", "relmse_4x4")
                         for peers in (("mitsuba", "cycles"), ("mitsuba", "cycles", "cycles+oidn"))]
        denoised = [verdict_cell(label(name, view), rows, metric, peers, "icrender+oidn")
                    for metric in ("relmse", "relmse_4x4") for peers in (("icrender",), ("cycles+oidn",))]
        first.append(f"| {title} | " + " | ".join(against_peers) + " |")
        second.append(f"| {title} | " + " | ".join(denoised) + " |")
        every_peer = ("mitsuba", "cycles", "cycles+oidn")
        third.append(f"| {title} | " + " | ".join(time_ratio_cell(rows, metric, every_peer)
                                                  for metric in ("relmse", "relmse_4x4")) + " |")
    return "\n".join(first) + "\n\n" + "\n".join(second) + "\n\n" + "\n".join(third)


def plot(name, cfg, rows, path):
    plt = common.ensure_module("matplotlib.pyplot", "matplotlib")
    fig, axes = plt.subplots(2, 3, figsize=(17, 10))
    styles = {"icrender": "o-", "icrender+oidn": "D-", "mitsuba": "s--", "cycles": "^--", "cycles+oidn": "v:"}
    for row, (clock, clock_label) in enumerate(CLOCKS.items()):
        for ax, metric, label in ((axes[row][0], "relmse", "relMSE"),
                                  (axes[row][1], "relmse_4x4", "relMSE of 4x4-averaged pixels"),
                                  (axes[row][2], "rmse", "RMSE")):
            for renderer, style in styles.items():
                pts = sorted((r[clock], r[metric], r["spp"]) for r in rows if r["renderer"] == renderer)
                if not pts:
                    continue
                ax.plot([p[0] for p in pts], [p[1] for p in pts], style, label=renderer)
                for t, e, spp in pts:
                    ax.annotate(str(spp), (t, e), fontsize=6, xytext=(2, 2), textcoords="offset points")
            ax.set_xscale("log")
            ax.set_yscale("log")
            ax.set_xlabel(clock_label)
            ax.set_ylabel(label)
            ax.grid(True, which="both", alpha=0.3)
            ax.legend(fontsize=8)
    w, h = cfg["size"]
    fig.suptitle(f"{name} {w}x{h}, -ab {cfg['ab']}, --lambertian, 2 shared cores: error against the converged "
                 f"reference (labels: samples per pixel)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="cornell,conference,sibenik")
    parser.add_argument("--views", default="all",
                        help="the views to measure (names in SCENES, e.g. default), or all: two per scene")
    parser.add_argument("--peer-spp", default="4,8,16,32,64,128,256")
    parser.add_argument("--peer-spp-large", default="4,8,16,32,64",
                        help="the conference room's and Sibenik's (a full sweep there takes many minutes)")
    parser.add_argument("--max-denoised-spp", type=int, default=64, help="Cycles+OIDN up to this many spp")
    parser.add_argument("--repeats", type=int, default=1, help="passes over all renderers; fastest time kept")
    parser.add_argument("--reference-spp", type=int, default=0,
                        help="Mitsuba's reference (default: 16384 for the Cornell box, 4096 for the others)")
    parser.add_argument("--reference-noise", type=float, default=0,
                        help="icrender reference's noise target (default: the scene's, 0.002 for the Cornell box, "
                             "0.004 for the others)")
    parser.add_argument("--references-only", action="store_true",
                        help="make (or check) every view's two references and stop: they take minutes and are "
                             "not timed, so they can be made ahead, on a busy machine")
    parser.add_argument("--report-only", action="store_true",
                        help="re-read docs/peers/peers-SCENE.csv, print the targets and redraw the plot")
    parser.add_argument("--tables", action="store_true",
                        help="write the three tables (verdicts and time at equal error) from docs/peers/*.csv (all six views) into "
                             "docs/benchmarks.md, print them, and stop")
    parser.add_argument("--no-denoise", action="store_true", help="no icrender+oidn curve (icrender --denoise)")
    parser.add_argument("--denoise-quality", default="fast", choices=("fast", "balanced", "high"),
                        help="icrender --denoise-quality for the icrender+oidn curve")
    parser.add_argument("--no-mitsuba", action="store_true")
    parser.add_argument("--no-cycles", action="store_true")
    parser.add_argument("--out", default=os.path.join(common.ROOT, "bench", "out", "peers"))
    parser.add_argument("--plots", default=os.path.join(common.ROOT, "docs", "peers"),
                        help="where the CSV and PNG go (committed)")
    args = parser.parse_args()
    jobs = [(name, view) for name in args.scenes.split(",") for view in SCENES[name]["views"]
            if args.views == "all" or view in args.views.split(",")]
    if args.tables:
        tables = tables_markdown(args.plots)
        write_tables(TABLES_PAGE, tables)
        print(tables)
        return
    if args.report_only:
        for name, view in jobs:
            rows = read_rows(os.path.join(args.plots, f"peers-{label(name, view)}.csv"))
            plot(label(name, view), SCENES[name], rows, os.path.join(args.plots, f"peers-{label(name, view)}.png"))
            report_targets(label(name, view), rows)
        return
    common.build()
    os.makedirs(args.plots, exist_ok=True)
    load = os.getloadavg()
    log(f"load average at start {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    for name, view in jobs:
        cfg = SCENES[name]
        start = time.time()
        rows = measure(name, view, cfg, args)
        if args.references_only:
            continue
        name = label(name, view)
        csv_path = os.path.join(args.plots, f"peers-{name}.csv")
        with open(csv_path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
            w.writeheader()
            w.writerows(rows)
        plot(name, cfg, rows, os.path.join(args.plots, f"peers-{name}.png"))
        for r in rows:
            log(f"{name}: {r['renderer']:12} {r['settings']:70} {r['spp']:4} spp {r['seconds']:8.3f} s "
                f"(CPU/cores {r['core_seconds']:7.3f} s) "
                f"relMSE {r['relmse']:.2e} 4x4 {r['relmse_4x4']:.2e} RMSE {r['rmse']:.2e}")
        report_targets(name, rows)
        load = os.getloadavg()
        log(f"{name}: done in {time.time() - start:.0f} s; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; "
            f"{csv_path}")


if __name__ == "__main__":
    main()
