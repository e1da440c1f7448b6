"""The outdoor review's flag pole alone: a subdivided cylinder bent by a keyframed two-bone armature
whose upper bone swings -35 -> 35 -> -35 degrees over frames 1-19, rendered at frame 10 (where the
swing turns back inside the shutter) under a sun and a grey world, direct light only (Cycles max
bounces 0, STPM without photons and glossy bounces), 64 x 96, 4 seeds x 32 spp, with motion blur on
and off.  Prints the 8x8-block z-test and the mean ratio STPM / Cycles over the pole's pixels per 16-row band.
python review/pole_probe.py   (PYTHONPATH = checkout)"""
import math
import sys
from pathlib import Path
import numpy as np
ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]
import bpy  # noqa: E402
from test_addon_scenes import fresh, add_camera, add_light, set_world, node_material  # noqa: E402
from cycles_ref import render_cycles, render_stpm, block_ztest  # noqa: E402

bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
for blur in (False, True):
    s = fresh()
    s.render.use_motion_blur = blur; s.render.motion_blur_shutter = 0.5
    add_camera(location=(0, -3.2, 1.0), rotation=(math.radians(90), 0, 0), lens=50)
    sun = add_light("SUN", energy=3.0, location=(0, 0, 5)); sun.rotation_euler = (math.radians(60), 0, math.radians(30))
    set_world((0.3, 0.35, 0.45))
    bpy.ops.mesh.primitive_cylinder_add(radius=0.06, depth=2.0, vertices=16, location=(0, 0, 1.0))
    pole = bpy.context.object
    bpy.ops.object.mode_set(mode="EDIT"); bpy.ops.mesh.select_all(action="SELECT")
    bpy.ops.mesh.subdivide(number_cuts=12); bpy.ops.object.mode_set(mode="OBJECT")
    pole.data.materials.append(node_material("Yellow", "ShaderNodeBsdfPrincipled")[0])
    pole.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.8, 0.6, 0.05, 1)
    pole.data.materials[0].node_tree.nodes["Principled BSDF"].inputs["Roughness"].default_value = 0.4
    arm = bpy.data.armatures.new("Rig"); rig = bpy.data.objects.new("Rig", arm); s.collection.objects.link(rig)
    bpy.context.view_layer.objects.active = rig; bpy.ops.object.mode_set(mode="EDIT")
    b1 = arm.edit_bones.new("Low"); b1.head, b1.tail = (0, 0, 0), (0, 0, 1)
    b2 = arm.edit_bones.new("High"); b2.head, b2.tail = (0, 0, 1), (0, 0, 2); b2.parent = b1
    bpy.ops.object.mode_set(mode="OBJECT")
    for o in bpy.context.view_layer.objects:
        o.select_set(o in (pole, rig))
    bpy.ops.object.parent_set(type="ARMATURE_AUTO")
    pb = rig.pose.bones["High"]; pb.rotation_mode = "XYZ"
    for f, a in ((1, -35.0), (10, 35.0), (19, -35.0)):
        pb.rotation_euler.x = math.radians(a); pb.keyframe_insert("rotation_euler", index=0, frame=f)
    s.frame_set(10)
    s.render.resolution_x, s.render.resolution_y, s.render.resolution_percentage = 64, 96, 100
    st, _ = render_stpm(s, samples=32, glossy_bounces=0)
    cy = render_cycles(s, Path("/tmp"), samples=32)
    z = block_ztest(st, cy)
    pole_px = np.abs(cy.mean(0) - cy.mean(0)[:, :4].mean(axis=1, keepdims=True)).max(-1) > 0.02   # not the world
    bands = [round(float(st[:, y:y + 16][:, pole_px[y:y + 16]].mean() / cy[:, y:y + 16][:, pole_px[y:y + 16]].mean()), 3)
             for y in range(0, 96, 16)]
    print(f"motion blur {blur}: {z.summary()}; rows of 16, STPM / Cycles: {bands}")
