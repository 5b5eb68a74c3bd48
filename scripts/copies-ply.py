#!/usr/bin/env python3
"""Writes a binary PLY of N copies of one triangle (each copy with its own three vertices), as
CAD exports with duplicated parts carry them. Used to time `terawalk preview` and the build on
coincident geometry.

    scripts/copies-ply.py OUT.ply [N=100000] [SIZE=100.0]
"""
import struct
import sys


def main():
    out = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 100_000
    size = float(sys.argv[3]) if len(sys.argv) > 3 else 100.0
    tri = [(0.0, 0.0, 0.0), (size, 0.0, 0.0), (0.0, size, 0.3 * size)]
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {3 * n}\nproperty float x\nproperty float y\nproperty float z\n"
        f"element face {n}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    vertex = b"".join(struct.pack("<3f", *v) for v in tri)
    with open(out, "wb") as f:
        f.write(header.encode())
        f.write(vertex * n)
        f.writelines(struct.pack("<B3i", 3, 3 * i, 3 * i + 1, 3 * i + 2) for i in range(n))


if __name__ == "__main__":
    main()
