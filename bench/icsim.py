"""Trace-driven discrete-event simulation of the four parallel irradiance cache modes.

Input: the cache trace of a serial run (`icrender render --threads 1 --trace-cache FILE`): every
lookup in the order the renderer made it (pixel, point, normal, hit) and every new record with
the geometry that decides where it may be used (position, normal, principal axis, radii,
leak-test horizon). Costs come from real runs' statistics: seconds per new record, per pixel, per
lookup answered by the cache.

The simulator replays the image's pixels tile by tile, handing tiles to simulated ranks on
demand as the master controller does, and decides for each lookup whether a record the
simulated rank can see at that simulated time covers the point, with the same validity test as
the renderer (src/irradiance/record.rs, Hessian metric). What a rank can see follows its mode:

  noshare      its own records;
  centralised  its own, plus those the master had when the rank last synchronised (a rank sends
               its new records every --sync records and waits for the reply with the records it
               lacks);
  broadcast    its own, plus every record another rank broadcast (every --sync records), once the
               message has arrived (latency + size / bandwidth);
  component    PRs: the records the master had when they last asked for a tile; a PR's miss
               becomes a request buffered until --send requests, then sent to the PA of its
               tile (tile i to PA i mod n, src/parallel/component/pr.rs; flushed at tile end);
               PAs: their own records plus the master's at their last sync (every 8 records; a PA
               does not wait for the master's reply);
               when tiles run out, idle PRs take an eighth of the longest PA queue (load balancing),
               and so does a PA that runs dry (an eighth of the longest other queue).

With `overture` N > 0 (the renderer's --overture, default 3): in the serial run and the
traditional modes a rank first looks up (and makes) the records of the first surfaces at the
tile's N-pixel grid, then renders the tile's pixels (src/render.rs render_tile); in component
mode a PR renders the pixels on that grid (in the image's coordinates) first, so that their
requests reach the PA first (src/render/pixel.rs render_tile), a PA computes the requests of
pixels on that grid first (src/parallel/component/order.rs), and a helping PR is handed the
newest off-grid ones first.

A miss at a point the serial run answered from the cache makes a record shaped like the one
that answered it there (its radii, axis and horizon, at the new point and normal).

Messages cost latency + bytes / bandwidth on the network and a fixed CPU time per message on
both ends. Simulated time is per rank; the master's answers take a round trip. With `cores` set,
the worker ranks share that many cores in time slices (a machine running more ranks than cores,
as the one the measurements come from); by default every rank has a processor of its own.
"""

import bisect
import heapq
import math
from collections import defaultdict, deque

RECORD_BYTES = 128  # src/irradiance/codec.rs
REQUEST_BYTES = 100  # src/parallel/protocol/requests.rs
PIXEL_BYTES = 52  # src/parallel/protocol/mod.rs encode_pixels: four RGB layers and a record count
MIN_SHARE = 2  # src/parallel/component/balancer.rs: the smallest share worth forwarding
SHARE_DIVISOR = 8  # src/parallel/component/balancer.rs: an idle PR takes 1/8 of the longest queue

NETWORKS = {
    # name: (latency s, bandwidth bytes/s)
    "1gbit": (50e-6, 1e9 / 8),
    "100gbit": (2e-6, 100e9 / 8),
    "100mbit": (100e-6, 100e6 / 8),
    "loopback": (10e-6, 4e9),
}

HORIZON_SECTORS = 8
# Mean delay between a message's arrival and a polling rank noticing it, per round trip (the
# master's and the waiting rank's), when nothing measured is given: about half of
# src/parallel/comm.rs's largest pauses (0.1 ms at the master, 0.5 ms at a worker, where a wait
# that began with the request is noticed within about twice its own age). bench/paper.py
# measures it instead (the noshare runs' idle time per tile).
POLL_WAKE = 0.15e-3


def _norm(v):
    n = math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    return (v[0] / n, v[1] / n, v[2] / n) if n > 0 else v


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


class Record:
    __slots__ = ("p", "n", "u", "v", "r0", "r1", "reach", "level", "horizon", "headroom", "owner", "t_master",
                 "t_bcast", "rid")

    def __init__(self, p, n, u, r0, r1, level, horizon, headroom=math.inf):
        self.p, self.n, self.u = p, n, u
        self.v = _cross(n, u)
        self.r0, self.r1 = r0, r1
        self.reach = max(r0, r1)
        self.level = level
        self.horizon = horizon
        self.headroom = headroom
        self.owner = -1
        self.t_master = math.inf  # when the master has it
        self.t_bcast = math.inf  # when other ranks have it (broadcast)
        self.rid = 0

    def moved(self, p, n):
        """The same shape at another point and normal (axis projected on the new tangent plane)."""
        d = self.u[0] * n[0] + self.u[1] * n[1] + self.u[2] * n[2]
        u = (self.u[0] - d * n[0], self.u[1] - d * n[1], self.u[2] - d * n[2])
        if u[0] * u[0] + u[1] * u[1] + u[2] * u[2] < 1e-12:
            u = _norm(_cross(n, (1.0, 0.0, 0.0) if abs(n[0]) < 0.9 else (0.0, 1.0, 0.0)))
        else:
            u = _norm(u)
        return Record(p, n, u, self.r0, self.r1, self.level, self.horizon, self.headroom)

    def weight(self, p, n, level, max_angle, headroom=math.inf):
        """The renderer's validity test (Record::weight_at, Hessian metric, and the headroom
        test of irradiance::record::under_one_roof): weight or None."""
        if self.level > level:
            return None
        ox, oy, oz = p[0] - self.p[0], p[1] - self.p[1], p[2] - self.p[2]
        if ox * ox + oy * oy + oz * oz > self.reach * self.reach:
            return None
        sn = self.n
        along = ox * (n[0] + sn[0]) * 0.5 + oy * (n[1] + sn[1]) * 0.5 + oz * (n[2] + sn[2]) * 0.5
        cos_n = max(-1.0, min(1.0, n[0] * sn[0] + n[1] * sn[1] + n[2] * sn[2]))
        if along < -0.05 * min(self.r0, self.r1) or cos_n <= 0.0:
            return None
        d = ox * sn[0] + oy * sn[1] + oz * sn[2]
        tx, ty, tz = ox - sn[0] * d, oy - sn[1] * d, oz - sn[2] * d
        dist = math.sqrt(tx * tx + ty * ty + tz * tz)
        tu = tx * self.u[0] + ty * self.u[1] + tz * self.u[2]
        tv = tx * self.v[0] + ty * self.v[1] + tz * self.v[2]
        turn = (math.atan2(tv, tu) / (2 * math.pi)) % 1.0
        sector = min(int(turn * HORIZON_SECTORS), HORIZON_SECTORS - 1)
        if dist > self.horizon[sector]:
            return None
        if not under_one_roof(self.headroom, headroom, math.sqrt(ox * ox + oy * oy + oz * oz)):
            return None
        angle = math.acos(cos_n)
        if angle >= max_angle:
            return None
        du, dv = tu / self.r0, tv / self.r1
        t2 = du * du + dv * dv
        if not t2 < 1.0:
            return None
        return (1.0 - math.sqrt(t2)) * (1.0 - angle / max_angle)


def under_one_roof(a, b, distance, same_roof_ratio=4.0, roof_reach=2.0):
    """Whether a record and a point with headrooms a and b may share records `distance` apart
    (irradiance::record::under_one_roof, its fade taken as a cut)."""
    low, high = min(a, b), max(a, b)
    if not low < math.inf or distance <= 0.0:
        return True
    excess = high / low - same_roof_ratio
    return excess <= 0.0 or distance < roof_reach * low / excess


class Trace:
    """A serial run's cache trace: lookups per pixel, each with the record a miss there makes."""

    def __init__(self, path, width, height, accuracy):
        self.width, self.height = width, height
        self.max_angle = min(math.sqrt(2.0) * accuracy, math.pi / 4)
        self.lookups = defaultdict(list)  # pixel -> [(p, n, level, record a miss makes)]
        self.serial_misses = 0
        self.serial_lookups = 0
        reaches = []
        entry = None
        with open(path) as f:
            for line in f:
                parts = line.split()
                if parts[0] == "L":
                    pixel, level, hit = int(parts[1]), int(parts[2]), parts[3] == "1"
                    p = (float(parts[4]), float(parts[5]), float(parts[6]))
                    n = (float(parts[7]), float(parts[8]), float(parts[9]))
                    entry = [p, n, level, None]
                    self.lookups[pixel].append(entry)
                    self.serial_lookups += 1
                    self.serial_misses += 0 if hit else 1
                elif parts[0] == "R":
                    v = [float(x) for x in parts[3:]]
                    rec = Record(tuple(v[0:3]), tuple(v[3:6]), tuple(v[6:9]), v[9], v[10], int(parts[2]),
                                 tuple(v[11:19]), v[19] if len(v) > 19 else math.inf)
                    entry[3] = rec
                    reaches.append(rec.reach)
        reaches.sort()
        self.cell = max(reaches[len(reaches) // 2] if reaches else 1.0, 1e-9)
        missing = [e for es in self.lookups.values() for e in es if e[3] is None]
        if missing:
            raise ValueError(f"{path}: {len(missing)} lookups without a record line (an old trace?)")

    def tiles(self, tw, th):
        """Tiles in scanline order (src/render.rs), each a list of pixel indices."""
        out = []
        for y0 in range(0, self.height, th):
            for x0 in range(0, self.width, tw):
                out.append([y * self.width + x for y in range(y0, min(y0 + th, self.height))
                            for x in range(x0, min(x0 + tw, self.width))])
        return out


class Grid:
    """Uniform hash grid; a record sits in every cell its reach overlaps."""

    def __init__(self, cell):
        self.cell = cell
        self.cells = defaultdict(list)

    def insert(self, r):
        c, k = self.cell, r.reach
        x0, x1 = math.floor((r.p[0] - k) / c), math.floor((r.p[0] + k) / c)
        y0, y1 = math.floor((r.p[1] - k) / c), math.floor((r.p[1] + k) / c)
        z0, z1 = math.floor((r.p[2] - k) / c), math.floor((r.p[2] + k) / c)
        for x in range(x0, x1 + 1):
            for y in range(y0, y1 + 1):
                for z in range(z0, z1 + 1):
                    self.cells[(x, y, z)].append(r)

    def near(self, p):
        c = self.cell
        return self.cells.get((math.floor(p[0] / c), math.floor(p[1] / c), math.floor(p[2] / c)), ())


class Costs:
    """CPU seconds per new record (its L_a, lookups included), per pixel (everything but L_a),
    per message on each end, and per component-mode request: making and sending it on a PR
    (`request_pr`), receiving and handling it where it is computed (`request_pa`)."""

    def __init__(self, record, pixel, hit=0.0, message=20e-6, request_pr=0.0, request_pa=0.0):
        self.record, self.pixel, self.hit, self.message = record, pixel, hit, message
        self.request_pr, self.request_pa = request_pr, request_pa

    def __repr__(self):
        return (f"Costs(record {self.record * 1e3:.3f} ms, pixel {self.pixel * 1e6:.2f} us, message "
                f"{self.message * 1e6:.1f} us, request {self.request_pr * 1e6:.1f} + {self.request_pa * 1e6:.1f} us)")


class PAQueue:
    """A PA's queue (src/parallel/component/order.rs): requests at grid pixels first, each
    group in arrival order; only requests that have arrived can be taken."""

    def __init__(self, width, stride):
        self.width, self.stride = width, stride
        self.grid, self.rest = deque(), deque()  # (arrival time, pixel, entry)

    def on_grid(self, pixel):
        s = self.stride
        return s > 1 and pixel % self.width % s == s // 2 and pixel // self.width % s == s // 2

    def __len__(self):
        return len(self.grid) + len(self.rest)

    def append(self, arrival, pixel, entry):
        (self.grid if self.on_grid(pixel) else self.rest).append((arrival, pixel, entry))

    def pop_ready(self, now):
        """The next request that has arrived by `now`, or None."""
        for q in (self.grid, self.rest):
            if q and q[0][0] <= now + 1e-15:
                return q.popleft()[2]
        return None

    def next_arrival(self):
        return min(q[0][0] for q in (self.grid, self.rest) if q)

    def take_newest(self, count):
        """Up to `count` requests for a helper, the newest off-grid ones first, in queue order:
        (pixel, entry) pairs."""
        taken = deque()
        for q in (self.rest, self.grid):
            while q and len(taken) < count:
                taken.appendleft(q.pop()[1:])
        return taken


class Result:
    def __init__(self, mode, workers):
        self.mode, self.workers = mode, workers
        self.misses = 0
        self.lookups = 0
        self.busy = [0.0] * workers  # CPU seconds per worker
        self.idle = [0.0] * workers
        self.end = [0.0] * workers
        self.messages = 0
        self.bytes = 0
        self.requests = 0
        self.forwarded = 0

    @property
    def makespan(self):
        return max(self.end) if self.end else 0.0

    @property
    def aggregated(self):
        return sum(self.busy)

    @property
    def idle_fraction(self):
        """Idle share of the aggregated time (paper, Figure 10): sum of idle times over
        processors x rendering time."""
        total = self.makespan * self.workers
        return (total - self.aggregated) / total if total > 0 else 0.0

    def row(self):
        return {"mode": self.mode, "workers": self.workers, "misses": self.misses, "aggregated_s": self.aggregated,
                "makespan_s": self.makespan, "idle_pct": 100 * self.idle_fraction, "messages": self.messages,
                "bytes": self.bytes}


class Sim:
    """One simulated render. `workers` excludes the master (paper: processors)."""

    def __init__(self, trace, mode, workers, costs, network="1gbit", tile=(16, 16), sync=None, send=32, pa=None,
                 pa_sync=8, wake=POLL_WAKE, cores=None, quantum=3e-3, overture=0):
        self.t = trace
        self.overture = overture
        self.mode = mode
        self.W = workers
        self.c = costs
        self.lat, self.bw = NETWORKS[network] if isinstance(network, str) else network
        # A waiting rank and the master poll for messages with a growing pause (at most 0.5 ms,
        # src/parallel/comm.rs): on average a message is noticed this long after it arrives
        # (half of it at each end of a round trip).
        self.wake = wake
        # Fewer cores than worker ranks (the measuring machine, --oversubscribe): the ranks take
        # turns, `cores` at a time, in time slices of `quantum` seconds (the order of Linux's
        # scheduler slices). None: a processor per rank (a cluster).
        self.groups = max(1, math.ceil(workers / cores)) if cores else 1
        self.quantum = quantum
        self.tiles = deque(trace.tiles(*tile))
        self.sync = sync if sync is not None else 50
        self.send = send
        self.pa_sync = pa_sync
        self.npa = 0
        if mode == "component":
            self.npa = pa if pa is not None else max(workers // 2, 1)
            if self.npa >= workers:
                raise ValueError("component mode needs at least one PR")
        self.res = Result(mode, workers)
        self.grid = Grid(trace.cell)
        self.master = []  # records at the master, in arrival order (t_master ascending)
        self.master_times = []
        self.seen_sync = [-math.inf] * workers  # master time of each rank's last sync

    def cpu(self, w, t, work):
        """When rank w, starting at t, has done `work` seconds of computing."""
        if self.groups <= 1 or work <= 0.0:
            return t + work
        q, G, g = self.quantum, self.groups, w % self.groups
        k = math.floor(t / q + 1e-9)
        if k % G != g:  # wait for this rank's next slice
            k += (g - k) % G
            t = max(t, k * q)
        while True:
            run = min(work, (k + 1) * q - t)
            t += run
            work -= run
            if work <= 1e-12:
                return t
            k += G  # the others' slices pass
            t = k * q

    # -- messages ------------------------------------------------------------------------
    def msg(self, nbytes, count=1):
        self.res.messages += count
        self.res.bytes += nbytes * count
        return self.lat + nbytes / self.bw

    # -- the cache -----------------------------------------------------------------------
    def visible(self, r, rank, now):
        if r.owner == rank:
            return True
        if self.mode == "noshare":
            return False
        if self.mode == "broadcast":
            return r.t_bcast <= now
        return r.t_master <= self.seen_sync[rank]

    def covered(self, p, n, level, rank, now, headroom=math.inf):
        ma = self.t.max_angle
        for r in self.grid.near(p):
            if self.visible(r, rank, now) and r.weight(p, n, level, ma, headroom) is not None:
                return True
        return False

    def new_record(self, entry, rank):
        r = entry[3].moved(entry[0], entry[1])
        r.owner = rank
        self.grid.insert(r)
        self.res.misses += 1
        return r

    def to_master(self, records, arrival):
        for r in records:
            r.t_master = arrival
            self.master.append(r)
            self.master_times.append(arrival)

    def missing_for(self, rank, since, upto):
        """How many records the master holds that arrived in (since, upto] and are not the rank's."""
        lo = bisect.bisect_right(self.master_times, since)
        hi = bisect.bisect_right(self.master_times, upto)
        return sum(1 for r in self.master[lo:hi] if r.owner != rank)

    # -- traditional modes ------------------------------------------------------------------
    def plan(self, tile):
        """A tile's steps, (pixel, overture?): the overture's grid pixels first (their eye-path
        lookup only), then every pixel (src/render.rs render_tile)."""
        steps = [(p, False) for p in tile]
        s, width = self.overture, self.t.width
        if s <= 0 or not tile:
            return steps
        x0, y0 = min(p % width for p in tile), min(p // width for p in tile)
        grid = [(p, True) for p in tile if (p % width - x0) % s == s // 2 and (p // width - y0) % s == s // 2]
        return grid + steps

    def pr_order(self, tile):
        """The order a component-mode PR renders a tile's pixels in (src/render/pixel.rs
        render_tile): with the overture on, the pixels on the image's grid first (the grid the
        PAs compute first), then the others, each group in scanline order."""
        s, width = self.overture, self.t.width
        if s <= 1:
            return tile
        on = [p for p in tile if p % width % s == s // 2 and p // width % s == s // 2]
        return on + [p for p in tile if not (p % width % s == s // 2 and p // width % s == s // 2)]

    def run_traditional(self):
        W, c, res = self.W, self.c, self.res
        clock = [0.0] * W
        outbox = [[] for _ in range(W)]
        heap = [(0.0, w) for w in range(W)]
        heapq.heapify(heap)
        state = [None] * W  # (pixels of the current tile, index)
        master_free = 0.0
        while heap:
            now, w = heapq.heappop(heap)
            if state[w] is None or state[w][1] >= len(state[w][0]):
                # Ask the master for a tile (the finished tile's pixels go with the request).
                t0 = clock[w]
                finished = sum(1 for _, o in state[w][0] if not o) if state[w] is not None else 0
                arrive = t0 + self.msg(16 + PIXEL_BYTES * finished) + self.wake / 2
                master_free = max(master_free, arrive)
                back = master_free + self.msg(8) + self.wake / 2
                res.busy[w] += 2 * c.message
                clock[w] = back + c.message
                res.idle[w] += back - t0
                if not self.tiles:
                    self.finish_traditional(w, clock, outbox)
                    continue
                state[w] = (self.plan(self.tiles.popleft()), 0)
                heapq.heappush(heap, (clock[w], w))
                continue
            steps, i = state[w]
            pixel, overture = steps[i]
            state[w] = (steps, i + 1)
            entries = self.t.lookups.get(pixel, ())
            spent = 0.0 if overture else c.pixel
            for entry in entries[:1] if overture else entries:
                res.lookups += 1
                if self.covered(entry[0], entry[1], entry[2], w, clock[w], entry[3].headroom):
                    spent += c.hit
                else:
                    spent += c.record
                    r = self.new_record(entry, w)
                    if self.mode != "noshare":
                        outbox[w].append(r)
            clock[w] = self.cpu(w, clock[w], spent)
            res.busy[w] += spent
            if self.mode != "noshare" and len(outbox[w]) >= self.sync:
                self.share(w, clock, outbox)
            heapq.heappush(heap, (clock[w], w))
        res.end = clock

    def share(self, w, clock, outbox):
        res, c = self.res, self.c
        records = outbox[w]
        outbox[w] = []
        nbytes = 16 + RECORD_BYTES * len(records)
        t0 = clock[w]
        if self.mode == "centralised":
            arrive = t0 + self.msg(nbytes) + self.wake / 2
            self.to_master(records, arrive)
            missing = self.missing_for(w, self.seen_sync[w], arrive)
            back = arrive + self.msg(16 + RECORD_BYTES * missing) + self.wake / 2
            self.seen_sync[w] = arrive
            res.busy[w] += 2 * c.message
            res.idle[w] += back - t0
            clock[w] = back + 2 * c.message
        elif self.mode == "broadcast":
            # One message to every other rank and to the master; sending costs CPU per message.
            k = self.W
            travel = self.msg(nbytes, k) + self.wake / 2
            for r in records:
                r.t_bcast = t0 + travel
            spent = k * c.message
            clock[w] += spent
            res.busy[w] += spent
            # Receiving: every other worker spends one message's CPU time.
            for o in range(self.W):
                if o != w:
                    res.busy[o] += c.message

    def finish_traditional(self, w, clock, outbox):
        if outbox[w] and self.mode == "centralised":
            self.share(w, clock, outbox)
        elif self.mode == "broadcast":
            self.share(w, clock, outbox)

    # -- component mode ---------------------------------------------------------------------
    def run_component(self):
        W, c, res = self.W, self.c, self.res
        pas = list(range(self.npa))
        prs = list(range(self.npa, W))
        clock = [0.0] * W
        queue = {a: PAQueue(self.t.width, self.overture) for a in pas}
        outbox = {a: [] for a in range(W)}
        buffer = {p: [] for p in prs}
        # The PA each PR's current tile sends to: tile i goes to PA i mod n, so one PA sees all
        # of a tile's neighbouring points (src/parallel/component/pr.rs).
        tile_pa = {p: 0 for p in prs}
        handed = 0  # tiles handed out so far; tiles are numbered in scanline order
        reported = {a: 0 for a in pas}  # queue length the master last heard of
        state = {p: None for p in prs}
        pr_done = set()
        helping = {}  # helper PR -> deque of entries
        heap = [(0.0, w) for w in range(W)]
        heapq.heapify(heap)
        outstanding = 0  # requests sent but not computed

        parked = deque()
        dry = deque()  # PAs that ran dry after the last tile went out, waiting for a share

        def take_share(to):
            """An eighth of the longest PA queue other than `to`'s, if worth forwarding (src/
            parallel/component/balancer.rs LoadBalancer::share_for): (that PA, its share as (pixel, entry)
            pairs), or None."""
            best = max((o for o in pas if o != to), key=lambda o: len(queue[o]), default=None)
            if best is None or len(queue[best]) // SHARE_DIVISOR < MIN_SHARE:
                return None
            taken = queue[best].take_newest(len(queue[best]) // SHARE_DIVISOR)
            res.forwarded += len(taken)
            return best, taken

        def feed_pa(a, now):
            """A PA that ran dry gets a share of the longest other queue (balancer.rs LoadBalancer::rebalance): its
            status to the master, the master's order, the share."""
            shared = take_share(a)
            if shared is None:
                return False
            best, taken = shared
            share = len(taken)
            arrive = max(clock[a], now) + self.msg(16) + self.msg(8) + self.msg(12 + REQUEST_BYTES * share) \
                + 1.5 * self.wake
            res.busy[best] += c.message
            for pixel, e in taken:
                queue[a].append(arrive, pixel, e)
            if not inheap[a]:
                inheap[a] = True
                heapq.heappush(heap, (max(clock[a], arrive), a))
            return True

        def dispatch(p, now):
            shared = take_share(p)
            if shared is None:
                return False
            taken = shared[1]
            share = len(taken)
            start = max(clock[p], now)
            back = start + self.msg(8) + self.msg(12 + REQUEST_BYTES * share) + self.lat + 1.5 * self.wake
            res.idle[p] += back - clock[p]
            clock[p] = back
            helping[p] = deque(e for _, e in taken)
            heapq.heappush(heap, (clock[p], p))
            return True

        def round_trip(w):
            """w's new records to the master and the records w lacks back, starting at w's
            clock: when the master has them (master time) and when the answer is back at w."""
            records = outbox[w]
            outbox[w] = []
            arrive = clock[w] + self.msg(16 + RECORD_BYTES * len(records)) + self.wake / 2
            self.to_master(records, arrive)
            missing = self.missing_for(w, self.seen_sync[w], arrive)
            back = arrive + self.msg(16 + RECORD_BYTES * missing) + self.wake / 2
            res.busy[w] += 2 * c.message
            return arrive, back

        def sync_master(w, arrive_extra=0.0):
            """Records up, the records w lacks down. A PR waits for the reply (it needs the
            records before its tile); a PA does not (src/parallel/component/pa.rs): it goes on
            computing and takes the records in when they come (their arrival is approximated
            here by the master's time, as for the PRs)."""
            t0 = clock[w]
            arrive, back = round_trip(w)
            self.seen_sync[w] = arrive
            if w in queue:
                clock[w] = t0 + 2 * c.message
            else:
                res.idle[w] += back - t0
                clock[w] = back + c.message
            while w in queue and parked and dispatch(parked[0], arrive):
                parked.popleft()
            while w in queue and dry and feed_pa(dry[0], arrive):
                dry.popleft()

        def flush(p):
            nonlocal outstanding
            if not buffer[p]:
                return
            a = pas[tile_pa[p]]
            arrive = clock[p] + self.msg(12 + REQUEST_BYTES * len(buffer[p])) + self.wake / 2
            clock[p] += c.message
            res.busy[p] += c.message
            for pixel, e in buffer[p]:
                queue[a].append(arrive, pixel, e)
            outstanding += len(buffer[p])
            buffer[p] = []
            if not inheap[a]:
                inheap[a] = True
                heapq.heappush(heap, (max(clock[a], arrive), a))

        inheap = {w: True for w in range(W)}
        pending = {p: None for p in prs}  # the tile a PR has asked for: (tile, index, reply time, master time)
        out_of_tiles = set()

        def request_tile(w):
            """A PR asks the master for its next tile (and sends its own records, if it made
            any while helping); it goes on working while the answer travels."""
            nonlocal handed
            t0 = clock[w]
            arrive, back = round_trip(w)
            clock[w] = t0 + c.message
            tile, index = None, None
            if self.tiles:
                tile, index = self.tiles.popleft(), handed
                handed += 1
            pending[w] = (tile, index, back, arrive)

        def compute(w, entry):
            """A request computed on rank w (PA or helping PR) through w's cache."""
            nonlocal outstanding
            outstanding -= 1
            res.requests += 1
            spent = c.request_pa
            if self.covered(entry[0], entry[1], entry[2], w, clock[w], entry[3].headroom):
                spent += c.hit
            else:
                spent += c.record
                outbox[w].append(self.new_record(entry, w))
            clock[w] = self.cpu(w, clock[w], spent)
            res.busy[w] += spent
            if len(outbox[w]) >= self.pa_sync:
                sync_master(w)

        scheduled = set()
        while heap:
            now, w = heapq.heappop(heap)
            if now < clock[w] - 1e-15:
                heapq.heappush(heap, (clock[w], w))
                if w in queue:
                    inheap[w] = True
                continue
            if w in queue:  # a PA
                inheap[w] = False
                q = queue[w]
                e = q.pop_ready(clock[w])
                if e is not None:
                    compute(w, e)
                    reported[w] = len(q)
                    inheap[w] = True
                    heapq.heappush(heap, (clock[w], w))
                elif q:
                    res.idle[w] += q.next_arrival() - clock[w]
                    clock[w] = q.next_arrival()
                    inheap[w] = True
                    heapq.heappush(heap, (clock[w], w))
                else:
                    if outbox[w]:
                        sync_master(w)
                    reported[w] = 0
                    res.end[w] = clock[w]
                    # Woken again by flush() when requests arrive, or, once every tile is out,
                    # by a share of another PA's queue.
                    if not self.tiles and w not in dry and not feed_pa(w, clock[w]):
                        dry.append(w)
                continue
            # A PR.
            if w in helping:
                h = helping[w]
                if h:
                    compute(w, h.popleft())
                    heapq.heappush(heap, (clock[w], w))
                    continue
                del helping[w]
                if outbox[w]:
                    sync_master(w)
            if state[w] is not None and state[w][1] < len(state[w][0]):
                pixels, i = state[w]
                pixel = pixels[i]
                state[w] = (pixels, i + 1)
                spent = c.pixel
                for entry in self.t.lookups.get(pixel, ()):
                    res.lookups += 1
                    if self.covered(entry[0], entry[1], entry[2], w, clock[w], entry[3].headroom):
                        spent += c.hit
                    else:
                        buffer[w].append((pixel, entry))
                        spent += c.request_pr
                clock[w] = self.cpu(w, clock[w], spent)
                res.busy[w] += spent
                if len(buffer[w]) >= self.send:
                    flush(w)
                heapq.heappush(heap, (clock[w], w))
                continue
            # Needs work: the finished tile's requests go out, then the tile asked for when this
            # one began (src/parallel/component/pr.rs: a PR asks for its next tile as it starts
            # the current one), with the records the master sent with it.
            flush(w)
            if w not in out_of_tiles:
                if pending[w] is None:  # the first tile: nothing was asked for yet
                    request_tile(w)
                tile, index, back, arrive = pending[w]
                pending[w] = None
                if back > clock[w]:
                    res.idle[w] += back - clock[w]
                    clock[w] = back
                clock[w] += c.message
                self.seen_sync[w] = max(self.seen_sync[w], arrive)
                if tile is not None:
                    state[w] = (self.pr_order(tile), 0)
                    tile_pa[w] = index % len(pas)
                    request_tile(w)
                    heapq.heappush(heap, (clock[w], w))
                    continue
                out_of_tiles.add(w)
            pr_done.add(w)
            # Load balancing: an eighth of the longest PA queue; otherwise the master keeps the PR
            # waiting until a PA reports a queue worth splitting (or everything is done).
            if dispatch(w, clock[w]):
                continue
            if outstanding > 0:
                parked.append(w)
                continue
            res.end[w] = clock[w]
        for a in pas:
            res.end[a] = max(res.end[a], clock[a])
        for p in prs:
            res.end[p] = max(res.end[p], clock[p])
        # The image buffers go to the master at the end (48 bytes a pixel each).
        self.msg(48 * self.t.width * self.t.height, W)

    def run(self):
        if self.mode == "serial":
            # One process with no master: no messages, no waits, nothing to pay for them.
            self.c = Costs(record=self.c.record, pixel=self.c.pixel, hit=self.c.hit, message=0.0)
            self.wake, self.lat, self.bw = 0.0, 0.0, math.inf
            self.mode, self.W = "noshare", 1
            self.res = Result("serial", 1)
            self.seen_sync = [-math.inf]
            self.run_traditional()
            self.mode = "serial"
        elif self.mode == "component":
            self.run_component()
        else:
            self.run_traditional()
        end = max(self.res.end)
        for w in range(self.W):
            self.res.idle[w] = end - self.res.busy[w]
        return self.res


def simulate(trace, mode, workers, costs, **kwargs):
    return Sim(trace, mode, workers, costs, **kwargs).run()
