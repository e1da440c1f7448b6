"""What one export may reuse from the previous one: the rendered viewport's incremental export.

A viewport session exports the scene again after every edit, but only the parts an edit
touched are converted again.  :class:`ExportCache` holds what :func:`addon.export.export_scene`
converted last time:

=============  ===================================================================  ==========================
kept           reused while                                                         forgotten by
=============  ===================================================================  ==========================
meshes         the object's geometry did not change (vertices, modifiers, the       :meth:`forget_geometry`
               materials it carries, the UV tangents / colour attributes they read)
materials      no material, node tree or image changed                              :meth:`forget_materials`
world          the world, its node trees and images did not change, and the scene   :meth:`forget_world`
               still uses the same world
=============  ===================================================================  ==========================

Transforms, lights and the scene's render flags are read on every export (they are cheap).
Which Blender updates forget what is :func:`forget_for_updates`' business (the depsgraph's
``updates`` list, read on Blender's main thread).  Counters say what was converted:
``exports`` (scene walks), ``mesh_conversions`` (meshes converted again: a camera move or an
object move converts none).
"""
from __future__ import annotations

__all__ = ["ExportCache", "forget_for_updates"]


class ExportCache:
    """Converted meshes, the material exporter and the world of the last export.

    Attributes
    ----------
    meshes : key -> (owner, scene.Mesh): the key is the export's mesh key (object name or, for
        instances, the evaluated data's address; the material indices; the tangent and colour
        maps read); owner the original object's name, or None for an instance.
    materials : the last export's ``MaterialExporter`` (None: convert materials again).
    world : the last export's ``scene.World`` and its warnings, or None.
    exports, mesh_conversions : counters (scene walks; meshes converted, not taken from here).
    """

    def __init__(self):
        self.meshes: dict = {}
        self.materials = None
        self.world = None
        self.exports = 0
        self.mesh_conversions = 0
        self._used: set = set()

    # -- During an export ---------------------------------------------------------------------
    def begin(self) -> None:
        """An export starts: meshes it does not take are dropped when it ends (:meth:`end`)."""
        self.exports += 1
        self._used = set()

    def mesh(self, key):
        """The converted mesh under ``key`` or None."""
        hit = self.meshes.get(key)
        if hit is None:
            return None
        self._used.add(key)
        return hit[1]

    def keep_mesh(self, key, owner, mesh) -> None:
        """Keep a mesh the export converted (``owner``: original object name, None for instances)."""
        self.meshes[key] = (owner, mesh)
        self._used.add(key)
        self.mesh_conversions += 1

    def end(self) -> None:
        """Forget the meshes of objects the export no longer saw (deleted, hidden)."""
        self.meshes = {k: v for k, v in self.meshes.items() if k in self._used}

    # -- Between exports -------------------------------------------------------------------------
    def forget_geometry(self, names) -> None:
        """Objects ``names`` (original names) changed shape: convert their meshes again.  Instances
        are keyed by the address of their evaluated data, which Blender may reuse after any
        re-evaluation, so every instance's mesh is converted again too."""
        names = set(names)
        self.meshes = {k: (owner, m) for k, (owner, m) in self.meshes.items()
                       if owner is not None and owner not in names}

    def forget_materials(self) -> None:
        self.materials = None

    def forget_world(self) -> None:
        self.world = None

    def forget_all(self) -> None:
        self.meshes = {}
        self.materials = None
        self.world = None


# Blender ID types (``type(update.id).__name__`` prefixes) whose change makes materials / the world stale
_SHADING_TYPES = ("Material", "ShaderNodeTree", "NodeTree", "Image", "Texture")


def forget_for_updates(cache: ExportCache, updates) -> dict:
    """Forget what the depsgraph ``updates`` changed (Blender's main thread: it reads bpy IDs).

    Returns a summary: {'objects': original names of objects changed in any way (camera objects
    apart), 'geometry': of those, the ones whose geometry changed, 'cameras': camera objects
    changed, 'materials': bool, 'world': bool, 'scene': the scene itself changed (settings,
    selection, the world it uses), 'other': other ID types seen}.
    """
    out = {"objects": set(), "geometry": set(), "cameras": set(), "materials": False, "world": False,
           "scene": False, "other": set()}
    for update in updates:
        idb = update.id
        kind = type(idb).__name__
        original = getattr(idb, "original", idb) or idb
        name = getattr(original, "name_full", getattr(idb, "name", ""))
        if kind == "Object":
            if getattr(idb, "type", "") == "CAMERA":
                out["cameras"].add(name)
                continue
            out["objects"].add(name)
            if update.is_updated_geometry:
                out["geometry"].add(name)
        elif kind == "Camera":           # camera data (lens, clipping): the viewport's view is its own
            out["cameras"].add(name)
        elif kind == "World":
            out["world"] = True
        elif kind == "Scene":
            out["scene"] = True
        elif kind.startswith(_SHADING_TYPES) or kind.endswith("NodeTree"):
            # A node tree shared by materials and the world (a group) makes both stale
            out["materials"] = True
            if not kind.startswith("Material"):
                out["world"] = True
        else:
            out["other"].add(kind)
    if out["geometry"]:
        cache.forget_geometry(out["geometry"])
    if out["materials"]:
        cache.forget_materials()
    if out["world"]:
        cache.forget_world()
    return out
