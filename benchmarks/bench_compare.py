"""What accuracy costs in time on a moving caustic: time-dependent estimators against the accumulation buffer.

Scene (``tests/test_compare.py: moving_caustic_scene``): a point light under a
0.6 x 0.6 mirror (z = 2, facing down) that slides 0.5 m along x during the
shutter, so the 1.8 m wide mirror caustic sweeps 1.5 m across the floor; a
black shade under the light leaves the view lit by the caustic only; a
diffuse box slides through the caustic the other way (a moving receiver).
Orthographic view from z = 1.8, 96 x 64.

Measured, part A: ``stpm compare`` (stpm_core.compare.run_compare) with the
file's settings (4 samples/pixel, 20k caustic photons, k = 30), ACCUMULATION N
in {1, 4, 16} and TEMPORAL / KD4D at budgets (photons x b, samples x s) with
the file's k and with k = 10 b^(1/4) (``K_RULE``: the measured optimum, see
docs/compare.md); the time each time-dependent estimator needs to reach
ACCUMULATION-16's error (RMSE, relMSE, FLIP), interpolated on its
error-vs-time Pareto front, and the speed-up = ACCUMULATION-16 time / that
time (the issue's target: >= 8x).

Part B, the speed-up as a function of the file's samples per pixel S: the
same time-dependent runs against ACCUMULATION-16 rendered with S in
``SAMPLES_PER_STILL`` (every other setting the file's).  ACCUMULATION-16's
error hardly depends on S on this scene (its photons dominate it), its time
is about proportional to S.

The reference is the scene's exact image (``analytic_moving_caustic``:
quadrature over space and time, no photons, no estimator), so no method is
flattered.  The two computed reference recipes are measured against it too
(``acc_ref_*``: the default, an accumulation buffer of 64 instants x 4x
photons; ``temporal_ref_*``: TEMPORAL with 128x photons and 16x samples).
The report lands in ``bench_out/compare_report/``.

    python -m benchmarks compare      # about 2 minutes on 2 cores (references cached after the first)
"""
from __future__ import annotations

import os
import sys
import time

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(_ROOT, "tests"))

import numpy as np  # noqa: E402

from stpm_core.compare import (Reference, cost_of_accuracy, get_reference, plan_runs, run_compare,  # noqa: E402
                               run_sweep)
from stpm_core.compare.sweep import Run  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402

from test_compare import analytic_moving_caustic, moving_caustic_scene  # noqa: E402  (tests/ on sys.path)

RESOLUTION = (96, 64)
BASE = dict(samples=4, photons_caustic=20_000, photons_global=0, k_nearest=30, seed=1,
            effects="MANUAL", caustics=True, indirect=False)
# (photons x, samples x) with the file's k
BUDGETS = ((1, 1), (4, 1), (4, 2), (8, 2), (8, 4), (16, 4), (16, 8), (32, 8), (64, 8))
# (photons x, samples x) with k = K_RULE(b): the measured optimum (bias at edges dominates: small k pays)
K_RULE = (10.0, 0.25)                                    # k = 10 b^(1/4)
TUNED_BUDGETS = ((4, 2), (4, 4), (8, 4), (16, 4), (32, 4), (32, 8), (64, 8))
SAMPLES_PER_STILL = (1, 2, 4, 8, 16, 64)                 # part B: ACCUMULATION-16 with these samples/pixel
TEMPORAL_REF_PHOTONS, TEMPORAL_REF_SAMPLES = 128, 16     # cross-check: the TEMPORAL reference recipe


def k_rule_budgets(k_file: int, budgets=TUNED_BUDGETS, rule=K_RULE):
    """(b, s, f) with f x k_file = rule[0] x b^rule[1] (the sweep's k factor)."""
    return tuple((b, s, rule[0] * b ** rule[1] / k_file) for b, s in budgets)


def _runs_from_report(report):
    """Run records (no images) from report['runs'], enough for cost_of_accuracy."""
    return [Run(label=r["label"], method=r["method"], settings=None, accumulation_steps=r["accumulation_steps"],
                status=r["status"], wall_s=r["wall_s"], errors={m: r[m] for m in ("rmse", "relmse", "flip")})
            for r in report["runs"]]


def _exact(resolution):
    """The analytic image, cached in bench_out/cache (it is deterministic)."""
    path = f"bench_out/cache/exact_{resolution[0]}x{resolution[1]}.npy"
    if os.path.exists(path):
        return np.load(path)
    img = analytic_moving_caustic(resolution)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    np.save(path, img)
    return img


def run(out_dir="bench_out/compare_report", budgets=BUDGETS, tuned_budgets=TUNED_BUDGETS, resolution=RESOLUTION,
        samples_per_still=SAMPLES_PER_STILL) -> dict:
    t0 = time.perf_counter()
    scene, settings = moving_caustic_scene(resolution), RenderSettings(**BASE)
    # -- References: the exact image (main) and two computed recipes (cross-checks, cached) ---------
    t1 = time.perf_counter()
    exact = _exact(resolution)
    analytic_s = time.perf_counter() - t1
    acc_ref = get_reference(scene, settings, cache_dir="bench_out/cache")                 # default recipe
    tmp_ref = get_reference(scene, settings, cache_dir="bench_out/cache", method="TEMPORAL",
                            photon_factor=TEMPORAL_REF_PHOTONS, sample_factor=TEMPORAL_REF_SAMPLES)
    exact_ref = Reference(exact, {"kind": "analytic", "why": "the exact image: quadrature over the shutter (256 "
                                  "instants) and the pixel filter (8 x 8 points per pixel) of the caustic and "
                                  "direct irradiance, derived from the geometry (tests/test_compare.py)."})
    report = run_compare(scene, settings, out_dir, reference=exact_ref,
                         photon_budgets=tuple(budgets) + k_rule_budgets(settings.k_nearest, tuned_budgets),
                         accumulation_steps=(1, 4, 16), estimators=("TEMPORAL", "KD4D"),
                         scene_name="moving caustic (bench_compare), analytic reference",
                         extra_references={"default recipe (accumulation, 64 x 4x photons)": acc_ref,
                                           "temporal recipe (128x photons, 16x samples)": tmp_ref})
    out = {"resolution": f"{resolution[0]}x{resolution[1]}", "analytic_s": analytic_s, "target_speedup": 8.0}
    # -- How good are the computed references? (their error against the exact image) ------------------
    for tag, (name, ref) in {"acc_ref": ("default recipe (accumulation, 64 x 4x photons)", acc_ref),
                             "temporal_ref": ("temporal recipe (128x photons, 16x samples)", tmp_ref)}.items():
        cx = report["cross_references"][name]
        out[f"{tag}_s"] = ref.info.get("wall_s")
        for m in ("rmse", "relmse", "flip"):
            out[f"{tag}_{m}"] = cx["main_reference_error"][m]
        out[f"{tag}_mean_rel"] = float((ref.rgb - exact).mean() / exact.mean())
    # -- Cost of accuracy against the exact image ----------------------------------------------------------
    tgt = report["cost"]["target"]
    out["acc16_s"] = tgt["wall_s"]
    for m in ("rmse", "relmse", "flip"):
        out[f"acc16_{m}"] = tgt[m]
        best = report["cost"]["best_time_dependent"].get(m)
        out[f"best_{m}_estimator"] = best["estimator"] if best else "not reached"
        out[f"best_{m}_time_s"] = best["time_s"] if best else None
        out[f"speedup_{m}"] = best["speedup"] if best else None
        for est, v in report["cost"]["metrics"][m].items():
            out[f"{est.lower()}_{m}_time_s"] = v["time_s"]
    for r in report["runs"]:
        out[f"run {r['label']}"] = (f"{r['wall_s']:.2f} s rmse {r['rmse']:.4g} relmse {r['relmse']:.4g} "
                                    f"flip {r['flip']:.4g}") if r["status"] == "done" else r["status"]
    # -- Part B: the speed-up against ACCUMULATION-16 rendered with S samples per pixel ---------------------
    td_runs = [r for r in _runs_from_report(report) if r.method != "ACCUMULATION"]
    acc_plain = next(r for r in _runs_from_report(report) if r.label == "ACCUMULATION N=16")
    for S in samples_per_still:
        if S == settings.samples:
            acc = acc_plain
        else:
            (acc,) = plan_runs(settings.replace(samples=S), photon_budgets=(), accumulation_steps=(16,), estimators=())
            run_sweep(scene, [acc], exact)
        cost = cost_of_accuracy(td_runs + [acc], target_steps=16)
        e = acc.errors
        out[f"S={S} acc16"] = f"{acc.wall_s:.2f} s rmse {e['rmse']:.4g} relmse {e['relmse']:.4g} flip {e['flip']:.4g}"
        for m in ("rmse", "relmse", "flip"):
            best = cost["best_time_dependent"].get(m)
            out[f"S={S} speedup_{m}"] = best["speedup"] if best else None
    out["total_s"] = time.perf_counter() - t0
    out["report"] = report["files"]["html"]
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:32s} {v}")
