"""STPM Photon Mapper: a Blender render engine (thin registration only).

Works both as a Blender 4.2+ extension (``bl_ext.<repo>.stpm``) and from a
source checkout (``import addon; addon.register()`` with the repository root on
``sys.path``).  Everything else lives in the sibling modules:

* ``properties.py`` -- ``scene.stpm`` settings
* ``engine.py``     -- the RenderEngine (export -> stpm_core.render -> passes)
* ``ui.py``         -- Render-properties panels and presets
* ``export/``       -- one converter per kind of Blender data
* ``batch.py``      -- .blend loading and frame rendering without the UI
* ``compare_op.py`` -- "Compare with Accumulation Buffer" (the stpm compare report)
* ``bake_op.py``    -- "Bake Unsupported Inputs" (Cycles bakes of what the node interpreter cannot evaluate)
* ``denoise.py``    -- the compositor's STPM Denoise group (Blender's Denoise node on the guide passes)
* ``viewport.py``   -- the rendered viewport (a session per 3D view: export, worker thread, image, restarts)
* ``preview.py``    -- material / world / light previews (``is_preview``)
"""
from __future__ import annotations

_registered = False


def register() -> None:
    """Register properties, engine and panels (idempotent)."""
    global _registered
    if _registered:
        return
    from . import bake_op, compare_op, engine, properties, ui
    properties.register()
    engine.register()
    compare_op.register()
    bake_op.register()
    ui.register()
    _registered = True


def unregister() -> None:
    """Undo :func:`register` (idempotent)."""
    global _registered
    if not _registered:
        return
    from . import bake_op, compare_op, engine, properties, ui
    ui.unregister()
    bake_op.unregister()
    compare_op.unregister()
    engine.unregister()
    properties.unregister()
    _registered = False
