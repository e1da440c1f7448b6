"""Material, world and light previews (``RenderEngine.is_preview``): a small, fast render.

Blender renders its own preview scene (a sphere, cube, ... on a checker floor under two area
lights and a world) with the engine, at the preview's size (128 x 128 for an ID's preview
image, the Material panel's preview at the panel's size).  That scene carries no STPM
settings of the user's, so previews use fixed ones (:data:`PREVIEW_SETTINGS`): progressive
passes of one camera sample per pixel and a few thousand photons, short paths, no motion blur,
no baking.  The first pass renders at most :data:`PREVIEW_FIRST_PIXELS` pixels (scaled up to
the preview's size), so an image shows at once; each later pass replaces it.

Nothing of a preview reaches the user's scene or ``engine.LAST_RENDER`` (a preview may run while
F12 renders); its warnings are not reported (what the preview scene lacks is no news to the
user), errors are, as one line.
"""
from __future__ import annotations

import numpy as np

from . import _core
from .export import export_scene

__all__ = ["PREVIEW_SETTINGS", "preview_settings", "render_preview", "PREVIEW_FIRST_PIXELS"]

# The preview's render settings (RenderSettings fields); everything else keeps its default
PREVIEW_SETTINGS = {
    "method": "PROGRESSIVE", "samples": 1, "passes": 4, "photons_global": 4000, "photons_caustic": 4000,
    "k_nearest": 10, "max_depth": 4, "glossy_bounces": 2, "transmission_bounces": 4, "estimator": "STANDARD",
}
# The first pass renders at most this many pixels (the preview's own size when smaller)
PREVIEW_FIRST_PIXELS = 64 * 64


def preview_settings():
    """The core's RenderSettings of a preview."""
    return _core.RenderSettings.from_dict(dict(PREVIEW_SETTINGS))


def render_preview(engine, depsgraph) -> None:
    """Render Blender's preview scene with :data:`PREVIEW_SETTINGS` into ``engine``'s result.

    Passes are written as they finish (the preview sharpens); Esc or a new preview
    (``engine.test_break``) stops it after the passes so far.  StpmError -> one ERROR line.
    """
    from .engine import write_passes
    from .viewport import first_pass_size

    scene = depsgraph.scene
    try:
        stpm_scene, _warnings = export_scene(depsgraph, lambda f, sub: engine.frame_set(f, subframe=sub),
                                             motion_steps=2, bakes=None, motion_blur=False)
        settings = preview_settings()
        width, height = stpm_scene.resolution
        layer = depsgraph.view_layer.name
        render = _core.render_function()

        def show(passes, info=None):
            write_passes(engine, _scaled(passes, height, width), width, height, layer)

        small = first_pass_size(width, height, PREVIEW_FIRST_PIXELS)
        if small != (width, height):
            from dataclasses import replace
            render(replace(stpm_scene, resolution=small), settings.replace(passes=1),
                   cancel=engine.cancel_requested, on_pass=show)
        if engine.cancel_requested():
            return
        result = render(stpm_scene, settings, cancel=engine.cancel_requested, on_pass=show)
        show(result.passes)
    except _core.RenderCancelled:
        return
    except _core.StpmError as exc:
        engine.report({"ERROR"}, f"STPM preview of {scene.name!r}: {exc}")


def _scaled(passes: dict, height: int, width: int) -> dict:
    """Passes of a reduced first pass repeated up to (height, width) (nearest pixel), others as they are."""
    out = {}
    for name, img in passes.items():
        img = np.asarray(img)
        h, w = img.shape[:2]
        if (h, w) != (height, width):
            rows = np.minimum((np.arange(height) * h) // height, h - 1)
            cols = np.minimum((np.arange(width) * w) // width, w - 1)
            img = img[rows][:, cols]
        out[name] = img
    return out
