#!/usr/bin/env python3
"""Check files written by blendsim by importing them into Blender, independently of blendsim.

usage: blender_check.py FILE EXPECTED.json [FILE EXPECTED.json ...]

Runs with a Python that has Blender's `bpy` module (pip bpy==4.2.0 on Python 3.11; `make
deps-blender` puts one in build/blender-venv). For each FILE (.usda, .usdc or .glb), in one
Blender session:

1. Starts from factory settings with an empty scene (bpy.ops.wm.read_factory_settings(
   use_empty=True)): every importer option at its default, as a new user has them.
2. glTF only: sets the scene frame rate to EXPECTED's fps first (Blender's glTF importer
   converts seconds to frames with the rate it finds; it does not set it).
3. Imports with Blender's own importer at its defaults: bpy.ops.wm.usd_import or
   bpy.ops.import_scene.gltf. Exactly one mesh object must arrive.
4. For each EXPECTED time, goes to frame `timecode` (USD) or `time * fps` (glTF; fractional
   frames as subframes), evaluates the mesh through the depsgraph (shape keys, F-curves,
   modifiers, as Blender plays it), and maps it to world space with the object's matrix_world.
5. Compares with EXPECTED's points placed as a user expects them in Blender (z up, meters):
   scaled by meters_per_unit, and for a y-up scene rotated +90 degrees about X (a y-up point
   (x, y, z) is Blender's (x, -z, y)). The largest distance divided by the bounding-box
   diagonal of the placed expected points must be <= tolerance. Also reports the error in
   the mesh's local frame after undoing the placement (`local_error`): whether the animation
   is right even when the placement is not; `scale`, the size of the imported object
   relative to the expected one, and `unscaled_error`, the error once that size is undone
   (right up to its units).

6. With EXPECTED `corners` (per triangle, three [point, u, v], v up as in OBJ) and
   `triangle_materials` (per triangle, its material name): Blender's active UV layer must give
   every face corner the expected UV (within 1e-5; faces matched by their points' set), its
   material slots must be the expected names, and each face's material (slot of its
   material_index) its triangle's. With `map_vertices`, Blender's vertices may be more than the
   points (an importer that keeps glTF seam copies): each is matched to the nearest expected
   point at the first time, and must follow it at every time.

EXPECTED.json is the format of README.md (times, timecodes, points, tolerance, fps, up_axis,
meters_per_unit), plus the optional corners, triangle_materials and map_vertices above.

Prints issues to stderr, one JSON line per file, and a last one-line JSON summary to stdout
({"ok": ..., "files": [...]}); exit code 0 when everything passes, 1 otherwise. Blender 4.2.0
may crash while the interpreter shuts down after a glTF import, so the script leaves with
os._exit once the summary is flushed.
"""

import json
import math
import os
import sys

import bpy
import numpy as np


def placement(expected):
    """The linear map a user expects: scene units -> meters, scene up axis -> Blender's Z."""
    m = np.eye(3) * expected.get("meters_per_unit", 1.0)
    if expected.get("up_axis", "y") == "y":
        # +90 degrees about X: (x, y, z) -> (x, -z, y).
        m = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]]) @ m
    return m


def diagonal(points):
    """Bounding-box diagonal of an array of points (any leading shape)."""
    flat = points.reshape(-1, 3)
    return float(np.linalg.norm(flat.max(axis=0) - flat.min(axis=0)))


def max_distance(a, b):
    """The largest point distance (NaN when any point is NaN)."""
    return float(np.linalg.norm(a - b, axis=1).max())


def import_file(path, expected):
    """Import into a fresh empty scene; returns the new mesh objects."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    ext = os.path.splitext(path)[1].lower()
    if ext == ".glb":
        fps = expected.get("fps", 24.0)
        scene.render.fps = max(1, round(fps))
        scene.render.fps_base = scene.render.fps / fps
        result = bpy.ops.import_scene.gltf(filepath=path)
    elif ext in (".usda", ".usdc", ".usd"):
        result = bpy.ops.wm.usd_import(filepath=path)
    else:
        raise ValueError(f"not a USD or glTF file: {path}")
    if "FINISHED" not in result:
        raise ValueError(f"the importer returned {result}")
    return [o for o in scene.objects if o.type == "MESH"]


def frame_of(path, expected, i):
    if path.lower().endswith(".glb"):
        return expected["times"][i] * expected.get("fps", 24.0)
    return expected["timecodes"][i]


def evaluate(obj, frame):
    """World-space points of `obj` at `frame` as Blender plays it."""
    scene = bpy.context.scene
    whole = math.floor(frame)
    scene.frame_set(int(whole), subframe=frame - whole)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    world = np.array(evaluated.matrix_world)
    local = np.empty(3 * len(mesh.vertices))
    mesh.vertices.foreach_get("co", local)
    evaluated.to_mesh_clear()
    return local.reshape(-1, 3) @ world[:3, :3].T + world[:3, 3], world


def nearest_points(got, want):
    """For each Blender vertex, the index of the nearest expected point (brute force: test meshes)."""
    d = np.linalg.norm(got[:, None, :] - want[None, :, :], axis=2)
    return d.argmin(axis=1)


def check_corners(obj, expected, mapping, summary):
    """UVs per face corner, material slots and per-face materials against the expected ones."""
    mesh = obj.data
    slots = [s.material.name if s.material else None for s in obj.material_slots]
    summary["uv_layers"] = [l.name for l in mesh.uv_layers]
    summary["material_slots"] = slots
    want = {}
    for corners, material in zip(expected["corners"], expected["triangle_materials"]):
        want[tuple(sorted(int(c[0]) for c in corners))] = (sorted((int(c[0]), c[1], c[2]) for c in corners), material)
    if sorted(set(slots)) != sorted(set(expected["triangle_materials"])):
        summary["issues"].append(f"material slots {slots}, expected {sorted(set(expected['triangle_materials']))}")
    layer = mesh.uv_layers.active
    if layer is None:
        summary["issues"].append("no UV layer")
        return
    worst_uv, wrong_material, unmatched = 0.0, 0, 0
    for poly in mesh.polygons:
        corners = []
        for loop in poly.loop_indices:
            v = mesh.loops[loop].vertex_index
            point = int(mapping[v]) if mapping is not None else v
            u, w = layer.data[loop].uv
            corners.append((point, float(u), float(w)))
        key = tuple(sorted(c[0] for c in corners))
        if key not in want:
            unmatched += 1
            continue
        expected_corners, material = want[key]
        for (_, u, w), (_, eu, ew) in zip(sorted(corners), expected_corners):
            worst_uv = max(worst_uv, abs(u - eu), abs(w - ew))
        got_material = slots[poly.material_index] if poly.material_index < len(slots) else None
        wrong_material += got_material != material
    summary.update(uv_error=worst_uv, faces=len(mesh.polygons), faces_unmatched=unmatched, faces_wrong_material=wrong_material)
    if len(mesh.polygons) != len(want) or unmatched:
        summary["issues"].append(f"{len(mesh.polygons)} faces ({unmatched} not among the expected triangles), expected {len(want)}")
    if worst_uv > 1e-5:
        summary["issues"].append(f"a face corner's UV is {worst_uv:.3g} from the expected one")
    if wrong_material:
        summary["issues"].append(f"{wrong_material} faces have another material than expected")


def check(path, expected):
    summary = {"file": path, "issues": []}
    objects = import_file(path, expected)
    if len(objects) != 1:
        summary["issues"].append(f"expected one mesh object, Blender imported {len(objects)}")
        return summary
    obj = objects[0]
    scene = bpy.context.scene
    keys = obj.data.shape_keys
    blocks = list(keys.key_blocks)[1:] if keys else []
    summary.update(
        object=obj.name,
        vertices=len(obj.data.vertices),
        shape_keys=len(blocks),
        shape_key_names=[b.name for b in blocks[:6]] + (["..."] if len(blocks) > 6 else []),
        slider_range=[min((b.slider_min for b in blocks), default=0.0), max((b.slider_max for b in blocks), default=0.0)],
        scene_fps=scene.render.fps / scene.render.fps_base,
        frame_range=[scene.frame_start, scene.frame_end],
    )
    place = placement(expected)
    unplace = np.linalg.inv(place)
    want_local = np.array(expected["points"], dtype=float)
    want_world = want_local @ place.T
    scale = max(diagonal(want_world), 1e-30)
    worst, worst_local, worst_unscaled, worst_frame, world, size = 0.0, 0.0, 0.0, None, None, None
    mapping = None
    for i, want in enumerate(want_world):
        frame = frame_of(path, expected, i)
        got, world = evaluate(obj, frame)
        if i == 0 and expected.get("map_vertices"):
            mapping = nearest_points(got, want)
        if mapping is not None:
            want = want[mapping]
            want_local_i = want_local[i][mapping]
        else:
            want_local_i = want_local[i]
        if len(got) != len(want):
            summary["issues"].append(f"frame {frame}: {len(got)} points, expected {len(want)}")
            return summary
        error = max_distance(got, want) / scale
        if math.isnan(error):
            summary["issues"].append(f"frame {frame}: a point is NaN")
        # The size Blender gave the object relative to the expected one (from the first frame),
        # and the error once that size is undone: right up to its units, or not at all.
        if size is None:
            size = diagonal(got) / max(diagonal(want), 1e-30)
        worst_unscaled = max(worst_unscaled, max_distance(got / size, want) / scale)
        local = max_distance(got @ unplace.T, want_local_i) / scale * expected.get("meters_per_unit", 1.0)
        worst_local = max(worst_local, local)
        if error >= worst:
            worst, worst_frame = error, frame
    summary.update(
        frames=len(want_world),
        max_error=worst,
        worst_frame=worst_frame,
        local_error=worst_local,
        scale=size,
        unscaled_error=worst_unscaled,
        matrix_world=[[round(float(x), 6) for x in row] for row in world],
    )
    if "corners" in expected:
        check_corners(obj, expected, mapping, summary)
    tolerance = expected.get("tolerance", 1e-5)
    if worst > tolerance:
        summary["issues"].append(
            f"max error {worst:.3g} (relative to the bbox diagonal) at frame {worst_frame} exceeds {tolerance}"
            f" (in the mesh's own frame: {worst_local:.3g})"
        )
    return summary


def main(argv):
    args = argv[1:]
    if not args or len(args) % 2:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    files = []
    for path, expected_path in zip(args[::2], args[1::2]):
        with open(expected_path) as f:
            expected = json.load(f)
        try:
            summary = check(path, expected)
        except Exception as e:  # an importer failure is a finding about the file, not a crash
            summary = {"file": path, "issues": [f"{type(e).__name__}: {e}"]}
        summary["ok"] = not summary["issues"]
        for issue in summary["issues"]:
            print(f"{path}: {issue}", file=sys.stderr)
        print(json.dumps(summary), flush=True)
        files.append(summary)
    ok = all(f["ok"] for f in files)
    print(json.dumps({"ok": ok, "blender": bpy.app.version_string, "files": files}), flush=True)
    return 0 if ok else 1


if __name__ == "__main__":
    code = main(sys.argv)
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)
