"""The reference image every run of ``stpm compare`` is measured against.

Either **supplied** (``--reference REF.exr``: its ``Combined`` pass, or plain
R, G, B channels) or **computed** and cached:

* a scene with photon-mapped light (caustics or indirect light in the plan):
  the TEMPORAL estimator with the automatic, consistent time window
  (``temporal_alpha = 0``), ``photon_factor`` x the file's photons,
  ``sample_factor`` x its samples and k x photon_factor^(1/3).  Its bias
  vanishes as photons grow: with alpha = max(1.5, 0.25 (N / k)^(1/3)) the
  candidate disc radius ~ sqrt(alpha k / N) and the time window ~ 1 / alpha
  both shrink as (k / N)^(1/3) (docs/photon-mapping.md), while k grows, so
  bias and noise both vanish and the estimate tends to the irradiance at the
  query point and time; see docs/compare.md.
* a scene without photon-mapped light: the same distribution ray tracer with
  ``sample_factor`` x the samples, i.e. a plain motion-blurred ray tracer
  (direct light by shadow rays, specular chains, emission, each camera sample
  at its own time): an unbiased estimate of the shutter-averaged pixel.

The core has no unbiased path tracer for point-light caustics (a point light
seen through a perfect mirror cannot be hit by a camera path), so the photon
reference is the one that converges to the right answer there.

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
           "REFERENCE_PHOTON_FACTOR", "REFERENCE_SAMPLE_FACTOR"]

REFERENCE_PHOTON_FACTOR = 16     # reference photons = this x the file's
REFERENCE_SAMPLE_FACTOR = 4      # reference samples per pixel = this x the file's
_CACHE_VERSION = 1               # bump when the reference recipe changes
_STREAM_REFERENCE = 0x5EF        # seed stream: the reference's noise is independent of the runs'


@dataclass
class Reference:
    """A reference image and where it came from.

    Attributes
    ----------
    rgb : (H, W, 3) float64 linear RGB (row 0 = top).
    info : JSON-ready dict: source ('supplied' | 'computed' | 'cached'), kind
        ('photon' | 'ray-traced' | 'accumulation' | 'supplied'), path, settings, wall_s,
        cache_key, why (one sentence on why it converges).
    """

    rgb: np.ndarray
    info: dict = field(default_factory=dict)


# ----------------------------------------------------------------------------
# Reference settings
# ----------------------------------------------------------------------------
def _uses_photons(scene, settings) -> bool:
    """Whether a render of ``scene`` with ``settings`` builds any photon map."""
    from ..render import plan_effects

    plan = plan_effects(scene, settings)
    if settings.effects == "MANUAL":
        caustic, indirect = settings.caustics, settings.indirect
    else:
        caustic, indirect = plan["caustics"], plan["indirect"]
    return bool((caustic and settings.photons_caustic > 0) or (indirect and settings.photons_global > 0))


def reference_settings(scene, settings, *, photon_factor: float = REFERENCE_PHOTON_FACTOR,
                       sample_factor: float = REFERENCE_SAMPLE_FACTOR, overrides: dict | None = None):
    """(RenderSettings, kind) of the computed reference for ``scene`` rendered with ``settings``.

    kind is 'photon' (TEMPORAL, consistent window, more photons and samples),
    'ray-traced' (no photon map in play: only more samples) or 'accumulation'
    (``overrides`` asked for method ACCUMULATION: an estimator-neutral cross-check).
    """
    from ..sampling import rng_for

    if photon_factor < 1 or sample_factor < 1:
        raise StpmError("reference photon and sample factors must be >= 1")
    seed = int(rng_for(settings.seed, _STREAM_REFERENCE).integers(0, 2**62))
    changes = dict(method="PHOTON", estimator="TEMPORAL", temporal_alpha=0.0, seed=seed,
                   samples=int(math.ceil(settings.samples * sample_factor)))
    kind = "ray-traced"
    if _uses_photons(scene, settings):
        kind = "photon"
        changes.update(photons_caustic=int(round(settings.photons_caustic * photon_factor)),
                       photons_global=int(round(settings.photons_global * photon_factor)),
                       k_nearest=int(round(settings.k_nearest * photon_factor ** (1.0 / 3.0))))
    changes.update(overrides or {})
    ref = settings.replace(**changes)
    if ref.method == "ACCUMULATION":
        kind = "accumulation"
    return ref, kind


_WHY = {
    "photon": ("TEMPORAL estimator with the automatic time window: as photons grow (k fixed "
               "relative to N) the disc radius and the time window both shrink to zero while "
               "the photon count inside them grows, so its bias and its variance vanish: it "
               "converges to the time-dependent irradiance at each point and instant."),
    "ray-traced": ("no photon map is needed by this scene: distribution ray tracing (shadow rays, "
                   "specular chains, emission, each camera sample at its own shutter time) is an "
                   "unbiased Monte Carlo estimate of the shutter-averaged pixel, converging as "
                   "samples grow."),
    "accumulation": ("accumulation buffer with many instants, each a still with many photons: each still's "
                     "STANDARD estimate is consistent (nothing moves within a still) and the average over "
                     "stratified instants converges to the shutter integral, so it tends to the right "
                     "answer as instants and photons per still grow; it shares no estimator with TEMPORAL "
                     "or KD4D."),
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
                  photon_factor: float = REFERENCE_PHOTON_FACTOR,
                  sample_factor: float = REFERENCE_SAMPLE_FACTOR, overrides: dict | None = None,
                  progress=None, cancel=None) -> Reference:
    """The reference for ``scene`` rendered with ``settings``.

    reference : None (compute or load from the cache), a path to an EXR, or an
        (H, W, 3|4) linear image.
    cache_dir : where computed references are kept (default :func:`default_cache_dir`).
    progress, cancel : as for :func:`stpm_core.render.render`.
    """
    # -- Supplied ------------------------------------------------------------------
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
    ref_settings, kind = reference_settings(scene, settings, photon_factor=photon_factor,
                                            sample_factor=sample_factor, overrides=overrides)
    key = reference_cache_key(scene, ref_settings)
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    cache_file = cache_dir / f"{key}.npz"
    info = {"kind": kind, "settings": ref_settings.to_dict(), "cache_key": key, "why": _WHY[kind],
            "photon_factor": float(photon_factor), "sample_factor": float(sample_factor)}
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
