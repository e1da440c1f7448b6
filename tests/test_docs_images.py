"""docs/make_images.py: the README's moving-receiver pictures regenerate from the current code."""
from __future__ import annotations

import importlib.util
import os

import numpy as np
import pytest

pytest.importorskip("bpy")

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_make_images_quick_writes_three_panels(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("make_images", os.path.join(ROOT, "docs", "make_images.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--quick", "--out", str(tmp_path)]) == 0
    from stpm_core.imageio import read_png
    for name in ("moving_receiver_standard_temporal_accumulation.png", "moving_receiver_caustic_pass.png"):
        img = read_png(tmp_path / name)
        assert img.shape[:2] == (45, 180)              # three 60 x 45 renders side by side
        assert np.isfinite(img).all() and img.max() > 0
    out = capsys.readouterr().out
    means = {line.split()[0]: float(line.split("Caustic mean")[1].split()[0])
             for line in out.splitlines() if "Caustic mean" in line}
    # time-less photons on the moving box: darker than the time-dependent estimate and the 16 stills
    assert means["STANDARD"] < means["TEMPORAL"] and means["STANDARD"] < means["ACCUMULATION"]


def test_make_progressive_images_quick_writes_the_passes(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("make_progressive_images",
                                                  os.path.join(ROOT, "docs", "make_progressive_images.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--quick", "--out", str(tmp_path)]) == 0
    from stpm_core.imageio import read_png
    for name in ("progressive_passes.png", "progressive_passes_caustic.png"):
        img = read_png(tmp_path / name)
        assert img.shape[:2] == (45, 180)              # passes 1, 4, 16 at 60 x 45, side by side
        assert img.max() > 0
    out = capsys.readouterr().out
    assert [int(line.split()[1]) for line in out.splitlines() if line.startswith("pass")] == [1, 4, 16]


def test_make_udim_image_quick_writes_both_pictures(tmp_path, capsys):
    spec = importlib.util.spec_from_file_location("make_udim_image", os.path.join(ROOT, "docs", "make_udim_image.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.main(["--quick", "--out", str(tmp_path)]) == 0
    from stpm_core.imageio import read_png
    udim = read_png(tmp_path / "udim_stpm_vs_cycles.png")
    assert udim.shape[:2] == (48, 98)                  # STPM | Cycles, 48 x 48 each, a 2-pixel gap
    assert read_png(tmp_path / "working_space_acescg_stpm_vs_cycles.png").shape[:2] == (48, 148)
    out = capsys.readouterr().out
    ratios = [float(line.split("mean ratio STPM / Cycles")[1].split(",")[0]) for line in out.splitlines()
              if "mean ratio STPM / Cycles" in line]
    assert len(ratios) == 2 and all(abs(r - 1.0) < 0.03 for r in ratios), out
