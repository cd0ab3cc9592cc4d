#!/usr/bin/env python3
"""Check a USD file written by blendsim with usd-core (the `pxr` module), independently of blendsim.

usage: usd_check.py FILE EXPECTED.json [--usdc]

1. Opens FILE (.usda or .usdc) and runs every registered UsdValidation validator; any
   error or warning fails.
2. Checks stage metadata against EXPECTED when given there (fps, up_axis, meters_per_unit)
   and that the defaultPrim exists.
3. Evaluates the animation at every EXPECTED timecode the way a USD client does:
   blendshapes through UsdSkel (Cache -> ComputeSkelBindings -> SkinningQuery ->
   AnimQuery.ComputeBlendShapeWeights -> BlendShapeMapper.Remap -> BlendShapeQuery
   ComputeSubShapeWeights / ComputeDeformedPoints), full-frame through the mesh's
   `points` attribute. Compares with EXPECTED points: the largest point distance divided by
   the expected points' bounding-box diagonal must be <= tolerance.
4. With --usdc, converts FILE to usdc with Sdf (usda <-> usdc by extension), reopens it and
   repeats 1-3, and requires the same evaluation as the original.

EXPECTED.json: {"times": [s...], "timecodes": [frames...], "points": [[[x,y,z]...] per time],
"tolerance": 1e-5, optional "kind": "blendshape" | "full-frame", "fps", "up_axis": "y" | "z",
"meters_per_unit"}. See README.md.

Prints issues to stderr and a one-line JSON summary to stdout; exit code 0 when everything
passes, 1 otherwise.
"""

import json
import math
import os
import sys
import tempfile

from pxr import Sdf, Usd, UsdGeom, UsdSkel, UsdValidation


def validate(stage):
    """Every registered validator's errors and warnings, as strings."""
    registry = UsdValidation.ValidationRegistry()
    context = UsdValidation.ValidationContext(registry.GetOrLoadAllValidators())
    issues = []
    for error in context.Validate(stage):
        if error.HasNoError() or error.GetType() == UsdValidation.ValidationErrorType.Info:
            continue
        sites = ", ".join(str(s.GetPrim().GetPath()) for s in error.GetSites() if s.GetPrim())
        issues.append(f"{error.GetType()}: {error.GetIdentifier()}: {error.GetMessage()} [{sites}]")
    return issues


def metadata_issues(stage, expected):
    issues = []
    if not stage.GetDefaultPrim():
        issues.append("no defaultPrim")
    if "fps" in expected:
        for name, value in [("timeCodesPerSecond", stage.GetTimeCodesPerSecond()), ("framesPerSecond", stage.GetFramesPerSecond())]:
            if value != expected["fps"]:
                issues.append(f"{name} = {value}, expected {expected['fps']}")
    if "up_axis" in expected and UsdGeom.GetStageUpAxis(stage) != expected["up_axis"].upper():
        issues.append(f"upAxis = {UsdGeom.GetStageUpAxis(stage)}, expected {expected['up_axis'].upper()}")
    if "meters_per_unit" in expected and not math.isclose(UsdGeom.GetStageMetersPerUnit(stage), expected["meters_per_unit"], rel_tol=1e-9):
        issues.append(f"metersPerUnit = {UsdGeom.GetStageMetersPerUnit(stage)}, expected {expected['meters_per_unit']}")
    codes = expected["timecodes"]
    if codes and (stage.GetStartTimeCode() > min(codes) or stage.GetEndTimeCode() < max(codes)):
        issues.append(f"time range [{stage.GetStartTimeCode()}, {stage.GetEndTimeCode()}] does not cover the expected timecodes [{min(codes)}, {max(codes)}]")
    return issues


def evaluate(stage, timecodes):
    """(kind, [points per timecode]) for the stage's single mesh."""
    meshes = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
    if len(meshes) != 1:
        raise ValueError(f"expected one Mesh, found {len(meshes)}")
    mesh = UsdGeom.Mesh(meshes[0])
    roots = [p for p in stage.Traverse() if p.IsA(UsdSkel.Root)]
    if not roots:
        return "full-frame" if mesh.GetPointsAttr().GetNumTimeSamples() > 0 else "static", [
            [tuple(p) for p in mesh.GetPointsAttr().Get(tc)] for tc in timecodes
        ]

    root = UsdSkel.Root(roots[0])
    cache = UsdSkel.Cache()
    cache.Populate(root, Usd.TraverseInstanceProxies())
    bindings = cache.ComputeSkelBindings(root, Usd.TraverseInstanceProxies())
    targets = [(b, s) for b in bindings for s in b.GetSkinningTargets()]
    if len(targets) != 1 or targets[0][1].GetPrim() != mesh.GetPrim():
        raise ValueError(f"expected the mesh to be the one skinning target, found {[str(s.GetPrim().GetPath()) for _, s in targets]}")
    binding, skinning = targets[0]
    if not skinning.HasBlendShapes():
        raise ValueError("the mesh has no blend shapes bound")
    anim = cache.GetSkelQuery(binding.GetSkeleton()).GetAnimQuery()
    if not anim:
        raise ValueError("the skeleton has no animation source")
    shapes = UsdSkel.BlendShapeQuery(UsdSkel.BindingAPI(mesh.GetPrim()))
    point_indices = shapes.ComputeBlendShapePointIndices()
    offsets = shapes.ComputeSubShapePointOffsets()
    mapper = skinning.GetBlendShapeMapper()
    frames = []
    for tc in timecodes:
        weights = mapper.Remap(anim.ComputeBlendShapeWeights(tc))
        sub_weights, shape_indices, sub_indices = shapes.ComputeSubShapeWeights(weights)
        points = mesh.GetPointsAttr().Get(tc)
        if not shapes.ComputeDeformedPoints(sub_weights, shape_indices, sub_indices, point_indices, offsets, points):
            raise ValueError(f"ComputeDeformedPoints failed at timecode {tc} (offsets not matching the points?)")
        frames.append([tuple(p) for p in points])
    return "blendshape", frames


def diagonal(frames):
    lo = [min(p[d] for f in frames for p in f) for d in range(3)]
    hi = [max(p[d] for f in frames for p in f) for d in range(3)]
    return math.dist(lo, hi)


def max_distance(a, b):
    """The largest point distance; NaN when any distance is (max() would skip it)."""
    distances = [math.dist(p, q) for p, q in zip(a, b)]
    return math.nan if any(math.isnan(d) for d in distances) else max(distances)


def check(path, expected):
    """Summary dict for one file; 'issues' lists everything that failed."""
    summary = {"file": path, "issues": []}
    stage = Usd.Stage.Open(path)
    if stage is None:
        summary["issues"].append("usd-core cannot open the file")
        return summary, None
    summary["issues"] += validate(stage)
    summary["issues"] += metadata_issues(stage, expected)
    try:
        kind, frames = evaluate(stage, expected["timecodes"])
    except ValueError as e:
        summary["issues"].append(str(e))
        return summary, None
    summary["kind"] = kind
    if "kind" in expected and kind != expected["kind"] and not (kind == "static" and expected["kind"] == "blendshape"):
        summary["issues"].append(f"animates as {kind}, expected {expected['kind']}")
    scale = max(diagonal(expected["points"]), 1e-30)
    worst, worst_at = 0.0, None
    for tc, got, want in zip(expected["timecodes"], frames, expected["points"]):
        if len(got) != len(want):
            summary["issues"].append(f"timecode {tc}: {len(got)} points, expected {len(want)}")
            return summary, frames
        error = max_distance(got, want) / scale
        if math.isnan(error):
            summary["issues"].append(f"timecode {tc}: a point is NaN")
        if error > worst:
            worst, worst_at = error, tc
    summary.update(vertices=len(frames[0]) if frames else 0, timecodes=len(frames), max_error=worst, worst_timecode=worst_at)
    if worst > expected.get("tolerance", 1e-5):
        summary["issues"].append(f"max error {worst:.3g} (relative to the bbox diagonal) at timecode {worst_at} exceeds {expected.get('tolerance', 1e-5)}")
    return summary, frames


def main(argv):
    args = [a for a in argv[1:] if not a.startswith("--")]
    if len(args) != 2 or any(a not in ("--usdc",) for a in argv[1:] if a.startswith("--")):
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    path, expected_path = args
    with open(expected_path) as f:
        expected = json.load(f)
    summary, frames = check(path, expected)
    if "--usdc" in argv and frames is not None:
        with tempfile.TemporaryDirectory() as tmp:
            converted = os.path.join(tmp, os.path.splitext(os.path.basename(path))[0] + ".usdc")
            if not Sdf.Layer.FindOrOpen(path).Export(converted):
                summary["issues"].append("Sdf could not export the layer to usdc")
            else:
                usdc, usdc_frames = check(converted, expected)
                summary["usdc"] = {"bytes": os.path.getsize(converted), "max_error": usdc.get("max_error")}
                summary["issues"] += ["usdc: " + i for i in usdc["issues"]]
                if usdc_frames is not None:
                    drift = max(max_distance(a, b) for a, b in zip(frames, usdc_frames))
                    summary["usdc"]["max_difference_from_usda"] = drift
                    if drift != 0.0:
                        summary["issues"].append(f"usdc evaluates differently from the original (max difference {drift})")
    summary["ok"] = not summary["issues"]
    for issue in summary["issues"]:
        print(f"{path}: {issue}", file=sys.stderr)
    print(json.dumps(summary))
    return 0 if summary["ok"] else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
