"""Render settings: the same names as Blender's ``scene.stpm`` and ``stpm render``.

See ``shared/interface.md``; names here are fixed (add, never rename).  Each field is one row of
the typed schema (:mod:`stpm_core.schema`): its kind, default, range or choices and doc are
declared here once, and the scene-file loader, the command-line options and the add-on's
``scene.stpm`` properties are derived from ``RenderSettings.SPECS``.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass, fields
from typing import ClassVar

from .errors import SettingsError
from .schema import setting, specs_of
from .strata import is_round_end, round_ends_near, round_ends_text

__all__ = ["RenderSettings", "METHODS", "ESTIMATORS", "EFFECTS", "KERNELS"]

# Enum choices: (value, the add-on's label, its description)
_METHOD_CHOICES = (
    ("PHOTON", "Time-Dependent Photons", "Time-stamped photon maps: one photon pass for the whole shutter"),
    ("ACCUMULATION", "Accumulation Buffer", "Average of complete stills at instants across the shutter (baseline)"),
    ("PROGRESSIVE", "Progressive", "Passes whose space-time kernel shrinks: the image improves pass by pass and "
                                   "converges; stop at a pass count, a time limit or a noise threshold"),
)
_ESTIMATOR_CHOICES = (
    ("STANDARD", "Standard", "k nearest photons in space, time ignored (wrong on moving receivers)"),
    ("TEMPORAL", "Temporal", "3D kd-tree, then the candidates nearest in time"),
    ("KD4D", "4D kd-tree", "One kd-tree over space and scaled time"),
)
_EFFECTS_CHOICES = (
    ("AUTO", "Automatic", "Simulate only what the scene calls for (see stpm plan)"),
    ("MANUAL", "Manual", "Choose caustics and indirect light yourself"),
)
_KERNEL_CHOICES = (
    ("BOX", "Box", "Constant density-estimation kernel"),
    ("CONE", "Cone", "Cone filter: sharper caustics, a little more noise"),
)
METHODS = tuple(c[0] for c in _METHOD_CHOICES)
ESTIMATORS = tuple(c[0] for c in _ESTIMATOR_CHOICES)
EFFECTS = tuple(c[0] for c in _EFFECTS_CHOICES)
KERNELS = tuple(c[0] for c in _KERNEL_CHOICES)

_PROGRESSIVE_NEEDS_A_STOP = ("method PROGRESSIVE would never stop: set passes, time_limit or noise_threshold "
                             "(--passes, --time-limit, --noise-threshold)")


@dataclass
class RenderSettings:
    """Everything that controls a render besides the scene.

    Every field is a schema row (:func:`stpm_core.schema.setting`): its doc, kind and range are
    listed under Attributes below (generated from the rows: ``RenderSettings.SPECS``).
    ``validate()`` checks each field against its row, then the rules between fields (a
    PROGRESSIVE render must have a stop); a bad value raises
    :class:`~stpm_core.errors.SettingsError` with one line naming the field.
    """

    method: str = setting(
        "PHOTON", "enum", "'PHOTON' (time-stamped photon maps), 'ACCUMULATION' (average of accumulation_steps "
        "complete stills, the baseline) or 'PROGRESSIVE' (passes of samples camera samples per pixel and "
        "photons_* photons each, read with a space-time kernel that shrinks pass by pass: converges; "
        "docs/photon-mapping.md)",
        choices=_METHOD_CHOICES, label="Method", flag="--method",
        help="photon: time-stamped photon maps; accumulation: the average of N stills (the baseline); "
             "progressive: passes whose space-time kernel shrinks (converges; see --passes, --time-limit)")
    estimator: str = setting(
        "TEMPORAL", "enum", "'STANDARD' | 'TEMPORAL' | 'KD4D' radiance estimate",
        choices=_ESTIMATOR_CHOICES, label="Estimator", flag="--estimator",
        help="photon density estimate (methods photon and progressive)")
    accumulation_steps: int = setting(
        8, "int", "instants averaged by ACCUMULATION; each costs about one still", lo=1, hi=4096,
        label="Accumulation Steps", flag="--accumulation-steps", metavar="N", ui={"soft_max": 64},
        help="stills averaged by --method accumulation")
    samples: int = setting(
        16, "int", "camera samples per pixel, each at its own time in the shutter", lo=1, hi=1 << 16,
        label="Samples", flag="--samples", metavar="S", ui={"soft_max": 1024})
    use_adaptive_sampling: bool = setting(
        False, "bool", "as Cycles' Noise Threshold check box: method PHOTON traces the first samples of every "
        "pixel, then rounds of 64 only for the pixels whose estimated error is above adaptive_threshold, up to "
        "samples (docs/rendering.md, \"Adaptive sampling\"); ACCUMULATION and PROGRESSIVE ignore it",
        label="Adaptive Sampling", flag="--adaptive-sampling", metavar="on|off",
        help="adaptive sampling on or off (method photon; samples is then the most a pixel takes)")
    adaptive_threshold: float = setting(
        0.01, "float", "as Cycles' Noise Threshold: a pixel stops when its estimated error |I - A| / sqrt(I) "
        "(Cycles' measure, times Cycles' 5) falls below it; 0 = adaptive sampling off", lo=0.0, hi=1.0,
        label="Noise Threshold", flag="--adaptive-threshold", metavar="T", ui={"precision": 4, "soft_max": 0.1},
        help="adaptive sampling's per-pixel noise threshold")
    adaptive_min_samples: int = setting(
        0, "int", "as Cycles' Min Samples: the samples every pixel takes before its first check; 0 = automatic "
        "(Cycles': ceil(16 / threshold^0.3), 64 at 0.01)", lo=0, hi=1 << 16, label="Min Samples",
        flag="--adaptive-min-samples", metavar="N", ui={"soft_max": 4096},
        help="adaptive sampling's samples before the first check (0: automatic)")
    photons_global: int = setting(
        200_000, "int", "photons emitted for the global (indirect) map", lo=0, hi=1 << 31,
        label="Global Photons", flag="--photons-global", metavar="N", ui={"soft_max": 10_000_000})
    photons_caustic: int = setting(
        200_000, "int", "caustic photons, emitted toward the specular objects for the caustic map",
        lo=0, hi=1 << 31, label="Caustic Photons", flag="--photons-caustic", metavar="N",
        ui={"soft_max": 10_000_000})
    photon_guiding: bool = setting(
        False, "bool", "emit the global map's photons where the camera looks: a camera pilot marks the cells of "
        "each light's emission that light seen surfaces directly; 80 % of the photons come from marked cells, 20 % "
        "uniform, powers divided by the mixture's density (docs/photon-mapping.md, \"Emission guided by direct "
        "visibility\")", label="Photon Guiding", flag="--photon-guiding", metavar="on|off",
        help="guide the global photons to what the camera sees (direct-visibility pilot) on or off")
    k_nearest: int = setting(
        50, "int", "photons per radiance estimate (k)", lo=1, hi=100_000, label="Nearest Photons", flag="--k",
        metavar="K", ui={"soft_max": 500})
    final_gather_samples: int = setting(
        0, "int", "final gathering of the global photon map (Jensen's two-pass method with Christensen's "
        "precomputed irradiance): rays sampled from the diffuse lobe at the camera's first diffuse vertex, "
        "each reading the irradiance precomputed at every 4th global photon where it lands; 0 = off (the "
        "camera vertex reads the global map directly: blotches, no extra rays); off when diffuse_bounces < 2. "
        "Method PHOTON and ACCUMULATION; PROGRESSIVE refuses it", lo=0, hi=4096, label="Final Gather Samples",
        flag="--final-gather-samples", metavar="N", ui={"soft_max": 64},
        help="final gathering rays per shading point (0: off, direct visualisation)")
    temporal_alpha: float = setting(
        0.0, "float", "TEMPORAL's candidates per estimate as a multiple of k; 0 = automatic and consistent, "
        "1.5 = the paper's", lo=0.0, hi=1e6, gap=1.0, rule="0 (automatic) or >= 1",
        label="Temporal Alpha", flag="--temporal-alpha", metavar="A", ui={"soft_max": 10.0},
        help="TEMPORAL candidates as a multiple of k (0: automatic)")
    time_scale: float = setting(
        0.0, "float", "KD4D's s in scene units per shutter; 0 = automatic from the scene's motion",
        lo=0.0, hi=1e30, label="Time Scale", flag="--time-scale", metavar="S", ui={"soft_max": 100.0},
        help="KD4D's scene units per shutter (0: automatic)")
    seed: int = setting(
        0, "int", "all randomness derives from it: same seed, same image", lo=0, hi=2**63 - 1,
        label="Seed", flag="--seed", metavar="S", help="random seed")
    effects: str = setting(
        "AUTO", "enum", "'AUTO' (simulate only what the scene calls for: stpm plan) or 'MANUAL' (caustics "
        "and indirect say which maps to build)", choices=_EFFECTS_CHOICES, label="Effects")
    caustics: bool = setting(
        True, "bool", "with effects MANUAL: build the caustic photon map", label="Caustics")
    indirect: bool = setting(
        True, "bool", "with effects MANUAL: build the global photon map", label="Indirect")
    kernel: str = setting(
        "BOX", "enum", "'BOX' or 'CONE' density-estimation kernel", choices=_KERNEL_CHOICES, label="Kernel")
    max_depth: int = setting(
        8, "int", "longest specular chain followed from the camera, and photon bounces", lo=1, hi=1024,
        label="Max Depth")
    diffuse_bounces: int = setting(
        4, "int", "as Cycles' Diffuse bounces: diffuse reflections a light path may make, counted as Cycles "
        "counts them (a camera vertex reading a photon map makes one, next-event estimation none): 0 = direct "
        "light only (no photon maps, no caustics), 1 = the caustics and one bounce of indirect light",
        lo=0, hi=1024, label="Diffuse Bounces")
    glossy_bounces: int = setting(
        4, "int", "as Cycles' Glossy bounces: reflections (mirror or rough) a camera path goes on through, "
        "within max_depth (photon paths follow max_depth only)", lo=0, hi=1024, label="Glossy Bounces")
    transmission_bounces: int = setting(
        12, "int", "as Cycles' Transmission bounces: refractions a camera path goes on through, within "
        "max_depth", lo=0, hi=1024, label="Transmission Bounces")
    rough_splits: int = setting(
        1, "int", "camera paths go on from their first vertex with a rough glossy or rough glass lobe with this "
        "many rays, each carrying 1 / N of it (path splitting): N times the samples of what such a lobe "
        "reflects -- a varnish or rough metal reflecting the sun through glass -- for the cost of the extra "
        "rays, not of whole camera samples; 1 = off", lo=1, hi=64, label="Rough Splits")
    transparent_max_bounces: int = setting(
        8, "int", "as Cycles' Transparent bounces: transparent surfaces (Transparent BSDF, alpha cut-outs) one "
        "ray segment -- camera, shadow or photon -- passes in a row; the next one absorbs it (black, "
        "shadowed). Passes are not bounces", lo=0, hi=1024, label="Transparent Bounces")
    filter_width: float = setting(
        1.5, "float", "Blackman-Harris pixel filter width in pixels (Blender's default 1.5)", lo=0.0, hi=64.0,
        label="Filter Width", ui={"subtype": "PIXEL"})
    threads: int = setting(
        0, "int", "worker threads for ray casting and look-ups (0 = all cores)", lo=0, hi=1024, label="Threads")
    clamp_direct: float = setting(
        0.0, "float", "as Cycles' Clamp Direct: the largest channel of one contribution at the camera's first "
        "hit (its emission and next-event estimate) is scaled down to this value; 0 = off (clamping removes "
        "fireflies and energy)", lo=0.0, hi=1e30, label="Clamp Direct", ui={"soft_max": 100.0})
    clamp_indirect: float = setting(
        0.0, "float", "as Cycles' Clamp Indirect: the same after a bounce and for photon-map light; 0 = off",
        lo=0.0, hi=1e30, label="Clamp Indirect", ui={"soft_max": 100.0})
    passes: int = setting(
        16, "int", "PROGRESSIVE: stop after this many passes (0 = no pass limit); each pass traces the photon "
        "counts and the samples per pixel set here", lo=0, hi=1 << 24,
        label="Passes", flag="--passes", metavar="N", ui={"soft_max": 1024},
        help="progressive: stop after N passes (0: no pass limit)")
    time_limit: float = setting(
        0.0, "float", "PROGRESSIVE: stop after this many seconds of rendering (0 = none; as Cycles)",
        lo=0.0, hi=1e9, label="Time Limit", flag="--time-limit", metavar="S",
        ui={"soft_max": 3600.0, "subtype": "TIME_ABSOLUTE"},
        help="progressive: stop after S seconds of rendering (0: none)")
    noise_threshold: float = setting(
        0.0, "float", "PROGRESSIVE: stop when the estimated per-pixel relative error (95th percentile over "
        "8x8 blocks, from the odd and even passes) is below it (0 = none)", lo=0.0, hi=1e6,
        label="Noise Threshold", flag="--noise-threshold", metavar="T", ui={"soft_max": 0.2, "precision": 4},
        help="progressive: stop when the estimated per-pixel relative error is below T (0: none)")
    shrink_alpha: float = setting(
        0.0, "float", "PROGRESSIVE: the kernel's shrink parameter a of V_{i+1} = V_i (i + a) / (i + 1); smaller "
        "shrinks faster; 0 = automatic (2 / (d + 2) for a d-dimensional kernel: 0.5 on surfaces, 0.4 in space x "
        "time)", lo=0.0, hi=1.0, hi_open=True, rule="0 (automatic) or in (0, 1)", label="Shrink Alpha",
        ui={"precision": 3},
        flag="--shrink-alpha", metavar="A", help="progressive: the kernel's shrink parameter (0: automatic)")
    pass_offset: int = setting(
        0, "int", "PROGRESSIVE: index of the first pass rendered (a farm splits one frame's passes between "
        "machines; stpm merge joins them)", lo=0, hi=1 << 24, label="Pass Offset", flag="--pass-offset", metavar="A",
        help="progressive: index of the first pass (split a frame between machines; join with stpm merge)")
    denoise: bool = setting(
        False, "bool", "also write Cycles' guide passes (Denoising Albedo, Denoising Normal) and the raw Combined "
        "as Noisy Image; Blender's Denoise node makes the denoised Combined of them (docs/blender.md, "
        "\"Denoising\")", label="Denoise")

    SPECS: ClassVar[tuple] = ()          # the schema rows, in field order (filled below)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> "RenderSettings":
        """Raise :class:`SettingsError` naming the first impossible value (fields in order, then the
        rules between fields); values are canonicalised (numpy scalars -> int / float, 0 / 1 -> bool,
        enums upper-cased)."""
        for spec in self.SPECS:
            setattr(self, spec.name, spec.check(getattr(self, spec.name)))
        if self.method == "PROGRESSIVE" and self.passes == 0 and self.time_limit == 0.0 \
                and self.noise_threshold == 0.0:
            raise SettingsError(_PROGRESSIVE_NEEDS_A_STOP)
        if self.method == "PROGRESSIVE" and self.final_gather_samples > 0:
            raise SettingsError("final_gather_samples works with method PHOTON or ACCUMULATION, not PROGRESSIVE "
                                "(its passes have no fixed global map to precompute irradiance on); set it to 0")
        if self.method == "PROGRESSIVE" and not is_round_end(self.pass_offset):
            ends = ", ".join(str(n) for n in round_ends_near(self.pass_offset, 2))
            raise SettingsError(f"pass_offset {self.pass_offset} is inside a round of time strata; passes are "
                                f"split between machines at round ends: {round_ends_text()} (nearest: {ends})")
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


RenderSettings.SPECS = specs_of(RenderSettings)
RenderSettings.__doc__ += "\n    Attributes\n    ----------\n" + "".join(
    f"    {s.name} : {s.doc} ({s.describe()}; default {s.default!r}).\n" for s in RenderSettings.SPECS)
