"""Depth-of-field scenes built in bpy for the Cycles comparison (``test_cycles_dof``).

``build(case)``: an emissive checker strip inclined to the view (depth 1.2 to 1.86 scene units
across the frame, so blur grows from the focus row to both ends) and three small emissive spheres
far behind it (depth 9) on a black world, seen by a 200 mm camera (a long lens makes the blur
several pixels wide at 64 x 48: blur radius in pixels = A |1/z - 1/z_f| lens / sensor * 64).  Emission only: no lights, so the only noise is the camera's (film and lens).
``CASES`` names the f-stop, focus and aperture shape (and ``ortho_scale`` for an orthographic
camera).
"""
from __future__ import annotations

import math

import bpy

from test_addon_scenes import add_camera, add_mesh, fresh, set_world

#: case -> camera dof settings (Blender's names)
CASES = {
    "f1.4_round": dict(aperture_fstop=1.4, focus_distance=1.6),
    "f4_round": dict(aperture_fstop=4.0, focus_distance=1.6),
    "f2_5blades_ratio": dict(aperture_fstop=2.0, focus_distance=1.4, aperture_blades=5,
                             aperture_rotation=math.radians(25), aperture_ratio=1.5),
    # orthographic (ortho_scale 1.2): Cycles' radius 1 / (2 fstop) = 0.125 scene units
    "ortho_f4_5blades": dict(aperture_fstop=4.0, focus_distance=1.6, aperture_blades=5, aperture_rotation=0.3,
                             ortho_scale=1.2),
}


def _emission(name: str, checker: bool, strength: float):
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    for n in list(t.nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            t.nodes.remove(n)
    out = next(n for n in t.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    em = t.nodes.new("ShaderNodeEmission")
    em.inputs["Strength"].default_value = strength
    if checker:
        coord = t.nodes.new("ShaderNodeTexCoord")
        ch = t.nodes.new("ShaderNodeTexChecker")
        ch.inputs["Scale"].default_value = 12.0
        ch.inputs["Color1"].default_value = (0.9, 0.8, 0.6, 1)
        ch.inputs["Color2"].default_value = (0.05, 0.1, 0.2, 1)
        t.links.new(coord.outputs["UV"], ch.inputs["Vector"])
        t.links.new(ch.outputs["Color"], em.inputs["Color"])
    else:
        em.inputs["Color"].default_value = (1.0, 0.9, 0.7, 1)
    t.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def build(case: str, resolution=(64, 48)):
    """The scene of ``case`` (a key of CASES) as bpy.context.scene."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = resolution
    set_world((0.0, 0.0, 0.0), 0.0)
    # Camera at (0, -3, 0) looking along +Y
    cam = add_camera(location=(0.0, -3.0, 0.0), rotation=(math.radians(90), 0, 0), lens=200.0)
    cam.data.clip_start, cam.data.clip_end = 0.05, 100.0
    cam.data.dof.use_dof = True
    for k, v in CASES[case].items():
        if k == "ortho_scale":
            cam.data.type, cam.data.ortho_scale = "ORTHO", v
        else:
            setattr(cam.data.dof, k, v)
    # The checker strip tilted 12 degrees off the view axis: depth 1.12 (below the frame) to 1.86 (its
    # far edge, above the frame's centre); black world above it
    plane = add_mesh("plane", "Checker", size=1.0, location=(0.0, -1.5065, -0.0226),
                     material=_emission("Checker", True, 1.0))
    plane.rotation_euler = (math.radians(12), 0, 0)
    plane.scale = (0.5, 0.755, 1.0)
    # Small bright spheres at depth 9 above its far edge: bokeh of the aperture's shape
    for i, (x, z) in enumerate(((-0.5, 0.45), (0.0, 0.5), (0.45, 0.42))):
        add_mesh("sphere", f"Dot{i}", location=(x, 6.0, z), radius=0.03, segments=16, ring_count=8,
                 material=_emission(f"Dot{i}", False, 20.0))
    return scene
