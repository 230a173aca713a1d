#!/usr/bin/env python3
"""A simulation of the default build (`--ic-build prepass`) under mpirun, validated against
measured runs and then used to predict a 4K conference frame on 4 to 1,024 ranks.

The sibling of bench/icsim.py, which replays the progressive modes' cache traces. The prepass
needs no trace: its work is a fixed sequence of phases, the same on every rank count, whose
sizes come from a one-process run's --stats (`prepass_round_log`: sites, records and compute
seconds per round) and whose costs come from that run's times. How the default build runs under
mpirun (src/parallel/prepass.rs, src/prepass/mod.rs, src/parallel/ahead.rs, src/parallel/master.rs
and worker.rs): rank 0 is a master that renders nothing and takes no part in the rounds; the
W = P - 1 workers share every list interleaved (worker k takes items k, k + W, ...) on a
communicator of their own, and every exchange among them is an allgather polled with pauses.

  load       every rank loads the scene and builds its BVH (in parallel on a cluster; ranks
             sharing cores here take turns).
  grid       the last bounce's grid: its rows shared by the workers, then an allgather among
             the workers (48 bytes a sample, src/parallel/protocol PrepassGrid).
  rounds     ~70 coarse-to-fine rounds. Per round a worker looks up its ceil(S/W) sites
             (`site_s` each) and computes a record where none covers one (`record_s` each);
             the round waits for the slowest worker, whose records are the expected maximum of
             the round's R records dealt to W workers (binomial, each record independently on
             any worker: the sites are interleaved, so clusters are spread), then two
             allgathers among the W workers (lengths, then 4 + 128 bytes a record), then every
             worker inserts the records and shrinks them where neighbours disagree (the serial
             part of a round: the one-process round's seconds beyond its compute). The first
             worker hands each round's records to the master once, from a thread of its own
             (off the critical path; its bytes are counted).
  ahead      component mode: a worker waiting at a round's barrier traces its tiles' eye paths,
             direct and specular light meanwhile (src/parallel/ahead.rs), and what it traced
             leaves its final pass: a share of its waits (the share tracing filled in a
             calibration run) up to the traceable share of its final pass (that run's trace
             seconds a pixel over the final pass's) and the 64 MiB of traces it may hold.
  maps       the edge map's strips shared by the workers, bit-packed, allgathered among them.
  samples    the edge pixels' sample rounds: more rounds as above.
  fit        the record set's curvature fit and freeze (serial, on every worker: the
             one-process run's `prepass_fit_s`).
  final      tiles on demand: a worker sends the finished tile (the file's chunks it compressed,
             and the preview's pixels) with its next request and waits for the master's reply;
             the master takes the tiles one at a time, so its link carries the whole image.

The collective. Open MPI 4.1's libnbc (what `MPI_Iallgatherv` runs here; `ompi_info --param coll
libnbc` offers no algorithm choice for it) is linear: each rank posts a receive from and a send
to each of the P - 1 others at once (ompi/mca/coll/libnbc/nbc_iallgatherv.c, "simple linear",
p - 1 pairs in one schedule round); its iallgather of the lengths is linear too unless forced.
Modelled as latency + (P - 1) per-message overheads + the busiest link's bytes over the
bandwidth (a rank sends its part P - 1 times and receives everyone else's). The alternatives
(`--algorithm ring|bruck`) replace that by P - 1 or ceil(log2 P) steps, each paying latency.

Polling. A worker waiting in a collective sleeps between tests with pauses that double to
0.2 ms (src/parallel/comm.rs COLLECTIVE_MAX_PAUSE); one tracing ahead tests between steps of 16
pixels. The data allgather cannot complete before every worker has seen the lengths' and posted
its part, so a round pays the longest pause of the workers that waited.

Ranks sharing cores (this machine, mpirun --oversubscribe): the compute of a phase takes
max(slowest rank, all ranks' work / cores) with the effective cores measured by a one-process
run at 2 threads against 1; the parts every rank repeats (load, insert, fit) take P / cores
times as long.

Run (needs the release binary, mpirun, and root for the test bed's namespaces):

    python3 bench/prepass_sim.py                 # profile, measure, validate, predict; writes docs/
    python3 bench/prepass_sim.py --simulate-only # re-simulate from the CSVs of the last run

Writes bench/out/prepass-*.csv and docs/scaling/*.csv, and docs/SCALING.md from its own output.
"""

import argparse
import csv
import json
import math
import os
import shutil
import signal
import statistics
import subprocess
import sys
import time

import common
import icsim

RECORD_WIRE = 4 + icsim.RECORD_BYTES  # a round's record: its site's index and the record
GRID_SAMPLE_BYTES = 48  # position, normal, direct and indirect light: four vec3
ROW_HEADER = 8  # a row's y and its length (u32 each)
# A finished tile's bytes a pixel and the master's seconds a pixel storing it come from the
# -np 2 calibration run (--stats per_rank[0] tile_bytes and tiles_s): the workers send the file's
# compressed chunks (src/image/layered_exr.rs TileChunks) and the master only writes them.
LENGTH_BYTES = 8  # each rank's part length in the first allgather (u64)
EDGE_STRIP = 8  # src/prepass/mod.rs: rows of an edge map's strip
MAX_SITE_PIXELS = 1 << 18  # src/irradiance/last_bounce.rs: the grid's sites at most
MAX_PAUSE, MASTER_MAX_PAUSE = 0.5e-3, 0.1e-3  # src/parallel/comm.rs
LONG_WAIT, LONG_WAIT_PAUSE = 20e-3, 5e-3  # src/parallel/comm.rs
COLLECTIVE_MAX_PAUSE = 0.2e-3  # src/parallel/comm.rs: a wait in the prepass's collectives
KEPT_HEADER = 1 + 8 * 6 + 4  # a round's log and record count, as the first worker hands it to the master
# src/parallel/ahead.rs: the traces a worker may hold, and about what a traced pixel holds.
TRACE_BYTES_LIMIT, TRACE_BYTES_PER_PIXEL = 64 << 20, 400
# Per-message CPU cost of posting and progressing one point-to-point part of a collective
# (LogP's gap): an assumption, not measured here. TCP through the kernel a few microseconds;
# an RDMA network (what 100 Gbit clusters run MPI over) under one.
GAP = {"tcp": 5e-6, "rdma": 0.5e-6}
# The networks of the prediction: latency, bandwidth, gap. 1 Gbit: the test bed's switch and TCP
# stack; 100 Gbit: an RDMA fabric (icsim.NETWORKS's latency and bandwidth).
NETWORKS = {"1gbit": icsim.NETWORKS["1gbit"] + (GAP["tcp"],),
            "100gbit": icsim.NETWORKS["100gbit"] + (GAP["rdma"],)}
CONFERENCE = os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf")
CORNELL = os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf")
MPI_ENV = {"OMPI_ALLOW_RUN_AS_ROOT": "1", "OMPI_ALLOW_RUN_AS_ROOT_CONFIRM": "1",
           "OMPI_MCA_btl_tcp_if_include": "lo", "OMPI_MCA_oob_tcp_if_include": "lo"}
OUT = os.path.join(common.ROOT, "bench", "out")
DOCS = os.path.join(common.ROOT, "docs")


# -- what a one-process run says ----------------------------------------------------------------

def fit_costs(rounds):
    """Seconds per site looked up and per record made, least squares without intercept over the
    rounds' (sites, records) -> compute seconds; both kept positive (a round of lookups alone
    still pins the site's cost, rounds rich in records the record's)."""
    sxx = sum(r["sites"] ** 2 for r in rounds)
    syy = sum(r["records"] ** 2 for r in rounds)
    sxy = sum(r["sites"] * r["records"] for r in rounds)
    sxt = sum(r["sites"] * r["compute_s"] for r in rounds)
    syt = sum(r["records"] * r["compute_s"] for r in rounds)
    det = sxx * syy - sxy * sxy
    site = (sxt * syy - syt * sxy) / det if det else 0.0
    record = (syt * sxx - sxt * sxy) / det if det else 0.0
    if site <= 0 or record <= 0:  # one of them swamped: fit the other alone
        if record <= 0:
            site, record = sxt / sxx, 0.0
        else:
            site, record = 0.0, syt / syy
    return site, record


def uncontended(stats):
    """A one-process run's times as if it had had its core to itself: scaled by its threads' CPU
    seconds over their busy (wall) seconds. Other engineers' jobs share this machine's 2 cores;
    a run that got half a core took twice as long, and the profile's costs would be doubled.
    The measured mpirun runs are not corrected (their load average is kept instead)."""
    k = 1.0 / max(stats.get("busy_over_cpu") or 1.0, 1.0)
    out = dict(stats)
    for key in ("wall_s", "load_s", "build_s", "render_s", "prepass_s", "prepass_fit_s"):
        if key in stats and stats[key] is not None:
            out[key] = stats[key] * k
    out["prepass_round_log"] = [{key: (v * k if key.endswith("_s") or key == "seconds" else v) for key, v in r.items()}
                                for r in stats["prepass_round_log"]]
    return out


class Profile:
    """A one-process run (--threads 1) of a scene, size and options: the rounds and the phases'
    seconds. `gap_s` (prepass time outside the rounds: the grid, the edge map and the fit) is
    split with a second run without the edge map (`noedge`, --edge-samples 1): its gap is the
    grid and the fit."""

    def __init__(self, stats, noedge=None, threads2=None, fit_s=None, mpi_extra_s=0.0):
        self.mpi_extra_s = mpi_extra_s or 0.0
        self.contention = stats.get("busy_over_cpu") or 1.0
        stats = uncontended(stats)
        noedge = uncontended(noedge) if noedge else None
        threads2 = uncontended(threads2) if threads2 else None
        self.width, self.height = stats["width"], stats["height"]
        self.pixels = self.width * self.height
        self.rounds = [{"sites": r["sites"], "records": r["records"], "compute_s": r["compute_s"],
                        "serial_s": max(r["seconds"] - r["compute_s"] - r["pool_s"], 0.0)}
                       for r in stats["prepass_round_log"]]
        self.site_s, self.record_s = fit_costs(self.rounds)
        self.serial_per_record = (sum(r["serial_s"] for r in self.rounds)
                                  / max(sum(r["records"] for r in self.rounds), 1))
        gap = stats["prepass_s"] - sum(r["compute_s"] + r["serial_s"] for r in self.rounds)
        if noedge is not None:
            grid_fit = noedge["prepass_s"] - sum(r["seconds"] for r in noedge["prepass_round_log"])
            self.edge_s = max(gap - grid_fit, 0.0)
        else:
            grid_fit, self.edge_s = gap, 0.0
        # The fit and freeze at the end (the run's own `prepass_fit_s`); the grid is the rest
        # of the gap.
        fit_s = stats.get("prepass_fit_s") if fit_s is None else fit_s
        self.fit_s = min(fit_s or 0.0, grid_fit)
        self.grid_s = max(grid_fit - self.fit_s, 0.0)
        self.grid_samples = stats.get("last_bounce_samples", 0)
        self.grid_rows = math.ceil(self.height / site_stride(self.width, self.height))
        # One process's render_s holds its prepass; the final pass is the rest.
        self.final_s = max(stats["render_s"] - stats["prepass_s"], 0.0)
        self.load_s = stats["load_s"] + stats["build_s"]
        self.wall_s = stats["wall_s"]
        self.records = stats["prepass_records"]
        # Effective cores of this machine for the compute: one thread's compute over two's.
        self.cores = 1.0
        if threads2 is not None:
            one = sum(r["compute_s"] for r in self.rounds) + self.final_s
            two = (sum(r["compute_s"] for r in threads2["prepass_round_log"])
                   + threads2["render_s"] - threads2["prepass_s"])
            self.cores = max(1.0, min(2.0, one / two)) if two > 0 else 1.0

    # A tile's cost of going through the master (encoding, the rendezvous of a large message
    # polled with pauses, storing it) beyond its bytes on the link: from a calibration run.
    tile_overhead_s = 0.0
    # A finished tile's bytes a pixel on the wire, and the master's seconds a pixel storing it
    # (from the calibration run; until then the pixels' values and no cost).
    tile_wire = 4 * (13 + 13 + 4 * 6)
    master_pixel_s = 0.0
    # Component mode's tracing ahead (a calibration run at -np 3): the share of a worker's
    # seconds in the collectives that tracing filled, and the seconds a traced pixel took.
    ahead_fill = 0.0
    ahead_pixel_s = 0.0

    def tiles(self):
        return math.ceil(self.width / 32) * math.ceil(self.height / 32)

    def one_process(self):
        """The phases' seconds of this profile as one process, one thread (the model's own sum,
        to compare with the run's wall time)."""
        return (self.load_s + self.grid_s + sum(r["compute_s"] + r["serial_s"] for r in self.rounds) + self.edge_s
                + self.fit_s + self.final_s)

    def scaled_to(self, stats):
        """This profile's costs on the rounds of another size's run (`stats`: a one-process
        `cache` or `render` run, whose sites and records per round are taken as they are and
        whose times are not used): the grid by its sites (capped at MAX_SITE_PIXELS), the edge
        map and the final pass by the pixels, the fit by the records."""
        out = Profile.__new__(Profile)
        out.__dict__.update(self.__dict__)
        out.width, out.height = stats["width"], stats["height"]
        out.pixels = out.width * out.height
        out.rounds = [{"sites": r["sites"], "records": r["records"],
                       "compute_s": r["sites"] * self.site_s + r["records"] * self.record_s,
                       "serial_s": r["records"] * self.serial_per_record} for r in stats["prepass_round_log"]]
        grid_sites = lambda w, h: math.ceil(w / site_stride(w, h)) * math.ceil(h / site_stride(w, h))
        g = grid_sites(out.width, out.height) / grid_sites(self.width, self.height)
        out.grid_s, out.grid_samples = self.grid_s * g, int(self.grid_samples * g)
        out.grid_rows = math.ceil(out.height / site_stride(out.width, out.height))
        k = out.pixels / self.pixels
        out.edge_s, out.final_s = self.edge_s * k, self.final_s * k
        out.records = stats["prepass_records"]
        out.fit_s = self.fit_s * out.records / max(self.records, 1)
        out.wall_s = None
        return out

    def summary(self):
        return (f"{self.width}x{self.height}: {len(self.rounds)} rounds, {sum(r['sites'] for r in self.rounds)} sites, "
                f"{self.records} records; site {self.site_s * 1e6:.2f} us, record {self.record_s * 1e3:.3f} ms; grid "
                f"{self.grid_s:.2f} s, edge map {self.edge_s:.2f} s, fit {self.fit_s:.2f} s, rounds' serial "
                f"{sum(r['serial_s'] for r in self.rounds):.2f} s, final pass {self.final_s:.2f} s, load+BVH "
                f"{self.load_s:.2f} s, wall {self.wall_s:.2f} s;"
                + (f" effective cores {self.cores:.2f};" if self.cores != 1.0 else "") + f" times divided by "
                f"{self.contention:.2f}, the run's busy over CPU seconds")


def site_stride(width, height):
    """src/irradiance/last_bounce.rs site_stride: the grid's sites spaced to stay within
    MAX_SITE_PIXELS."""
    s = 1
    while math.ceil(width / s) * math.ceil(height / s) > MAX_SITE_PIXELS:
        s += 1
    return s


# -- the pieces of the model ----------------------------------------------------------------------

def binomial_max(n, workers):
    """Expected largest share of n items dealt to `workers` independently and uniformly:
    sum over k >= 1 of P(max >= k), the shares taken as independent binomials."""
    if workers <= 1 or n == 0:
        return float(n)
    p = 1.0 / workers
    mean, sd = n * p, math.sqrt(n * p * (1 - p))
    if mean > 200:  # normal enough: the mean plus the expected maximum of `workers` normals
        return mean + sd * expected_max_normal(workers)
    # The binomial's CDF term by term up to far past the mean.
    top = int(mean + 12 * sd + 12)
    logp, log1p = math.log(p), math.log1p(-p)
    cdf, out = 0.0, 0.0
    for k in range(0, min(top, n) + 1):
        cdf += math.exp(math.lgamma(n + 1) - math.lgamma(k + 1) - math.lgamma(n - k + 1) + k * logp + (n - k) * log1p)
        out += 1.0 - min(cdf, 1.0) ** workers  # P(max >= k + 1)
    return out


def expected_max_normal(n):
    """E[max of n standard normals] (Blom's approximation of the top order statistic)."""
    if n <= 1:
        return 0.0
    from statistics import NormalDist
    return NormalDist().inv_cdf((n - 0.375) / (n + 0.25))


def share_below(n, workers, below):
    """Fraction of workers whose binomial share of n is at most `below` (the early ones)."""
    if workers <= 1 or n == 0:
        return 0.0
    p = 1.0 / workers
    mean, sd = n * p, math.sqrt(n * p * (1 - p))
    from statistics import NormalDist
    return NormalDist(mean, max(sd, 1e-9)).cdf(below + 0.5)


class Net:
    def __init__(self, latency, bandwidth, gap, algorithm="linear"):
        self.lat, self.bw, self.gap, self.algorithm = latency, bandwidth, gap, algorithm

    def allgather(self, ranks, part, total):
        """Seconds of one allgather of `ranks` parts, the largest `part` bytes, `total` in all."""
        if ranks <= 1:
            return 0.0
        if self.algorithm == "linear":
            # Every pair at once: the busiest rank sends its part P - 1 times and takes in the
            # rest; links are full duplex and the switch is not the bottleneck.
            return self.lat + 2 * (ranks - 1) * self.gap + max((ranks - 1) * part, total - min(part, total)) / self.bw
        if self.algorithm == "ring":
            return (ranks - 1) * (self.lat + 2 * self.gap) + (total - total / ranks) / self.bw
        steps = math.ceil(math.log2(ranks))  # bruck / recursive doubling
        return steps * (self.lat + 2 * self.gap) + (total - total / ranks) / self.bw


def wake(waited, master):
    """Mean delay between a collective completing and a rank that waited `waited` seconds
    noticing it: half its pause then (src/parallel/comm.rs poll_with_pauses)."""
    cap = MASTER_MAX_PAUSE if master else MAX_PAUSE
    pause = LONG_WAIT_PAUSE if waited >= LONG_WAIT else min(max(waited, 5e-6), cap)
    return pause / 2


def longest_wake(pauses):
    """Expected largest of independent uniform(0, p) delays, for a list of (p, how many)."""
    # P(max <= t) = prod (t / p_i) over t below every p; integrate 1 - F numerically on a few
    # points of the largest pause (the largest dominates).
    pauses = [(p, n) for p, n in pauses if n > 0 and p > 0]
    if not pauses:
        return 0.0
    top = max(p for p, _ in pauses)
    steps, out = 64, 0.0
    for i in range(steps):
        t = (i + 0.5) / steps * top
        f = 1.0
        for p, n in pauses:
            f *= min(t / p, 1.0) ** n
        out += (1.0 - f) * top / steps
    return out


# What a simulated run's time went to, grouped for the report: each part's seconds on P ranks
# against the same work's seconds in one process (none for pure overheads).
GROUPS = [
    ("serial", ("load", "setup", "fit", "round_serial"), "the serial share: scene load and BVH build, record inserts, fit "
                                                "(every rank repeats them)"),
    ("split", ("grid", "maps"), "the grid's and edge map's rows over the workers"),
    ("compute", ("compute", "shared_cores", "ahead"), "the rounds' lookups and records, evenly shared (and on "
                                                        "shared cores, the ranks' turns)"),
    ("imbalance", ("imbalance",), "the rounds' imbalance: the slowest worker's records"),
    ("latency", ("latency", "wake"), "round latency: the collectives' latency and per-message costs, and the "
                                     "polling pauses"),
    ("bytes", ("bytes", "grid_comm", "maps_comm"), "bytes: the records, grid rows and map rows on the links"),
    ("final", ("final",), "the final pass: tiles on the rendering workers, their round trips and the master's link"),
]


class Result:
    """A simulated run: `parts` (seconds of each part on the critical path, summing to the wall
    time) and `alone` (the same work's seconds in one process)."""

    def __init__(self, ranks):
        self.ranks = ranks
        self.parts = {}
        self.alone = {}
        self.final_bound = ""
        self.bytes = 0
        self.ahead_s = 0.0

    @property
    def wall(self):
        return sum(self.parts.values())

    def losses(self, t1):
        """Each group's share of the ranks' time lost against one process (`t1` seconds):
        W * its seconds - its one-process seconds, over P * wall; the master's whole time is
        the group "master". The shares and the efficiency sum to one."""
        P, W = self.ranks, self.ranks - 1
        total = P * self.wall
        out = {"master": self.wall / total}
        for name, keys, _ in GROUPS:
            out[name] = sum(W * self.parts.get(k, 0.0) - self.alone.get(k, 0.0) for k in keys) / total
        return out


def simulate(profile, ranks, net, cores=None, mode="broadcast", change=()):
    """Simulated wall seconds of the default build on `ranks` processes (a master and ranks - 1
    one-thread workers); `cores` None: a processor per rank, else the ranks share that many
    (effective) cores. `change`: changes to the build that are not made, to see what they would
    buy (see `CHANGES`)."""
    change = set(change)
    P, W = ranks, ranks - 1
    pr = profile
    res = Result(ranks)
    part, alone = res.parts, res.alone
    # What every rank repeats: on shared cores P copies take turns on `cores` cores.
    repeat = P / cores if cores is not None and P > cores else 1.0

    def spread(total_work, slowest):
        """A phase of `total_work` seconds over the workers, the slowest doing `slowest`."""
        if cores is not None and W > cores:
            return max(slowest, total_work / cores)
        return slowest

    part["load"], alone["load"] = pr.load_s * repeat, pr.load_s
    # Setting up the roles, writing the image, gathering reports: the -np 2 calibration run's
    # wall time beyond its phases (a constant here; the prediction takes it as it is).
    part["setup"] = pr.mpi_extra_s
    # The grid: rows interleaved over the workers, then an allgather among them.
    grid_bytes = pr.grid_samples * GRID_SAMPLE_BYTES + pr.grid_rows * ROW_HEADER
    slowest_rows = math.ceil(pr.grid_rows / W) / max(pr.grid_rows, 1)
    part["grid"], alone["grid"] = spread(pr.grid_s, pr.grid_s * slowest_rows), pr.grid_s
    # Bytes the ranks count sent (src/parallel/comm.rs all_gather_bytes: a rank's part once per
    # other rank; each part opens with its item count, u32): to check the model's traffic.
    res.bytes = (grid_bytes + 4 * W) * (W - 1) + LENGTH_BYTES * W * (W - 1)
    part["grid_comm"] = (net.allgather(W, LENGTH_BYTES, W * LENGTH_BYTES)
                         + net.allgather(W, grid_bytes * slowest_rows, grid_bytes)) if W > 1 else 0.0
    for k in ("compute", "imbalance", "shared_cores", "latency", "bytes", "wake", "round_serial"):
        part[k] = 0.0
    latency_only = Net(net.lat, math.inf, net.gap, net.algorithm)
    ahead = mode == "component" and W >= 2 and pr.ahead_pixel_s > 0 and "no_ahead" not in change
    waits = 0.0
    for k, r in enumerate(pr.rounds):
        S, R = r["sites"], r["records"]
        work = S * pr.site_s + R * pr.record_s
        top = binomial_max(R, W)
        slowest = math.ceil(S / W) * pr.site_s + top * pr.record_s
        compute = spread(work, slowest)
        mine = math.ceil(top) * RECORD_WIRE + 4
        total = R * RECORD_WIRE + 4 * W
        lengths = net.allgather(W, LENGTH_BYTES, W * LENGTH_BYTES)
        data = net.allgather(W, mine, total)
        fixed = latency_only.allgather(W, mine, total)
        # The workers that waited for the slowest notice the lengths up to their pause late (a
        # pause doubles up to COLLECTIVE_MAX_PAUSE), and the data step waits for the last to
        # post. In component mode they trace between steps of 16 pixels instead.
        waited = max(slowest - work / W, 0.0)
        pause = 16 * pr.ahead_pixel_s if ahead else min(max(waited, 5e-6), COLLECTIVE_MAX_PAUSE)
        pauses = [(pause, max(W - 1, 0))]
        res.bytes += (R * RECORD_WIRE + 4 * W) * (W - 1) + LENGTH_BYTES * W * (W - 1)
        res.bytes += R * RECORD_WIRE + KEPT_HEADER  # the round, to the master once
        part["compute"] += work / W
        part["imbalance"] += max(slowest - work / W, 0.0)
        part["shared_cores"] += compute - max(slowest, work / W)
        exchange = {"latency": lengths + fixed, "bytes": data - fixed,
                    "wake": longest_wake(pauses) + min(max(data, 5e-6), COLLECTIVE_MAX_PAUSE) / 2}
        if "overlap" in change and k + 1 < len(pr.rounds):
            # The next round's lookups made while the exchange is in flight (against the cache
            # before this round's records, and checked again near them): the exchange hides
            # behind up to those lookups' time.
            lookups = math.ceil(pr.rounds[k + 1]["sites"] / W) * pr.site_s
            seen = max(sum(exchange.values()), 1e-12)
            keep = max(seen - lookups, 0.0) / seen
            exchange = {key: v * keep for key, v in exchange.items()}
        for key, v in exchange.items():
            part[key] += v
        # A worker's wait in this round: for the slowest (the mean worker's share of its
        # lead) and for the exchange.
        waits += waited + sum(exchange.values())
        part["round_serial"] += r["serial_s"] * repeat
    alone["compute"] = sum(r["compute_s"] for r in pr.rounds)
    alone["round_serial"] = sum(r["serial_s"] for r in pr.rounds)
    # The edge map: strips over the workers, bit-packed rows allgathered over every rank.
    strips = math.ceil(pr.height / EDGE_STRIP)
    edge_bytes = math.ceil(pr.width / 8) * pr.height + strips * ROW_HEADER
    share = math.ceil(strips / W) / strips
    part["maps"], alone["maps"] = spread(pr.edge_s, pr.edge_s * share), pr.edge_s
    part["maps_comm"] = (net.allgather(W, LENGTH_BYTES, W * LENGTH_BYTES)
                         + net.allgather(W, edge_bytes * share, edge_bytes)) if pr.edge_s and W > 1 else 0.0
    if pr.edge_s:
        res.bytes += (edge_bytes + 4 * W) * (W - 1) + LENGTH_BYTES * W * (W - 1)
    res.bytes += pr.pixels * pr.tile_wire  # the final pass's tiles, to the master
    # The workers fit; the master only freezes its copy (for the cache file).
    part["fit"], alone["fit"] = pr.fit_s * (W / cores if cores is not None and W > cores else 1.0), pr.fit_s
    if "fit_split" in change:
        # Each worker fits its share of the records and an allgather hands out the fits (a
        # record's curvature: 24 bytes).
        part["fit"] = pr.fit_s / W + net.allgather(W, 24 * pr.records / W, 24 * pr.records)
    # Tracing ahead: a share of each worker's waits, up to the traceable part of its final pass
    # and the traces it may hold; that much leaves its final pass.
    res.ahead_s = 0.0
    if ahead:
        pixels = min(pr.pixels / W, TRACE_BYTES_LIMIT / TRACE_BYTES_PER_PIXEL)
        res.ahead_s = min(pr.ahead_fill * waits, pixels * pr.ahead_pixel_s)
        if cores is not None and W > cores:
            # Ranks sharing cores: a waiting worker's tracing takes a core from one still
            # computing, so the prepass lasts its share of that work longer.
            part["ahead"] = W * res.ahead_s / cores - res.ahead_s
    part["final"], res.final_bound = final_pass(pr, W, net, cores, mode, change, res.ahead_s)
    alone["final"] = pr.final_s
    return res


def final_pass(pr, W, net, cores, mode, change=(), ahead_s=0.0):
    """Tiles on demand (32x32): each a round trip through the master that carries the finished
    tile back. Bound by the rendering workers (their tiles and round trips, and the last
    tile's tail) or by the master's link (every tile's bytes). Every worker renders, in every
    mode; `ahead_s` of each worker's share was traced during the prepass."""
    n = W
    tiles = math.ceil(pr.width / 32) * math.ceil(pr.height / 32)
    per_tile = max(pr.final_s - n * ahead_s, 0.0) / tiles
    tile_bytes = pr.pixels / tiles * pr.tile_wire
    # On shared cores the rendering ranks take turns with each other (the idle PAs sleep).
    speed = min(cores, n) / n if cores is not None and n > cores else 1.0
    trip = (2 * net.lat + 2 * net.gap + tile_bytes / net.bw + MASTER_MAX_PAUSE / 2 + wake(per_tile / speed, False)
            + pr.tile_overhead_s)
    workers = max(tiles / n, 1.0) * (per_tile / speed + trip) + 0.5 * per_tile / speed
    # The master takes the tiles one at a time: each one's bytes on its link, and storing them
    # at its measured seconds a pixel (the calibrated overhead is the worker's wait, in `trip`).
    master = tiles * (tile_bytes / net.bw + net.gap) + pr.pixels * pr.master_pixel_s + per_tile / speed + trip
    if "direct_tiles" in change:
        # The workers write their tiles themselves (a parallel file system, MPI-IO): the
        # master's link carries the requests alone.
        master = tiles * (64 / net.bw + net.gap)
    if master > workers:
        return master, "master (its link, storing)"
    return workers, "workers"


# -- measured runs ----------------------------------------------------------------------------------

def one_process(scene, size, options, threads, work, extra=()):
    """`icrender render` in one process: its --stats."""
    width, height = size.split("x")
    stats, _ = common.render(scene, os.path.join(work, "one.exr"),
                             ["-x", width, "-y", height] + options.split() + ["--threads", str(threads)] + list(extra))
    return stats


def mpi_command(np, scene, size, options, mode, out, stats_path):
    width, height = size.split("x")
    cmd = ["-np", str(np), common.BINARY, "render", scene, "-o", out, "-q", "--no-preview", "--overwrite",
           "--stats", stats_path, "-x", width, "-y", height] + options.split()
    return cmd + (["--mode", mode] if mode else [])


def load_average():
    """This machine's one-minute load average (other engineers' jobs share its 2 cores: kept with
    every run so that a slow spell shows in the CSV)."""
    with open("/proc/loadavg") as f:
        return float(f.read().split()[0])


def read_run(stats_path, elapsed):
    with open(stats_path) as f:
        s = json.load(f)
    master = s["per_rank"][0]
    log = s["prepass_round_log"]
    # The master's own prepass seconds outside the rounds and the pool: the fit and freeze.
    own = (master["prepass_s"] - sum(r["seconds"] for r in log)
           - (master["prepass_pool_s"] - sum(r["pool_s"] for r in log)))
    # Beside the load, the prepass and the final pass: setting up the ranks' roles, writing the
    # image, gathering the reports.
    extra = s["wall_s"] - s["load_s"] - s["build_s"] - s["prepass_s"] - s["render_s"]
    workers = [r for r in s["per_rank"][1:]]
    ahead = {"ahead_s": sum(r.get("ahead_s", 0.0) for r in workers),
             "ahead_pixels": sum(r.get("ahead_pixels", 0) for r in workers),
             "workers_pool_s": sum(r.get("prepass_pool_s", 0.0) for r in workers)}
    return {**ahead, "wall_s": s["wall_s"], "mpirun_s": elapsed, "extra_s": max(extra, 0.0), "prepass_s": s["prepass_s"], "render_s": s["render_s"],
            "load_s": s["load_s"] + s["build_s"], "bytes": s["bytes"], "records": s["prepass_records"],
            "master_own_s": max(own, 0.0), "mode": s["mode"], "load_average": load_average(),
            "pixels": s["width"] * s["height"], "tile_bytes": master.get("tile_bytes", 0),
            "tiles_s": master.get("tiles_s", 0.0)}


def mpi_local(np, scene, size, options, mode, work):
    """mpirun on this machine (oversubscribed): the run's numbers, or None and why."""
    out, stats_path = os.path.join(work, "m.exr"), os.path.join(work, "m.json")
    if os.path.exists(stats_path):
        os.remove(stats_path)
    cmd = ["mpirun", "--oversubscribe"] + mpi_command(np, scene, size, options, mode, out, stats_path)
    start = time.monotonic()
    result = subprocess.run(cmd, env=dict(os.environ, **MPI_ENV), capture_output=True, text=True, timeout=600)
    elapsed = time.monotonic() - start
    if result.returncode != 0 or not os.path.exists(stats_path):
        return None, (result.stderr.strip().splitlines() or ["exit %d" % result.returncode])[-1]
    return read_run(stats_path, elapsed), None


def mpi_testbed(np, scene, size, options, mode, work):
    """mpirun across the namespace test bed's hosts (bench/cluster_bench.py's machinery)."""
    import cluster_bench
    out, stats_path = os.path.join(work, "t.exr"), os.path.join(work, "t.json")
    if os.path.exists(stats_path):
        os.remove(stats_path)
    start = time.monotonic()
    result = cluster_bench.testbed("mpirun", *mpi_command(np, scene, size, options, mode, out, stats_path),
                                   check=False, timeout=600)
    elapsed = time.monotonic() - start
    if result.returncode != 0 or not os.path.exists(stats_path):
        return None, (result.stderr.strip().splitlines() or ["exit %d" % result.returncode])[-1]
    return read_run(stats_path, elapsed), None


def local_link(times=3):
    """Latency and bandwidth between two ranks on this machine (`icrender bench messages`), the
    median of `times` measurements (a measurement taken while other jobs hold the cores can be
    off by orders of magnitude)."""
    costs = []
    for _ in range(times):
        result = subprocess.run(["mpirun", "--oversubscribe", "-np", "2", common.BINARY, "bench", "messages"],
                                env=dict(os.environ, **MPI_ENV), capture_output=True, text=True, timeout=120,
                                check=True)
        cost = json.loads(result.stdout.strip().splitlines()[-1])
        costs.append((cost["latency_s"], cost["bandwidth_bytes_per_s"]))
    return statistics.median(c[0] for c in costs), statistics.median(c[1] for c in costs)


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def pct(pred, real):
    return 100.0 * (pred - real) / real if real else float("nan")


# -- the study: measure, validate, predict, write ----------------------------------------------------

STORE = os.path.join(DOCS, "scaling", "measured.json")
LOCAL = {"scene": "conference", "path": CONFERENCE, "size": "640x360", "options": "-ab 2"}
# A second, smaller scene on this machine: a Cornell box, few records, the grid a larger share.
SMALL = {"scene": "cornell", "path": CORNELL, "size": "256x256", "options": "-ab 2"}
CASES = {f"{c['scene']}-{c['size']}": c for c in (LOCAL, SMALL)}
TESTBED = {"scene": "conference", "path": CONFERENCE, "size": "320x180", "options": "-ab 2"}
TARGET = {"scene": "conference", "path": CONFERENCE, "size": "3840x2160", "options": "-ab 2"}
ROUND_KEYS = ("sites", "records", "compute_s", "pool_s", "seconds")


def slim(stats):
    """The --stats fields the model reads (the store stays small)."""
    keep = ("width", "height", "wall_s", "load_s", "build_s", "render_s", "prepass_s", "prepass_fit_s", "prepass_records",
            "last_bounce_samples", "edge_pixels", "mode", "ranks")
    out = {k: stats.get(k) for k in keep}
    out["prepass_round_log"] = [{k: r[k] for k in ROUND_KEYS} for r in stats["prepass_round_log"]]
    out["busy_over_cpu"] = (sum(t["busy_s"] for t in stats.get("per_thread", []))
                            / max(sum(t["cpu_s"] for t in stats.get("per_thread", [])), 1e-9)) if stats.get("per_thread") else None
    return out


def profile_runs(case, work, store, threads2=False):
    """One-process runs of a case (default, without the edge map, and at 2 threads) and a
    calibration run at -np 2 for the master's fit time; kept in the store."""
    name = f"{case['scene']}-{case['size']}"
    entry = {}
    entry["default"] = slim(one_process(case["path"], case["size"], case["options"], 1, work))
    entry["noedge"] = slim(one_process(case["path"], case["size"], case["options"], 1, work, ["--edge-samples", "1"]))
    if threads2:
        entry["threads2"] = slim(one_process(case["path"], case["size"], case["options"], 2, work))
    store.setdefault("profiles", {})[name] = entry
    calibrate(case, work, store)
    print(f"profile {name}: one process {entry['default']['wall_s']:.2f} s (busy/cpu "
          f"{entry['default']['busy_over_cpu'] or 0:.2f}), fit {entry['default'].get('prepass_fit_s') or 0:.3f} s")


def calibrate(case, work, store):
    """Runs for what one process cannot show, not among the validated runs: at -np 2
    (broadcast: a master and one worker) the setup beyond the phases and a tile's cost of going
    through the master (the final pass's time beyond one process's, per tile); at -np 3 in
    component mode the share of the workers' waits that tracing ahead filled and a traced
    pixel's seconds."""
    entry = store["profiles"][f"{case['scene']}-{case['size']}"]
    run, error = mpi_local(2, case["path"], case["size"], case["options"], "broadcast", work)
    if run is None:
        raise RuntimeError(f"calibration run failed: {error}")
    entry["mpi_extra_s"], entry["calibration_final_s"] = run["extra_s"], run["render_s"]
    entry["tile_wire"] = run["tile_bytes"] / run["pixels"]
    entry["master_pixel_s"] = run["tiles_s"] / run["pixels"]
    ahead, error = mpi_local(3, case["path"], case["size"], case["options"], "component", work)
    if ahead is None:
        raise RuntimeError(f"calibration run failed: {error}")
    entry["ahead_fill"] = ahead["ahead_s"] / max(ahead["workers_pool_s"], 1e-9)
    entry["ahead_pixel_s"] = ahead["ahead_s"] / max(ahead["ahead_pixels"], 1)
    print(f"calibration {case['scene']}-{case['size']}: -np 2 setup {run['extra_s']:.3f} s, final pass "
          f"{run['render_s']:.3f} s, tiles {entry['tile_wire']:.1f} bytes a pixel, the master "
          f"{entry['master_pixel_s'] * 1e9:.0f} ns a pixel storing them; -np 3 component: tracing ahead filled {100 * entry['ahead_fill']:.0f}% of the "
          f"workers' waits, {entry['ahead_pixel_s'] * 1e6:.2f} us a pixel")


def representative(entry):
    """The one-process run a case's profile is made from: of its first run and those repeated
    between the measured runs (`measure_local`, `measure_testbed`), the one of median wall time,
    so that a spell of the machine's, faster or slower, during the profiles alone does not read
    as the model's error."""
    runs = sorted([entry["default"]] + entry.get("repeats", []), key=lambda r: r["wall_s"])
    return runs[(len(runs) - 1) // 2]


def profile_again(case, work, store):
    """One more one-process run of `case`, among the measured runs, for `representative`."""
    stats = slim(one_process(case["path"], case["size"], case["options"], 1, work))
    store["profiles"][f"{case['scene']}-{case['size']}"].setdefault("repeats", []).append(stats)
    print(f"profile {case['scene']}-{case['size']} again: one process {stats['wall_s']:.2f} s")


def profile_of(store, case, cores=True):
    e = store["profiles"][f"{case['scene']}-{case['size']}"]
    pr = Profile(representative(e), e.get("noedge"), e.get("threads2") if cores else None, None, e.get("mpi_extra_s"))
    pr.ahead_fill, pr.ahead_pixel_s = e.get("ahead_fill", 0.0), e.get("ahead_pixel_s", 0.0)
    pr.tile_wire = e.get("tile_wire", pr.tile_wire)
    pr.master_pixel_s = e.get("master_pixel_s", pr.master_pixel_s)
    if e.get("calibration_final_s") is not None:
        pr.tile_overhead_s = max(e["calibration_final_s"] - pr.final_s, 0.0) / pr.tiles()
    return pr


def measure_local(store, work, repeats, plan):
    """mpirun on this machine: `plan` is [(case, mode, ranks)], each run `repeats` times,
    interleaved (a slow spell of the machine then hits every configuration alike)."""
    runs = store.setdefault("local", [])
    for case in {id(c): c for c, _, _ in plan}.values():
        store["profiles"][f"{case['scene']}-{case['size']}"]["repeats"] = []
    for rep in range(repeats):
        # The profiles again, between the runs they predict (`representative`).
        for case in {id(c): c for c, _, _ in plan}.values():
            profile_again(case, work, store)
        for case, mode, np in plan:
            run, error = mpi_local(np, case["path"], case["size"], case["options"], mode, work)
            name = f"{case['scene']}-{case['size']}"
            if run is None:
                print(f"local {name} {mode} -np {np}: FAILED: {error}")
                continue
            runs.append(dict({"where": "local", "case": name, "mode": mode, "ranks": np, "repeat": rep}, **run))
            print(f"local {name} {mode:<9} -np {np} #{rep}: wall {run['wall_s']:6.2f} s (prepass {run['prepass_s']:5.2f}, "
                  f"final {run['render_s']:5.2f}, mpirun {run['mpirun_s']:5.2f}, load average {run['load_average']})")


def measure_testbed(store, work, repeats, links, cases):
    """The namespace test bed: the links' cost, then each (mode, ranks) `repeats` times."""
    import cluster_bench
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    runs, costs = store.setdefault("testbed", []), store.setdefault("links", {})
    hosts = max(np for _, np in cases)
    store["profiles"][f"{TESTBED['scene']}-{TESTBED['size']}"]["repeats"] = []
    try:
        for link in links:
            cluster_bench.up(hosts, link)
            measured = [m for m in (cluster_bench.measure_link(link) for _ in range(3)) if m]
            if measured:
                costs[link] = [statistics.median(m["latency_s"] for m in measured),
                               statistics.median(m["bandwidth_bytes_per_s"] for m in measured)]
            for rep in range(repeats):
                profile_again(TESTBED, work, store)
                for mode, np in cases:
                    run, error = mpi_testbed(np, TESTBED["path"], TESTBED["size"], TESTBED["options"], mode, work)
                    if run is None:
                        print(f"test bed {link} {mode} -np {np}: FAILED: {error}")
                        cluster_bench.up(hosts, link)
                        continue
                    runs.append(dict({"where": link, "case": f"{TESTBED['scene']}-{TESTBED['size']}", "mode": mode,
                                      "ranks": np, "repeat": rep}, **run))
                    print(f"test bed {link:>8} {mode:<9} -np {np} #{rep}: wall {run['wall_s']:6.2f} s (prepass "
                          f"{run['prepass_s']:5.2f}, final {run['render_s']:5.2f}), {run['bytes'] / 1e6:.1f} MB")
    finally:
        cluster_bench.testbed("down", check=False)


def validate(store, algorithm="linear"):
    """Every measured configuration's median wall time against the simulation's."""
    rows = []
    local = Net(*store["links"]["local"], GAP["tcp"], algorithm)
    groups = {}
    machine = profile_of(store, LOCAL)
    for r in store.get("local", []) + store.get("testbed", []):
        name = r.get("case") or (f"{LOCAL['scene']}-{LOCAL['size']}" if r["where"] == "local"
                                 else f"{TESTBED['scene']}-{TESTBED['size']}")
        groups.setdefault((r["where"], name, r["mode"], r["ranks"]), []).append(r)
    for (where, name, mode, np), runs in sorted(groups.items(), key=lambda kv: (kv[0][0] != "local", kv[0])):
        case = CASES.get(name, TESTBED)
        profile = profile_of(store, case)
        # The machine's effective cores, as the local case's 1- and 2-thread runs measured them.
        profile.cores = machine.cores
        net = local if where == "local" else Net(*store["links"][where], GAP["tcp"], algorithm)
        # Every rank of the test bed runs on this machine's cores too.
        res = simulate(profile, np, net, cores=profile.cores, mode=mode)
        real = statistics.median(r["wall_s"] for r in runs)
        # Rank 0's load and prepass together: its prepass starts with a collective that waits
        # for the slowest rank's load, so the two apart are not comparable with the model's.
        real_prepass = statistics.median(r["prepass_s"] + r["load_s"] for r in runs)
        real_final = statistics.median(r["render_s"] for r in runs)
        sim_prepass = sum(v for k, v in res.parts.items() if k not in ("setup", "final"))
        rows.append({"where": where, "scene": case["scene"], "size": case["size"], "options": case["options"],
                     "mode": mode, "ranks": np, "repeats": len(runs), "real_wall_s": round(real, 3),
                     "sim_wall_s": round(res.wall, 3), "wall_err_pct": round(pct(res.wall, real), 1),
                     "real_prepass_s": round(real_prepass, 3), "sim_prepass_s": round(sim_prepass, 3),
                     "prepass_err_pct": round(pct(sim_prepass, real_prepass), 1),
                     "real_final_s": round(real_final, 3), "sim_final_s": round(res.parts["final"], 3),
                     "final_err_pct": round(pct(res.parts["final"], real_final), 1),
                     "spread_pct": round(100 * (max(r["wall_s"] for r in runs) - min(r["wall_s"] for r in runs)) / real, 1),
                     "real_mb": round(statistics.median(r["bytes"] for r in runs) / 1e6, 2),
                     "sim_mb": round(res.bytes / 1e6, 2),
                     "bytes_err_pct": round(pct(res.bytes, statistics.median(r["bytes"] for r in runs)), 1),
                     "load_average": round(statistics.median(r.get("load_average", float("nan")) for r in runs), 1)})
    for r in rows:
        print(f"validation {r['where']:>8} {r['scene']:>10} {r['size']:>7} {r['mode']:<9} -np {r['ranks']}: measured {r['real_wall_s']:6.2f} s "
              f"(median of {r['repeats']}, spread {r['spread_pct']:4.1f}%), simulated {r['sim_wall_s']:6.2f} s: "
              f"error {r['wall_err_pct']:+5.1f}% (load and prepass {r['prepass_err_pct']:+5.1f}%, final pass "
              f"{r['final_err_pct']:+5.1f}%); bytes {r['real_mb']:.1f} MB, simulated {r['sim_mb']:.1f} MB "
              f"({r['bytes_err_pct']:+.1f}%)")
    if rows:
        errors = [abs(r["wall_err_pct"]) for r in rows]
        print(f"validation: mean |error| {statistics.mean(errors):.1f}%, worst {max(errors):.1f}% over {len(rows)} "
              f"configurations; {sum(e <= 15 for e in errors)} of {len(rows)} within 15%")
    return rows


def scaling_check(store):
    """The cost transfer across sizes: a smaller profile's costs on a larger run's rounds (its
    sites and records), against that run's own one-process time (both without other jobs'
    share of the cores): 320x180 on 640x360, and 640x360 on the target size."""
    out = []
    pairs = [(TESTBED, store["profiles"][f"{LOCAL['scene']}-{LOCAL['size']}"]["default"])]
    if "target" in store:
        pairs.append((LOCAL, store["target"]))
    for case, stats in pairs:
        small = profile_of(store, case, cores=False)
        moved = small.scaled_to(stats)
        real = uncontended(stats)
        for what, pred, meas in (("one process", moved.one_process(), real["wall_s"]),
                                 ("prepass", moved.one_process() - moved.final_s - moved.load_s, real["prepass_s"]),
                                 ("final pass", moved.final_s, real["render_s"] - real["prepass_s"])):
            out.append({"from": f"{small.width}x{small.height}", "to": f"{stats['width']}x{stats['height']}",
                        "what": what, "predicted_s": round(pred, 2), "measured_s": round(meas, 2),
                        "err_pct": round(pct(pred, meas), 1)})
            print(f"scaling check: {small.width}x{small.height}'s costs on {stats['width']}x{stats['height']}'s rounds, "
                  f"{what}: {pred:.2f} s against {meas:.2f} s measured: {pct(pred, meas):+.1f}%")
    return out


RANKS = [4, 8, 16, 32, 64, 128, 256, 512, 1024]


def target_profile(store):
    """The target's profile from its own one-process render: its rounds, their fitted costs,
    its grid and final pass; the fit (no MPI master measured there) from the local case's
    calibration run scaled by the records, the setup as the local case's."""
    base = profile_of(store, LOCAL, cores=False)
    out = Profile(store["target"], mpi_extra_s=base.mpi_extra_s)
    out.tile_overhead_s = base.tile_overhead_s
    out.tile_wire, out.master_pixel_s = base.tile_wire, base.master_pixel_s
    out.ahead_fill, out.ahead_pixel_s = base.ahead_fill, base.ahead_pixel_s
    return out


def predict(store, algorithms=("linear", "bruck")):
    """The 4K frame on 4 to 1,024 ranks, each rank a processor of its own."""
    target = target_profile(store)
    t1 = target.one_process()
    print(f"prediction: {TARGET['size']} {TARGET['options']}: {target.summary()}; one process {t1:.1f} s")
    rows = []
    for network in ("1gbit", "100gbit"):
        for algorithm in algorithms:
            net = Net(*NETWORKS[network], algorithm)
            for mode in ("component", "broadcast"):
                for np in RANKS:
                    res = simulate(target, np, net, cores=None, mode=mode)
                    eff = t1 / (np * res.wall)
                    losses = res.losses(t1)
                    bound = max((k for k in losses if k not in ("compute",)), key=lambda k: losses[k])
                    # The same without the scene load, BVH build and setup every rank pays before
                    # it can start (what the build itself scales like).
                    fixed = res.parts["load"] + res.parts["setup"]
                    build_eff = (t1 - target.load_s) / (np * (res.wall - fixed))
                    row = {"network": network, "algorithm": algorithm, "mode": mode, "ranks": np,
                           "t1_s": round(t1, 2), "wall_s": round(res.wall, 3), "efficiency_pct": round(100 * eff, 1),
                           "build_efficiency_pct": round(100 * build_eff, 1),
                           "bound": bound, "final_bound": res.final_bound}
                    row.update({f"loss_{k}_pct": round(100 * v, 1) for k, v in losses.items()})
                    row.update({f"{k}_s": round(v, 4) for k, v in res.parts.items()})
                    rows.append(row)
    for network in ("1gbit", "100gbit"):
        for algorithm in algorithms:
            for mode in ("component", "broadcast"):
                mine = [r for r in rows if r["network"] == network and r["algorithm"] == algorithm and r["mode"] == mode]
                print(f"{network} {algorithm} allgather, {mode}: " + ", ".join(
                    f"{r['ranks']}: {r['efficiency_pct']:.0f}% ({r['bound']})" for r in mine))
    return target, rows


# Changes not made, simulated to see what each would buy: (label, mode, algorithm, change flags).
CHANGES = [
    ("as is (component mode, linear iallgatherv)", "component", "linear", ()),
    ("no tracing ahead (as --mode broadcast renders)", "component", "linear", ("no_ahead",)),
    ("workers write their tiles themselves (MPI-IO), not through the master", "component", "linear",
     ("direct_tiles",)),
    ("the fit shared by the workers (their shares allgathered)", "component", "linear", ("fit_split",)),
    ("a Bruck (ceil(log2 P) steps) allgather", "component", "bruck", ()),
    ("the next round's lookups overlap the collective", "component", "linear", ("overlap",)),
    ("all of these but the first", "component", "bruck", ("direct_tiles", "fit_split", "overlap")),
]


def what_if(target, t1, ranks=(256, 1024)):
    """Each change of CHANGES simulated on the target: rows of (change, network, ranks,
    efficiency, and the same without the scene load)."""
    rows = []
    for network in ("1gbit", "100gbit"):
        for np in ranks:
            for label, mode, algorithm, flags in CHANGES:
                res = simulate(target, np, Net(*NETWORKS[network], algorithm), mode=mode, change=flags)
                fixed = res.parts["load"] + res.parts["setup"]
                rows.append({"network": network, "ranks": np, "change": label,
                             "efficiency_pct": round(100 * t1 / (np * res.wall), 1),
                             "build_efficiency_pct": round(100 * (t1 - target.load_s) / (np * (res.wall - fixed)), 1)})
    return rows


def table(rows, columns, headers):
    out = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    for r in rows:
        out.append("| " + " | ".join(str(r[c]) if not callable(c) else c(r) for c in columns) + " |")
    return "\n".join(out)


def write_docs(store, validation, check, target, prediction, ifs, log):
    """docs/SCALING.md from this run's own numbers, and its CSVs under docs/scaling/."""
    folder = os.path.join(DOCS, "scaling")
    os.makedirs(folder, exist_ok=True)
    common.write_csv(os.path.join(folder, "validation.csv"), validation)
    common.write_csv(os.path.join(folder, "prediction.csv"), prediction)
    common.write_csv(os.path.join(folder, "what-if.csv"), ifs)
    common.write_csv(os.path.join(folder, "scaling-check.csv"), check)
    common.write_csv(os.path.join(folder, "runs.csv"),
                     [{k: v for k, v in r.items()} for r in store.get("local", []) + store.get("testbed", [])])
    common.write_csv(os.path.join(folder, "links.csv"),
                     [{"link": k, "latency_s": v[0], "bandwidth_bytes_per_s": v[1]} for k, v in store["links"].items()])
    t1 = target.one_process()
    lines = [
        "# Scaling of the default build (the cache prepass) under mpirun",
        "",
        "Generated by `bench/prepass_sim.py` from its own runs and simulation; do not edit by hand. Rerun:",
        "",
        "    sudo python3 bench/prepass_sim.py                  # measure (about 10 minutes on a quiet 2-core machine), validate, predict",
        "    python3 bench/prepass_sim.py --skip profiles,local,testbed,target --only calibration   # the -np 2 calibration runs again",
        "    python3 bench/prepass_sim.py --simulate-only       # validate and predict again from docs/scaling/measured.json",
        "",
        f"CSVs: `docs/scaling/validation.csv`, `prediction.csv`, `what-if.csv`, `runs.csv` (every measured run), "
        f"`links.csv`; the measured inputs (one-process round logs, runs) in `docs/scaling/measured.json`. "
        f"Measured {store.get('measured_at', '?')}.",
        "",
        "## The model",
        "",
        "The prepass is a fixed sequence of phases, the same for any rank count; its sizes (sites and records per "
        "round) come from a one-process run's `prepass_round_log`, its costs from that run's times:",
        "",
        "- **load**: scene load and BVH build, on every rank.",
        "- **grid**: the last bounce's rows over the W = P - 1 workers, then an allgather among them (48 bytes a sample).",
        "- **rounds**: per round, a worker looks up ceil(S/W) sites and makes its share of the R records; the round "
        "waits for the slowest worker, whose share is the expected maximum of R records dealt binomially to W "
        "workers (the sites are interleaved, so a cluster of records spreads; the build deals a round's misses "
        "evenly, so this is an upper bound on its imbalance); then two allgathers among the W workers, on a "
        "communicator of their own (the lengths, then 4 + 128 bytes a record); then every worker inserts the "
        "records (the serial part). The master takes no part: the first worker hands it each round's records "
        "once, from a thread of its own (off the critical path; the bytes are counted).",
        "- **ahead** (component mode): a worker waiting at a round's barrier traces its tiles' eye paths, direct "
        "and specular light, and that work leaves its final pass: the share of its waits that tracing filled "
        "in a -np 3 calibration run, up to the traceable share of its final pass (the calibration's seconds a "
        "traced pixel) and the 64 MiB of traces a worker may hold.",
        "- **maps**: the edge map's strips over the workers, bit-packed rows allgathered among them; then the "
        "edge pixels' sample rounds.",
        "- **fit**: the record set's curvature fit, on every worker (the one-process run's `prepass_fit_s`).",
        "- **final**: 32x32 tiles on demand, each a round trip through the master carrying the tile back (the file's "
        "chunks, compressed by the worker, and its preview pixels: the -np 2 calibration run's bytes a pixel) plus a "
        "tile's overhead beyond one process (that run's final pass beyond the one-process final pass, per tile: "
        "encoding, a large message's rendezvous polled with pauses); bound by the rendering workers or by the "
        "master, which takes the tiles one at a time (their bytes on its link, and writing them at the calibration "
        "run's measured seconds a pixel). Every worker renders tiles, in every mode.",
        "",
        "Per-site and per-record seconds are fitted (least squares) to the one-process run's per-round compute "
        "seconds. The collective is Open MPI 4.1's libnbc `MPI_Iallgatherv`, which is linear (each rank posts a "
        "send to and a receive from every other rank at once: `ompi/mca/coll/libnbc/nbc_iallgatherv.c`, "
        "\"simple linear\"; `ompi_info` offers no other algorithm for it): latency + 2(W - 1) per-message costs "
        "+ the busiest link's bytes over the bandwidth. Alternatives modelled: Bruck/recursive doubling "
        "(ceil(log2 W) steps) and ring (W - 1 steps). Polling: a worker notices a completed collective up to its "
        "pause late (pauses double up to 0.2 ms; a worker tracing ahead looks between steps of 16 pixels), and "
        "the data allgather waits for the last worker to post. Ranks sharing this machine's cores: a phase takes "
        "max(slowest rank, all work / effective cores) (effective cores: one thread's compute over two threads'), "
        "and what every rank repeats takes P / cores times as long. Per-message cost (LogP gap): 5 us over TCP, "
        "0.5 us over RDMA (assumed, not measured). The effective cores of every case are the machine's, from the "
        "conference 640x360 runs at 1 and 2 threads. A case's profile is, of its one-process runs (one before "
        "the measured runs and one before each repeat of them), the one of median wall time: a spell of the "
        "machine's during the profiles alone would read as the model's error. The one-process profiles' times "
        "are divided by their threads' busy over CPU seconds (the share of the cores other jobs took); the "
        "mpirun runs are not corrected, and their load average is listed.",
        "",
        "## Inputs",
        "",
    ]
    for name, e in store["profiles"].items():
        pr = Profile(e["default"], e.get("noedge"), e.get("threads2"), None, e.get("mpi_extra_s"))
        lines.append(f"- `{name}` one process, one thread: {pr.summary()}; tracing ahead (-np 3, component) "
                     f"filled {100 * e.get('ahead_fill', 0.0):.0f}% of the workers' waits at "
                     f"{1e6 * e.get('ahead_pixel_s', 0.0):.2f} us a pixel; finished tiles (-np 2) "
                     f"{e.get('tile_wire', 0.0):.1f} bytes a pixel, the master {1e9 * e.get('master_pixel_s', 0.0):.0f} "
                     f"ns a pixel storing them.")
    lines += ["", "Links (`icrender bench messages`: latency from the smallest message's half round trip, bandwidth "
                  "from a stream; the median of 3 measurements):", ""]
    lines += [f"- {k}: latency {v[0] * 1e6:.1f} us, bandwidth {v[1] / 1e6:.0f} MB/s" for k, v in store["links"].items()]
    lines += ["", "## Validation", "",
              "Median wall time (`wall_s` of --stats) of each configuration against the simulation. `local`: this "
              f"machine (2 cores, mpirun --oversubscribe), {LOCAL['scene']} {LOCAL['size']} {LOCAL['options']} and "
              f"{SMALL['scene']} {SMALL['size']} {SMALL['options']}; test "
              f"bed: network namespaces on the same 2 cores, links capped by tc, {TESTBED['scene']} "
              f"{TESTBED['size']} {TESTBED['options']}. broadcast: no tracing ahead; component: the default mode, "
              "tracing ahead.", ""]
    lines.append(table(validation, ["where", "scene", "size", "mode", "ranks", "repeats", "real_wall_s", "sim_wall_s", "wall_err_pct",
                                    "spread_pct", "prepass_err_pct", "final_err_pct", "real_mb", "bytes_err_pct",
                                    "load_average"],
                       ["where", "scene", "size", "mode", "ranks", "runs", "measured s", "simulated s", "error %", "runs' spread %",
                        "load + prepass error %", "final pass error %", "MB sent", "bytes error %", "load average"]))
    errors = [abs(r["wall_err_pct"]) for r in validation]
    if errors:
        lines += ["", f"Mean |error| {statistics.mean(errors):.1f}%, worst {max(errors):.1f}%; "
                      f"{sum(e <= 15 for e in errors)} of {len(errors)} configurations within 15%."]
    lines += ["", "Cost transfer across sizes (one process, one thread, without other jobs' share of the cores): a "
                  "smaller size's fitted costs on a larger run's own rounds, the grid by its sites, the final pass by "
                  "the pixels:", ""]
    lines.append(table(check, ["from", "to", "what", "predicted_s", "measured_s", "err_pct"],
                       ["costs of", "rounds of", "time", "predicted s", "measured s", "error %"]))
    lines += ["", "The prediction below does not rest on this transfer: it takes the target size's own one-process "
                  "run (its rounds and their times), so a size's costs carried to another (the rows above) are a "
                  "check of how far a smaller run could stand in for it, not an input."]
    lines += ["", f"## Prediction: {TARGET['scene']} {TARGET['size']} {TARGET['options']}", "",
              f"From a one-process, one-thread `icrender render` at {TARGET['size']} (its times without other "
              f"jobs' share of the cores): {target.summary()}. Its grid includes the edge map (no run without the "
              f"edge map at this size; both are shared by the workers). The per-tile overhead and the tracing ahead are "
              f"the {LOCAL['size']} calibration's. One process: {t1:.1f} s. Efficiency = one process's time / (P x wall), P "
              "counting the master; build efficiency: the same without the scene load, BVH build and setup that "
              "every rank pays before it starts. Loss shares (of P x wall) say what bounds it; they and the "
              "efficiency sum to 100%.", ""]
    for network in ("1gbit", "100gbit"):
        for mode in ("component", "broadcast"):
            mine = [r for r in prediction if r["network"] == network and r["algorithm"] == "linear" and r["mode"] == mode]
            lines += [f"### {network}, {mode}{' (the default)' if mode == 'component' else ''}, linear iallgatherv", ""]
            lines.append(table(mine, ["ranks", "wall_s", "efficiency_pct", "build_efficiency_pct", "bound", "loss_master_pct", "loss_serial_pct",
                                      "loss_imbalance_pct", "loss_latency_pct", "loss_bytes_pct", "loss_final_pct",
                                      "final_bound"],
                               ["ranks", "wall s", "efficiency %", "build efficiency %", "bound", "master %", "serial %", "imbalance %",
                                "round latency %", "bytes %", "final pass %", "final pass bound"]))
            lines.append("")
    lines += ["### What would lift it", "", "Each change simulated alone, and all together (efficiency %):", ""]
    changes = list(dict.fromkeys(r["change"] for r in ifs))
    cols = sorted({(r["network"], r["ranks"]) for r in ifs}, key=lambda x: (x[0] != "1gbit", x[1]))
    head = ["change"] + [f"{n} {p}" for n, p in cols]
    body = []
    for c in changes:
        row = {"change": c}
        for n, p in cols:
            row[f"{n} {p}"] = next(r["efficiency_pct"] for r in ifs if r["change"] == c and r["network"] == n and r["ranks"] == p)
        body.append(row)
    lines.append(table(body, head, head))
    lines += ["", "## Targets", ""] + log + [""]
    with open(os.path.join(DOCS, "SCALING.md"), "w") as f:
        f.write("\n".join(lines))
    print(f"wrote {os.path.join(DOCS, 'SCALING.md')} and {folder}/*.csv")


def targets(prediction, ifs):
    """The issue's targets at 256 ranks in the default mode: met or not, what bounds the
    efficiency (the loss shares and the parts' seconds against the ideal T1 / P), and what the
    simulated changes would give."""
    out = []
    for network, goal in (("100gbit", 80.0), ("1gbit", 60.0)):
        r = next(r for r in prediction if r["network"] == network and r["algorithm"] == "linear"
                 and r["mode"] == "component" and r["ranks"] == 256)
        met = "met" if r["efficiency_pct"] >= goal else "missed"
        shares = sorted(((k[5:-4], v) for k, v in r.items() if k.startswith("loss_")), key=lambda kv: -kv[1])
        ideal = r["t1_s"] / 256
        parts = sorted(((k[:-2], v) for k, v in r.items() if k.endswith("_s") and k not in ("t1_s", "wall_s")),
                       key=lambda kv: -kv[1])
        mine = [i for i in ifs if i["network"] == network and i["ranks"] == 256]
        best = max(mine[1:-1], key=lambda i: i["efficiency_pct"])
        every = mine[-1]
        out.append(
            f"- **{network}, 256 ranks, default mode: {r['efficiency_pct']}% against {goal:.0f}%: {met}** (build "
            f"efficiency, without the load and setup, {r['build_efficiency_pct']}%). Wall {r['wall_s']} s against "
            f"an ideal {ideal:.3f} s (one process's {r['t1_s']} s over 256). Largest parts: "
            + ", ".join(f"{k} {v:.3f} s" for k, v in parts[:5])
            + f". Loss shares: " + ", ".join(f"{k} {v}%" for k, v in shares if k != "compute")
            + f"; the final pass is bound by its {r['final_bound']}. The largest single change simulated: "
            f"{best['change']} ({best['efficiency_pct']}%); all of them together {every['efficiency_pct']}% "
            f"({every['build_efficiency_pct']}% without the load and setup).")
    # Work every rank repeats whatever the count bounds the efficiency on its own: with F such
    # seconds per rank, efficiency <= 1 / (1 + P F / T1), so a goal E needs F <= T1 (1 - E) / (E P).
    r = next(r for r in prediction if r["network"] == "100gbit" and r["algorithm"] == "linear"
             and r["mode"] == "component" and r["ranks"] == 256)
    fixed = r["load_s"] + r["setup_s"] + r["round_serial_s"] + r["fit_s"]
    need = r["t1_s"] * 0.2 / (0.8 * 256)
    out.append(f"- **The serial share alone**: every rank repeats {fixed:.2f} s whatever the rank count (scene "
               f"load and BVH {r['load_s']:.2f} s, setup {r['setup_s']:.2f} s, inserting every record "
               f"{r['round_serial_s']:.2f} s, the fit {r['fit_s']:.2f} s). With one process's {r['t1_s']} s of work, "
               f"80% at 256 ranks needs at most {need:.3f} s of it, and {fixed:.2f} s caps the efficiency at "
               f"{100 / (1 + 256 * fixed / r['t1_s']):.0f}% at 256 ranks on any network (80% up to "
               f"{int(r['t1_s'] * 0.25 / fixed)} ranks). Lifting it needs the fit and the inserts split over the "
               f"ranks (each rank inserting only the records near what it renders) and a faster load (a scene and "
               f"BVH read prebuilt), or a frame with more work per rank (a 4K frame at -ab 2 is {r['t1_s']:.0f} s of one core).")
    for line in out:
        print(line)
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--simulate-only", action="store_true",
                        help="validate and predict from docs/scaling/measured.json without running anything")
    parser.add_argument("--repeats", type=int, default=3, help="runs of each measured configuration")
    parser.add_argument("--local-ranks", default="2,3,4,5")
    parser.add_argument("--modes", default="broadcast,component")
    parser.add_argument("--links", default="1gbit,100mbit", help="the test bed's link settings (tc rates)")
    parser.add_argument("--testbed-runs", default="broadcast:3,broadcast:5,component:5",
                        help="mode:ranks pairs run on every link of the test bed")
    parser.add_argument("--target-stats", help="--stats of a one-process render at the target size (skips that run)")
    parser.add_argument("--skip", default="", help="comma-separated stages to skip: profiles,target,local,testbed")
    parser.add_argument("--only", default="", help="'calibration': the -np 2 calibration runs again (with --skip)")
    args = parser.parse_args()
    skip = set(filter(None, args.skip.split(",")))
    store = {}
    if os.path.exists(STORE):
        with open(STORE) as f:
            store = json.load(f)
    if not args.simulate_only:
        common.require("bench/prepass_sim.py", commands=["mpirun"])
        common.build()
        work = common.scratch()
        started = time.monotonic()
        store["measured_at"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())

        def keep():
            """The store after every stage: a stage that fails or is stopped leaves the others'."""
            os.makedirs(os.path.dirname(STORE), exist_ok=True)
            with open(STORE, "w") as f:
                json.dump(store, f, indent=1)

        store.setdefault("links", {})["local"] = list(local_link())
        if "profiles" not in skip:
            profile_runs(LOCAL, work, store, threads2=True)
            profile_runs(SMALL, work, store)
            profile_runs(TESTBED, work, store)
            keep()
        if "calibration" in args.only:
            for case in (LOCAL, SMALL, TESTBED):
                calibrate(case, work, store)
            keep()
        if "local" not in skip:
            store["local"] = []
            plan = [(LOCAL, mode, int(n)) for mode in args.modes.split(",") for n in args.local_ranks.split(",")
                    if not (mode == "component" and int(n) < 3)]  # a PA and a PR need two workers
            plan += [(SMALL, mode, n) for mode in args.modes.split(",") for n in (3, 5)]
            measure_local(store, work, args.repeats, plan)
            keep()
        if "testbed" not in skip:
            if os.geteuid() != 0:
                print("prepass_sim: the test bed needs root (network namespaces); its runs are skipped")
            else:
                store["testbed"] = []
                cases = [(m, int(n)) for m, n in (p.split(":") for p in args.testbed_runs.split(","))]
                measure_testbed(store, work, args.repeats, args.links.split(","), cases)
                keep()
        if args.target_stats:
            with open(args.target_stats) as f:
                store["target"] = slim(json.load(f))
        elif "target" not in skip:
            t = time.monotonic()
            store["target"] = slim(one_process(TARGET["path"], TARGET["size"], TARGET["options"], 1, work))
            print(f"target {TARGET['size']} one process: {time.monotonic() - t:.0f} s")
        keep()
        print(f"measured in {time.monotonic() - started:.0f} s; kept in {STORE}")
    validation = validate(store)
    check = scaling_check(store)
    if "target" not in store:
        print(f"no one-process run at {TARGET['size']} in {STORE}: nothing predicted")
        return
    target, prediction = predict(store)
    ifs = what_if(target, target.one_process())
    for r in ifs:
        print(f"what if {r['network']:>7} {r['ranks']:4d} ranks: {r['efficiency_pct']:5.1f}%  {r['change']}")
    log = targets(prediction, ifs)
    write_docs(store, validation, check, target, prediction, ifs, log)


if __name__ == "__main__":
    main()
