"""Render-properties panels (``STPM_RENDER_PT_*``), the preset operator/menu and the effects-plan operator."""
from __future__ import annotations

import json

import bpy
from bpy.props import EnumProperty

from .presets import PRESET_ITEMS, apply_preset


class STPM_OT_apply_preset(bpy.types.Operator):
    """Set the STPM render settings from a preset"""

    bl_idname = "stpm.apply_preset"
    bl_label = "Apply STPM Preset"
    bl_options = {"REGISTER", "UNDO"}

    preset: EnumProperty(name="Preset", items=PRESET_ITEMS, default="PREVIEW")

    def execute(self, context):
        apply_preset(context.scene.stpm, self.preset)
        return {"FINISHED"}


class STPM_MT_presets(bpy.types.Menu):
    bl_idname = "STPM_MT_presets"
    bl_label = "STPM Presets"

    def draw(self, context):
        for ident, label, _desc in PRESET_ITEMS:
            self.layout.operator(STPM_OT_apply_preset.bl_idname, text=label).preset = ident


def scene_plan(scene) -> dict | None:
    """The effects plan stored on the scene (``scene["stpm_plan"]``, JSON) or None."""
    text = scene.get("stpm_plan") if hasattr(scene, "get") else None
    if not text:
        return None
    try:
        return json.loads(text)
    except (TypeError, ValueError):
        return None


class STPM_OT_compute_plan(bpy.types.Operator):
    """Work out which effects this frame calls for (motion blur, caustics, indirect light), as STPM will render it"""

    bl_idname = "stpm.compute_plan"
    bl_label = "Compute Effects Plan"
    bl_options = {"REGISTER"}

    def execute(self, context):
        from . import _core
        from .batch import export_current
        from .engine import store_plan
        from .properties import settings_from_scene
        scene = context.scene
        try:  # the same export as the compare operator: render visibility, F12's objects
            settings = settings_from_scene(scene)
            stpm_scene, _settings = export_current(scene)
            plan = _core.sub("plan").make_plan(stpm_scene, settings)
        except _core.StpmError as exc:
            self.report({"ERROR"}, f"STPM: {exc}")
            return {"CANCELLED"}
        store_plan(scene, plan)
        self.report({"INFO"}, "STPM plan: " + _core.sub("plan").plan_summary(plan))
        return {"FINISHED"}


class _STPMPanel:
    """Mixin: Render properties, shown only while STPM is the engine."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {"STPM"}

    # Properties of scene.stpm drawn one per row by the default draw (panels with more set PROPS = ())
    PROPS: tuple = ()

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def _column(self):
        """A column of the panel's layout with Blender's property-split style."""
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        return layout.column()

    def draw(self, context):
        col = self._column()
        for name in self.PROPS:
            col.prop(context.scene.stpm, name)


class STPM_RENDER_PT_sampling(_STPMPanel, bpy.types.Panel):
    bl_label = "Sampling"
    PROPS = ("samples", "seed", "max_depth", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
             "transparent_max_bounces", "rough_splits", "filter_width", "threads", "clamp_direct", "clamp_indirect")

    def draw_header_preset(self, context):
        self.layout.menu(STPM_MT_presets.bl_idname, text="", icon="PRESET")


class STPM_RENDER_PT_sampling_viewport(_STPMPanel, bpy.types.Panel):
    """The rendered viewport's stops (as Cycles' Sampling > Viewport)."""

    bl_label = "Viewport"
    bl_parent_id = "STPM_RENDER_PT_sampling"

    def draw(self, context):
        col = self._column()
        col.prop(context.scene.stpm, "preview_passes", text="Passes")
        col.prop(context.scene.stpm, "preview_time_limit", text="Time Limit")


class STPM_RENDER_PT_sampling_adaptive(_STPMPanel, bpy.types.Panel):
    """Adaptive sampling (as Cycles' Sampling > Render > Noise Threshold): method PHOTON gives more
    samples, up to Samples, to the pixels whose estimated error is above the threshold."""

    bl_label = "Noise Threshold"
    bl_parent_id = "STPM_RENDER_PT_sampling"

    def draw_header(self, context):
        self.layout.prop(context.scene.stpm, "use_adaptive_sampling", text="")

    def draw(self, context):
        props = context.scene.stpm
        col = self._column()
        col.active = props.use_adaptive_sampling and props.method == "PHOTON"
        col.prop(props, "adaptive_threshold", text="Noise Threshold")
        col.prop(props, "samples", text="Max Samples")
        col.prop(props, "adaptive_min_samples", text="Min Samples")
        if props.method != "PHOTON":
            col.label(text="Method Photon only (Progressive: Estimator & Method > Noise Threshold)", icon="INFO")


class STPM_RENDER_PT_photons(_STPMPanel, bpy.types.Panel):
    bl_label = "Photons"
    PROPS = ("photons_global", "photons_caustic", "k_nearest", "kernel", "final_gather_samples", "photon_guiding")


class STPM_RENDER_PT_method(_STPMPanel, bpy.types.Panel):
    bl_label = "Estimator & Method"

    def draw(self, context):
        props = context.scene.stpm
        layout = self.layout
        col = self._column()
        col.prop(props, "method")
        if props.method == "ACCUMULATION":
            col.prop(props, "accumulation_steps")
        if props.method == "PROGRESSIVE":
            sub = col.column(align=True)
            sub.prop(props, "passes")
            sub.prop(props, "time_limit")
            sub.prop(props, "noise_threshold")
            col.prop(props, "shrink_alpha")
            col.prop(props, "pass_offset")
        col.prop(props, "estimator")
        sub = col.column()
        sub.active = props.estimator == "TEMPORAL"
        sub.prop(props, "temporal_alpha")
        sub = col.column()
        sub.active = props.estimator == "KD4D"
        sub.prop(props, "time_scale")
        # What accuracy costs in time: the stpm compare report, written next to the .blend
        layout.operator("stpm.compare", icon="GRAPH")


class STPM_RENDER_PT_motion_blur(_STPMPanel, bpy.types.Panel):
    """Blender's own shutter settings: STPM follows them."""

    bl_label = "Motion Blur"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.render, "use_motion_blur", text="")

    def draw(self, context):
        rd = context.scene.render
        self.layout.active = rd.use_motion_blur
        col = self._column()
        col.prop(rd, "motion_blur_position", text="Position")
        col.prop(rd, "motion_blur_shutter")
        col.prop(context.scene.stpm, "motion_steps")
        col.separator()
        col.label(text="Shutter Curve")
        col.template_curve_mapping(rd, "motion_blur_shutter_curve")


class STPM_RENDER_PT_effects(_STPMPanel, bpy.types.Panel):
    bl_label = "Effects"

    def draw(self, context):
        props = context.scene.stpm
        layout = self.layout
        col = self._column()
        col.prop(props, "effects")
        sub = col.column()
        sub.active = props.effects == "MANUAL"
        sub.prop(props, "caustics")
        sub.prop(props, "indirect")
        # The plan: computed on demand, or by the last render
        layout.separator()
        layout.operator(STPM_OT_compute_plan.bl_idname, icon="FILE_REFRESH")
        plan = scene_plan(context.scene)
        if plan is None:
            layout.label(text="No plan yet: compute it or render", icon="INFO")
            return
        box = layout.box()
        col = box.column(align=True)
        for key, label in (("motion_blur", "Motion Blur"), ("caustics", "Caustics"), ("indirect", "Indirect"),
                           ("time_dependent", "Time Dependent")):
            col.label(text=label, icon="CHECKMARK" if plan.get(key) else "X")
        col.label(text=f"Estimator: {plan.get('estimator', '?')}")
        col = box.column(align=True)
        for reason in plan.get("reasons", []):
            col.label(text=reason)


class STPM_RENDER_PT_bake(_STPMPanel, bpy.types.Panel):
    """Cycles bakes of the shader inputs the node interpreter cannot evaluate (addon/export/bake.py)."""

    bl_label = "Baking"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        col = self._column()
        col.prop(context.scene.stpm, "bake_resolution")
        self.layout.operator("stpm.bake_inputs", icon="RENDER_STILL")


class STPM_RENDER_PT_denoising(_STPMPanel, bpy.types.Panel):
    """Denoise toggle (as Cycles' Sampling > Render > Denoise): the compositor's STPM Denoise group."""

    bl_label = "Denoising"
    bl_parent_id = "STPM_RENDER_PT_sampling"

    def draw_header(self, context):
        self.layout.prop(context.scene.stpm, "denoise", text="")

    def draw(self, context):
        layout = self.layout
        layout.active = context.scene.stpm.denoise
        col = layout.column(align=True)
        col.label(text="Compositor: Render Layers > STPM Denoise > output")
        col.label(text="Passes: Denoising Albedo, Denoising Normal, Noisy Image")


class STPM_OBJECT_PT_shadow_terminator(bpy.types.Panel):
    """Object > Shadow Terminator: Blender's own object settings Cycles reads (and STPM: docs/rendering.md,
    "Shadow terminator"), shown while STPM is the engine (Cycles' panel is for Cycles only)."""

    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "object"
    bl_label = "Shadow Terminator"
    bl_options = {"DEFAULT_CLOSED"}
    COMPAT_ENGINES = {"STPM"}

    @classmethod
    def poll(cls, context):
        obj = getattr(context, "object", None)
        return context.engine in cls.COMPAT_ENGINES and obj is not None and obj.type in {"MESH", "CURVE", "SURFACE",
                                                                                           "FONT", "META"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        col = layout.column()
        col.prop(context.object, "shadow_terminator_geometry_offset", text="Geometry Offset")
        col.prop(context.object, "shadow_terminator_shading_offset", text="Shading Offset")


class STPM_LIGHT_PT_photons(bpy.types.Panel):
    """Light properties: the portal flag (Cycles' ``light.cycles.is_portal``) and the photon budget
    (``light.stpm.photon_weight``)."""

    bl_label = "STPM"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "data"
    COMPAT_ENGINES = {"STPM"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and getattr(context, "light", None) is not None

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        light = context.light
        col = layout.column()
        cyc = getattr(light, "cycles", None)
        if light.type == "AREA" and cyc is not None and hasattr(cyc, "is_portal"):
            col.prop(cyc, "is_portal", text="Portal")
        sub = col.column()
        sub.active = not (light.type == "AREA" and bool(getattr(cyc, "is_portal", False)))
        sub.prop(light.stpm, "photon_weight")


class STPM_WORLD_PT_photons(bpy.types.Panel):
    """World properties: the world's photon budget (``world.stpm.photon_weight``)."""

    bl_label = "STPM"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "world"
    COMPAT_ENGINES = {"STPM"}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and getattr(context, "world", None) is not None

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        layout.column().prop(context.world.stpm, "photon_weight")


classes = (
    STPM_OT_apply_preset,
    STPM_OT_compute_plan,
    STPM_MT_presets,
    STPM_RENDER_PT_sampling,
    STPM_RENDER_PT_sampling_viewport,
    STPM_RENDER_PT_sampling_adaptive,
    STPM_RENDER_PT_photons,
    STPM_RENDER_PT_method,
    STPM_RENDER_PT_motion_blur,
    STPM_RENDER_PT_effects,
    STPM_RENDER_PT_bake,
    STPM_RENDER_PT_denoising,
    STPM_LIGHT_PT_photons,
    STPM_WORLD_PT_photons,
    STPM_OBJECT_PT_shadow_terminator,
)


# Blender's helper: register in order, unregister in reverse
register, unregister = bpy.utils.register_classes_factory(classes)
