"""Shared bpy helpers of the ``make_*.py`` scene generators (not a scene itself).

Every generator starts from an empty file (:func:`new_scene`), adds objects
with the helpers below, then calls :func:`finish` to set the STPM engine,
Blender's motion-blur settings and a multilayer EXR output, and save.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import bpy

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))   # the checkout's add-on registers the STPM engine
sys.path.insert(0, str(HERE))

from make_demo import _linear_keys, _material, set_multilayer_exr  # noqa: E402

__all__ = ["HERE", "new_scene", "material", "diffuse", "glass", "metal", "emission", "add_plane", "add_box",
           "add_sphere", "mesh_object", "point_light", "area_light", "camera", "keyframes", "linear_keys",
           "finish", "out_path"]

material = _material
linear_keys = _linear_keys


def new_scene(name: str):
    """Empty file with the STPM add-on registered; returns the scene."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.context.preferences.filepaths.save_version = 0   # no .blend1 backups next to the scenes
    import addon
    addon.register()
    scene = bpy.context.scene
    scene.name = name
    return scene


def diffuse(name: str, color=(0.8, 0.8, 0.8)):
    return _material(name, "ShaderNodeBsdfDiffuse", Color=(*color, 1.0))


def glass(name: str = "Glass", ior: float = 1.5):
    return _material(name, "ShaderNodeBsdfGlass", IOR=ior, Roughness=0.0)


def metal(name: str = "Metal", color=(0.95, 0.95, 0.95)):
    """A smooth mirror metal (Glossy BSDF, roughness 0)."""
    return _material(name, "ShaderNodeBsdfGlossy", Color=(*color, 1.0), Roughness=0.0)


def emission(name: str, strength: float = 5.0):
    return _material(name, "ShaderNodeEmission", Strength=strength)


def _assign(obj, name: str, mat):
    obj.name = name
    if mat is not None:
        obj.data.materials.append(mat)
    return obj


def add_plane(name: str, size: float, mat, location=(0, 0, 0), rotation=(0, 0, 0)):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    return _assign(bpy.context.object, name, mat)


def add_box(name: str, size: float, mat, location=(0, 0, 0)):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    return _assign(bpy.context.object, name, mat)


def add_sphere(name: str, radius: float, mat, location=(0, 0, 0), segments: int = 48, rings: int = 24):
    bpy.ops.mesh.primitive_uv_sphere_add(radius=radius, segments=segments, ring_count=rings, location=location)
    obj = _assign(bpy.context.object, name, mat)
    bpy.ops.object.shade_smooth()
    return obj


def mesh_object(name: str, verts, faces, mat, location=(0, 0, 0), smooth: bool = False):
    """An object from raw vertex / face lists (object space)."""
    me = bpy.data.meshes.new(name)
    me.from_pydata([tuple(v) for v in verts], [], [tuple(f) for f in faces])
    me.update()
    if smooth:
        for p in me.polygons:
            p.use_smooth = True
    obj = bpy.data.objects.new(name, me)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    if mat is not None:
        me.materials.append(mat)
    return obj


def point_light(name: str, energy: float, location, radius: float = 0.05):
    data = bpy.data.lights.new(name, type="POINT")
    data.energy = energy
    data.shadow_soft_size = radius
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def area_light(name: str, energy: float, location, size: float, rotation=(0, 0, 0)):
    data = bpy.data.lights.new(name, type="AREA")
    data.energy = energy
    data.size = size
    obj = bpy.data.objects.new(name, data)
    obj.location = location
    obj.rotation_euler = rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


def camera(location, rotation_deg, lens: float = 35.0):
    data = bpy.data.cameras.new("Camera")
    data.lens = lens
    obj = bpy.data.objects.new("Camera", data)
    obj.location = location
    obj.rotation_euler = tuple(math.radians(a) for a in rotation_deg)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.scene.camera = obj
    return obj


def keyframes(obj, path: str, keys, index: int = -1):
    """Insert ``(frame, value)`` keys on ``obj.<path>`` (a whole vector, or one ``index``), linear."""
    for frame, value in keys:
        if index >= 0:
            getattr(obj, path)[index] = value
        else:
            setattr(obj, path, value)
        obj.keyframe_insert(path, index=index, frame=frame)
    _linear_keys(obj)


def finish(scene, path: Path, *, shutter: float = 0.5, motion_blur: bool = True, resolution=(320, 240),
           world=(0.05, 0.05, 0.05), motion_steps: int = 3, photons_caustic: int = 200_000,
           photons_global: int = 200_000) -> Path:
    """STPM engine, frame 1, Blender motion blur, dim world, multilayer EXR; save to ``path``."""
    w = bpy.data.worlds.new("World")
    if bpy.app.version < (5, 0, 0):
        w.use_nodes = True
    w.node_tree.nodes.get("Background").inputs["Color"].default_value = (*world, 1.0)
    scene.world = w
    scene.frame_start, scene.frame_end = 1, 1
    scene.frame_set(1)
    r = scene.render
    r.engine = "STPM"
    r.resolution_x, r.resolution_y, r.resolution_percentage = resolution[0], resolution[1], 100
    r.use_motion_blur = motion_blur
    r.motion_blur_shutter = shutter
    r.motion_blur_position = "CENTER"
    scene.stpm.motion_steps = motion_steps
    scene.stpm.photons_caustic = photons_caustic
    scene.stpm.photons_global = photons_global
    set_multilayer_exr(r.image_settings)
    bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
    return path


def out_path(default_name: str) -> Path:
    """``argv[1]`` when given, else ``blend_scenes/<default_name>``."""
    return Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / default_name
