#!/usr/bin/env python3
"""icrender against the path tracers a user would pick instead, Mitsuba 3 and Blender Cycles,
at equal error: error against a converged reference as a function of render time, all on the
same cores in the same run.

    python3 bench/peers.py                          # Cornell box, conference room, Sibenik
    python3 bench/peers.py --scenes cornell         # one scene
    python3 bench/peers.py --scenes cornell --repeats 3 --peer-spp 4,8,16,32,64

For each scene, under bench/out/peers/SCENE/:
  1. icrender renders once to fix the view (its EXR's icrender/view), and that view is given
     to every renderer;
  2. the converged reference is made twice, by icrender's brute force (`icrender reference`)
     and by Mitsuba at high spp, all with `--lambertian` semantics (every material a two-sided
     Lambertian of its base colour, textures kept, emitters unchanged); the bench prints how
     far apart they are and stops if their means differ by more than 1% (one of them has a
     bug); errors are measured against the mean of the two;
  3. Mitsuba 3 (`path`, max_depth = -ab + 2) and Cycles (max bounces = -ab, raw and with
     OpenImageDenoise) render at --peer-spp, icrender at its sweep of -aa / -ad / --spp;
     each pass over all renderers is repeated --repeats times back to back, and the fastest
     time of each run is kept (the machine is shared; errors do not change between repeats);
  4. writes peers-SCENE.csv and peers-SCENE.png (relMSE, relMSE of 4x4-averaged pixels as in
     DESIGN.md, and RMSE, against time), and prints the targets of issue 9.

Times: icrender's render_s, Mitsuba's mi.render, Cycles' render after a warm-up render that
built its BVH (persistent data): rendering alone, without loading or BVH building, for all.
Peers are bench tools, installed with pip when missing; never dependencies of the renderer.
"""

import argparse
import csv
import json
import os
import subprocess
import sys
import time

import numpy as np

import common

HERE = os.path.dirname(os.path.abspath(__file__))

# Each scene: file, size, -ab, and icrender's runs (-aa, -ad, --spp, --light-samples).
SCENES = {
    "cornell": {
        "file": os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"),
        "size": (256, 256), "ab": 1,
        "icrender": [(0.3, 64, 1, 4), (0.3, 64, 2, 2), (0.3, 64, 4, 2), (0.25, 96, 8, 1), (0.2, 128, 16, 1),
                     (0.15, 192, 32, 1), (0.1, 256, 64, 1)],
        "reference_seconds": 300,
    },
    "conference": {
        "file": os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"),
        "size": (320, 240), "ab": 2,
        "icrender": [(0.3, 64, 1, 4), (0.25, 96, 4, 2), (0.2, 128, 8, 1), (0.15, 192, 16, 1), (0.1, 256, 32, 1)],
        "reference_seconds": 600,
    },
    "sibenik": {
        "file": os.path.join(common.SHARED_SCENES, "sibenik_cathedral", "sibenik.gltf"),
        "size": (320, 240), "ab": 2,
        "icrender": [(0.3, 64, 1, 1), (0.25, 96, 4, 1), (0.2, 128, 8, 1), (0.15, 192, 16, 1), (0.1, 256, 32, 1)],
        "reference_seconds": 600,
    },
}


def log(message):
    print(f"peers: {message}", flush=True)


def read_rgb(path, scratch=None):
    """An EXR's R, G, B (the composite) as an (height, width, 3) float64 array."""
    exr = common.ensure_module("OpenEXR")
    channels = exr.File(path).channels()
    for name in ("RGBA", "RGB"):
        if name in channels:
            return channels[name].pixels[..., :3].astype(np.float64)
    raise RuntimeError(f"{path}: no RGB channels (has {', '.join(channels)})")


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
            return line.split(":", 1)[1].strip().strip('"')
    raise RuntimeError(f"{out} has no icrender/view attribute")


def references(name, cfg, base, view, folder, args, scratch):
    """Both converged references, their agreement, and the mean of the two."""
    ours = os.path.join(folder, "reference-icrender.exr")
    if not os.path.exists(ours):
        log(f"{name}: icrender reference (brute force, up to {cfg['reference_seconds']} s)")
        subprocess.run([common.BINARY, "reference", cfg["file"], "-o", ours, "-q", "--no-preview",
                        "--noise", str(args.reference_noise), "--max-seconds", str(cfg["reference_seconds"]),
                        "-ad", "16", "--spp", "4", "--light-samples", "4"] + base, check=True)
    theirs = os.path.join(folder, f"reference-mitsuba-{args.reference_spp}spp.exr")
    if not os.path.exists(theirs):
        log(f"{name}: Mitsuba reference at {args.reference_spp} spp")
        job = dict(scene=cfg["file"], view=view, width=cfg["size"][0], height=cfg["size"][1], ab=cfg["ab"],
                   spp=[args.reference_spp], out=folder, prefix="reference")
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


def measure(name, cfg, args):
    folder = os.path.join(args.out, name)
    os.makedirs(folder, exist_ok=True)
    scratch = common.scratch()
    width, height = cfg["size"]
    base = ["-x", str(width), "-y", str(height), "-ab", str(cfg["ab"]), "--lambertian"]
    view = icrender_view(cfg["file"], base, folder)
    log(f"{name}: view {view}")
    reference, agreement = references(name, cfg, base, view, folder, args, scratch)
    peer_spp = [int(s) for s in args.peer_spp.split(",")]
    job = dict(scene=cfg["file"], view=view, width=width, height=height, ab=cfg["ab"], spp=peer_spp, out=folder,
               prefix="run", denoised_spp=[s for s in peer_spp if s <= args.max_denoised_spp])
    times, images = {}, {}
    for repeat in range(args.repeats):
        log(f"{name}: pass {repeat + 1} of {args.repeats}")
        for aa, ad, spp, ls in cfg["icrender"]:
            key = ("icrender", f"-aa {aa} -ad {ad} --spp {spp} --light-samples {ls}", spp)
            out = os.path.join(folder, f"run-icrender-aa{aa}-ad{ad}-spp{spp}-ls{ls}.exr")
            stats, _ = common.render(cfg["file"], out, base + ["-aa", str(aa), "-ad", str(ad), "--spp", str(spp),
                                                               "--light-samples", str(ls), "--seed", str(repeat + 1)])
            times.setdefault(key, []).append(stats["render_s"])
            images.setdefault(key, out)
        if not args.no_mitsuba:
            for row in run_peer("peer_mitsuba.py", job, folder):
                key = ("mitsuba", "path, independent sampler", row["spp"])
                times.setdefault(key, []).append(row["seconds"])
                images.setdefault(key, row["exr"])
        if not args.no_cycles:
            for row in run_peer("peer_cycles.py", job, folder):
                key = ("cycles+oidn" if row["denoised"] else "cycles", "CPU", row["spp"])
                times.setdefault(key, []).append(row["seconds"])
                images.setdefault(key, row["exr"])
    rows = []
    for key, ts in times.items():
        e = errors(read_rgb(images[key], scratch), reference)
        rows.append(dict(scene=name, renderer=key[0], settings=key[1], spp=key[2], seconds=min(ts),
                         seconds_all=" ".join(f"{t:.3f}" for t in ts), **e, **agreement))
    rows.sort(key=lambda r: (r["renderer"], r["seconds"]))
    return rows


def interpolate_time(rows, error, metric):
    """The time a renderer's curve reaches `error` (log-log interpolation), or None."""
    pts = sorted((r["seconds"], r[metric]) for r in rows)
    best = float("inf")
    for (t0, e0), (t1, e1) in zip(pts, pts[1:]):
        if e0 >= error >= e1 and e0 > e1:
            f = (np.log(e0) - np.log(error)) / (np.log(e0) - np.log(e1))
            best = min(best, float(np.exp(np.log(t0) + f * (np.log(t1) - np.log(t0)))))
    for t, e in pts:
        if e <= error:
            best = min(best, t)
    return None if best == float("inf") else best


def targets(name, rows, metric):
    """Prints issue 9's targets for a scene on one error measure."""
    ours = [r for r in rows if r["renderer"] == "icrender"]
    peers = {p: [r for r in rows if r["renderer"] == p] for p in ("mitsuba", "cycles", "cycles+oidn")}
    peers = {p: rs for p, rs in peers.items() if rs}
    if not ours or not peers:
        return
    if name == "cornell":
        # Below the best peer at every time in the measured range: at each peer point, our
        # curve's error at that time (log-log interpolated) against the peer's.
        worst = None
        for p, rs in peers.items():
            for r in rs:
                t = interpolate_time(ours, r[metric], metric)
                if t is not None:
                    ratio = r["seconds"] / t
                    if worst is None or ratio < worst[0]:
                        worst = (ratio, p, r)
                else:
                    worst = (0.0, p, r) if worst is None or worst[0] > 0 else worst
        if worst:
            ratio, p, r = worst
            verdict = "met" if ratio > 1 else "missed"
            log(f"{name} [{metric}]: target 'below the best peer at every time': {verdict}; tightest point: "
                f"{p} {r['spp']} spp reaches {r[metric]:.2e} in {r['seconds']:.2f} s, icrender in "
                f"{(r['seconds'] / ratio if ratio else float('nan')):.2f} s ({ratio:.2f}x)")
    else:
        best = None
        for p, rs in peers.items():
            for r in rs:
                if r["spp"] == 16 and (best is None or r[metric] < best[1][metric]):
                    best = (p, r)
        if best:
            p, r = best
            t = interpolate_time(ours, r[metric], metric)
            speedup = r["seconds"] / t if t else 0.0
            verdict = "met" if speedup >= 3 else "missed"
            log(f"{name} [{metric}]: target '3x sooner than the best peer's 16 spp': {verdict}: {p} 16 spp "
                f"{r[metric]:.2e} in {r['seconds']:.2f} s; icrender "
                + (f"{t:.2f} s ({speedup:.2f}x)" if t else "never reaches it in the measured range"))


def plot(name, cfg, rows, path):
    plt = common.ensure_module("matplotlib.pyplot", "matplotlib")
    fig, axes = plt.subplots(1, 3, figsize=(17, 5))
    styles = {"icrender": "o-", "mitsuba": "s--", "cycles": "^--", "cycles+oidn": "v:"}
    for ax, metric, label in ((axes[0], "relmse", "relMSE"), (axes[1], "relmse_4x4", "relMSE of 4x4-averaged pixels"),
                              (axes[2], "rmse", "RMSE")):
        for renderer, style in styles.items():
            pts = sorted((r["seconds"], r[metric], r["spp"]) for r in rows if r["renderer"] == renderer)
            if not pts:
                continue
            ax.plot([p[0] for p in pts], [p[1] for p in pts], style, label=renderer)
            for t, e, spp in pts:
                ax.annotate(str(spp), (t, e), fontsize=6, xytext=(2, 2), textcoords="offset points")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("render time (s), 2 cores")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
    w, h = cfg["size"]
    fig.suptitle(f"{name} {w}x{h}, -ab {cfg['ab']}, --lambertian: error against the converged reference "
                 f"(labels: samples per pixel)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--scenes", default="cornell,conference,sibenik")
    parser.add_argument("--peer-spp", default="4,8,16,32,64,128,256")
    parser.add_argument("--max-denoised-spp", type=int, default=64, help="Cycles+OIDN up to this many spp")
    parser.add_argument("--repeats", type=int, default=2, help="passes over all renderers; fastest time kept")
    parser.add_argument("--reference-spp", type=int, default=4096, help="Mitsuba's reference")
    parser.add_argument("--reference-noise", type=float, default=0.004, help="icrender reference's noise target")
    parser.add_argument("--no-mitsuba", action="store_true")
    parser.add_argument("--no-cycles", action="store_true")
    parser.add_argument("--out", default=os.path.join(common.ROOT, "bench", "out", "peers"))
    parser.add_argument("--plots", default=os.path.join(common.ROOT, "docs", "peers"),
                        help="where the CSV and PNG go (committed)")
    args = parser.parse_args()
    common.build()
    if not args.no_mitsuba:
        common.ensure_module("mitsuba")
    if not args.no_cycles:
        common.ensure_module("bpy")
    os.makedirs(args.plots, exist_ok=True)
    load = os.getloadavg()
    log(f"load average at start {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} cores")
    for name in args.scenes.split(","):
        cfg = SCENES[name]
        start = time.time()
        rows = measure(name, cfg, args)
        csv_path = os.path.join(args.plots, f"peers-{name}.csv")
        with open(csv_path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
            w.writeheader()
            w.writerows(rows)
        plot(name, cfg, rows, os.path.join(args.plots, f"peers-{name}.png"))
        for r in rows:
            log(f"{name}: {r['renderer']:12} {r['settings']:48} {r['spp']:4} spp {r['seconds']:8.3f} s "
                f"relMSE {r['relmse']:.2e} 4x4 {r['relmse_4x4']:.2e} RMSE {r['rmse']:.2e}")
        for metric in ("relmse", "relmse_4x4", "rmse"):
            targets(name, rows, metric)
        load = os.getloadavg()
        log(f"{name}: done in {time.time() - start:.0f} s; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; "
            f"{csv_path}")


if __name__ == "__main__":
    main()
