"""Plots of bench/paper.py (the paper's Figures 3, 7, 8, 9, 10 and Table 1, and the prediction)."""

import os

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

MODES = ["noshare", "centralised", "broadcast", "component"]
COLOURS = {"serial": "gray", "noshare": "tab:red", "centralised": "tab:blue", "broadcast": "tab:green",
           "component": "tab:purple"}


def _save(fig, out_dir, name, made):
    fig.savefig(os.path.join(out_dir, name), dpi=90, bbox_inches="tight")
    plt.close(fig)
    made.append(name)


def make_all(out_dir, runs, gains, sim_rows, pred_rows, scenes):
    made = []
    # Figure 7: speed-up and efficiency against the serial run (work speed-up: CPU time).
    fig, axes = plt.subplots(2, len(scenes), figsize=(4.5 * len(scenes), 7), squeeze=False)
    for i, name in enumerate(scenes):
        mine = [r for r in runs if r["scene"] == name and r["mode"] in MODES]
        for mode in MODES:
            pts = sorted((r["workers"], r["work_speedup"], r["efficiency_pct"], r["wall_speedup"])
                         for r in mine if r["mode"] == mode)
            if not pts:
                continue
            axes[0][i].plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=COLOURS[mode], label=mode)
            axes[0][i].plot([p[0] for p in pts], [p[3] for p in pts], "x:", color=COLOURS[mode], alpha=0.5)
            axes[1][i].plot([p[0] for p in pts], [p[2] for p in pts], "o-", color=COLOURS[mode], label=mode)
        ws = sorted({r["workers"] for r in mine})
        if ws:
            axes[0][i].plot(ws, ws, "k--", lw=0.8, label="linear")
        axes[1][i].axhline(100, color="k", ls="--", lw=0.8)
        axes[0][i].set_title(f"{name}: speed-up (o work, x wall)", fontsize=9)
        axes[1][i].set_title(f"{name}: efficiency % (work)", fontsize=9)
        for ax in axes[:, i]:
            ax.set_xlabel("processors (workers)")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
    _save(fig, out_dir, "fig7-speedup.png", made)

    # Figures 3, 8, 9: aggregated time and cache misses per mode.
    fig, axes = plt.subplots(2, len(scenes), figsize=(4.5 * len(scenes), 7), squeeze=False)
    for i, name in enumerate(scenes):
        mine = [r for r in runs if r["scene"] == name]
        serial = [r for r in mine if r["mode"] == "serial"]
        for mode in MODES:
            pts = sorted((r["workers"], r["misses"], r["aggregated_s"]) for r in mine if r["mode"] == mode)
            if not pts:
                continue
            axes[0][i].plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=COLOURS[mode], label=mode)
            axes[1][i].plot([p[0] for p in pts], [p[2] for p in pts], "o-", color=COLOURS[mode], label=mode)
        if serial:
            axes[0][i].axhline(serial[0]["misses"], color="gray", ls=":", label="serial")
            axes[1][i].axhline(serial[0]["aggregated_s"], color="gray", ls=":", label="serial")
        axes[0][i].set_title(f"{name}: aggregated cache misses", fontsize=9)
        axes[1][i].set_title(f"{name}: aggregated time T_amb+T_notamb (CPU s)", fontsize=9)
        for ax in axes[:, i]:
            ax.set_xlabel("processors (workers)")
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
    _save(fig, out_dir, "fig3-8-9-misses-time.png", made)

    # Figure 10: idle time percentage.
    fig, axes = plt.subplots(1, len(scenes), figsize=(4.5 * len(scenes), 3.5), squeeze=False)
    for i, name in enumerate(scenes):
        for mode in MODES:
            pts = sorted((r["workers"], r["idle_pct"]) for r in runs if r["scene"] == name and r["mode"] == mode)
            if pts:
                axes[0][i].plot([p[0] for p in pts], [p[1] for p in pts], "o-", color=COLOURS[mode], label=mode)
        axes[0][i].set_title(f"{name}: idle time (% of aggregated)", fontsize=9)
        axes[0][i].set_xlabel("processors (workers)")
        axes[0][i].grid(True, alpha=0.3)
        axes[0][i].legend(fontsize=7)
    _save(fig, out_dir, "fig10-idle.png", made)

    # Table 1 as bars: gain of component mode over the second-best mode, each setting, with the
    # bootstrap intervals from the repeats as error bars.
    if gains:
        settings = [s for s in ("paper", "default") if any(g.get("setting", "paper") == s for g in gains)]
        titles = {"paper": "the paper's setting", "default": "every mode at its default"}
        fig, axes = plt.subplots(1, len(settings), figsize=(6 * len(settings), 3.5), squeeze=False)
        ws = sorted({g["workers"] for g in gains})
        width = 0.8 / max(len(scenes), 1)
        for ax, setting in zip(axes[0], settings):
            mine = [g for g in gains if g.get("setting", "paper") == setting]
            for k, name in enumerate(scenes):
                found = [next((g for g in mine if g["scene"] == name and g["workers"] == w), None) for w in ws]
                vals = [g["gain_pct"] if g else 0 for g in found]
                err = [[g["gain_pct"] - g["gain_lo"] if g and g.get("gain_lo") == g.get("gain_lo") else 0
                        for g in found],
                       [g["gain_hi"] - g["gain_pct"] if g and g.get("gain_hi") == g.get("gain_hi") else 0
                        for g in found]]
                ax.bar([j + k * width for j in range(len(ws))], vals, width, yerr=err, capsize=3, label=name)
            ax.set_xticks([j + width * (len(scenes) - 1) / 2 for j in range(len(ws))])
            ax.set_xticklabels([str(w) for w in ws])
            ax.axhline(0, color="k", lw=0.8)
            ax.set_xlabel("processors (workers)")
            ax.set_title(f"gain over the second-best mode (work speed-up, %), {titles[setting]}", fontsize=8)
            ax.legend(fontsize=7)
        _save(fig, out_dir, "table1-gain.png", made)

    # Validation: simulated against measured misses and aggregated time.
    if sim_rows:
        fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
        for mode in ["serial"] + MODES:
            pts = [r for r in sim_rows if r["mode"] == mode]
            if not pts:
                continue
            axes[0].scatter([r["real_misses"] for r in pts], [r["sim_misses"] for r in pts], color=COLOURS[mode],
                            label=mode, s=18)
            axes[1].scatter([r["real_aggregated_s"] for r in pts], [r["sim_aggregated_s"] for r in pts],
                            color=COLOURS[mode], label=mode, s=18)
        for ax, title in zip(axes, ["aggregated misses", "aggregated time (CPU s)"]):
            lo, hi = ax.get_xlim()
            lo2, hi2 = ax.get_ylim()
            lo, hi = min(lo, lo2), max(hi, hi2)
            ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
            ax.plot([lo, hi], [lo * 0.85, hi * 0.85], "k:", lw=0.6)
            ax.plot([lo, hi], [lo * 1.15, hi * 1.15], "k:", lw=0.6)
            ax.set_xlabel("measured")
            ax.set_ylabel("simulated")
            ax.set_title(f"simulation vs measurement: {title} (dotted: +-15%)", fontsize=9)
            ax.grid(True, alpha=0.3)
            ax.legend(fontsize=7)
        _save(fig, out_dir, "validation.png", made)

    # Prediction: speed-up, idle and misses at 4 .. 1024 processors, two networks.
    if pred_rows:
        nets = sorted({r["network"] for r in pred_rows})
        for net in nets:
            fig, axes = plt.subplots(3, len(scenes), figsize=(4.5 * len(scenes), 10), squeeze=False)
            for i, name in enumerate(scenes):
                mine = [r for r in pred_rows if r["scene"] == name and r["network"] == net]
                for mode in MODES:
                    pts = sorted((r["workers"], r["speedup"], r["idle_pct"], r["misses"]) for r in mine
                                 if r["mode"] == mode)
                    if not pts:
                        continue
                    xs = [p[0] for p in pts]
                    axes[0][i].plot(xs, [p[1] for p in pts], "o-", color=COLOURS[mode], label=mode, ms=3)
                    axes[1][i].plot(xs, [p[2] for p in pts], "o-", color=COLOURS[mode], label=mode, ms=3)
                    axes[2][i].plot(xs, [p[3] for p in pts], "o-", color=COLOURS[mode], label=mode, ms=3)
                if mine:
                    xs = sorted({r["workers"] for r in mine})
                    axes[0][i].plot(xs, xs, "k--", lw=0.8, label="linear")
                    axes[2][i].axhline(mine[0]["serial_misses"], color="gray", ls=":", label="serial")
                    size = f"{mine[0]['width']}x{mine[0]['height']}"
                else:
                    size = "?"
                axes[0][i].set_title(f"{name} {size}, {net}: predicted speed-up", fontsize=9)
                axes[1][i].set_title(f"{name}: predicted idle time %", fontsize=9)
                axes[2][i].set_title(f"{name}: predicted aggregated misses", fontsize=9)
                for ax in axes[:, i]:
                    ax.set_xscale("log", base=2)
                    ax.set_xlabel("processors (workers)")
                    ax.grid(True, alpha=0.3)
                    ax.legend(fontsize=7)
                axes[0][i].set_yscale("log", base=2)
            _save(fig, out_dir, f"prediction-{net}.png", made)
    return made
