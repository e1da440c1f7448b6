"""``stpm compare`` sweep: budgets with a k factor, k growing with the photon budget (``k_exponent``).

The photon runs may use any k (ACCUMULATION keeps the file's): k = round(f x k_file x b^e)
for a budget (b photons x, s samples x, f k x) and the sweep's exponent e.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from stpm_core.compare import run_compare
from stpm_core.compare.sweep import budget_k, budget_label, parse_budget, plan_runs
from stpm_core.errors import StpmError
from stpm_core.render import render
from stpm_core.settings import RenderSettings
from test_compare import caustic_settings, moving_receiver_scene


def test_parse_budget_forms_and_errors():
    assert parse_budget(4) == (4.0, 1.0, 1.0)
    assert parse_budget("4:2") == parse_budget((4, 2)) == (4.0, 2.0, 1.0)
    assert parse_budget("16:2:0.5") == parse_budget([16, 2, 0.5]) == (16.0, 2.0, 0.5)
    for bad in ("1:2:3:4", "4:2:0", "4::1", (4, 2, -1), (), "x", float("inf")):
        with pytest.raises(StpmError):
            parse_budget(bad)


def test_budget_k_rule():
    assert budget_k(30, 64) == 30                                  # exponent 0: the file's k
    assert budget_k(30, 8, 1.0, 1 / 3) == 60                       # 30 x 8^(1/3)
    assert budget_k(30, 16, 0.5) == 15                             # k factor only
    assert budget_k(30, 64, 0.2, 1 / 3) == 24                      # 0.2 x 30 x 4
    assert budget_k(30, 1, 0.001) == 1                             # never below 1
    with pytest.raises(StpmError):
        budget_k(30, 4, 1.0, -0.5)
    assert budget_label(16, 2, 15) == "x16 s2 k15" and budget_label(4) == "x4"


def test_plan_runs_k_factor_and_exponent_leave_accumulation_alone():
    st = caustic_settings(k_nearest=30, samples=4)
    runs = plan_runs(st, photon_budgets=(1, "16:2:0.5", (16, 2), "64:8"), accumulation_steps=(1, 16),
                     estimators=("KD4D",), k_exponent=1 / 3)
    by = {r.label: r for r in runs}
    assert set(by) == {"KD4D x1", "KD4D x16 s2 k38", "KD4D x16 s2 k76", "KD4D x64 s8 k120",
                       "ACCUMULATION N=1", "ACCUMULATION N=16"}
    r = by["KD4D x16 s2 k38"]
    assert (r.settings.photons_caustic, r.settings.samples, r.settings.k_nearest, r.k_factor) == (64000, 8, 38, 0.5)
    assert by["KD4D x1"].settings.k_nearest == 30                  # b = 1: b^e = 1
    for n in (1, 16):                                              # ACCUMULATION: the file's settings, k included
        a = by[f"ACCUMULATION N={n}"].settings
        assert (a.k_nearest, a.samples, a.photons_caustic) == (30, 4, st.photons_caustic)
    assert by["KD4D x16 s2 k38"].to_json()["k_nearest"] == 38
    # two budgets that land on the same run are planned once
    twice = plan_runs(st, photon_budgets=("4:1:0.5", "4:1:0.51"), accumulation_steps=(1,), estimators=("KD4D",))
    assert [r.label for r in twice] == ["ACCUMULATION N=1", "KD4D x4 k15"]


def test_larger_k_lowers_the_variance_of_a_photon_run():
    """A real outcome: with the k the plan gives (x8 photons, e = 1 -> k = 8 x 4 = 32 vs the file's 4) the
    pixel variance between two seeds falls about k-fold where the caustic is flat."""
    scene = moving_receiver_scene((24, 16))
    st = caustic_settings(k_nearest=4, samples=1, photons_caustic=1000)
    imgs = {}
    for e in (0.0, 1.0):
        (run,) = [r for r in plan_runs(st, photon_budgets=(8,), accumulation_steps=(), estimators=("KD4D",),
                                       k_exponent=e)]
        imgs[e] = [render(scene, run.settings.replace(seed=seed)).passes["Combined"][..., :3] for seed in (1, 2)]
        assert run.settings.k_nearest == (4 if e == 0 else 32)
    var = {e: float(np.mean((a - b) ** 2)) for e, (a, b) in imgs.items()}
    assert var[1.0] < 0.35 * var[0.0]


def test_run_compare_records_k_exponent(tmp_path):
    from test_compare import emitter_scene

    scene = emitter_scene((16, 8))
    st = RenderSettings(samples=1, photons_caustic=0, photons_global=0, seed=2, k_nearest=10)
    ref = np.ones((8, 16, 3))
    rep = run_compare(scene, st, tmp_path, reference=ref, photon_budgets=("2:1:0.5",), accumulation_steps=(1,),
                      estimators=("KD4D",), k_exponent=1.0)
    data = json.loads((tmp_path / "report.json").read_text())
    assert data == rep and rep["sweep"]["k_exponent"] == 1.0
    assert rep["sweep"]["photon_budgets"] == [[2.0, 1.0, 0.5]]
    kd = next(r for r in rep["runs"] if r["method"] == "KD4D")
    assert kd["label"] == "KD4D x2" and kd["k_nearest"] == 10 and kd["k_factor"] == 0.5   # 0.5 x 10 x 2 = 10
    assert "k x0.5" in (tmp_path / "report.html").read_text()


def test_warm_up_renders_each_code_path_once_tiny(monkeypatch):
    import stpm_core.render as render_mod
    from stpm_core.compare.sweep import WARM_UP_RESOLUTION, run_sweep, warm_up

    calls = []
    real = render_mod.render

    def spy(scene, settings, **kw):
        calls.append((scene.resolution, settings))
        return real(scene, settings, **kw)

    monkeypatch.setattr(render_mod, "render", spy)
    scene = moving_receiver_scene((24, 16))
    st = caustic_settings(photons_caustic=8000)
    runs = plan_runs(st, photon_budgets=(1, 4), accumulation_steps=(1, 4), estimators=("TEMPORAL", "KD4D"))
    assert warm_up(scene, runs) > 0
    assert sorted((s.method, s.estimator) for _, s in calls) == [("ACCUMULATION", "TEMPORAL"),
                                                                 ("PHOTON", "KD4D"), ("PHOTON", "TEMPORAL")]
    assert all(tuple(r) == WARM_UP_RESOLUTION and s.samples == 1 and s.photons_caustic == 2000
               and s.accumulation_steps == 1 for r, s in calls)
    # run_sweep warms up before its clock starts, and not at all when the budget allows no run
    ref = np.zeros((16, 24, 3))
    calls.clear()
    out = run_sweep(scene, runs[:1], ref, with_flip=False)
    assert out["warm_up_s"] > 0 and len(calls) == 2 and runs[0].status == "done"
    calls.clear()
    out = run_sweep(scene, plan_runs(st, photon_budgets=(1,), accumulation_steps=(), estimators=("KD4D",)), ref,
                    time_budget=0.0, with_flip=False)
    assert out["warm_up_s"] == 0.0 and calls == []
