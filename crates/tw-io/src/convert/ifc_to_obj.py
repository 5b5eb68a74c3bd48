"""IFC -> Wavefront OBJ for terawalk (run by tw-io's `convert` module, not by hand).

Usage: python3 ifc_to_obj.py INPUT.ifc OUTPUT.obj

Tessellates every product with IfcOpenShell's geometry iterator in world coordinates (metres:
IfcOpenShell converts the file's length unit to SI) and writes one OBJ object per product,
named "Name [GlobalId]" (the IFC class stands in for a missing name), so that a pick in the
viewer tells which product it hit. Each product gets one colour: the surface style of most of
its faces (an OBJ `usemtl` change inside an object would split it into "name/material"
objects). Spaces and openings are skipped: they are volumes, not visible building parts.

Exit status 3 means IfcOpenShell is not installed; terawalk then prints how to install it.
"""

import math
import multiprocessing
import sys

MISSING_MODULE = 3


def main(argv):
    if len(argv) != 3:
        print("usage: ifc_to_obj.py INPUT.ifc OUTPUT.obj", file=sys.stderr)
        return 2
    try:
        import ifcopenshell
        import ifcopenshell.geom
    except ImportError as e:
        print(f"terawalk: the Python module ifcopenshell is missing ({e})", file=sys.stderr)
        return MISSING_MODULE
    src, dst = argv[1], argv[2]
    try:
        model = ifcopenshell.open(src)
    except Exception as e:  # IfcOpenShell's parse errors have no common base class
        print(f"{src}: IfcOpenShell cannot read it: {e}", file=sys.stderr)
        return 1
    settings = ifcopenshell.geom.settings()
    settings.set("use-world-coords", True)
    threads = max(1, multiprocessing.cpu_count())
    iterator = ifcopenshell.geom.iterator(
        settings, model, threads, exclude=("IfcSpace", "IfcOpeningElement")
    )
    mtl_path = dst[: -len(".obj")] + ".mtl" if dst.endswith(".obj") else dst + ".mtl"
    materials = {}
    products = triangles = 0
    with open(dst, "w", encoding="utf-8", newline="\n") as obj:
        obj.write(f"# {src} converted by IfcOpenShell {ifcopenshell.version}\n")
        obj.write(f"mtllib {mtl_path.rsplit('/', 1)[-1]}\n")
        if iterator.initialize():
            first_vertex = 1
            while True:
                shape = iterator.get()
                written = write_product(obj, shape, first_vertex, materials)
                first_vertex += written[0]
                triangles += written[1]
                products += 1
                if products % 1000 == 0:
                    print(f"{products} products", file=sys.stderr, flush=True)
                if not iterator.next():
                    break
    with open(mtl_path, "w", encoding="utf-8", newline="\n") as mtl:
        for name, (r, g, b, alpha) in materials.items():
            mtl.write(f"newmtl {name}\nKd {r:.4f} {g:.4f} {b:.4f}\nd {alpha:.4f}\n")
    print(f"{products} products, {triangles} triangles")
    return 0


def object_name(shape):
    """'Name [GlobalId]', the IFC class when the product has no name; one line."""
    name = (shape.name or "").strip() or shape.type
    return " ".join(f"{name} [{shape.guid}]".split())


def dominant_material(geometry, materials):
    """The OBJ material of the style most faces use, added to `materials`; None if unstyled."""
    styles = list(geometry.materials)
    ids = [i for i in geometry.material_ids if 0 <= i < len(styles)]
    if not ids:
        return None
    style = styles[max(set(ids), key=ids.count)]
    d = style.diffuse
    rgb = tuple(min(1.0, max(0.0, c)) for c in (d.r(), d.g(), d.b()))
    t = style.transparency
    alpha = 1.0 if t is None or math.isnan(t) else min(1.0, max(0.0, 1.0 - t))
    key = "c%02x%02x%02x%02x" % tuple(round(c * 255) for c in (*rgb, alpha))
    materials[key] = (*rgb, alpha)
    return key


def write_product(obj, shape, first_vertex, materials):
    """Writes one product; returns (vertices, triangles) written."""
    geometry = shape.geometry
    verts = geometry.verts
    faces = geometry.faces
    if not faces:
        return (0, 0)
    obj.write(f"o {object_name(shape)}\n")
    material = dominant_material(geometry, materials)
    if material:
        obj.write(f"usemtl {material}\n")
    for i in range(0, len(verts) - 2, 3):
        obj.write(f"v {verts[i]!r} {verts[i + 1]!r} {verts[i + 2]!r}\n")
    for i in range(0, len(faces) - 2, 3):
        a, b, c = (first_vertex + faces[i + k] for k in range(3))
        obj.write(f"f {a} {b} {c}\n")
    return (len(verts) // 3, len(faces) // 3)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
