#!/usr/bin/env python3
"""Combines the glTF binaries (.glb) of CAD assemblies into one .glb, optionally tiled into a
bigger assembly, flattens a .glb into a one-object binary PLY, and summarises a .glb. Used by
scripts/fetch-cad.sh on the KiCad demo boards tessellated by Open CASCADE; needs numpy.

    scripts/cad-glb.py merge OUT.glb IN.glb... [--copies N]
    scripts/cad-glb.py ply IN.glb OUT.ply
    scripts/cad-glb.py info IN.glb

merge: packs the inputs into a near-square block, in shelves side by side (the layout plane is
the two widest axes of their bounds, so flat boards stay flat), then places that block N times
in a near-square grid.
Every placement is a fresh copy of the inputs' node trees (glTF allows a node only one parent)
whose nodes share the inputs' meshes, so N copies cost N times the nodes but one copy of the
geometry; an importer expands them into N times the triangles. Nodes that draw a mesh and carry
only Open CASCADE's label entry as a name ("=>[0:1:1:3]") are renamed after their parent (the
part's reference, "C12"), prefixed by the input's file stem, so each part is a named object.

ply: writes every drawn triangle in world coordinates (node transforms applied, mirrored
instances rewound), with the primitive's material colour per vertex (linear to sRGB), as one
object: binary little-endian PLY with float x y z, uchar red green blue and uchar/int faces.
"""
import json
import math
import os
import struct
import sys

import numpy as np

COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
TRIANGLES = 4


class Glb:
    """One .glb: its JSON document and its binary chunk (memory-mapped)."""

    def __init__(self, path):
        self.path = path
        with open(path, "rb") as f:
            magic, version, _length = struct.unpack("<4sII", f.read(12))
            if magic != b"glTF" or version != 2:
                raise ValueError(f"{path}: byte 0: not a glTF 2.0 binary")
            json_len, json_type = struct.unpack("<II", f.read(8))
            if json_type != 0x4E4F534A:
                raise ValueError(f"{path}: byte 12: the first chunk is not JSON")
            self.doc = json.loads(f.read(json_len))
            bin_at = 20 + json_len + 8
        for key in ("images", "textures", "skins", "animations"):
            if self.doc.get(key):
                raise ValueError(f"{path}: has {key}, which this script does not carry over")
        self.bin = np.memmap(path, dtype=np.uint8, mode="r", offset=bin_at) if self.doc.get("buffers") else None

    def accessor(self, index):
        """The accessor's elements as an (count, width) array (a view where the layout allows)."""
        acc = self.doc["accessors"][index]
        view = self.doc["bufferViews"][acc["bufferView"]]
        dtype = np.dtype(COMPONENTS[acc["componentType"]])
        width = WIDTHS[acc["type"]]
        start = view.get("byteOffset", 0) + acc.get("byteOffset", 0)
        stride = view.get("byteStride", dtype.itemsize * width)
        count = acc["count"]
        raw = self.bin[start : start + stride * (count - 1) + dtype.itemsize * width] if count else self.bin[:0]
        return np.lib.stride_tricks.as_strided(
            raw.view(np.uint8), shape=(count, width * dtype.itemsize), strides=(stride, 1)
        ).copy().view(dtype).reshape(count, width)

    def scene_roots(self):
        scenes = self.doc.get("scenes", [])
        if scenes:
            return scenes[self.doc.get("scene", 0)].get("nodes", [])
        children = {c for n in self.doc.get("nodes", []) for c in n.get("children", [])}
        return [i for i in range(len(self.doc.get("nodes", []))) if i not in children]

    def instances(self):
        """(node index, world matrix) of every node that draws a mesh, depth first."""
        nodes = self.doc.get("nodes", [])
        stack = [(r, np.identity(4)) for r in reversed(self.scene_roots())]
        while stack:
            i, parent = stack.pop()
            world = parent @ local_matrix(nodes[i])
            if "mesh" in nodes[i]:
                yield i, world
            stack.extend((c, world) for c in reversed(nodes[i].get("children", [])))

    def triangles_drawn(self):
        per_mesh = [mesh_triangles(self.doc, m) for m in self.doc.get("meshes", [])]
        return sum(per_mesh[self.doc["nodes"][i]["mesh"]] for i, _ in self.instances())

    def bounds(self):
        """World-space bounds from the POSITION accessors' min/max (required by glTF)."""
        lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
        for i, world in self.instances():
            for prim in self.doc["meshes"][self.doc["nodes"][i]["mesh"]]["primitives"]:
                acc = self.doc["accessors"][prim["attributes"]["POSITION"]]
                corners = np.array([[x, y, z, 1.0] for x in (acc["min"][0], acc["max"][0])
                                    for y in (acc["min"][1], acc["max"][1]) for z in (acc["min"][2], acc["max"][2])])
                moved = (world @ corners.T).T[:, :3]
                lo, hi = np.minimum(lo, moved.min(0)), np.maximum(hi, moved.max(0))
        return lo, hi


def local_matrix(node):
    if "matrix" in node:
        return np.array(node["matrix"], dtype=float).reshape(4, 4).T
    x, y, z, w = node.get("rotation", [0.0, 0.0, 0.0, 1.0])
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    m = np.identity(4)
    m[:3, :3] = r * np.array(node.get("scale", [1.0, 1.0, 1.0]))
    m[:3, 3] = node.get("translation", [0.0, 0.0, 0.0])
    return m


def mesh_triangles(doc, mesh):
    total = 0
    for prim in mesh["primitives"]:
        if prim.get("mode", TRIANGLES) != TRIANGLES:
            continue
        key = prim["indices"] if "indices" in prim else prim["attributes"]["POSITION"]
        total += doc["accessors"][key]["count"] // 3
    return total


def merge(out, inputs, copies):
    """Step 1: append every input's buffers, accessors, materials and meshes once; step 2: place
    copies of their node trees in a block per copy and the blocks in a grid."""
    glbs = [Glb(p) for p in inputs]
    doc = {"asset": {"version": "2.0", "generator": "terawalk scripts/cad-glb.py"}, "accessors": [], "bufferViews": [],
           "materials": [], "meshes": [], "nodes": [], "scenes": [{"nodes": []}], "scene": 0}
    used = sorted({e for g in glbs for e in g.doc.get("extensionsUsed", [])})
    if used:
        doc["extensionsUsed"] = used
    blobs, offset, mesh_base = [], 0, []
    for g in glbs:
        view_base, acc_base, mat_base = len(doc["bufferViews"]), len(doc["accessors"]), len(doc["materials"])
        for view in g.doc.get("bufferViews", []):
            start = view.get("byteOffset", 0)
            blobs.append(bytes(g.bin[start : start + view["byteLength"]]))
            pad = (-view["byteLength"]) % 4
            blobs.append(b"\0" * pad)
            doc["bufferViews"].append({**view, "buffer": 0, "byteOffset": offset})
            offset += view["byteLength"] + pad
        for acc in g.doc.get("accessors", []):
            doc["accessors"].append({**acc, "bufferView": acc["bufferView"] + view_base})
        doc["materials"].extend(g.doc.get("materials", []))
        mesh_base.append(len(doc["meshes"]))
        for mesh in g.doc.get("meshes", []):
            prims = []
            for prim in mesh["primitives"]:
                p = {**prim, "attributes": {k: v + acc_base for k, v in prim["attributes"].items()}}
                if "indices" in prim:
                    p["indices"] = prim["indices"] + acc_base
                if "material" in prim:
                    p["material"] = prim["material"] + mat_base
                prims.append(p)
            doc["meshes"].append({**mesh, "primitives": prims})
    doc["buffers"] = [{"byteLength": offset}]

    places, size, (u, v) = block_layout(glbs)
    cols = math.ceil(math.sqrt(copies))
    for k in range(copies):
        shift = np.zeros(3)
        shift[u], shift[v] = (k % cols) * size[u], (k // cols) * size[v]
        for g, base, place in zip(glbs, mesh_base, places):
            stem = os.path.basename(g.path).rsplit(".", 1)[0]
            name = stem if copies == 1 else f"{stem}#{k}"
            root = len(doc["nodes"])
            doc["nodes"].append({"name": name, "translation": list(place + shift), "children": []})
            doc["scenes"][0]["nodes"].append(root)
            for r in g.scene_roots():
                doc["nodes"][root]["children"].append(copy_tree(g.doc["nodes"], r, base, name, doc["nodes"]))
    write_glb(out, doc, blobs)


def block_layout(glbs):
    """Translations that pack the inputs into a near-square block on the plane of the two widest
    axes of their union (the board plane): shelves of inputs side by side, in input order, a gap
    of 5% of the widest input apart. Returns the translations, the block's size and the axes."""
    bounds = [g.bounds() for g in glbs]
    lo = np.min([b[0] for b in bounds], axis=0)
    hi = np.max([b[1] for b in bounds], axis=0)
    u, v = (int(a) for a in np.argsort(hi - lo)[::-1][:2])
    extents = [(float(b_hi[u] - b_lo[u]), float(b_hi[v] - b_lo[v])) for b_lo, b_hi in bounds]
    gap = 0.05 * max(w for w, _ in extents)
    width = max(max(w for w, _ in extents), 1.2 * math.sqrt(sum((w + gap) * (h + gap) for w, h in extents)))
    places, x, y, shelf, used = [], 0.0, 0.0, 0.0, 0.0
    for (b_lo, _), (w, h) in zip(bounds, extents):
        if x > 0 and x + w > width:
            x, y, shelf = 0.0, y + shelf + gap, 0.0
        t = np.zeros(3)
        t[u], t[v] = x - b_lo[u], y - b_lo[v]
        places.append(t)
        used = max(used, x + w)
        x, shelf = x + w + gap, max(shelf, h)
    size = np.zeros(3)
    size[u], size[v] = used + gap, y + shelf + gap
    return places, size, (u, v)


def copy_tree(nodes, index, mesh_base, prefix, out):
    """Copies node `index` and its descendants into `out`; returns the copy's index."""
    def copy(i, parent_name):
        node = {k: v for k, v in nodes[i].items() if k != "children"}
        if "mesh" in node:
            node["mesh"] += mesh_base
            if node.get("name", "").startswith("=>") or not node.get("name"):
                node["name"] = f"{prefix}/{parent_name}"
        at = len(out)
        out.append(node)
        kids = [copy(c, nodes[i].get("name", parent_name)) for c in nodes[i].get("children", [])]
        if kids:
            out[at]["children"] = kids
        return at

    return copy(index, prefix)


def write_glb(out, doc, blobs):
    text = json.dumps(doc, separators=(",", ":")).encode()
    text += b" " * ((-len(text)) % 4)
    bin_len = sum(len(b) for b in blobs)
    tmp = out + ".part"
    with open(tmp, "wb") as f:
        f.write(struct.pack("<4sII", b"glTF", 2, 12 + 8 + len(text) + 8 + bin_len))
        f.write(struct.pack("<II", len(text), 0x4E4F534A))
        f.write(text)
        f.write(struct.pack("<II", bin_len, 0x004E4942))
        f.writelines(blobs)
    os.replace(tmp, out)


def srgb(linear):
    c = np.clip(np.asarray(linear[:3], dtype=float), 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.round(s * 255).astype(np.uint8)


def to_ply(src, out):
    """Two passes over the drawn primitives: vertices (world space, coloured), then faces."""
    g = Glb(src)
    prims = []
    for i, world in g.instances():
        for prim in g.doc["meshes"][g.doc["nodes"][i]["mesh"]]["primitives"]:
            if prim.get("mode", TRIANGLES) == TRIANGLES:
                prims.append((world, prim))
    counts = [(g.doc["accessors"][p["attributes"]["POSITION"]]["count"],
               g.doc["accessors"][p["indices"]]["count"] // 3 if "indices" in p
               else g.doc["accessors"][p["attributes"]["POSITION"]]["count"] // 3) for _, p in prims]
    verts, faces = sum(c[0] for c in counts), sum(c[1] for c in counts)
    materials = g.doc.get("materials", [])
    vertex = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    face = np.dtype([("n", "u1"), ("i", "<i4", (3,))], align=False)
    tmp = out + ".part"
    with open(tmp, "wb") as f:
        f.write((
            "ply\nformat binary_little_endian 1.0\ncomment KiCad demo boards via scripts/cad-glb.py\n"
            f"element vertex {verts}\nproperty float x\nproperty float y\nproperty float z\n"
            "property uchar red\nproperty uchar green\nproperty uchar blue\n"
            f"element face {faces}\nproperty list uchar int vertex_indices\nend_header\n"
        ).encode())
        for world, prim in prims:
            pos = g.accessor(prim["attributes"]["POSITION"]).astype(float)
            rec = np.empty(len(pos), vertex)
            moved = pos @ world[:3, :3].T + world[:3, 3]
            rec["x"], rec["y"], rec["z"] = moved[:, 0], moved[:, 1], moved[:, 2]
            factor = materials[prim["material"]].get("pbrMetallicRoughness", {}).get(
                "baseColorFactor", [1.0, 1.0, 1.0, 1.0]) if "material" in prim else [1.0, 1.0, 1.0, 1.0]
            rec["r"], rec["g"], rec["b"] = srgb(factor)
            f.write(rec.tobytes())
        base = 0
        for (world, prim), (nv, nf) in zip(prims, counts):
            idx = (g.accessor(prim["indices"]).reshape(-1)[: nf * 3] if "indices" in prim
                   else np.arange(nf * 3)).astype(np.int64).reshape(nf, 3)
            if np.linalg.det(world[:3, :3]) < 0:
                idx = idx[:, ::-1]
            rec = np.empty(nf, face)
            rec["n"] = 3
            rec["i"] = idx + base
            f.write(rec.tobytes())
            base += nv
    os.replace(tmp, out)
    return faces


def info(path):
    g = Glb(path)
    drawn = list(g.instances())
    lo, hi = g.bounds()
    print(f"{path}: {g.triangles_drawn()} triangles, {len(drawn)} part instances, "
          f"{len(g.doc.get('meshes', []))} meshes, {len(g.doc.get('materials', []))} materials, "
          f"size {' x '.join(f'{v:.3f}' for v in hi - lo)} m")


def main(argv):
    if len(argv) >= 3 and argv[0] == "merge":
        copies = 1
        if "--copies" in argv:
            at = argv.index("--copies")
            copies = int(argv[at + 1])
            argv = argv[:at] + argv[at + 2 :]
        if copies < 1:
            raise SystemExit("--copies must be at least 1")
        merge(argv[1], argv[2:], copies)
    elif len(argv) == 3 and argv[0] == "ply":
        to_ply(argv[1], argv[2])
    elif len(argv) == 2 and argv[0] == "info":
        info(argv[1])
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    try:
        main(sys.argv[1:])
    except (OSError, ValueError, KeyError, IndexError) as e:
        raise SystemExit(f"cad-glb.py: {e}")
