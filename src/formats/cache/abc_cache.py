"""Alembic point caches for blendsim, through the Alembic C++ library's Python bindings (PyPI
alembic3d), run by src/formats/cache/abc.rs.

read FILE OBJECT START END OUT_DIR
    One PolyMesh's (or SubD's cage) positions, with the transforms of its Xform ancestors
    applied, at its samples START..END (indices, END inclusive, negative from the end; OBJECT "-"
    picks the only mesh, or the only animated one). A mesh whose points are constant but whose
    transforms move is sampled at its most sampled moving ancestor's times. Writes
    OUT_DIR/frames.pc2 (one sample at a time: memory is one frame) and OUT_DIR/info.json.

Errors: one line `blendsim-abc: PROBLEM | FIX` on stderr and exit code 4; exit code 3 when the
bindings cannot be imported.
"""

import ctypes
import json
import struct
import sys

try:
    import imath
    from alembic3d import Abc, AbcGeom
except ImportError as e:
    print(e, file=sys.stderr)
    sys.exit(3)

KEEP = Abc.WrapExistingFlag.kWrapExisting


def fail(problem, fix):
    print(f"blendsim-abc: {problem} | {fix}", file=sys.stderr)
    sys.exit(4)


def meshes(obj, out):
    for child in obj.children:
        meta = child.getMetaData()
        if AbcGeom.IPolyMesh.matches(meta):
            out.append((child, AbcGeom.IPolyMesh(child, KEEP).getSchema(), "PolyMesh"))
        elif AbcGeom.ISubD.matches(meta):
            out.append((child, AbcGeom.ISubD(child, KEEP).getSchema(), "SubD"))
        meshes(child, out)
    return out


def xforms(obj):
    """The Xform schemas whose transforms apply to `obj`, nearest first."""
    out = []
    parent = obj.getParent()
    while parent.valid() and parent.getParent().valid():
        if AbcGeom.IXform.matches(parent.getMetaData()):
            schema = AbcGeom.IXform(parent, KEEP).getSchema()
            out.append(schema)
            if not schema.getInheritsXforms():
                break
        parent = parent.getParent()
    return out


def moves(schema):
    return schema.getNumSamples() > 1 and not schema.isConstant()


def describe(found):
    names = [f"{o.getFullName()}" for o, _, _ in found[:8]]
    return ", ".join(names) + (", ..." if len(found) > 8 else "")


def choose(found, wanted):
    if wanted != "-":
        # The object's full name or name, or its Xform's (a DCC's object above its shape).
        match = [f for f in found if wanted in (f[0].getFullName(), f[0].getName(), f[0].getParent().getFullName(), f[0].getParent().getName())]
        if not match:
            fail(f"has no mesh object {wanted} (its meshes: {describe(found) or 'none'})", "set object to one of the names listed")
        return match[0]
    if len(found) == 1:
        return found[0]
    if not found:
        fail("has no PolyMesh or SubD object", "export the animated mesh as a PolyMesh")
    animated = [f for f in found if moves(f[1]) or any(moves(x) for x in xforms(f[0]))]
    if len(animated) == 1:
        return animated[0]
    fail(f"has several meshes ({describe(found)}), {len(animated)} of them animated", "set object = \"NAME\" in [cache] to the mesh to read")


def world(parents, time):
    m = imath.M44d()
    for schema in parents:
        m = m * schema.getValue(Abc.ISampleSelector(time)).getMatrix()
    return m


def float_bytes(points, count):
    """The float32 bytes of a V3fArray: its buffer (the bindings export its address with a short
    length, so the bytes are copied from the address), checked against its first and last
    points; element by element when the buffer looks otherwise."""
    view = memoryview(points)
    data = None
    if view.format == "f" and view.itemsize == 4 and view.c_contiguous and not view.readonly and count > 0:
        address = ctypes.addressof(ctypes.c_char.from_buffer(view))
        data = ctypes.string_at(address, 12 * count)
        for i in (0, count - 1):
            p = points[i]
            if struct.unpack_from("<3f", data, 12 * i) != struct.unpack("<3f", struct.pack("<3f", p.x, p.y, p.z)):
                data = None
                break
    view.release()
    if data is None:
        data = b"".join(struct.pack("<3f", p.x, p.y, p.z) for p in points)
    return data


def mapped(path):
    """The address ranges where the library mapped `path` (Ogawa archives are read through
    memory maps), to release the pages of each frame once it is copied."""
    import os
    real = os.path.realpath(path)
    ranges = []
    try:
        with open("/proc/self/maps") as maps:
            for line in maps:
                fields = line.split(maxsplit=5)
                if len(fields) == 6 and fields[5].strip() == real and fields[1].startswith("r"):
                    lo, hi = (int(x, 16) for x in fields[0].split("-"))
                    ranges.append((lo, hi - lo))
    except OSError:
        pass
    return ranges


def release(ranges):
    """Drop the resident pages of the read-only file maps (MADV_DONTNEED): they are clean
    pages of the file, read again from it if needed, so the reader's memory stays at one frame
    instead of growing with every frame read (measured on a 100k-vertex, 240-frame cache: peak
    resident 386 MB without, about 100 MB with)."""
    libc = release.libc
    for lo, size in ranges:
        libc.madvise(ctypes.c_void_p(lo), ctypes.c_size_t(size), 4)


release.libc = ctypes.CDLL(None, use_errno=True)


def read(path, wanted, start, end, out_dir):
    try:
        archive = Abc.IArchive(path)
    except Exception as e:  # the library raises on files it cannot read
        fail(f"the Alembic library cannot open the file ({str(e).splitlines()[0] if str(e) else type(e).__name__})",
             "check that the file is a complete Ogawa Alembic archive")
    maps = mapped(path)
    obj, schema, kind = choose(meshes(archive.getTop(), []), wanted)
    where = obj.getFullName()
    parents = xforms(obj)
    if moves(schema):
        sampling, samples = schema.getTimeSampling(), schema.getNumSamples()
    else:
        moving = [x for x in parents if moves(x)]
        if not moving:
            fail(f"{kind} {where} does not move (constant points and transforms): a static mesh, not a point cache",
                 "export the animation (Blender: the frame range of the animation), or set object to the animated mesh")
        best = max(moving, key=lambda x: x.getNumSamples())
        sampling, samples = best.getTimeSampling(), best.getNumSamples()
    first = start if start >= 0 else samples + start
    last = end if end >= 0 else samples + end
    if not 0 <= first <= last < samples:
        fail(f"frame range start = {start}, end = {end} selects no frames of the {samples} the cache holds (indices 0 to {samples - 1})",
             f"choose 0 <= start <= end < {samples}; negative values count from the end (-1 is the last frame)")
    times = [sampling.getSampleTime(i) for i in range(first, last + 1)]
    sample0 = schema.getValue(Abc.ISampleSelector(times[0]))
    counts, indices = list(sample0.getFaceCounts()), list(sample0.getFaceIndices())
    count = len(sample0.getPositions())
    varying = str(schema.getTopologyVariance()).endswith("kHeterogeneousTopology")
    with open(f"{out_dir}/frames.pc2", "wb") as f:
        f.write(b"POINTCACHE2\0" + struct.pack("<iiffi", 1, count, float(times[0]), 1.0, len(times)))
        for frame, t in enumerate(times):
            sample = schema.getValue(Abc.ISampleSelector(t))
            points = sample.getPositions()
            if len(points) != count or (varying and (list(sample.getFaceCounts()) != counts or list(sample.getFaceIndices()) != indices)):
                fail(f"the topology of {where} changes at frame {frame} (time {t:g} s: {len(points)} points, {count} at the first frame)",
                     "bake the cache from a mesh whose faces and vertex count do not change")
            f.write(float_bytes(points * world(parents, t), count))
            del sample, points
            release(maps)
    info = {
        "object": where,
        "kind": kind,
        "times": times,
        "points": count,
        "face_vertex_counts": counts,
        "face_vertex_indices": indices,
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
