"""The cluster-scale simulation (icsim.py) checked against the namespace cluster's runs
(cluster_bench.py): each measured run is simulated with the message costs measured on its own
links (`icrender bench messages` between two test-bed hosts: latency and bandwidth), the
per-record and per-pixel costs of the scene's serial run scaled to what the *other* traditional
modes' runs at the same link and process count took (ranks sharing this machine's cores compute
slower than one alone), and the per-request cost of the component mode taken from the *other*
component runs of the scene (leave one out: no run's own time enters its prediction), and the
prediction error is printed for cache misses, messages, bytes, aggregated time (T_amb + T_notamb
of the worker ranks) and render time.

Used by cluster_bench.py at the end of its runs, and by paper.py for docs/RESULTS.md; run alone,
it checks the CSVs cluster_bench.py left in bench/out:

    python3 bench/cluster_sim.py
"""

import csv
import json
import os

import common
import icsim

SCENES = {
    "cornell": os.path.join(common.SHARED_SCENES, "cornell_box", "CornellBox-Original.gltf"),
    "conference": os.path.join(common.SHARED_SCENES, "conference_room", "conference.gltf"),
    "corridor": os.path.join(common.ROOT, "scenes", "corridor.gltf"),
}
# What cluster_bench.py ran with when its settings file is missing (its defaults).
DEFAULT_SETTINGS = {"size": "192x144", "options": "-ab 1 -aa 0.2 -ad 256 -as 64 --tile 16x16"}
# A link with no measurement falls back to its nominal figures.
NOMINAL = {"unshaped": "loopback", "1gbit": "1gbit", "100mbit": "100mbit"}
TRADITIONAL = ("noshare", "centralised", "broadcast")


def pct(pred, real):
    return 100.0 * (pred - real) / real if real else float("nan")


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def link_costs(path):
    """link name -> (latency s, bandwidth B/s) as measured by cluster_bench.py, if it measured."""
    if not os.path.exists(path):
        return {}
    return {r["link"]: (float(r["latency_s"]), float(r["bandwidth_bytes_per_s"]))
            for r in read_csv(path) if r.get("latency_s") and r.get("bandwidth_bytes_per_s")}


def serial_costs(stats, pixels):
    """Per-record and per-pixel CPU seconds of a serial run."""
    record = stats["t_amb_s"] / max(stats["records_computed"], 1)
    pixel = stats["t_notamb_s"] / pixels
    return icsim.Costs(record=record, pixel=pixel, message=20e-6)


def validate(csv_path, links_path, settings_path, out_dir, say=print):
    """Simulates every successful run of the test bed's CSV; returns (rows, note)."""
    if not os.path.exists(csv_path):
        note = f"{csv_path} is absent (run `sudo python3 bench/cluster_bench.py` first): cluster check skipped."
        say(note)
        return [], note
    settings = DEFAULT_SETTINGS
    if os.path.exists(settings_path):
        with open(settings_path) as f:
            settings = json.load(f)
    width, height = (int(v) for v in settings["size"].split("x"))
    pixels = width * height
    tile = tuple(int(v) for v in (settings["options"].split("--tile")[1].split()[0].split("x")
                                  if "--tile" in settings["options"] else ("16", "16")))
    rows = [r for r in read_csv(csv_path) if r.get("status") == "ok"]
    measured_links = link_costs(links_path)
    work = common.scratch()
    traces = {}
    for name in sorted({r["scene"] for r in rows if r["mode"] == "serial"}):
        if name not in SCENES:
            continue
        trace = os.path.join(out_dir, f"trace-cluster-{name}.txt")
        base = ["-x", str(width), "-y", str(height)] + settings["options"].split() + ["--threads", "1"] + common.RASTER_ORDER
        common.render(SCENES[name], os.path.join(work, "t.exr"), base + ["--trace-cache", trace])
        stats, _ = common.render(SCENES[name], os.path.join(work, "s.exr"), base)
        accuracy = float(settings["options"].split("-aa")[1].split()[0]) if "-aa" in settings["options"] else 0.2
        traces[name] = (icsim.Trace(trace, width, height, accuracy), serial_costs(stats, pixels))
    runs = [r for r in rows if r["mode"] != "serial" and r["scene"] in traces]

    def simulate(r, costs):
        trace = traces[r["scene"]][0]
        network = measured_links.get(r["link"]) or NOMINAL.get(r["link"], "1gbit")
        return icsim.simulate(trace, r["mode"], int(r["ranks"]) - 1, costs, network=network, tile=tile,
                              cores=os.cpu_count())

    # Pass 1, with the serial run's costs: what the traditional modes would take at those costs.
    base_agg = {id(r): simulate(r, traces[r["scene"]][1]).aggregated for r in runs if r["mode"] in TRADITIONAL}

    def group_factor(r):
        """How much more CPU a record and a pixel took in the *other* traditional runs of the same
        scene, link and process count than in the serial run (ranks sharing cores run slower:
        caches, context switches): real aggregated time over the one simulated at serial costs."""
        others = [o for o in runs if o is not r and o["mode"] in TRADITIONAL and o["scene"] == r["scene"]
                  and o["link"] == r["link"] and o["ranks"] == r["ranks"] and o.get("aggregated_s")]
        sim = sum(base_agg[id(o)] for o in others)
        return sum(float(o["aggregated_s"]) for o in others) / sim if sim > 0 else 1.0

    def scaled(r):
        base, k = traces[r["scene"]][1], group_factor(r)
        return icsim.Costs(record=base.record * k, pixel=base.pixel * k, message=base.message)

    out = []
    for r in runs:
        costs = scaled(r)
        how = "record and pixel costs from the other traditional modes at this link and count"
        if r["mode"] == "component" and "requests_sent" in r:
            # Per request: the other component runs' aggregated time beyond their records and
            # pixels (costed like theirs), per request sent (leave one out).
            others = [o for o in runs if o is not r and o["mode"] == "component" and o["scene"] == r["scene"]
                      and o.get("requests_sent")]
            extra, requests = 0.0, 0
            for o in others:
                oc = scaled(o)
                extra += float(o["aggregated_s"]) - float(o["misses"]) * oc.record - pixels * oc.pixel
                requests += int(float(o["requests_sent"]))
            req = max(extra, 0.0) / requests if requests else 0.0
            costs.request_pr = costs.request_pa = req / 2
            how += "; per request from the other component runs"
        res = simulate(r, costs)
        row = {"scene": r["scene"], "link": r["link"], "mode": r["mode"], "processes": int(r["ranks"]),
               "network": "measured" if r["link"] in measured_links else "nominal", "costs": how,
               "real_misses": float(r["misses"]), "sim_misses": res.misses,
               "misses_err_pct": pct(res.misses, float(r["misses"])),
               "real_messages": int(float(r["messages"])), "sim_messages": res.messages,
               "messages_err_pct": pct(res.messages, float(r["messages"])),
               "real_bytes": float(r["bytes"]), "sim_bytes": res.bytes, "bytes_err_pct": pct(res.bytes, float(r["bytes"]))}
        if r.get("aggregated_s"):
            row.update(real_aggregated_s=float(r["aggregated_s"]), sim_aggregated_s=res.aggregated,
                       time_err_pct=pct(res.aggregated, float(r["aggregated_s"])))
        row.update(real_render_s=float(r["render_s"]), sim_render_s=res.makespan,
                   render_err_pct=pct(res.makespan, float(r["render_s"])))
        out.append(row)
        say(f"sim vs test bed {r['scene']:>10} {r['link']:>8} {r['mode']:<12} {r['ranks']} proc: misses "
            f"{row['misses_err_pct']:+6.1f}%, messages {row['messages_err_pct']:+6.1f}%, bytes "
            f"{row['bytes_err_pct']:+6.1f}%, aggregated time {row.get('time_err_pct', float('nan')):+6.1f}%, "
            f"render time {row['render_err_pct']:+6.1f}%")
    if out:
        for key, label in [("misses_err_pct", "misses"), ("messages_err_pct", "messages"), ("bytes_err_pct", "bytes"),
                           ("time_err_pct", "aggregated time"), ("render_err_pct", "render time")]:
            errors = [abs(r[key]) for r in out if key in r and r[key] == r[key]]
            if errors:
                say(f"sim vs test bed: {label:<16} mean |error| {sum(errors) / len(errors):5.1f}%, "
                    f"worst {max(errors):5.1f}% over {len(errors)} runs")
    links_note = ", ".join(f"{k}: {v[0] * 1e6:.0f} us, {v[1] / 1e6:.0f} MB/s" for k, v in sorted(measured_links.items()))
    note = (f"{len(out)} runs of {os.path.relpath(csv_path, common.ROOT)} simulated ({width}x{height}, "
            f"{settings['options']}), message costs "
            + (f"measured on the test bed's links ({links_note})." if measured_links else "nominal (links not measured)."))
    return out, note


if __name__ == "__main__":
    out_dir = os.path.join(common.ROOT, "bench", "out")
    checked, summary = validate(os.path.join(out_dir, "cluster-bench.csv"), os.path.join(out_dir, "cluster-links.csv"),
                                os.path.join(out_dir, "cluster-bench.json"), out_dir)
    common.write_csv(os.path.join(out_dir, "cluster-validation.csv"), checked)
    print(summary)
