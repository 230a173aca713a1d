#!/usr/bin/env python3
"""icrender against Radiance's rpict on the same scene, view, size and ambient options.

    python3 bench/vs_radiance.py                                   # Cornell box, 256x256
    python3 bench/vs_radiance.py --scene ../shared/scenes/conference_room/conference.gltf -x 320 -y 240

What it does (all files go to --out, default target/vs_radiance/<scene>_<x>x<y>/):
  1. builds icrender (cargo build --release);
  2. takes the reference EXR given with --reference, or the one it made before for the same
     scene, size, -ab and --ref-spp, or renders one with `icrender reference` (falling back to a
     brute-force `icrender render -aa 0` when that command fails);
  3. renders with `icrender render` on every core and on one thread (--stats, --reference);
  4. exports the scene (`icrender export`), runs oconv, then rpict with the view icrender used
     (read from the `icrender/view` attribute of icrender's EXR), the same -x -y and -ab -aa -ad
     -as -ar, and -af to a fresh ambient file whose records `lookamb -d` counts;
  5. converts rpict's picture to EXR (oiiotool) and compares it with `icrender compare --json`;
  6. checks units and orientation (means and block means of rpict's image against the
     reference) and prints a table with the time and error ratios icrender/rpict.

Radiance comes from the PyPI package `pyradiance` (bench/requirements.txt; checked before any work); its binaries
are in the package's bin/ and need RAYPATH to point at its lib/. Standard library only otherwise.
Times: "wall" is the whole process as the script sees it (start-up, scene, render, writing the
image; the error is measured afterwards by `icrender compare`, for both renderers); "work" is, for
icrender, its own wall_s statistic (scene load, BVH, render; not the start-up nor writing the EXR),
for rpict the whole process (octree read, render, writing the picture, all small next to the
render); "cpu" is user + system time of the process, so a machine busy with other work shows as
wall > cpu / threads. The ratios are printed for all three. icrender runs on every core, on one
thread, and on one thread pinned to one core (taskset -c 0), where also the image library's
loading (OpenImageIO: ~0.3 s of CPU, done beside the render otherwise) takes its turn.
"""

import argparse
import array
import importlib.util
import json
import os
import re
import resource
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SCENE = ROOT / ".." / "shared" / "scenes" / "cornell_box" / "CornellBox-Original.gltf"
# Means of a Lambertian scene's two renderings should agree within this (units, emitter side,
# colours); beyond it the numbers below are not comparable.
MEAN_TOLERANCE = 0.05
# Block means (an 4x4 grid over the image) may differ by this before the orientation is suspect.
BLOCK_TOLERANCE = 0.25


def say(message):
    print(f"[vs_radiance] {message}", flush=True)


def loud(message):
    bar = "!" * 78
    print(f"\n{bar}\n!!! WARNING: {message}\n{bar}\n", flush=True)


def radiance_tools():
    """Directory of pyradiance's binaries and the environment (PATH, RAYPATH) to run them."""
    spec = importlib.util.find_spec("pyradiance")
    if spec is None:
        sys.exit("vs_radiance: needs the Python package pyradiance (Radiance's binaries), not installed for "
                 f"{sys.executable}; install the benches' pinned dependencies with: python3 -m venv .venv && "
                 ". .venv/bin/activate && pip install -r bench/requirements.txt")
    package = Path(next(iter(spec.submodule_search_locations)))
    bin_dir, lib_dir = package / "bin", package / "lib"
    for tool in ("oconv", "rpict", "lookamb", "getinfo", "pvalue"):
        if not (bin_dir / tool).exists():
            sys.exit(f"vs_radiance: {bin_dir / tool} not found (pyradiance without binaries?)")
    env = dict(os.environ)
    env["PATH"] = f"{bin_dir}{os.pathsep}{env.get('PATH', '')}"
    env["RAYPATH"] = f".{os.pathsep}{lib_dir}"
    return bin_dir, env


def run(cmd, *, env=None, stdout=None, check=True, quiet=False):
    """Runs a command; returns (CompletedProcess, wall seconds, cpu seconds of the child)."""
    if not quiet:
        say("$ " + " ".join(shlex.quote(str(c)) for c in cmd))
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run(
        [str(c) for c in cmd],
        env=env,
        stdout=stdout if stdout is not None else subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=stdout is None,
    )
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if check and result.returncode != 0:
        err = result.stderr if isinstance(result.stderr, str) else result.stderr.decode(errors="replace")
        sys.exit(f"vs_radiance: command failed ({result.returncode}): {' '.join(map(str, cmd))}\n{err}")
    return result, wall, cpu


def exr_attribute(path, name):
    out, _, _ = run(["oiiotool", "--info", "-v", path], quiet=True)
    match = re.search(rf'^\s*{re.escape(name)}:\s*"(.*)"\s*$', out.stdout, re.M)
    return match.group(1) if match else None


def exr_channels(path):
    out, _, _ = run(["oiiotool", "--info", "-v", path], quiet=True)
    match = re.search(r"channel list:\s*(.*)$", out.stdout, re.M)
    return [c.strip() for c in match.group(1).split(",")] if match else []


def compare(icrender, image, reference):
    """Composite error of `image` against `reference` from `icrender compare --json`."""
    out, _, _ = run([icrender, "compare", image, reference, "--json"], quiet=True)
    layers = json.loads(out.stdout)
    return next(layer for layer in layers if layer["layer"] == "composite")


def pixels(path, width, height, bin_dir, env, scratch):
    """RGB floats of an image, top row first: EXRs go through oiiotool to Radiance's format
    (RGBE keeps ~1% per channel, plenty for means), then `pvalue -df` gives raw floats."""
    source = Path(path)
    if source.suffix.lower() == ".exr":
        hdr = scratch / (source.stem + ".check.hdr")
        run(["oiiotool", source, "--ch", "R,G,B", "-o", hdr], quiet=True)
        source = hdr
    out, _, _ = run([bin_dir / "pvalue", "-h", "-H", "-o", "-df", source], env=env, stdout=subprocess.PIPE, quiet=True)
    values = array.array("f")
    values.frombytes(out.stdout)
    if len(values) != 3 * width * height:
        sys.exit(f"vs_radiance: {source}: expected {width}x{height} pixels, read {len(values) // 3}")
    return values


def block_means(values, width, height, blocks=4):
    """Mean (over RGB) of each cell of a blocks x blocks grid, row by row from the top."""
    sums = [[0.0] * blocks for _ in range(blocks)]
    counts = [[0] * blocks for _ in range(blocks)]
    for y in range(height):
        by = y * blocks // height
        row = 3 * y * width
        for x in range(width):
            bx = x * blocks // width
            i = row + 3 * x
            sums[by][bx] += values[i] + values[i + 1] + values[i + 2]
            counts[by][bx] += 3
    return [[s / max(c, 1) for s, c in zip(sr, cr)] for sr, cr in zip(sums, counts)]


def block_relmse(values, reference, width, height, block=4):
    """relMSE of block x block averaged pixels (noise averages out, bias and edges stay)."""
    total, n = 0.0, 0
    for by in range(0, height - block + 1, block):
        for bx in range(0, width - block + 1, block):
            for c in range(3):
                a = r = 0.0
                for y in range(by, by + block):
                    base = 3 * (y * width + bx) + c
                    for x in range(block):
                        a += values[base + 3 * x]
                        r += reference[base + 3 * x]
                a /= block * block
                r /= block * block
                total += (a - r) ** 2 / (r * r + 0.01)
                n += 1
    return total / max(n, 1)


def grid_difference(a, b):
    """Largest relative difference between two block-mean grids."""
    worst = 0.0
    for ra, rb in zip(a, b):
        for x, y in zip(ra, rb):
            worst = max(worst, abs(x - y) / max(abs(y), 1e-6))
    return worst


def check_agreement(rpict_px, reference_px, rpict_err, width, height, lambertian_note):
    """Units and orientation: whole-image means and 4x4 block means of rpict against the
    reference, including the flipped and mirrored grids (which would fit better if an axis
    were reversed). Returns the list of problems found."""
    problems = []
    mean_r, mean_ref = rpict_err["mean"], rpict_err["reference_mean"]
    ratio = mean_r / mean_ref if mean_ref > 0 else float("inf")
    say(f"check: mean rpict {mean_r:.6f}, reference {mean_ref:.6f}: ratio {ratio:.4f}")
    if abs(ratio - 1.0) > MEAN_TOLERANCE:
        problems.append(f"mean of rpict's image {mean_r:.6f} vs reference {mean_ref:.6f} (x{ratio:.3f}){lambertian_note}")
    grid = block_means(rpict_px, width, height)
    ref_grid = block_means(reference_px, width, height)
    as_is = grid_difference(grid, ref_grid)
    flipped = grid_difference(grid[::-1], ref_grid)
    mirrored = grid_difference([row[::-1] for row in grid], ref_grid)
    say(f"check: 4x4 block means differ by at most {100 * as_is:.1f}% (flipped {100 * flipped:.1f}%, mirrored {100 * mirrored:.1f}%)")
    if as_is > BLOCK_TOLERANCE:
        problems.append(f"4x4 block means differ by up to {100 * as_is:.0f}%")
    if min(flipped, mirrored) < 0.5 * as_is:
        problems.append("the image fits the reference better flipped or mirrored: orientation differs")
    return problems


def reference_image(args, icrender, out_dir, scene_args):
    if args.reference:
        ref = Path(args.reference)
        if not ref.exists():
            sys.exit(f"vs_radiance: {ref}: no such reference")
        return ref, "given"
    tag = f"spp{args.ref_spp}_ls{args.ref_light_samples}"
    ref = out_dir / f"reference_{tag}.exr"
    if ref.exists():
        return ref, "reused from an earlier run"
    common = scene_args + ["-x", args.x, "-y", args.y, "-ab", args.ab, "--no-preview"]
    cmd = [icrender, "reference", *common, "-o", ref, "--max-seconds", args.ref_seconds, "--spp", args.ref_spp]
    cmd += ["--light-samples", args.ref_light_samples]
    result, wall, _ = run(cmd, check=False)
    if result.returncode == 0 and ref.exists():
        return ref, f"icrender reference, {wall:.0f} s"
    say(f"`icrender reference` failed ({result.returncode}): {result.stderr.strip().splitlines()[-1:]}")
    say("falling back to a brute-force render: -aa 0 -ad 4096 --spp 16 --light-samples 16")
    cmd = [icrender, "render", *common, "-o", ref, "-aa", "0", "-ad", "4096", "--spp", "16", "--light-samples", "16", "-q", "--overwrite"]
    _, wall, _ = run(cmd)
    return ref, f"FALLBACK brute force (icrender render -aa 0 -ad 4096 --spp 16 --light-samples 16), {wall:.0f} s"


def icrender_run(args, icrender, scene_args, ambient, out_dir, ref, threads, pin=False, tag_suffix=""):
    """One icrender render, timed as a whole process like rpict (the error is measured after it,
    with `icrender compare`, as for rpict). `pin`: on one core only (taskset -c 0), so nothing of
    the process runs beside the render, not even the image library's background loading."""
    tag = (f"icrender_t{threads}{'_pinned' if pin else ''}" if threads else "icrender") + tag_suffix
    exr, stats_path = out_dir / f"{tag}.exr", out_dir / f"{tag}.json"
    for stale in (exr, stats_path):  # icrender never replaces an existing output (no --overwrite here)
        stale.unlink(missing_ok=True)
    cmd = [icrender, "render", *scene_args, "-o", exr, "-x", args.x, "-y", args.y, *ambient, "--overwrite"]
    cmd += ["--stats", stats_path, "--no-preview", "-q", *shlex.split(args.ic_args)]
    if threads:
        cmd += ["--threads", threads]
    if pin:
        cmd = ["taskset", "-c", "0", *cmd]
    result, wall, cpu = run(cmd)
    stats = json.loads(stats_path.read_text())
    error = compare(icrender, exr, ref)
    return {
        "renderer": "icrender",
        "threads": f"{stats.get('threads', threads)}{' pinned' if pin else ''}",
        "wall": wall,
        "work": stats.get("wall_s", wall),
        "cpu": cpu,
        "render": stats.get("render_s"),
        "records": stats.get("records_computed"),
        "rmse": error["rmse"],
        "relmse": error["rel_mse"],
        "exr": exr,
    }


def ladder_settings(args):
    """-ad from the given one down by halves (four steps), -as scaled alike: the settings both
    renderers are run at for the comparison at equal error; -ab -aa -ar stay as given."""
    steps = []
    for k in range(4):
        ad = max(args.ad >> k, 16)
        as_ = max(args.as_ >> k, 0)
        if (ad, as_) not in steps:
            steps.append((ad, as_))
    return steps


# Shadow rays a pixel icrender is also tried with at equal error (besides its default, 16).
FEWER_LIGHT_SAMPLES = 8


def icrender_ladder(args):
    """icrender's settings for the comparison at equal error: rpict's ladder plus an -ad halfway
    between its two cheapest steps, each with the default shadow rays and with
    FEWER_LIGHT_SAMPLES (an icrender knob: rpict's direct light has no sampling noise to trade).
    Items: (-ad, -as, --light-samples or None for the default)."""
    ads = ladder_settings(args)
    if len(ads) >= 2:
        (a1, s1), (a0, s0) = ads[-2], ads[-1]
        middle = ((a0 + a1) // 2, (s0 + s1) // 2)
        if middle not in ads:
            ads.insert(len(ads) - 1, middle)
    return [(ad, as_, ls) for ad, as_ in ads for ls in (None, FEWER_LIGHT_SAMPLES)]


def equal_error(args, icrender, scene_args, out_dir, ref, ref_px, rpict_base, octree, bin_dir, rad_env):
    """Both renderers at each ladder setting: icrender on one core and on every core, rpict (one
    process); for every rpict run, the cheapest icrender run whose relMSE, RMSE and 4x4 relMSE
    are all at most rpict's, and the ratio of the times: process CPU on one core, process wall
    on every core. Printed for each rpict run: at rpict's defaults (-ad 512 -as 128, the first
    step by default) and at its cheaper settings, where the fixed cost of a process weighs more."""
    w, h = args.x, args.y
    runs = []
    pin = shutil.which("taskset") is not None
    for ad, as_, ls in icrender_ladder(args):
        # -ar's floor alone (no view floor), as rpict has it.
        options = ["-ab", args.ab, "-aa", args.aa, "-ad", ad, "-as", as_, "-ar", args.ar, "--ic-min-pixels", "0"]
        options += ["--light-samples", ls] if ls else []
        for threads, pinned in ((1, pin), (0, False)):
            # Same seed, same image: repeats differ in time only; the fastest is kept (the machine
            # is shared, and slowed down runs say nothing about either renderer).
            tries = [icrender_run(args, icrender, scene_args, options, out_dir, ref, threads, pin=pinned,
                                  tag_suffix=f"_ad{ad}" + (f"_ls{ls}" if ls else "")) for _ in range(max(args.repeat, 1))]
            r = dict(tries[-1], cpu=min(t["cpu"] for t in tries), wall=min(t["wall"] for t in tries))
            r["relmse4"] = block_relmse(pixels(r["exr"], w, h, bin_dir, rad_env, out_dir), ref_px, w, h)
            r["ad"], r["as"], r["ls"], r["cores"] = ad, as_, ls or "", "one" if threads == 1 else "all"
            runs.append(r)
    for ad, as_ in ladder_settings(args):
        ambient = ["-ab", args.ab, "-aa", args.aa, "-ad", ad, "-as", as_, "-ar", args.ar]
        hdr, exr = out_dir / f"rpict_ad{ad}.hdr", out_dir / f"rpict_ad{ad}.exr"
        times = []
        for _ in range(max(args.repeat, 1)):  # -pj 0: every repeat makes the same picture
            with open(hdr, "wb") as f:
                _, wall, cpu = run(rpict_base + [*ambient, *shlex.split(args.rpict_args), octree], env=rad_env,
                                   stdout=f)
            times.append((wall, cpu))
        wall, cpu = min(t[0] for t in times), min(t[1] for t in times)
        run(["oiiotool", hdr, "-o", exr], quiet=True)
        e = compare(icrender, exr, ref)
        runs.append({"renderer": "rpict", "cores": "one", "ad": ad, "as": as_, "ls": "", "cpu": cpu, "wall": wall,
                     "rmse": e["rmse"],
                     "relmse": e["rel_mse"],
                     "relmse4": block_relmse(pixels(hdr, w, h, bin_dir, rad_env, out_dir), ref_px, w, h), "exr": exr})
    print()
    print("At equal error (icrender on one core: pinned with taskset, process CPU; on every core: "
          "process wall; rpict: one process):")
    header = (f"{'renderer':<9} {'cores':>5} {'-ad':>5} {'-as':>5} {'ls':>3} {'cpu s':>7} {'wall s':>7} "
              f"{'relMSE':>10} {'RMSE':>10} {'relMSE4x4':>10}")
    print(header)
    print("-" * len(header))
    for r in runs:
        print(f"{r['renderer']:<9} {r['cores']:>5} {r['ad']:>5} {r['as']:>5} {r['ls']:>3} {r['cpu']:>7.3f} {r['wall']:>7.3f} "
              f"{r['relmse']:>10.3e} {r['rmse']:>10.3e} {r['relmse4']:>10.3e}")
    metrics = ("relmse", "rmse", "relmse4")
    verdicts = []
    for cores, clock in (("one", "cpu"), ("all", "wall")):
        ic = [r for r in runs if r["renderer"] == "icrender" and r["cores"] == cores]
        for rp in (r for r in runs if r["renderer"] == "rpict"):
            good = [r for r in ic if all(r[m] <= rp[m] for m in metrics)]
            if not good:
                print(f"{cores} core(s): rpict -ad {rp['ad']}: no icrender run of the ladder reaches its error")
                verdicts.append({"cores": cores, "rpict_ad": rp["ad"], "icrender_ad": None, "ratio": None})
                continue
            best = min(good, key=lambda r: r[clock])
            ratio = rp[clock] / best[clock]
            shadow = f" --light-samples {best['ls']}" if best["ls"] else ""
            print(f"{cores} core(s), process {clock}: rpict -ad {rp['ad']} ({rp[clock]:.2f} s): icrender -ad "
                  f"{best['ad']}{shadow} reaches its error in {best[clock]:.2f} s: {ratio:.1f}x faster")
            verdicts.append({"cores": cores, "rpict_ad": rp["ad"], "icrender_ad": best["ad"],
                             "icrender_light_samples": best["ls"] or None, "ratio": ratio})
    return {"runs": [{k: (str(v) if isinstance(v, Path) else v) for k, v in r.items()} for r in runs],
            "verdicts": verdicts}


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], allow_abbrev=False)
    parser.add_argument("--scene", default=str(DEFAULT_SCENE))
    parser.add_argument("-x", type=int, default=256)
    parser.add_argument("-y", type=int, default=256)
    parser.add_argument("-ab", type=int, default=1)
    parser.add_argument("-aa", type=float, default=0.2)
    parser.add_argument("-ad", type=int, default=512)
    parser.add_argument("-as", dest="as_", type=int, default=128)
    parser.add_argument("-ar", type=int, default=64)
    parser.add_argument("--reference", help="converged reference EXR (default: made, then reused)")
    parser.add_argument("--ref-seconds", type=float, default=300, help="time limit of `icrender reference`")
    parser.add_argument(
        "--ref-spp",
        type=int,
        default=1,
        help="pixel samples per reference pass: 1 traces every pass through the pixel centres (where both "
        "renderers sample at 1 spp here), more integrates each pixel's area (then edges count as error)",
    )
    parser.add_argument(
        "--ref-light-samples",
        type=int,
        default=16,
        help="shadow rays per eye-path point in the reference: cheap next to its brute-force indirect light, "
        "and what keeps many-emitter scenes' direct light from dominating its noise",
    )
    parser.add_argument("--lambertian", action="store_true", help="every material Lambertian, in both renderers")
    parser.add_argument("--ic-args", default="", help="extra options for `icrender render`, e.g. '--spp 4'")
    parser.add_argument("--rpict-args", default="", help="extra options for rpict")
    parser.add_argument(
        "--rpict-adaptive",
        action="store_true",
        help="let rpict use its own pixel sampling (-ps 4 -pj 0.67) instead of one centred ray per pixel",
    )
    parser.add_argument("--out", help="output folder (default target/vs_radiance/<scene>_<x>x<y>)")
    parser.add_argument("--no-build", action="store_true", help="use target/release/icrender as it is")
    parser.add_argument("--repeat", type=int, default=1,
                        help="with --equal-error: run every setting this many times (at least once), keeping "
                             "the fastest")
    parser.add_argument("--equal-error", action="store_true",
                        help="also run both renderers at -ad halved three times (-as alike), icrender on one "
                             "core and on every core, and compare the time each needs for the same error")
    args = parser.parse_args()

    scene = Path(args.scene)
    scene = (scene if scene.is_absolute() else ROOT / scene).resolve()
    if not scene.exists():
        sys.exit(f"vs_radiance: {scene}: no such scene")
    suffix = "_lambertian" if args.lambertian else ""
    out_dir = Path(args.out) if args.out else ROOT / "target" / "vs_radiance" / f"{scene.stem}_{args.x}x{args.y}_ab{args.ab}{suffix}"
    out_dir.mkdir(parents=True, exist_ok=True)
    bin_dir, rad_env = radiance_tools()
    if shutil.which("oiiotool") is None:
        sys.exit("vs_radiance: oiiotool not found (Debian: openimageio-tools)")

    if not args.no_build:
        run(["cargo", "build", "--release", "--manifest-path", ROOT / "Cargo.toml"])
    icrender = ROOT / "target" / "release" / "icrender"
    scene_args = [scene] + (["--lambertian"] if args.lambertian else [])
    ambient = ["-ab", args.ab, "-aa", args.aa, "-ad", args.ad, "-as", args.as_, "-ar", args.ar]

    ref, ref_origin = reference_image(args, icrender, out_dir, scene_args)
    ref_stats = exr_attribute(ref, "icrender/statistics")
    if ref_stats:
        try:
            ref_stats = json.loads(ref_stats.replace('\\"', '"'))
            if ref_stats.get("reference_noise") is not None:
                ref_origin += f", {ref_stats.get('spp')} spp, estimated noise {100 * ref_stats['reference_noise']:.2f}%"
        except json.JSONDecodeError:
            pass
    say(f"reference: {ref} ({ref_origin})")

    rows = [icrender_run(args, icrender, scene_args, ambient, out_dir, ref, None)]
    rows.append(icrender_run(args, icrender, scene_args, ambient, out_dir, ref, 1))
    if shutil.which("taskset"):
        rows.append(icrender_run(args, icrender, scene_args, ambient, out_dir, ref, 1, pin=True))

    # The view icrender used, as Radiance options; the reference must have used the same one.
    view = exr_attribute(rows[0]["exr"], "icrender/view")
    if not view:
        sys.exit(f"vs_radiance: {rows[0]['exr']} has no icrender/view attribute")
    ref_view = exr_attribute(ref, "icrender/view")
    if ref_view and ref_view != view:
        loud(f"the reference was rendered with another view:\n  reference {ref_view}\n  render    {view}")

    rad, octree, amb = out_dir / "scene.rad", out_dir / "scene.oct", out_dir / "rpict.amb"
    hdr, rp_exr = out_dir / "rpict.hdr", out_dir / "rpict.exr"
    rad.unlink(missing_ok=True)
    export_cmd = [icrender, "export", scene, "-o", rad] + (["--lambertian"] if args.lambertian else [])
    _, export_wall, _ = run(export_cmd)
    with open(octree, "wb") as f:
        _, oconv_wall, _ = run([bin_dir / "oconv", rad], env=rad_env, stdout=f)
    cube = run([bin_dir / "getinfo", "-d", octree], env=rad_env, quiet=True)[0].stdout.split()
    for stale in (amb, hdr):
        stale.unlink(missing_ok=True)
    # Pixel sampling: icrender at 1 spp traces one ray through each pixel's centre. rpict by
    # default traces every 4th pixel (-ps 4), interpolates the rest where they differ by less
    # than -pt, and jitters the ray in the pixel (-pj 0.67). Like for like is -ps 1 -pj 0: one
    # centred ray per pixel in both, so the same pixels see the same points and the time and
    # error are those of the same work. (--rpict-adaptive shows rpict as users run it.)
    # -pa 0 keeps -x -y exactly; the view's -vh -vv already give square pixels.
    pixel = [] if args.rpict_adaptive else ["-ps", "1", "-pj", "0"]
    rpict_base = [bin_dir / "rpict", "-x", args.x, "-y", args.y, "-pa", "0", *pixel, *shlex.split(view)]
    rpict = rpict_base + [*ambient, "-af", amb, *shlex.split(args.rpict_args), octree]
    with open(hdr, "wb") as f:
        _, rp_wall, rp_cpu = run(rpict, env=rad_env, stdout=f)
    lookamb = run([bin_dir / "lookamb", "-h", "-d", amb], env=rad_env, quiet=True)[0].stdout
    records = sum(1 for line in lookamb.splitlines() if line.strip())
    # The same without indirect light (-ab 0): separates the light sources' units and sides
    # (emission + direct) from the indirect light in the agreement check. Cheap.
    hdr0 = out_dir / "rpict_ab0.hdr"
    rpict0 = [str(c) for c in rpict]
    rpict0[rpict0.index("-ab") + 1] = "0"
    rpict0 = [c for c in rpict0 if c not in ("-af", str(amb))]
    with open(hdr0, "wb") as f:
        run(rpict0, env=rad_env, stdout=f)
    run(["oiiotool", hdr, "-o", rp_exr], quiet=True)
    channels = exr_channels(rp_exr)
    if channels[:3] != ["R", "G", "B"]:
        sys.exit(f"vs_radiance: {rp_exr}: channels {channels}, expected R, G, B")
    rp_err = compare(icrender, rp_exr, ref)
    rows.append(
        {
            "renderer": "rpict",
            "threads": 1,
            "wall": rp_wall,
            "work": rp_wall,
            "cpu": rp_cpu,
            "render": None,
            "records": records,
            "rmse": rp_err["rmse"],
            "relmse": rp_err["rel_mse"],
            "exr": rp_exr,
        }
    )

    # Units and orientation, before trusting any number.
    w, h = args.x, args.y
    ref_px = pixels(ref, w, h, bin_dir, rad_env, out_dir)
    rp_px = pixels(hdr, w, h, bin_dir, rad_env, out_dir)
    note = "" if args.lambertian else " (not --lambertian: material approximations may explain part)"
    problems = check_agreement(rp_px, ref_px, rp_err, w, h, note)
    ref_layers = {e["layer"]: e["reference_mean"] for e in json.loads(run([icrender, "compare", ref, ref, "--json"], quiet=True)[0].stdout)}
    rp0_exr = out_dir / "rpict_ab0.exr"
    run(["oiiotool", hdr0, "-o", rp0_exr], quiet=True)
    rp0_mean = compare(icrender, rp0_exr, ref)["mean"]
    ref_direct = ref_layers.get("emission", 0.0) + ref_layers.get("direct", 0.0)
    if ref_direct > 0:
        ratio0 = rp0_mean / ref_direct
        say(f"check: emission + direct (rpict -ab 0) mean {rp0_mean:.6f}, reference's layers {ref_direct:.6f}: ratio {ratio0:.4f}")
        if abs(ratio0 - 1.0) > MEAN_TOLERANCE:
            problems.append(f"light sources: rpict -ab 0 mean {rp0_mean:.6f} vs reference emission + direct {ref_direct:.6f} (x{ratio0:.3f})")
    indirect = {"reference": ref_layers.get("indirect"), "rpict (-ab N minus -ab 0)": rp_err["mean"] - rp0_mean}
    for row in rows:
        px = rp_px if row["renderer"] == "rpict" else pixels(row["exr"], w, h, bin_dir, rad_env, out_dir)
        row["relmse4"] = block_relmse(px, ref_px, w, h)
        row["mean"] = compare(icrender, row["exr"], ref)["mean"]
    for r, tag in ((rows[0], "icrender"), (rows[1], "icrender 1 thread")):
        layers = json.loads(run([icrender, "compare", r["exr"], ref, "--json"], quiet=True)[0].stdout)
        indirect[tag] = next((e["mean"] for e in layers if e["layer"] == "indirect"), None)
    if indirect["reference"]:
        say("check: mean indirect light: " + ", ".join(
            f"{k} {v:.6f} (x{v / indirect['reference']:.3f})" for k, v in indirect.items() if v is not None))
    ic_ratio = rows[0]["mean"] / max(rp_err["reference_mean"], 1e-30)
    if abs(ic_ratio - 1.0) > MEAN_TOLERANCE:
        problems.append(f"icrender's own mean {rows[0]['mean']:.6f} vs reference {rp_err['reference_mean']:.6f}")
    for p in problems:
        loud(p)

    # The table.
    ic_size = None
    info = run([icrender, "info", scene, "--json"], check=False, quiet=True)[0]
    if info.returncode == 0:
        try:
            data = json.loads(info.stdout)
            ic_size = data.get("bounds", {}).get("size")
        except json.JSONDecodeError:
            pass
    print()
    print(f"scene {scene.name}, {w}x{h}, -ab {args.ab} -aa {args.aa} -ad {args.ad} -as {args.as_} -ar {args.ar}"
          f"{' --lambertian' if args.lambertian else ''}; rpict {' '.join(pixel) or '(adaptive sampling)'} {args.rpict_args}")
    print(f"reference {ref} ({ref_origin}), mean {rp_err['reference_mean']:.6f}")
    print(f"export {export_wall:.2f} s, oconv {oconv_wall:.2f} s (not in the times below)")
    if cube and ic_size:
        # Both take the smallest record radius as scene size / -ar, but Radiance's scene size is
        # the octree cube (getinfo -d), icrender's the bounding box diagonal.
        print(f"scene size for -ar: Radiance octree cube {float(cube[-1]):.4g}, icrender bounding-box diagonal "
              f"{ic_size:.4g}: at the same -ar icrender's smallest record radius is x{ic_size / float(cube[-1]):.2f}")
    print()
    header = (f"{'renderer':<10} {'threads':>7} {'wall s':>8} {'work s':>8} {'cpu s':>8} {'render s':>9} {'records':>8} "
              f"{'relMSE':>10} {'RMSE':>10} {'relMSE4x4':>10} {'mean':>9}")
    print(header)
    print("-" * len(header))
    for r in rows:
        render = f"{r['render']:.3f}" if r["render"] is not None else "-"
        print(
            f"{r['renderer']:<10} {r['threads']:>7} {r['wall']:>8.3f} {r['work']:>8.3f} {r['cpu']:>8.3f} {render:>9} {r['records']:>8} "
            f"{r['relmse']:>10.3e} {r['rmse']:>10.3e} {r['relmse4']:>10.3e} {r['mean']:>9.5f}"
        )
    print()
    rp = rows[-1]
    for r in rows[:-1]:
        print(
            f"icrender/rpict ({r['threads']} thread(s) vs 1): "
            f"time (work) x{r['work'] / rp['work']:.3f}, (process wall) x{r['wall'] / rp['wall']:.3f}, "
            f"(process cpu) x{r['cpu'] / rp['cpu']:.3f}, relMSE x{r['relmse'] / rp['relmse']:.3f}, "
            f"RMSE x{r['rmse'] / rp['rmse']:.3f}, relMSE4x4 x{r['relmse4'] / rp['relmse4']:.3f}, "
            f"records x{r['records'] / max(rp['records'], 1):.3f}"
        )
    if problems:
        print(f"\n{len(problems)} agreement problem(s): see the warnings above; the ratios are not to be trusted.")
    summary = {"scene": str(scene), "width": w, "height": h, "reference": str(ref), "reference_origin": ref_origin,
               "rows": [{k: (str(v) if isinstance(v, Path) else v) for k, v in r.items()} for r in rows],
               "indirect_means": indirect, "problems": problems}
    if args.equal_error:
        summary["equal_error"] = equal_error(args, icrender, scene_args, out_dir, ref, ref_px, rpict_base, octree,
                                             bin_dir, rad_env)
    (out_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    say(f"files in {out_dir}")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
