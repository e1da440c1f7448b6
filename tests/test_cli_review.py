"""The ``stpm`` command line after the CLI review: atomic outputs, output / frame / memory checks
before rendering, Ctrl-C at any moment, Blender's own output, progress lines on a pipe.

Real outcomes: files on disk (or their absence), exit status, the exact stderr lines.
Tiny scenes (8x6 .. 64x48 pixels, few photons) keep each test within a few seconds.
"""
from __future__ import annotations

import importlib.util
import io
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from stpm_core import cli, command_common, imageio
from stpm_core.demo import demo_scene
from stpm_core.errors import StpmError
from stpm_core.imageio import read_exr, read_png
from stpm_core.scenefile import save_scene
from stpm_core.settings import RenderSettings

ROOT = Path(__file__).resolve().parent.parent
STPM = ROOT / ".venv" / "bin" / "stpm"
STATIC_BLEND = ROOT / "blend_scenes" / "static_scene.blend"


def _stpm_cmd() -> list[str]:
    """The installed console script when present, else the module (same code)."""
    return [str(STPM)] if STPM.exists() else [sys.executable, "-m", "stpm_core.cli"]


def _env() -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("STPM_DEBUG", None)
    return env


def stpm(*args, timeout=120) -> subprocess.CompletedProcess:
    return subprocess.run([*_stpm_cmd(), *map(str, args)], cwd=ROOT, env=_env(), capture_output=True,
                          text=True, timeout=timeout)


def _has_blend() -> bool:
    return importlib.util.find_spec("bpy") is not None and STATIC_BLEND.exists() \
        and (ROOT / "addon" / "batch.py").exists()


needs_blend = pytest.mark.skipif(not _has_blend(), reason="needs bpy, addon.batch and blend_scenes/static_scene.blend")


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Path:
    """The demo scene at 8x6 pixels, 1 sample, a few photons (frame 1)."""
    d = tmp_path_factory.mktemp("review")
    settings = RenderSettings(samples=1, photons_caustic=500, photons_global=0, k_nearest=8, seed=3)
    return save_scene(demo_scene(resolution=(8, 6)), d / "tiny.stpm", settings=settings)


@pytest.fixture
def no_render(monkeypatch):
    """Make any call of the renderer fail the test: the checks under test must come before it."""
    import stpm_core.render as render_mod

    def forbidden(*a, **k):
        raise AssertionError("render() was called")
    monkeypatch.setattr(render_mod, "render", forbidden)
    monkeypatch.delenv("STPM_DEBUG", raising=False)


def _one_error_line(err: str, needle: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("stpm: error: ") and needle in lines[0], lines[0]
    assert "Traceback" not in err
    return lines[0]


# ----------------------------------------------------------------------------
# 1. Atomic outputs
# ----------------------------------------------------------------------------
def _passes(h=6, w=8):
    rng = np.random.default_rng(0)
    return {"Combined": rng.random((h, w, 4), dtype=np.float32), "Depth": rng.random((h, w, 1), dtype=np.float32)}


def _failing_writer(monkeypatch):
    """imageio's OpenImageIO step writes a few bytes, then fails (a full disk, a kill)."""
    def half_then_fail(path, spec, pixels, what):
        Path(path).write_bytes(b"v/1\x01 partial")
        raise StpmError(f"cannot write {what}: No space left on device")
    monkeypatch.setattr(imageio, "_oiio_write", half_then_fail)


def test_failed_write_leaves_no_file_and_no_temp(tmp_path, monkeypatch):
    """A write failing midway: nothing under the final name, no temporary file; an old file survives."""
    (tmp_path / "old.exr").write_bytes(b"previous good render")
    _failing_writer(monkeypatch)
    for call in (lambda: imageio.write_exr(tmp_path / "a.exr", _passes()),
                 lambda: imageio.write_exr(tmp_path / "old.exr", _passes()),
                 lambda: imageio.write_png(tmp_path / "a.png", _passes()["Combined"])):
        with pytest.raises(StpmError, match="No space left"):
            call()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.exr"]
    assert (tmp_path / "old.exr").read_bytes() == b"previous good render"

    def bad_text(self, text, *a, **k):
        Path.write_bytes(self, text[:5].encode())
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(Path, "write_text", bad_text)
    with pytest.raises(OSError):
        imageio.write_json(tmp_path / "s.json", {"a": 1})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.exr"]
    assert not imageio._PENDING


def test_successful_write_replaces_atomically(tmp_path):
    """The real writers: the file appears complete under its name, no temporary left."""
    imageio.write_exr(tmp_path / "a.exr", _passes())
    imageio.write_png(tmp_path / "a.png", _passes()["Combined"])
    imageio.write_json(tmp_path / "a.json", {"x": np.float32(1.5)})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "a.json", "a.png"]
    assert read_exr(tmp_path / "a.exr")["Combined"].shape == (6, 8, 4)
    assert read_png(tmp_path / "a.png").shape == (6, 8, 3)
    assert json.loads((tmp_path / "a.json").read_text()) == {"x": 1.5}


def test_cli_write_failure_leaves_no_output_of_the_frame(tiny, tmp_path, monkeypatch, capsys):
    """The PNG fails after the EXR was written: neither (nor the stats) is left, nor a temporary file."""
    real_png = imageio.write_png

    def png_fails(path, rgb, **kw):
        real_png(path, rgb, **kw)
        raise OSError(28, "No space left on device", str(path))
    monkeypatch.setattr(imageio, "write_png", png_fails)
    out = tmp_path / "out"
    out.mkdir()
    rc = cli.main(["render", str(tiny), "-o", str(out / "f.exr"), "--stats", str(out / "f.json"), "-q"])
    assert rc == 1
    _one_error_line(capsys.readouterr().err, "No space left on device")
    assert list(out.iterdir()) == []


def test_cli_ctrl_c_while_writing_leaves_no_output(tiny, tmp_path, monkeypatch, capsys):
    """SIGINT arriving while the outputs are written: exit 130 and no file of the cancelled frame."""
    real_png = imageio.write_png

    def png_interrupted(path, rgb, **kw):
        os.kill(os.getpid(), signal.SIGINT)  # handled by the CLI's flag: the write goes on
        return real_png(path, rgb, **kw)
    monkeypatch.setattr(imageio, "write_png", png_interrupted)
    out = tmp_path / "out"
    out.mkdir()
    before = signal.getsignal(signal.SIGINT)  # SIG_IGN when the suite runs as a background job
    rc = cli.main(["render", str(tiny), "-o", str(out / "f.exr"), "--stats", str(out / "f.json"), "-q"])
    assert rc == 130
    err = capsys.readouterr().err
    assert "stpm: render cancelled" in err and "Traceback" not in err
    assert list(out.iterdir()) == []
    assert signal.getsignal(signal.SIGINT) is before  # the caller's handler restored


# ----------------------------------------------------------------------------
# 2.-3. Output paths checked before rendering
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("which", ["exr", "png", "scene", "scene-other-spelling"])
def test_stats_may_not_overwrite_an_output_or_the_scene(tiny, tmp_path, which, no_render, capsys):
    out = tmp_path / "o.exr"
    stats = {"exr": out, "png": tmp_path / "o.png", "scene": tiny,
             "scene-other-spelling": tiny.parent / ".." / tiny.parent.name / tiny.name}[which]
    before = tiny.read_bytes()
    assert cli.main(["render", str(tiny), "-o", str(out), "--stats", str(stats), "-q"]) == 1
    _one_error_line(capsys.readouterr().err, "is the same file as the")
    assert tiny.read_bytes() == before and not out.exists()


def test_directories_and_unwritable_folders_refused_before_rendering(tiny, tmp_path, no_render, capsys):
    (tmp_path / "sdir").mkdir()
    (tmp_path / "dir.exr").mkdir()
    cases = [(["--stats", str(tmp_path / "sdir")], "is a directory"),
             (["-o", str(tmp_path / "dir.exr")], "is a directory"),
             (["-o", str(tmp_path / "nowhere" / "x.exr")], "does not exist")]
    if Path("/proc").is_dir():  # a folder nobody may create files in, root included
        cases.append((["-o", "/proc/x.exr"], "not writable"))
    for extra, needle in cases:
        args = ["render", str(tiny), "-q", *extra]
        if "-o" not in extra:
            args += ["-o", str(tmp_path / "ok.exr")]
        assert cli.main(args) == 1, extra
        line = _one_error_line(capsys.readouterr().err, needle)
        assert str(Path(extra[-1]).name) in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dir.exr", "sdir"]


# ----------------------------------------------------------------------------
# 4. Frames
# ----------------------------------------------------------------------------
def test_range_on_core_file_refused_before_rendering(tiny, tmp_path, no_render, capsys):
    assert cli.main(["render", str(tiny), "--frame", "1-3", "-o", str(tmp_path / "f.exr"), "-q"]) == 1
    _one_error_line(capsys.readouterr().err, "holds frame 1 only")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("frame", ["2147483648", "-2147483649", "1-99999999999999999999"])
def test_huge_frame_numbers_are_a_usage_error(tiny, frame):
    r = stpm("render", tiny, "--frame", frame, "-q")
    assert r.returncode == 2
    _one_error_line(r.stderr, "frame limits")
    r = stpm("compare", tiny, "--frame", "2147483648")
    assert r.returncode == 2
    _one_error_line(r.stderr, "frame limits")


@pytest.mark.bpy
@needs_blend
def test_blend_frame_outside_its_range_warns_and_renders(tmp_path):
    """static_scene.blend runs frames 1..1: frame 3 renders (as Blender does) after a warning line."""
    r = stpm("render", STATIC_BLEND, "--frame", "3", "-o", tmp_path / "f.exr", "--resolution", "8x6",
             "--samples", "1", "--photons-caustic", "0", "--photons-global", "0", "-q")
    assert r.returncode == 0, r.stderr
    warn = [line for line in r.stderr.splitlines() if "outside the file's frame range" in line]
    assert warn == ["stpm: warning: frame 3 outside the file's frame range 1..1 (rendered anyway, as Blender does)"]
    assert read_exr(tmp_path / "f.exr")["Combined"].shape == (6, 8, 4)


# ----------------------------------------------------------------------------
# 5. Ctrl-C while Python, Blender and the .blend load
# ----------------------------------------------------------------------------
def _wait_for_handlers(p: subprocess.Popen, timeout: float = 30.0) -> None:
    """Wait until ``stpm`` (pid p) has installed its signal handling: SIGTERM caught (/proc/PID/status SigCgt).

    Python itself catches SIGINT from its first instant; SIGTERM is caught only once
    stpm's main() runs, so this marks the end of interpreter start-up (a SIGINT before
    it is Python's own KeyboardInterrupt, outside stpm's reach).
    """
    status = Path(f"/proc/{p.pid}/status")
    if not status.exists():
        time.sleep(0.5)
        return
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout and p.poll() is None:
        for line in status.read_text().splitlines():
            if line.startswith("SigCgt:") and int(line.split()[1], 16) & (1 << (signal.SIGTERM - 1)):
                return
        time.sleep(0.005)
    raise AssertionError("stpm never installed its signal handlers")


@pytest.mark.bpy
@needs_blend
def test_ctrl_c_while_loading_a_blend_exits_130_without_traceback(tmp_path):
    """SIGINT 0 .. 1.2 s after stpm's start (imports, `import bpy`, the .blend load): exit 130, one line, no file.

    The render asked for is long (64x48, 256 samples), so every signal lands before it ends.
    """
    for delay in (0.0, 0.4, 0.8, 1.2):
        out = tmp_path / f"c{delay}.exr"
        p = subprocess.Popen([*_stpm_cmd(), "render", str(STATIC_BLEND), "-o", str(out), "--resolution", "64x48",
                              "--samples", "256", "--photons-caustic", "2000", "--photons-global", "0"],
                             cwd=ROOT, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        _wait_for_handlers(p)
        time.sleep(delay)
        assert p.poll() is None, p.communicate()
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
        assert p.returncode == 130, err
        assert "Traceback" not in err and err.strip().splitlines()[-1] == "stpm: render cancelled", err
        assert not out.exists()
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------
# 6. Memory
# ----------------------------------------------------------------------------
def test_image_too_big_for_memory_refused(tiny, tmp_path, no_render, monkeypatch, capsys):
    monkeypatch.setattr(command_common, "available_memory", lambda: 1 << 30)      # 1 GiB
    assert (command_common.image_memory((4000, 3000), "PHOTON") > 1 << 30
            > command_common.image_memory((400, 300), "ACCUMULATION"))
    assert cli.main(["render", str(tiny), "--resolution", "4000x3000", "-o", str(tmp_path / "x.exr"), "-q"]) == 1
    line = _one_error_line(capsys.readouterr().err, "GiB")
    assert "4000x3000 needs about 2.9 GiB" in line and "1.0 GiB available" in line
    monkeypatch.undo()
    # the real machine: 65536 x 65536 pixels need a TiB
    r = stpm("render", tiny, "--resolution", "65536x65536", "-o", tmp_path / "x.exr", "-q")
    assert r.returncode == 1
    _one_error_line(r.stderr, "1024.0 GiB")
    assert list(tmp_path.iterdir()) == []


def test_available_memory_is_plausible():
    avail = command_common.available_memory()
    total = os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    assert avail is not None and 0 < avail <= total


# ----------------------------------------------------------------------------
# 7. compare --reference
# ----------------------------------------------------------------------------
def test_compare_refuses_a_non_exr_reference(tiny, tmp_path):
    png = imageio.write_png(tmp_path / "ref.png", np.full((6, 8, 3), 0.5, np.float32))
    fake = tmp_path / "ref.exr"
    fake.write_bytes(b"not an exr at all")
    for ref, needle in ((png, "is a PNG image"), (fake, "is not an OpenEXR file")):
        r = stpm("compare", tiny, "--reference", ref, "-o", tmp_path / "cmp", "-q")
        assert r.returncode == 1
        _one_error_line(r.stderr, needle)
    assert not (tmp_path / "cmp").exists()


# ----------------------------------------------------------------------------
# 8. Progress on a pipe
# ----------------------------------------------------------------------------
def test_progress_pipe_one_line_per_phase_and_decile_not_per_tile():
    from stpm_core.progress import ProgressBar, phase_of
    assert phase_of("frame 2: tracing tile 3/130") == phase_of("frame 2: tracing tile 4/130") != \
        phase_of("frame 3: tracing tile 4/130")
    pipe = io.StringIO()
    bar = ProgressBar(stream=pipe)
    bar(0.0, "loading compiled kernels")
    for i in range(1, 11):
        bar(0.3 * i / 10, "tracing caustic photons")
    bar(0.3, "photon maps built")
    for t in range(130):
        bar(0.3 + 0.7 * (t + 1) / 130, f"tracing tile {t + 1}/130")
    bar(1.0, "done")
    lines = pipe.getvalue().splitlines()
    tiles = [line for line in lines if "tracing tile" in line]
    # phase start (30.5 %) then one per decile 40 .. 100 %: 8 lines, not 130
    assert len(tiles) == 8, lines
    assert len(lines) == 1 + 4 + 1 + 8 + 1, lines


def test_progress_of_a_real_render_on_a_pipe(tmp_path):
    """640x480 is traced in 80 tiles: at most 11 'tracing tile' lines (first tile + each 10 %)."""
    scene = save_scene(demo_scene(resolution=(640, 480)), tmp_path / "p.stpm",
                       settings=RenderSettings(samples=1, photons_caustic=0, photons_global=0))
    r = stpm("render", scene, "-o", tmp_path / "p.exr")
    assert r.returncode == 0, r.stderr
    progress = [line for line in r.stderr.splitlines() if "%" in line]
    tiles = [line for line in progress if "tracing tile" in line]
    n_tiles = int(tiles[-1].split("/")[1].split()[0])
    assert n_tiles >= 40, tiles       # enough tiles that one line per tile would show
    assert len(tiles) <= 11, r.stderr
    assert len(progress) <= 14, r.stderr


# ----------------------------------------------------------------------------
# 9. Blender's own output
# ----------------------------------------------------------------------------
@pytest.mark.bpy
@needs_blend
def test_bad_blend_is_one_error_line(tmp_path):
    fake = tmp_path / "fake.blend"
    fake.write_bytes(b"not a blend!")
    r = stpm("plan", fake)
    assert r.returncode == 1
    line = _one_error_line(r.stderr, "fake.blend")
    assert "Error:" not in line and "File format is not supported" in line
    assert r.stdout == ""


@pytest.mark.bpy
@needs_blend
def test_quiet_hides_blenders_read_blend_line(tmp_path):
    args = ("render", STATIC_BLEND, "-o", tmp_path / "q.exr", "--resolution", "8x6", "--samples", "1",
            "--photons-caustic", "0", "--photons-global", "0")
    loud, quiet = stpm(*args), stpm(*args, "-q")
    assert loud.returncode == 0 and quiet.returncode == 0, loud.stderr + quiet.stderr
    assert "Read blend:" in loud.stderr and "Read blend:" not in quiet.stderr
    assert "Read blend:" not in loud.stdout + quiet.stdout
    assert quiet.stdout.splitlines() == [f"wrote {tmp_path / 'q.exr'}", f"wrote {tmp_path / 'q.png'}"]


# ----------------------------------------------------------------------------
# 10. --method accumulation with an estimator
# ----------------------------------------------------------------------------
def test_accumulation_with_an_estimator_warns(tiny, tmp_path):
    base = ("render", tiny, "-o", tmp_path / "a.exr", "-q", "--method", "accumulation", "--accumulation-steps", "2")
    r = stpm(*base, "--estimator", "temporal")
    assert r.returncode == 0, r.stderr
    assert r.stderr.strip().splitlines() == ["stpm: warning: --estimator temporal has no effect with --method "
                                             "accumulation: each still is read with STANDARD"]
    r = stpm(*base)        # the file's estimator (TEMPORAL) was not asked for: no warning
    assert r.returncode == 0 and "--estimator" not in r.stderr, r.stderr
    assert json.loads(read_exr(tmp_path / "a.exr")["_metadata"]["stpm:stats"])["estimator"] == "STANDARD"


# ----------------------------------------------------------------------------
# 11. --version, help with ranges
# ----------------------------------------------------------------------------
def test_version_and_help_ranges(capsys):
    from importlib.metadata import version
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"stpm {version('stpm')}"
    assert cli.main(["render", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for needle in ("integer in [1, 65536]", "integer in [1, 4096]", "integer in [1, 100000]", "[1, 1e6]",
                   "[-1048574, 1048574]"):
        assert needle in text, needle


def test_default_output_keeps_a_hash_in_the_scene_name(tiny, tmp_path, capsys):
    """No --output: 'shot #1.stpm' -> 'shot #1.exr' (the '#' of the name is not a frame placeholder)."""
    scene = tmp_path / "shot #1.stpm"
    scene.write_bytes(tiny.read_bytes())
    assert cli.main(["render", str(scene), "-q"]) == 0
    assert capsys.readouterr().out.splitlines() == [f"wrote {tmp_path / 'shot #1.exr'}",
                                                    f"wrote {tmp_path / 'shot #1.png'}"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["shot #1.exr", "shot #1.png", "shot #1.stpm"]


def test_sigterm_cancels_and_a_second_signal_aborts(tmp_path):
    """SIGTERM: cancelled cleanly, exit 143.  A second signal before the cancel is done: 'stpm: aborted'
    at once, exit 128 + that signal.  No file left either way.

    The second signal is SIGTERM right after a SIGINT: two different signals are handled one after
    the other however close they come (two SIGINTs that close would be handled once), and a cancel
    takes a few milliseconds, too short to aim a second SIGINT into reliably."""
    scene = save_scene(demo_scene(resolution=(160, 120)), tmp_path / "long.stpm",
                       settings=RenderSettings(samples=64, photons_caustic=0, photons_global=0))
    for signals, status, last in (((signal.SIGTERM,), {143}, "stpm: render cancelled"),
                                  ((signal.SIGINT, signal.SIGTERM), {130, 143}, "stpm: aborted")):
        out = tmp_path / "out"
        out.mkdir()
        p = subprocess.Popen([*_stpm_cmd(), "render", str(scene), "-o", str(out / "c.exr"), "--stats",
                              str(out / "c.json")], cwd=ROOT, env=_env(), stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True)
        line = ""
        while "tracing tile" not in line:  # the render is running, tiles in flight
            line = p.stderr.readline()
            assert line, p.communicate(timeout=60)[1]
        for sig in signals:
            p.send_signal(sig)
        _, err = p.communicate(timeout=120)
        assert p.returncode in status, err
        assert err.strip().splitlines()[-1] == last and "Traceback" not in err, err
        assert list(out.iterdir()) == []
        out.rmdir()


def test_compare_checks_report_folder_and_memory_before_running(tiny, tmp_path):
    (tmp_path / "afile").write_text("x")
    r = stpm("compare", tiny, "-o", tmp_path / "afile", "-q")
    assert r.returncode == 1
    _one_error_line(r.stderr, "is a file, not a directory")
    r = stpm("compare", tiny, "-o", tmp_path / "cmp", "--resolution", "30000x30000", "-q")
    assert r.returncode == 1
    _one_error_line(r.stderr, "GiB")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]


def test_sigterm_during_plan_prints_no_plan_and_exits_143(tiny, monkeypatch, capsys):
    """A SIGTERM while `stpm plan` computes the plan: no plan on stdout, 'stpm: cancelled', status 143."""
    import os

    import stpm_core.plan as plan_mod
    real = plan_mod.make_plan

    def signalled(*a, **k):
        os.kill(os.getpid(), signal.SIGTERM)
        return real(*a, **k)

    monkeypatch.setattr(plan_mod, "make_plan", signalled)
    assert cli.main(["plan", str(tiny), "--json"]) == 143
    out, err = capsys.readouterr()
    assert out == "" and err.strip().splitlines()[-1] == "stpm: cancelled", (out, err)
