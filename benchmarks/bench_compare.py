"""What accuracy costs in time on a moving-caustic scene: time-dependent estimators against the accumulation buffer.

Scene: a point light under a 0.6 x 0.6 mirror (z = 2, facing down) that slides
0.5 m along x during the shutter, so the 1.8 m wide mirror caustic sweeps
1.5 m across the floor; a black shade under the light leaves the view lit by the caustic
only; a diffuse box slides through the caustic the other way (a moving
receiver).  Orthographic view from z = 1.8.

Measured: ``stpm compare`` (stpm_core.compare.run_compare) with ACCUMULATION
N in {1, 4, 16} and TEMPORAL / KD4D (and STANDARD at x1 and x16) at budgets
(photons x b, samples x s); the time each time-dependent estimator needs to
reach ACCUMULATION-16's error (RMSE, relMSE, FLIP), interpolated on its
error-vs-time Pareto front, and the speed-up = ACCUMULATION-16 time / that
time.  The reference is the TEMPORAL recipe (128x photons, 16x samples); as a
cross-check that does not share an estimator with TEMPORAL / KD4D, the same
numbers are also taken against an accumulation buffer of 64 instants with 16x
photons per instant (``check_*``), and ``references_differ_*`` says how far
apart the two references are.  The report lands in ``bench_out/compare_report/``.

    python -m benchmarks compare          # about 5 minutes on 2 cores
"""
from __future__ import annotations

import os
import sys
import time

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(_ROOT, "tests"))

from stpm_core.compare import get_reference, run_compare  # noqa: E402
from stpm_core.scene import Material  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402
from stpm_core.shutter import Shutter  # noqa: E402

RESOLUTION = (96, 64)
BASE = dict(samples=4, photons_caustic=20_000, photons_global=0, k_nearest=30, seed=1,
            effects="MANUAL", caustics=True, indirect=False)
BUDGETS = ((1, 1), (4, 1), (4, 2), (8, 2), (8, 4), (16, 4), (16, 8), (32, 8))
REFERENCE_PHOTONS, REFERENCE_SAMPLES = 128, 16
CHECK_PHOTONS, CHECK_STEPS = 16, 64          # cross-check: ACCUMULATION N=64, 16x photons per instant


def moving_caustic_scene(resolution=RESOLUTION):
    """Mirror sliding x = -0.25 -> 0.25 (the caustic moves 3x that), box sliding x = 0.8 -> -0.8."""
    from scenes import box_mesh, make_scene, moving, ortho_camera_down, plane_mesh, point_light, translate

    mats = [Material.diffuse((0.8, 0.8, 0.8), name="floor"), Material.mirror(name="mirror"),
            Material.diffuse((0.0, 0.0, 0.0), name="shade")]
    objs = [plane_mesh(10.0, z=0.0, material=0, name="floor"),
            (plane_mesh(0.6, z=0.0, material=1, flip=True, name="mirror"), moving((-0.25, 0, 2.0), (0.25, 0, 2.0))),
            (plane_mesh(0.3, z=0.0, material=2, flip=True, name="shade"), translate(0, 0, 0.9)),
            (box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 0.3), material=0, name="box"), moving((0.8, 0, 0), (-0.8, 0, 0)))]
    return make_scene(objs, mats, ortho_camera_down(height=1.8, ortho_scale=2.4),
                      [point_light((0, 0, 1.0), 100.0)], resolution=resolution, shutter=Shutter(1.0, 2.0),
                      metadata={"name": "moving caustic"})


def run(out_dir="bench_out/compare_report", budgets=BUDGETS, resolution=RESOLUTION) -> dict:
    t0 = time.perf_counter()
    scene, settings = moving_caustic_scene(resolution), RenderSettings(**BASE)
    # -- Cross-check reference: accumulation buffer, 64 instants x 16x photons (no TEMPORAL/KD4D in it) --
    check = get_reference(scene, settings, cache_dir="bench_out/cache", photon_factor=CHECK_PHOTONS,
                          sample_factor=1, overrides={"method": "ACCUMULATION", "accumulation_steps": CHECK_STEPS})
    report = run_compare(scene, settings, out_dir,
                         photon_budgets=budgets, accumulation_steps=(1, 4, 16), estimators=("TEMPORAL", "KD4D"),
                         cache_dir="bench_out/cache", reference_photon_factor=REFERENCE_PHOTONS,
                         reference_sample_factor=REFERENCE_SAMPLES, scene_name="moving caustic (bench_compare)",
                         extra_references={"accumulation-64": check})
    out = {"resolution": f"{resolution[0]}x{resolution[1]}", "reference_s": report["reference"].get("wall_s"),
           "reference_source": report["reference"]["source"], "check_reference_s": check.info.get("wall_s")}
    cx = report["cross_references"]["accumulation-64"]
    for m in ("rmse", "relmse", "flip"):
        out[f"references_differ_{m}"] = cx["main_reference_error"][m]
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
        best = cx["cost"]["best_time_dependent"].get(m)
        out[f"check_acc16_{m}"] = cx["cost"]["target"][m]
        out[f"check_best_{m}_estimator"] = best["estimator"] if best else "not reached"
        out[f"check_speedup_{m}"] = best["speedup"] if best else None
    for r in report["runs"]:
        out[f"run {r['label']}"] = f"{r['wall_s']:.2f} s rmse {r['rmse']:.4g} flip {r['flip']:.4g}"
    out["total_s"] = time.perf_counter() - t0
    out["report"] = report["files"]["html"]
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:32s} {v}")
