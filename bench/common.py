"""Shared helpers of the bench scripts: building and running icrender, reading its numbers.

Benchmarks print figures and write CSVs and plots; they assert nothing (tests do that).
"""

import csv
import importlib
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SHARED_SCENES = os.path.normpath(os.path.join(ROOT, "..", "shared", "scenes"))
# Where cargo puts it: $CARGO_TARGET_DIR when set (a worktree sharing a build directory), else target/.
BINARY = os.path.join(ROOT, os.environ.get("CARGO_TARGET_DIR") or "target", "release", "icrender")


def build():
    """Builds the release binary (quietly) and returns its path."""
    subprocess.run(["cargo", "build", "--release", "--quiet"], cwd=ROOT, check=True)
    return BINARY


# One command that installs every bench's Python dependencies at the versions they were run with.
INSTALL_HINT = "python3 -m venv .venv && . .venv/bin/activate && pip install -r bench/requirements.txt"


def require(script, modules=(), commands=()):
    """Stops at once, with one line, when a Python package or a program the bench needs is
    missing, so that no bench renders for minutes and then fails at its first plot."""
    missing = [m for m in modules if importlib.util.find_spec(m) is None]
    if missing:
        sys.exit(f"{script}: needs the Python package(s) {', '.join(missing)}, not installed for {sys.executable}; "
                 f"install the benches' pinned dependencies with: {INSTALL_HINT}")
    absent = [c for c in commands if shutil.which(c) is None]
    if absent:
        sys.exit(f"{script}: needs {', '.join(absent)} on the PATH (bash scripts/install-deps.sh installs Open MPI)")


def ensure_module(name, package=None):
    """Imports a module the bench has checked with require() before starting its work."""
    del package  # the pip name; require() names it in its message
    return importlib.import_module(name)


# The paper's modes make their records as they render (the renderer's default, the prepass,
# places every record first and leaves the modes nothing to share): every run of the paper's
# comparison builds its cache progressively.
# With one sample in every pixel, as the paper's renderers took (--edge-samples defaults to 4),
# and PRs that wait for a PA that is behind rather than compute its requests (--pr-waits).
PAPER_BUILD = ["--ic-build", "progressive", "--edge-samples", "0", "--pr-waits"]
# Scanline order without the overture (--overture 0): how the paper's renderers computed, and the
# order of the serial runs whose cache traces bench/icsim.py replays.
RASTER_ORDER = PAPER_BUILD + ["--overture", "0"]
# The renderer's default --overture (src/job.rs DEFAULT_OVERTURE); in component mode, the grid
# whose requests a PA computes first (src/parallel/component/order.rs).
DEFAULT_OVERTURE = 3


def render(scene, out, options, reference=None):
    """Runs `icrender render`; returns (stats dict, {layer: (rmse, relmse)} against reference)."""
    stats_path = out + ".json"
    cmd = [BINARY, "render", scene, "-o", out, "-q", "--no-preview", "--overwrite", "--stats", stats_path] + options
    if reference:
        cmd += ["--reference", reference]
    result = subprocess.run(cmd, capture_output=True, text=True)
    if result.returncode != 0:
        raise RuntimeError(f"icrender failed: {' '.join(cmd)}\n{result.stderr}")
    with open(stats_path) as f:
        stats = json.load(f)
    errors = {}
    for line in result.stdout.splitlines():
        parts = line.split()
        if len(parts) >= 6 and parts[0] == "error":
            errors[parts[1]] = (float(parts[3]), float(parts[5]))
    return stats, errors


def compare(image, reference):
    """`icrender compare --json`: {layer: (rmse, relmse)}."""
    result = subprocess.run([BINARY, "compare", image, reference, "--json"], capture_output=True, text=True, check=True)
    return {e["layer"]: (e["rmse"], e["rel_mse"]) for e in json.loads(result.stdout)}


def reference(scene, out, options, noise=0.003, max_seconds=600):
    """Renders (or reuses) a converged brute-force reference."""
    if os.path.exists(out):
        return out
    cmd = [BINARY, "reference", scene, "-o", out, "-q", "--no-preview", "--noise", str(noise), "--max-seconds", str(max_seconds)] + options
    subprocess.run(cmd, check=True)
    return out


def scratch():
    return tempfile.mkdtemp(prefix="icrender-bench-")


def read_csv(path):
    """A CSV written by `write_csv`, each value a number where it reads as one."""
    def value(text):
        for kind in (int, float):
            try:
                return kind(text)
            except ValueError:
                pass
        return text
    with open(path, newline="") as f:
        return [{k: value(v) for k, v in row.items()} for row in csv.DictReader(f)]


def write_csv(path, rows):
    """Rows (dicts) as a CSV whose columns are every key in order of first appearance; nothing
    is written for no rows."""
    if not rows:
        return
    keys = []
    for r in rows:
        keys += [k for k in r if k not in keys]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
