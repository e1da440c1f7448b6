"""A plane bent by an animated shape key, textured through Object or Generated coordinates (bpy).

``build(coords)``: a 2 x 2 plane subdivided 8 x 8 with a shape key "Bow" that moves every
vertex by dx = 0.5 (1 - y^2) (not affine: the Generated box cannot undo it); its value goes
0 -> 1 linearly over frames 4 -> 6, frame 5 rendered, shutter 1 frame (values 0.25 -> 0.75).
The plane emits a Checker (scale 3, white / black) read through Texture Coordinate ``coords``
("Object" or "Generated"), strength 1, nothing else lights anything; an orthographic camera
looks straight down at it.  Emission only: the image is the texture as each renderer reads it.

``build_texspace()``: the same plane without the shape key, Generated coordinates, its Auto
Texture Space off and a manual space ``TEXSPACE`` (location, size) that is not the plane's bounds.

Built by ``tests/test_cycles_deforming_texco.py``.
"""
from __future__ import annotations

import math

import bpy

from test_addon_scenes import add_camera, fresh, linear_keys, set_world

__all__ = ["build", "build_texspace", "TEXSPACE", "W", "H"]

W, H = 48, 48


TEXSPACE = ((0.3, -0.2, 0.0), (0.6, 0.9, 1.0))


def build_texspace(w: int = W, h: int = H):
    """The flat plane with a manual texture space (Generated, no motion blur)."""
    scene = build("Generated", False, w, h, bow=False)
    me = bpy.data.objects["Sheet"].data
    me.use_auto_texspace = False
    me.texspace_location, me.texspace_size = TEXSPACE
    return scene


def build(coords: str = "Object", motion_blur: bool = True, w: int = W, h: int = H, bow: bool = True):
    """The scene above (``bow`` False: no shape key); returns bpy.context.scene (frame 5)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = w, h
    set_world((0, 0, 0), 0.0)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=9, y_subdivisions=9, size=2.0, location=(0, 0, 0))
    obj = bpy.context.object
    obj.name = "Sheet"
    mat = bpy.data.materials.new("Checker")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    t = mat.node_tree
    t.nodes.remove(t.nodes["Principled BSDF"])
    tc, ck, em = (t.nodes.new(k) for k in ("ShaderNodeTexCoord", "ShaderNodeTexChecker", "ShaderNodeEmission"))
    ck.inputs["Scale"].default_value = 3.0
    ck.inputs["Color1"].default_value = (1.0, 1.0, 1.0, 1.0)
    ck.inputs["Color2"].default_value = (0.0, 0.0, 0.0, 1.0)
    t.links.new(tc.outputs[coords], ck.inputs["Vector"])
    t.links.new(ck.outputs["Color"], em.inputs["Color"])
    t.links.new(em.outputs[0], t.nodes["Material Output"].inputs["Surface"])
    obj.data.materials.append(mat)
    if bow:
        obj.shape_key_add(name="Basis")
        key = obj.shape_key_add(name="Bow")
        for p in key.data:
            p.co.x += 0.5 * (1.0 - p.co.y ** 2)
        for f, v in ((4, 0.0), (6, 1.0)):
            key.value = v
            key.keyframe_insert("value", frame=f)
        linear_keys(obj.data.shape_keys)
    add_camera(location=(0.25, 0.0, 3.0), rotation=(0.0, 0.0, 0.0), type="ORTHO", ortho_scale=2.6)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = motion_blur, 1.0
    scene.frame_set(5)
    return scene
