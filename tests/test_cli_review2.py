"""``stpm render`` after the second artist review: a .blend's Render Region is written as Blender
writes it (``blender -b -f``): with Crop to Render Region the region alone, else the whole frame
blank outside it.  Before, the command line ignored the region and wrote the whole frame rendered.
"""
from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from stpm_core import cli
from stpm_core.errors import StpmError
from stpm_core.imageio import read_exr
from test_cli_review import STATIC_BLEND, _env, needs_blend, stpm

# Blender 5.0.1 / Cycles on a 40 x 30 frame with this region (measured in the review): cropped
# 20 x 12; not cropped 40 x 30 with Combined (0, 0, 0, 0) and Depth 1e10 outside the region.
BOX = (0.25, 0.75, 0.1, 0.5)


def test_scene_region_is_blenders_pixel_arithmetic():
    meta = {"render_region": list(BOX)}
    x0, r0, x1, r1 = cli.scene_region(meta, (40, 30))
    assert (x1 - x0, r1 - r0) == (20, 12) and (x0, x1) == (10, 30) and (r0, r1) == (15, 27)  # rows from the top
    assert cli.scene_region({"render_region": [0, 1, 0, 1]}, (40, 30)) is None          # the whole frame
    assert cli.scene_region({}, (40, 30)) is None
    with pytest.raises(StpmError, match="render_region"):
        cli.scene_region({"render_region": [0, "x", 0, 1]}, (40, 30))


def test_apply_render_region_crops_or_blanks():
    H, W = 30, 40
    passes = {"Combined": np.random.default_rng(0).random((H, W, 4)).astype(np.float32) + 0.1,
              "Depth": np.full((H, W, 1), 3.0, np.float32)}
    keep = {k: v.copy() for k, v in passes.items()}
    stats = {}
    cli.apply_render_region(passes, {"render_region": list(BOX), "render_region_crop": True}, stats)
    assert passes["Combined"].shape == (12, 20, 4)
    np.testing.assert_array_equal(passes["Combined"], keep["Combined"][15:27, 10:30])
    assert stats["render_region"]["crop"] is True
    passes = {k: v.copy() for k, v in keep.items()}
    cli.apply_render_region(passes, {"render_region": list(BOX)}, {})
    c, d = passes["Combined"], passes["Depth"]
    assert c.shape == (H, W, 4)
    np.testing.assert_array_equal(c[15:27, 10:30], keep["Combined"][15:27, 10:30])
    assert np.all(c[:15] == 0) and np.all(c[:, :10] == 0) and np.all(d[:15] == 1e10) and np.all(d[15:27, 10:30] == 3)


@needs_blend
@pytest.mark.parametrize("crop", [True, False])
def test_stpm_render_writes_a_blend_render_region_as_blender(tmp_path, crop):
    blend = tmp_path / "region.blend"
    code = (f"import bpy; bpy.ops.wm.open_mainfile(filepath={str(STATIC_BLEND)!r}); r = bpy.context.scene.render; "
            f"r.resolution_x, r.resolution_y, r.resolution_percentage = 40, 30, 100; "
            f"r.use_border = True; r.use_crop_to_border = {crop}; "
            f"r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = {BOX}; "
            f"bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, env=_env(), timeout=120)
    opts = ["--frame", "1", "--samples", "1", "--photons-global", "200", "--photons-caustic", "200", "--quiet"]
    r = stpm("render", blend, *opts, "-o", tmp_path / "r.exr")
    assert r.returncode == 0, r.stderr
    full = stpm("render", STATIC_BLEND, *opts, "--resolution", "40x30", "-o", tmp_path / "f.exr")
    assert full.returncode == 0, full.stderr
    got, ref = read_exr(tmp_path / "r.exr"), read_exr(tmp_path / "f.exr")
    g, f = got["Combined"], ref["Combined"]
    if crop:
        assert g.shape[:2] == (12, 20)
        np.testing.assert_allclose(g, f[15:27, 10:30], rtol=1e-5, atol=1e-6)
    else:
        assert g.shape[:2] == (30, 40)
        np.testing.assert_allclose(g[15:27, 10:30], f[15:27, 10:30], rtol=1e-5, atol=1e-6)
        assert np.all(g[:15] == 0) and np.all(g[:, 30:] == 0)
        assert np.all(got["Depth"][:15] == 1e10)
