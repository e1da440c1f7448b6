"""Batch use without the UI: load a .blend into the core's scene model, or render frames.

* :func:`load_blend` -- opens the file with bpy and exports one frame (no RenderEngine:
  time steps through ``scene.frame_set(frame, subframe=...)`` on the view-layer depsgraph,
  with viewport visibility and subdivision levels set to their render values for the time
  of the export: :func:`render_visibility`).
* :func:`serve` -- the .blend reader process of ``stpm render/plan/compare SCENE.blend``
  (started by :class:`stpm_core.blend_loader.BlendReader`): opens the file once and writes
  each frame asked for to a core scene file, so a crash of Blender's own reader ends that
  process, never ``stpm``.
* :func:`render_blend` -- renders frames through Blender itself
  (``bpy.ops.render.render``), exactly what ``blender -b f.blend -E STPM -f N``
  does, and writes Blender's multilayer EXR plus a PNG preview per frame.

Frames are independent: a farm (e.g. Flamenco) runs one task per frame.
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import sys
import time
import traceback
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


def load_blend(path, frame=None, bake: bool = False) -> tuple:
    """Open ``path`` and export one frame.

    Parameters
    ----------
    path : .blend file.
    frame : frame number (int or float; None = the file's current frame).
    bake : first bake, in one child process, the inputs the node interpreter cannot evaluate
        that have no cached bake yet (``stpm render`` does; :mod:`.export.bake`).

    Returns (Scene, settings dict) -- the dict holds the file's ``scene.stpm``
    values under RenderSettings' names (the CLI overlays its options on it).
    The Scene's ``metadata['warnings']`` lists what the export approximated;
    ``metadata['frame_range']`` holds the file's [frame_start, frame_end].
    """
    scene = _open(path)
    stpm_scene, settings = export_current(scene, frame, bake=bake)
    _note_source(stpm_scene, path, scene)
    return stpm_scene, settings


def serve(reply_fd: int) -> None:
    """Answer the requests of :class:`stpm_core.blend_loader.BlendReader`, then exit (``os._exit``).

    Runs in its own process (``python -c "from addon.batch import serve; serve(FD)"``) whose
    stdout and stderr are the parent's log of Blender's output.  Requests are JSON lines on
    stdin, each answered by one JSON line on the descriptor ``reply_fd``:

    * ``{"open": PATH}`` -> ``{"ok": true, "frame_range": [start, end]}``: open the .blend (once);
    * ``{"frame": F or null, "bake": bool, "out": FILE}`` -> ``{"ok": true, "settings": {...},
      "export_s": s, "save_s": s}``: export frame F (None: the file's current frame) as
      :func:`load_blend` does, write it to the core scene file FILE (uncompressed: it is read
      once, at once) and answer with the file's ``scene.stpm`` values;
    * ``{"denoise": NPZ, "out": NPY}`` -> ``{"ok": true, "denoise_s": s}``: Blender's Denoise node on the
      passes in NPZ (Combined or Noisy Image, Denoising Albedo, Denoising Normal;
      :func:`addon.denoise.denoise_passes`), the denoised RGBA written to NPY (no .blend needed);
    * a failure -> ``{"ok": false, "kind": "StpmError" | "SettingsError" | ..., "error": line}``
      for the user's errors, ``{"ok": false, "bug": type, "error": ..., "traceback": ...}`` for
      anything else.

    End of input ends the process at once (no interpreter or Blender teardown).
    """
    from ._core import sub
    save_scene = sub("scenefile").save_scene
    reply_to = os.fdopen(reply_fd, "w", encoding="utf-8")

    def reply(**answer) -> None:
        reply_to.write(json.dumps(answer) + "\n")
        reply_to.flush()

    path = scene = None
    while True:
        line = sys.stdin.readline()
        if not line:
            break
        try:
            request = json.loads(line)
            if "open" in request:
                path = request["open"]
                scene = _open(path)
                reply(ok=True, frame_range=[int(scene.frame_start), int(scene.frame_end)])
                continue
            if "denoise" in request:
                import numpy as np
                from .denoise import denoise_passes
                t0 = time.perf_counter()
                with np.load(request["denoise"]) as data:
                    denoised = denoise_passes({name: data[name] for name in data.files})
                np.save(request["out"], denoised)
                reply(ok=True, denoise_s=time.perf_counter() - t0)
                continue
            if scene is None:
                raise RuntimeError("no .blend open")
            t0 = time.perf_counter()
            stpm_scene, settings = export_current(scene, request["frame"], bake=bool(request["bake"]))
            _note_source(stpm_scene, path, scene)
            t1 = time.perf_counter()
            save_scene(stpm_scene, request["out"], compress=False)
            del stpm_scene
            reply(ok=True, settings=settings, export_s=t1 - t0, save_s=time.perf_counter() - t1)
        except _core.StpmError as e:
            reply(ok=False, kind=type(e).__name__, error=str(e))
        except Exception as e:  # noqa: BLE001 -- a bug: the parent reports it as one
            reply(ok=False, bug=type(e).__name__, error=str(e), traceback=traceback.format_exc())
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(0)


def _note_source(stpm_scene, path, scene) -> None:
    """Record where an exported scene came from: ``metadata['source']`` and ``['frame_range']``,
    and add :func:`command_line_notes` to its warnings."""
    stpm_scene.metadata["source"] = str(path)
    if int(scene.frame_start) <= int(scene.frame_end):                                  # for the CLI's check
        stpm_scene.metadata["frame_range"] = [int(scene.frame_start), int(scene.frame_end)]
    notes = command_line_notes(scene)
    if notes:
        stpm_scene.metadata["warnings"] = list(stpm_scene.metadata.get("warnings", [])) + notes


# Compositor nodes that change nothing in the image (their presence is no reason for a warning)
_PASSIVE_COMPOSITOR_NODES = {"CompositorNodeRLayers", "NodeGroupOutput", "NodeGroupInput", "CompositorNodeComposite",
                             "CompositorNodeViewer", "NodeReroute", "NodeFrame", "CompositorNodeOutputFile"}


def command_line_notes(scene) -> list[str]:
    """What ``blender -b FILE -f N`` would render of ``scene`` that a .blend read by ``stpm`` (one
    exported view layer, no compositor) leaves out: warning lines, [] when nothing.

    * more than one view layer ticked *Use for Rendering* (Blender renders each), or the one
      exported (the active layer) unticked;
    * a compositor that changes the image (Output > Post Processing > Compositing on, a node other
      than Render Layers / the outputs / the STPM Denoise group, which ``stpm render`` runs itself).
    """
    from .denoise import GROUP, scene_compositor
    notes = []
    exported = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
    rendered = [vl.name for vl in scene.view_layers if vl.use]
    if len(rendered) > 1 or exported.name not in rendered:
        notes.append(f"view layers: Blender renders {len(rendered)} of this file ({', '.join(map(repr, rendered))}); "
                     f"stpm exports the active one, {exported.name!r}, alone (its EXR layer is named ViewLayer). "
                     f"Render the others with F12 or blender -b -E STPM -f, or make the one you want active "
                     f"and save")
    tree = scene_compositor(scene, create=False) if scene.render.use_compositing else None
    if tree is not None:
        active = sorted({n.bl_idname.replace("CompositorNode", "") for n in tree.nodes
                         if n.bl_idname not in _PASSIVE_COMPOSITOR_NODES and not n.mute
                         and not (n.bl_idname == "CompositorNodeGroup" and n.name == GROUP)})
        if active:
            notes.append(f"compositor: its nodes ({', '.join(active)}) are not run by stpm: the EXR and PNG hold "
                         f"the render itself (F12 and blender -b -E STPM -f apply them)")
    return notes


def _editable(idblock) -> bool:
    """Can this ID's properties be set (not linked from a library without an override)?"""
    return getattr(idblock, "library", None) is None or getattr(idblock, "override_library", None) is not None


# Modifiers whose viewport / render subdivision levels differ: (viewport property, render property)
_LEVELS = {"SUBSURF": ("levels", "render_levels"), "MULTIRES": ("levels", "render_levels")}


@contextlib.contextmanager
def render_visibility(view_layer):
    """Make the view-layer (viewport) depsgraph see what F12 renders, for the time of the block.

    Outside a render there is no render-mode depsgraph, so the viewport flags
    are set to their render counterparts and restored afterwards:

    * objects: ``hide_viewport`` (monitor icon) := ``hide_render``; the eye icon
      (``hide_get``) is cleared: it never affects a render;
    * collections: ``hide_viewport`` := ``hide_render``; view-layer collections'
      eye icon cleared (``exclude`` is shared by viewport and render: kept);
    * modifiers: ``show_viewport`` := ``show_render``; Subdivision Surface and
      Multires viewport ``levels`` := ``render_levels``.

    Left as the viewport has them (docs/blender.md): particle display amount,
    geometry nodes' *Is Viewport*, curve/text viewport resolution and other
    modifier-specific viewport settings.
    """
    undo = []  # (callable, args) that restore one value each, run in reverse order

    def put(target, attr, value):
        old = getattr(target, attr)
        if old != value:
            setattr(target, attr, value)
            undo.append((setattr, (target, attr, old)))

    try:
        for coll in bpy.data.collections:
            if _editable(coll):
                put(coll, "hide_viewport", coll.hide_render)
        stack = [view_layer.layer_collection]
        while stack:
            lc = stack.pop()
            if not lc.exclude:
                put(lc, "hide_viewport", False)
            stack.extend(lc.children)
        for obj in bpy.data.objects:
            if not _editable(obj):
                continue
            put(obj, "hide_viewport", obj.hide_render)
            for mod in obj.modifiers:
                put(mod, "show_viewport", mod.show_render)
                levels = _LEVELS.get(mod.type)
                if levels is not None:
                    put(mod, levels[0], getattr(mod, levels[1]))
        for obj in view_layer.objects:
            if obj.hide_get(view_layer=view_layer):
                obj.hide_set(False, view_layer=view_layer)
                undo.append((lambda o: o.hide_set(True, view_layer=view_layer), (obj,)))
        yield
    finally:
        for fn, args in reversed(undo):
            try:
                fn(*args)
            except (AttributeError, ReferenceError, RuntimeError, TypeError):  # removed meanwhile: nothing to restore
                pass


def export_current(scene, frame=None, bake: bool = False) -> tuple:
    """Export the open Blender ``scene`` at ``frame`` (None = its current frame).

    Outside a RenderEngine, time moves with ``scene.frame_set``; the current
    frame is restored afterwards.  Objects, collections and modifiers are
    exported with their *render* visibility (:func:`render_visibility`), so the
    same objects as an F12 render.  ``bake``: run the missing bakes first
    (:func:`bake_current`).  Returns (Scene, settings dict) as :func:`load_blend` does.
    """
    with _at_frame(scene, frame):
        bakes = "default"
        if bake:
            bakes, _report = _bake_here(scene)
        return _export_at(scene, bakes)


@contextlib.contextmanager
def _at_frame(scene, frame=None):
    """The open ``scene`` at ``frame`` (None = its current frame) with render visibility
    (:func:`render_visibility`); the frame is restored afterwards."""
    frame_before, subframe_before = scene.frame_current, scene.frame_subframe
    f = float(scene.frame_current if frame is None else frame)
    fi = int(f // 1)
    view_layer = bpy.context.view_layer if bpy.context.scene == scene else scene.view_layers[0]
    with render_visibility(view_layer):
        scene.frame_set(fi, subframe=f - fi)
        try:
            yield
        finally:
            scene.frame_set(frame_before, subframe=subframe_before)


def _bake_here(scene, log=None) -> tuple:
    """Bake what is missing at the frame and visibility already set: (resolver, report)."""
    from .export import bake as bake_mod
    return bake_mod.bake_scene(scene, bpy.context.evaluated_depsgraph_get(), log=log)


def bake_current(scene, frame=None, log=None) -> dict:
    """Bake the missing inputs of the open ``scene`` at ``frame`` (None = its current frame),
    with render visibility, in one child process (:mod:`.export.bake`); the frame is restored.
    Returns the report of :func:`.export.bake.run_jobs` plus ``statuses``: {state: count} of
    every input to bake after the run."""
    with _at_frame(scene, frame):
        resolver, report = _bake_here(scene, log)
        from .export import rendered_meshes
        counts: dict = {}
        for obj, is_instance, mats in rendered_meshes(bpy.context.evaluated_depsgraph_get()):
            for m in mats:
                if m is not None:
                    for s in resolver.status(m, obj, is_instance):
                        counts[s.state] = counts.get(s.state, 0) + 1
        report["statuses"] = counts
        return report


def _export_at(scene, bakes="default") -> tuple:
    """The body of :func:`export_current`: export at the frame already set."""
    depsgraph = bpy.context.evaluated_depsgraph_get()

    def frame_set(frame_int: int, subframe: float) -> None:
        scene.frame_set(frame_int, subframe=subframe)

    stpm_scene, warnings = export_scene(depsgraph, frame_set, motion_steps=scene.stpm.motion_steps, bakes=bakes)
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
