"""Progressive rendering against the other ways to spend time: error-vs-time curves in one run.

Scenes (``tests/test_compare.py``), each with its exact image (``analytic_moving_caustic``: quadrature,
no photons), 96 x 64:

* moving caustic: a mirror slides, its caustic sweeps the floor, a box slides through it;
* moving receiver: the same with the mirror at rest (a static caustic, the box moving through it).

Methods, every render on the same machine in one run:

* PROGRESSIVE, both kernel forms (TEMPORAL's cylinder, KD4D's ball): passes of PASS_PHOTONS caustic
  photons and PASS_SAMPLES samples per pixel, k = PASS_K, measured after passes 1, 2, 4, ... (the time
  spent measuring taken out);
* SPPM with one shutter instant per pass (pbrt-v4's method, ``stpm_core/compare/sppm.py``): the same
  photons, samples and initial size per pass;
* ACCUMULATION-16: 16 stills, each with its own 250k-photon caustic map and 16 samples per pixel (the
  issue's target);
* fixed-k TEMPORAL at growing budgets (photons and samples together, k = 10 b^(1/4), the measured best
  rule of docs/compare.md).

Figures: each method's error (RMSE against the exact image) at the middle and at the end of the time
axis (log-interpolated on its Pareto front), the time each needs to reach ACCUMULATION-16's error, and
the speed-ups PROGRESSIVE / ACCUMULATION-16 (target >= 8x) and PROGRESSIVE / SPPM (target >= 2x); the
same speed-ups in CPU seconds (``*_cpu_*``: every thread of the process, ``time.process_time``), which
the machine's load moves less than the wall time (at load 12-17 on 2 cores a render's wall time was
2-4x its CPU time, by how busy the machine was during it), and the load average.
The curves go to ``bench_out/progressive_<scene>.svg`` (and .png when ImageMagick can convert).

    python -m benchmarks progressive      # about 6-10 minutes on 2 cores
"""
from __future__ import annotations

import math
import os
import subprocess
import sys
import time

_ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, os.path.join(_ROOT, "tests"))

import numpy as np  # noqa: E402

from stpm_core.compare.costs import pareto_front, time_to_reach  # noqa: E402
from stpm_core.compare.plots import error_vs_time_svg  # noqa: E402
from stpm_core.compare.sppm import render_sppm  # noqa: E402
from stpm_core.compare.sweep import checkpoints  # noqa: E402
from stpm_core.render import render  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402

from test_compare import analytic_moving_caustic, moving_caustic_scene  # noqa: E402  (tests/ on sys.path)

RESOLUTION = (96, 64)
SCENES = {"moving caustic": (-0.25, 0.25), "moving receiver": (0.0, 0.0)}
COMMON = dict(photons_global=0, seed=1, effects="MANUAL", caustics=True, indirect=False)
PASS_PHOTONS, PASS_SAMPLES, PASS_K = 12_500, 1, 20     # many small passes (measured best: docs/compare.md)
PASSES = 1024
SPPM_PASSES = 1024
ACC16 = dict(accumulation_steps=16, samples=16, photons_caustic=250_000, k_nearest=30)
FIXED = ((20_000, 4), (80_000, 8), (320_000, 16), (1_280_000, 32), (5_120_000, 64))   # (photons, samples)


def _rmse(img, ref) -> float:
    return float(np.sqrt(np.mean((np.asarray(img, np.float64)[:, :, :3] - ref) ** 2)))


def _exact(mirror):
    path = f"bench_out/cache/exact_{RESOLUTION[0]}x{RESOLUTION[1]}_{mirror[0]:g}_{mirror[1]:g}.npy"
    if os.path.exists(path):
        return np.load(path)
    img = analytic_moving_caustic(RESOLUTION, mirror=mirror)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    np.save(path, img)
    return img


def _curve(fn, scene, settings, ref, passes):
    """([(seconds, rmse, label)], [(CPU seconds, rmse, label)]) after passes 1, 2, 4, ... of a progressive
    render (the time spent measuring taken out of both)."""
    marks, pts, cpu, spent, cpu_spent = checkpoints(passes), [], [], [0.0], [0.0]
    c0 = time.process_time()

    def on_pass(img, info):
        if info["pass"] in marks:
            t0, u0 = time.perf_counter(), time.process_time()
            e = _rmse(img["Combined"], ref)
            pts.append((info["elapsed_s"] - spent[0], e, f"pass {info['pass']}"))
            cpu.append((u0 - c0 - cpu_spent[0], e, f"pass {info['pass']}"))
            spent[0] += time.perf_counter() - t0
            cpu_spent[0] += time.process_time() - u0
    fn(scene, settings, on_pass=on_pass)
    return pts, cpu


def _timed_render(scene, settings):
    """(RenderResult, its CPU seconds: every thread of this process, :func:`time.process_time`)."""
    c0 = time.process_time()
    r = render(scene, settings)
    return r, time.process_time() - c0


def _error_at(pts, t: float) -> float | None:
    """The error of a curve's Pareto front at time t (log-log interpolation; None before its first point)."""
    front = pareto_front([(a, b) for a, b, *_ in pts])
    if not front or t < front[0][0]:
        return None
    for (t0, e0), (t1, e1) in zip(front, front[1:]):
        if t0 <= t <= t1:
            w = (math.log(t) - math.log(t0)) / (math.log(t1) - math.log(t0))
            return math.exp(math.log(e0) + w * (math.log(e1) - math.log(e0)))
    return front[-1][1]


def _warm(scene):
    """Compile / load every code path once, untimed."""
    small = moving_caustic_scene((24, 16))
    base = RenderSettings(**COMMON, photons_caustic=2000, samples=1, k_nearest=10)
    for st in (base.replace(method="PROGRESSIVE", passes=2), base.replace(method="PROGRESSIVE", passes=2,
                                                                          estimator="KD4D"),
               base.replace(method="ACCUMULATION", accumulation_steps=2), base):
        render(small, st)
    render_sppm(small, base.replace(passes=2))


def run_scene(name, mirror) -> tuple[dict, dict]:
    scene = moving_caustic_scene(RESOLUTION, mirror=mirror)
    ref = _exact(mirror)
    load0 = os.getloadavg()[0]
    series, cpu = {}, {}        # method -> [(wall seconds, rmse, label)], [(CPU seconds, rmse, label)]
    # -- Progressive, both kernel forms; SPPM -------------------------------------------------------
    prog = RenderSettings(**COMMON, method="PROGRESSIVE", passes=PASSES, photons_caustic=PASS_PHOTONS,
                          samples=PASS_SAMPLES, k_nearest=PASS_K)
    series["PROGRESSIVE"], cpu["PROGRESSIVE"] = _curve(render, scene, prog, ref, PASSES)
    series["PROGRESSIVE KD4D"], cpu["PROGRESSIVE KD4D"] = _curve(render, scene, prog.replace(estimator="KD4D"),
                                                                 ref, PASSES)
    sppm = RenderSettings(**COMMON, passes=SPPM_PASSES, photons_caustic=PASS_PHOTONS, samples=1, k_nearest=PASS_K)
    series["SPPM"], cpu["SPPM"] = _curve(render_sppm, scene, sppm, ref, SPPM_PASSES)
    # -- Accumulation buffer of 16 stills, fixed-k TEMPORAL budgets ----------------------------------
    acc, acc_cpu = _timed_render(scene, RenderSettings(**COMMON, method="ACCUMULATION", **ACC16))
    acc_pt = (acc.stats["wall_s"], _rmse(acc.passes["Combined"], ref), "ACCUMULATION-16")
    series["ACCUMULATION"], cpu["ACCUMULATION"] = [acc_pt], [(acc_cpu,) + acc_pt[1:]]
    series["TEMPORAL"], cpu["TEMPORAL"] = [], []
    for photons, samples in FIXED:
        b = photons / FIXED[0][0]
        st = RenderSettings(**COMMON, method="PHOTON", estimator="TEMPORAL", photons_caustic=photons, samples=samples,
                            k_nearest=max(1, round(10 * b ** 0.25)))
        r, r_cpu = _timed_render(scene, st)
        e, lbl = _rmse(r.passes["Combined"], ref), f"{photons // 1000}k s{samples}"
        series["TEMPORAL"].append((r.stats["wall_s"], e, lbl))
        cpu["TEMPORAL"].append((r_cpu, e, lbl))
    # -- Figures ----------------------------------------------------------------------------------------
    t_max = min(max(p[0] for p in pts) for pts in series.values() if len(pts) > 1)
    t_mid = math.sqrt(min(p[0] for pts in series.values() for p in pts) * t_max)
    out = {"acc16_s": acc_pt[0], "acc16_rmse": acc_pt[1], "t_mid_s": t_mid, "t_end_s": t_max,
           "load": f"{load0:.1f} -> {os.getloadavg()[0]:.1f}"}
    reach = {}
    for key, pts in series.items():
        tag = key.lower().replace(" ", "_")
        out[f"{tag}_rmse_at_mid"] = _error_at(pts, t_mid)
        out[f"{tag}_rmse_at_end"] = _error_at(pts, t_max)
        reach[key], bound = time_to_reach([(a, b) for a, b, *_ in pts], acc_pt[1])
        out[f"{tag}_time_to_acc16_s"] = reach[key]
        out[f"{tag}_points"] = " ".join(f"{lbl}:{e:.4f}@{t:.2f}s" for t, e, lbl in pts)
    # the same in CPU seconds (every thread of the process): at a load of 8-14 on 2 cores the wall
    # time measures the scheduler as much as the work (docs/photon-mapping.md, "Error budget")
    reach_cpu = {key: time_to_reach([(a, b) for a, b, *_ in pts], acc_pt[1])[0] for key, pts in cpu.items()}
    out["acc16_cpu_s"] = acc_cpu
    for form in ("PROGRESSIVE", "PROGRESSIVE KD4D"):
        tag = form.lower().replace(" ", "_")
        t = reach[form]
        out[f"{tag}_speedup_vs_acc16"] = acc_pt[0] / t if t else None
        out[f"{tag}_speedup_vs_sppm"] = (reach["SPPM"] / t) if (t and reach["SPPM"]) else None
        t = reach_cpu[form]
        out[f"{tag}_cpu_time_to_acc16_s"] = t
        out[f"{tag}_cpu_speedup_vs_acc16"] = acc_cpu / t if t else None
        out[f"{tag}_cpu_speedup_vs_sppm"] = (reach_cpu["SPPM"] / t) if (t and reach_cpu["SPPM"]) else None
    lowest = {}
    for when in ("mid", "end"):
        vals = {k: out[f"{k.lower().replace(' ', '_')}_rmse_at_{when}"] for k in series if k != "ACCUMULATION"}
        vals = {k: v for k, v in vals.items() if v is not None}
        lowest[when] = min(vals, key=vals.get) if vals else None
        out[f"lowest_at_{when}"] = lowest[when]
    return out, series


def _plot(name, series, target):
    os.makedirs("bench_out", exist_ok=True)
    svg = error_vs_time_svg({k: v for k, v in series.items()}, ylabel="RMSE against the exact image",
                            target=(target, "ACCUMULATION-16 (250k photons, 16 spp per still)"),
                            title=f"{name}: error against render time", width=720, height=440)
    base = f"bench_out/progressive_{name.replace(' ', '_')}"
    with open(base + ".svg", "w") as f:
        f.write(svg)
    try:
        subprocess.run(["convert", base + ".svg", base + ".png"], check=True, capture_output=True, timeout=60)
        return base + ".png"
    except (OSError, subprocess.SubprocessError):
        return base + ".svg"


def run() -> dict:
    t0 = time.perf_counter()
    _warm(None)
    out = {"resolution": f"{RESOLUTION[0]}x{RESOLUTION[1]}",
           "pass": f"{PASS_PHOTONS} caustic photons, {PASS_SAMPLES} spp, k = {PASS_K}",
           "targets": "PROGRESSIVE reaches ACCUMULATION-16 >= 8x sooner, SPPM >= 2x sooner; lowest from mid-axis"}
    for name, mirror in SCENES.items():
        res, series = run_scene(name, mirror)
        out.update({f"{name}: {k}": v for k, v in res.items()})
        out[f"{name}: plot"] = _plot(name, series, res["acc16_rmse"])
    out["total_s"] = time.perf_counter() - t0
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:48s} {v}")
