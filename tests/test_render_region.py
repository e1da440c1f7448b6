"""A Render Region traces its own pixels only, with method PROGRESSIVE too, and to the pixel.

docs/blender.md ("Render Region"), docs/cli.md ("Render Region").  The camera samples of a pixel
come from its tile's random stream (seed, pass, tile index), drawn in order over the tile's samples
and then over its paths' bounces: so a tile wholly inside the region is traced exactly as in a whole
frame (bit-equal pixels), and a tile the region's edge crosses traces the region's pixels alone
(the same camera rays, other shading random numbers: equal in distribution).
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from scenes import make_scene, ortho_camera_down, plane_mesh, translate
from stpm_core.film import DEPTH_BACKGROUND
from stpm_core.motion import MotionTransform
from stpm_core.render import render
from stpm_core.scene import Light, Material
from stpm_core.settings import RenderSettings

ROOT = Path(__file__).resolve().parents[1]
# 2 samples per pass: 64-pixel tiles (integrator.BATCH_SAMPLES); 192 x 128 is 3 x 2 tiles
PROG = dict(method="PROGRESSIVE", passes=4, samples=2, photons_caustic=0, photons_global=0, seed=3,
            effects="MANUAL", use_adaptive_sampling=False)


def _soft_shadow_scene(res=(192, 128), metadata=None):
    """A floor under an area light and a small occluder: every pixel's value is noisy (soft shadow,
    the light's area sampled per camera sample)."""
    light = Light(type="AREA", power=200.0, size=0.6, transform=MotionTransform.static(translate(0, 0, 1.5)))
    occluder = plane_mesh(0.4, z=0.6, material=0, name="occluder")
    return make_scene([plane_mesh(10.0, material=0), occluder], [Material.diffuse((0.8, 0.8, 0.8))],
                      ortho_camera_down(height=3.0, ortho_scale=2.0), [light], resolution=res, metadata=metadata)


def test_progressive_region_traces_exactly_its_pixels():
    # Before: PROGRESSIVE ignored the region (every pass traced the whole frame), and without
    # adaptive sampling the other methods traced the whole 64-px tiles the region touched
    scene = _soft_shadow_scene()
    st = RenderSettings(**PROG)
    full = render(scene, st)
    win = (40, 0, 136, 100)                      # x0, y0, x1, y1: holds tile (64..128, 0..64) whole
    part = render(scene, st, window=win)
    inside = np.zeros((128, 192), bool)
    inside[0:100, 40:136] = True
    # -- the region's camera rays and no other -------------------------------------------------
    assert part.stats["camera_rays"] == inside.sum() * 2 * 4, (part.stats["camera_rays"], inside.sum())
    assert full.stats["camera_rays"] == 192 * 128 * 2 * 4
    a, b = full.passes["Combined"], part.passes["Combined"]
    assert np.all(b[~inside] == 0) and np.all(b[inside][:, 3] == 1)
    assert np.all(part.passes["Depth"][~inside] == DEPTH_BACKGROUND)
    # -- a tile wholly inside: the whole frame's pixels, bit for bit ----------------------------
    whole = np.zeros_like(inside)
    whole[0:64, 64:128] = True
    np.testing.assert_array_equal(a[whole], b[whole])
    # -- the edge tiles' pixels: the whole frame's camera rays (Depth, Normal equal), other shading
    #    random numbers (Combined equal within noise) ---------------------------------------------
    edge = inside & ~whole
    for name in ("Depth", "Normal"):
        np.testing.assert_array_equal(full.passes[name][edge], part.passes[name][edge], err_msg=name)
    d = (b[edge][:, :3] - a[edge][:, :3]).mean(axis=1)
    assert np.mean(d != 0) > 0.5                  # (noisy: the test can tell equal from unequal)
    z = d.mean() / (d.std(ddof=1) / np.sqrt(d.size))
    assert abs(z) < 4.0, z
    # the same per-pixel spread (the edge pixels are not smoothed or doubled up)
    assert 0.7 < np.var(b[edge][:, 0]) / np.var(a[edge][:, 0]) < 1.3
    # -- the noise estimate is over the region's 8 x 8 blocks ------------------------------------
    assert part.sums.window == win
    assert part.stats["progressive"]["noise_p95"] > 0


def test_photon_method_region_edge_tiles_trace_the_region_alone():
    # Without adaptive sampling the tiles a region touched were traced whole (main): 4 tiles here
    scene = _soft_shadow_scene()
    st = RenderSettings(**{**PROG, "method": "PHOTON", "samples": 2})
    win = (60, 50, 70, 80)                        # 10 x 30 pixels across two tiles' corners
    part = render(scene, st, window=win)
    assert part.stats["camera_rays"] == 10 * 30 * 2
    b = part.passes["Combined"]
    assert np.count_nonzero(b[..., 3]) == 300


# ----------------------------------------------------------------------------
# Partial results of a region: stpm render --pass-offset, stpm merge
# ----------------------------------------------------------------------------
def _cli(*args, cwd):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "stpm_core.cli", *args], cwd=cwd, env=env, capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def region_parts(tmp_path_factory):
    from stpm_core.scenefile import save_scene
    d = tmp_path_factory.mktemp("region")
    st = RenderSettings(**{k: v for k, v in PROG.items() if k not in ("method", "passes")})
    # 48 x 32 (one tile); region A columns 12..35, rows 8..23, cropped; region B the left half, top
    for name, meta in (("a", {"render_region": [0.25, 0.75, 0.25, 0.75], "render_region_crop": True}),
                       ("b", {"render_region": [0.0, 0.5, 0.5, 1.0]}), ("f", {})):
        save_scene(_soft_shadow_scene((48, 32), metadata=meta), d / f"{name}.stpm", st)
    for args in (("a.stpm", "--passes", "8", "-o", "a_full.exr", "--stats", "a_full.json"),
                 ("a.stpm", "--pass-offset", "0", "--passes", "4", "-o", "a1.exr", "--stats", "a1.json"),
                 ("a.stpm", "--pass-offset", "4", "--passes", "4", "-o", "a2.exr"),
                 ("b.stpm", "--pass-offset", "4", "--passes", "4", "-o", "b2.exr"),
                 ("f.stpm", "--pass-offset", "4", "--passes", "4", "-o", "f2.exr")):
        out = _cli("render", *args, "--method", "progressive", "-q", cwd=d)
        assert out.returncode == 0, out.stderr
    return d


def test_a_region_partial_traces_the_region_and_merges_into_one_processs_image(region_parts):
    import json
    from stpm_core.imageio import read_exr
    from stpm_core.partial import read_partial
    d = region_parts
    sums, head = read_partial(d / "a1.exr")
    assert head["region"] == [12, 8, 36, 24] and head["region_crop"] is True and sums.window == (12, 8, 36, 24)
    assert json.loads((d / "a1.json").read_text())["camera_rays"] == 24 * 16 * 2 * 4
    out = _cli("merge", "a1.exr", "a2.exr", "-o", "a_merged.exr", cwd=d)
    assert out.returncode == 0, out.stderr
    one, merged = read_exr(d / "a_full.exr"), read_exr(d / "a_merged.exr")
    assert one["Combined"].shape == (16, 24, 4)          # Crop to Render Region, as stpm render writes it
    for name in ("Combined", "Depth", "Direct", "Normal"):
        np.testing.assert_array_equal(one[name], merged[name], err_msg=name)


@pytest.mark.parametrize("other,message", [
    ("b2.exr", "different Render Regions (columns 0..23, rows 0..15 and columns 12..35, rows 8..23)"),
    ("f2.exr", "different Render Regions (the whole frame and columns 12..35, rows 8..23)"),
])
def test_merge_refuses_partials_of_another_region(region_parts, other, message):
    out = _cli("merge", "a1.exr", other, "-o", "bad.exr", cwd=region_parts)
    assert out.returncode == 1 and message in out.stderr and out.stderr.count("\n") == 1, out.stderr
    assert not (region_parts / "bad.exr").exists()


def test_the_noise_of_a_region_is_estimated_over_its_pixels():
    # The Final Progressive preset stops at a noise threshold: over a whole frame that is 0 outside
    # the region, the noiseless blocks outside would pull the 95th percentile down (an early stop)
    from stpm_core.progressive import PassSums, noise_estimate
    rng = np.random.default_rng(4)
    win = (8, 0, 24, 16)
    region, crop, frame = PassSums(1, window=win), PassSums(1), PassSums(1)
    for i in range(1, 5):
        img = np.zeros((32, 48, 4), np.float32)
        img[0:16, 8:24, :3] = rng.gamma(4.0, 0.25, (16, 16, 1))
        region.add(i, {"Combined": img})
        frame.add(i, {"Combined": img})
        crop.add(i, {"Combined": img[0:16, 8:24]})
    got, want = noise_estimate(region), noise_estimate(crop)
    assert got["blocks"].shape == (2, 2)
    assert got["noise_p95"] == want["noise_p95"] and got["noise_mean"] == want["noise_mean"]
    assert noise_estimate(frame)["noise_mean"] < 0.2 * got["noise_mean"]      # (what the frame's blocks say)
