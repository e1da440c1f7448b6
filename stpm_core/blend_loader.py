"""The one seam between ``stpm_core`` and the Blender add-on: reading a ``.blend``.

Why it exists: ``stpm_core`` never imports ``bpy`` (it runs without Blender:
the ``stpm`` command, tests, benchmarks), and the add-on's exporter
(``addon/export/``, driven by ``addon.batch``) is the only reader of ``.blend``
files -- the core has no second one.  A core module that needs a ``.blend``
comes through here, and this is the only module of ``stpm_core`` that imports
``addon`` (checked by tests/test_layering.py).  The import is lazy, made on the
first call, so importing ``stpm_core`` never loads Blender.

What it calls:

* :func:`load_blend` -> ``addon.batch.load_blend(path, frame[, bake])``, which opens the
  file with bpy and exports one frame: (Scene, the file's ``scene.stpm`` settings
  as a dict).
* :func:`blend_frame_range` imports nothing: it reads the ``frame_range`` the
  exporter records in the scene's metadata, else the ``bpy`` module the export
  already loaded (``sys.modules``).
"""
from __future__ import annotations

import sys
from pathlib import Path

from .errors import StpmError

__all__ = ["BlendSupportMissing", "load_blend", "blend_frame_range"]


class BlendSupportMissing(StpmError):
    """.blend input is not available here: Blender's bpy module or ``addon.batch`` cannot be imported."""


def load_blend(path, frame: int | float | None = None, bake: bool = False) -> tuple:
    """(Scene, settings dict) of frame ``frame`` (None: the file's current frame) of the .blend ``path``.

    ``bake``: first bake the shader inputs the node interpreter cannot evaluate and that have no
    cached bake (one Cycles child process; ``addon/export/bake.py``), as ``stpm render`` does.

    Raises :class:`BlendSupportMissing` (one line, naming the file and the fix)
    when bpy or the add-on cannot be imported, and the add-on's StpmError when
    the file cannot be read, with Blender's "Error: " said once
    (``cannot open x.blend: File format is not supported ...``).  Blender's
    console output is the caller's business (it writes to the descriptors).
    """
    path = Path(path)
    try:
        from addon import batch  # bpy lives only in addon/
    except ImportError as e:
        raise BlendSupportMissing(f"cannot load {path.name}: .blend files need Blender's bpy module and "
                                  f"addon.batch ({e}); install the 'test' extra or export a .stpm scene") from None
    try:
        return batch.load_blend(str(path), frame, bake=True) if bake else batch.load_blend(str(path), frame)
    except StpmError as e:  # "cannot open x.blend: Error: File format ...": say "Error" once
        raise type(e)(str(e).replace(": Error: ", ": ")) from None


def blend_frame_range(scene) -> tuple[int, int] | None:
    """(frame_start, frame_end) of the .blend ``scene`` was exported from, or None if unknown.

    From ``scene.metadata['frame_range']`` when the exporter records it, else from
    the bpy module already loaded by the export (never imported here).
    """
    meta = scene.metadata if isinstance(scene.metadata, dict) else {}
    rng = meta.get("frame_range")
    if rng is not None:
        try:
            return int(rng[0]), int(rng[1])
        except (TypeError, ValueError, IndexError):
            return None
    bpy = sys.modules.get("bpy")
    try:
        bscene = bpy.data.scenes[meta["blender_scene"]] if "blender_scene" in meta else bpy.context.scene
        return int(bscene.frame_start), int(bscene.frame_end)
    except Exception:  # noqa: BLE001 -- no bpy or no such scene: no range to check
        return None
