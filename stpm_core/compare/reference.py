"""The reference image every run of ``stpm compare`` is measured against.

Either **supplied** (``--reference REF.exr``: its ``Combined`` pass, or plain
R, G, B channels) or **computed** and cached.  Recipes (``method``):

* ``'ACCUMULATION'`` (default): an accumulation buffer of ``steps`` = 64
  instants, each a still with ``photon_factor`` = 4 x the file's photons and
  ``sample_factor`` = 1 x its samples (so 64 x the samples per pixel in all),
  k x photon_factor^(1/3).  Within one instant nothing moves, so each still's
  STANDARD estimate is consistent (its disc shrinks as photons grow); the mean
  over stratified instants converges to the shutter integral.  It shares no
  estimator with TEMPORAL or KD4D, and no instant with an ACCUMULATION run of
  N instants unless N is a multiple of 64 ((i + 1/2) / 64 = (j + 1/2) / N needs
  N (2i + 1) = 64 (2j + 1)), so it flatters no run of the sweep.
* ``'TEMPORAL'`` / ``'KD4D'``: one time-stamped photon map, the automatic
  consistent time window / time scale, 16 x the photons, 4 x the samples,
  k x 16^(1/3).  Consistent too (docs/photon-mapping.md), and cheaper, but at
  reachable photon counts TEMPORAL's window still leaks a moving caustic into
  unlit moments (about +8 % at 128 x photons on the benchmark scene, against its
  analytic answer), so it is not the default.
* A scene with no photon-mapped light (no caustics, no indirect in the plan):
  whatever the method, one render with ``sample_factor`` x the samples (4 when
  not given): a plain motion-blurred distribution ray tracer (direct light by
  shadow rays, specular chains, emission, each camera sample at its own time),
  an unbiased estimate of the shutter-averaged pixel.

The core has no unbiased path tracer for point-light caustics (a point light
seen through a perfect mirror cannot be hit by a camera path), so a
consistent photon estimate is what converges to the right answer there.

Cache: ``<cache_dir>/<key>.npz`` with key = SHA-256 of the scene's content
(the exported scene arrays and header, metadata left out), its frame and
resolution, and the reference settings.  Default cache directory:
``$XDG_CACHE_HOME/stpm/references`` (``~/.cache/stpm/references``).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time as _time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import StpmError
from .metrics import combined_rgb

__all__ = ["Reference", "reference_settings", "scene_digest", "reference_cache_key",
           "default_cache_dir", "load_reference_exr", "get_reference",
           "REFERENCE_METHODS", "REFERENCE_METHOD", "REFERENCE_STEPS", "REFERENCE_FACTORS",
           "REFERENCE_PHOTON_FACTOR", "REFERENCE_SAMPLE_FACTOR"]

REFERENCE_METHODS = ("ACCUMULATION", "TEMPORAL", "KD4D")
REFERENCE_METHOD = "ACCUMULATION"
REFERENCE_STEPS = 64             # instants of the accumulation-buffer reference
# (photons x, samples x) of the file's, per recipe (per instant for ACCUMULATION)
REFERENCE_FACTORS = {"ACCUMULATION": (4.0, 1.0), "TEMPORAL": (16.0, 4.0), "KD4D": (16.0, 4.0)}
REFERENCE_PHOTON_FACTOR, REFERENCE_SAMPLE_FACTOR = REFERENCE_FACTORS[REFERENCE_METHOD]
_CACHE_VERSION = 2               # bump when the reference recipe or what a render computes changes
#                                  (2: the world lights the scene, 2026-11-25)
_STREAM_REFERENCE = 0x5EF        # seed stream: the reference's noise is independent of the runs'


@dataclass
class Reference:
    """A reference image and where it came from.

    Attributes
    ----------
    rgb : (H, W, 3) float64 linear RGB (row 0 = top).
    info : JSON-ready dict: source ('supplied' | 'computed' | 'cached'), kind
        ('accumulation' | 'temporal' | 'kd4d' | 'ray-traced' | 'supplied'), path, settings, wall_s,
        cache_key, why (one sentence on why it converges).
    """

    rgb: np.ndarray
    info: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------
# Reference settings
# ----------------------------------------------------------------------------
def _uses_photons(scene, settings) -> bool:
    """Whether a render of ``scene`` with ``settings`` builds any photon map."""
    from ..plan import apply_plan, make_plan

    used = apply_plan(settings, make_plan(scene, settings))   # the settings render() acts on
    return used.photons_caustic > 0 or used.photons_global > 0


def reference_settings(scene, settings, *, method: str = REFERENCE_METHOD, photon_factor: float | None = None,
                       sample_factor: float | None = None, steps: int = REFERENCE_STEPS,
                       overrides: dict | None = None):
    """(RenderSettings, kind) of the computed reference for ``scene`` rendered with ``settings``.

    method : 'ACCUMULATION' | 'TEMPORAL' | 'KD4D' (see the module docstring).
    photon_factor, sample_factor : None = the method's defaults (:data:`REFERENCE_FACTORS`).
    steps : instants of an ACCUMULATION reference.
    overrides : settings applied last (tests, cross-checks).
    kind : 'accumulation' | 'temporal' | 'kd4d', or 'ray-traced' when no photon map is in play.
    """
    from ..sampling import rng_for

    method = str(method).upper()
    if method not in REFERENCE_METHODS:
        raise StpmError(f"reference method must be one of {', '.join(REFERENCE_METHODS).lower()}, got {method!r}")
    pf, sf = REFERENCE_FACTORS[method]
    pf = pf if photon_factor is None else float(photon_factor)
    sf = sf if sample_factor is None else float(sample_factor)
    if pf < 1 or sf < 1 or int(steps) < 1:
        raise StpmError("reference photon and sample factors and steps must be >= 1")
    seed = int(rng_for(settings.seed, _STREAM_REFERENCE).integers(0, 2**62))
    changes = dict(method="PHOTON", estimator="TEMPORAL", temporal_alpha=0.0, seed=seed)
    if not _uses_photons(scene, settings):
        # -- No photon map: a motion-blurred ray tracer with more samples ----------------------
        kind = "ray-traced"
        rt_sf = float(sample_factor) if sample_factor is not None else REFERENCE_FACTORS["TEMPORAL"][1]
        changes.update(samples=int(math.ceil(settings.samples * rt_sf)))
    else:
        kind = method.lower()
        changes.update(samples=int(math.ceil(settings.samples * sf)),
                       photons_caustic=int(round(settings.photons_caustic * pf)),
                       photons_global=int(round(settings.photons_global * pf)),
                       k_nearest=int(round(settings.k_nearest * pf ** (1.0 / 3.0))))
        if method == "ACCUMULATION":
            changes.update(method="ACCUMULATION", accumulation_steps=int(steps))
        else:
            changes.update(estimator=method)
    changes.update(overrides or {})
    ref = settings.replace(**changes)
    if ref.method == "ACCUMULATION" and kind != "ray-traced":
        kind = "accumulation"
    return ref, kind


_WHY = {
    "accumulation": ("accumulation buffer with many instants, each a still with many photons: within one "
                     "instant nothing moves, so each still's STANDARD estimate is consistent (its disc "
                     "shrinks as photons grow), and the mean over stratified instants converges to the "
                     "shutter integral. It shares no estimator with TEMPORAL or KD4D and no instant with "
                     "the sweep's accumulation runs."),
    "temporal": ("TEMPORAL estimator with the automatic time window: as photons grow the candidate disc "
                 "and the time window both shrink as (k / N)^(1/3) while k grows, so its bias and "
                 "variance vanish: it converges to the time-dependent irradiance at each point and instant "
                 "(slowly where a caustic moves over a static receiver)."),
    "kd4d": ("KD4D estimator with the automatic time scale: the 4D ball in (surface x scaled time) "
             "shrinks as (k s / N)^(1/3) while k grows, so its bias and variance vanish."),
    "ray-traced": ("no photon map is needed by this scene: distribution ray tracing (shadow rays, "
                   "specular chains, emission, each camera sample at its own shutter time) is an "
                   "unbiased Monte Carlo estimate of the shutter-averaged pixel, converging as "
                   "samples grow."),
    "supplied": "supplied by the user.",
}


# ----------------------------------------------------------------------------
# Cache key
# ----------------------------------------------------------------------------
def scene_digest(scene) -> str:
    """SHA-256 hex digest of the scene's content: the exported header (metadata left out)
    and every array, in a fixed order.  Same scene content -> same digest."""
    from ..scenefile import scene_to_arrays

    header, arrays = scene_to_arrays(scene)
    header = {k: v for k, v in header.items() if k != "metadata"}
    h = hashlib.sha256(json.dumps(header, sort_keys=True).encode("utf-8"))
    for key in sorted(arrays):
        a = np.ascontiguousarray(arrays[key])
        h.update(f"{key}:{a.dtype.str}:{a.shape}".encode("utf-8"))
        h.update(a.tobytes())
    return h.hexdigest()


def reference_cache_key(scene, ref_settings) -> str:
    """Cache key (hex) = hash(scene content, frame, resolution, reference settings, recipe version)."""
    h = hashlib.sha256()
    h.update(scene_digest(scene).encode("ascii"))
    h.update(json.dumps({"frame": float(scene.frame), "resolution": list(map(int, scene.resolution)),
                         "settings": ref_settings.to_dict(), "version": _CACHE_VERSION},
                        sort_keys=True).encode("utf-8"))
    return h.hexdigest()[:32]


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/stpm/references``, else ``~/.cache/stpm/references``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "stpm" / "references"


# ----------------------------------------------------------------------------
# Supplied reference
# ----------------------------------------------------------------------------
def load_reference_exr(path, resolution=None) -> np.ndarray:
    """Linear RGB (H, W, 3) float64 from an EXR: its Combined pass, else its R, G, B channels.

    resolution : (W, H) the report's renders have; a mismatch is an error.
    """
    from ..imageio import read_exr

    path = Path(path)
    if not path.is_file():
        raise StpmError(f"reference image not found: {path}")
    data = read_exr(path)
    if "Combined" in data:
        rgb = combined_rgb(data["Combined"])
    elif all(c in data for c in "RGB"):
        rgb = combined_rgb(np.concatenate([data["R"], data["G"], data["B"]], axis=2))
    else:
        raise StpmError(f"reference {path.name} has no Combined pass and no R, G, B channels")
    if resolution is not None and (rgb.shape[1], rgb.shape[0]) != tuple(map(int, resolution)):
        raise StpmError(f"reference {path.name} is {rgb.shape[1]}x{rgb.shape[0]} but the scene renders at "
                        f"{int(resolution[0])}x{int(resolution[1])}")
    return rgb


# ----------------------------------------------------------------------------
# Get a reference: supplied, cached or computed
# ----------------------------------------------------------------------------
def get_reference(scene, settings, *, reference=None, cache_dir=None, use_cache: bool = True,
                  method: str = REFERENCE_METHOD, photon_factor: float | None = None,
                  sample_factor: float | None = None, steps: int = REFERENCE_STEPS,
                  overrides: dict | None = None, progress=None, cancel=None) -> Reference:
    """The reference for ``scene`` rendered with ``settings``.

    reference : None (compute or load from the cache), a path to an EXR, an
        (H, W, 3|4) linear image, or a :class:`Reference` (its info describes it in the report).
    method, photon_factor, sample_factor, steps, overrides : the recipe (:func:`reference_settings`).
    cache_dir : where computed references are kept (default :func:`default_cache_dir`).
    progress, cancel : as for :func:`stpm_core.render.render`.
    """
    # -- Supplied ------------------------------------------------------------------
    if isinstance(reference, Reference):
        rgb = combined_rgb(reference.rgb)
        if (rgb.shape[1], rgb.shape[0]) != tuple(map(int, scene.resolution)):
            raise StpmError(f"reference image is {rgb.shape[1]}x{rgb.shape[0]} but the scene renders at "
                            f"{scene.resolution[0]}x{scene.resolution[1]}")
        info = {"source": "supplied", "kind": "supplied", "path": None, "settings": None, "wall_s": None,
                "cache_key": None, "why": _WHY["supplied"]}
        info.update(reference.info or {})
        return Reference(rgb, info)
    if reference is not None:
        if isinstance(reference, (str, os.PathLike)):
            rgb = load_reference_exr(reference, scene.resolution)
            path = str(Path(reference).resolve())
        else:
            rgb = combined_rgb(reference)
            path = None
            if (rgb.shape[1], rgb.shape[0]) != tuple(map(int, scene.resolution)):
                raise StpmError(f"reference image is {rgb.shape[1]}x{rgb.shape[0]} but the scene renders at "
                                f"{scene.resolution[0]}x{scene.resolution[1]}")
        return Reference(rgb, {"source": "supplied", "kind": "supplied", "path": path, "settings": None,
                               "wall_s": None, "cache_key": None, "why": _WHY["supplied"]})

    # -- Cached --------------------------------------------------------------------
    ref_settings, kind = reference_settings(scene, settings, method=method, photon_factor=photon_factor,
                                            sample_factor=sample_factor, steps=steps, overrides=overrides)
    key = reference_cache_key(scene, ref_settings)
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    cache_file = cache_dir / f"{key}.npz"
    info = {"kind": kind, "settings": ref_settings.to_dict(), "cache_key": key, "why": _WHY[kind]}
    if use_cache and cache_file.is_file():
        try:
            with np.load(cache_file) as z:
                rgb = np.asarray(z["rgb"], dtype=np.float64)
                meta = json.loads(bytes(z["info"]).decode("utf-8"))
            if rgb.shape == (scene.resolution[1], scene.resolution[0], 3):
                return Reference(rgb, {**info, "source": "cached", "path": str(cache_file),
                                       "wall_s": meta.get("wall_s")})
        except (OSError, ValueError, KeyError):
            pass  # a damaged cache entry is recomputed below

    # -- Computed ------------------------------------------------------------------
    from ..render import render

    t0 = _time.perf_counter()
    result = render(scene, ref_settings, progress=progress, cancel=cancel)
    rgb = combined_rgb(result.passes)
    wall_s = float(result.stats.get("wall_s", _time.perf_counter() - t0))
    path = None
    if use_cache:
        try:
            cache_dir.mkdir(parents=True, exist_ok=True)
            tmp = cache_file.with_name(cache_file.name + ".tmp.npz")
            blob = np.frombuffer(json.dumps({"wall_s": wall_s, **info}).encode("utf-8"), dtype=np.uint8)
            np.savez_compressed(tmp, rgb=rgb.astype(np.float32), info=blob)
            os.replace(tmp, cache_file)
            path = str(cache_file)
        except OSError:
            path = None  # an unwritable cache only costs the next run a recomputation
    return Reference(rgb.astype(np.float32).astype(np.float64),
                     {**info, "source": "computed", "path": path, "wall_s": wall_s})
