"""``scene.stpm``: the STPM render settings stored in the .blend.

Names and meanings are fixed by ``shared/interface.md`` and mirror
:class:`stpm_core.settings.RenderSettings` one to one (plus ``motion_steps``,
an export setting).  :func:`settings_from_scene` turns them into the core's
settings object.
"""
from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

# Everything RenderSettings knows, read straight from the property group.
SETTING_NAMES = (
    "method", "estimator", "accumulation_steps", "samples", "photons_global",
    "photons_caustic", "k_nearest", "temporal_alpha", "time_scale", "seed",
    "effects", "caustics", "indirect", "kernel", "max_depth", "filter_width", "threads",
    "clamp_direct", "clamp_indirect", "glossy_bounces", "transmission_bounces",
    "passes", "time_limit", "noise_threshold", "shrink_alpha", "pass_offset",
)


class STPM_SceneSettings(bpy.types.PropertyGroup):
    """Render settings of one scene (``scene.stpm``)."""

    # Method and estimator
    method: EnumProperty(
        name="Method", default="PHOTON",
        items=(("PHOTON", "Time-Dependent Photons", "Time-stamped photon maps: one photon pass for the whole shutter"),
               ("ACCUMULATION", "Accumulation Buffer", "Average of complete stills at instants across the shutter (baseline)"),
               ("PROGRESSIVE", "Progressive", "Passes whose space-time kernel shrinks: the image improves pass by pass "
                "and converges; stop at a pass count, a time limit or a noise threshold")))
    estimator: EnumProperty(
        name="Estimator", default="TEMPORAL",
        items=(("STANDARD", "Standard", "k nearest photons in space, time ignored (wrong on moving receivers)"),
               ("TEMPORAL", "Temporal", "3D kd-tree, then the candidates nearest in time"),
               ("KD4D", "4D kd-tree", "One kd-tree over space and scaled time")))
    accumulation_steps: IntProperty(
        name="Accumulation Steps", default=8, min=1, soft_max=64, max=4096,
        description="Instants averaged by the accumulation buffer; each costs about one still")
    temporal_alpha: FloatProperty(
        name="Temporal Alpha", default=0.0, min=0.0, soft_max=10.0,
        description="Temporal candidates per estimate as a multiple of k; 0 = automatic and consistent, 1.5 = the paper's")
    time_scale: FloatProperty(
        name="Time Scale", default=0.0, min=0.0, soft_max=100.0,
        description="KD4D's s in scene units per shutter; 0 = automatic from the scene's motion")
    # Progressive: when to stop, how fast the kernel shrinks
    passes: IntProperty(
        name="Passes", default=16, min=0, soft_max=1024, max=1 << 24,
        description="Progressive: stop after this many passes (0 = no pass limit); each pass traces the photon "
                    "counts and the samples per pixel set here")
    time_limit: FloatProperty(
        name="Time Limit", default=0.0, min=0.0, soft_max=3600.0, max=1e9, subtype="TIME_ABSOLUTE",
        description="Progressive: stop after this many seconds of rendering (0 = none), as Cycles")
    noise_threshold: FloatProperty(
        name="Noise Threshold", default=0.0, min=0.0, soft_max=0.2, max=1e6, precision=4,
        description="Progressive: stop when the estimated relative error per pixel (95th percentile over 8x8 "
                    "blocks, from the odd and even passes) is below it (0 = none), as Cycles")
    shrink_alpha: FloatProperty(
        name="Shrink Alpha", default=0.0, min=0.0, max=0.999, precision=3,
        description="Progressive: the kernel's measure shrinks by (i + a) / (i + 1) per pass; smaller shrinks "
                    "faster (0 = automatic)")
    pass_offset: IntProperty(
        name="Pass Offset", default=0, min=0, max=1 << 24,
        description="Progressive: index of the first pass (a farm splits one frame's passes between machines)")
    kernel: EnumProperty(
        name="Kernel", default="BOX",
        items=(("BOX", "Box", "Constant density-estimation kernel"),
               ("CONE", "Cone", "Cone filter: sharper caustics, a little more noise")))

    # Sampling
    samples: IntProperty(
        name="Samples", default=16, min=1, soft_max=1024, max=1 << 16,
        description="Camera samples per pixel, each at its own time in the shutter")
    seed: IntProperty(name="Seed", default=0, min=0, description="All randomness derives from it: same seed, same image")
    max_depth: IntProperty(name="Max Depth", default=8, min=1, max=1024,
                           description="Longest specular chain followed from the camera, and photon bounces")
    filter_width: FloatProperty(name="Filter Width", default=1.5, min=0.0, max=64.0, subtype="PIXEL",
                                description="Blackman-Harris pixel filter width (Blender's default 1.5 px)")
    threads: IntProperty(name="Threads", default=0, min=0, max=1024,
                         description="Worker threads for ray casting and look-ups (0 = all cores)")
    glossy_bounces: IntProperty(
        name="Glossy Bounces", default=4, min=0, max=1024,
        description="As Cycles: reflections (mirror or rough) a camera path goes on through, within Max Depth")
    transmission_bounces: IntProperty(
        name="Transmission Bounces", default=12, min=0, max=1024,
        description="As Cycles: refractions a camera path goes on through, within Max Depth")
    clamp_direct: FloatProperty(
        name="Clamp Direct", default=0.0, min=0.0, soft_max=100.0, max=1e30,
        description="As Cycles: the largest channel of one contribution at the camera's first hit is "
                    "scaled down to this value (0 = off; clamping removes fireflies and energy)")
    clamp_indirect: FloatProperty(
        name="Clamp Indirect", default=0.0, min=0.0, soft_max=100.0, max=1e30,
        description="As Cycles: the same after a bounce and for photon-map light (0 = off)")

    # Photons
    photons_global: IntProperty(
        name="Global Photons", default=200_000, min=0, soft_max=10_000_000, max=2**31 - 1,
        description="Photons emitted for the global (indirect) map")
    photons_caustic: IntProperty(
        name="Caustic Photons", default=200_000, min=0, soft_max=10_000_000, max=2**31 - 1,
        description="Caustic photons, emitted toward the specular objects")
    k_nearest: IntProperty(name="Nearest Photons", default=50, min=1, soft_max=500, max=100_000,
                           description="Photons per radiance estimate (k)")

    # Effects
    effects: EnumProperty(
        name="Effects", default="AUTO",
        items=(("AUTO", "Automatic", "Simulate only what the scene calls for (see stpm plan)"),
               ("MANUAL", "Manual", "Choose caustics and indirect light yourself")))
    caustics: BoolProperty(name="Caustics", default=True, description="Build the caustic photon map (Manual effects)")
    indirect: BoolProperty(name="Indirect", default=True, description="Build the global photon map (Manual effects)")

    # Motion export
    motion_steps: IntProperty(
        name="Motion Steps", default=3, min=2, max=65,
        description="Times across the shutter at which moving objects, lights and the camera are sampled "
                    "(an object's own Cycles motion steps win when larger)")

    # Baking what the node interpreter cannot evaluate (addon/export/bake.py)
    bake_resolution: IntProperty(
        name="Bake Resolution", default=512, min=16, soft_max=4096, max=16384, subtype="PIXEL",
        description="Width and height of the texture each unsupported shader input is baked to "
                    "(Bake Unsupported Inputs, stpm render)")

    @classmethod
    def register(cls) -> None:
        bpy.types.Scene.stpm = PointerProperty(type=cls, name="STPM", description="STPM render settings")

    @classmethod
    def unregister(cls) -> None:
        del bpy.types.Scene.stpm


def settings_dict(props) -> dict:
    """``scene.stpm`` -> plain dict of RenderSettings fields."""
    return {name: getattr(props, name) for name in SETTING_NAMES}


def settings_from_scene(scene):
    """The core's :class:`RenderSettings` for ``scene`` (raises SettingsError on bad values)."""
    from ._core import RenderSettings
    return RenderSettings.from_dict(settings_dict(scene.stpm))


classes = (STPM_SceneSettings,)


# Blender's helper: register in order, unregister in reverse
register, unregister = bpy.utils.register_classes_factory(classes)
