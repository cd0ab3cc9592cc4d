"""USD point caches for blendsim, through usd-core's pxr (run by src/formats/cache/usd.rs).

read FILE PRIM START END OUT_DIR
    One Mesh prim's topology and its `points` time samples START..END (indices, END
    inclusive, negative from the end; PRIM "-" picks the only Mesh, or the only animated one).
    Writes OUT_DIR/frames.pc2 (one sample at a time: memory is one frame) and
    OUT_DIR/info.json (prim, timeCodesPerSecond, time codes, topology).

Errors: one line `blendsim-usd: PROBLEM | FIX` on stderr and exit code 4; exit code 3 when
pxr cannot be imported.
"""

import array
import json
import struct
import sys

try:
    from pxr import Gf, Usd, UsdGeom, Vt
except ImportError as e:
    print(e, file=sys.stderr)
    sys.exit(3)


def fail(problem, fix):
    print(f"blendsim-usd: {problem} | {fix}", file=sys.stderr)
    sys.exit(4)


def little_endian(data):
    """The bytes of a float buffer in little-endian order (PC2's)."""
    if sys.byteorder == "little":
        return data
    values = array.array("f")
    values.frombytes(bytes(data))
    values.byteswap()
    return values.tobytes()


def choose_mesh(stage, prim_path):
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    names = ", ".join(str(p.GetPath()) for p in meshes[:8]) + (", ..." if len(meshes) > 8 else "")
    if prim_path != "-":
        prim = stage.GetPrimAtPath(prim_path)
        if not prim.IsValid():
            fail(f"has no prim {prim_path} (its meshes: {names or 'none'})", "set prim to the path of the animated Mesh")
        if not prim.IsA(UsdGeom.Mesh):
            fail(f"prim {prim_path} is a {prim.GetTypeName() or 'typeless prim'}, not a Mesh", "set prim to the path of the animated Mesh")
        return prim
    animated = [p for p in meshes if UsdGeom.Mesh(p).GetPointsAttr().GetNumTimeSamples() > 0]
    if len(meshes) == 1:
        return meshes[0]
    if len(animated) == 1:
        return animated[0]
    if not meshes:
        fail("has no Mesh prim", "export the animated mesh as a UsdGeom Mesh")
    fail(f"has several meshes ({names})", "set prim to the path of the animated Mesh")


def read(path, prim_path, start, end, out_dir):
    stage = Usd.Stage.Open(path)
    if stage is None:
        fail("usd-core cannot open the stage", "check that the file opens in usd-core (python3 -c \"from pxr import Usd; Usd.Stage.Open('FILE')\")")
    prim = choose_mesh(stage, prim_path)
    where = str(prim.GetPath())
    mesh = UsdGeom.Mesh(prim)
    points = mesh.GetPointsAttr()
    samples = points.GetTimeSamples()
    if not samples:
        fail(f"the points of {where} have no time samples (a static mesh, not a point cache)",
             "export the animation as points time samples (a point cache), or set prim to the animated Mesh")
    first = start if start >= 0 else len(samples) + start
    last = end if end >= 0 else len(samples) + end
    if not 0 <= first <= last < len(samples):
        fail(f"frame range start = {start}, end = {end} selects no frames of the {len(samples)} the cache holds (indices 0 to {len(samples) - 1})",
             f"choose 0 <= start <= end < {len(samples)}; negative values count from the end (-1 is the last frame)")
    times = samples[first:last + 1]
    counts_attr, indices_attr = mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr()
    counts, indices = counts_attr.Get(times[0]), indices_attr.Get(times[0])
    if counts is None or indices is None:
        fail(f"the Mesh {where} has no faceVertexCounts or faceVertexIndices", "export the mesh with its faces")
    for attr, value in ((counts_attr, counts), (indices_attr, indices)):
        for t in attr.GetTimeSamplesInInterval(Gf.Interval(times[0], times[-1])):
            if attr.Get(t) != value:
                fail(f"the {attr.GetName()} of {where} change at time code {t}: the topology is not constant",
                     "bake the cache from a mesh whose faces do not change")
    count = len(points.Get(times[0]))
    with open(f"{out_dir}/frames.pc2", "wb") as f:
        f.write(b"POINTCACHE2\0" + struct.pack("<iiffi", 1, count, float(times[0]), 1.0, len(times)))
        for t in times:
            value = points.Get(t)
            if len(value) != count:
                fail(f"the points of {where} at time code {t} are {len(value)}, but {count} at time code {times[0]}",
                     "bake the cache from a mesh whose vertex count does not change")
            f.write(little_endian(memoryview(Vt.Vec3fArray(value))))
    info = {
        "prim": where,
        "time_codes_per_second": stage.GetTimeCodesPerSecond(),
        "time_codes": list(times),
        "samples": len(samples),
        "points": count,
        "face_vertex_counts": list(counts),
        "face_vertex_indices": list(indices),
        "left_handed": mesh.GetOrientationAttr().Get() == UsdGeom.Tokens.leftHanded,
        # Only when authored: USD's fallback (0.01) would turn every unitless stage into cm.
        "meters_per_unit": UsdGeom.GetStageMetersPerUnit(stage) if UsdGeom.StageHasAuthoredMetersPerUnit(stage) else None,
    }
    with open(f"{out_dir}/info.json", "w") as f:
        json.dump(info, f)


def main(argv):
    if len(argv) == 6 and argv[0] == "read":
        read(argv[1], argv[2], int(argv[3]), int(argv[4]), argv[5])
    else:
        print(__doc__, file=sys.stderr)
        sys.exit(2)


main(sys.argv[1:])
