"""Blender (bpy 4.2) as the independent reader of an FBX file (run by tests/integration/studio_caches.rs).

    python blender_fbx_import.py FILE.fbx OUT_DIR

Imports FILE.fbx into an empty scene with Blender's own FBX importer (default settings) and
evaluates its one mesh object at every frame of the imported action's range, as Blender plays
it (armature, shape keys, object transforms). Writes, in OUT_DIR:

- frames.f32: world space, Blender units (metres), z up: FRAMES x vertices x 3 little-endian float32;
- info.json: mesh (its name), vertices, frames, first and last frame, fps.
"""

import json
import struct
import sys

import bpy


def main(argv):
    path, out = argv[1], argv[2]
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.import_scene.fbx(filepath=path)
    scene = bpy.context.scene
    meshes = [o for o in scene.objects if o.type == "MESH"]
    if len(meshes) != 1:
        sys.exit(f"{path}: expected one mesh object, Blender imported {[o.name for o in meshes]}")
    obj = meshes[0]
    ranges = {tuple(a.frame_range) for a in bpy.data.actions}
    if len(ranges) != 1:
        sys.exit(f"{path}: expected one frame range over the imported actions, got {sorted(ranges)}")
    first, last = (round(f) for f in ranges.pop())
    frames = []
    for frame in range(first, last + 1):
        scene.frame_set(frame)
        evaluated = obj.evaluated_get(bpy.context.evaluated_depsgraph_get())
        mesh = evaluated.to_mesh()
        frames.append([evaluated.matrix_world @ v.co for v in mesh.vertices])
        evaluated.to_mesh_clear()
    with open(f"{out}/frames.f32", "wb") as f:
        for points in frames:
            for p in points:
                f.write(struct.pack("<3f", *p))
    info = dict(mesh=obj.name, vertices=len(frames[0]), frames=len(frames), first=first, last=last,
                fps=scene.render.fps / scene.render.fps_base)
    with open(f"{out}/info.json", "w") as f:
        json.dump(info, f)


if __name__ == "__main__":
    main(sys.argv)
