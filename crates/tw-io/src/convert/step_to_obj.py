"""STEP/IGES -> Wavefront OBJ for terawalk (run by tw-io's `convert` module, not by hand).

Usage: python3 step_to_obj.py INPUT.step|INPUT.iges OUTPUT.obj

Reads the file into an Open CASCADE XDE document (names, colours and the assembly structure
kept), walks the assembly from its free shapes down, placing each part by the product of the
component locations above it, tessellates every solid (BRepMesh, linear deflection a
thousandth of the model's bounding-box diagonal, angular 0.5 rad) and writes one OBJ object
per solid, named by its path of component names ("board/R1/body"; a part with several solids
numbers them "#2", "#3", ...). Colour: the solid's own, else its part's, else the nearest
component's above it. Coordinates are in millimetres: Open CASCADE converts STEP/IGES
lengths to mm when it reads them.

Exit status 3 means Open CASCADE's Python binding (OCP, PyPI `cadquery-ocp`) is missing;
terawalk then prints how to install it.
"""

import sys

MISSING_MODULE = 3


def main(argv):
    if len(argv) != 3:
        print("usage: step_to_obj.py INPUT.step OUTPUT.obj", file=sys.stderr)
        return 2
    try:
        import OCP  # noqa: F401
    except ImportError as e:
        print(f"terawalk: the Python module OCP (cadquery-ocp) is missing ({e})", file=sys.stderr)
        return MISSING_MODULE
    src, dst = argv[1], argv[2]
    doc = read_document(src)
    writer = ObjWriter(dst, src)
    walker = Walker(doc, writer)
    walker.run()
    writer.close()
    print(f"{writer.objects} solids, {writer.triangles} triangles")
    return 0


def read_document(path):
    from OCP.IFSelect import IFSelect_RetDone
    from OCP.TCollection import TCollection_ExtendedString
    from OCP.TDocStd import TDocStd_Document

    doc = TDocStd_Document(TCollection_ExtendedString("XmlOcaf"))
    lower = path.lower()
    if lower.endswith((".igs", ".iges")):
        from OCP.IGESCAFControl import IGESCAFControl_Reader as Reader
    else:
        from OCP.STEPCAFControl import STEPCAFControl_Reader as Reader
    reader = Reader()
    reader.SetNameMode(True)
    reader.SetColorMode(True)
    if reader.ReadFile(path) != IFSelect_RetDone:
        raise SystemExit(f"{path}: Open CASCADE cannot read this file")
    if not reader.Transfer(doc):
        raise SystemExit(f"{path}: Open CASCADE read the file but could not transfer its shapes")
    return doc


def label_sequence():
    """An empty sequence of labels (its class moved between OCP releases)."""
    try:
        from OCP.TDF import TDF_LabelSequence
    except ImportError:
        from OCP.collections import Sequence_TDF_Label as TDF_LabelSequence
    return TDF_LabelSequence()


def label_name(label):
    from OCP.TDataStd import TDataStd_Name

    attr = TDataStd_Name()
    if not label.FindAttribute(TDataStd_Name.GetID_s(), attr):
        return ""
    name = " ".join(attr.Get().ToExtString().split())
    # "=>[0:1:1:2]" is the name Open CASCADE makes up for an unnamed reference.
    return "" if name.startswith("=>[") else name


class Walker:
    """Depth-first over the XDE assembly tree."""

    def __init__(self, doc, writer):
        from OCP.XCAFDoc import XCAFDoc_DocumentTool

        self.shapes = XCAFDoc_DocumentTool.ShapeTool_s(doc.Main())
        self.colors = XCAFDoc_DocumentTool.ColorTool_s(doc.Main())
        self.writer = writer
        self.deflection = None

    def run(self):
        from OCP.TopLoc import TopLoc_Location

        roots = label_sequence()
        self.shapes.GetFreeShapes(roots)
        self.deflection = self.model_deflection(roots)
        for i in range(1, roots.Length() + 1):
            label = roots.Value(i)
            self.visit(label, TopLoc_Location(), [], None)

    def model_deflection(self, roots):
        from OCP.Bnd import Bnd_Box
        from OCP.BRepBndLib import BRepBndLib

        box = Bnd_Box()
        for i in range(1, roots.Length() + 1):
            BRepBndLib.Add_s(self.shapes.GetShape_s(roots.Value(i)), box)
        if box.IsVoid():
            return 0.1
        lo, hi = box.CornerMin(), box.CornerMax()
        diagonal = lo.Distance(hi)
        return max(diagonal * 1e-3, 1e-6)

    def color(self, label, inherited):
        from OCP.Quantity import Quantity_ColorRGBA
        from OCP.XCAFDoc import XCAFDoc_ColorGen, XCAFDoc_ColorSurf

        from OCP.XCAFDoc import XCAFDoc_ColorTool

        c = Quantity_ColorRGBA()
        for kind in (XCAFDoc_ColorSurf, XCAFDoc_ColorGen):
            if XCAFDoc_ColorTool.GetColor_s(label, kind, c):
                rgb = c.GetRGB()
                return (rgb.Red(), rgb.Green(), rgb.Blue(), c.Alpha())
        return inherited

    def visit(self, label, location, path, color):
        from OCP.TDF import TDF_Label

        name = label_name(label)
        color = self.color(label, color)
        if self.shapes.IsReference_s(label):
            referred = TDF_Label()
            self.shapes.GetReferredShape_s(label, referred)
            location = location.Multiplied(self.shapes.GetLocation_s(label))
            self.visit_part(referred, location, path + [name] if name else path, color)
            return
        self.visit_part(label, location, path + [name] if name else path, color)

    def visit_part(self, label, location, path, color):
        color = self.color(label, color)
        own = label_name(label)
        if self.shapes.IsAssembly_s(label):
            components = label_sequence()
            self.shapes.GetComponents_s(label, components, False)
            for i in range(1, components.Length() + 1):
                self.visit(components.Value(i), location, path, color)
            return
        if own and (not path or path[-1] != own):
            path = path + [own]
        self.write_solids(label, location, "/".join(path) or "solid", color)

    def write_solids(self, label, location, name, color):
        from OCP.BRepMesh import BRepMesh_IncrementalMesh
        from OCP.TopAbs import TopAbs_SHELL, TopAbs_SOLID
        from OCP.TopExp import TopExp_Explorer

        # Pieces are found and coloured in the part's own frame (the colour tool knows the
        # shapes as stored), then moved into place.
        shape = self.shapes.GetShape_s(label)
        BRepMesh_IncrementalMesh(shape, self.deflection, False, 0.5, True)
        pieces = []
        explorer = TopExp_Explorer(shape, TopAbs_SOLID)
        while explorer.More():
            pieces.append(explorer.Current())
            explorer.Next()
        if not pieces:
            # Surface models: shells (or the bare faces) stand in for solids.
            explorer = TopExp_Explorer(shape, TopAbs_SHELL)
            while explorer.More():
                pieces.append(explorer.Current())
                explorer.Next()
        if not pieces:
            pieces = [shape]
        for n, piece in enumerate(pieces):
            piece_color = self.color_of_shape(piece, color)
            placed = piece.Moved(location)
            self.writer.solid(name if n == 0 else f"{name} #{n + 1}", placed, piece_color)

    def color_of_shape(self, shape, inherited):
        from OCP.Quantity import Quantity_ColorRGBA
        from OCP.XCAFDoc import XCAFDoc_ColorGen, XCAFDoc_ColorSurf

        from OCP.TopAbs import TopAbs_FACE
        from OCP.TopExp import TopExp_Explorer

        c = Quantity_ColorRGBA()
        # The solid's own colour, else its first coloured face's (CAD exports often colour
        # faces only), else the inherited one.
        candidates = [shape]
        explorer = TopExp_Explorer(shape, TopAbs_FACE)
        while explorer.More():
            candidates.append(explorer.Current())
            explorer.Next()
        for candidate in candidates:
            for kind in (XCAFDoc_ColorSurf, XCAFDoc_ColorGen):
                if self.colors.GetColor(candidate, kind, c):
                    rgb = c.GetRGB()
                    return (rgb.Red(), rgb.Green(), rgb.Blue(), c.Alpha())
        return inherited


def to_face(shape):
    """TopoDS::Face (a static method OCP releases spell with and without `_s`)."""
    from OCP.TopoDS import TopoDS

    cast = getattr(TopoDS, "Face_s", None) or TopoDS.Face
    return cast(shape)


class ObjWriter:
    """Streams objects into an OBJ file and collects their colours for its MTL file."""

    def __init__(self, path, source):
        self.mtl_path = (path[: -len(".obj")] if path.endswith(".obj") else path) + ".mtl"
        self.obj = open(path, "w", encoding="utf-8", newline="\n")
        self.obj.write(f"# {source} converted by Open CASCADE (OCP)\n")
        self.obj.write(f"mtllib {self.mtl_path.rsplit('/', 1)[-1]}\n")
        self.materials = {}
        self.next_vertex = 1
        self.objects = 0
        self.triangles = 0

    def solid(self, name, shape, color):
        from OCP.BRep import BRep_Tool
        from OCP.TopAbs import TopAbs_FACE, TopAbs_REVERSED
        from OCP.TopExp import TopExp_Explorer
        from OCP.TopLoc import TopLoc_Location
        lines = [f"o {name}\n"]
        if color is not None:
            key = "c%02x%02x%02x%02x" % tuple(round(min(1.0, max(0.0, c)) * 255) for c in color)
            self.materials[key] = color
            lines.append(f"usemtl {key}\n")
        triangles = 0
        explorer = TopExp_Explorer(shape, TopAbs_FACE)
        while explorer.More():
            face = to_face(explorer.Current())
            explorer.Next()
            loc = TopLoc_Location()
            mesh = BRep_Tool.Triangulation_s(face, loc)
            if mesh is None:
                continue
            transform = loc.Transformation()
            first = self.next_vertex
            for i in range(1, mesh.NbNodes() + 1):
                p = mesh.Node(i).Transformed(transform)
                lines.append(f"v {p.X()!r} {p.Y()!r} {p.Z()!r}\n")
            self.next_vertex += mesh.NbNodes()
            reversed_face = face.Orientation() == TopAbs_REVERSED
            for i in range(1, mesh.NbTriangles() + 1):
                a, b, c = mesh.Triangle(i).Get()
                if reversed_face:
                    b, c = c, b
                lines.append(f"f {first + a - 1} {first + b - 1} {first + c - 1}\n")
            triangles += mesh.NbTriangles()
        if triangles:
            self.obj.writelines(lines)
            self.objects += 1
            self.triangles += triangles

    def close(self):
        self.obj.close()
        with open(self.mtl_path, "w", encoding="utf-8", newline="\n") as mtl:
            for key, (r, g, b, a) in self.materials.items():
                mtl.write(f"newmtl {key}\nKd {r:.4f} {g:.4f} {b:.4f}\nd {a:.4f}\n")


if __name__ == "__main__":
    sys.exit(main(sys.argv))
