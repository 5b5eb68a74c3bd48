#!/usr/bin/env python3
"""The table of scripts/peer-osg.sh: reads the per-run results in its working folder and prints
median frame time, fps and peak RSS of terawalk and OpenSceneGraph with their ratios, then writes
the same as JSON.

Per run r (1-based) the folder holds terawalk-r/report.json (`terawalk bench`), terawalk-r.rss and
osg-r.rss (/usr/bin/time -f %M: peak resident set in KiB), osg-r.json (osg_walk), and views.json
(image_compare on the first frame). A program's figure is the median over the runs of its
per-run median frame time, and the median of its per-run peak RSS.
"""
import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
import time


def fail(msg):
    print(f"peer-osg report: {msg}", file=sys.stderr)
    sys.exit(1)


def read_json(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        fail(f"{path}: {e}")


def read_rss_mb(path):
    """Peak RSS in MB (10^6 bytes) from a /usr/bin/time -f %M file (KiB; last line)."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = [l.strip() for l in f if l.strip()]
        return int(lines[-1]) * 1024 / 1e6
    except (OSError, ValueError, IndexError) as e:
        fail(f"{path}: no peak RSS ({e})")


def terawalk_run(d, r):
    rep = read_json(os.path.join(d, f"terawalk-{r}", "report.json"))
    try:
        run = rep["runs"][0]
        s = run["summary"]
        return {
            "median_ms": s["median_ms"],
            "frames": s["frames"],
            "peak_rss_mb": read_rss_mb(os.path.join(d, f"terawalk-{r}.rss")),
            "strategy": run["name"],
            "median_triangles": s.get("median_triangles"),
            "adapter": rep["meta"]["adapter"],
        }
    except (KeyError, IndexError, TypeError) as e:
        fail(f"{d}/terawalk-{r}/report.json: missing {e}")


def osg_run(d, r):
    rep = read_json(os.path.join(d, f"osg-{r}.json"))
    try:
        return {
            "median_ms": rep["median_ms"],
            "frames": rep["frames"],
            "peak_rss_mb": read_rss_mb(os.path.join(d, f"osg-{r}.rss")),
            "load_s": rep["load_s"],
            "renderer": rep["renderer"],
            "osg_version": rep["osg_version"],
        }
    except KeyError as e:
        fail(f"{d}/osg-{r}.json: missing {e}")


def summarise(runs, extra):
    med = statistics.median(r["median_ms"] for r in runs)
    out = {
        "median_ms": med,
        "fps": 1000.0 / med if med > 0 else 0.0,
        "peak_rss_mb": statistics.median(r["peak_rss_mb"] for r in runs),
        "frames": runs[0]["frames"],
        "runs": [{k: r[k] for k in ("median_ms", "peak_rss_mb", "load_s") if k in r} for r in runs],
    }
    out.update(extra)
    return out


def write_atomic(path, doc):
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".peer-osg-")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        json.dump(doc, f, indent=2)
        f.write("\n")
    os.chmod(tmp, 0o644)
    os.replace(tmp, path)


def adapter_label(adapter, api):
    """"llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)" -> "Vulkan llvmpipe"; `api` when the
    string names none (OSG's GL_RENDERER)."""
    name = adapter.split(" (")[0]
    if adapter.endswith(")") and adapter.count("(") >= 2:
        api = adapter.rsplit("(", 1)[1].split(",")[0].strip(")")
    return f"{api} {name}"


def print_table(doc):
    tw, osg, ratio, views = doc["terawalk"], doc["osg"], doc["ratios"], doc["views"]
    w, h = doc["size"]
    print(f"model {doc['model']}, path {doc['path']}: {tw['frames']} frames at {w}x{h}, "
          f"median of {doc['runs']} runs")
    print(f"{'':34} {'median ms':>10} {'fps':>8} {'peak RSS MB':>12} {'load s':>8}")
    print(f"{'terawalk bench, ' + adapter_label(tw['adapter'], '?'):34} {tw['median_ms']:10.1f} "
          f"{tw['fps']:8.2f} {tw['peak_rss_mb']:12.0f} {'':>8}")
    print(f"{'OSG ' + osg['osg_version'] + ', ' + adapter_label(osg['renderer'], 'GL'):34} "
          f"{osg['median_ms']:10.1f} {osg['fps']:8.2f} {osg['peak_rss_mb']:12.0f} {osg['load_s']:8.2f}")
    print(f"ratios: terawalk fps / OSG fps = {ratio['fps_terawalk_over_osg']:.2f}, "
          f"OSG RSS / terawalk RSS = {ratio['rss_osg_over_terawalk']:.2f}")
    verdict = "match" if views["match"] else "DO NOT MATCH"
    print(f"views of the first frame: {verdict} (edge NCC {views['edge_ncc']:.2f}, best shift "
          f"{views['best_shift_px']} px, best scale {views['best_scale']:.3f}); "
          f"side by side (terawalk left, OSG right): {views['side_by_side']}")


def main():
    ap = argparse.ArgumentParser()
    for a in ("--dir", "--model", "--path", "--size", "--out", "--build-s"):
        ap.add_argument(a, required=True)
    ap.add_argument("--runs", type=int, required=True)
    a = ap.parse_args()
    tw_runs = [terawalk_run(a.dir, r) for r in range(1, a.runs + 1)]
    osg_runs = [osg_run(a.dir, r) for r in range(1, a.runs + 1)]
    tw = summarise(tw_runs, {"adapter": tw_runs[0]["adapter"], "strategy": tw_runs[0]["strategy"],
                             "median_triangles": tw_runs[0]["median_triangles"],
                             "build_s": None if a.build_s == "null" else float(a.build_s)})
    osg = summarise(osg_runs, {"renderer": osg_runs[0]["renderer"],
                               "osg_version": osg_runs[0]["osg_version"],
                               "load_s": statistics.median(r["load_s"] for r in osg_runs)})
    if tw["frames"] != osg["frames"]:
        fail(f"terawalk rendered {tw['frames']} frames but OSG {osg['frames']}")
    views = read_json(os.path.join(a.dir, "views.json"))
    views["side_by_side"] = os.path.join(a.dir, "side-by-side.png")
    w, h = (int(x) for x in a.size.split("x"))
    doc = {
        "format": "terawalk-peer-osg-comparison",
        "version": 1,
        "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "machine": f"{os.cpu_count()} cores, {platform.system().lower()} {platform.machine()}",
        "model": a.model,
        "path": a.path,
        "size": [w, h],
        "runs": a.runs,
        "terawalk": tw,
        "osg": osg,
        "ratios": {
            "fps_terawalk_over_osg": tw["fps"] / osg["fps"] if osg["fps"] > 0 else None,
            "rss_osg_over_terawalk": osg["peak_rss_mb"] / tw["peak_rss_mb"],
        },
        "views": views,
    }
    write_atomic(a.out, doc)
    print_table(doc)
    print(f"written: {a.out}")


if __name__ == "__main__":
    main()
