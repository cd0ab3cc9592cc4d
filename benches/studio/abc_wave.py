"""A large Alembic point cache for `make bench-studio`, written with the Alembic library's
Python bindings (PyPI alembic3d): an N x N grid (N*N vertices) waving over FRAMES frames at 24
fps, one PolyMesh under one Xform (scaled 2x, so the reader applies it).

    python3 abc_wave.py OUT.abc N FRAMES [nan | grow]

`nan` puts a NaN in the last frame; `grow` adds a point at the last frame (topology change).
"""

import math
import sys

import imath
from alembic3d import Abc, AbcCoreAbstract, AbcGeom


def main(out, n, frames, damage=None):
    archive = Abc.OArchive(out)
    ts = AbcCoreAbstract.TimeSampling(1.0 / 24.0, 0.0)
    index = archive.addTimeSampling(ts)
    xform = AbcGeom.OXform(archive.getTop(), "Sheet")
    xs = xform.getSchema()
    sample = AbcGeom.XformSample()
    sample.setScale(imath.V3d(2.0, 2.0, 2.0))
    xs.set(sample)
    mesh = AbcGeom.OPolyMesh(xform, "SheetShape", index)
    schema = mesh.getSchema()
    counts = imath.IntArray((n - 1) * (n - 1))
    indices = imath.IntArray(4 * (n - 1) * (n - 1))
    k = 0
    for i in range(n - 1):
        for j in range(n - 1):
            counts[i * (n - 1) + j] = 4
            a = i * n + j
            for v in (a, a + n, a + n + 1, a + 1):  # clockwise, as Alembic stores faces
                indices[k] = v
                k += 1
    for f in range(frames):
        t = f / 24.0
        count = n * n + (1 if damage == "grow" and f == frames - 1 else 0)
        points = imath.V3fArray(count)
        for v in range(n * n):
            x, y = (v % n) / n, (v // n) / n
            points[v] = imath.V3f(x, 0.1 * math.sin(6.0 * x - 3.0 * t) * math.cos(4.0 * y + t), y)
        if damage == "nan" and f == frames - 1:
            points[0] = imath.V3f(float("nan"), 0.0, 0.0)
        if count > n * n:
            points[n * n] = imath.V3f(0.0, 0.0, 0.0)
        if f == 0 or damage == "grow":
            schema.set(AbcGeom.OPolyMeshSchemaSample(points, indices, counts))
        else:
            s = AbcGeom.OPolyMeshSchemaSample()
            s.setPositions(points)
            schema.set(s)


main(sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4] if len(sys.argv) > 4 else None)
