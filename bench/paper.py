#!/usr/bin/env python3
"""The paper's evaluation (Debattista, Santos & Chalmers, EGPGV 2006, section 6), Radiance side by
side, and a cluster-scale prediction, in one command:

    python3 bench/paper.py            # small default (about 26 minutes on 2 idle cores)
    python3 bench/paper.py --full     # the paper's image sizes and more ranks (hours)
    python3 bench/paper.py --quick    # a check that it runs end to end (a minute or two; not a result)
    python3 bench/paper.py --records-sweep   # only the records sweep (issue 53): every mode at its
                                             # defaults, progressive, 3-8 processes, 128-512 pixels

For the Cornell box, the corridor and the conference room it
  1. renders (or reuses, from bench/out/paper/) a converged reference per scene and size;
  2. runs the serial renderer (with --trace-cache, the simulation's input) and noshare,
     centralised, broadcast and component modes under mpirun at each process count (--ranks; the
     master controller is one of the processes, as in the paper's "additional node"), in two
     settings side by side: the paper's (serial and traditional modes in scanline order,
     component mode at the default overture) and every mode at its default overture;
     component mode's gain and misses against the other modes with bootstrap intervals over
     the repeats, and a verdict of "within noise" where an interval contains 0;
  3. records each run's statistics and its error against the reference;
  4. exports each scene to Radiance, runs rpict with the same view and -ab -aa -ad -as -ar, and
     rtrace -n N with a shared ambient file at the same worker counts;
  5. simulates every mode from the serial trace (bench/icsim.py), prints the prediction error
     at the measured counts, predicts 4 .. 1024 processors on 1 Gbit and 100 Gbit networks, and
     checks the cluster test bed's measurements (bench/out/cluster-bench.csv) when present;
  6. writes CSVs and plots under bench/out/paper/ and docs/results/, and docs/RESULTS.md.

Times: this machine's cores are shared, so "aggregated time" is CPU time (T_amb + T_notamb
summed over the worker ranks, from --stats), and "speed-up" measured here is the work speed-up
P x T_serial / aggregated time (what P dedicated processors would reach without idle time); the
wall-clock speed-up is printed too but means little with more ranks than cores.
"""

import argparse
import datetime
import json
import multiprocessing
import os
import platform
import re
import shlex
import shutil
import statistics
import subprocess
import sys
import time
import zlib

import cluster_sim
import common
import icsim

HERE = os.path.dirname(os.path.abspath(__file__))
DOCS = os.path.join(common.ROOT, "docs")
MODES = ["noshare", "centralised", "broadcast", "component"]
# name: (scene path, -aa as in the paper: 0.1 for the Cornell box, 0.2 otherwise, full size)
SCENES = {
    "cornell": (os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"), 0.1, (512, 512)),
    "corridor": (os.path.join(common.ROOT, "scenes", "corridor.gltf"), 0.2, (512, 512)),
    "conference": (os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"), 0.2, (672, 512)),
}
# The default (small) image sizes. 256x256, the prediction's trace, where a run is short: the
# shorter a run, the noisier its CPU time on these shared cores (the corridor's at 128x128 spread
# by 30-40 % and its medians missed the simulation by up to 21 %; at 256x256 a run costs 2.5x
# the CPU for 1.4x the wall time, most of an mpirun being start-up). The conference room's runs
# are long enough at 128x128, and twice as slow at 256x256, which would take the bench past 30 minutes.
BENCH_SIZE = {"cornell": (256, 256), "corridor": (256, 256), "conference": (128, 128)}
# Radiance is slow on the conference room (minutes at 128x128): its side by side is smaller by default.
RADIANCE_SMALL = {"conference": (64, 64)}
MPI_ENV = dict(os.environ, OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1",
               OMPI_MCA_btl_tcp_if_include="lo", OMPI_MCA_oob_tcp_if_include="lo")


def say(msg):
    print(f"[paper] {msg}", flush=True)


def rel(path):
    return os.path.relpath(path, common.ROOT)


# -- runs ------------------------------------------------------------------------------------

def workers_cpu(stats):
    """Aggregated time of the worker ranks (the master controller excluded): T_amb + T_notamb."""
    ranks = [r for r in stats.get("per_rank", []) if r.get("role") != "mc"]
    if not ranks:
        return stats["t_amb_s"] + stats["t_notamb_s"]
    return sum(r["t_amb_s"] + r["t_notamb_s"] for r in ranks)


def workers_idle(stats):
    return sum(r.get("idle_s", 0.0) for r in stats.get("per_rank", []) if r.get("role") != "mc")


def composite_error(exr, ref):
    e = common.compare(exr, ref)
    return e.get("composite", (float("nan"), float("nan")))


def run_serial(scene, base, ref, work, trace=None, order=common.RASTER_ORDER):
    """One process, one thread; by default in scanline order like the paper's serial runs (and
    the traces the simulation replays); order=[]: the renderer's default overture."""
    out = os.path.join(work, "serial.exr")
    # RASTER_ORDER carries the progressive build; the default order needs it added.
    build = [] if "--ic-build" in order else common.PAPER_BUILD
    opts = base + ["--threads", "1"] + build + order + (["--trace-cache", trace] if trace else [])
    start = time.perf_counter()
    stats, _ = common.render(scene, out, opts)
    wall = time.perf_counter() - start
    rmse, relmse = composite_error(out, ref) if ref else (float("nan"), float("nan"))
    return {"mode": "serial", "processes": 1, "workers": 1, "misses": stats["records_computed"],
            "lookups": stats["lookups"], "t_amb_s": stats["t_amb_s"], "t_notamb_s": stats["t_notamb_s"],
            "aggregated_s": stats["t_amb_s"] + stats["t_notamb_s"], "idle_s": 0.0, "render_s": stats["render_s"],
            "wall_s": wall, "messages": 0, "bytes": 0, "rmse": rmse, "relmse": relmse}


def mode_overture(mode):
    """The --overture a mode runs with here, and bench/icsim.py models it with. The paper's
    setting: the serial run and the traditional modes compute in scanline order (0); component
    mode's PAs reorder their queues (the paper's section 6 credits the reordering for its fewer
    misses than the serial run; here, deliberately, the default grid's requests first)."""
    return common.DEFAULT_OVERTURE if mode == "component" else 0


def run_mpi(scene, mode, np, base, ref, work, timeout, overture=None):
    """One mpirun; `overture`: the --overture to run with (None: the paper's setting,
    `mode_overture`)."""
    overture = mode_overture(mode) if overture is None else overture
    out, stats_path = os.path.join(work, f"{mode}-{np}.exr"), os.path.join(work, f"{mode}-{np}.json")
    for p in (out, stats_path):
        if os.path.exists(p):
            os.remove(p)
    cmd = ["mpirun", "--oversubscribe", "-np", str(np), common.BINARY, "render", scene, "-o", out, "--mode", mode,
           "-q", "--no-preview", "--overwrite", "--stats", stats_path] + base + common.PAPER_BUILD + [
               "--overture", str(overture)]
    start = time.perf_counter()
    result = subprocess.run(cmd, capture_output=True, text=True, env=MPI_ENV, timeout=timeout)
    wall = time.perf_counter() - start
    if result.returncode != 0:
        lines = [l for l in result.stderr.splitlines() if l.strip()]
        raise RuntimeError(lines[-1] if lines else f"exit code {result.returncode}")
    with open(stats_path) as f:
        s = json.load(f)
    rmse, relmse = composite_error(out, ref)
    ranks = [r for r in s["per_rank"] if r.get("role") != "mc"]
    return {"mode": mode, "processes": np, "workers": np - 1, "misses": s["records_computed"], "lookups": s["lookups"],
            "t_amb_s": sum(r["t_amb_s"] for r in ranks), "t_notamb_s": sum(r["t_notamb_s"] for r in ranks),
            "aggregated_s": workers_cpu(s), "idle_s": workers_idle(s), "render_s": s["render_s"], "wall_s": wall,
            "messages": s["messages"], "bytes": s["bytes"], "rmse": rmse, "relmse": relmse,
            "requests_sent": s.get("requests_sent", 0), "requests_forwarded": s.get("requests_forwarded", 0),
            "request_handling_s": s.get("request_handling_s", 0.0),
            "tiles": sum(r.get("tiles", 0) for r in ranks), "overture": overture}


# A run's CPU time, and the parts it is made of, as taken from the fastest of its repeats.
CPU_FIELDS = ("aggregated_s", "t_amb_s", "t_notamb_s", "request_handling_s")


def mean_row(rows):
    """Repeated runs as one. CPU times are the fastest run's (its aggregated time and the parts
    of it, so they add up): on cores shared with other work, interference only ever adds CPU
    time (caches and the core's other hyperthread taken by another process, a core stolen by
    the host), so the fastest run is the closest to a processor of one's own, which is what the
    prediction is for; the same rule as Python's timeit. Everything else (misses, messages,
    idle and wall time, errors) is the median of the runs (robust to one run the machine
    disturbed); the rest from the first."""
    out = dict(rows[0])
    for k, v in rows[0].items():
        if isinstance(v, (int, float)) and k not in ("processes", "workers"):
            out[k] = statistics.median(r[k] for r in rows)
    fastest = min(rows, key=lambda r: r["aggregated_s"])
    for k in CPU_FIELDS:
        if k in fastest:
            out[k] = fastest[k]
    out["repeats"] = len(rows)
    out["aggregated_s_median"] = statistics.median(r["aggregated_s"] for r in rows)
    out["aggregated_s_max"] = max(r["aggregated_s"] for r in rows)
    return out


# -- comparisons with confidence intervals ----------------------------------------------------

# The two orders of computation compared side by side (the report's "settings"):
#   paper:   as the paper ran them: the serial run and the traditional modes in scanline order
#            (--overture 0), component mode at the renderer's default (`mode_overture`);
#   default: every mode at the renderer's default --overture (the serial run too), so that the
#            traditional modes order their work (the overture's grid first) as component mode does.
SETTINGS = ("paper", "default")
BOOTSTRAP = 4000  # resamples per interval
# Repeats of each configuration, both settings. The last 18-minute run of this bench (8 repeats,
# the paper's setting only) spent 6.6 minutes in mpirun and the serial runs, 4.6 of them in the
# traditional modes: 10 repeats of both settings come to about 14 minutes of runs, the whole
# bench to about 26. More repeats narrow the intervals of the verdicts (the spread between
# repeats reached 40 %, and with 8 the sign of a gain changed between runs of the bench).
REPEAT = 10
DEFAULT_REPEAT = 10
CONFIDENCE = 0.95


def _percentiles(values, confidence=CONFIDENCE):
    values = sorted(values)
    lo = values[int(round((1 - confidence) / 2 * (len(values) - 1)))]
    hi = values[int(round((1 + confidence) / 2 * (len(values) - 1)))]
    return lo, hi


def verdict(lo, hi, better, worse):
    """`better` when the whole interval is above zero, `worse` when below, else within noise
    (no interval, from a single repeat: "one run, no interval")."""
    if lo != lo or hi != hi:
        return "one run, no interval"
    if lo > 0:
        return better
    if hi < 0:
        return worse
    return "within noise"


def compare_component(reps, seed):
    """Component mode against the other modes at one scene, process count and setting, from
    every repeat of each (`reps`: mode -> list of runs). CPU time: the gain of component mode's
    work speed-up over the second-best mode's, each configuration's time from its fastest repeat
    as everywhere in this bench (the serial run cancels out: the gain is the second-best mode's
    aggregated time over component mode's, less one), and the same on the medians. Misses: how
    many fewer (negative) or more records component mode made than the mode with the fewest,
    on the medians. Each with a percentile bootstrap interval: every configuration's repeats
    resampled with replacement, the estimate (including which mode is second best) recomputed,
    BOOTSTRAP times. A verdict is "within noise" when its interval contains 0. None without
    component mode or another mode."""
    import random
    comp = reps.get("component") or []
    others = {m: rs for m, rs in reps.items() if m != "component" and rs}
    if not comp or not others:
        return None
    rng = random.Random(seed)

    def estimate(pick, field, comp_rows, other_rows):
        c = pick([r[field] for r in comp_rows])
        best_mode, best = min(((m, pick([r[field] for r in rows])) for m, rows in other_rows.items()),
                              key=lambda t: t[1])
        return c, best_mode, best

    def gain(comp_rows, other_rows, pick):
        c, m, b = estimate(pick, "aggregated_s", comp_rows, other_rows)
        return 100.0 * (b / c - 1.0), m

    def misses(comp_rows, other_rows):
        c, m, b = estimate(statistics.median, "misses", comp_rows, other_rows)
        return 100.0 * (c / b - 1.0), m, c, b

    g_min, second = gain(comp, others, min)
    g_med, second_med = gain(comp, others, statistics.median)
    m_pct, fewest, m_comp, m_best = misses(comp, others)
    boot_min, boot_med, boot_mis = [], [], []
    single = len(comp) < 2 or any(len(rs) < 2 for rs in others.values())
    for _ in range(0 if single else BOOTSTRAP):
        c = [rng.choice(comp) for _ in comp]
        o = {m: [rng.choice(rs) for _ in rs] for m, rs in others.items()}
        boot_min.append(gain(c, o, min)[0])
        boot_med.append(gain(c, o, statistics.median)[0])
        boot_mis.append(misses(c, o)[0])
    nan = (float("nan"), float("nan"))
    lo, hi = _percentiles(boot_min) if boot_min else nan
    lo_med, hi_med = _percentiles(boot_med) if boot_med else nan
    lo_mis, hi_mis = _percentiles(boot_mis) if boot_mis else nan
    return {"second_mode": second, "gain_pct": g_min, "gain_lo": lo, "gain_hi": hi,
            "gain_verdict": verdict(lo, hi, "faster", "slower"),
            "second_mode_median": second_med, "gain_median_pct": g_med, "gain_median_lo": lo_med,
            "gain_median_hi": hi_med, "gain_median_verdict": verdict(lo_med, hi_med, "faster", "slower"),
            "component_misses": m_comp, "fewest_mode": fewest, "fewest_misses": m_best, "misses_pct": m_pct,
            "misses_lo": lo_mis, "misses_hi": hi_mis,
            # Fewer misses is better: the interval is of component's excess.
            "misses_verdict": verdict(-hi_mis, -lo_mis, "fewer", "more"),
            "component_repeats": len(comp), "other_repeats": min(len(rs) for rs in others.values()),
            # The verdict the report states: both estimators' when they agree, else within noise
            # (the fastest repeat's interval can only reach down to the fastest run seen, so it
            # is narrower than the truth on one side; the medians' is the more conservative).
            "verdict": (verdict(lo, hi, "faster", "slower")
                        if verdict(lo, hi, "faster", "slower") == verdict(lo_med, hi_med, "faster", "slower")
                        else "within noise")}


def spread_pct(rows):
    """How far a configuration's repeats spread: slowest over fastest aggregated time, less one."""
    times = [r["aggregated_s"] for r in rows]
    return 100.0 * (max(times) / min(times) - 1.0) if times and min(times) > 0 else float("nan")


# -- Radiance -----------------------------------------------------------------------------

def exr_view(exr):
    out = subprocess.run(["oiiotool", "--info", "-v", exr], capture_output=True, text=True, check=True).stdout
    m = re.search(r'^\s*icrender/view:\s*"(.*)"\s*$', out, re.M)
    return m.group(1) if m else None


def radiance(scene_name, scene, size, ambient, view, ref, ranks, work):
    """rpict on one core, then rtrace -n N with a shared ambient file: rows of time, records, error."""
    import vs_radiance  # the bench beside this one: pyradiance's binaries and environment
    bin_dir, env = vs_radiance.radiance_tools()
    rad, octree = os.path.join(work, "scene.rad"), os.path.join(work, "scene.oct")
    for p in (rad, octree):
        if os.path.exists(p):
            os.remove(p)
    subprocess.run([common.BINARY, "export", scene, "-o", rad], check=True, capture_output=True)
    with open(octree, "wb") as f:
        subprocess.run([os.path.join(bin_dir, "oconv"), rad], stdout=f, env=env, check=True)
    w, h = size
    amb_opts = ["-ab", "1", "-aa", str(ambient["aa"]), "-ad", str(ambient["ad"]), "-as", str(ambient["as"]),
                "-ar", str(ambient["ar"])]
    version = subprocess.run([os.path.join(bin_dir, "rpict"), "-version"], capture_output=True, text=True, env=env)
    rows = []

    def records(amb):
        out = subprocess.run([os.path.join(bin_dir, "lookamb"), "-h", "-d", amb], capture_output=True, text=True,
                             env=env).stdout
        return sum(1 for line in out.splitlines() if line.strip())

    def finish(label, procs, hdr, amb, wall, cpu):
        exr = hdr[:-4] + ".exr"
        subprocess.run(["oiiotool", hdr, "-o", exr], check=True, capture_output=True)
        rmse, relmse = composite_error(exr, ref)
        rows.append({"scene": scene_name, "renderer": label, "processes": procs, "wall_s": wall, "cpu_s": cpu,
                     "records": records(amb), "rmse": rmse, "relmse": relmse})
        say(f"{scene_name:>10} {label:<14} {procs} proc: {wall:6.2f} s wall, {cpu:6.2f} s CPU, "
            f"{rows[-1]['records']} records, relMSE {relmse:.3e}")

    # rpict, one process: one centred ray per pixel (-ps 1 -pj 0) as icrender at 1 spp.
    hdr, amb = os.path.join(work, "rpict.hdr"), os.path.join(work, "rpict.amb")
    for p in (hdr, amb):
        if os.path.exists(p):
            os.remove(p)
    cmd = [os.path.join(bin_dir, "rpict"), "-x", str(w), "-y", str(h), "-pa", "0", "-ps", "1", "-pj", "0",
           *shlex.split(view), *amb_opts, "-af", amb, octree]
    wall, cpu = timed(cmd, hdr, env)
    finish("rpict", 1, hdr, amb, wall, cpu)
    # The same without indirect light (-ab 0): what rpict spends on everything else, which splits
    # its time into a cost per pixel and a cost per record (the prediction's `1gbit-rpict`).
    hdr0 = os.path.join(work, "rpict-ab0.hdr")
    cmd0 = [os.path.join(bin_dir, "rpict"), "-x", str(w), "-y", str(h), "-pa", "0", "-ps", "1", "-pj", "0",
            *shlex.split(view), "-ab", "0", octree]
    _, rows[-1]["cpu_ab0_s"] = timed(cmd0, hdr0, env)
    # rtrace -n N: Radiance's own multi-process rendering, sharing one ambient file.
    vw = [os.path.join(bin_dir, "vwrays"), "-ff", "-x", str(w), "-y", str(h), "-pa", "0", "-pj", "0",
          *shlex.split(view)]
    for n in ranks:
        hdr, amb = os.path.join(work, f"rtrace-{n}.hdr"), os.path.join(work, f"rtrace-{n}.amb")
        for p in (hdr, amb):
            if os.path.exists(p):
                os.remove(p)
        rays = subprocess.run(vw, capture_output=True, env=env, check=True).stdout
        dims = subprocess.run(vw[:1] + ["-d"] + vw[1:], capture_output=True, text=True, env=env,
                              check=True).stdout.split()
        cmd = [os.path.join(bin_dir, "rtrace"), "-n", str(n), "-ffc", *dims, *amb_opts, "-af", amb, octree]
        wall, cpu = timed(cmd, hdr, env, stdin=rays)
        finish("rtrace -n", n, hdr, amb, wall, cpu)
    return rows, (version.stdout or version.stderr).strip()


def timed(cmd, out_path, env, stdin=None):
    import resource
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    with open(out_path, "wb") as f:
        subprocess.run(cmd, stdout=f, stderr=subprocess.PIPE, input=stdin, env=env, check=True)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


# -- simulation ----------------------------------------------------------------------------

def sim_costs(serial, pixels):
    """Per-record and per-pixel costs measured from the scene's serial runs (CPU seconds)."""
    record = serial["t_amb_s"] / max(serial["misses"], 1)
    pixel = serial["t_notamb_s"] / pixels
    return icsim.Costs(record=record, pixel=pixel, message=20e-6)


def rpict_costs(row, pixels):
    """rpict's CPU seconds per record and per pixel on this machine, from its run with indirect
    light (-ab 1, records counted in its ambient file) and without (-ab 0): per pixel the
    latter over the pixels, per record the difference over the records. None when unknown."""
    if not row.get("records") or row.get("cpu_ab0_s") is None or row["cpu_s"] <= row["cpu_ab0_s"]:
        return None
    return (row["cpu_s"] - row["cpu_ab0_s"]) / row["records"], row["cpu_ab0_s"] / pixels


def mode_costs(runs, processes, pixels, serial):
    """Per-record and per-pixel CPU costs measured from the given runs of the traditional modes at
    one process count (on shared cores a record costs more CPU time with more processes about),
    or the serial runs' when there are none."""
    same = [r for r in runs if r["processes"] == processes and r["mode"] in ("noshare", "centralised", "broadcast")]
    if not same:
        return sim_costs(serial, pixels), "the serial runs"
    record = sum(r["t_amb_s"] for r in same) / max(sum(r["misses"] for r in same), 1)
    pixel = sum(r["t_notamb_s"] for r in same) / (pixels * len(same))
    return icsim.Costs(record=record, pixel=pixel, message=20e-6), \
        f"{'/'.join(r['mode'] for r in same)} at {processes} processes"


def timed_request_cost(comp_runs):
    """CPU seconds per component-mode request as the renderer times them (a PR encoding and
    queueing its batches, a PA decoding and queueing them; the messages that carry them are
    charged as messages by the simulation), over the given runs; None when not reported."""
    handled = sum(r.get("request_handling_s", 0.0) for r in comp_runs)
    requests = sum(r.get("requests_sent", 0) for r in comp_runs)
    return handled / requests if handled > 0 and requests else None


def request_cost(comp_runs, runs, serial, pixels):
    """CPU seconds per component-mode request: the component runs' aggregated time beyond their
    records and pixels (costed as the traditional modes' at the same count), per request."""
    extra, requests = 0.0, 0
    for r in comp_runs:
        c, _ = mode_costs(runs, r["processes"], pixels, serial)
        extra += r["aggregated_s"] - r["misses"] * c.record - pixels * c.pixel
        requests += r.get("requests_sent", 0)
    return max(extra, 0.0) / requests if requests else 0.0


def mode_factors(row, runs, pixels, serial):
    """How much more (or less) a record and a pixel cost in this traditional mode than in the
    other traditional modes at the same process count, from this mode's runs at the *other*
    counts (mean ratio). Each mode has overheads of its own that land in T_amb and T_notamb
    (broadcast's receiving thread, centralised's syncs, noshare's smaller cache): without this,
    the other modes' costs over-predicted noshare by 14-20 % and under-predicted broadcast by
    up to 19 % in every run of this bench, the signs never changing. None for component mode
    (its own costs are the request cost) or when the mode ran at one count only."""
    if row["mode"] not in ("noshare", "centralised", "broadcast"):
        return None
    records, pixel_ratios = [], []
    for r in runs:
        if r["mode"] != row["mode"] or r["processes"] == row["processes"]:
            continue
        others, _ = mode_costs([o for o in runs if o["mode"] != row["mode"]], r["processes"], pixels, serial)
        if others.record > 0 and others.pixel > 0:
            records.append(r["t_amb_s"] / max(r["misses"], 1) / others.record)
            pixel_ratios.append(r["t_notamb_s"] / pixels / others.pixel)
    if not records:
        return None
    return statistics.mean(records), statistics.mean(pixel_ratios)


def validation_costs(row, runs, serial, pixels):
    """Costs to simulate one measured run, measured from *other* runs of the same scene (leave one
    out): per record and pixel from the other traditional modes at the same process count times
    the mode's own factor from its runs at the other counts (`mode_factors`; the serial runs for
    the serial run), per request from the component runs at the other counts."""
    if row["mode"] == "serial":
        return sim_costs(serial, pixels), "the serial runs"
    others = [r for r in runs if r is not row and r["mode"] != row["mode"]]
    costs, how = mode_costs(others, row["processes"], pixels, serial)
    factors = mode_factors(row, runs, pixels, serial)
    if factors:
        costs.record *= factors[0]
        costs.pixel *= factors[1]
        how += (f", x{factors[0]:.2f} per record and x{factors[1]:.2f} per pixel for {row['mode']} "
                f"(its own runs at other counts against the other modes there)")
    if row["mode"] == "component":
        comp = [r for r in runs if r["mode"] == "component" and r["processes"] != row["processes"]]
        timed = timed_request_cost(comp)
        if comp and timed is not None:
            # Its own factor needs simulations of those runs (`component_calibration`): main() applies it.
            costs.request_pr = costs.request_pa = timed / 2
            how += "; requests as the code timed them in component's runs at the other counts"
        else:
            req = request_cost(comp or [row], runs, serial, pixels)
            how += ("; requests from component's runs at other counts (their residual)" if comp
                    else "; requests from this run (calibration: its time is fitted)")
            costs.request_pr = costs.request_pa = req / 2
    return costs, how


def component_calibration(row, costs, runs, serial, pixels):
    """What component mode's own factor for `row` is measured from: its runs at the other counts,
    each with the other modes' costs there and `row`'s request cost (as the code timed it in
    those runs). Component mode has overheads and savings of its own, like each traditional mode
    (`mode_factors`): its PAs' communicator threads cost; a PA's processor caches hold only the
    indirect light's work, which the paper credits for part of its gain. Its factor is the
    measured CPU time of those runs over their simulated time at these costs (mean ratio):
    unlike the traditional modes' it is taken against the simulation, because its requests and
    messages are charged there, not in T_amb and T_notamb. Without it (the residual cost per
    request clamped at zero), component mode came out 4-12 % too slow in most runs of the bench."""
    out = []
    for r in runs:
        if r["mode"] != "component" or r["processes"] == row["processes"]:
            continue
        c, _ = mode_costs([o for o in runs if o["mode"] != "component"], r["processes"], pixels, serial)
        c.request_pr, c.request_pa = costs.request_pr, costs.request_pa
        out.append((r, c))
    return out


def scaled(costs, factor):
    return icsim.Costs(record=costs.record * factor, pixel=costs.pixel * factor, hit=costs.hit * factor,
                       message=costs.message * factor, request_pr=costs.request_pr * factor,
                       request_pa=costs.request_pa * factor)


def pct(pred, real):
    return 100.0 * (pred - real) / real if real else float("nan")


# -- the records sweep (issue 53, part 3) ------------------------------------------------------

# Every mode at its defaults with the cache built as the tiles render (the paper's way), over
# these process counts (master included; oversubscribed on this machine), square image sizes
# and the three scenes: component mode should make the fewest records in every configuration.
SWEEP_RANKS = (3, 4, 5, 8)
SWEEP_SIZES = (128, 256, 512)
SWEEP_REPEAT = 5
# The setting the gap was found in (issue 53: -ab 1 -aa 0.2 on the Cornell box), for every scene.
SWEEP_AA = 0.2


def run_records(scene, mode, np, size, seed, ad, work, timeout):
    """One mpirun of `mode` at its defaults (tiles, --sync, --send, --pa, edge samples) in
    progressive mode: its records and CPU time."""
    out, stats_path = os.path.join(work, f"sweep-{mode}-{np}.exr"), os.path.join(work, f"sweep-{mode}-{np}.json")
    cmd = ["mpirun", "--oversubscribe", "-np", str(np), common.BINARY, "render", scene, "-o", out, "--mode", mode,
           "-q", "--no-preview", "--overwrite", "--stats", stats_path, "-x", str(size), "-y", str(size), "-ab", "1",
           "-aa", str(SWEEP_AA), "-ad", str(ad), "--ic-build", "progressive", "--seed", str(seed)]
    result = subprocess.run(cmd, capture_output=True, text=True, env=MPI_ENV, timeout=timeout)
    if result.returncode != 0:
        lines = [l for l in result.stderr.splitlines() if l.strip()]
        raise RuntimeError(lines[-1] if lines else f"exit code {result.returncode}")
    with open(stats_path) as f:
        s = json.load(f)
    return {"mode": mode, "processes": np, "size": size, "seed": seed, "misses": s["records_computed"],
            "aggregated_s": workers_cpu(s), "render_s": s["render_s"]}


def records_sweep(args):
    """Runs the sweep, round after round (every configuration once per round, each round with
    its own seed, so that a drift of the machine spreads over all of them), prints a table of
    component mode's records against the mode with the fewest among the others, with a
    bootstrap interval over the seeds (`compare_component`), and writes records-sweep.csv and
    records-sweep.md under --out. Says at the end whether component mode had the fewest (on
    the medians) in every configuration, and where that was beyond noise."""
    ranks = [int(r) for r in args.sweep_ranks.split(",")]
    sizes = [int(v) for v in args.sweep_sizes.split(",")]
    scenes = args.scenes.split(",")
    os.makedirs(args.out, exist_ok=True)
    say("building icrender")
    common.build()
    work = common.scratch()
    started = time.perf_counter()
    reps, rows = {}, []
    for round_ in range(args.sweep_repeat):
        seed = round_ + 1
        for name in scenes:
            for size in sizes:
                for np in ranks:
                    for mode in MODES:
                        try:
                            r = run_records(SCENES[name][0], mode, np, size, seed, args.ad, work, args.timeout)
                        except (RuntimeError, subprocess.TimeoutExpired) as e:
                            say(f"{name} {size} {mode} {np} processes, seed {seed}: FAILED: {e}")
                            continue
                        r["scene"] = name
                        rows.append(r)
                        reps.setdefault((name, size, np), {}).setdefault(mode, []).append(r)
        say(f"records sweep: round {round_ + 1} of {args.sweep_repeat} done ({time.perf_counter() - started:.0f} s)")
    write_csv(os.path.join(args.out, "records-sweep-runs.csv"), rows)
    table, fewest_everywhere, beyond_everywhere = [], True, True
    for (name, size, np), by_mode in reps.items():
        c = compare_component(by_mode, seed=zlib.crc32(f"sweep {name} {size} {np}".encode()))
        if not c:
            fewest_everywhere = beyond_everywhere = False
            continue
        medians = {m: statistics.median(r["misses"] for r in rs) for m, rs in by_mode.items()}
        fewest = all(medians["component"] < v for m, v in medians.items() if m != "component")
        fewest_everywhere &= fewest
        beyond_everywhere &= c["misses_verdict"] == "fewer"
        table.append({"scene": name, "size": size, "processes": np, "repeats": c["component_repeats"],
                      **{f"{m}_records": medians.get(m, float("nan")) for m in MODES},
                      "fewest_other": c["fewest_mode"], "component_vs_fewest_pct": c["misses_pct"],
                      "lo_pct": c["misses_lo"], "hi_pct": c["misses_hi"], "verdict": c["misses_verdict"],
                      "component_fewest": fewest, "cpu_gain_pct": c["gain_median_pct"],
                      "cpu_verdict": c["gain_median_verdict"]})
    write_csv(os.path.join(args.out, "records-sweep.csv"), table)
    head = ("| scene | size | processes | " + " | ".join(MODES) + " | component vs fewest other (95 % interval) "
            "| fewest? | CPU, median vs second best |")
    lines = [f"Records made (median of {args.sweep_repeat} seeds), every mode at its defaults, --ic-build "
             f"progressive, -ab 1 -aa {SWEEP_AA} -ad {args.ad}:", "", head,
             "|" + "---|" * (5 + len(MODES))]
    for t in table:
        counts = " | ".join(f"{t[m + '_records']:.0f}" for m in MODES)
        lines.append(f"| {t['scene']} | {t['size']} | {t['processes']} | {counts} | "
                     f"{t['component_vs_fewest_pct']:+.1f} % vs {t['fewest_other']} [{t['lo_pct']:+.1f}, "
                     f"{t['hi_pct']:+.1f}]: {t['verdict']} | {'yes' if t['component_fewest'] else 'NO'} | "
                     f"{t['cpu_gain_pct']:+.1f} %: {t['cpu_verdict']} |")
    lines += ["", f"Component mode had the fewest records (medians) in every configuration: "
              f"{'yes' if fewest_everywhere else 'NO'}; beyond noise in every one: "
              f"{'yes' if beyond_everywhere else 'no'}. {len(rows)} runs, "
              f"{(time.perf_counter() - started) / 60:.1f} min."]
    text = "\n".join(lines)
    print(text)
    with open(os.path.join(args.out, "records-sweep.md"), "w") as f:
        f.write(text + "\n")
    write_sweep_page(args, rows, text, time.perf_counter() - started)


def write_sweep_page(args, rows, table_text, elapsed):
    """docs/RECORDS_SWEEP.md (under --docs): the command as run, when and how long, the table
    and its verdict; every run in records_sweep/runs.csv beside it."""
    folder = os.path.join(args.docs, "records_sweep")
    os.makedirs(folder, exist_ok=True)
    write_csv(os.path.join(folder, "runs.csv"), rows)
    command = " ".join(["python3 bench/paper.py"] + sys.argv[1:])
    page = [
        "# Records sweep: progressive mode, every mode at its defaults",
        "",
        f"Written by `{command}` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} "
        f"({elapsed / 60:.1f} min, 2 shared cores, every mpirun oversubscribed); every run in "
        "[records_sweep/runs.csv](records_sweep/runs.csv). Do not edit by hand: rerun the command. The "
        f"full sweep (`python3 bench/paper.py --records-sweep`: {', '.join(map(str, SWEEP_RANKS))} "
        f"processes, {', '.join(map(str, SWEEP_SIZES))} pixels, the three scenes, {SWEEP_REPEAT} seeds "
        "each) takes hours here.",
        "",
        "Component mode should make the fewest records in every configuration: its PRs send their "
        "misses to the PAs, where the other modes' ranks each make records side by side. \"fewest?\" "
        "compares medians; the interval is a 95 % bootstrap over the seeds.",
        "",
        table_text,
    ]
    with open(os.path.join(args.docs, "RECORDS_SWEEP.md"), "w") as f:
        f.write("\n".join(page) + "\n")
    say(f"wrote {rel(os.path.join(args.docs, 'RECORDS_SWEEP.md'))}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--full", action="store_true",
                        help="the paper's sizes (512x512, conference 672x512) and 3,5,9 processes")
    parser.add_argument("--scenes", default=",".join(SCENES))
    parser.add_argument("--size", help="WxH for every scene (default: BENCH_SIZE, 256x256 but the conference room 128x128; --full: the paper's)")
    parser.add_argument("--ranks", help="MPI process counts, master included (default 3,4,5; --full 3,5,9)")
    parser.add_argument("--repeat", type=int, help="runs per configuration: the fastest's CPU times, the median of the rest "
                        f"(default {REPEAT}; --full 1)")
    parser.add_argument("--default-repeat", type=int,
                        help="runs per configuration of the traditional modes at the default --overture (the "
                             "second setting; component mode's runs serve both); 0: that setting is not run "
                             f"(default {DEFAULT_REPEAT}; --full 1)")
    parser.add_argument("--quick", action="store_true",
                        help="a check that the bench runs end to end, not a measurement: the Cornell box at 64x64, "
                             "3 and 4 processes, 3 repeats, no Radiance, a small prediction; writes to "
                             "bench/out/paper-quick/ (RESULTS.md there too) unless --out/--docs say otherwise")
    parser.add_argument("--ad", type=int, default=512)
    parser.add_argument("--as", dest="as_", type=int, default=128)
    parser.add_argument("--ar", type=int, default=64)
    parser.add_argument("--tile", default="16x16")
    parser.add_argument("--predict", default="4,8,16,24,64,256,1024",
                        help="processor counts (workers) the simulation predicts")
    parser.add_argument("--predict-size", help="image size of the prediction's trace (default 256x256; --full: the paper's)")
    parser.add_argument("--ref-seconds", type=float, default=60, help="time limit of each reference (default 60 s; "
                        "made once, kept in --out)")
    parser.add_argument("--no-radiance", action="store_true", help="skip rpict and rtrace")
    parser.add_argument("--radiance-size", help="WxH of the Radiance side by side (default: the bench's, but "
                        "64x64 for the conference room, where rpict takes minutes; --full: the bench's)")
    parser.add_argument("--rtrace-all", action="store_true",
                        help="rtrace -n at every worker count (default: the largest only; --full: all)")
    parser.add_argument("--cluster-csv", default=os.path.join(common.ROOT, "bench", "out", "cluster-bench.csv"))
    parser.add_argument("--out", default=os.path.join(common.ROOT, "bench", "out", "paper"))
    parser.add_argument("--docs", default=DOCS, help="where RESULTS.md and results/ go")
    parser.add_argument("--timeout", type=int, default=900, help="seconds before one mpirun is given up")
    parser.add_argument("--records-sweep", action="store_true",
                        help="only the records sweep: every mode at its defaults in progressive mode over "
                             "--sweep-ranks, --sweep-sizes and --scenes, with --sweep-repeat seeds each; whether "
                             "component mode made the fewest records everywhere (records-sweep.md in --out, "
                             "RECORDS_SWEEP.md in --docs)")
    parser.add_argument("--sweep-ranks", default=",".join(map(str, SWEEP_RANKS)))
    parser.add_argument("--sweep-sizes", default=",".join(map(str, SWEEP_SIZES)), help="square image sizes")
    parser.add_argument("--sweep-repeat", type=int, default=SWEEP_REPEAT, help="seeds per configuration")
    args = parser.parse_args()
    if args.records_sweep:
        common.require("bench/paper.py", (), ["mpirun"])
        records_sweep(args)
        return
    if args.quick:
        quick_out = os.path.join(common.ROOT, "bench", "out", "paper-quick")
        args.out = args.out if args.out != parser.get_default("out") else quick_out
        args.docs = args.docs if args.docs != DOCS else quick_out
        args.scenes = args.scenes if args.scenes != parser.get_default("scenes") else "cornell"
        args.size = args.size or "64x64"
        args.ranks = args.ranks or "3,4"
        args.repeat = args.repeat or 3
        args.default_repeat = 3 if args.default_repeat is None else args.default_repeat
        args.no_radiance = True
        args.predict = "4,8" if args.predict == parser.get_default("predict") else args.predict
        args.predict_size = args.predict_size or "64x64"
        args.ref_seconds = min(args.ref_seconds, 10)
    common.require("bench/paper.py", ["matplotlib", "pyradiance"], ["mpirun"])
    started = time.perf_counter()
    command = "python3 bench/paper.py" + ("" if len(sys.argv) == 1 else " " + " ".join(shlex.quote(a) for a in sys.argv[1:]))
    ranks = [int(r) for r in (args.ranks or ("3,5,9" if args.full else "3,4,5")).split(",")]
    # With 5 the median of one configuration still moved by up to ~15 % between runs of the
    # bench on this machine (its repeats span up to 40 %); see REPEAT.
    repeat = args.repeat or (1 if args.full else REPEAT)
    default_repeat = args.default_repeat if args.default_repeat is not None else (1 if args.full else DEFAULT_REPEAT)
    scenes = args.scenes.split(",")
    os.makedirs(args.out, exist_ok=True)
    results_dir = os.path.join(args.docs, "results")
    os.makedirs(results_dir, exist_ok=True)
    say("building icrender")
    common.build()
    work = common.scratch()
    tw, th = (int(v) for v in args.tile.split("x"))

    runs, rad_rows, setups, every_run = [], [], {}, []
    runs_default, comparisons = [], []
    rad_version = None
    for name in scenes:
        path, aa, full_size = SCENES[name]
        size = tuple(int(v) for v in args.size.split("x")) if args.size else (full_size if args.full else BENCH_SIZE[name])
        w, h = size
        ambient = {"aa": aa, "ad": args.ad, "as": args.as_, "ar": args.ar}
        base = ["-x", str(w), "-y", str(h), "-ab", "1", "-aa", str(aa), "-ad", str(args.ad), "-as", str(args.as_),
                "-ar", str(args.ar), "--tile", args.tile,
                # -ar's floor alone, as in rpict and in the runs docs/RESULTS.md reports.
                "--ic-min-pixels", "0"]
        ref = os.path.join(args.out, f"ref-{name}-{w}x{h}.exr")
        t0 = time.perf_counter()
        if not os.path.exists(ref):
            say(f"{name}: reference {w}x{h} (at most {args.ref_seconds:.0f} s)")
        common.reference(path, ref, ["-x", str(w), "-y", str(h), "-ab", "1", "--spp", "1", "--light-samples", "16"],
                         noise=0.01, max_seconds=args.ref_seconds)
        ref_s = time.perf_counter() - t0
        sdir = os.path.join(work, name)
        os.makedirs(sdir, exist_ok=True)
        trace = os.path.join(args.out, f"trace-{name}-{w}x{h}.txt")
        # The traced run samples a record at every lookup (slow): its times are not used.
        traced = run_serial(path, base, None, sdir, trace=trace)
        # Every configuration's repeats are spread over the whole measurement, round after round
        # (serial, then every mode at every count, then again), not run back to back: this
        # machine's speed drifts by tens of percent over minutes, and the simulation's
        # leave-one-out costs compare configurations measured at different times.
        # The paper's setting: every mode at every count. The default setting adds the
        # traditional modes at the default overture (component mode runs at its default in both:
        # the same runs serve both settings), in the first `default_repeat` rounds.
        configs = [(mode, np, "paper") for mode in MODES for np in ranks if not (mode == "component" and np < 3)]
        configs += [(mode, np, "default") for mode in MODES if mode != "component" for np in ranks] \
            if default_repeat else []
        serial, reps, default = [], {c: [] for c in configs}, []
        for round_ in range(max(repeat, default_repeat, 1)):
            if round_ < repeat:
                serial.append(run_serial(path, base, ref, sdir))
            # One process at the renderer's defaults: the default setting's serial run.
            if round_ < max(default_repeat, 3):
                default.append(run_serial(path, base, ref, sdir, order=[]))
            for mode, np, setting in configs:
                if round_ >= (default_repeat if setting == "default" else repeat):
                    continue
                overture = common.DEFAULT_OVERTURE if setting == "default" else None
                try:
                    reps[(mode, np, setting)].append(run_mpi(path, mode, np, base, ref, sdir, args.timeout,
                                                             overture=overture))
                except (RuntimeError, subprocess.TimeoutExpired) as e:
                    say(f"{name:>10} {mode:<12} {np} processes ({setting}): FAILED: {e}")
        while len(serial) < 3:  # the serial run is cheap: at least three
            serial.append(run_serial(path, base, ref, sdir))
        while len(default) < 3:
            default.append(run_serial(path, base, ref, sdir, order=[]))
        if any(r["misses"] != traced["misses"] for r in serial):
            say(f"{name}: WARNING: the traced run made {traced['misses']} records, the others "
                f"{[r['misses'] for r in serial]}")
        srow = mean_row(serial)
        srow.update(scene=name, width=w, height=h, setting="paper")
        every_run += [dict(r, scene=name, setting="paper", repeat=i) for i, r in enumerate(serial)]
        every_run += [dict(r, scene=name, setting="default", repeat=i) for i, r in enumerate(default)]
        every_run += [dict(r, scene=name, setting=c[2], repeat=i) for c in configs for i, r in enumerate(reps[c])]
        runs.append(srow)
        say(f"{name:>10} serial       : {srow['misses']:.0f} misses, {srow['aggregated_s']:.3f} s CPU, "
            f"relMSE {srow['relmse']:.3e}")
        drow = mean_row(default)
        drow.update(scene=name, width=w, height=h, setting="default")
        say(f"{name:>10} serial at the default --overture {common.DEFAULT_OVERTURE}: {drow['misses']:.0f} misses, "
            f"{drow['aggregated_s']:.3f} s CPU, relMSE {drow['relmse']:.3e}")
        if default_repeat:
            runs_default.append(drow)
        setups[name] = {"path": path, "size": size, "aa": aa, "base": base, "ref": ref, "trace": trace,
                        "serial": srow, "serial_default": drow, "ref_s": ref_s,
                        "serial_repeats": len(serial), "serial_default_repeats": len(default)}
        for mode, np, setting in configs:
            if not reps[(mode, np, setting)]:
                continue
            row = mean_row(reps[(mode, np, setting)])
            row.update(scene=name, width=w, height=h, setting=setting,
                       spread_pct=spread_pct(reps[(mode, np, setting)]))
            (runs if setting == "paper" else runs_default).append(row)
            if mode == "component" and default_repeat:  # the same runs, at their default order, in both settings
                runs_default.append(dict(row, setting="default"))
            say(f"{name:>10} {mode:<12} {np} proc ({setting}): {row['misses']:7.1f} misses, {row['aggregated_s']:.3f} "
                f"s CPU (fastest of {row['repeats']}; median {row['aggregated_s_median']:.3f}, slowest "
                f"{row['aggregated_s_max']:.3f}), idle {row['idle_s']:.3f} s, "
                f"relMSE {row['relmse']:.3e}")
        # Component mode against the others, each setting, with intervals from the repeats.
        for setting in SETTINGS if default_repeat else ("paper",):
            for np in ranks:
                by_mode = {m: reps.get((m, np, "paper" if m == "component" else setting)) or [] for m in MODES}
                c = compare_component(by_mode, seed=zlib.crc32(f"{name} {np} {setting}".encode()))
                if c:
                    comparisons.append(dict(c, scene=name, setting=setting, processes=np, workers=np - 1))
        write_csv(os.path.join(args.out, "runs.csv"), runs)  # so far (the final one is written at the end)
        if not args.no_radiance:
            rsize = size
            if args.radiance_size:
                rsize = tuple(int(v) for v in args.radiance_size.split("x"))
            elif name in RADIANCE_SMALL and not args.full:
                rsize = RADIANCE_SMALL[name]
            counts = [n - 1 for n in ranks] if (args.full or args.rtrace_all) else [max(ranks) - 1]
            rdir = os.path.join(sdir, "radiance")
            os.makedirs(rdir, exist_ok=True)
            icr = drow
            rref = ref
            if rsize != size:
                rw, rh = rsize
                rbase = ["-x", str(rw), "-y", str(rh)] + base[4:]
                rref = os.path.join(args.out, f"ref-{name}-{rw}x{rh}.exr")
                common.reference(path, rref, ["-x", str(rw), "-y", str(rh), "-ab", "1", "--spp", "1",
                                              "--light-samples", "16"], noise=0.01, max_seconds=args.ref_seconds)
                icr = dict(run_serial(path, rbase, rref, rdir, order=[]), scene=name, width=rw, height=rh)
                view = exr_view(os.path.join(rdir, "serial.exr"))
            else:
                # The view of the image the last run wrote (every run of the scene has the same).
                view = exr_view(os.path.join(sdir, "serial.exr"))
            rows, rad_version = radiance(name, path, rsize, ambient, view, rref, counts, rdir)
            for r in rows:
                r.update(width=rsize[0], height=rsize[1])
            setups[name]["rpict_costs"] = rpict_costs(rows[0], rsize[0] * rsize[1])
            rad_rows += rows
            setups[name]["radiance_icrender"] = icr
            setups[name]["radiance_size"] = rsize

    # Derived figures: speed-ups against the serial run of the same setting, gain of component mode.
    for r in runs + runs_default:
        s = setups[r["scene"]]["serial" if r.get("setting", "paper") == "paper" else "serial_default"]
        p = r["workers"]
        r["efficiency_pct"] = 100.0 * s["aggregated_s"] / r["aggregated_s"] if r["aggregated_s"] else float("nan")
        r["work_speedup"] = p * s["aggregated_s"] / r["aggregated_s"] if r["aggregated_s"] else float("nan")
        r["wall_speedup"] = s["render_s"] / r["render_s"] if r["render_s"] else float("nan")
        busy_total = r["aggregated_s"] + r["idle_s"]
        r["idle_pct"] = 100.0 * r["idle_s"] / busy_total if busy_total else 0.0
    # Table 1 for both settings: the point estimates on the fastest repeats (as the tables), the
    # intervals and verdicts from every repeat (`compare_component`).
    gains = []
    for c in comparisons:
        rows = runs if c["setting"] == "paper" else runs_default
        by_mode = {r["mode"]: r for r in rows if r["scene"] == c["scene"] and r["processes"] == c["processes"]
                   and r["mode"] in MODES}
        gains.append(dict(c, component_speedup=by_mode["component"]["work_speedup"],
                          second_speedup=by_mode[c["second_mode"]]["work_speedup"]))
    for g in gains:
        say(f"{g['scene']:>10} {g['workers']} workers ({g['setting']}): gain {g['gain_pct']:+.1f}% "
            f"[{g['gain_lo']:+.1f}, {g['gain_hi']:+.1f}] vs {g['second_mode']} ({g['gain_verdict']}; medians {g['gain_median_pct']:+.1f}% ({g['gain_median_verdict']}): {g['verdict']}); misses "
            f"{g['misses_pct']:+.1f}% [{g['misses_lo']:+.1f}, {g['misses_hi']:+.1f}] vs {g['fewest_mode']} "
            f"({g['misses_verdict']})")

    # -- simulation: validation at the measured counts ---------------------------------------
    say("simulation: validating against the measured runs")
    sim_rows = []
    for name in scenes:
        st = setups[name]
        w, h = st["size"]
        st["costs"] = sim_costs(st["serial"], w * h)
        mine = [r for r in runs if r["scene"] == name]
        # How long a rank waiting for the master waits here, beyond the work: the noshare runs'
        # idle time per tile request (their only waits). On cores shared by more processes than
        # there are cores this is the time a woken process waits for a core.
        noshare = [r for r in mine if r["mode"] == "noshare" and r.get("tiles")]
        wake = (sum(r["idle_s"] for r in noshare) / sum(r["tiles"] for r in noshare)) if noshare else icsim.POLL_WAKE
        st["wake"] = wake
        say(f"{name}: a round trip to the master takes {wake * 1e3:.2f} ms here (noshare runs' idle time per tile)")
        tasks = [(r, *validation_costs(r, mine, st["serial"], w * h)) for r in mine]
        calibrations = {id(r): component_calibration(r, costs, mine, st["serial"], w * h)
                        for r, costs, how in tasks if r["mode"] == "component" and costs.request_pr > 0}
        # Independent and deterministic, like the prediction's: one process per core.
        with multiprocessing.Pool(os.cpu_count() or 1, initializer=_load_trace,
                                  initargs=(st["trace"], w, h, st["aa"], (tw, th))) as pool:
            flat = [(key, r, c) for key, cal in calibrations.items() for r, c in cal]
            simulated = pool.map(_validate_one, [(r["mode"], r["workers"], c, max(wake, 1e-6)) for _, r, c in flat])
            ratios = {}
            for (key, r, _), res in zip(flat, simulated):
                ratios.setdefault(key, []).append(r["aggregated_s"] / res["aggregated"])
            for i, (r, costs, how) in enumerate(tasks):
                if ratios.get(id(r)):
                    factor = statistics.mean(ratios[id(r)])
                    tasks[i] = (r, scaled(costs, factor),
                                how + f", everything x{factor:.2f} for component mode (its own runs at the other "
                                      "counts, simulated at these costs, against their measured time)")
            for r, costs, how in tasks:
                say(f"{name:>10} {r['mode']:<12} {r['processes']} proc: {costs} from {how}")
            results = pool.map(_validate_one, [(r["mode"], r["workers"], costs, max(wake, 1e-6))
                                               for r, costs, _ in tasks])
        for (r, costs, how), res in zip(tasks, results):
            sim_rows.append({"scene": name, "mode": r["mode"], "processes": r["processes"], "workers": r["workers"],
                             "costs_from": how,
                             "real_misses": r["misses"], "sim_misses": res["misses"],
                             "misses_err_pct": pct(res["misses"], r["misses"]),
                             "real_aggregated_s": r["aggregated_s"], "sim_aggregated_s": res["aggregated"],
                             "time_err_pct": pct(res["aggregated"], r["aggregated_s"]),
                             # The measured time's own spread over the repeats: an error within it
                             # is within the measurement's noise.
                             "real_median_s": r.get("aggregated_s_median", r["aggregated_s"]),
                             "real_slowest_s": r.get("aggregated_s_max", r["aggregated_s"]),
                             "time_err_median_pct": pct(res["aggregated"], r.get("aggregated_s_median",
                                                                                 r["aggregated_s"])),
                             "within_spread": 0.995 * r["aggregated_s"] <= res["aggregated"]
                             <= 1.005 * r.get("aggregated_s_max", r["aggregated_s"]),
                             "real_messages": r["messages"], "sim_messages": res["messages"],
                             "real_bytes": r["bytes"], "sim_bytes": res["bytes"]})
    for r in sim_rows:
        say(f"{r['scene']:>10} {r['mode']:<12} {r['processes']} proc: misses real {r['real_misses']:7.1f} "
            f"sim {r['sim_misses']:6d} ({r['misses_err_pct']:+5.1f}%), aggregated time real "
            f"{r['real_aggregated_s']:.3f} s sim {r['sim_aggregated_s']:.3f} s ({r['time_err_pct']:+5.1f}%)")

    # -- the cluster test bed's runs (issue 10), if measured ------------------------------
    out_dir = os.path.dirname(args.cluster_csv)
    cluster_rows, cluster_note = cluster_sim.validate(
        args.cluster_csv, os.path.join(out_dir, "cluster-links.csv"), os.path.join(out_dir, "cluster-bench.json"),
        args.out, say=say)

    # -- prediction ------------------------------------------------------------------------
    predict = [int(p) for p in args.predict.split(",")]
    pred_rows = []
    for name in scenes:
        st = setups[name]
        if args.predict_size:
            pw, ph = (int(v) for v in args.predict_size.split("x"))
        else:
            pw, ph = SCENES[name][2] if args.full else (256, 256)
        ptrace_path = os.path.join(args.out, f"trace-{name}-{pw}x{ph}.txt")
        if (pw, ph) != st["size"]:
            pbase = ["-x", str(pw), "-y", str(ph)] + st["base"][4:]
            pserial = run_serial(st["path"], pbase, None, os.path.join(work, name), trace=ptrace_path)
        else:
            pserial = st["serial"]
            ptrace_path = st["trace"]
        ptrace = icsim.Trace(ptrace_path, pw, ph, st["aa"])
        # Per record and pixel: the serial runs (a processor to itself); per request: as the
        # component runs timed it, for the same reason (the validation's residual, what those
        # runs spent beyond records and pixels, includes waiting for a shared core and is a
        # small difference of large numbers: ~8 us a request per 10 % of a run's noise).
        costs = st["costs"]
        comp = [r for r in runs if r["scene"] == name and r["mode"] == "component"]
        residual = request_cost(comp, runs, st["serial"], w * h)
        timed = timed_request_cost(comp)
        st["request_residual"], st["request_timed"] = residual, timed
        costs.request_pr = costs.request_pa = (timed if timed is not None else residual) / 2
        serial_res = icsim.simulate(ptrace, "serial", 1, costs, network="1gbit", tile=(tw, th))
        # A waiting rank notices the master's answer as late as measured here (the noshare runs'
        # idle time per tile): measured, and an upper bound for ranks with a core each.
        wake = st["wake"]
        say(f"{name}: predicting {pw}x{ph} ({len(ptrace.tiles(tw, th))} tiles), {costs}, "
            f"round trip wait {wake * 1e3:.2f} ms")
        # What if a request cost only what the protocol needs (1 us to make, send and read) and a
        # waiting rank noticed a message at once (blocking receives instead of polling)?
        lean = icsim.Costs(record=costs.record, pixel=costs.pixel, message=costs.message, request_pr=1e-6,
                           request_pa=1e-6)
        scenarios = {"1gbit": (costs, wake, "1gbit"), "100gbit": (costs, wake, "100gbit"),
                     "1gbit-lean": (lean, 1e-6, "1gbit")}
        # What if every record and pixel cost what rpict's cost here (the paper's renderer was
        # Radiance), communication staying as measured: the paper's balance of work to messages.
        if st.get("rpict_costs"):
            record, pixel = st["rpict_costs"]
            scenarios["1gbit-rpict"] = (icsim.Costs(record=record, pixel=pixel, message=costs.message,
                                                    request_pr=costs.request_pr, request_pa=costs.request_pa),
                                        wake, "1gbit")
            say(f"{name}: rpict's costs here: record {record * 1e3:.3f} ms, pixel {pixel * 1e6:.2f} us")
        tasks = [(net, mode, p, c, wake, network) for net, (c, wake, network) in scenarios.items() for p in predict
                 for mode in MODES if not (mode == "component" and p < 2)]
        # The simulations are independent and deterministic: one process per core.
        with multiprocessing.Pool(os.cpu_count() or 1, initializer=_load_trace,
                                  initargs=(ptrace_path, pw, ph, st["aa"], (tw, th))) as pool:
            results = pool.map(_predict_one, tasks)
        # Each scenario's speed-up is against the serial run at its own costs.
        serial_by = {net: serial_res if c is costs else
                     icsim.simulate(ptrace, "serial", 1, c, network=network, tile=(tw, th))
                     for net, (c, _, network) in scenarios.items()}
        for (net, mode, p, _, _, _), res in zip(tasks, results):
            serial_res = serial_by[net]
            pred_rows.append({"scene": name, "network": net, "mode": mode, "workers": p,
                              "width": pw, "height": ph, "misses": res["misses"],
                              "serial_misses": serial_res.misses,
                              "aggregated_s": res["aggregated"], "makespan_s": res["makespan"],
                              "speedup": serial_res.makespan / res["makespan"],
                              "efficiency_pct": 100 * serial_res.makespan / res["makespan"] / p,
                              "idle_pct": 100 * res["idle_fraction"], "messages": res["messages"],
                              "bytes": res["bytes"]})
        say(f"{name}: prediction done ({time.perf_counter() - started:.0f} s so far)")

    elapsed = time.perf_counter() - started
    write_outputs(args, runs, gains, rad_rows, sim_rows, cluster_rows, cluster_note, pred_rows, setups, scenes,
                  ranks, repeat, command, elapsed, rad_version, predict, every_run, runs_default, default_repeat)
    say(f"done in {elapsed / 60:.1f} min")


_TRACE = {}


def _load_trace(path, width, height, accuracy, tile):
    _TRACE["trace"] = icsim.Trace(path, width, height, accuracy)
    _TRACE["tile"] = tile


def _validate_one(task):
    """One measured run simulated on this machine's cores (bench/icsim.py time-slices them)."""
    mode, workers, costs, wake = task
    res = icsim.simulate(_TRACE["trace"], mode, workers, costs, network="loopback", tile=_TRACE["tile"], wake=wake,
                         cores=os.cpu_count(), overture=mode_overture(mode))
    return {"misses": res.misses, "aggregated": res.aggregated, "messages": res.messages, "bytes": res.bytes}


def _predict_one(task):
    _, mode, p, costs, wake, network = task
    res = icsim.simulate(_TRACE["trace"], mode, p, costs, network=network, tile=_TRACE["tile"], wake=wake,
                         overture=mode_overture(mode))
    return {"misses": res.misses, "aggregated": res.aggregated, "makespan": res.makespan,
            "idle_fraction": res.idle_fraction, "messages": res.messages, "bytes": res.bytes}


# -- outputs -------------------------------------------------------------------------------

def write_csv(path, rows):
    if rows:
        common.write_csv(path, rows)
        say(f"wrote {rel(path)}")


def write_outputs(args, runs, gains, rad_rows, sim_rows, cluster_rows, cluster_note, pred_rows, setups, scenes,
                  ranks, repeat, command, elapsed, rad_version, predict, every_run=(), runs_default=(),
                  default_repeat=0):
    import plots
    results_dir = os.path.join(args.docs, "results")
    csvs = {"runs.csv": runs, "runs-default.csv": list(runs_default), "runs-all.csv": list(every_run),
            "gains.csv": gains, "radiance.csv": rad_rows, "validation.csv": sim_rows,
            "cluster-validation.csv": cluster_rows, "prediction.csv": pred_rows}
    for fname, rows in csvs.items():
        write_csv(os.path.join(args.out, fname), rows)
        write_csv(os.path.join(results_dir, fname), rows)
    figures = plots.make_all(results_dir, runs, gains, sim_rows, pred_rows, scenes)
    for f in figures:
        shutil.copy(os.path.join(results_dir, f), os.path.join(args.out, f))
    import report
    text = report.render(command=command, elapsed=elapsed, runs=runs, gains=gains, rad_rows=rad_rows,
                         sim_rows=sim_rows, cluster_rows=cluster_rows, cluster_note=cluster_note,
                         pred_rows=pred_rows, setups=setups, scenes=scenes, ranks=ranks, repeat=repeat,
                         rad_version=rad_version, figures=figures, predict=predict, args=args,
                         runs_default=list(runs_default), default_repeat=default_repeat,
                         confidence=CONFIDENCE, resamples=BOOTSTRAP)
    path = os.path.join(args.docs, "RESULTS.md")
    with open(path, "w") as f:
        f.write(text)
    say(f"wrote {rel(path)}")


if __name__ == "__main__":
    sys.path.insert(0, HERE)
    main()
