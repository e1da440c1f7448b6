"""Tiny Blender scenes built with bpy for the add-on tests (and a test of the builders).

Imported by the other ``test_addon_*`` files.  bpy can be imported once per
process: every builder starts from ``read_factory_settings(use_empty=True)``.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy")

ROOT = Path(__file__).resolve().parent.parent
for _p in (ROOT, ROOT / "blend_scenes"):
    if str(_p) not in sys.path:
        sys.path.insert(0, str(_p))

import addon  # noqa: E402
from addon.export import export_scene  # noqa: E402
from make_demo import node_material  # noqa: E402,F401  (the scene scripts' material helper, shared)


def fresh() -> "bpy.types.Scene":
    """An empty scene with the STPM add-on registered and linear keyframes."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    bpy.context.preferences.edit.keyframe_new_interpolation_type = "LINEAR"
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 32, 24, 100
    return scene


def linear_keys(idblock) -> None:
    """Make every keyframe of an ID (object, shape key, camera data...) linear.

    Walks layered actions (Blender 4.4+) and legacy ``action.fcurves``.
    """
    action = idblock.animation_data.action
    curves = list(getattr(action, "fcurves", []) or [])
    for layer in getattr(action, "layers", []):
        for strip in layer.strips:
            for bag in getattr(strip, "channelbags", []):
                curves.extend(bag.fcurves)
    for fc in curves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


def add_mesh(kind: str = "cube", name: str = "Obj", location=(0, 0, 0), material=None, **kw):
    """A primitive mesh object linked to the scene."""
    op = {"cube": bpy.ops.mesh.primitive_cube_add, "plane": bpy.ops.mesh.primitive_plane_add,
          "sphere": bpy.ops.mesh.primitive_uv_sphere_add}[kind]
    op(location=location, **kw)
    obj = bpy.context.object
    obj.name = name
    if material is not None:
        obj.data.materials.append(material)
    return obj


def add_camera(location=(0, -6, 2), rotation=(math.radians(75), 0, 0), **data):
    cam_data = bpy.data.cameras.new("Cam")
    for k, v in data.items():
        setattr(cam_data, k, v)
    cam = bpy.data.objects.new("Cam", cam_data)
    cam.location, cam.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(cam)
    bpy.context.scene.camera = cam
    return cam


def add_light(kind: str = "POINT", name: str = "Light", location=(0, 0, 3), **data):
    lamp = bpy.data.lights.new(name, type=kind)
    for k, v in data.items():
        setattr(lamp, k, v)
    obj = bpy.data.objects.new(name, lamp)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def set_world(color=(0.0, 0.0, 0.0), strength=1.0):
    world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    bg = world.node_tree.nodes["Background"]
    bg.inputs["Color"].default_value = (*color, 1.0)
    bg.inputs["Strength"].default_value = strength
    bpy.context.scene.world = world
    return world


def diffuse(name: str, rgb):
    """A material of one Diffuse BSDF of colour rgb (the tests' Lambertian surface)."""
    return node_material(name, "ShaderNodeBsdfDiffuse", Color=(*rgb, 1.0))[0]


def export_now(scene=None, motion_steps: int = 3):
    """Export the current scene through the batch path (scene.frame_set, view-layer depsgraph)."""
    scene = scene or bpy.context.scene
    depsgraph = bpy.context.evaluated_depsgraph_get()
    return export_scene(depsgraph, lambda f, sub: scene.frame_set(f, subframe=sub), motion_steps=motion_steps)


def test_builders_make_a_renderable_scene():
    # A cube, a camera and a light export to one instance, one light, one camera
    fresh()
    add_mesh("cube")
    add_camera()
    add_light()
    scene, warnings = export_now()
    assert len(scene.instances) == 1 and len(scene.lights) == 1
    assert scene.meshes[0].triangles.shape == (12, 3)
    assert warnings == []
