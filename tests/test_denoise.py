"""Cycles' denoising passes from the core (``RenderSettings.denoise``; kernels.paths.denoising_rows).

Known answers on small scenes: a diffuse plane's Denoising Albedo is its colour and its Denoising
Normal its normal in Cycles' camera space (x right, y up, z into the view); the world behind gives
its radiance and a zero normal; a mirror hands both on to what it reflects, times its Fresnel; a
rough metal stops them when its GGX alpha is above Cycles' 0.075, and not below.  The other passes
are bit-identical with and without ``denoise``.  Against Cycles itself, and through Blender's
Denoise node: tests/test_addon_denoise.py.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from kernel_scenes import kernel_scenes
from scenes import make_scene, ortho_camera_down, plane_mesh, translate
from stpm_core.film import DENOISING_PASSES
from stpm_core.render import render
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings

ST = RenderSettings(samples=4, photons_global=0, photons_caustic=0, seed=3, filter_width=0.0, threads=1,
                    denoise=True)


def _rot_x(deg: float, pos=(0.0, 0.0, 0.0)) -> np.ndarray:
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    M = translate(*pos)
    M[1:3, 1:3] = [[c, -s], [s, c]]
    return M


def test_the_passes_come_with_denoise_and_change_nothing_else():
    names = {n for n, _c, _i in DENOISING_PASSES}
    for label, scene, st in kernel_scenes():
        plain = render(scene, st)
        guided = render(scene, st.replace(denoise=True))
        assert set(guided.passes) - set(plain.passes) == names, label
        for name, img in plain.passes.items():          # bit for bit: the features draw no random numbers
            assert np.array_equal(img, guided.passes[name]), (label, name)
        assert np.array_equal(guided.passes["Noisy Image"], guided.passes["Combined"]), label
        assert np.all(np.isfinite(guided.passes["Denoising Albedo"])), label


def test_a_diffuse_plane_gives_its_colour_and_its_normal_and_the_world_its_radiance():
    base = np.array([0.6, 0.3, 0.2])
    world = (0.05, 0.1, 0.2)
    scene = make_scene([plane_mesh(1.0, material=0)], [Material(base_color=base, specular=0.0, roughness=0.5)],
                       ortho_camera_down(ortho_scale=2.0), world=world, resolution=(16, 16))
    res = render(scene, ST)
    alb, nrm = res.passes["Denoising Albedo"], res.passes["Denoising Normal"]
    plane = np.zeros((16, 16), bool)
    plane[4:12, 4:12] = True                  # the 1 m plane in the 2 m view (box filter: whole pixels)
    np.testing.assert_allclose(alb[plane], np.broadcast_to(base, (64, 3)), atol=1e-6)
    np.testing.assert_allclose(nrm[plane], np.broadcast_to([0.0, 0.0, -1.0], (64, 3)), atol=1e-6)
    np.testing.assert_allclose(alb[~plane], np.broadcast_to(world, ((~plane).sum(), 3)), atol=1e-6)
    assert np.all(nrm[~plane] == 0.0)


def test_a_mirror_hands_the_features_on_to_what_it_reflects():
    """A mirror tilted 45 degrees under an orthographic camera sends every ray sideways onto a wall:
    the albedo is the wall's colour times the mirror's Fresnel at 45 degrees, the normal the wall's."""
    wall = np.array([0.2, 0.5, 0.7])
    f0 = 0.9
    mats = [Material(base_color=np.full(3, f0), metallic=1.0, roughness=0.0),
            Material(base_color=wall, specular=0.0, roughness=0.5)]
    mirror = (plane_mesh(4.0, material=0), _rot_x(45.0))            # normal (0, -1, 1) / sqrt 2
    wall_obj = (plane_mesh(10.0, material=1), _rot_x(-90.0, pos=(0.0, -3.0, 0.0)))   # at y = -3, facing +y
    scene = make_scene([mirror, wall_obj], mats, ortho_camera_down(ortho_scale=1.0), resolution=(8, 8))
    res = render(scene, ST)
    fresnel = f0 + (1.0 - f0) * (1.0 - math.cos(math.radians(45.0))) ** 5
    np.testing.assert_allclose(res.passes["Denoising Albedo"].reshape(-1, 3),
                               np.broadcast_to(fresnel * wall, (64, 3)), rtol=1e-6)
    np.testing.assert_allclose(res.passes["Denoising Normal"].reshape(-1, 3),
                               np.broadcast_to([0.0, 1.0, 0.0], (64, 3)), atol=1e-6)


@pytest.mark.parametrize("roughness, stops", [(0.3, True), (0.25, False)])
def test_a_rough_metal_stops_the_features_above_cycles_alpha_and_not_below(roughness, stops):
    """Cycles counts a lobe as diffuse-like when its GGX alpha = roughness^2 exceeds 0.075
    (roughness 0.274): then the albedo is the metal's reflectance (F0 head-on) and the normal its
    own; below, the features go on with the reflected rays, which leave for a black world."""
    base = np.array([0.9, 0.6, 0.3])
    scene = make_scene([plane_mesh(4.0, material=0)], [Material(base_color=base, metallic=1.0, roughness=roughness)],
                       ortho_camera_down(ortho_scale=1.0), resolution=(8, 8))
    res = render(scene, ST)
    alb, nrm = res.passes["Denoising Albedo"].reshape(-1, 3), res.passes["Denoising Normal"].reshape(-1, 3)
    if stops:
        np.testing.assert_allclose(alb, np.broadcast_to(base, (64, 3)), atol=1e-6)
        np.testing.assert_allclose(nrm, np.broadcast_to([0.0, 0.0, -1.0], (64, 3)), atol=1e-6)
    else:
        assert np.all(alb == 0.0) and np.all(nrm == 0.0)


def test_progressive_passes_and_their_partial_results_carry_the_denoising_passes(tmp_path):
    """PROGRESSIVE averages the guides pass by pass like every pass; ``stpm render --pass-offset``'s
    partial results hold them (stpm merge reads them back)."""
    from stpm_core.demo import demo_scene
    from stpm_core.partial import read_partial, write_partial
    from stpm_core.progressive import PassSums
    st = RenderSettings(method="PROGRESSIVE", passes=2, samples=2, photons_global=2000, photons_caustic=2000,
                        seed=1, denoise=True)
    res = render(demo_scene((24, 18)), st)
    assert {n for n, _c, _i in DENOISING_PASSES} <= set(res.passes)
    assert np.array_equal(res.passes["Noisy Image"], res.passes["Combined"])
    plain = render(demo_scene((24, 18)), st.replace(denoise=False))
    for name, img in plain.passes.items():
        assert np.array_equal(img, res.passes[name]), name
    sums = PassSums(1)                       # passes count from 1
    sums.add(1, res.passes)
    write_partial(tmp_path / "p.exr", sums, seed=1, scene_digest="0" * 64, settings_digest="1" * 64)
    back, _head = read_partial(tmp_path / "p.exr")
    np.testing.assert_array_equal(back.sums["Denoising Normal"], res.passes["Denoising Normal"].astype(np.float64))


def test_without_blender_the_command_line_keeps_the_raw_image_and_says_so(monkeypatch):
    """``stpm render`` denoises in a Blender child process; where bpy cannot be found, Combined stays
    the raw image and one warning line says why (the guide passes are written all the same)."""
    from types import SimpleNamespace
    import stpm_core.blend_loader as bl

    def no_bpy():
        raise ImportError("no module named 'bpy'")

    monkeypatch.setattr(bl, "_child_env", no_bpy)
    monkeypatch.setattr(bl, "_DENOISERS", {})
    raw = np.full((4, 4, 4), 0.5, np.float32)
    result = SimpleNamespace(passes={"Combined": raw, "Denoising Albedo": np.ones((4, 4, 3), np.float32),
                                     "Denoising Normal": np.zeros((4, 4, 3), np.float32)}, stats={})
    warnings = bl.denoise_result(result, "shot.blend")
    assert len(warnings) == 1 and "bpy" in warnings[0] and "not denoised" in warnings[0]
    assert result.passes["Combined"] is raw and "denoise_s" not in result.stats
