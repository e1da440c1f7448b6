"""``scene.stpm``: the STPM render settings stored in the .blend.

Names and meanings are fixed by ``shared/interface.md``.  The render settings are not declared
here: one property per row of the core's schema (:data:`stpm_core.settings.RenderSettings.SPECS`,
:mod:`stpm_core.schema`) -- its label, default, min / max, enum items and description -- so the
add-on, the command line and the scene-file loader cannot disagree.  Declared here are only the
settings the core has no field for: export (``motion_steps``, ``bake_resolution``) and the
rendered viewport's stops (``preview_passes``, ``preview_time_limit``, as Cycles' viewport
samples: :func:`addon.viewport.viewport_settings` turns them into ``passes`` / ``time_limit``).
:func:`settings_from_scene` turns the properties into the core's settings object.
"""
from __future__ import annotations

import struct

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from ._core import RenderSettings

# Blender's IntProperty holds a signed 32-bit integer: wider schema ranges are narrowed to it
_INT32_MAX = 2**31 - 1


def _denoise_changed(props, context) -> None:
    """``denoise`` toggled: add or remove the compositor's STPM Denoise group (addon/denoise.py)."""
    from .denoise import sync_compositor
    sync_compositor(props.id_data)


# What the add-on does when a setting changes (the schema is the core's: it knows no bpy)
_UPDATES = {"denoise": _denoise_changed}


def _property(spec):
    """The bpy property of one schema row (:class:`stpm_core.schema.Spec`)."""
    kw = {"name": spec.label or spec.name.replace("_", " ").title(),
          "description": spec.doc[:1].upper() + spec.doc[1:]}
    kw.update(spec.ui)
    if spec.name in _UPDATES:
        kw["update"] = _UPDATES[spec.name]
    if spec.kind == "enum":
        return EnumProperty(items=spec.choices, default=spec.default, **kw)
    if spec.kind == "bool":
        return BoolProperty(default=spec.default, **kw)
    if spec.kind == "int":
        return IntProperty(default=spec.default, min=max(spec.lo, -_INT32_MAX), max=min(spec.hi, _INT32_MAX), **kw)
    if spec.kind == "float":
        # FloatProperty is single precision: an open upper bound (shrink_alpha < 1) becomes the
        # largest float32 below it
        hi = float(np.nextafter(np.float32(spec.hi), np.float32(-np.inf))) if spec.hi_open else spec.hi
        return FloatProperty(default=spec.default, min=spec.lo, max=hi, **kw)
    raise TypeError(f"setting {spec.name!r} of kind {spec.kind!r} has no Blender property")


# Everything RenderSettings knows, read straight from the property group.
SETTING_NAMES = tuple(spec.name for spec in RenderSettings.SPECS)


class STPM_SceneSettings(bpy.types.PropertyGroup):
    """Render settings of one scene (``scene.stpm``)."""

    # Render settings: one property per schema row (see the module docstring)
    __annotations__ = {spec.name: _property(spec) for spec in RenderSettings.SPECS}

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

    # The rendered viewport (addon/viewport.py): progressive passes until one of these stops it
    preview_passes: IntProperty(
        name="Viewport Passes", default=1024, min=0, soft_min=1, max=1 << 24,
        description="Progressive passes the rendered viewport renders (one camera sample per pixel each), "
                    "unlimited if 0")
    preview_time_limit: FloatProperty(
        name="Viewport Time Limit", default=0.0, min=0.0, max=1e9, soft_max=3600.0, subtype="TIME_ABSOLUTE",
        description="Seconds the rendered viewport renders after each change; 0 = no limit")

    @classmethod
    def register(cls) -> None:
        bpy.types.Scene.stpm = PointerProperty(type=cls, name="STPM", description="STPM render settings")

    @classmethod
    def unregister(cls) -> None:
        del bpy.types.Scene.stpm


_PHOTON_WEIGHT_DOC = ("Share of the photons relative to the other lights and the world (photons are split "
                      "in proportion to power times this weight; the image's expectation does not change, "
                      "only where the noise goes). 0: no photons (no indirect light from it)")


class STPM_LightSettings(bpy.types.PropertyGroup):
    """STPM settings of one light (``light.stpm``)."""

    photon_weight: FloatProperty(name="Photon Weight", default=1.0, min=0.0, max=1e6, soft_max=10.0,
                                 description=_PHOTON_WEIGHT_DOC)

    @classmethod
    def register(cls) -> None:
        bpy.types.Light.stpm = PointerProperty(type=cls, name="STPM", description="STPM light settings")

    @classmethod
    def unregister(cls) -> None:
        del bpy.types.Light.stpm


class STPM_WorldSettings(bpy.types.PropertyGroup):
    """STPM settings of one world (``world.stpm``)."""

    photon_weight: FloatProperty(name="Photon Weight", default=1.0, min=0.0, max=1e6, soft_max=10.0,
                                 description=_PHOTON_WEIGHT_DOC)

    @classmethod
    def register(cls) -> None:
        bpy.types.World.stpm = PointerProperty(type=cls, name="STPM", description="STPM world settings")

    @classmethod
    def unregister(cls) -> None:
        del bpy.types.World.stpm


def _typed_float(v: float) -> float:
    """A FloatProperty's value (single precision) as the decimal the artist typed: the shortest one
    with the same float32 (0.01 is held as 0.009999999776; the core gets 0.01, its default)."""
    f = struct.unpack("f", struct.pack("f", v))[0]
    for digits in range(1, 10):
        d = float(f"{f:.{digits}g}")
        if struct.unpack("f", struct.pack("f", d))[0] == f:
            return d
    return f


_FLOAT_SETTINGS = frozenset(spec.name for spec in RenderSettings.SPECS if spec.kind == "float")


def settings_dict(props) -> dict:
    """``scene.stpm`` -> plain dict of RenderSettings fields (floats as typed: :func:`_typed_float`)."""
    return {name: _typed_float(getattr(props, name)) if name in _FLOAT_SETTINGS else getattr(props, name)
            for name in SETTING_NAMES}


def settings_from_scene(scene):
    """The core's :class:`RenderSettings` for ``scene`` (raises SettingsError on bad values)."""
    return RenderSettings.from_dict(settings_dict(scene.stpm))


classes = (STPM_SceneSettings, STPM_LightSettings, STPM_WorldSettings)


# Blender's helper: register in order, unregister in reverse
register, unregister = bpy.utils.register_classes_factory(classes)
