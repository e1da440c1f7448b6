"""Render settings: the same names as Blender's ``scene.stpm`` and ``stpm render``.

See ``shared/interface.md``; names here are fixed (add, never rename).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields

import numpy as np

from .errors import SettingsError

__all__ = ["RenderSettings", "METHODS", "ESTIMATORS", "EFFECTS", "KERNELS"]

METHODS = ("PHOTON", "ACCUMULATION", "PROGRESSIVE")
ESTIMATORS = ("STANDARD", "TEMPORAL", "KD4D")
EFFECTS = ("AUTO", "MANUAL")
KERNELS = ("BOX", "CONE")


@dataclass
class RenderSettings:
    """Everything that controls a render besides the scene.

    Attributes
    ----------
    method : 'PHOTON' (time-stamped photon maps), 'ACCUMULATION' (average of
        ``accumulation_steps`` complete stills, the baseline) or 'PROGRESSIVE' (passes of
        ``samples`` camera samples per pixel and ``photons_*`` photons each, read with a
        space-time kernel that shrinks pass by pass: converges; docs/photon-mapping.md).
    estimator : 'STANDARD' | 'TEMPORAL' | 'KD4D' radiance estimate.
    accumulation_steps : instants averaged by ACCUMULATION (>= 1).
    samples : camera samples per pixel, each at its own shutter time.
    photons_global : photons emitted for the global (indirect) map.
    photons_caustic : photons emitted toward specular objects for the caustic map.
    k_nearest : photons per radiance estimate.
    temporal_alpha : TEMPORAL candidates as a multiple of k; 0 = automatic and consistent.
    time_scale : KD4D's s in scene units per shutter; 0 = automatic.
    seed : all randomness derives from it.
    effects : 'AUTO' (simulate only what the scene calls for) or 'MANUAL'.
    caustics, indirect : with effects='MANUAL', whether to build each map.
    kernel : 'BOX' or 'CONE' density-estimation kernel.
    max_depth : longest specular chain followed from the camera / photon bounces.
    glossy_bounces, transmission_bounces : as Cycles' Glossy / Transmission bounces (defaults 4,
        12): a camera path goes on through at most this many reflections (delta or rough) /
        refractions, within max_depth in all.  Photon paths follow max_depth only.
    filter_width : Blackman-Harris pixel filter width in pixels (Blender default 1.5).
    threads : worker threads for ray casting / look-ups (0 = all cores).
    passes : PROGRESSIVE: stop after this many passes (0 = no pass limit).
    time_limit : PROGRESSIVE: stop after this many seconds of rendering (0 = none; as Cycles).
    noise_threshold : PROGRESSIVE: stop when the estimated per-pixel relative error (95th
        percentile over 8x8 blocks, from the odd and even passes) is below it (0 = none).
    shrink_alpha : PROGRESSIVE: the kernel's shrink parameter a of V_{i+1} = V_i (i + a) / (i + 1);
        0 = automatic (2 / (d + 2) for a d-dimensional kernel: 0.5 on surfaces, 0.4 in space x time).
    pass_offset : PROGRESSIVE: index of the first pass rendered (a farm splits passes between
        machines; ``stpm merge`` joins them).
    clamp_direct, clamp_indirect : Cycles' Clamp Direct / Indirect: the largest channel of one
        contribution to a sample -- at the camera's first hit (direct: its emission and
        next-event estimate) or after a bounce and from the photon maps (indirect) -- is scaled
        down to this value; 0 = off (the default: clamping loses energy).
    """

    method: str = "PHOTON"
    estimator: str = "TEMPORAL"
    accumulation_steps: int = 8
    samples: int = 16
    photons_global: int = 200_000
    photons_caustic: int = 200_000
    k_nearest: int = 50
    temporal_alpha: float = 0.0
    time_scale: float = 0.0
    seed: int = 0
    effects: str = "AUTO"
    caustics: bool = True
    indirect: bool = True
    kernel: str = "BOX"
    max_depth: int = 8
    glossy_bounces: int = 4
    transmission_bounces: int = 12
    filter_width: float = 1.5
    threads: int = 0
    clamp_direct: float = 0.0
    clamp_indirect: float = 0.0
    passes: int = 16
    time_limit: float = 0.0
    noise_threshold: float = 0.0
    shrink_alpha: float = 0.0
    pass_offset: int = 0

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> "RenderSettings":
        """Raise :class:`SettingsError` naming the first impossible value."""
        def enum(name, allowed):
            v = getattr(self, name)
            if isinstance(v, str):
                v = v.upper()
                setattr(self, name, v)
            if v not in allowed:
                raise SettingsError(f"{name} must be one of {', '.join(allowed)}, got {v!r}")

        def integer(name, lo, hi=2**62):
            v = getattr(self, name)
            if isinstance(v, np.integer) and not isinstance(v, np.bool_):
                v = int(v)                                   # a numpy integer (bpy, numpy): exact
                setattr(self, name, v)
            if isinstance(v, bool) or not isinstance(v, int) or not (lo <= v <= hi):
                raise SettingsError(f"{name} must be an integer in [{lo}, {hi}], got {v!r:.60}")

        def real(name, lo, hi=float("inf")):
            v = getattr(self, name)
            # Numbers only: a string ("0.5"), a boolean or None is refused, not coerced
            if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
                raise SettingsError(f"{name} must be a number, got {v!r:.60}")
            try:
                v = float(v)
            except OverflowError:                            # an integer too large for a float
                raise SettingsError(f"{name} must be in [{lo}, {hi}], got {v!r:.40}") from None
            if not math.isfinite(v):
                raise SettingsError(f"{name} must be a finite number in [{lo}, {hi}], got {v}")
            if not (lo <= v <= hi):
                raise SettingsError(f"{name} must be in [{lo}, {hi}], got {v}")
            setattr(self, name, v)

        def boolean(name):
            # true / false only; the integers 0 and 1 (and numpy booleans) are unambiguous and coerced.
            # A string ("false") is refused: read as a truth value it would mean the opposite.
            v = getattr(self, name)
            if isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1)):
                setattr(self, name, bool(v))
                return
            raise SettingsError(f"{name} must be true or false, got {v!r:.60}")

        enum("method", METHODS)
        enum("estimator", ESTIMATORS)
        enum("effects", EFFECTS)
        enum("kernel", KERNELS)
        boolean("caustics")
        boolean("indirect")
        integer("accumulation_steps", 1, 4096)
        integer("samples", 1, 1 << 16)
        integer("photons_global", 0, 1 << 31)
        integer("photons_caustic", 0, 1 << 31)
        integer("k_nearest", 1, 100_000)
        integer("seed", 0, 2**63 - 1)
        integer("max_depth", 1, 1024)
        integer("glossy_bounces", 0, 1024)
        integer("transmission_bounces", 0, 1024)
        integer("threads", 0, 1024)
        real("temporal_alpha", 0.0, 1e6)
        if 0.0 < self.temporal_alpha < 1.0:
            raise SettingsError(f"temporal_alpha must be 0 (automatic) or >= 1, got {self.temporal_alpha}")
        real("time_scale", 0.0, 1e30)
        real("filter_width", 0.0, 64.0)
        real("clamp_direct", 0.0, 1e30)
        real("clamp_indirect", 0.0, 1e30)
        integer("passes", 0, 1 << 24)
        integer("pass_offset", 0, 1 << 24)
        real("time_limit", 0.0, 1e9)
        real("noise_threshold", 0.0, 1e6)
        real("shrink_alpha", 0.0, 1.0)
        if self.shrink_alpha >= 1.0:
            raise SettingsError(f"shrink_alpha must be 0 (automatic) or in (0, 1), got {self.shrink_alpha}")
        if self.method == "PROGRESSIVE" and self.passes == 0 and self.time_limit == 0.0 \
                and self.noise_threshold == 0.0:
            raise SettingsError("method PROGRESSIVE would never stop: set passes, time_limit or noise_threshold")
        return self

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "RenderSettings":
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise SettingsError(f"unknown setting {unknown[0]!r}")
        return cls(**d)

    def replace(self, **changes) -> "RenderSettings":
        d = self.to_dict()
        d.update(changes)
        return RenderSettings.from_dict(d)
