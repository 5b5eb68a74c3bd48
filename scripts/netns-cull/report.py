#!/usr/bin/env python3
"""The table of scripts/netns-cull.sh: reads the benches in its working folder and prints, per
one-way delay, fps, p99 frame time, round trip, frames culled locally, bytes per frame, delta
savings, and the occlusion switch's bytes per frame for the measured delta size, then writes the
same as JSON.

The folder holds local/report.json (the bench without a server), delay-D/report.json per delay D
(`bench --cull-server`; the network figures are the lines it keeps in meta.extra) and delays.txt
("D TIMEOUT_MS" per line, in the order run).

The thesis' formula (Govindaraju 2004, §3: bytes per frame of the occlusion switch) is
8n + nh/b + 3(72 + h): n ids of 4 bytes to two receivers, a header of h bytes per b ids, and a
72-byte camera with its header to three PCs. n is the measured ids a delta carried per frame
(added + dropped, the thesis' "delta size"). The measured bytes are what the client wrote and
read (tw-net's messages, no TCP/IP headers); the formula counts one culling pair's traffic of a
three-PC switch, so the ratio says how far this two-PC wire is from it.
"""
import argparse
import json
import os
import platform
import re
import sys
import tempfile
import time


def fail(msg):
    print(f"netns-cull report: {msg}", file=sys.stderr)
    sys.exit(1)


def read_json(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        fail(f"{path}: {e}")


# The network lines `bench --cull-server` keeps in meta.extra (crates/terawalk/src/commands/
# cull_client.rs, NetTotals::lines), keyed "RUN: what".
NETWORK_LINES = {
    "cull server frames": (
        r"(\d+) of (\d+) \((\d+) culled locally; (\d+) server frames\)",
        ("remote_frames", "frames", "fallbacks", "server_frames"),
    ),
    "bytes per frame": (
        r"sent (\d+), received (\d+) \(visible set (\d+) ids, delta (\d+) ids\)",
        ("bytes_sent", "bytes_received", "visible_ids", "delta_ids"),
    ),
    "delta savings": (r"([0-9.]+) %", ("delta_savings_pct",)),
    "round trip": (
        r"median ([0-9.]+) ms \(server culling median ([0-9.]+) ms\)",
        ("round_trip_ms", "server_cull_ms"),
    ),
}


def bench_run(path):
    """A bench's first run: its summary figures and the adapter."""
    rep = read_json(path)
    try:
        run = rep["runs"][0]
        s = run["summary"]
        return rep, {
            "strategy": run["name"],
            "frames": s["frames"],
            "fps": s["median_fps"],
            "median_ms": s["median_ms"],
            "p99_ms": s["p99_ms"],
            "median_triangles": s.get("median_triangles"),
            "adapter": rep["meta"]["adapter"],
        }
    except (KeyError, IndexError, TypeError) as e:
        fail(f"{path}: missing {e}")


def network_figures(rep, path):
    """The network lines of a bench's first run, as numbers."""
    run = rep["runs"][0]["name"]
    extra = dict(rep["meta"].get("extra", []))
    out = {}
    for what, (pattern, names) in NETWORK_LINES.items():
        line = extra.get(f"{run}: {what}")
        if line is None:
            fail(f"{path}: no '{run}: {what}' line in meta.extra (was the bench run with --cull-server?)")
        m = re.match(pattern, line)
        if not m:
            fail(f"{path}: cannot read '{run}: {what}': {line!r}")
        for name, value in zip(names, m.groups()):
            out[name] = float(value) if "." in value else int(value)
    return out


def thesis_bytes(n, h, b):
    """Bytes per frame of the occlusion switch for n ids (the thesis' §3 formula)."""
    return 8 * n + n * h / b + 3 * (72 + h)


def read_delays(d):
    path = os.path.join(d, "delays.txt")
    try:
        with open(path, encoding="utf-8") as f:
            rows = [line.split() for line in f if line.strip()]
        return [(int(a), int(b)) for a, b in rows]
    except (OSError, ValueError) as e:
        fail(f"{path}: {e}")


def write_atomic(path, doc):
    folder = os.path.dirname(os.path.abspath(path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".netns-cull-")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=2)
        f.write("\n")
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)


def print_table(doc):
    w, h = doc["size"]
    local = doc["local"]
    print(f"store {doc['store']}, path {doc['path']}: {local['frames']} frames at {w}x{h}, "
          f"{local['strategy']}, {local['adapter']}")
    print(f"delay: one-way, netem on both ends of the veth (round trip + 2 x delay); thesis bytes: "
          f"8n + nh/b + 3(72+h), h = {doc['thesis']['h']}, b = {doc['thesis']['b']}, n = delta ids")
    head = (f"{'delay ms':>8} {'fps':>8} {'÷local':>6} {'p99 ms':>7} {'rtt ms':>7} {'fallback':>8} "
            f"{'sent B':>7} {'recv B':>7} {'saved %':>7} {'n':>6} {'thesis B':>9} {'÷thesis':>7}")
    print(head)
    print(f"{'local':>8} {local['fps']:8.1f} {1.0:6.2f} {local['p99_ms']:7.1f} {'':>7} "
          f"{'all':>8}")
    for r in doc["delays"]:
        fell = f"{r['fallbacks']}/{r['frames']}"
        print(f"{r['delay_ms']:>8} {r['fps']:8.1f} {r['fps_over_local']:6.2f} {r['p99_ms']:7.1f} "
              f"{r['round_trip_ms']:7.2f} {fell:>8} {r['bytes_sent']:7} {r['bytes_received']:7} "
              f"{r['delta_savings_pct']:7.1f} {r['delta_ids']:6} {r['thesis_bytes']:9.0f} "
              f"{r['measured_over_thesis']:7.2f}")


def main():
    ap = argparse.ArgumentParser()
    for a in ("--dir", "--store", "--path", "--size", "--out"):
        ap.add_argument(a, required=True)
    ap.add_argument("--header-bytes", type=int, required=True)
    ap.add_argument("--ids-per-packet", type=int, required=True)
    a = ap.parse_args()
    _, local = bench_run(os.path.join(a.dir, "local", "report.json"))
    rows = []
    for delay, timeout in read_delays(a.dir):
        path = os.path.join(a.dir, f"delay-{delay}", "report.json")
        rep, row = bench_run(path)
        net = network_figures(rep, path)
        if net["frames"] != row["frames"]:
            fail(f"{path}: {net['frames']} frames on the wire but {row['frames']} in the run")
        row.update(net)
        row["delay_ms"] = delay
        row["cull_timeout_ms"] = timeout
        row["fps_over_local"] = row["fps"] / local["fps"] if local["fps"] > 0 else None
        row["thesis_bytes"] = thesis_bytes(row["delta_ids"], a.header_bytes, a.ids_per_packet)
        measured = row["bytes_sent"] + row["bytes_received"]
        row["measured_over_thesis"] = measured / row["thesis_bytes"]
        rows.append(row)
    w, h = (int(x) for x in a.size.split("x"))
    doc = {
        "format": "terawalk-netns-cull",
        "version": 1,
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": f"{os.cpu_count()} cores, {platform.system().lower()} {platform.machine()}",
        "store": a.store,
        "path": a.path,
        "size": [w, h],
        "delay": "one-way ms, netem on both ends of the veth pair: the round trip grows by 2 x delay",
        "thesis": {"formula": "8n + nh/b + 3(72+h)", "h": a.header_bytes, "b": a.ids_per_packet},
        "local": local,
        "delays": rows,
    }
    write_atomic(a.out, doc)
    print_table(doc)
    print(f"written: {a.out}")


if __name__ == "__main__":
    main()
