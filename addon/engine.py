"""The STPM RenderEngine: export -> ``stpm_core.render.render`` -> Blender passes.

No rendering maths here.  Passes come from the one table
(``stpm_core.render.PASSES``): :meth:`STPMRenderEngine.update_render_passes`
declares them, :func:`write_passes` fills them, so Blender's own outputs (File
Output, multilayer EXR, compositor) see every pass.
"""
from __future__ import annotations

import json
import time
import traceback

import bpy
import numpy as np

from . import _core
from .denoise import compositor_problem
from .export import export_scene
from .properties import settings_from_scene

# Statistics, warnings and pass names of the last finished render (scripts, tests, batch)
LAST_RENDER: dict = {}

# Blender's pass type for each channel-id string of the table
_PASS_TYPE = {"RGBA": "COLOR", "RGB": "COLOR", "XYZ": "VECTOR", "Z": "VALUE"}


def pass_type(channel_ids: str) -> str:
    """Blender pass type ('COLOR' / 'VECTOR' / 'VALUE') for channel ids like 'RGBA'."""
    return _PASS_TYPE.get(channel_ids, "VALUE" if len(channel_ids) == 1 else "COLOR")


# Blender's view-layer pass switches STPM fills (the rest of ``use_pass_*`` stay empty)
_PRODUCED = {"use_pass_combined", "use_pass_z", "use_pass_normal", "use_pass_emit"}
_NOT_PASSES = {"use_pass_cryptomatte_accurate"}  # a quality option, not a pass


def unsupported_passes(view_layer, denoise: bool = False) -> list[str]:
    """UI names of the passes enabled on ``view_layer`` that STPM does not produce (Mist, AO, ...).

    Cycles' *Denoising Data* (``view_layer.cycles.denoising_store_passes``) asks for Denoising
    Normal, Albedo and Depth: STPM writes the first two only with ``scene.stpm.denoise``
    (``denoise``), and Denoising Depth never; the name says which are missing and how to get the
    others."""
    names = []
    if getattr(getattr(view_layer, "cycles", None), "denoising_store_passes", False):
        names.append("Denoising Depth" if denoise else
                     "Denoising Data (tick Sampling > Denoising for Denoising Albedo and Denoising Normal)")
    for owner in (view_layer, getattr(view_layer, "eevee", None), getattr(view_layer, "cycles", None)):
        if owner is None:
            continue
        for prop in owner.bl_rna.properties:
            ident = prop.identifier
            if (ident.startswith("use_pass_") and prop.type == "BOOLEAN" and ident not in _PRODUCED
                    and ident not in _NOT_PASSES and getattr(owner, ident, False)):
                names.append(prop.name or ident[len("use_pass_"):])
    if len(getattr(view_layer, "aovs", ()) or ()):
        names.append("Shader AOVs")
    if len(getattr(view_layer, "lightgroups", ()) or ()):
        names.append("Light Groups")
    return names


def border_region(render, width: int, height: int) -> tuple | None:
    """Blender's Render Region (``render.use_border``) in pixels of the full frame, or None.

    Returns (x, y, w, h): x, y the region's lower-left pixel with y counted from
    the *bottom* row (Blender's convention), w x h its size.  Blender computes
    it in C as ``(int)(border.xmin * winx)`` etc. in single precision; the same
    arithmetic is done here in float32 so the two always agree.
    """
    if not getattr(render, "use_border", False):
        return None
    f32 = np.float32

    def edge(frac, size):
        return int(f32(min(max(float(frac), 0.0), 1.0)) * f32(size))

    x0, x1 = edge(render.border_min_x, width), edge(render.border_max_x, width)
    y0, y1 = edge(render.border_min_y, height), edge(render.border_max_y, height)
    if x1 <= x0 or y1 <= y0 or (x0, y0, x1, y1) == (0, 0, width, height):
        return None
    return x0, y0, x1 - x0, y1 - y0


def region_window(region, height: int) -> tuple | None:
    """The core's pixel window (x0, y0, x1, y1), rows from the top, of a :func:`border_region`
    (x, y from the bottom, w, h), or None: the render traces the region's pixels only."""
    if region is None:
        return None
    x, y, w, h = region
    return x, height - y - h, x + w, height - y


def result_views(render) -> list[str]:
    """Names of the views Blender renders: [''] for mono, e.g. ['left', 'right'] for stereo 3D."""
    if not getattr(render, "use_multiview", False):
        return [""]
    if render.views_format == "STEREO_3D":
        names = [v.name for v in render.views if v.use and v.name in ("left", "right")]
    else:
        names = [v.name for v in render.views if v.use]
    return names or [""]


def write_passes(engine, passes: dict, width: int, height: int, layer_name: str = "",
                 region: tuple | None = None, views=("",)) -> list[str]:
    """Copy core passes ((H, W, C) float32, row 0 = top) into new render results.

    Parameters
    ----------
    passes : name -> (height, width, C) image of the full frame.
    width, height : full frame size in pixels.
    region : (x, y, w, h) from :func:`border_region` (y from the bottom) or None:
        Blender's result of a Render Region render is region-sized, so only the
        region's pixels are written, at offset (0, 0) of that result.
    views : view names to fill (multiview / stereo): each gets the same image.

    Returns the pass names written.  Blender stores rows bottom-up, so each
    image is flipped vertically, cut to the region, flattened and handed over
    with one ``foreach_set``.
    """
    x0, y0, w, h = region if region is not None else (0, 0, width, height)
    images = {}
    for name, _channels, _ids in _core.passes_table(denoise=True, adaptive=True):   # every pass the result holds
        img = passes.get(name)
        if img is not None:
            img = np.asarray(img, dtype=np.float32).reshape(height, width, -1)[::-1]  # bottom-up
            images[name] = img[y0:y0 + h, x0:x0 + w]
    written = []
    for view in views:
        result = engine.begin_result(0, 0, w, h, layer=layer_name, view=view)
        try:
            layer = result.layers[0]  # begin_result(layer=...) holds just the view layer being rendered
            for name, img in images.items():
                bpass = layer.passes.find_by_name(name, view) if hasattr(layer.passes, "find_by_name") else None
                if bpass is None:
                    bpass = layer.passes.get(name)
                if bpass is None:
                    continue
                if img.shape[2] != bpass.channels:  # e.g. Combined given as RGB: add alpha 1
                    fixed = np.ones((h, w, bpass.channels), dtype=np.float32)
                    c = min(img.shape[2], bpass.channels)
                    fixed[..., :c] = img[..., :c]
                    img = fixed
                rh, rw = result.resolution_y, result.resolution_x
                if (rh, rw) != (h, w):  # Blender disagrees on the size: fill what overlaps, never raise
                    out = np.zeros((rh, rw, bpass.channels), dtype=np.float32)
                    out[:min(rh, h), :min(rw, w)] = img[:min(rh, h), :min(rw, w)]
                    img = out
                bpass.rect.foreach_set(np.ascontiguousarray(img).reshape(-1))
                if name not in written:
                    written.append(name)
        finally:
            engine.end_result(result)
    return written


class STPMRenderEngine(bpy.types.RenderEngine):
    """Time-dependent photon mapping (Cammarano & Jensen 2002).

    One instance per render: F12, each material / world preview, and each 3D view in Rendered
    mode get their own, and share nothing (the viewport's state lives in the instance's
    :class:`addon.viewport.ViewportSession`).
    """

    bl_idname = "STPM"
    bl_label = "STPM Photon Mapper"
    bl_use_preview = True            # material / world / light previews: addon/preview.py
    bl_use_postprocess = True        # compositor and sequencer run after us
    bl_use_shading_nodes_custom = False  # Blender's own shader nodes (Cycles' node editor)
    bl_use_eevee_viewport = True     # Material preview in the viewport uses EEVEE

    # Render passes: the one table
    def update_render_passes(self, scene=None, renderlayer=None):
        props = getattr(scene, "stpm", None)
        denoise = bool(getattr(props, "denoise", False))
        adaptive = bool(getattr(props, "use_adaptive_sampling", False))
        for name, channels, ids in _core.passes_table(denoise, adaptive):
            self.register_pass(scene, renderlayer, name, channels, ids, pass_type(ids))

    # Final render and previews
    def render(self, depsgraph):
        """Blender's entry point: :meth:`_render` (previews: :func:`addon.preview.render_preview`),
        with any unexpected exception turned into one ERROR line in the render report (the
        traceback goes to the console for bug reports)."""
        try:
            if self.is_preview:
                from . import preview
                preview.render_preview(self, depsgraph)
                return
            self._render(depsgraph)
        except Exception as exc:  # a bug or an unforeseen scene: never a raw traceback in the UI
            traceback.print_exc()
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            self.update_stats("STPM", "Failed")
            self.report({"ERROR"}, f"STPM: render failed ({type(exc).__name__}{': ' + first if first else ''}); "
                                   f"the traceback is in the console, please report it")

    def _render(self, depsgraph):
        scene = depsgraph.scene
        self.stpm_warnings = []
        self.stpm_stats = {}
        t0 = time.perf_counter()
        try:
            self.update_stats("STPM", "Exporting scene")
            settings = settings_from_scene(scene)
            stpm_scene, warnings = export_scene(
                depsgraph, lambda f, sub: self.frame_set(f, subframe=sub),
                motion_steps=scene.stpm.motion_steps)
            export_s = time.perf_counter() - t0
            stpm_scene.metadata["warnings"] = list(warnings)     # the core does not repeat these
            missing = unsupported_passes(depsgraph.view_layer, denoise=settings.denoise)
            if missing:
                warnings.append(f"view layer {depsgraph.view_layer.name!r}: passes STPM does not produce stay empty: "
                                f"{', '.join(missing)} (STPM writes "
                                f"{', '.join(n for n, _c, _i in _core.passes_table())})")
            denoise_problem = compositor_problem(scene)      # denoise on, but no STPM Denoise group to run
            if denoise_problem:
                warnings.append(denoise_problem)
            if settings.method == "PROGRESSIVE" and settings.pass_offset > 0:
                warnings.append(f"Pass Offset {settings.pass_offset}: this image holds passes "
                                f"{settings.pass_offset + 1} on only, and is not a partial result stpm merge "
                                "joins (a farm writes those with stpm render --pass-offset; docs/cli.md)")
            for w in warnings:
                self.report({"WARNING"}, w)
            if self.cancel_requested():
                return
            render = _core.render_function()
            # Blender's "Persistent Data" (Render > Performance): keep the baked static geometry
            # between frames while it does not change; off frees it
            _core.sub("raycast").set_persistent_static(bool(scene.render.use_persistent_data))
            width, height = stpm_scene.resolution
            region = border_region(scene.render, width, height)
            views = result_views(scene.render)

            def show_pass(passes, info):
                # Progressive: the image so far into the render result after each pass (Blender redraws it)
                write_passes(self, passes, width, height, depsgraph.view_layer.name, region=region, views=views)
                noise = info.get("noise_p95")
                self.update_stats("STPM", f"Pass {info['pass']}, {info['elapsed_s']:.1f} s"
                                  + (f", noise {noise:.3f}" if noise is not None and noise < 1e30 else ""))

            result = render(stpm_scene, settings, progress=self._progress, cancel=self.cancel_requested,
                            on_pass=show_pass if settings.method == "PROGRESSIVE" else None,
                            window=region_window(region, height))
        except _core.RenderCancelled:
            self.update_stats("STPM", "Cancelled")
            return
        except _core.StpmError as exc:
            self.report({"ERROR"}, f"STPM: {exc}")
            return
        except ImportError as exc:
            self.report({"ERROR"}, f"STPM: the renderer could not be loaded ({exc})")
            return
        # Results, warnings and statistics
        for w in getattr(result, "warnings", []):
            self.report({"WARNING"}, w)
        # The effects plan: render report, EXR metadata, and the scene (for the Effects panel)
        plan = dict(getattr(result, "plan", {}) or {})
        meta = {}
        if plan:
            summary = _core.sub("plan").plan_summary(plan)
            self.report({"INFO"}, f"STPM plan: {summary}")
            meta = {"STPM Plan": json.dumps(plan), "STPM Plan Summary": summary}
            store_plan(scene, plan)
        prog = (getattr(result, "stats", {}) or {}).get("progressive")
        if prog:
            self.report({"INFO"}, "STPM progressive: " + _core.sub("progressive").summary(prog))
        adaptive = (getattr(result, "stats", {}) or {}).get("adaptive")
        if adaptive:
            # adaptive sampling (Sampling > Noise Threshold): the samples the pixels took
            self.report({"INFO"}, f"STPM adaptive sampling: {adaptive['samples_mean']:.1f} samples per pixel on "
                                  f"average ({adaptive['samples_min']}-{adaptive['samples_max']})")
        if len(views) > 1:
            text = (f"stereoscopy / multiview is not supported: every view ({', '.join(views)}) gets the same "
                    f"mono image from the scene camera")
            self.report({"WARNING"}, text)
            warnings = list(warnings) + [text]
        written = write_passes(self, result.passes, width, height, depsgraph.view_layer.name,
                               region=region, views=views)
        add_metadata(self, meta)
        stats = dict(getattr(result, "stats", {}) or {})
        stats["export_s"] = export_s
        stats["wall_s"] = time.perf_counter() - t0
        self.stpm_warnings = list(warnings) + list(getattr(result, "warnings", []))
        self.stpm_stats = stats
        LAST_RENDER.clear()
        LAST_RENDER.update(stats=stats, warnings=list(self.stpm_warnings), passes=written, scene=stpm_scene, plan=plan)
        mean_spp = f", {adaptive['samples_mean']:.1f} samples per pixel" if adaptive else ""
        self.update_stats("STPM", f"Done in {stats['wall_s']:.1f} s (export {export_s:.2f} s{mean_spp})")

    # Rendered viewport: addon/viewport.py does the work (ViewportSession), these only delegate
    def view_update(self, context, depsgraph):
        """Blender's viewport sync (Rendered mode turned on, an edit): export what changed, restart."""
        from . import viewport
        viewport.view_update(self, context, depsgraph)

    def view_draw(self, context, depsgraph):
        """Draw the newest image; a moved or resized view, or changed settings, restart without export."""
        from . import viewport
        viewport.view_draw(self, context, depsgraph)

    def __del__(self):
        """Blender frees this engine (a view left Rendered mode): stop its viewport thread."""
        try:
            if "stpm_viewport" in self.__dict__:
                from . import viewport
                viewport.stop_engine_session(self)
        except (ReferenceError, ImportError):       # freed RNA, or the interpreter is shutting down
            pass

    def cancel_requested(self) -> bool:
        """Has the user cancelled (Esc)?  Blender's ``test_break``, polled by the core about every second."""
        return bool(self.test_break())

    def _progress(self, fraction: float, message: str = "") -> None:
        """Core progress callback -> Blender's progress bar and status text."""
        self.update_progress(float(min(max(fraction, 0.0), 1.0)))
        if message:
            self.update_stats("STPM", message)


def add_metadata(engine, metadata: dict) -> None:
    """name -> str into the final render result's stamp data (Blender writes it into EXR headers)."""
    full = engine.get_result() if metadata else None
    if full is None or not hasattr(full, "stamp_data_add_field"):
        return
    for key, value in metadata.items():
        full.stamp_data_add_field(key, value)


def store_plan(scene, plan: dict) -> None:
    """Keep the plan on the (original) scene as JSON in ``scene["stpm_plan"]`` for the Effects panel."""
    target = getattr(scene, "original", scene) or scene
    try:
        target["stpm_plan"] = json.dumps(plan)
    except (AttributeError, RuntimeError, TypeError):  # read-only while rendering in some contexts
        pass


def _compatible_panels():
    """Blender's own panels that make sense with STPM (dimensions, output, materials...)."""
    panels = []
    for name in ("RENDER_PT_format", "RENDER_PT_frame_range", "RENDER_PT_output", "RENDER_PT_color_management",
                 "DATA_PT_camera", "DATA_PT_lens", "DATA_PT_camera_display", "DATA_PT_context_light",
                 "DATA_PT_light", "DATA_PT_EEVEE_light", "MATERIAL_PT_preview", "EEVEE_MATERIAL_PT_context_material",
                 "EEVEE_MATERIAL_PT_surface", "EEVEE_WORLD_PT_surface", "WORLD_PT_context_world",
                 "CYCLES_LIGHT_PT_light", "CYCLES_MATERIAL_PT_surface", "CYCLES_WORLD_PT_surface",
                 "CYCLES_CAMERA_PT_dof", "VIEWLAYER_PT_layer_passes",
                 "CYCLES_WORLD_PT_preview", "CYCLES_LIGHT_PT_preview"):   # world / light previews (bl_use_preview)
        panel = getattr(bpy.types, name, None)
        if panel is not None and hasattr(panel, "COMPAT_ENGINES"):
            panels.append(panel)
    return panels


def register() -> None:
    bpy.utils.register_class(STPMRenderEngine)
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.add("STPM")


def unregister() -> None:
    for panel in _compatible_panels():
        panel.COMPAT_ENGINES.discard("STPM")
    bpy.utils.unregister_class(STPMRenderEngine)
