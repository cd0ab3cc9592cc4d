"""Blender (bpy 4.2) as the independent writer of studio caches (run by tests/integration/studio_caches.rs).

    python blender_studio_export.py OUT_DIR FRAMES

Builds an animated mesh: a subdivided cylinder (non-unit object scale) with an animated shape
key, parented to an armature of 3 chained bones that bend over time (Armature modifier), and
a Displace modifier after the armature; the scene is in centimetres (unit scale 0.01) at 24
fps, frames 1..FRAMES. Writes, in OUT_DIR:

- body.abc: Blender's Alembic export of the whole stack (every modifier, evaluated per frame);
- body.fbx: Blender's FBX export (bake_anim, one take) with the Displace modifier turned off,
  because Blender's FBX exporter drops the shape keys of a mesh whose non-armature modifiers it
  applies (the FBX then carries skin + blend shape, which is what an FBX can hold);
- abc.f32 / fbx.f32: the mesh Blender evaluates at every frame for each export (the stack as
  exported), world space, Blender units, z up: FRAMES x vertices x 3 little-endian float32;
- info.json: vertices, frames, fps, the scene's unit scale;
- choice.fbx / choice.abc: the same scene plus a static cube "Crate" and, for the FBX, a second
  action on the rig ("Wave" beside "Bend"), exported with every action as a take: a reader must
  be told which take, and find the animated mesh among two; static.fbx: the cube alone.
"""

import json
import math
import struct
import sys

import bpy


def build(frames):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.unit_settings.system = "METRIC"
    scene.unit_settings.scale_length = 0.01
    scene.unit_settings.length_unit = "CENTIMETERS"
    scene.render.fps = 24
    scene.frame_start, scene.frame_end = 1, frames

    # A closed cylinder (radius 10, height 60, centred on its origin) of 16 sides and 12 rings,
    # quads on the side and an n-gon cap at each end.
    sides, rings = 16, 12
    verts = [(10.0 * math.cos(2 * math.pi * k / sides), 10.0 * math.sin(2 * math.pi * k / sides), -30.0 + 60.0 * r / (rings - 1))
             for r in range(rings) for k in range(sides)]
    faces = [(r * sides + k, r * sides + (k + 1) % sides, (r + 1) * sides + (k + 1) % sides, (r + 1) * sides + k)
             for r in range(rings - 1) for k in range(sides)]
    faces.append(tuple(reversed(range(sides))))
    faces.append(tuple((rings - 1) * sides + k for k in range(sides)))
    me = bpy.data.meshes.new("BodyMesh")
    me.from_pydata(verts, [], faces)
    me.update()
    body = bpy.data.objects.new("Body", me)
    scene.collection.objects.link(body)
    body.location = (0, 0, 30.0)
    body.scale = (1.5, 0.8, 1.2)

    # A shape key that bulges the middle, animated 0 -> 1 -> 0.3.
    body.shape_key_add(name="Basis")
    bulge = body.shape_key_add(name="Bulge")
    for v, p in zip(body.data.vertices, bulge.data):
        r = math.hypot(v.co.x, v.co.y)
        if r > 1e-6:
            k = 0.4 * math.sin(math.pi * v.co.z / 60.0)
            p.co.x, p.co.y = v.co.x * (1 + k), v.co.y * (1 + k)
    for frame, value in ((1, 0.0), (frames // 2, 1.0), (frames, 0.3)):
        bulge.value = value
        bulge.keyframe_insert("value", frame=frame)

    # Three chained bones along the height.
    arm_data = bpy.data.armatures.new("RigData")
    rig = bpy.data.objects.new("Rig", arm_data)
    scene.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig
    rig.name = "Rig"
    bpy.ops.object.mode_set(mode="EDIT")
    bones = rig.data.edit_bones
    first = bones.new("B0")
    first.head, first.tail = (0, 0, 0), (0, 0, 20)
    parent = first
    for i in (1, 2):
        b = bones.new(f"B{i}")
        b.head, b.tail, b.parent, b.use_connect = (0, 0, 20 * i), (0, 0, 20 * (i + 1)), parent, True
        parent = b
    bpy.ops.object.mode_set(mode="OBJECT")

    # Weights by height: each vertex shared by the two nearest bones.
    for i in range(3):
        body.vertex_groups.new(name=f"B{i}")
    for v in body.data.vertices:
        z = min(max(v.co.z + 30.0, 0.0), 60.0)  # object space: the cylinder is centred on its origin
        t = z / 20.0 - 0.5
        lo = min(max(int(math.floor(t)), 0), 2)
        hi = min(lo + 1, 2)
        w = min(max(t - lo, 0.0), 1.0) if hi != lo else 0.0
        body.vertex_groups[f"B{lo}"].add([v.index], 1.0 - w, "REPLACE")
        if hi != lo:
            body.vertex_groups[f"B{hi}"].add([v.index], w, "REPLACE")
    body.parent = rig
    arm = body.modifiers.new("Armature", "ARMATURE")
    arm.object = rig
    disp = body.modifiers.new("Displace", "DISPLACE")
    disp.strength = 1.5
    disp.direction = "X"

    for i, pb in enumerate(rig.pose.bones):
        pb.rotation_mode = "XYZ"
        for frame, angle in ((1, 0.0), (frames // 2, 0.5 + 0.2 * i), (frames, -0.3)):
            pb.rotation_euler = (angle, 0.1 * i * angle, 0.0)
            pb.keyframe_insert("rotation_euler", frame=frame)
    return scene, body, disp


def evaluated(scene, body, frames):
    """The mesh Blender evaluates at every frame, world space, as float32 bytes."""
    out = bytearray()
    count = None
    for frame in range(1, frames + 1):
        scene.frame_set(frame)
        depsgraph = bpy.context.evaluated_depsgraph_get()
        ob = body.evaluated_get(depsgraph)
        me = ob.to_mesh()
        m = ob.matrix_world
        count = len(me.vertices)
        for v in me.vertices:
            p = m @ v.co
            out += struct.pack("<3f", p.x, p.y, p.z)
        ob.to_mesh_clear()
    return bytes(out), count


def main(out_dir, frames):
    scene, body, disp = build(frames)
    abc_ref, vertices = evaluated(scene, body, frames)
    bpy.ops.wm.alembic_export(filepath=f"{out_dir}/body.abc", start=1, end=frames, selected=False)
    disp.show_viewport = disp.show_render = False
    fbx_ref, _ = evaluated(scene, body, frames)
    scene.frame_set(1)
    bpy.ops.export_scene.fbx(filepath=f"{out_dir}/body.fbx", bake_anim=True, bake_anim_use_all_actions=False,
                             bake_anim_use_nla_strips=False, add_leaf_bones=False)
    with open(f"{out_dir}/abc.f32", "wb") as f:
        f.write(abc_ref)
    with open(f"{out_dir}/fbx.f32", "wb") as f:
        f.write(fbx_ref)
    with open(f"{out_dir}/info.json", "w") as f:
        json.dump({"vertices": vertices, "frames": frames, "fps": 24, "unit_scale": scene.unit_settings.scale_length}, f)
    # Files to choose in: a static cube beside the body, two actions on the rig.
    bpy.ops.mesh.primitive_cube_add(size=20.0, location=(60.0, 0, 10.0))
    bpy.context.active_object.name = "Crate"
    rig = bpy.data.objects["Rig"]
    rig.animation_data.action.name = "Bend"
    wave = rig.animation_data.action.copy()
    wave.name = "Wave"
    wave.use_fake_user = True
    bpy.ops.wm.alembic_export(filepath=f"{out_dir}/choice.abc", start=1, end=frames, selected=False)
    bpy.ops.export_scene.fbx(filepath=f"{out_dir}/choice.fbx", bake_anim=True, bake_anim_use_all_actions=True,
                             bake_anim_use_nla_strips=False, add_leaf_bones=False)
    for ob in list(bpy.data.objects):
        ob.select_set(ob.name == "Crate")
    bpy.ops.export_scene.fbx(filepath=f"{out_dir}/static.fbx", use_selection=True, bake_anim=True)
    print(json.dumps({"ok": True, "vertices": vertices}), flush=True)


main(sys.argv[1], int(sys.argv[2]))
