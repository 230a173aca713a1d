#!/usr/bin/env python3
"""The error every render estimates for itself (`error_estimate` in --stats) against the error
a converged reference measures, on the peers bench's scenes and views.

    python3 bench/error_estimate.py              # about 12 minutes on 2 cores
    python3 bench/error_estimate.py --quick      # the Cornell box's first view: a check, not a result
    python3 bench/error_estimate.py --page-only 14   # the page again from the last runs

For each view (bench/peer_scenes.py) at a reduced size: a brute-force reference (`icrender
reference`, to a noise target or a time limit, the same --lambertian semantics as the peers
bench), then icrender at the fastest, a middle and the slowest of the peers bench's settings,
each with two seeds. The true relMSE comes from `icrender compare`, the 4x4 one from both images
box-averaged 4x4 (oiiotool) and compared; the reference's own error (its distance from a second
reference of other seeds) is listed beside them, as it is part of every error measured.

Then the passes (`--target-error`, `--time-limit`) on the same views: each of the peers bench's
settings once (seed 1), for the fastest fixed setting that reaches a given true error; two
targets (the middle setting's true error and a third of the way from it to the slowest's, both
at least three times the reference's own), each against the fastest fixed setting whose error
is no higher; and a time limit of three times the middle setting's time. Prints tables and
writes docs/ERROR_ESTIMATE.md, its CSVs and a plot of estimated and true error against the
render's time.
"""

import argparse
import datetime
import json
import os
import statistics
import subprocess
import time

import common
from peer_scenes import SCENES

DOCS = os.path.join(common.ROOT, "docs")
# A smaller image than the peers bench's (the references are the cost): the same views.
SIZES = {"cornell": (128, 128), "conference": (160, 120), "sibenik": (160, 120)}
REFERENCE_NOISE, REFERENCE_SECONDS = 0.004, 45
SEEDS = [1, 2]
TARGET_FACTOR = 2.0
# The passes' targets: the true error at most this many times the target, the time at most this
# many times the limit, and at most this many times the fastest fixed setting's time.
TARGET_ERROR_FACTOR, TIME_LIMIT_FACTOR, COST_FACTOR = 1.5, 1.1, 1.25
# A target is at least this many times the reference's own error (else it cannot be judged), and
# no passes run longer than this (seconds).
REFERENCE_MARGIN, PASSES_CAP_S = 3.0, 90


def settings_of(cfg):
    """The fastest, a middle and the slowest of the peers bench's settings for the scene."""
    ladder = cfg["icrender"]
    return [ladder[0], ladder[len(ladder) // 2], ladder[-1]]


def base_options(name, cfg, view):
    width, height = SIZES[name]
    return ["-x", str(width), "-y", str(height), "-ab", str(cfg["ab"]), "--lambertian"] + cfg["views"][view]


def reference(name, cfg, view, out, seed):
    cmd = [common.BINARY, "reference", cfg["file"], "-o", out, "-q", "--no-preview", "--overwrite",
           "--noise", str(REFERENCE_NOISE), "--max-seconds", str(REFERENCE_SECONDS), "--seed", str(seed)]
    subprocess.run(cmd + base_options(name, cfg, view), check=True)


def averaged_4x4(path, out):
    """The composite of `path` box-averaged over 4x4 pixels (the peers bench's 4x4 measure)."""
    subprocess.run(["oiiotool", path, "--ch", "R,G,B", "--resize:filter=box", "25%", "-o", out],
                   check=True, capture_output=True)
    return out


def composite_relmse(image, reference_path):
    return common.compare(image, reference_path)["composite"][1]


def measure(name, cfg, view, work, quick):
    ref = os.path.join(work, f"{name}-{view}-ref.exr")
    ref_b = os.path.join(work, f"{name}-{view}-ref-b.exr")
    started = time.time()
    reference(name, cfg, view, ref, 101)
    reference(name, cfg, view, ref_b, 202)
    # Two references of independent seeds differ by twice one's error.
    reference_error = composite_relmse(ref_b, ref) / 2
    ref4 = averaged_4x4(ref, os.path.join(work, "ref4.exr"))
    reference_error_4x4 = composite_relmse(averaged_4x4(ref_b, os.path.join(work, "refb4.exr")), ref4) / 2
    print(f"[error_estimate] {name}-{view}: references in {time.time() - started:.0f} s, their own relMSE "
          f"{reference_error:.2e} (4x4 {reference_error_4x4:.2e})", flush=True)
    rows = []
    for rank, setting in enumerate(settings_of(cfg)[:1] if quick else settings_of(cfg)):
        for seed in SEEDS[:1] if quick else SEEDS:
            out = os.path.join(work, "image.exr")
            options = base_options(name, cfg, view) + setting.split() + ["--seed", str(seed), "--aovs", "none"]
            stats, _ = common.render(cfg["file"], out, options)
            estimate = stats["error_estimate"]
            true = composite_relmse(out, ref)
            true_4x4 = composite_relmse(averaged_4x4(out, os.path.join(work, "image4.exr")), ref4)
            row = {"scene": name, "view": view, "setting": setting, "rank": rank, "seed": seed,
                   "render_s": round(stats["render_s"], 3), "estimate_s": round(estimate["seconds"], 3),
                   "estimated": estimate["relmse"], "true": true, "ratio": estimate["relmse"] / true,
                   "estimated_4x4": estimate["relmse_4x4"], "true_4x4": true_4x4,
                   "ratio_4x4": estimate["relmse_4x4"] / true_4x4, "noise": estimate["noise"],
                   "cache": estimate["cache"], "reference_error": reference_error,
                   "reference_error_4x4": reference_error_4x4}
            rows.append(row)
            print(f"[error_estimate] {name}-{view} [{setting}] seed {seed}: {row['render_s']:.2f} s, estimated "
                  f"{row['estimated']:.2e} true {true:.2e} (x{row['ratio']:.2f}); 4x4 {row['estimated_4x4']:.2e} "
                  f"true {true_4x4:.2e} (x{row['ratio_4x4']:.2f})", flush=True)
    return rows, ref, ref4, reference_error


def passes_runs(name, cfg, view, work, ref, ref4, reference_error, rows, quick):
    """The ladder once (seed 1), then --target-error at two targets and --time-limit once."""
    ladder = []
    for setting in (cfg["icrender"][:2] if quick else cfg["icrender"]):
        out = os.path.join(work, "ladder.exr")
        options = base_options(name, cfg, view) + setting.split() + ["--seed", "1", "--aovs", "none"]
        stats, _ = common.render(cfg["file"], out, options)
        ladder.append({"setting": setting, "render_s": stats["render_s"], "true": composite_relmse(out, ref)})
    mine = [r for r in rows if r["seed"] == 1]
    middle = next(r for r in mine if r["rank"] == 1) if len(mine) > 1 else mine[0]
    slowest = max(mine, key=lambda r: r["rank"])
    floor = REFERENCE_MARGIN * reference_error
    targets = sorted({max(middle["true"], floor), max(middle["true"] * (slowest["true"] / middle["true"]) ** (1 / 3), floor)},
                     reverse=True)
    out_rows = []
    for kind, value in [("target", t) for t in targets] + [("limit", max(2.0, round(3 * middle["render_s"], 1)))]:
        out = os.path.join(work, "passes.exr")
        flag = ["--target-error", f"{value:.3g}", "--time-limit", str(PASSES_CAP_S)] if kind == "target" \
            else ["--time-limit", str(value)]
        options = base_options(name, cfg, view) + flag + ["--seed", "1", "--aovs", "none"]
        started = time.time()
        stats, _ = common.render(cfg["file"], out, options)
        wall = time.time() - started
        passes = stats["passes"]
        last = passes["log"][-1]
        true = composite_relmse(out, ref)
        true_4x4 = composite_relmse(averaged_4x4(out, os.path.join(work, "passes4.exr")), ref4)
        seconds = last["elapsed_s"]
        row = {"scene": name, "view": view, "kind": kind, "value": value, "stopped": passes["stopped"],
               "passes": passes["passes"], "record_sets": passes["record_sets"], "passes_total": len(passes["log"]),
               "accuracy": passes["accuracy"], "divisions": passes["divisions"], "seconds": round(seconds, 3),
               "wall_s": round(wall, 3), "estimated": stats["error_estimate"]["relmse"], "true": true,
               "true_4x4": true_4x4, "reference_error": reference_error}
        truth = true - reference_error
        row["true_vs_truth"] = truth if truth >= 0.5 * true else None
        if kind == "target":
            reached = [r for r in ladder if r["true"] <= true]
            fastest = min(reached, key=lambda r: r["render_s"]) if reached else None
            row["fastest_setting"] = fastest["setting"] if fastest else None
            row["fastest_s"] = round(fastest["render_s"], 3) if fastest else None
            row["cost_ratio"] = seconds / fastest["render_s"] if fastest else None
            row["error_ratio"] = true / value
            print(f"[error_estimate] {name}-{view} --target-error {value:.3g}: {passes['stopped']}, "
                  f"{passes['passes']} passes ({passes['record_sets']} record sets) in {seconds:.2f} s; estimate "
                  f"{row['estimated']:.2e}, measured {true:.2e} (x{row['error_ratio']:.2f} the target); fastest "
                  f"fixed setting as good: {row['fastest_s']} s (x{row['cost_ratio'] or float('nan'):.2f})", flush=True)
        else:
            row["time_ratio"] = seconds / value
            print(f"[error_estimate] {name}-{view} --time-limit {value}: {passes['passes']} passes in {seconds:.2f} s "
                  f"(x{row['time_ratio']:.2f} the limit; the process {wall:.2f} s); estimate {row['estimated']:.2e}, "
                  f"measured {true:.2e}", flush=True)
        out_rows.append(row)
    return out_rows


def plot(rows, path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    views = sorted({(r["scene"], r["view"]) for r in rows})
    fig, axes = plt.subplots(1, len(views), figsize=(3.2 * len(views), 3.2), squeeze=False)
    for ax, (scene, view) in zip(axes[0], views):
        mine = sorted((r for r in rows if (r["scene"], r["view"]) == (scene, view)), key=lambda r: r["render_s"])
        t = [r["render_s"] for r in mine]
        ax.loglog(t, [r["true"] for r in mine], "o-", label="measured relMSE")
        ax.loglog(t, [r["estimated"] for r in mine], "s--", label="estimated")
        ax.loglog(t, [r["true_4x4"] for r in mine], "o-", label="measured 4x4")
        ax.loglog(t, [r["estimated_4x4"] for r in mine], "s--", label="estimated 4x4")
        ax.set_title(f"{scene} {view}", fontsize=9)
        ax.set_xlabel("render s")
    axes[0][0].set_ylabel("relMSE")
    axes[0][0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def against_truth(row):
    """The ratios of the estimates to the error against the truth: the error measured less the
    reference's own (the two are independent, so their mean squares add), where it leaves at least
    half of what was measured; else None (the reference is too noisy to tell)."""
    out = {}
    for key, ref_key in (("", "reference_error"), ("_4x4", "reference_error_4x4")):
        true = row["true" + key] - row[ref_key]
        out["ratio" + key] = row["estimated" + key] / true if true >= 0.5 * row["true" + key] else None
    return out


def true_ratio(row):
    """The true error over the target: the measured error less the reference's own (their mean
    squares add), where that leaves at least half of what was measured; else None."""
    true = float(row["true"]) - float(row["reference_error"])
    return true / float(row["value"]) if true >= 0.5 * float(row["true"]) else None


def passes_lines(passes):
    """The page's section on --target-error and --time-limit."""
    shown = lambda v, f="{:.2f}": "-" if v in (None, "") else f.format(float(v))  # noqa: E731
    targets = [r for r in passes if r["kind"] == "target"]
    limits = [r for r in passes if r["kind"] == "limit"]
    lines = ["## Passes: `--target-error` and `--time-limit`", "",
             "Every run once, seed 1. `measured` includes the reference's own error (`ref` above), `true` is it less "
             "the reference's own (where that leaves at least half); "
             "`fastest fixed`: the fastest of the peers bench's settings whose measured error is no higher; `s`: when "
             "the last pass ended (after the scene's load, as `render s`).", "",
             "| view | target | stopped | passes (sets) | -aa, -ad | s | estimated | measured | measured / target "
             "| true / target | fastest fixed s | s / fastest |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in targets:
        lines.append(f"| {r['scene']} {r['view']} | {float(r['value']):.2e} | {r['stopped']} | {r['passes']} of "
                     f"{r['passes_total']} ({r['record_sets']}) | {float(r['accuracy']):.3f}, {r['divisions']} | "
                     f"{r['seconds']} | {float(r['estimated']):.2e} | {float(r['true']):.2e} | "
                     f"{shown(r['error_ratio'])} | {shown(true_ratio(r))} | {shown(r['fastest_s'], '{:.3f}')} | "
                     f"{shown(r['cost_ratio'])} |")
    lines += ["", "| view | limit s | last pass ended s | / limit | passes (sets) | process s | estimated | measured |",
              "|---|---|---|---|---|---|---|---|"]
    for r in limits:
        lines.append(f"| {r['scene']} {r['view']} | {r['value']} | {r['seconds']} | {shown(r['time_ratio'])} | "
                     f"{r['passes']} of {r['passes_total']} ({r['record_sets']}) | {r['wall_s']} | "
                     f"{float(r['estimated']):.2e} | {float(r['true']):.2e} |")
    judged = [r for r in targets if true_ratio(r) is not None]
    ok_error = [r for r in judged if true_ratio(r) <= TARGET_ERROR_FACTOR]
    ok_measured = [r for r in targets if float(r["error_ratio"]) <= TARGET_ERROR_FACTOR]
    ok_time = [r for r in limits if float(r["time_ratio"]) <= TIME_LIMIT_FACTOR]
    costed = [r for r in targets if r["cost_ratio"] not in (None, "")]
    ok_cost = [r for r in costed if float(r["cost_ratio"]) <= COST_FACTOR]
    cost_ratios = sorted(float(r["cost_ratio"]) for r in costed) or [float("nan")]
    lines += ["", f"Targets: `--target-error E` ends with a true relMSE of at most {TARGET_ERROR_FACTOR} E; "
              f"`--time-limit S` within {TIME_LIMIT_FACTOR} S; reaching a target costs at most {COST_FACTOR}x the "
              "fastest fixed setting that reaches the same error.", "",
              f"- true error (measured less the reference's own, where that leaves at least half) at most "
              f"{TARGET_ERROR_FACTOR} E: {len(ok_error)} of {len(judged)} (of {len(targets)}); the measured error, the "
              f"reference's own in it, at most {TARGET_ERROR_FACTOR} E: {len(ok_measured)} of {len(targets)}.",
              f"- within {TIME_LIMIT_FACTOR} S: {len(ok_time)} of {len(limits)}.",
              f"- at most {COST_FACTOR}x the fastest fixed setting: {len(ok_cost)} of {len(costed)} with a fixed setting "
              f"as good (of {len(targets)}); the ratio from {cost_ratios[0]:.2f} to {cost_ratios[-1]:.2f}, median "
              f"{statistics.median(cost_ratios):.2f}.", ""]
    return lines


def page(rows, minutes, quick, passes=()):
    for r in rows:
        r.update({f"{k}_vs_truth": v for k, v in against_truth(r).items()})
    judged = [r for r in rows if r["ratio_vs_truth"] is not None]
    judged_4x4 = [r for r in rows if r["ratio_4x4_vs_truth"] is not None]
    within = [r for r in judged if 1 / TARGET_FACTOR <= r["ratio_vs_truth"] <= TARGET_FACTOR]
    within_4x4 = [r for r in judged_4x4 if 1 / TARGET_FACTOR <= r["ratio_4x4_vs_truth"] <= TARGET_FACTOR]
    ratios = sorted(r["ratio_vs_truth"] for r in judged) or [float("nan")]
    ratios_4x4 = sorted(r["ratio_4x4_vs_truth"] for r in judged_4x4) or [float("nan")]
    shown = lambda v: "-" if v is None else f"{v:.2f}"  # noqa: E731
    lines = ["# The error estimate against the true error", "",
             f"Written by `python3 bench/error_estimate.py` on {datetime.date.today()} ({minutes:.1f} min, "
             f"{os.cpu_count()} cores){' with --quick: not a result' if quick else ''}; every run in "
             "[error_estimate/runs.csv](error_estimate/runs.csv). How the estimate is made: [error.md](error.md).",
             "", "The peers bench's views at a reduced size, its fastest, middle and slowest settings, two seeds "
             "each, against a brute-force reference (`icrender reference`, --lambertian). `ref` is the "
             "reference's own relMSE (half its distance from a second reference of other seeds): it is in every "
             "true error.", "",
             "true error.  `ratio`: estimated over measured; `vs truth`: estimated over measured less the "
             "reference's own (their mean squares add), shown where that leaves at least half of what was measured.",
             "",
             "| view | setting | seed | render s | estimate s | estimated | measured | ratio | vs truth | estimated 4x4 "
             "| measured 4x4 | ratio 4x4 | vs truth 4x4 | ref | ref 4x4 |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['scene']} {r['view']} | `{r['setting']}` | {r['seed']} | {r['render_s']} | "
                     f"{r['estimate_s']} | {r['estimated']:.2e} | {r['true']:.2e} | {r['ratio']:.2f} | "
                     f"{shown(r['ratio_vs_truth'])} | {r['estimated_4x4']:.2e} | {r['true_4x4']:.2e} | "
                     f"{r['ratio_4x4']:.2f} | {shown(r['ratio_4x4_vs_truth'])} | "
                     f"{r['reference_error']:.1e} | {r['reference_error_4x4']:.1e} |")
    lines += ["", "![estimated and true error against the render's time](error_estimate/error_estimate.png)", "",
              "Target: every estimate within a factor of 2 of the true relMSE.", "",
              f"- relMSE against the truth: {len(within)} of the {len(judged)} runs whose reference can tell "
              f"(of {len(rows)}) within; the ratio from {ratios[0]:.2f} to {ratios[-1]:.2f}, median "
              f"{statistics.median(ratios):.2f}.",
              f"- 4x4 relMSE against the truth: {len(within_4x4)} of {len(judged_4x4)} within; from "
              f"{ratios_4x4[0]:.2f} to {ratios_4x4[-1]:.2f}, median {statistics.median(ratios_4x4):.2f}.",
              f"- Met: {'yes' if len(within) == len(judged) == len(rows) and len(within_4x4) == len(judged_4x4) == len(rows) else 'no'}"
              f"{'' if len(judged) == len(judged_4x4) == len(rows) else ' (not every run could be judged: its reference was too noisy)'}.",
              ""]
    if passes:
        lines += passes_lines(passes)
    with open(os.path.join(DOCS, "ERROR_ESTIMATE.md"), "w") as f:
        f.write("\n".join(lines))
    print(f"wrote {os.path.join(DOCS, 'ERROR_ESTIMATE.md')}")


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="the Cornell box's first view, one setting: a check")
    parser.add_argument("--page-only", type=float, metavar="MINUTES",
                        help="write the page again from docs/error_estimate/runs.csv (the runs took MINUTES)")
    args = parser.parse_args()
    folder = os.path.join(DOCS, "error_estimate")
    if args.page_only is not None:
        rows = common.read_csv(os.path.join(folder, "runs.csv"))
        passes_csv = os.path.join(folder, "passes.csv")
        passes = common.read_csv(passes_csv) if os.path.exists(passes_csv) else []
        plot(rows, os.path.join(folder, "error_estimate.png"))
        page(rows, args.page_only, args.quick, passes)
        return
    common.require("bench/error_estimate.py", modules=["matplotlib"], commands=["oiiotool"])
    common.build()
    work = common.scratch()
    started = time.time()
    rows, passes = [], []
    for name, cfg in SCENES.items():
        for view in cfg["views"]:
            mine, ref, ref4, reference_error = measure(name, cfg, view, work, args.quick)
            rows += mine
            passes += passes_runs(name, cfg, view, work, ref, ref4, reference_error, mine, args.quick)
            if args.quick:
                break
        if args.quick:
            break
    os.makedirs(folder, exist_ok=True)
    common.write_csv(os.path.join(folder, "runs.csv"), rows)
    common.write_csv(os.path.join(folder, "passes.csv"), passes)
    plot(rows, os.path.join(folder, "error_estimate.png"))
    page(rows, (time.time() - started) / 60, args.quick, passes)


if __name__ == "__main__":
    main()
