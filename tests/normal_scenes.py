"""A capped 16-sided cylinder whose shading normals come each way Blender makes them (bpy).

``build(case)``: the cylinder of ``bpy.ops.mesh.primitive_cylinder_add(vertices=16)`` (radius 1,
depth 2, caps: one 16-gon each), diffuse grey, seen from the front and above, lit by a radius-0
point light at (-3, -5, 3) in a black world, so the lit side, the terminator and the top cap are
all in the image.  The cases:

* ``caps_flat``: Shade Smooth on the side faces only, the caps flat, no sharp edges (the report);
* ``caps_flat_sharp``: the same with the 32 cap edges marked sharp;
* ``all_smooth``, ``all_flat``: Shade Smooth / Shade Flat on the whole mesh;
* ``auto_smooth``: Shade Auto Smooth (the "Smooth by Angle" modifier, 30 degrees);
* ``smooth_by_angle``: Shade Smooth by Angle (sharp edges written into the mesh, 30 degrees);
* ``sharp_seam``: all faces smooth, one vertical side edge marked sharp;
* ``custom``: custom split normals (each corner's normal tipped toward the mesh's centre line by
  the normalised position: a rounder look than the faces), caps flat, sides smooth;
* ``free_point``: a point-domain ``custom_normal`` attribute (Blender 4.5+ "free" normals: the
  normalised position), caps flat, sides smooth;
* ``all_edges_sharp``: every face marked smooth one by one (a ``sharp_face`` attribute, all
  False) and every edge sharp: Blender's viewport shades it flat, Cycles 5.0 smooth;
* ``free_face``: a face-domain ``custom_normal`` attribute (tipped 27 degrees up), sides smooth.

``build(case, normal_map=True)`` adds a tangent-space Normal Map of a constant colour (the normal
tipped 45 degrees toward the tangent) and turns the UV map 45 degrees, so that the tangents climb
the sides (:func:`_normal_map`).

``show_normals()`` swaps the cylinder's material for an emission of 0.5 + 0.5 N (N: the Geometry
node's shading normal), which turns a Cycles render into its shading normals.

Built by ``tests/test_cycles_normals.py``.
"""
from __future__ import annotations

import math

import bpy
import numpy as np

from direct_light_scenes import _diffuse
from test_addon_scenes import add_camera, add_light, fresh, set_world

__all__ = ["build", "show_normals", "CASES"]

W, H = 64, 48
CASES = ("caps_flat", "caps_flat_sharp", "all_smooth", "all_flat", "auto_smooth", "smooth_by_angle",
         "sharp_seam", "custom", "free_point", "all_edges_sharp", "free_face")


def _select_only(obj):
    bpy.ops.object.select_all(action="DESELECT")
    obj.select_set(True)
    bpy.context.view_layer.objects.active = obj


def _sides_smooth(me):
    """Smooth the quads (the sides), leave the caps (16-gons or triangle fans) flat."""
    for p in me.polygons:
        p.use_smooth = len(p.vertices) == 4


def _cap_edges(me) -> list:
    """Indices of the edges between a cap and a side face (both ends at the same height)."""
    co = np.array([v.co[:] for v in me.vertices])
    return [e.index for e in me.edges if abs(co[e.vertices[0], 2] - co[e.vertices[1], 2]) < 1e-6]


def _normals(case: str, obj):
    """Give the cylinder ``obj`` the shading normals of ``case`` (see the module docstring)."""
    me = obj.data
    _select_only(obj)
    if case == "caps_flat":
        _sides_smooth(me)
    elif case == "caps_flat_sharp":
        _sides_smooth(me)
        for i in _cap_edges(me):
            me.edges[i].use_edge_sharp = True
    elif case == "all_smooth":
        bpy.ops.object.shade_smooth()
    elif case == "all_flat":
        bpy.ops.object.shade_flat()
    elif case == "auto_smooth":
        bpy.ops.object.shade_auto_smooth(angle=math.radians(30.0))
        assert any(m.type == "NODES" for m in obj.modifiers), "Shade Auto Smooth added no modifier"
    elif case == "smooth_by_angle":
        bpy.ops.object.shade_smooth_by_angle(angle=math.radians(30.0))
    elif case == "sharp_seam":
        bpy.ops.object.shade_smooth()
        seam = next(i for i in range(len(me.edges)) if i not in set(_cap_edges(me)))
        me.edges[seam].use_edge_sharp = True
    elif case == "custom":
        _sides_smooth(me)
        co = np.array([me.vertices[c.vertex_index].co[:] for c in me.loops])
        n = co / np.linalg.norm(co, axis=1, keepdims=True)
        me.normals_split_custom_set([tuple(v) for v in n])
        assert me.has_custom_normals
    elif case == "free_point":
        _sides_smooth(me)
        co = np.array([v.co[:] for v in me.vertices])
        n = (co / np.linalg.norm(co, axis=1, keepdims=True)).astype(np.float32)
        a = me.attributes.new("custom_normal", "FLOAT_VECTOR", "POINT")
        a.data.foreach_set("vector", n.ravel())
    elif case == "all_edges_sharp":
        for p in me.polygons:
            p.use_smooth = True
        for e in me.edges:
            e.use_edge_sharp = True
    elif case == "free_face":
        _sides_smooth(me)
        n = np.array([p.normal[:] for p in me.polygons]) + np.array([0.0, 0.0, 0.5])
        n = (n / np.linalg.norm(n, axis=1, keepdims=True)).astype(np.float32)
        a = me.attributes.new("custom_normal", "FLOAT_VECTOR", "FACE")
        a.data.foreach_set("vector", n.ravel())
    else:
        raise ValueError(f"unknown case {case!r}")
    me.update()


def show_normals(name: str = "Cylinder"):
    """Make object ``name`` (the cylinder) emit 0.5 + 0.5 N (Geometry > Normal, world space),
    nothing else (its first material is rewired)."""
    mat = bpy.data.objects[name].data.materials[0]
    t = mat.node_tree
    geo = t.nodes.new("ShaderNodeNewGeometry")
    vm = t.nodes.new("ShaderNodeVectorMath")
    vm.operation = "MULTIPLY_ADD"
    vm.inputs[1].default_value = vm.inputs[2].default_value = (0.5, 0.5, 0.5)
    em = t.nodes.new("ShaderNodeEmission")
    t.links.new(geo.outputs["Normal"], vm.inputs[0])
    t.links.new(vm.outputs[0], em.inputs["Color"])
    t.links.new(em.outputs[0], t.nodes["Material Output"].inputs["Surface"])


def _normal_map(obj):
    """Turn the UV map of ``obj`` 45 degrees ((u, v) -> (u + v, v - u)) and give its diffuse
    material a tangent-space Normal Map of the constant colour (0.85, 0.5, 0.85): tangent-space
    normal (0.7, 0, 0.7), 45 degrees toward the tangent."""
    me = obj.data
    uv = np.empty(len(me.loops) * 2, np.float32)
    me.uv_layers.active.uv.foreach_get("vector", uv)
    u, v = uv[0::2].copy(), uv[1::2].copy()
    uv[0::2], uv[1::2] = u + v, v - u
    me.uv_layers.active.uv.foreach_set("vector", uv)
    t = me.materials[0].node_tree
    nm = t.nodes.new("ShaderNodeNormalMap")
    nm.inputs["Color"].default_value = (0.85, 0.5, 0.85, 1.0)
    diffuse = next(n for n in t.nodes if n.type == "BSDF_DIFFUSE")
    t.links.new(nm.outputs["Normal"], diffuse.inputs["Normal"])


def build(case: str, w: int = W, h: int = H, fill: str = "NGON", normal_map: bool = False):
    """The scene of ``case`` (see the module docstring); returns bpy.context.scene.  fill: the caps
    (``end_fill_type``: "NGON", or "TRIFAN" for triangle fans); normal_map: :func:`_normal_map`."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = w, h
    set_world((0, 0, 0), 0.0)
    bpy.ops.mesh.primitive_cylinder_add(vertices=16, radius=1.0, depth=2.0, location=(0.0, 0.0, 0.0),
                                        end_fill_type=fill)
    cyl = bpy.context.object
    cyl.data.materials.append(_diffuse("Grey"))
    _normals(case, cyl)
    if normal_map:
        _normal_map(cyl)
    add_light("POINT", "Key", location=(-3.0, -5.0, 3.0), energy=1000.0, shadow_soft_size=0.0)
    add_camera(location=(0.0, -6.0, 3.5), rotation=(math.radians(60), 0, 0), lens=60)
    return scene
