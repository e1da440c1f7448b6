"""Build ``blend_scenes/demo.blend``: a glass sphere moving over a floor under a small light.

A motion-blurred caustic: the sphere slides 1 m along +X during frame 1's
shutter (CENTER, 0.5 frames), focusing a small point light onto a diffuse
floor.  Run with the repository's virtualenv::

    .venv/bin/python blend_scenes/make_demo.py [OUT.blend]

Only bpy is used (no add-on needed); the file selects the STPM engine, which
Blender keeps by name even when the add-on is not loaded yet.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import bpy

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # the checkout's add-on registers the STPM engine


def node_material(name: str, node: str, **inputs):
    """A node material whose surface is one shader ``node`` with ``inputs`` set -> (material, node)."""
    mat = bpy.data.materials.new(name)
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    tree = mat.node_tree
    for n in list(tree.nodes):
        if n.bl_idname != "ShaderNodeOutputMaterial":
            tree.nodes.remove(n)
    out = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    shader = tree.nodes.new(node)
    for key, value in inputs.items():
        shader.inputs[key].default_value = value
    tree.links.new(shader.outputs[0], out.inputs["Surface"])
    return mat, shader


def _material(name: str, node: str, **inputs):
    """:func:`node_material`'s material alone."""
    return node_material(name, node, **inputs)[0]


def build(path: Path) -> Path:
    """Create the demo scene from an empty file and save it to ``path``."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    import addon
    addon.register()
    scene = bpy.context.scene
    scene.name = "Demo"

    # Floor: a 6 m diffuse plane
    bpy.ops.mesh.primitive_plane_add(size=6.0, location=(0, 0, 0))
    floor = bpy.context.object
    floor.name = "Floor"
    floor.data.materials.append(_material("Floor", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.8, 0.8, 1.0)))

    # Glass sphere, keyed to slide 1 m per frame along +X
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.5, segments=48, ring_count=24, location=(-0.5, 0, 1.0))
    sphere = bpy.context.object
    sphere.name = "GlassSphere"
    bpy.ops.object.shade_smooth()
    sphere.data.materials.append(_material("Glass", "ShaderNodeBsdfGlass", IOR=1.5, Roughness=0.0))
    for frame, x in ((0, -1.5), (1, -0.5), (2, 0.5)):
        sphere.location.x = x
        sphere.keyframe_insert("location", index=0, frame=frame)
    _linear_keys(sphere)

    # Small point light above the sphere
    light_data = bpy.data.lights.new("Key", type="POINT")
    light_data.energy = 300.0
    light_data.shadow_soft_size = 0.05
    light = bpy.data.objects.new("Key", light_data)
    light.location = (0.0, 0.0, 3.0)
    scene.collection.objects.link(light)

    # Camera looking down at the floor
    cam_data = bpy.data.cameras.new("Camera")
    cam_data.lens = 35.0
    cam = bpy.data.objects.new("Camera", cam_data)
    cam.location = (0.0, -5.5, 3.2)
    cam.rotation_euler = (math.radians(60.0), 0.0, 0.0)
    scene.collection.objects.link(cam)
    scene.camera = cam

    # World: dim grey
    world = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    bg = world.node_tree.nodes.get("Background")
    bg.inputs["Color"].default_value = (0.05, 0.05, 0.05, 1.0)
    scene.world = world

    # Render settings: STPM, motion blur on, small preview resolution
    scene.frame_start, scene.frame_end, scene.frame_current = 1, 1, 1
    r = scene.render
    r.engine = "STPM"
    r.resolution_x, r.resolution_y, r.resolution_percentage = 320, 240, 100
    r.use_motion_blur = True
    r.motion_blur_shutter = 0.5
    r.motion_blur_position = "CENTER"
    set_multilayer_exr(r.image_settings)
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    return path


def set_multilayer_exr(image_settings) -> None:
    """Multilayer OpenEXR output (Blender 5 moved it to ``media_type``)."""
    if hasattr(image_settings, "media_type"):
        image_settings.media_type = "MULTI_LAYER_IMAGE"
        image_settings.file_format = "OPEN_EXR_MULTILAYER"
    else:
        image_settings.file_format = "OPEN_EXR_MULTILAYER"


def _linear_keys(obj) -> None:
    """Make every keyframe of ``obj`` linear (layered actions in Blender 4.4+ too)."""
    action = obj.animation_data.action
    curves = []
    if hasattr(action, "layers") and len(action.layers):
        for layer in action.layers:
            for strip in layer.strips:
                for bag in getattr(strip, "channelbags", []):
                    curves.extend(bag.fcurves)
    elif hasattr(action, "fcurves"):
        curves = list(action.fcurves)
    for fc in curves:
        for kp in fc.keyframe_points:
            kp.interpolation = "LINEAR"


if __name__ == "__main__":
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "demo.blend"
    print(build(out))
