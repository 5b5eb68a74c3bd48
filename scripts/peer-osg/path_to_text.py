#!/usr/bin/env python3
"""Converts a terawalk camera path (JSON, see crates/tw-runtime/src/path.rs) into the plain text
that osg_walk reads, so the C++ side needs no JSON parser.

Usage: path_to_text.py PATH.json OUT.txt
       path_to_text.py PATH.json --first-camera

OUT.txt: a line "terawalk-path-text 1", then one frame per line: ex ey ez tx ty tz ux uy uz fovy
(input coordinates; fovy = vertical field of view in degrees). With --first-camera it instead
prints the first frame in `terawalk render --camera` form ("x,y,z;x,y,z;x,y,z;fovy") on stdout.
Errors name the file and the frame, and exit with status 1.
"""
import json
import math
import sys


def fail(msg):
    print(f"path_to_text: {msg}", file=sys.stderr)
    sys.exit(1)


def load_frames(path):
    """The frames of a terawalk path, each as (eye, target, up, fovy), checked like terawalk does."""
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except OSError as e:
        fail(f"{path}: cannot open: {e.strerror}")
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        fail(f"{path}: not JSON: {e}")
    if not isinstance(doc, dict) or doc.get("format") != "terawalk-path":
        fail(f'{path}: "format" is not "terawalk-path"')
    if doc.get("version") != 1:
        fail(f"{path}: path version {doc.get('version')!r} is not supported (expected 1)")
    frames = doc.get("frames")
    if not isinstance(frames, list) or not frames:
        fail(f"{path}: the path has no frames")
    out = []
    for i, fr in enumerate(frames):
        try:
            eye, target, up = ([float(x) for x in fr[k]] for k in ("eye", "target", "up"))
            fovy = float(fr["fovy"])
        except (KeyError, TypeError, ValueError):
            fail(f"{path}: frame {i}: needs eye, target, up (3 numbers each) and fovy")
        vals = eye + target + up + [fovy]
        if len(eye) != 3 or len(target) != 3 or len(up) != 3 or not all(math.isfinite(v) for v in vals):
            fail(f"{path}: frame {i}: eye, target and up must be 3 finite numbers each")
        if not 1.0 <= fovy <= 179.0:
            fail(f"{path}: frame {i}: field of view must be 1..=179 degrees, got {fovy}")
        out.append((eye, target, up, fovy))
    return out


def main(argv):
    if len(argv) != 3:
        fail("usage: path_to_text.py PATH.json (OUT.txt | --first-camera)")
    src, dst = argv[1], argv[2]
    frames = load_frames(src)
    if dst == "--first-camera":
        eye, target, up, fovy = frames[0]
        print(";".join(",".join(repr(v) for v in p) for p in (eye, target, up)) + f";{fovy!r}")
        return
    try:
        with open(dst, "w", encoding="utf-8") as f:
            f.write("terawalk-path-text 1\n")
            for eye, target, up, fovy in frames:
                f.write(" ".join(repr(v) for v in eye + target + up + [fovy]) + "\n")
    except OSError as e:
        fail(f"{dst}: cannot write: {e.strerror}")


if __name__ == "__main__":
    main(sys.argv)
