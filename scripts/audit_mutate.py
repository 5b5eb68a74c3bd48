#!/usr/bin/env python3
"""Hostile-input files for scripts/audit.sh: truncations, seeded byte flips, store surgery and
hand-made malformed models. Deterministic: the same arguments give the same bytes (fixed seeds).

Subcommands (paths are plain files):
  offsets SRC           truncation offsets worth trying for SRC's format (one per line)
  trunc SRC DST N       the first N bytes of SRC
  flip SRC DST SEED     SRC with 1..3 bytes XOR-ed at offsets drawn from random.Random(SEED),
                        half of the seeds aiming at the first 512 bytes (headers)
  flipat SRC DST OFF    SRC with the byte at OFF XOR-ed with 0x10 (one bit)
  append SRC DST N      SRC followed by N bytes of seeded garbage
  store STORE           a store's regions, "kind name offset length [flags level_min]" per line
  garbage DST N SEED    N seeded random bytes
  special DIR           hand-made malformed models into DIR (names say what is wrong)
"""
import base64
import json
import random
import struct
import sys
import zlib
import gzip
import os

SECTION_NAMES = ["objects", "nodes", "groups", "page_table", "pages", "strings", "group_sources"]


def read(path):
    with open(path, "rb") as f:
        return f.read()


def write(path, data):
    with open(path, "wb") as f:
        f.write(data)


def header_len(data, name):
    """Where the format's header ends, so truncations land just before, at and after it."""
    if name.endswith(".gz"):
        return 10
    if name.endswith(".ply"):
        i = data.find(b"end_header\n")
        return i + len(b"end_header\n") if i >= 0 else 0
    if name.endswith(".stl"):
        return 84
    if name.endswith(".glb"):
        # 12-byte file header, 8-byte JSON chunk header, the JSON, then the BIN chunk header.
        if len(data) >= 20:
            json_len = struct.unpack_from("<I", data, 12)[0]
            return min(len(data), 20 + json_len)
        return 12
    if name.endswith(".tw"):
        return 344
    return 0


def offsets(src):
    data = read(src)
    n = len(data)
    h = header_len(data, src)
    cand = [0, 1, 7, h - 1, h, h + 1, n // 4, n // 2, (3 * n) // 4, n - 13, n - 1]
    seen = []
    for c in cand:
        if 0 <= c < n and c not in seen:
            seen.append(c)
    print("\n".join(str(c) for c in seen))


def flip(src, dst, seed):
    data = bytearray(read(src))
    rng = random.Random(int(seed))
    count = rng.randint(1, 3)
    head = rng.random() < 0.5
    for _ in range(count):
        hi = min(len(data), 512) if head else len(data)
        off = rng.randrange(0, hi)
        data[off] ^= rng.randint(1, 255)
    write(dst, bytes(data))


def flipat(src, dst, off):
    data = bytearray(read(src))
    data[int(off)] ^= 0x10
    write(dst, bytes(data))


def store(path):
    data = read(path)
    for i, name in enumerate(SECTION_NAMES):
        off, length = struct.unpack_from("<QQ", data, 160 + 24 * i)
        print(f"section {name} {off} {length}")
    pt_off, pt_len = struct.unpack_from("<QQ", data, 160 + 24 * 3)
    for p in range(pt_len // 32):
        e = pt_off + 32 * p
        off, clen = struct.unpack_from("<QI", data, e)
        level_min, level_max, flags = struct.unpack_from("<BBB", data, e + 28)
        print(f"page {p} {off} {clen} {flags} {level_min}")


def garbage(dst, n, seed):
    rng = random.Random(int(seed))
    write(dst, bytes(rng.getrandbits(8) for _ in range(int(n))))


def ply_ascii(verts, faces, header_extra=b"", vcount=None, fcount=None):
    vcount = len(verts) if vcount is None else vcount
    fcount = len(faces) if fcount is None else fcount
    out = b"ply\nformat ascii 1.0\n" + header_extra
    out += b"element vertex %s\nproperty float x\nproperty float y\nproperty float z\n" % str(vcount).encode()
    out += b"element face %s\nproperty list uchar int vertex_indices\nend_header\n" % str(fcount).encode()
    for v in verts:
        out += (" ".join(v) + "\n").encode()
    for f in faces:
        out += (str(len(f)) + " " + " ".join(str(i) for i in f) + "\n").encode()
    return out


def ply_binary(verts, faces, vcount=None, fcount=None):
    vcount = len(verts) if vcount is None else vcount
    fcount = len(faces) if fcount is None else fcount
    out = b"ply\nformat binary_little_endian 1.0\n"
    out += b"element vertex %d\nproperty float x\nproperty float y\nproperty float z\n" % vcount
    out += b"element face %d\nproperty list uchar uint vertex_indices\nend_header\n" % fcount
    for v in verts:
        out += struct.pack("<3f", *v)
    for f in faces:
        out += struct.pack("<B", len(f)) + b"".join(struct.pack("<I", i) for i in f)
    return out


def stl_binary(tris, count=None):
    count = len(tris) if count is None else count
    out = b"binary STL from audit_mutate".ljust(80, b" ") + struct.pack("<I", count)
    for t in tris:
        out += struct.pack("<3f", 0, 0, 1)
        for v in t:
            out += struct.pack("<3f", *v)
        out += b"\0\0"
    return out


TRI = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
TRI_BYTES = b"".join(struct.pack("<3f", *v) for v in TRI)


def gltf(uri, count=3, byte_length=36):
    return json.dumps({
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": count, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]}],
        "bufferViews": [{"buffer": 0, "byteLength": byte_length}],
        "buffers": [{"uri": uri, "byteLength": byte_length}],
    }).encode()


def glb(json_bytes, bin_bytes, total=None, json_len=None):
    json_bytes += b" " * ((4 - len(json_bytes) % 4) % 4)
    bin_bytes += b"\0" * ((4 - len(bin_bytes) % 4) % 4)
    body = struct.pack("<I4s", len(json_bytes) if json_len is None else json_len, b"JSON") + json_bytes
    body += struct.pack("<I4s", len(bin_bytes), b"BIN\0") + bin_bytes
    length = 12 + len(body) if total is None else total
    return struct.pack("<4sII", b"glTF", 2, length) + body


def glb_triangle(count=3, json_len=None, total=None):
    j = json.loads(gltf("x", count).decode())
    del j["buffers"][0]["uri"]
    return glb(json.dumps(j).encode(), TRI_BYTES, total=total, json_len=json_len)


def special(d):
    """Malformed models. The name's suffix after the last '--' says what the audit expects:
    fail (an error or a warning naming the problem), any (no panic, exit 0 or 1), ok (exit 0)."""
    v3 = [("0", "0", "0"), ("1", "0", "0"), ("0", "1", "0")]
    files = {
        "ply-absurd-vertex-count--fail.ply": ply_ascii(v3, [(0, 1, 2)], vcount=999999999999),
        "ply-absurd-vertex-count-bin--fail.ply": ply_binary(TRI, [(0, 1, 2)], vcount=999999999999),
        "ply-absurd-face-count--fail.ply": ply_binary(TRI, [(0, 1, 2)], fcount=999999999999),
        "ply-negative-count--fail.ply": ply_ascii(v3, [(0, 1, 2)], vcount=-3),
        "ply-huge-index--fail.ply": ply_binary(TRI, [(0, 1, 4000000000)]),
        "ply-huge-index-ascii--fail.ply": ply_ascii(v3, [(0, 1, 2147483647)]),
        "ply-face-255-verts--fail.ply": ply_binary(TRI, [(0, 1, 2)]).replace(b"\x03\0\0\0\0", b"\xff\0\0\0\0"),
        "ply-nan--fail.ply": ply_ascii([("nan", "0", "0")] + v3[1:], [(0, 1, 2)]),
        "ply-inf--fail.ply": ply_ascii([("inf", "0", "0")] + v3[1:], [(0, 1, 2)]),
        "ply-nan-bin--fail.ply": ply_binary([(float("nan"), 0, 0)] + TRI[1:], [(0, 1, 2)]),
        "ply-huge-coord--fail.ply": ply_ascii([("1e39", "0", "0")] + v3[1:], [(0, 1, 2)]),
        "ply-last-face-2-verts-bin--ok.ply": ply_binary(TRI, [(0, 1, 2), (0, 1)]),
        "ply-last-face-2-verts-ascii--ok.ply": ply_ascii(v3, [(0, 1, 2), (0, 1)]),
        "ply-escape-in-header--fail.ply": b"ply\nformat ascii 1.0\n\x1b]0;PWNED\x07\x1b[2J\nend_header\n",
        "ply-no-end-header--fail.ply": b"ply\nformat ascii 1.0\nelement vertex 3\n" + b"comment x\n" * 2000,
        "ply-long-line--fail.ply": b"ply\nformat ascii 1.0\ncomment " + b"a" * 50_000_000 + b"\n",
        "obj-nan--fail.obj": b"v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "obj-inf--fail.obj": b"v inf 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "obj-overflow--fail.obj": b"v 1e400 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "obj-huge-index--fail.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999\n",
        "obj-negative-index--fail.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -5 -6 -7\n",
        "obj-zero-index--fail.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n",
        "obj-missing-mtl--any.obj": b"mtllib /etc/passwd\nmtllib ../../none.mtl\nusemtl x\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
        "obj-escape--any.obj": b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nusemtl \x1b]0;PWNED\x07\nbogus \x1b]0;PWNED\x07\n",
        "obj-only-degenerate--fail.obj": b"v 0 0 0\nv 0 0 0\nv 0 0 0\nf 1 2 3\n",
        "obj-no-faces--fail.obj": b"v 0 0 0\nv 1 0 0\n",
        "stl-absurd-count--fail.stl": stl_binary([TRI], count=0xFFFFFFFF),
        "stl-count-too-small--any.stl": stl_binary([TRI, TRI], count=1),
        "stl-nan--fail.stl": stl_binary([[(float("nan"), 0, 0)] + TRI[1:]]),
        "stl-short-header--fail.stl": b"solid\0\0\0",
        "glb-absurd-length--fail.glb": glb_triangle(total=0xFFFFFFF0),
        "glb-absurd-json-length--fail.glb": glb_triangle(json_len=0xFFFFFFF0),
        "glb-absurd-accessor-count--fail.glb": glb_triangle(count=999999999999),
        "glb-valid--ok.glb": glb_triangle(),
        "gltf-uri-absolute--fail.gltf": gltf("/etc/passwd"),
        "gltf-uri-file-scheme--fail.gltf": gltf("file:///etc/passwd"),
        "gltf-uri-parent--fail.gltf": gltf("../outside.bin"),
        "gltf-uri-deep-parent--fail.gltf": gltf("sub/../../outside.bin"),
        "gltf-uri-missing--fail.gltf": gltf("missing.bin"),
        "gltf-uri-inside--ok.gltf": gltf("inside.bin"),
        "gltf-uri-data--ok.gltf": gltf("data:application/octet-stream;base64," + base64.b64encode(TRI_BYTES).decode()),
        "gltf-buffer-too-short--fail.gltf": gltf("inside.bin", count=3000, byte_length=36000),
        "gltf-not-json--fail.gltf": b"{\"asset\": {\"version\": \"2.0\"}, \"buffers\": [",
        "gltf-extras-array--ok.gltf": gltf("inside.bin").replace(b'"asset": {', b'"extras": [1, "x", null], "asset": {"extras": "s", '),
        "empty--fail.ply": b"",
        "empty--fail.obj": b"",
        "empty--fail.stl": b"",
        "empty--fail.glb": b"",
        "empty--fail.gltf": b"",
        "empty--fail.ply.gz": b"",
        "gz-of-empty--fail.ply.gz": gzip.compress(b""),
        "gz-not-gzip--any.ply.gz": b"ply\nformat ascii 1.0\nend_header\n",
        "gz-bomb-zeros--fail.ply.gz": gzip.compress(b"ply\nformat ascii 1.0\ncomment " + b"\0" * 200_000_000),
    }
    rng = random.Random(4242)
    for ext in ("ply", "obj", "stl", "glb", "gltf", "ply.gz"):
        expect = "any" if ext == "obj" else "fail"
        files[f"garbage--{expect}.{ext}"] = bytes(rng.getrandbits(8) for _ in range(65536))
    for name, data in files.items():
        write(os.path.join(d, name), data)
    write(os.path.join(d, "inside.bin"), TRI_BYTES)
    write(os.path.join(d, "..", "outside.bin"), TRI_BYTES)


def main():
    cmd, args = sys.argv[1], sys.argv[2:]
    if cmd == "offsets":
        offsets(*args)
    elif cmd == "trunc":
        write(args[1], read(args[0])[: int(args[2])])
    elif cmd == "flip":
        flip(*args)
    elif cmd == "flipat":
        flipat(*args)
    elif cmd == "append":
        rng = random.Random(int(args[2]))
        write(args[1], read(args[0]) + bytes(rng.getrandbits(8) for _ in range(int(args[2]))))
    elif cmd == "store":
        store(*args)
    elif cmd == "garbage":
        garbage(*args)
    elif cmd == "special":
        special(*args)
    else:
        sys.exit(f"audit_mutate.py: unknown subcommand {cmd}")


if __name__ == "__main__":
    main()
