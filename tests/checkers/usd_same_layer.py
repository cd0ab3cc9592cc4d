#!/usr/bin/env python3
"""Check with usd-core that a .usdc file holds the same layer as a .usda file.

usage: usd_same_layer.py A.usda B.usdc

Opens both with Sdf (any read error or warning fails) and compares them twice: as the usda
text usd-core writes for each layer (`ExportToString`: every prim spec, property, field, time
sample and value, in usd-core's own order and formatting), and spec by spec (every path in
the layer, its spec type and every field's value as Python objects, so a float that prints
alike but differs still fails). Prints issues to stderr and a one-line JSON summary to
stdout; exit code 0 when the layers are equal, 1 otherwise.
"""

import difflib
import json
import sys

from pxr import Sdf, Tf


def specs(layer):
    """{path: (spec type, {field: value})} of every spec in the layer."""
    out = {}

    def visit(path):
        spec = layer.GetObjectAtPath(path)
        fields = {}
        if spec is not None and hasattr(spec, "ListInfoKeys"):
            for key in spec.ListInfoKeys():
                fields[key] = spec.GetInfo(key)
        if isinstance(spec, Sdf.AttributeSpec):
            fields["timeSamples"] = {t: layer.QueryTimeSample(path, t) for t in layer.ListTimeSamplesForPath(path)}
        out[str(path)] = (type(spec).__name__, fields)

    layer.Traverse(Sdf.Path.absoluteRootPath, visit)
    return out


def main(argv):
    if len(argv) != 3:
        print(__doc__.strip().splitlines()[2], file=sys.stderr)
        return 2
    issues = []
    layers = []
    for path in argv[1:]:
        mark = Tf.Error.Mark()
        mark.SetMark()
        try:
            layer = Sdf.Layer.OpenAsAnonymous(path)
        except Tf.ErrorException as e:
            layer = None
            issues.append(f"{path}: {str(e).strip().splitlines()[-1]}")
        if not mark.IsClean():
            issues += [f"{path}: {e.commentary}" for e in mark.GetErrors()]
        if layer is None and not issues:
            issues.append(f"{path}: Sdf could not open it")
        layers.append(layer)
    summary = {"files": argv[1:]}
    if all(layers):
        a, b = (l.ExportToString() for l in layers)
        summary["text_chars"] = len(a)
        if a != b:
            diff = list(difflib.unified_diff(a.splitlines(), b.splitlines(), argv[1], argv[2], lineterm="", n=0))
            issues.append("the layers differ as text: " + " | ".join(l[:160] for l in diff[2:8]))
        sa, sb = specs(layers[0]), specs(layers[1])
        summary["specs"] = len(sa)
        for path in sorted(set(sa) | set(sb)):
            if sa.get(path) != sb.get(path):
                issues.append(f"spec {path} differs: {str(sa.get(path))[:200]} vs {str(sb.get(path))[:200]}")
                break
    summary["issues"] = issues
    summary["ok"] = not issues
    for issue in issues:
        print(issue, file=sys.stderr)
    print(json.dumps(summary))
    return 0 if summary["ok"] else 1


if __name__ == "__main__":
    sys.exit(main(sys.argv))
