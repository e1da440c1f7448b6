"""Evaluated Blender meshes -> numpy arrays (loop triangles, materials, corner normals).

Everything goes through ``foreach_get`` into preallocated numpy buffers, no
per-vertex Python loops.
"""
from __future__ import annotations

import numpy as np

GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT", "CURVES", "POINTCLOUD"}
# Object types whose surface Blender evaluates into a mesh that the depsgraph
# lists as a separate *instance* (the object itself carries curve/metaball data)
MESHED_ELSEWHERE = {"CURVE", "SURFACE", "META", "FONT"}


def has_mesh(obj) -> bool:
    """Does this depsgraph entry carry triangles itself (evaluated data is a Mesh)?

    Curves, text, surfaces and metaballs: their mesh arrives as an extra
    instance of the same object, so the object entry itself is skipped (as in
    Cycles); exporting both would double the geometry.
    """
    import bpy
    return isinstance(obj.data, bpy.types.Mesh)


def evaluated_mesh(obj):
    """The evaluated object's mesh and a cleanup callable.

    Returns (mesh or None, cleanup).
    """
    if has_mesh(obj):
        return obj.data, (lambda: None)
    return None, (lambda: None)


def vertex_positions(me) -> np.ndarray:
    """Object-space vertex positions (V, 3) float32."""
    co = np.empty(len(me.vertices) * 3, dtype=np.float32)
    me.vertices.foreach_get("co", co)
    return co.reshape(-1, 3)


def mesh_arrays(me) -> dict:
    """Triangulated arrays of a mesh.

    Returns a dict with
    vertices : (V, 3) float32 object space;
    triangles : (F, 3) int32 vertex indices;
    slots : (F,) int32 material slot index of each triangle;
    normals : (F, 3, 3) float32 corner normals when any face is smooth, else None.
    """
    me.calc_loop_triangles()
    tris = me.loop_triangles
    F = len(tris)
    # Loop triangles: vertex indices, material slots, smooth flags
    tri = np.empty(F * 3, dtype=np.int32)
    tris.foreach_get("vertices", tri)
    slots = np.empty(F, dtype=np.int32)
    tris.foreach_get("material_index", slots)
    smooth = np.zeros(F, dtype=bool)
    if F:
        tris.foreach_get("use_smooth", smooth)
    # Corner normals: Blender already gives flat faces their face normal here
    normals = None
    if smooth.any():
        loops = np.empty(F * 3, dtype=np.int32)
        tris.foreach_get("loops", loops)
        cn = np.empty(len(me.loops) * 3, dtype=np.float32)
        if hasattr(me, "corner_normals"):
            me.corner_normals.foreach_get("vector", cn)
            normals = cn.reshape(-1, 3)[loops].reshape(F, 3, 3)
        else:  # Blender < 4.1
            sn = np.empty(F * 9, dtype=np.float32)
            tris.foreach_get("split_normals", sn)
            normals = sn.reshape(F, 3, 3)
    return {"vertices": vertex_positions(me), "triangles": tri.reshape(F, 3),
            "slots": slots, "normals": normals}
