"""Smooth-shaded low-poly meshes under a hard point light: the shadow terminator (bpy).

A UV sphere of 16 x 8 segments and an open 16-sided cylinder (a tube: no caps), both
smooth-shaded, diffuse grey, lit from the side by a POINT light of radius 0 (no soft shadow to
hide anything) in a black world.  Near the terminator the interpolated normal still faces the
light where the flat triangle does not, and shadow rays leaving the flat triangle hit its
neighbours; Cycles lifts them toward the smooth surface the vertex normals imply
(``Object.shadow_terminator_geometry_offset``, default 0.1; docs/rendering.md, "Shadow
terminator").  ``flat=True`` shades the same meshes flat.  Built by
``tests/test_cycles_terminator.py``.
"""
from __future__ import annotations

import math

import bpy

from direct_light_scenes import _diffuse
from test_addon_scenes import add_camera, add_light, fresh, set_world

__all__ = ["build"]

W, H = 96, 48


def mathutils_look(eye, target):
    """Euler rotation turning an object's -Z from eye toward target."""
    from mathutils import Vector
    return (Vector(target) - Vector(eye)).to_track_quat("-Z", "Y").to_euler()


def build(geometry_offset: float | None = None, shading_offset: float | None = None, flat: bool = False,
          light: str = "POINT", w: int = W, h: int = H):
    """The sphere (left) and the tube (right) seen from the front, the light to the left, in front
    and above, so both terminators run through the image (the sphere shadows the tube's left
    edge).  geometry_offset / shading_offset:
    the objects' ``shadow_terminator_*`` settings (None: Blender's defaults 0.1 / 0.0); light: "POINT"
    (radius 0), "AREA" (1 m square, which Cycles weighs against the BSDF's samples) or "AREA_BIG" (6 m:
    the BSDF's density matters in that weight)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = w, h
    set_world((0, 0, 0), 0.0)
    mat = _diffuse("Grey")
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=1.0, location=(-1.3, 0.0, 0.0))
    sphere = bpy.context.object
    bpy.ops.mesh.primitive_cylinder_add(vertices=16, radius=0.8, depth=1.6, location=(1.3, 0.0, 0.0),
                                        end_fill_type="NOTHING")
    cyl = bpy.context.object
    for obj in (sphere, cyl):
        obj.data.materials.append(mat)
        if flat:
            bpy.ops.object.select_all(action="DESELECT")
            obj.select_set(True)
            bpy.context.view_layer.objects.active = obj
            bpy.ops.object.shade_flat()
        else:
            for poly in obj.data.polygons:
                poly.use_smooth = True
        if geometry_offset is not None:
            obj.shadow_terminator_geometry_offset = geometry_offset
        if shading_offset is not None:
            obj.shadow_terminator_shading_offset = shading_offset
    if light == "POINT":
        add_light("POINT", "Key", location=(-5.0, -2.0, 2.0), energy=1500.0, shadow_soft_size=0.0)
    else:                   # a 1 m square area light in the same place, facing the sphere: Cycles weighs
        size = 6.0 if light == "AREA_BIG" else 1.0                                                  # it by MIS
        key = add_light("AREA", "Key", location=(-5.0, -2.0, 2.0), energy=1500.0, size=size)
        key.rotation_euler = (mathutils_look(key.location, (-1.3, 0.0, 0.0)))
    add_camera(location=(0.0, -7.0, 0.0), rotation=(math.radians(90), 0, 0), lens=35)
    return scene
