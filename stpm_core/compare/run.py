"""``run_compare``: reference -> sweep -> cost of accuracy -> report.html + report.json.

    from stpm_core.compare import run_compare
    report = run_compare(scene, settings, "out/report_dir", time_budget=600)
    report["cost"]["best_time_dependent"]["rmse"]   # {'estimator', 'time_s', 'speedup', ...}

The returned dict is exactly what ``report.json`` holds (finite numbers,
``None`` / null for what was skipped or could not be measured).
"""
from __future__ import annotations

import dataclasses
import datetime as _dt
import json
import math
from pathlib import Path

import numpy as np

from ..errors import RenderCancelled, StpmError
from .costs import cost_of_accuracy
from .metrics import RELMSE_EPS, combined_rgb, display_scale, image_errors
from .reference import REFERENCE_METHOD, REFERENCE_STEPS, Reference, get_reference, reference_settings
from .report_html import render_html
from .sweep import (DEFAULT_ACCUMULATION_STEPS, DEFAULT_PHOTON_BUDGETS, METHOD_ORDER, PHOTON_ESTIMATORS,
                    is_consistent, parse_budget, plan_runs, run_sweep)

__all__ = ["run_compare", "REPORT_FORMAT", "REPORT_VERSION", "json_ready"]

REPORT_FORMAT = "stpm-compare"
REPORT_VERSION = 1


def json_ready(obj):
    """A copy of ``obj`` that ``json.dumps(allow_nan=False)`` accepts: numpy -> Python, NaN/inf -> None."""
    if isinstance(obj, dict):
        return {str(k): json_ready(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_ready(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_ready(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, (np.integer, int)):
        return int(obj)
    if isinstance(obj, (np.floating, float)):
        return float(obj) if math.isfinite(float(obj)) else None
    if obj is None or isinstance(obj, str):
        return obj
    return str(obj)


def _scene_info(scene, scene_name, scene_path) -> dict:
    from ..plan import make_plan

    plan = make_plan(scene)
    return {"name": scene_name or str(scene.metadata.get("name") or scene.metadata.get("source") or "scene"),
            "path": None if scene_path is None else str(Path(scene_path).resolve()),
            "resolution": [int(scene.resolution[0]), int(scene.resolution[1])],
            "frame": float(scene.frame),
            "shutter": {"open": float(scene.shutter.open), "close": float(scene.shutter.close),
                        "curve": scene.shutter.curve is not None},
            "has_motion": bool(scene.has_motion),
            "plan": {k: bool(plan[k]) for k in ("motion_blur", "caustics", "indirect", "time_dependent")},
            "objects": len(scene.instances), "lights": len(scene.lights)}


def _write_reference_exr(path: Path, rgb: np.ndarray, info: dict) -> str | None:
    """reference.exr next to the report (reusable with --reference); None if it cannot be written."""
    from ..imageio import write_exr

    rgba = np.concatenate([rgb, np.ones(rgb.shape[:2] + (1,))], axis=2).astype(np.float32)
    try:
        write_exr(path, {"Combined": rgba}, metadata={"stpm:reference": json.dumps(json_ready(info))})
    except (StpmError, OSError, ImportError, RuntimeError):
        return None
    return str(path)


def _cross_check(name: str, other, ref, runs, target_steps: int) -> dict:
    """Every finished run's error and the cost of accuracy against a second reference ``other``.

    other : a Reference or an (H, W, 3|4) array.  Also how far the main reference is from it.
    """
    rgb = other.rgb if isinstance(other, Reference) else combined_rgb(other)
    info = dict(other.info) if isinstance(other, Reference) else {"source": "supplied", "kind": "supplied"}
    if rgb.shape != ref.rgb.shape:
        raise StpmError(f"cross-check reference {name!r} is {rgb.shape[1]}x{rgb.shape[0]}, "
                        f"not {ref.rgb.shape[1]}x{ref.rgb.shape[0]}")
    agreement = image_errors(ref.rgb, rgb)
    agreement.pop("_flip_map")
    shadow = []
    for r in runs:
        errs = dict(r.errors)
        if r.status == "done":
            errs = image_errors(r.rgb.astype(np.float64), rgb)
            errs.pop("_flip_map")
        shadow.append(dataclasses.replace(r, errors=errs, rgb=None, flip_map=None))
    return {"reference": info, "main_reference_error": agreement,
            "runs": {r.label: {m: r.errors.get(m) for m in ("rmse", "relmse", "flip")} for r in shadow},
            "cost": cost_of_accuracy(shadow, target_steps=target_steps)}


def run_compare(scene, settings, out_dir, *, reference=None, time_budget: float | None = None,
                photon_budgets=DEFAULT_PHOTON_BUDGETS, accumulation_steps=DEFAULT_ACCUMULATION_STEPS,
                estimators=PHOTON_ESTIMATORS, k_exponent: float = 0.0, target_steps: int = 16,
                progressive_passes: int = 0,
                progress=None, cancel=None,
                cache_dir=None, use_cache: bool = True,
                reference_method: str = REFERENCE_METHOD, reference_photon_factor: float | None = None,
                reference_sample_factor: float | None = None, reference_steps: int = REFERENCE_STEPS,
                reference_overrides: dict | None = None,
                scene_name: str | None = None, scene_path=None, write_reference: bool = True,
                extra_references: dict | None = None) -> dict:
    """Compare the estimators with the accumulation buffer; write report.html and report.json.

    Parameters
    ----------
    scene, settings : the Scene and its RenderSettings (the file's).
    out_dir : report directory (created).
    reference : None (compute, cached), a path to an EXR (its Combined pass), an (H, W, 3|4) array or a
        Reference (rgb + info: e.g. {'kind': 'analytic', 'why': ...}).
    time_budget : seconds for the sweep (the reference not included); no run starts once spent.
    photon_budgets : budgets of the STANDARD / TEMPORAL / KD4D runs: b (the file's photons x b),
        (b, s) / 'b:s' (photons x b and samples per pixel x s) or (b, s, f) / 'b:s:f' (and k x f).
    k_exponent : e in the photon runs' k = round(f x k x b^e) (0: the file's k; see sweep.budget_k).
    accumulation_steps : the N of the ACCUMULATION runs.
    estimators : which photon estimators to sweep.
    progressive_passes : P > 0 adds the PROGRESSIVE curve (P passes) and the SPPM baseline
        (:mod:`stpm_core.compare.sppm`), each measured pass by pass (0: neither).
    target_steps : the accumulation N whose error the estimators must reach (16).
    progress(fraction, message), cancel() -> bool : as for render; progress spans reference + sweep.
        Cancelling during the sweep still writes the report (unfinished runs marked skipped,
        'cancelled'), then raises RenderCancelled.
    cache_dir, use_cache : computed-reference cache (default ``~/.cache/stpm/references``).
    reference_method, reference_photon_factor, reference_sample_factor, reference_steps,
    reference_overrides : the computed reference's recipe (default: accumulation buffer of 64
        instants x 4 x photons; see :func:`stpm_core.compare.reference.reference_settings`).
    scene_name, scene_path : shown in the report.
    write_reference : also write ``reference.exr`` into out_dir when the reference was computed.
    extra_references : name -> second reference (Reference or (H, W, 3|4) array): a cross-check;
        the report adds each run's error and the cost of accuracy against it, and how far the
        main reference is from it (``cross_references``).

    Returns the report dict (what report.json holds), with ``files`` naming what was written
    (keys html, json and, when written, reference_exr).
    """
    settings.validate()
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise StpmError(f"cannot create report directory {out_dir}: {e.strerror or e}") from None
    runs = plan_runs(settings, photon_budgets=photon_budgets, accumulation_steps=accumulation_steps,
                     estimators=estimators, k_exponent=k_exponent, progressive_passes=progressive_passes)

    # -- Progress: the reference weighs like the stills it costs -----------------------------
    ref_weight = 0.0
    if reference is None:
        rs, _kind = reference_settings(scene, settings, method=reference_method, photon_factor=reference_photon_factor,
                                       sample_factor=reference_sample_factor, steps=reference_steps,
                                       overrides=reference_overrides)
        photons = settings.photons_caustic + settings.photons_global
        p = (rs.photons_caustic + rs.photons_global) / photons if photons else 1.0
        n = rs.accumulation_steps if rs.method == "ACCUMULATION" else 1
        ref_weight = n * 0.5 * (p + rs.samples / settings.samples)     # in stills, like the runs' costs
    sweep_weight = sum(r.cost for r in runs)
    total = (ref_weight + sweep_weight) or 1.0

    def span(a, w, prefix=""):
        if progress is None:
            return None
        return lambda f, msg: progress((a + w * float(f)) / total, prefix + msg)

    # -- Reference -------------------------------------------------------------------------------
    ref = get_reference(scene, settings, reference=reference, cache_dir=cache_dir, use_cache=use_cache,
                        method=reference_method, photon_factor=reference_photon_factor,
                        sample_factor=reference_sample_factor, steps=reference_steps,
                        overrides=reference_overrides, progress=span(0.0, ref_weight, "reference: "),
                        cancel=cancel)
    files = {"html": str(out_dir / "report.html"), "json": str(out_dir / "report.json")}
    if write_reference and ref.info["source"] != "supplied":
        exr = _write_reference_exr(out_dir / "reference.exr", ref.rgb, ref.info)
        if exr is not None:
            files["reference_exr"] = exr

    # -- Sweep --------------------------------------------------------------------------------------
    sweep = run_sweep(scene, runs, ref.rgb, time_budget=time_budget, progress=span(ref_weight, sweep_weight),
                      cancel=cancel)

    # -- Best run per method, consistency, cost of accuracy ------------------------------------------
    methods = [m for m in METHOD_ORDER if any(r.method == m for r in runs)]
    best = {}
    for m in methods:
        done = [r for r in runs if r.method == m and r.status == "done" and r.errors.get("rmse") is not None]
        best[m] = min(done, key=lambda r: r.errors["rmse"]).label if done else None
    consistent = {m: dict(zip(("consistent", "why"), is_consistent(m, settings, scene))) for m in methods}
    cost = cost_of_accuracy(runs, target_steps=target_steps)
    cross = {name: _cross_check(name, other, ref, runs, target_steps)
             for name, other in (extra_references or {}).items()}

    report = json_ready({
        "format": REPORT_FORMAT, "version": REPORT_VERSION,
        "generated_utc": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M:%S UTC"),
        "scene": _scene_info(scene, scene_name, scene_path),
        "settings": settings.to_dict(),
        "reference": {**ref.info, "resolution": [int(ref.rgb.shape[1]), int(ref.rgb.shape[0])]},
        "metrics": {"image": "Combined pass, linear RGB", "rmse": "sqrt(mean((x - r)^2))",
                    "relmse": "mean((x - r)^2 / (r^2 + eps))", "relmse_eps": RELMSE_EPS,
                    "flip": "mean HDR-FLIP error (flip-evaluator)"},
        "display": {"exposure": display_scale(ref.rgb)},
        "sweep": {"photon_budgets": [list(b) for b in sorted({parse_budget(b) for b in photon_budgets})],
                  "k_exponent": float(k_exponent),
                  "accumulation_steps": sorted({int(n) for n in accumulation_steps}),
                  "estimators": list(estimators), "target_steps": int(target_steps),
                  "progressive_passes": int(progressive_passes), **sweep},
        "consistent": consistent,
        "runs": [r.to_json() for r in runs],
        "best": best,
        "cost": cost,
        "cross_references": cross,
        "files": files,
    })

    # -- Write -------------------------------------------------------------------------------------------
    text = json.dumps(report, indent=2, allow_nan=False)
    Path(files["json"]).write_text(text + "\n", encoding="utf-8")
    Path(files["html"]).write_text(render_html(report, ref.rgb, runs), encoding="utf-8")
    if progress is not None:
        progress(1.0, f"report written to {files['html']}")
    if sweep["cancelled"]:
        raise RenderCancelled(f"compare cancelled; partial report written to {files['html']}")
    return report
