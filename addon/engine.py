"""The STPM RenderEngine: export -> ``stpm_core.render.render`` -> Blender passes.

No rendering maths here.  Passes come from the one table
(``stpm_core.render.PASSES``): :meth:`STPMRenderEngine.update_render_passes`
declares them, :func:`write_passes` fills them, so Blender's own outputs (File
Output, multilayer EXR, compositor) see every pass.
"""
from __future__ import annotations

import json
import time

import bpy
import numpy as np

from . import _core
from .export import export_scene
from .properties import settings_from_scene

# Statistics, warnings and pass names of the last finished render (scripts, tests, batch)
LAST_RENDER: dict = {}

# Blender's pass type for each channel-id string of the table
_PASS_TYPE = {"RGBA": "COLOR", "RGB": "COLOR", "XYZ": "VECTOR", "Z": "VALUE"}


def pass_type(channel_ids: str) -> str:
    """Blender pass type ('COLOR' / 'VECTOR' / 'VALUE') for channel ids like 'RGBA'."""
    return _PASS_TYPE.get(channel_ids, "VALUE" if len(channel_ids) == 1 else "COLOR")


def write_passes(engine, passes: dict, width: int, height: int, layer_name: str = "") -> list[str]:
    """Copy core passes ((H, W, C) float32, row 0 = top) into a new render result.

    Returns the names written.  Blender stores rows bottom-up, so each image is
    flipped vertically, flattened and handed over with one ``foreach_set``.
    """
    result = engine.begin_result(0, 0, width, height, layer=layer_name)
    written = []
    try:
        layer = result.layers[0]  # begin_result(layer=...) holds just the view layer being rendered
        for name, channels, _ids in _core.passes_table():
            img = passes.get(name)
            bpass = layer.passes.find_by_name(name, "") if hasattr(layer.passes, "find_by_name") else None
            if bpass is None:
                bpass = layer.passes.get(name)
            if img is None or bpass is None:
                continue
            img = np.asarray(img, dtype=np.float32).reshape(height, width, -1)
            if img.shape[2] != bpass.channels:  # e.g. Combined given as RGB: add alpha 1
                fixed = np.ones((height, width, bpass.channels), dtype=np.float32)
                c = min(img.shape[2], bpass.channels)
                fixed[..., :c] = img[..., :c]
                img = fixed
            bpass.rect.foreach_set(np.ascontiguousarray(img[::-1]).reshape(-1))
            written.append(name)
    finally:
        engine.end_result(result)
    return written


class STPMRenderEngine(bpy.types.RenderEngine):
    """Time-dependent photon mapping (Cammarano & Jensen 2002)."""

    bl_idname = "STPM"
    bl_label = "STPM Photon Mapper"
    bl_use_preview = False
    bl_use_postprocess = True        # compositor and sequencer run after us
    bl_use_shading_nodes_custom = False  # Blender's own shader nodes (Cycles' node editor)
    bl_use_eevee_viewport = True     # Material preview in the viewport uses EEVEE

    # Render passes: the one table
    def update_render_passes(self, scene=None, renderlayer=None):
        for name, channels, ids in _core.passes_table():
            self.register_pass(scene, renderlayer, name, channels, ids, pass_type(ids))

    # Final render
    def render(self, depsgraph):
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
            for w in warnings:
                self.report({"WARNING"}, w)
            if self.cancel_requested():
                return
            render = _core.render_function()
            # Blender's "Persistent Data" (Render > Performance): keep the baked static geometry
            # between frames while it does not change; off frees it
            _core.sub("raycast").set_persistent_static(bool(scene.render.use_persistent_data))
            result = render(stpm_scene, settings, progress=self._progress, cancel=self.cancel_requested)
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
        w, h = stpm_scene.resolution
        written = write_passes(self, result.passes, w, h, depsgraph.view_layer.name)
        add_metadata(self, meta)
        stats = dict(getattr(result, "stats", {}) or {})
        stats["export_s"] = export_s
        stats["wall_s"] = time.perf_counter() - t0
        self.stpm_warnings = list(warnings) + list(getattr(result, "warnings", []))
        self.stpm_stats = stats
        LAST_RENDER.clear()
        LAST_RENDER.update(stats=stats, warnings=list(self.stpm_warnings), passes=written, scene=stpm_scene, plan=plan)
        self.update_stats("STPM", f"Done in {stats['wall_s']:.1f} s (export {export_s:.2f} s)")

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
                 "CYCLES_CAMERA_PT_dof", "VIEWLAYER_PT_layer_passes"):
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
