"""The ``stpm`` command line, run as a real subprocess on tiny scene files.

Success: outputs exist, the EXR has Blender's channel names, the stats JSON has
the required keys and reflects the options given.  Every bad input exits
non-zero with exactly one ``stpm: error: ...`` line on stderr and no traceback.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stpm_core.cli import _frame_path, parse_frames
from stpm_core.demo import demo_scene
from stpm_core.errors import StpmError
from stpm_core.film import PASSES
from stpm_core.imageio import read_exr, read_png
from stpm_core.motion import MotionTransform
from stpm_core.scenefile import save_scene, scene_to_arrays
from stpm_core.settings import RenderSettings

ROOT = Path(__file__).resolve().parent.parent
STATS_KEYS = ("wall_s", "export_s", "photon_trace_s", "photon_map_build_s", "render_s", "photons_caustic",
              "photons_global", "estimator", "method", "samples", "resolution", "seed")


def stpm(*args, cwd=None) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("STPM_DEBUG", None)
    return subprocess.run([sys.executable, "-m", "stpm_core.cli", *map(str, args)], cwd=cwd or ROOT,
                          env=env, capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    """The demo scene at 8x6 pixels with 1 sample and a few photons, settings seed 7."""
    d = tmp_path_factory.mktemp("cli")
    scene = demo_scene(resolution=(8, 6))
    settings = RenderSettings(samples=1, photons_caustic=2000, photons_global=500, k_nearest=8, seed=7)
    return save_scene(scene, d / "tiny.stpm", settings=settings)


@pytest.fixture(scope="module")
def rendered(tiny):
    """(completed process, EXR path, stats path) of one quiet render of the tiny scene."""
    out, stats = tiny.parent / "img.exr", tiny.parent / "stats.json"
    return stpm("render", tiny, "--output", out, "--stats", stats, "--quiet"), out, stats


def test_render_writes_exr_png_and_stats(tiny, rendered):
    r, out, stats = rendered
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    assert str(out) in r.stdout and str(out.with_suffix(".png")) in r.stdout
    # EXR: every pass, Blender's channel names, the scene's resolution
    exr = read_exr(out)
    assert set(exr["_channels"]) == {f"ViewLayer.{n}.{ids[i]}" for n, c, ids in PASSES for i in range(c)}
    assert exr["Combined"].shape == (6, 8, 4)
    # PNG preview next to it, same size
    assert read_png(out.with_suffix(".png")).shape == (6, 8, 3)
    # Stats: required keys; settings from the file (seed 7, 1 sample); file paths
    s = json.loads(stats.read_text())
    for key in STATS_KEYS:
        assert key in s, key
    assert s["seed"] == 7 and s["samples"] == 1 and s["resolution"] == [8, 6]
    assert s["method"] == "PHOTON" and s["estimator"] == "TEMPORAL"
    assert s["output_exr"] == str(out) and s["scene"] == str(tiny)
    assert s["wall_s"] >= s["render_s"] > 0
    assert json.loads(exr["_metadata"]["stpm:settings"])["seed"] == 7


def test_options_override_file_settings(tiny, tmp_path):
    out, stats = tmp_path / "o.exr", tmp_path / "o.json"
    r = stpm("render", tiny, "-o", out, "--stats", stats, "-q", "--samples", 2, "--seed", 11,
             "--estimator", "kd4d", "--method", "photon", "--resolution", "5x3", "--k", 4,
             "--time-scale", 1.5, "--photons-caustic", 1000, "--photons-global", 0)
    assert r.returncode == 0, r.stderr
    s = json.loads(stats.read_text())
    assert (s["samples"], s["seed"], s["estimator"], s["resolution"]) == (2, 11, "KD4D", [5, 3])
    assert s["settings"]["k_nearest"] == 4 and s["settings"]["time_scale"] == 1.5
    assert read_exr(out)["Combined"].shape == (3, 5, 4)


def test_photon_guiding_option_and_its_stats(tmp_path):
    """--photon-guiding on: the stats' photon_stats count the global photons stored on camera-visible
    surfaces and say what the guide marked (docs/photon-mapping.md, "Emission guided by direct visibility");
    a room lit by a sun through a window (tests/guide_scenes.py)."""
    from guide_scenes import window_room
    room = save_scene(window_room((8, 6)), tmp_path / "room.stpm", settings=RenderSettings(samples=1, k_nearest=8))
    out, stats = tmp_path / "g.exr", tmp_path / "g.json"
    r = stpm("render", room, "-o", out, "--stats", stats, "-q", "--photon-guiding", "on",
             "--photons-caustic", 0, "--photons-global", 3000)
    assert r.returncode == 0, r.stderr
    s = json.loads(stats.read_text())
    ps = s["photon_stats"]
    assert s["settings"]["photon_guiding"] is True and ps["photon_guiding"] is True
    assert 0 <= ps["photons_stored_visible_global"] <= ps["photons_stored_global"]
    assert ps["photons_stored_visible_global_fraction"] == ps["photons_stored_visible_global"] / 3000
    n = len(ps["photons_emitted_global_per_light"])
    assert len(ps["guide_marked_cells_per_light"]) == len(ps["photons_guided_global_per_light"]) == n
    assert 0.0 < ps["guide_marked_cells_per_light"][0] < 0.5 and ps["photons_guided_global_per_light"][0] == 2400


def test_adaptive_sampling_options(tiny, tmp_path):
    """--adaptive-sampling on: the stats' samples_mean, the EXR's Sample Count pass (each pixel's samples)."""
    out, stats = tmp_path / "a.exr", tmp_path / "a.json"
    r = stpm("render", tiny, "-o", out, "--stats", stats, "--samples", 12, "--adaptive-sampling", "on",
             "--adaptive-threshold", 0.05, "--adaptive-min-samples", 4, "--photons-caustic", 1000,
             "--photons-global", 0)
    assert r.returncode == 0, r.stderr
    assert "adaptive sampling:" in r.stderr
    s = json.loads(stats.read_text())
    assert s["settings"]["use_adaptive_sampling"] is True and s["settings"]["adaptive_min_samples"] == 4
    assert 4 <= s["samples_mean"] <= 12 and s["adaptive"]["min_samples"] == 4
    n = read_exr(out)["Sample Count"]
    assert n.min() >= 4 and n.max() <= 12 and abs(float(n.mean()) - s["samples_mean"]) < 1e-3


def test_default_output_and_same_seed_same_image(tiny, rendered):
    """No --output: the EXR lands next to the scene; the same seed gives the same image bit for bit."""
    r = stpm("render", tiny, "--frame", "1", "-q")
    assert r.returncode == 0, r.stderr
    assert tiny.with_suffix(".exr").exists() and tiny.with_suffix(".png").exists()
    ea, eb = read_exr(rendered[1]), read_exr(tiny.with_suffix(".exr"))
    for name, _, _ in PASSES:
        assert np.array_equal(ea[name], eb[name]), name


def test_plan_json(tiny, tmp_path, capsys):
    from stpm_core.cli import main
    r = stpm("plan", tiny, "--json")
    assert r.returncode == 0, r.stderr
    plan = json.loads(r.stdout)
    # The demo: a glass sphere moving over a diffuse floor under a point light.  The floor is
    # the only diffuse surface and it is convex: no diffuse interreflection, so no global map.
    assert plan["motion_blur"] is True and plan["caustics"] is True and plan["indirect"] is False
    assert plan["time_dependent"] is True
    assert isinstance(plan["reasons"], list) and plan["reasons"]
    # The same scene with the sphere at rest and no glass: nothing but direct light
    scene = demo_scene(resolution=(8, 6))
    scene.instances[1].transform = MotionTransform.static(scene.instances[1].transform.matrices[0])
    scene.materials[1] = scene.materials[0]
    still = save_scene(scene, tmp_path / "still.stpm")
    assert main(["plan", str(still), "--json"]) == 0  # in-process: the same code, no interpreter start-up
    plan = json.loads(capsys.readouterr().out)
    assert plan["motion_blur"] is False and plan["caustics"] is False and plan["time_dependent"] is False
    assert main(["plan", str(still)]) == 0
    assert "motion_blur" in capsys.readouterr().out


# ----------------------------------------------------------------------------
# Bad input: non-zero exit, one line on stderr, no traceback
# ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def bad_files(tiny):
    d = tiny.parent
    header, arrays = scene_to_arrays(demo_scene(resolution=(8, 6)))
    header["lights"][0]["power"] = -3.0
    with open(d / "negative.stpm", "wb") as f:
        np.savez_compressed(f, header=np.frombuffer(json.dumps(header).encode(), np.uint8), **arrays)
    (d / "notes.txt").write_text("not a scene")
    (d / "garbage.stpm").write_bytes(b"PK\x03\x04 this is not really a zip")
    return d


BAD = [
    ("missing file", ["render", "{d}/missing.stpm"], "not found"),
    ("malformed scene", ["render", "{d}/negative.stpm"], "power"),
    ("corrupt scene", ["render", "{d}/garbage.stpm"], "garbage.stpm"),
    ("unknown file type", ["render", "{d}/notes.txt"], "unknown scene file type"),
    ("bad sample count", ["render", "{tiny}", "--samples", "0"], "--samples must"),
    ("non-numeric samples", ["render", "{tiny}", "--samples", "many"], "--samples"),
    ("unknown estimator", ["render", "{tiny}", "--estimator", "magic"], "--estimator"),
    ("adaptive sampling not on or off", ["render", "{tiny}", "--adaptive-sampling", "maybe"], "--adaptive-sampling"),
    ("adaptive threshold above 1", ["render", "{tiny}", "--adaptive-threshold", "2"], "--adaptive-threshold"),
    ("unknown method", ["render", "{tiny}", "--method", "raytrace"], "--method"),
    ("bad temporal alpha", ["render", "{tiny}", "--temporal-alpha", "0.5"], "--temporal-alpha"),
    ("negative photons", ["render", "{tiny}", "--photons-caustic", "-1"], "--photons-caustic"),
    ("bad resolution", ["render", "{tiny}", "--resolution", "12by4"], "--resolution"),
    ("frame syntax", ["render", "{tiny}", "--frame", "1-x"], "--frame"),
    ("frame range backwards", ["render", "{tiny}", "--frame", "5-2"], "--frame"),
    ("frame not in core file", ["render", "{tiny}", "--frame", "3"], "frame"),
    ("output folder missing", ["render", "{tiny}", "--output", "{d}/nowhere/x.exr"], "does not exist"),
    ("output not exr", ["render", "{tiny}", "--output", "{d}/x.png"], ".exr"),
    ("unknown option", ["render", "{tiny}", "--fast"], "--fast"),
    ("no scene", ["render"], "scene"),
    ("unknown command", ["paint", "{tiny}"], "paint"),
    ("plan on missing file", ["plan", "{d}/missing.stpm", "--json"], "not found"),
    ("plan frame range", ["plan", "{tiny}", "--frame", "1-2"], "range"),
    ("compare missing scene", ["compare", "{d}/missing.stpm"], "not found"),
    ("compare missing reference", ["compare", "{tiny}", "--reference", "{d}/nope.exr"], "reference"),
    ("compare bad option", ["compare", "{tiny}", "--k", "0"], "--k"),
]


@pytest.mark.parametrize("label,args,needle", BAD, ids=[b[0] for b in BAD])
def test_bad_input_one_line_no_traceback(tiny, bad_files, label, args, needle):
    r = stpm(*[a.format(d=bad_files, tiny=tiny) for a in args])
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("stpm: error: "), lines[0]
    assert needle in lines[0], lines[0]
    assert "Traceback" not in r.stderr


# ----------------------------------------------------------------------------
# Helpers, in-process
# ----------------------------------------------------------------------------
def test_parse_frames():
    assert parse_frames("4") == [4]
    assert parse_frames("1-3") == [1, 2, 3]
    assert parse_frames("-2..1") == [-2, -1, 0, 1]
    for bad in ("", "a", "1-", "3-1", "1.5"):
        with pytest.raises(StpmError):
            parse_frames(bad)


def test_frame_paths():
    assert _frame_path("out/f_####.exr", 7, True) == Path("out/f_0007.exr")
    assert _frame_path("out/f.exr", 7, True) == Path("out/f_0007.exr")
    assert _frame_path("out/f.exr", 7, False) == Path("out/f.exr")


def test_ctrl_c_cancels_cleanly(tmp_path):
    """SIGINT during a render: exit 130, a 'cancelled' line, no traceback, no half-written EXR."""
    import signal
    scene = demo_scene(resolution=(160, 120))
    path = save_scene(scene, tmp_path / "long.stpm", settings=RenderSettings(samples=256, photons_caustic=0,
                                                                              photons_global=0))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-m", "stpm_core.cli", "render", str(path), "-o", str(tmp_path / "c.exr")],
                         cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    first = p.stderr.readline()  # the first progress line: the render (and its SIGINT handler) is running
    assert "%" in first, first
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert "stpm: render cancelled" in err and "Traceback" not in err
    assert not (tmp_path / "c.exr").exists()


def _has_blend_support() -> bool:
    import importlib.util
    return (importlib.util.find_spec("bpy") is not None and (ROOT / "addon" / "batch.py").exists()
            and (ROOT / "blend_scenes" / "demo.blend").exists())


@pytest.mark.bpy
@pytest.mark.skipif(not _has_blend_support(), reason="needs bpy, addon.batch and blend_scenes/demo.blend")
def test_blend_input_plan(tmp_path):
    """A .blend goes through addon.batch.load_blend; Blender's log never pollutes stdout."""
    r = stpm("plan", ROOT / "blend_scenes" / "demo.blend", "--frame", "1", "--json")
    assert r.returncode == 0, r.stderr
    plan = json.loads(r.stdout)
    assert plan["motion_blur"] and plan["caustics"]


@pytest.mark.bpy
@pytest.mark.slow
@pytest.mark.skipif(not _has_blend_support(), reason="needs bpy, addon.batch and blend_scenes/demo.blend")
def test_blend_input_frame_range(tmp_path):
    """A frame range of a .blend: one EXR and one stats file per frame, '#' replaced by the frame."""
    blend = ROOT / "blend_scenes" / "demo.blend"
    r = stpm("render", blend, "--frame", "1-2", "-o", tmp_path / "f_##.exr", "--stats", tmp_path / "s.json",
             "--resolution", "8x6", "--samples", "1", "--photons-caustic", "500", "--photons-global", "0", "-q")
    assert r.returncode == 0, r.stderr
    for f in (1, 2):
        assert read_exr(tmp_path / f"f_{f:02d}.exr")["Combined"].shape == (6, 8, 4)
        stats = json.loads((tmp_path / f"s_{f:04d}.json").read_text())
        assert stats["frame"] == f
        # the static floor is baked once for the range (frame 2 reuses frame 1's)
        assert stats["caster"]["static_reused"] == (f == 2)


def test_internal_error_is_one_line_and_exit_3(tiny, tmp_path, monkeypatch, capsys):
    """A bug (an unexpected exception) prints one line asking for a report, exit status 3."""
    import stpm_core.render as render_mod
    from stpm_core.cli import main

    def broken(*a, **k):
        raise ZeroDivisionError("boom")
    monkeypatch.setattr(render_mod, "render", broken)
    monkeypatch.delenv("STPM_DEBUG", raising=False)
    assert main(["render", str(tiny), "-o", str(tmp_path / "x.exr"), "-q"]) == 3
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "ZeroDivisionError: boom" in err[0] and "please report" in err[0]


def test_progress_bar_lines():
    """On a pipe: one line per new phase or 10 %; on a terminal: one redrawn line ending in a newline."""
    import io
    from stpm_core.progress import ProgressBar

    pipe = io.StringIO()
    bar = ProgressBar(stream=pipe)
    for i in range(101):
        bar(i / 100, "tracing")
    bar(1.0, "done")
    bar.close()
    lines = pipe.getvalue().splitlines()
    assert len(lines) == 12 and lines[0].strip().startswith("0.0%") and "done" in lines[-1]

    class Tty(io.StringIO):
        def isatty(self):
            return True
    tty = Tty()
    bar = ProgressBar(stream=tty, min_interval=0.0)
    bar(0.5, "half")
    bar(1.0, "done")
    bar.close()
    out = tty.getvalue()
    assert out.count("\r") == 2 and out.endswith("\n") and "[" + "#" * 15 + "." * 15 + "]" in out
    quiet = io.StringIO()
    ProgressBar(stream=quiet, quiet=True)(0.5, "x")
    assert quiet.getvalue() == ""


def test_demo_quick_core(tmp_path):
    """python -m stpm_core.demo --core --quick writes the scene, EXR, PNG and stats."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-m", "stpm_core.demo", "--core", "--quick", "--out", str(tmp_path)],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    for name in ("demo.stpm", "demo.exr", "demo.png", "demo_stats.json"):
        assert (tmp_path / name).exists(), name
        assert str(tmp_path / name) in r.stdout
    stats = json.loads((tmp_path / "demo_stats.json").read_text())
    assert stats["resolution"] == [80, 60] and stats["method"] == "PHOTON"


@pytest.mark.slow
def test_compare_writes_report(tiny, tmp_path):
    """stpm compare on the tiny scene: report.html and report.json in the report folder."""
    r = stpm("compare", tiny, "-o", tmp_path / "cmp", "--time-budget", "10", "-q")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "cmp" / "report.html").exists()
    assert isinstance(json.loads((tmp_path / "cmp" / "report.json").read_text()), dict)
