"""Registration, ``scene.stpm`` defaults, presets and panels."""
from __future__ import annotations

import dataclasses

import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import fresh  # noqa: E402

import addon  # noqa: E402
from addon.presets import PRESETS  # noqa: E402
from addon.properties import SETTING_NAMES, settings_from_scene  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402


def test_scene_settings_default_to_the_core_defaults():
    scene = fresh()
    core_defaults = RenderSettings()
    assert set(SETTING_NAMES) == {f.name for f in dataclasses.fields(RenderSettings)}
    for name in SETTING_NAMES:
        assert getattr(scene.stpm, name) == pytest.approx(getattr(core_defaults, name)), name
    assert settings_from_scene(scene) == core_defaults


def test_presets_apply_and_make_valid_settings():
    scene = fresh()
    for name, values in PRESETS.items():
        assert bpy.ops.stpm.apply_preset(preset=name) == {"FINISHED"}
        for key, value in values.items():
            assert getattr(scene.stpm, key) == pytest.approx(value, rel=1e-6)   # float properties are float32
        settings_from_scene(scene)  # raises on an impossible value
    assert PRESETS["FINAL"]["samples"] > PRESETS["PREVIEW"]["samples"]


def test_engine_and_panels_register_and_unregister():
    fresh()
    panels = ["STPM_RENDER_PT_sampling", "STPM_RENDER_PT_photons", "STPM_RENDER_PT_method",
              "STPM_RENDER_PT_motion_blur", "STPM_RENDER_PT_effects"]
    for name in panels:
        panel = getattr(bpy.types, name)
        assert panel.bl_context == "render" and "STPM" in panel.COMPAT_ENGINES
    engine = bpy.types.RenderEngine.bl_rna_get_subclass_py("STPM")
    assert engine.bl_label == "STPM Photon Mapper" and engine.bl_use_postprocess
    assert engine.bl_use_preview                           # material / world previews (addon/preview.py)
    assert {"view_update", "view_draw"} <= set(vars(engine))           # the rendered viewport
    addon.unregister()
    assert not hasattr(bpy.types.Scene, "stpm") and not hasattr(bpy.types, "STPM_RENDER_PT_sampling")
    addon.register()
    bpy.context.scene.render.engine = "STPM"
    assert bpy.context.scene.stpm.estimator == "TEMPORAL"


class _RecordingLayout:
    """Stands in for a UILayout: records every property and operator a panel draws."""

    def __init__(self, log):
        self.log = log

    def column(self, **_):
        return self

    box = row = column

    def prop(self, data, name, **_):
        assert hasattr(data, name), name                     # the property exists on that data
        self.log.append(name)

    def operator(self, idname, **_):
        self.log.append(idname)

    def template_curve_mapping(self, data, name, **_):
        assert hasattr(data, name), name
        self.log.append(name)

    def label(self, **_):
        pass

    def separator(self, **_):
        pass


def test_panels_draw_every_setting():
    """Each panel's draw runs against the real scene.stpm and scene.render (no UI in background
    mode, so a recording layout stands in) and together they show every setting of the sidebar."""
    from types import SimpleNamespace
    from addon import ui
    scene = fresh()
    context = SimpleNamespace(scene=scene, engine="STPM")
    drawn = {}
    for name in ("STPM_RENDER_PT_sampling", "STPM_RENDER_PT_photons", "STPM_RENDER_PT_method",
                 "STPM_RENDER_PT_motion_blur", "STPM_RENDER_PT_effects"):
        cls = getattr(ui, name)
        log = []
        panel = type("Drawn", (ui._STPMPanel,), {"PROPS": cls.PROPS})()
        panel.layout = _RecordingLayout(log)
        cls.draw(panel, context)
        drawn[name] = log
    assert drawn["STPM_RENDER_PT_sampling"] == ["samples", "seed", "max_depth", "diffuse_bounces", "glossy_bounces",
                                                "transmission_bounces", "transparent_max_bounces", "rough_splits",
                                                "filter_width",
                                                "threads", "clamp_direct", "clamp_indirect"]
    assert drawn["STPM_RENDER_PT_photons"] == ["photons_global", "photons_caustic", "k_nearest", "kernel",
                                               "final_gather_samples", "photon_guiding"]
    assert {"method", "estimator", "temporal_alpha", "time_scale", "stpm.compare"} <= set(drawn["STPM_RENDER_PT_method"])
    assert {"motion_blur_position", "motion_steps", "motion_blur_shutter_curve"} <= set(drawn["STPM_RENDER_PT_motion_blur"])
    assert {"effects", "caustics", "indirect"} <= set(drawn["STPM_RENDER_PT_effects"])
    # the progressive method's own settings appear with it
    scene.stpm.method = "PROGRESSIVE"
    log = []
    panel = type("Drawn", (ui._STPMPanel,), {})()
    panel.layout = _RecordingLayout(log)
    ui.STPM_RENDER_PT_method.draw(panel, context)
    assert {"passes", "time_limit", "noise_threshold", "shrink_alpha", "pass_offset"} <= set(log)
    drawn["progressive"] = log
    log = []                                        # Denoising: the toggle in its header (as Cycles)
    panel = type("Drawn", (ui._STPMPanel,), {})()
    panel.layout = _RecordingLayout(log)
    ui.STPM_RENDER_PT_denoising.draw_header(panel, context)
    ui.STPM_RENDER_PT_denoising.draw(panel, context)
    drawn["STPM_RENDER_PT_denoising"] = log
    assert log == ["denoise"]
    log = []                                        # Sampling > Viewport: the rendered viewport's stops
    panel = type("Drawn", (ui._STPMPanel,), {})()
    panel.layout = _RecordingLayout(log)
    ui.STPM_RENDER_PT_sampling_viewport.draw(panel, context)
    assert log == ["preview_passes", "preview_time_limit"]
    assert ui.STPM_RENDER_PT_sampling_viewport.bl_parent_id == "STPM_RENDER_PT_sampling"
    log = []                                        # Sampling > Noise Threshold: the toggle in its header
    panel = type("Drawn", (ui._STPMPanel,), {})()
    panel.layout = _RecordingLayout(log)
    ui.STPM_RENDER_PT_sampling_adaptive.draw_header(panel, context)
    ui.STPM_RENDER_PT_sampling_adaptive.draw(panel, context)
    assert log == ["use_adaptive_sampling", "adaptive_threshold", "samples", "adaptive_min_samples"]
    assert ui.STPM_RENDER_PT_sampling_adaptive.bl_parent_id == "STPM_RENDER_PT_sampling"
    drawn["STPM_RENDER_PT_sampling_adaptive"] = log
    scene.stpm.method = "ACCUMULATION"
    shown = {n for log in drawn.values() for n in log} | {"accumulation_steps"}
    assert set(SETTING_NAMES) - shown == set(), set(SETTING_NAMES) - shown
    log = []
    panel = type("Drawn", (ui._STPMPanel,), {})()
    panel.layout = _RecordingLayout(log)
    ui.STPM_RENDER_PT_method.draw(panel, context)
    assert "accumulation_steps" in log


def test_object_panel_shows_the_shadow_terminator_settings():
    """Object > Shadow Terminator (STPM only): Blender's object settings the renderer reads
    (docs/rendering.md, "Shadow terminator"), for geometry objects only."""
    from types import SimpleNamespace
    from addon import ui
    fresh()
    bpy.ops.mesh.primitive_uv_sphere_add()
    obj = bpy.context.object
    cls = ui.STPM_OBJECT_PT_shadow_terminator
    assert cls.poll(SimpleNamespace(engine="STPM", object=obj))
    assert not cls.poll(SimpleNamespace(engine="CYCLES", object=obj))
    assert not cls.poll(SimpleNamespace(engine="STPM", object=bpy.context.scene.camera))
    log = []
    panel = SimpleNamespace(layout=SimpleNamespace(column=lambda **_: _RecordingLayout(log)))
    cls.draw(panel, SimpleNamespace(object=obj))
    assert log == ["shadow_terminator_geometry_offset", "shadow_terminator_shading_offset"]
