"""Top-level render: scene + settings -> named passes, statistics, warnings.

Pipeline (``render``)::

    validate_scene -> make_caster -> LightSet -> effects plan
      -> photon maps (method PHOTON)       build_photon_maps(...)
      -> distribution ray tracing          integrator.trace_image(...)
      -> RenderResult(passes, stats, warnings, plan)

Method ``'ACCUMULATION'`` is the baseline the project compares against: the
average of ``accumulation_steps`` complete stills at instants
``t_i = shutter.sample((i + 0.5) / N)``, each with its own photon maps traced at
that instant (``time_override``), every camera sample at that instant, and the
STANDARD estimate (time plays no role inside one still).
"""
from __future__ import annotations

import re

import time as _time
from dataclasses import dataclass, field

import numpy as np

from . import kernels
from .bsdf import MaterialTable
from .errors import RenderCancelled
from .film import PASSES, PASS_NAMES
from .integrator import static_view_setup, trace_image
from .lights import LightSet
from .photons import build_photon_maps
from .plan import apply_plan, make_plan
from .raycast import make_caster
from .sampling import rng_for
from .scene import scene_warnings, validate_scene
from .shading import shading_data

__all__ = ["render", "RenderResult", "PASSES", "PASS_NAMES"]

# Random stream separating the accumulation stills' seeds.
STREAM_ACCUMULATION = 0xACC


@dataclass
class RenderResult:
    """What a render returns.

    Attributes
    ----------
    passes : name -> (H, W, C) float32, names and channels from :data:`PASSES`
        (row 0 = top).
    stats : timings (s), counts and the settings that matter (see ``render``).
    warnings : human-readable lines for the user.
    plan : the effects plan (:func:`stpm_core.plan.make_plan`).
    sums : method PROGRESSIVE only: :class:`stpm_core.progressive.PassSums` (what a partial
        result file holds, ``stpm_core.partial``); None otherwise.
    """

    passes: dict
    stats: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    plan: dict = field(default_factory=dict)
    sums: object = None          # method PROGRESSIVE: the float64 pass sums (progressive.PassSums)


def _build_maps(scene, settings, caster, lights, *, time_override=None, progress=None, cancel=None):
    """build_photon_maps(...) or None when no photons are asked for."""
    if settings.photons_caustic <= 0 and settings.photons_global <= 0:
        return None
    maps = build_photon_maps(scene, settings, caster, lights, time_override=time_override,
                             progress=progress, cancel=cancel)
    if static_view_setup(scene, maps) is not None:
        maps.prepare_standard()      # static views read STANDARD's trees too: built with the maps
    return maps


def _span(progress, a: float, b: float):
    """A progress callback mapping [0, 1] onto [a, b] of the caller's progress."""
    if progress is None:
        return None
    return lambda f, msg: progress(a + (b - a) * float(f), msg)


def _plain(v):
    """numpy scalars / arrays inside stats -> plain Python (so the stats dict is JSON-ready)."""
    if isinstance(v, dict):
        return {str(k): _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    return v


# A global map read directly needs many more photons than one look-up's k: with fewer than this many
# k's, each estimate averages a good part of the whole map (the sixth artist review's lawn: 530 of 1 M)
SPARSE_GLOBAL_KS = 10


def _sparse_global_map(map_stats: dict, psettings) -> str | None:
    """The warning for a global map too sparse to read directly (an open scene: light that bounces off
    the ground mostly leaves to the sky and is not stored), or None: with final gathering the map is
    read one bounce further, where its blur matters little."""
    stored = int(map_stats.get("photons_stored_global", map_stats.get("photons_global", 0)) or 0)
    emitted = int(map_stats.get("photons_emitted_global", 0) or 0)
    k = int(psettings.k_nearest)
    if emitted == 0 or psettings.final_gather_samples > 0 or stored >= SPARSE_GLOBAL_KS * k:
        return None
    return (f"the global photon map holds {stored} of {emitted} photons, fewer than {SPARSE_GLOBAL_KS} x k "
            f"({SPARSE_GLOBAL_KS * k}): each indirect-light estimate averages much of the scene, so light "
            f"bounced between nearby objects comes out too dark or blotchy (an open scene stores few photons); "
            f"set Final Gather Samples (16) or emit more global photons")


def _map_stats(maps) -> dict:
    return _plain(dict(getattr(maps, "stats", {}) or {})) if maps is not None else {}


# ----------------------------------------------------------------------------
# render
# ----------------------------------------------------------------------------
def render(scene, settings, *, progress=None, cancel=None, on_pass=None, scheduled_rounds=False,
           window=None) -> RenderResult:
    """Render ``scene`` with ``settings``: :func:`_render`, with numba's own errors (a kernel that could
    not be compiled or loaded on this machine) turned into one :class:`KernelsUnavailable` line.
    The first render of a process says whether the kernels load or compile
    (``kernels.first_use_progress``); stats get ``kernels_compiled`` etc. (``kernels.compile_stats``).

    on_pass(passes, info): method PROGRESSIVE calls it after each pass with the image so far
    (name -> (H, W, C) float32) and info (pass, passes, elapsed_s, noise_p95), so a viewer can show it.
    scheduled_rounds: PROGRESSIVE keeps to the schedule of time-strata rounds under a time limit (for a
    partial result, ``stpm render --pass-offset``) rather than taking smaller rounds that fit.
    window: (x0, y0, x1, y1) pixels, rows from the top, or None: the pixels wanted (a Render Region);
    every method traces the camera samples of those pixels only (``integrator.trace_image``; the
    photons light the whole scene anyway); the other pixels stay 0 (Depth: the background).
    PROGRESSIVE estimates its noise over the window's pixels (``progressive.PassSums.window``).
    """
    kernels.require()
    compiled_before = kernels.compile_counts()
    try:
        with scene.frozen():          # bounds and instance offsets once per render, not per pass
            result = _render(scene, settings, progress=progress, cancel=cancel, on_pass=on_pass,
                             scheduled_rounds=scheduled_rounds, window=window)
    except Exception as exc:
        if kernels.is_numba_error(exc):
            raise kernels.KernelsUnavailable(f"a compiled kernel failed on this machine: {kernels.compile_error(exc)}") from exc
        raise
    result.stats.update(kernels.compile_stats(compiled_before))
    return result


_NODE_MESSAGE = re.compile(r"^(material '.*?': )node ('.*?' \(\w+\))")


def _already_said(message: str, said: list) -> bool:
    """Did the exporter already report this node-interpreter message (the same text, or a message
    of the same material naming the same node, e.g. the bake report's)?"""
    if message in said:
        return True
    m = _NODE_MESSAGE.match(message)
    return m is not None and any(w.startswith(m.group(1)) and m.group(2) in w for w in said)


def _render(scene, settings, *, progress=None, cancel=None, on_pass=None, scheduled_rounds=False,
            window=None) -> RenderResult:
    """Render ``scene`` with ``settings`` (RenderSettings).

    progress(fraction in [0, 1], message) is called at least once per tile;
    cancel() -> bool is polled as often and raises :class:`RenderCancelled`.

    The effects plan (stpm_core.plan.make_plan, docs/effects.md) decides what is
    simulated: maps it rules out get 0 photons, and a scene whose lighting does
    not change in the shutter is read with STANDARD (``apply_plan``).

    stats keys: wall_s, export_s (0 here; the add-on fills it), plan_s, photon_trace_s,
    photon_map_build_s, photon_lookup_s, render_s, rays_cast, camera_rays, shadow_rays,
    bounce_rays, rays_per_s, photon_lookups, photon_estimates (of the look-ups, those estimated: the
    others shared a pixel's estimate, ``photons.sharing``), static_lookups (of the look-ups, those
    of a static view read with STANDARD: ``integrator.static_view_rows``), photons_caustic, photons_global
    (stored), photon_stats (the maps' own dict; a list for ACCUMULATION),
    estimator (the one used), method, samples, resolution, seed, accumulation_steps.
    """
    t_wall = _time.perf_counter()
    settings.validate()
    validate_scene(scene)
    warnings: list[str] = scene_warnings(scene)     # lights that emit nothing (zero area / scale)
    if cancel is not None and cancel():
        raise RenderCancelled("render cancelled")
    progress = kernels.first_use_progress(progress)    # a process's first render: 'loading' or 'compiling kernels'

    # -- Scene acceleration, lights, materials, plan --------------------------------
    caster = make_caster(scene)
    lights = LightSet(scene)
    table = MaterialTable(scene.materials)
    shading = shading_data(scene, table.closures)      # node programs compiled, textures packed
    # node inputs the interpreter could not evaluate (once: the exporter may have said so already)
    said = scene.metadata.get("warnings", []) if isinstance(getattr(scene, "metadata", None), dict) else []
    said = [w for w in said if isinstance(w, str)] if isinstance(said, list) else []
    warnings.extend(w for w in shading.unsupported if not _already_said(w, said))
    t_plan = _time.perf_counter()
    plan = make_plan(scene, settings, caster=caster, lights=lights)
    psettings = apply_plan(settings, plan)      # what the plan rules out gets no photons; STANDARD when static
    plan_s = _time.perf_counter() - t_plan
    if not scene.lights and not any(l.type == "MESH" for l in lights.lights) and not scene.world.shines:
        warnings.append("the scene has no lights, emissive surfaces or world light: the image is black")
    if plan["caustics"] and psettings.photons_caustic == 0 and settings.effects == "AUTO":
        warnings.append("the scene calls for caustics but photons_caustic is 0: the Caustic pass stays empty")
    if plan["indirect"] and psettings.photons_global == 0 and settings.effects == "AUTO":
        warnings.append("the scene calls for indirect light but photons_global is 0: the Indirect pass stays empty")
    if settings.method == "PHOTON" and settings.estimator == "STANDARD" and plan["time_dependent"]:
        warnings.append("estimator STANDARD ignores photon times: photon-lit surfaces that move come out too dark")

    photon_s = 0.0
    map_stats: list[dict] = []
    trace_stats = []
    progressive = sums = None
    if settings.method == "PROGRESSIVE":
        # -- Passes with a shrinking space-time kernel (stpm_core/progressive.py) ------------------
        from .progressive import progressive_warnings, render_passes
        t0 = _time.perf_counter()
        sums, progressive, trace_stats, map_stats = render_passes(
            scene, settings, psettings, caster, lights, table, progress=progress, cancel=cancel,
            on_pass=None if on_pass is None else (lambda sm, info: on_pass(sm.preview(), info)),
            scheduled_rounds=scheduled_rounds, window=window)
        passes = sums.image()
        photon_s = sum(float(m.get("photon_trace_s", 0.0)) for m in map_stats)
        warnings.extend(progressive_warnings(progressive))
    elif settings.method == "PHOTON":
        # -- Photon maps over the whole shutter ----------------------------------------
        t0 = _time.perf_counter()
        maps = _build_maps(scene, psettings, caster, lights, progress=_span(progress, 0.0, 0.3), cancel=cancel)
        photon_s += _time.perf_counter() - t0
        # -- Distribution ray tracing ---------------------------------------------------
        passes, ts = trace_image(scene, settings, caster, lights, maps, table=table, window=window,
                                 progress=progress, cancel=cancel,
                                 progress_span=(0.3 if maps is not None else 0.0, 1.0))
        trace_stats.append(ts)
        map_stats.append(_map_stats(maps))      # after tracing: includes look-up counts and time
    else:
        # -- Accumulation buffer: N stills at stratified instants --------------------------
        N = int(settings.accumulation_steps)
        acc = None
        still_settings = psettings.replace(estimator="STANDARD")
        for i in range(N):
            t_i = float(scene.shutter.sample(np.array([(i + 0.5) / N]))[0])
            seed_i = int(rng_for(settings.seed, STREAM_ACCUMULATION, i).integers(0, 2**62))
            a, b = i / N, (i + 1) / N
            t0 = _time.perf_counter()
            maps = _build_maps(scene, still_settings.replace(seed=seed_i), caster, lights, time_override=t_i,
                               progress=_span(progress, a, a + 0.3 * (b - a)), cancel=cancel)
            photon_s += _time.perf_counter() - t0
            passes_i, ts = trace_image(scene, still_settings, caster, lights, maps, table=table,
                                       time_override=t_i, stream=i + 1, window=window, progress=progress,
                                       cancel=cancel,
                                       progress_span=(a + (0.3 * (b - a) if maps is not None else 0.0), b))
            trace_stats.append(ts)
            map_stats.append(_map_stats(maps))
            if acc is None:
                acc = {k: v.astype(np.float64) for k, v in passes_i.items()}
            else:
                for k in acc:
                    acc[k] += passes_i[k]
        passes = {k: (v / N).astype(np.float32) for k, v in acc.items()}

    if settings.method != "PROGRESSIVE" and plan["indirect"]:
        warnings.extend(filter(None, [_sparse_global_map(map_stats[0] if map_stats else {}, psettings)]))

    # -- Statistics -------------------------------------------------------------------
    def total(key):
        return float(sum(float(s.get(key, 0.0) or 0.0) for s in map_stats))

    render_s = sum(ts.seconds for ts in trace_stats)
    rays = sum(ts.rays for ts in trace_stats)
    trace_s = total("trace_s") or total("photon_trace_s")
    build_s = total("build_s") or total("photon_map_build_s")
    if trace_s == 0.0 and build_s == 0.0:
        trace_s = photon_s
    stats = {
        "wall_s": _time.perf_counter() - t_wall,
        "export_s": 0.0,
        "plan_s": plan_s,
        "photon_trace_s": trace_s,
        "photon_map_build_s": build_s,
        "photon_s": photon_s,
        "photon_lookup_s": total("lookup_s"),
        "render_s": render_s,
        "rays_cast": int(rays),
        "camera_rays": int(sum(ts.camera_rays for ts in trace_stats)),
        "bounce_rays": int(sum(ts.bounce_rays for ts in trace_stats)),
        "shadow_rays": int(sum(ts.shadow_rays for ts in trace_stats)),
        "rays_per_s": float(rays / render_s) if render_s > 0 else 0.0,
        "photon_lookups": int(sum(ts.photon_lookups for ts in trace_stats)),
        "photon_estimates": int(sum(ts.photon_estimates for ts in trace_stats)),
        "static_lookups": int(sum(ts.static_lookups for ts in trace_stats)),
        "gather_rays": int(sum(ts.gather_rays for ts in trace_stats)),
        "gather_lookups": int(sum(ts.gather_lookups for ts in trace_stats)),
        "photons_caustic": int(total("caustic_photons") or total("photons_caustic")),
        "photons_global": int(total("global_photons") or total("photons_global")),
        "photon_stats": (map_stats[-1] if map_stats else {}) if progressive is not None
        else map_stats[0] if len(map_stats) == 1 else map_stats,
        "estimator": "STANDARD" if settings.method == "ACCUMULATION" else psettings.estimator,
        "method": settings.method,
        "samples": int(settings.samples),
        "accumulation_steps": int(settings.accumulation_steps) if settings.method == "ACCUMULATION" else 1,
        "resolution": [int(scene.resolution[0]), int(scene.resolution[1])],
        "seed": int(settings.seed),
        "caster": dict(getattr(caster, "stats", {}) or {}),
    }
    if progressive is not None:
        stats["progressive"] = progressive
    adaptive = [ts.extra["adaptive"] for ts in trace_stats if "adaptive" in ts.extra]
    if adaptive:
        # adaptive sampling (integrator._trace_adaptive): the samples pixels took, mean / min / max
        stats["adaptive"] = adaptive[0]
        stats["samples_mean"] = adaptive[0]["samples_mean"]
    stats = _plain(stats)
    if progress is not None:
        progress(1.0, "done")
    return RenderResult(passes=passes, stats=stats, warnings=warnings, plan=plan, sums=sums)
