"""``stpm compare``: metrics, reference, sweep, cost of accuracy and the report (HTML + JSON).

Scene used by the sweep tests (tiny, 48 x 32): a point light at z = 1 under a
1 x 1 mirror at z = 2 facing down, a black shade just below the light (so the
view is lit by the mirror caustic only), and a diffuse box sliding through the
caustic during the shutter: a moving receiver.  STANDARD ignores photon times,
so on the box and on the floor the box shadows it is biased whatever the
photon count; TEMPORAL and KD4D are consistent.

To measure the *estimators'* error rather than camera noise, the reference in
the sweep fixture uses the runs' own seed and samples (the camera samples are
then the same in every photon run and the reference) and 64 x their photons.
"""
from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from scenes import box_mesh, make_scene, moving, ortho_camera_down, plane_mesh, point_light, translate
from stpm_core.compare import cost_of_accuracy, get_reference, run_compare, time_to_reach
from stpm_core.compare.metrics import RELMSE_EPS, image_errors, relmse, rmse
from stpm_core.compare.plots import error_vs_time_svg
from stpm_core.compare.reference import reference_settings
from stpm_core.compare.report_html import png_bytes
from stpm_core.compare.sweep import Run, plan_runs
from stpm_core.errors import StpmError
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

SECTIONS = ("scene", "images", "error-maps", "plot", "table", "cost", "runs")
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")


# ----------------------------------------------------------------------------
# Scenes and settings
# ----------------------------------------------------------------------------
def moving_receiver_scene(resolution=(48, 32)):
    """Mirror caustic on a floor and on a box sliding x = -0.8 -> 0.8 over the shutter; ortho view from z = 1.8."""
    mats = [Material.diffuse((0.8, 0.8, 0.8), name="floor"), Material.mirror(name="mirror"),
            Material.diffuse((0.0, 0.0, 0.0), name="shade")]
    objs = [plane_mesh(10.0, z=0.0, material=0, name="floor"),
            (plane_mesh(1.0, z=0.0, material=1, flip=True, name="mirror"), translate(0, 0, 2.0)),
            (plane_mesh(0.3, z=0.0, material=2, flip=True, name="shade"), translate(0, 0, 0.9)),
            (box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 0.3), material=0), moving((-0.8, 0, 0), (0.8, 0, 0)))]
    return make_scene(objs, mats, ortho_camera_down(height=1.8, ortho_scale=2.4),
                      [point_light((0, 0, 1.0), 100.0)], resolution=resolution, shutter=Shutter(1.0, 2.0))


def caustic_settings(**kw):
    d = dict(samples=4, photons_caustic=4000, photons_global=0, k_nearest=30, seed=1,
             effects="MANUAL", caustics=True, indirect=False)
    d.update(kw)
    return RenderSettings(**d)


def moving_caustic_scene(resolution=(96, 64), mirror=(-0.25, 0.25)):
    """The benchmark's moving caustic: a point light at z = 1 under a 0.6 x 0.6 mirror (z = 2, facing
    down) sliding x = -0.25 -> 0.25 over the shutter, so the 1.8 m wide caustic moves 3x that on the
    floor; a black shade under the light (the view gets caustic light only); a diffuse box sliding
    x = 0.8 -> -0.8 through it.  Ortho view from z = 1.8, x in [-1.2, 1.2] (W:H must be 3:2).
    ``mirror``: the mirror centre's x at the shutter's open and close ((0, 0): a static caustic and a
    moving receiver only)."""
    mats = [Material.diffuse((0.8, 0.8, 0.8), name="floor"), Material.mirror(name="mirror"),
            Material.diffuse((0.0, 0.0, 0.0), name="shade")]
    objs = [plane_mesh(10.0, z=0.0, material=0, name="floor"),
            (plane_mesh(0.6, z=0.0, material=1, flip=True, name="mirror"),
             moving((mirror[0], 0, 2.0), (mirror[1], 0, 2.0))),
            (plane_mesh(0.3, z=0.0, material=2, flip=True, name="shade"), translate(0, 0, 0.9)),
            (box_mesh((-0.3, -0.3, 0.0), (0.3, 0.3, 0.3), material=0, name="box"), moving((0.8, 0, 0), (-0.8, 0, 0)))]
    return make_scene(objs, mats, ortho_camera_down(height=1.8, ortho_scale=2.4),
                      [point_light((0, 0, 1.0), 100.0)], resolution=resolution, shutter=Shutter(1.0, 2.0),
                      metadata={"name": "moving caustic"})


def moving_caustic_radiance(x, y, t, mirror=(-0.25, 0.25)):
    """Exact radiance (W m^-2 sr^-1) of :func:`moving_caustic_scene` seen from above at (x, y) and
    normalised shutter time t (arrays broadcast together): the terms :func:`analytic_moving_caustic`
    integrates (its docstring derives them)."""
    I = 100.0 / (4 * np.pi)                               # point-light intensity (W/sr)
    shade = (np.abs(x) < 0.15) & (np.abs(y) < 0.15)
    c = mirror[0] + (mirror[1] - mirror[0]) * t           # mirror centre (x)
    b = 0.8 - 1.6 * t                                     # box centre (x)
    on_box = (np.abs(x - b) < 0.3) & (np.abs(y) < 0.3) & ~shade
    z = np.where(on_box, 0.3, 0.0)
    # -- Caustic: virtual source through the moving aperture ----------------------------
    h = 3.0 - z
    E_c = I * h / (x * x + y * y + h * h) ** 1.5
    aperture = (np.abs(x / h - c) < 0.3) & (np.abs(y / h) < 0.3)
    shaded = (np.abs(2.1 * x / h) < 0.15) & (np.abs(2.1 * y / h) < 0.15)
    # floor point behind the box: f = 1 - 0.1 u in [0.9, 1] with f |y| < 0.3 and |f x - b| < 0.3
    with np.errstate(divide="ignore", invalid="ignore"):
        f_hi = np.minimum(1.0, np.where(y != 0, 0.3 / np.abs(y), np.inf))
        a1, a2 = (b - 0.3) / x, (b + 0.3) / x
        lo = np.maximum(0.9, np.where(x > 0, a1, np.where(x < 0, a2, -np.inf)))
        hi = np.minimum(f_hi, np.where(x > 0, a2, np.where(x < 0, a1, np.inf)))
    behind_box = (lo < hi) & ~on_box & ~((x == 0) & (np.abs(b) >= 0.3))
    E = np.where(aperture & ~shaded & ~behind_box, E_c, 0.0)
    # -- Direct light, unless the shade is in the way -------------------------------------
    hl = 1.0 - z
    lit = ~((np.abs(0.1 * x / hl) < 0.15) & (np.abs(0.1 * y / hl) < 0.15))
    E = E + np.where(lit, I * hl / (x * x + y * y + hl * hl) ** 1.5, 0.0)
    return np.where(shade, 0.0, 0.8 / np.pi * E)


def analytic_moving_caustic(resolution=(96, 64), filter_width: float = 1.5, sub: int = 8,
                            n_t: int = 256, mirror=(-0.25, 0.25)) -> np.ndarray:
    """The exact pixel values (H, W, 3) of :func:`moving_caustic_scene`, by quadrature (no photons).

    Seen from the ortho camera (x in [-1.2, 1.2], y in [-0.8, 0.8], row 0 = top)
    each point is the black shade (|x|, |y| < 0.15), the box top (z = 0.3,
    |x - b(t)| < 0.3, |y| < 0.3, b(t) = 0.8 - 1.6 t) or the floor (z = 0), all
    diffuse rho = 0.8, radiance rho / pi * E.  Irradiance E at p = (x, y, z):

    * caustic: the light's mirror image V = (0, 0, 3) seen through the mirror
      aperture (|x s - c(t)| < 0.3, |y s| < 0.3 at s = 1 / (3 - z),
      c(t) = -0.25 + 0.5 t, or ``mirror``'s), E = I (3 - z) / |p - V|^3, I = P / (4 pi);
      blocked by the shade (|x|, |y| s' < 0.15 at s' = 2.1 / (3 - z)) and,
      for the floor, by the box (the path from (x, y, 0) to (0.9 x, 0.9 y, 0.3)
      crossing its footprint);
    * direct: I (1 - z) / |p - L|^3 from L = (0, 0, 1) unless the shade is in the
      way (|x|, |y| 0.1 / (1 - z) < 0.15).

    Time: ``n_t`` midpoints over the shutter; space: ``sub`` x ``sub`` points per
    pixel, then the film's separable Blackman-Harris filter (radius
    ``filter_width`` pixels, normalised over the points inside the image).
    """
    from stpm_core.film import blackman_harris

    W, H = resolution
    pix = 2.4 / W
    # -- Fine grid: sub x sub points per pixel -------------------------------------------
    u = (np.arange(W * sub) + 0.5) / sub                  # continuous pixel coordinates
    v = (np.arange(H * sub) + 0.5) / sub
    x, y = np.meshgrid(-1.2 + u * pix, 0.8 - v * pix)
    F = np.zeros_like(x)
    for t in (np.arange(n_t) + 0.5) / n_t:
        F += moving_caustic_radiance(x, y, t, mirror)
    F /= n_t

    # -- Pixel filter: separable Blackman-Harris over the fine points inside the image ---------
    def weights(n, coords):
        w = blackman_harris(coords[None, :] - (np.arange(n) + 0.5)[:, None], filter_width)
        return w / w.sum(1, keepdims=True)

    img = weights(H, v) @ F @ weights(W, u).T
    return np.repeat(img[:, :, None], 3, axis=2)


def emitter_scene(resolution=(24, 16)):
    """An emissive slab moving under an ortho camera: no photon map is needed (ray-traced reference)."""
    slab = box_mesh((-0.2, -5, -0.1), (0.2, 5, 0.1))
    return make_scene([(slab, moving((-0.6, 0, 0), (0.6, 0, 0)))], [Material.emitter((1.0, 1.0, 1.0))],
                      ortho_camera_down(ortho_scale=2.0), resolution=resolution, shutter=Shutter(1.0, 2.0))


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """One full sweep on the moving-receiver scene: the report and its directory."""
    out = tmp_path_factory.mktemp("compare")
    scene, st = moving_receiver_scene(), caustic_settings()
    # an estimator-neutral second reference: accumulation buffer, 16 instants x 16x photons
    check = get_reference(scene, st, cache_dir=out / "cache", method="ACCUMULATION", steps=16,
                          photon_factor=16, sample_factor=1)
    report = run_compare(scene, st, out / "report",
                         photon_budgets=(1, 4, 16), accumulation_steps=(1, 4, 16), cache_dir=out / "cache",
                         reference_method="TEMPORAL", reference_photon_factor=64, reference_sample_factor=1,
                         reference_overrides={"seed": 1}, scene_name="moving receiver",
                         extra_references={"accumulation-16": check})
    return report, out / "report"


def _run(report, label):
    return next(r for r in report["runs"] if r["label"] == label)


# ----------------------------------------------------------------------------
# Metrics
# ----------------------------------------------------------------------------
def test_metrics_against_analytic_values():
    rng = np.random.default_rng(0)
    r = rng.uniform(0.1, 2.0, (16, 24, 3))
    x = r + 0.1                                      # constant offset: RMSE = 0.1 exactly
    assert rmse(x, r) == pytest.approx(0.1, rel=1e-12)
    assert relmse(x, r) == pytest.approx(np.mean(0.01 / (r ** 2 + RELMSE_EPS)), rel=1e-12)
    same = image_errors(r, r)
    assert same["rmse"] == 0.0 and same["relmse"] == 0.0 and same["flip"] == pytest.approx(0.0, abs=1e-6)
    worse = image_errors(r * 1.5, r)
    better = image_errors(r * 1.1, r)
    assert 0.0 < better["flip"] < worse["flip"] <= 1.0
    assert worse["_flip_map"].shape == (16, 24, 3)
    # An all-black reference has no FLIP exposure range: None, not a crash or NaN
    assert image_errors(x, np.zeros_like(r))["flip"] is None


def test_png_encoder_round_trips_through_an_independent_decoder(tmp_path):
    from stpm_core.imageio import read_png

    rgb8 = np.random.default_rng(1).integers(0, 256, (7, 11, 3), dtype=np.uint8)
    (tmp_path / "a.png").write_bytes(png_bytes(rgb8))
    np.testing.assert_array_equal(read_png(tmp_path / "a.png")[:, :, :3], rgb8)


# ----------------------------------------------------------------------------
# Cost of accuracy and the plot
# ----------------------------------------------------------------------------
def test_time_to_reach_interpolates_a_power_law_exactly():
    pts = [(t, 1.0 / t) for t in (1.0, 2.0, 8.0, 32.0)]             # error = 1 / time
    t, bound = time_to_reach(pts, 0.25)
    assert bound == "interpolated" and t == pytest.approx(4.0, rel=1e-12)
    assert time_to_reach(pts, 2.0) == (1.0, "at most")
    assert time_to_reach(pts, 0.001) == (None, "not reached")


def test_cost_of_accuracy_speedup():
    st = RenderSettings()

    def done(label, method, wall, err, n=None):
        r = Run(label=label, method=method, settings=st, accumulation_steps=n, status="done", wall_s=wall)
        r.errors = {"rmse": err, "relmse": err ** 2, "flip": None}
        return r

    runs = [done("A1", "ACCUMULATION", 1.0, 0.4, 1), done("A16", "ACCUMULATION", 16.0, 0.1, 16),
            done("T1", "TEMPORAL", 1.0, 0.2), done("T4", "TEMPORAL", 4.0, 0.05), done("S1", "STANDARD", 1.0, 0.3)]
    c = cost_of_accuracy(runs, target_steps=16)
    # TEMPORAL: 0.2 at 1 s, 0.05 at 4 s: error = 0.2 / t on the log-log line, so 0.1 at 2 s
    assert c["metrics"]["rmse"]["TEMPORAL"]["time_s"] == pytest.approx(2.0, rel=1e-9)
    assert c["metrics"]["rmse"]["TEMPORAL"]["speedup"] == pytest.approx(8.0, rel=1e-9)
    assert c["metrics"]["rmse"]["STANDARD"]["bound"] == "not reached"
    assert c["best_time_dependent"]["rmse"]["estimator"] == "TEMPORAL"
    assert c["best_time_dependent"]["flip"] is None                # no FLIP numbers: no claim


def test_svg_plot_is_well_formed_log_log():
    series = {"TEMPORAL": [(1.0, 0.1, "a"), (10.0, 0.01, "b")], "ACCUMULATION": [(100.0, 0.001, "c")],
              "KD4D": [(None, None, "skipped")]}
    svg = error_vs_time_svg(series, target=(0.01, "target"))
    root = ET.fromstring(svg)
    ns = "{http://www.w3.org/2000/svg}"
    lines = root.findall(f".//{ns}polyline")
    assert len(lines) == 2                              # one curve per method with points
    (x0, y0), (x1, y1) = [tuple(map(float, p.split(","))) for p in lines[0].get("points").split()]
    circles = [(float(c.get("cx")), float(c.get("cy"))) for c in root.findall(f".//{ns}g/{ns}circle")]
    (cx2, cy2) = circles[-1]
    # log-log: equal ratios give equal steps (1 -> 10 -> 100 s, 0.1 -> 0.01 -> 0.001)
    assert cx2 - x1 == pytest.approx(x1 - x0, abs=0.15) and cy2 - y1 == pytest.approx(y1 - y0, abs=0.15)


# ----------------------------------------------------------------------------
# Reference
# ----------------------------------------------------------------------------
def test_reference_recipes():
    scene, st = moving_receiver_scene(), caustic_settings(temporal_alpha=1.5, estimator="STANDARD")
    # default: accumulation buffer, 64 instants x 4x photons x 1x samples each
    acc, kind = reference_settings(scene, st)
    assert kind == "accumulation" and acc.method == "ACCUMULATION" and acc.accumulation_steps == 64
    assert (acc.photons_caustic, acc.samples, acc.k_nearest) == (16000, 4, round(30 * 4 ** (1 / 3)))
    # one time-stamped map: consistent window whatever the file's alpha
    ref, kind = reference_settings(scene, st, method="temporal")
    assert kind == "temporal" and ref.estimator == "TEMPORAL" and ref.temporal_alpha == 0.0
    assert (ref.photons_caustic, ref.samples, ref.k_nearest) == (64000, 16, round(30 * 16 ** (1 / 3)))
    assert reference_settings(scene, st, method="KD4D")[0].estimator == "KD4D"
    # no photon map in play: a plain motion-blurred ray tracer with more samples
    ref2, kind2 = reference_settings(emitter_scene(), RenderSettings(samples=4), sample_factor=8)
    assert kind2 == "ray-traced" and ref2.samples == 32 and ref2.method == "PHOTON"
    assert reference_settings(emitter_scene(), RenderSettings(samples=4))[0].samples == 16
    with pytest.raises(StpmError, match="reference method"):
        reference_settings(scene, st, method="PATH")


def test_reference_is_cached_and_supplied_exr_is_read(tmp_path):
    from stpm_core.imageio import write_exr

    scene, st = emitter_scene(), RenderSettings(samples=2, seed=3)
    a = get_reference(scene, st, cache_dir=tmp_path, sample_factor=4)
    b = get_reference(scene, st, cache_dir=tmp_path, sample_factor=4)
    assert a.info["source"] == "computed" and b.info["source"] == "cached"
    assert a.info["cache_key"] == b.info["cache_key"]
    np.testing.assert_array_equal(a.rgb, b.rgb)
    # Another recipe is another key
    assert get_reference(scene, st, cache_dir=tmp_path, sample_factor=2).info["source"] == "computed"
    # Supplied EXR: its Combined pass, checked against the scene's resolution
    H, W = a.rgb.shape[:2]
    img = np.random.default_rng(2).random((H, W, 4)).astype(np.float32)
    write_exr(tmp_path / "ref.exr", {"Combined": img})
    c = get_reference(scene, st, reference=tmp_path / "ref.exr")
    np.testing.assert_allclose(c.rgb, img[:, :, :3])
    assert c.info["source"] == "supplied"
    write_exr(tmp_path / "small.exr", {"Combined": img[:4, :4]})
    with pytest.raises(StpmError, match="renders at"):
        get_reference(scene, st, reference=tmp_path / "small.exr")


def _exact_and_settings(resolution=(24, 16)):
    st = RenderSettings(samples=2, photons_caustic=4000, photons_global=0, k_nearest=20, seed=1,
                        effects="MANUAL", caustics=True, indirect=False)
    return moving_caustic_scene(resolution), st, analytic_moving_caustic(resolution, sub=8, n_t=128)


def test_default_reference_is_closer_to_the_exact_image_than_the_runs_it_judges(tmp_path):
    """Moving caustic with an analytic answer: the default recipe (accumulation buffer, 64 instants x 4x
    photons) lands nearer the exact image than ACCUMULATION N=4 with the file's settings, unbiased."""
    from stpm_core.compare.metrics import combined_rgb
    from stpm_core.render import render

    scene, st, exact = _exact_and_settings()
    ref = get_reference(scene, st, cache_dir=tmp_path)
    assert ref.info["kind"] == "accumulation" and ref.info["settings"]["accumulation_steps"] == 64
    run4 = combined_rgb(render(scene, st.replace(method="ACCUMULATION", accumulation_steps=4)).passes)
    assert rmse(ref.rgb, exact) < 0.6 * rmse(run4, exact)
    assert abs(ref.rgb.mean() / exact.mean() - 1.0) < 0.03          # no overall bias beyond 3 %


@pytest.mark.slow
def test_default_reference_converges_as_photons_grow(tmp_path):
    scene, st, exact = _exact_and_settings((48, 32))
    errors = [rmse(get_reference(scene, st, cache_dir=tmp_path, photon_factor=f).rgb, exact) for f in (1, 4, 16)]
    assert errors[2] < 0.8 * errors[1] < 0.8 * 0.8 * errors[0]


# ----------------------------------------------------------------------------
# Sweep plan and time budget
# ----------------------------------------------------------------------------
def test_plan_runs_covers_every_method_cheapest_first():
    st = caustic_settings()
    runs = plan_runs(st, photon_budgets=(1, 4), accumulation_steps=(1, 2, 4, 8, 16, 32))
    labels = [r.label for r in runs]
    assert len(runs) == 3 * 2 + 6
    assert labels.index("ACCUMULATION N=1") < labels.index("TEMPORAL x4") < labels.index("ACCUMULATION N=32")
    t4 = next(r for r in runs if r.label == "TEMPORAL x4")
    assert t4.settings.photons_caustic == 4 * st.photons_caustic and t4.settings.samples == st.samples
    a8 = next(r for r in runs if r.label == "ACCUMULATION N=8")
    assert a8.settings.method == "ACCUMULATION" and a8.settings.accumulation_steps == 8
    assert [r.cost for r in runs] == sorted(r.cost for r in runs)


def test_time_budget_skips_runs_and_still_writes_the_report(tmp_path):
    scene = moving_receiver_scene((24, 16))
    ref = np.full((16, 24, 3), 0.2)
    report = run_compare(scene, caustic_settings(), tmp_path, reference=ref, time_budget=0.0,
                         photon_budgets=(1,), accumulation_steps=(1, 2))
    assert all(r["status"] == "skipped" for r in report["runs"])
    assert all(r["wall_s"] is None and r["rmse"] is None and r["flip"] is None for r in report["runs"])
    assert report["sweep"]["budget_exhausted"] and len(report["sweep"]["skipped"]) == 5
    assert json.loads((tmp_path / "report.json").read_text()) == report
    html = (tmp_path / "report.html").read_text()
    assert "Skipped" in html and "time budget" in html
    for s in SECTIONS:
        assert f'<section id="{s}">' in html


def test_cancelled_sweep_still_writes_a_partial_report(tmp_path):
    from stpm_core.errors import RenderCancelled

    finished = []
    progress = lambda f, msg: finished.append(msg) if "done in" in msg else None   # noqa: E731
    with pytest.raises(RenderCancelled, match="partial report"):
        run_compare(emitter_scene(), RenderSettings(samples=2), tmp_path, reference=np.full((16, 24, 3), 0.3),
                    photon_budgets=(1,), accumulation_steps=(1, 2), progress=progress,
                    cancel=lambda: bool(finished))
    data = json.loads((tmp_path / "report.json").read_text())
    assert [r["status"] for r in data["runs"]] == ["done"] + ["skipped"] * 4
    assert data["sweep"]["cancelled"] and all(r["note"] == "cancelled" for r in data["runs"][1:])
    assert "cancelled" in (tmp_path / "report.html").read_text()


# ----------------------------------------------------------------------------
# The report on a small moving scene
# ----------------------------------------------------------------------------
def _finite_numbers(obj):
    if isinstance(obj, dict):
        for v in obj.values():
            yield from _finite_numbers(v)
    elif isinstance(obj, list):
        for v in obj:
            yield from _finite_numbers(v)
    elif isinstance(obj, (int, float)) and not isinstance(obj, bool):
        yield obj


def test_report_has_every_section_finite_numbers_and_valid_json(sweep):
    report, out = sweep
    data = json.loads((out / "report.json").read_text(), parse_constant=lambda c: pytest.fail(f"JSON has {c}"))
    assert data == report
    assert all(math.isfinite(v) for v in _finite_numbers(data))
    assert len(data["runs"]) == 3 * 3 + 3
    for r in data["runs"]:
        assert r["status"] == "done"
        for key in ("wall_s", "rmse", "relmse", "flip"):
            assert isinstance(r[key], float) and r[key] > 0
    assert set(data["best"]) == {"ACCUMULATION", "STANDARD", "TEMPORAL", "KD4D"}
    assert data["consistent"]["STANDARD"]["consistent"] is False
    assert data["consistent"]["TEMPORAL"]["consistent"] is True
    assert data["cost"]["target"]["label"] == "ACCUMULATION N=16"
    assert data["reference"]["kind"] == "temporal" and data["reference"]["settings"]["photons_caustic"] == 256000
    html = (out / "report.html").read_text()
    for s in SECTIONS:
        assert f'<section id="{s}">' in html
    assert "http://" not in html.replace("http://www.w3.org/2000/svg", "")      # self-contained
    assert "https://" not in html
    # images: reference + 4 best runs, 4 FLIP maps, 4 signed-error maps, all embedded PNGs
    assert len(re.findall(r'<img src="data:image/png;base64,', html)) == 13
    assert html.count("<svg") == 3 and html.count('class="curve"') == 3 * 4
    assert (out / "reference.exr").is_file()


def test_two_independent_references_agree_better_than_standard(sweep):
    """TEMPORAL reference vs accumulation-buffer reference: no shared estimator, yet close."""
    report, _ = sweep
    cx = report["cross_references"]["accumulation-16"]
    assert cx["reference"]["kind"] == "accumulation"
    apart = cx["main_reference_error"]["rmse"]
    assert apart < 0.6 * _run(report, "STANDARD x16")["rmse"]
    assert apart < 0.6 * cx["runs"]["STANDARD x16"]["rmse"]
    # against either reference STANDARD's error stalls and TEMPORAL's falls
    assert cx["runs"]["TEMPORAL x16"]["rmse"] < 0.75 * cx["runs"]["TEMPORAL x1"]["rmse"]
    assert cx["runs"]["STANDARD x16"]["rmse"] > 0.7 * cx["runs"]["STANDARD x1"]["rmse"]


def test_accumulation_error_falls_as_instants_grow(sweep):
    report, _ = sweep
    for metric in ("rmse", "relmse", "flip"):
        e1, e4, e16 = (_run(report, f"ACCUMULATION N={n}")[metric] for n in (1, 4, 16))
        assert e1 > e4 > e16, metric
    assert _run(report, "ACCUMULATION N=16")["rmse"] < 0.6 * _run(report, "ACCUMULATION N=1")["rmse"]


def test_standard_error_stalls_while_temporal_keeps_falling(sweep):
    """Moving receiver: STANDARD's error is bias (flat in photons), TEMPORAL's and KD4D's fall."""
    report, _ = sweep
    for metric in ("rmse", "relmse"):
        s1, s16 = _run(report, "STANDARD x1")[metric], _run(report, "STANDARD x16")[metric]
        t1, t16 = _run(report, "TEMPORAL x1")[metric], _run(report, "TEMPORAL x16")[metric]
        k1, k16 = _run(report, "KD4D x1")[metric], _run(report, "KD4D x16")[metric]
        assert s16 > 0.7 * s1, metric           # 16x the photons, STANDARD hardly improves
        assert t16 < 0.6 * t1, metric           # TEMPORAL keeps converging
        assert k16 < 0.7 * k1, metric
        assert t16 < 0.6 * s16 and k16 < 0.6 * s16, metric


# ----------------------------------------------------------------------------
# The HTML in a real browser
# ----------------------------------------------------------------------------
_CHECK_SCRIPT = """<script>
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var ok = imgs.filter(function (i) { return i.complete && i.naturalWidth > 0; }).length;
  document.title = 'IMAGES ' + ok + '/' + imgs.length + ' SVG ' + document.querySelectorAll('svg').length;
});
</script></body>"""

_CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                   "--no-first-run", "--hide-scrollbars", "--virtual-time-budget=5000"]


@pytest.mark.skipif(CHROMIUM is None, reason="chromium is not installed (Debian: apt-get install -y chromium); "
                                             "the headless-browser check of report.html is skipped")
def test_report_opens_in_headless_chromium_with_images_loaded(sweep, tmp_path):
    _, out = sweep
    html = (out / "report.html").read_text()
    # -- The DOM after load: every <img> decoded (naturalWidth > 0) ---------------------
    check = tmp_path / "check.html"
    check.write_text(html.replace("</body>", _CHECK_SCRIPT))
    env = dict(os.environ, HOME=str(tmp_path))
    dom = subprocess.run([CHROMIUM, *_CHROMIUM_FLAGS, "--dump-dom", check.as_uri()], capture_output=True,
                         text=True, timeout=120, env=env).stdout
    m = re.search(r"<title>IMAGES (\d+)/(\d+) SVG (\d+)</title>", dom)
    assert m, "the page did not finish loading in chromium"
    ok, total, svgs = map(int, m.groups())
    assert total == 13 and ok == total and svgs == 3
    # -- A screenshot of the real page shows the pictures -----------------------------------
    shot = tmp_path / "shot.png"
    subprocess.run([CHROMIUM, *_CHROMIUM_FLAGS, "--window-size=1400,2000", f"--screenshot={shot}",
                    (out / "report.html").as_uri()], capture_output=True, timeout=120, env=env)
    from stpm_core.imageio import read_png

    px = read_png(shot)[:, :, :3].astype(float) / 255.0
    assert px.shape[:2] == (2000, 1400)
    # the error maps are saturated colour (magma purple, blue/red); text and tables are grey
    saturation = px.max(axis=2) - px.min(axis=2)
    assert np.count_nonzero(saturation > 0.25) > 20_000
    # the renders are mid-grey (caustic-lit floor): many pixels neither white nor black
    grey = (saturation < 0.05) & (px.mean(axis=2) > 0.15) & (px.mean(axis=2) < 0.85)
    assert np.count_nonzero(grey) > 20_000


# ----------------------------------------------------------------------------
# Command line
# ----------------------------------------------------------------------------
def test_stpm_compare_command_line(tmp_path, capsys, monkeypatch):
    from stpm_core import cli
    from stpm_core.compare import main
    from stpm_core.scenefile import save_scene

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))        # the default reference cache
    path = save_scene(emitter_scene((16, 8)), tmp_path / "slab.stpm",
                      RenderSettings(samples=2, photons_caustic=0, photons_global=0, seed=2))
    # -- stpm_core.compare.main: every sweep option -------------------------------------
    out = tmp_path / "rep"
    code = main([str(path), "--output", str(out), "--photon-budgets", "1,2:2",
                 "--accumulation-steps", "1,2", "--estimators", "temporal", "--reference-samples", "4",
                 "--progressive-passes", "4", "--cache-dir", str(tmp_path / "cache"), "--quiet"])
    assert code == 0
    printed = capsys.readouterr().out
    assert str(out / "report.html") in printed
    data = json.loads((out / "report.json").read_text())
    assert [r["label"] for r in data["runs"]] == ["ACCUMULATION N=1", "TEMPORAL x1", "ACCUMULATION N=2",
                                                  "TEMPORAL x2 s2", "PROGRESSIVE TEMPORAL 4 passes",
                                                  "SPPM 8 passes"]
    # the progressive curves: measured after passes 1, 2, 4 (and 8), times growing
    for label, marks in (("PROGRESSIVE TEMPORAL 4 passes", [1, 2, 4]), ("SPPM 8 passes", [1, 2, 4, 8])):
        curve = _run(data, label)["curve"]
        assert [c["pass"] for c in curve] == marks
        assert all(a["wall_s"] < b["wall_s"] for a, b in zip(curve, curve[1:]))
        assert curve[-1]["rmse"] == pytest.approx(_run(data, label)["rmse"])
    assert _run(data, "TEMPORAL x2 s2")["samples"] == 4
    assert data["reference"]["kind"] == "ray-traced" and data["reference"]["settings"]["samples"] == 8
    assert data["cost"]["target"]["label"] == "ACCUMULATION N=2"          # N=16 not run: the largest below
    # -- `stpm compare` through the console script's main: default sweep cut by a time budget -----
    out2 = tmp_path / "rep2"
    # (a budget spent by the first run: that run is done, every later one skipped, whatever the machine's speed)
    assert cli.main(["compare", str(path), "--output", str(out2), "--time-budget", "1e-9", "--quiet"]) == 0
    data2 = json.loads((out2 / "report.json").read_text())
    status = [r["status"] for r in data2["runs"]]
    assert len(status) == 3 * 5 + 6 + 2 and status[0] == "done" and set(status[1:]) == {"skipped"}   # + PROGRESSIVE, SPPM
    assert list((tmp_path / "xdg" / "stpm" / "references").glob("*.npz"))
    # -- bad input: one clear line, non-zero exit ---------------------------------------------
    with pytest.raises(StpmError, match="not found"):
        main([str(tmp_path / "missing.stpm")])
    with pytest.raises(StpmError, match="PHOTONS:SAMPLES"):
        main([str(path), "--photon-budgets", "1,2:x"])
    assert cli.main(["compare", str(tmp_path / "missing.stpm")]) == 1
