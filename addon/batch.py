"""Batch use without the UI: load a .blend into the core's scene model, or render frames.

* :func:`load_blend` -- used by ``stpm render/plan/compare SCENE.blend``: opens
  the file with bpy and exports one frame (no RenderEngine: time steps through
  ``scene.frame_set(frame, subframe=...)`` on the view-layer depsgraph, so
  modifiers are evaluated with their viewport settings).
* :func:`render_blend` -- renders frames through Blender itself
  (``bpy.ops.render.render``), exactly what ``blender -b f.blend -E STPM -f N``
  does, and writes Blender's multilayer EXR plus a PNG preview per frame.

Frames are independent: a farm (e.g. Flamenco) runs one task per frame.
"""
from __future__ import annotations

import contextlib
import os
import re
import sys
from pathlib import Path

import bpy

from . import _core
from .export import export_scene
from .properties import settings_dict


def _ensure_registered() -> None:
    """Make sure ``scene.stpm`` and the engine exist (safe to call repeatedly)."""
    if not hasattr(bpy.types.Scene, "stpm") or not hasattr(bpy.types, "STPMRenderEngine"):
        from . import register
        register()


@contextlib.contextmanager
def _stdout_to_stderr():
    """Send Blender's own console lines ("Read blend: ...", "Fra:1 ...") to stderr.

    Blender writes them to file descriptor 1 from C; callers such as
    ``stpm plan --json`` keep stdout for their own output.
    """
    try:
        fd_out, fd_err = sys.stdout.fileno(), sys.stderr.fileno()
    except (AttributeError, OSError, ValueError):  # captured streams without descriptors
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd_out)
    try:
        os.dup2(fd_err, fd_out)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, fd_out)
        os.close(saved)


def _open(path) -> "bpy.types.Scene":
    """Open a .blend file (StpmError when missing or unreadable) and return its scene."""
    path = Path(path)
    if not path.is_file():
        raise _core.StpmError(f"blend file not found: {path}")
    _ensure_registered()
    try:
        with _stdout_to_stderr():
            bpy.ops.wm.open_mainfile(filepath=str(path.resolve()), load_ui=False)
    except RuntimeError as exc:
        raise _core.StpmError(f"cannot open {path}: {str(exc).strip().splitlines()[-1]}") from None
    _ensure_registered()
    return bpy.context.scene


def parse_frames(spec) -> list[int]:
    """'1-24' / '1,3,5-7' / 7 -> sorted unique frame numbers (StpmError on bad text)."""
    if isinstance(spec, int):
        return [spec]
    frames: set[int] = set()
    for part in str(spec).replace(" ", "").split(","):
        m = re.fullmatch(r"(-?\d+)(?:(?:-|\.\.)(-?\d+))?", part)
        if not m:
            raise _core.StpmError(f"bad frame range {spec!r} (expected e.g. 1, 1-24 or 1,3,5-7)")
        a = int(m.group(1))
        b = int(m.group(2)) if m.group(2) is not None else a
        if b < a:
            raise _core.StpmError(f"bad frame range {part!r}: end before start")
        frames.update(range(a, b + 1))
    return sorted(frames)


def load_blend(path, frame=None) -> tuple:
    """Open ``path`` and export one frame.

    Parameters
    ----------
    path : .blend file.
    frame : frame number (int or float; None = the file's current frame).

    Returns (Scene, settings dict) -- the dict holds the file's ``scene.stpm``
    values under RenderSettings' names (the CLI overlays its options on it).
    The Scene's ``metadata['warnings']`` lists what the export approximated.
    """
    scene = _open(path)
    stpm_scene, settings = export_current(scene, frame)
    stpm_scene.metadata["source"] = str(path)
    return stpm_scene, settings


def export_current(scene, frame=None) -> tuple:
    """Export the open Blender ``scene`` at ``frame`` (None = its current frame).

    Outside a RenderEngine, time moves with ``scene.frame_set``; the current
    frame is restored afterwards.  Returns (Scene, settings dict) as
    :func:`load_blend` does.
    """
    frame_before, subframe_before = scene.frame_current, scene.frame_subframe
    f = float(scene.frame_current if frame is None else frame)
    fi = int(f // 1)
    scene.frame_set(fi, subframe=f - fi)
    try:
        depsgraph = bpy.context.evaluated_depsgraph_get()

        def frame_set(frame_int: int, subframe: float) -> None:
            scene.frame_set(frame_int, subframe=subframe)

        stpm_scene, warnings = export_scene(depsgraph, frame_set, motion_steps=scene.stpm.motion_steps)
    finally:
        scene.frame_set(frame_before, subframe=subframe_before)
    stpm_scene.metadata["warnings"] = list(warnings)
    return stpm_scene, settings_dict(scene.stpm)


def _set_format(image_settings, fmt: str) -> None:
    """'EXR' (multilayer, float) or 'PNG' on Blender 4.2 to 5.x image settings."""
    if fmt == "EXR":
        if hasattr(image_settings, "media_type"):
            image_settings.media_type = "MULTI_LAYER_IMAGE"
        image_settings.file_format = "OPEN_EXR_MULTILAYER"
        image_settings.color_depth = "32"
    else:
        if hasattr(image_settings, "media_type"):
            image_settings.media_type = "IMAGE"
        image_settings.file_format = "PNG"
        image_settings.color_mode = "RGBA"


def frame_path(pattern: str, frame: int) -> str:
    """Blender-style output name: a run of '#' becomes the zero-padded frame, else '_NNNN' is added."""
    m = re.search(r"#+", pattern)
    if m:
        return pattern[:m.start()] + str(frame).zfill(len(m.group())) + pattern[m.end():]
    root, ext = os.path.splitext(pattern)
    return f"{root}_{frame:04d}{ext or '.exr'}"


def render_blend(path, frames, output, *, settings: dict | None = None, resolution=None,
                 png: bool = True) -> list[dict]:
    """Render ``frames`` of ``path`` with the STPM engine through Blender.

    Parameters
    ----------
    frames : int, '1-24' style text or an iterable of ints.
    output : output path pattern (``#`` = frame digits), e.g. ``out/shot_####.exr``.
    settings : ``scene.stpm`` values to override (RenderSettings names).
    resolution : (width, height) override, pixels at 100 %.
    png : also save an sRGB PNG preview next to each EXR.

    Returns one dict per frame: ``frame``, ``exr``, ``png`` (or None), ``stats``,
    ``warnings``.  Each frame reopens the file, so frames are independent.
    """
    from .engine import LAST_RENDER
    frame_list = parse_frames(frames) if not isinstance(frames, (list, tuple, range)) else [int(f) for f in frames]
    results = []
    for f in frame_list:
        scene = _open(path)
        scene.render.engine = "STPM"
        for key, value in (settings or {}).items():
            if not hasattr(scene.stpm, key):
                raise _core.StpmError(f"unknown setting {key!r}")
            setattr(scene.stpm, key, value)
        if resolution is not None:
            scene.render.resolution_x, scene.render.resolution_y = int(resolution[0]), int(resolution[1])
            scene.render.resolution_percentage = 100
        scene.frame_set(f)
        exr = os.path.abspath(frame_path(str(output), f))
        os.makedirs(os.path.dirname(exr) or ".", exist_ok=True)
        scene.render.filepath = exr
        scene.render.use_file_extension = False
        _set_format(scene.render.image_settings, "EXR")
        LAST_RENDER.clear()
        with _stdout_to_stderr():
            bpy.ops.render.render(write_still=True)
        if not LAST_RENDER:
            raise _core.StpmError(f"frame {f}: the render produced no image (see the messages above)")
        png_path = None
        if png:
            png_path = os.path.splitext(exr)[0] + ".png"
            _set_format(scene.render.image_settings, "PNG")
            with _stdout_to_stderr():
                bpy.data.images["Render Result"].save_render(png_path, scene=scene)
        results.append({"frame": f, "exr": exr, "png": png_path,
                        "stats": dict(LAST_RENDER.get("stats", {})),
                        "warnings": list(LAST_RENDER.get("warnings", []))})
    return results
