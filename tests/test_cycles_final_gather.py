"""Final gathering against Cycles 5.0 on a small Cornell-like box (tests/gather_scenes.py).

Cycles' indirect light is its full render (4 diffuse bounces, STPM's default budget) minus its
direct-only render (max_bounces = 0), seed by seed; STPM's is the Indirect pass with
``final_gather_samples = 8`` (and, for the second assertion, 0: today's direct visualisation of
the global map).  Block Z-test over 4 seeds of each (6 x 6 pixel blocks, 48 blocks), as
tests/cycles_ref.py.  What would fail: a gather whose cache lacked the direct irradiance at its
hits loses the one-bounce light, most of the indirect (-58 % here); one that also added the
emission its rays see counts light twice; a wrong budget (``reader``) shifts the mean by about
the fifth bounce's share (+3 % here).
About 40 s on 2 cores (Cycles 16 renders of 48 x 36 at 128 spp, STPM 8 renders).
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from cycles_ref import block_ztest, render_cycles, render_cycles_paths  # noqa: E402

SEEDS = (0, 1, 2, 3)
STPM = dict(samples=16, photons_caustic=0, photons_global=100_000, k_nearest=50)
# 1 % of a block's level added to its standard error: the photon estimate's own bias (k-nearest blur
# of the precomputed irradiance at the gather hits), and 4 seeds' variance estimates have heavy tails
# (one block of 48 reached z = 8 at a +3 % offset without it, in an earlier version).  Measured with
# it: |z| max 1.8, mean 1.002 (final gather), 3.1, 1.008 (direct visualisation).  The mutations of
# the module docstring measured: the cache's direct part left out: mean 0.42, |z| 82; the budget
# read as without gathering (reader 1): mean 1.029.
FLOOR = 0.01


def _stpm_indirect(final_gather: int):
    """(K, H, W, 3) STPM Indirect passes of the exported box, one per seed, and the last result."""
    from addon.export import export_scene
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    bl = bpy.context.scene
    core = export_scene(bpy.context.evaluated_depsgraph_get(), lambda f, sub: bl.frame_set(f, subframe=sub))[0]
    out, res = [], None
    for s in SEEDS:
        res = render(core, RenderSettings(seed=s, final_gather_samples=final_gather, **STPM))
        out.append(np.asarray(res.passes["Indirect"][..., :3], np.float64))
    return np.stack(out), res


@pytest.fixture(scope="module")
def cycles_indirect(tmp_path_factory):
    import gather_scenes
    tmp = tmp_path_factory.mktemp("fg_cycles")
    scene = gather_scenes.cornell()
    full = render_cycles_paths(scene, tmp, samples=128, seeds=SEEDS, diffuse_bounces=4, glossy_bounces=4,
                               transmission_bounces=4)
    direct = render_cycles(scene, tmp, samples=128, seeds=SEEDS, max_bounces=0)
    return full - direct


def test_final_gather_matches_cycles_indirect_and_direct_visualisation(cycles_indirect):
    gathered, res = _stpm_indirect(8)
    assert res.stats["gather_rays"] > 0 and res.stats["gather_lookups"] > 0
    zg = block_ztest(gathered, cycles_indirect, block=6, floor=FLOOR)
    print("final gather vs Cycles:", zg.summary())
    assert abs(zg.mean_ratio - 1.0) < 0.02, zg.summary()
    assert zg.z_abs_max < 4.5, zg.summary()
    # today's direct visualisation: the same light within its own bias
    direct_vis, _ = _stpm_indirect(0)
    zd = block_ztest(direct_vis, cycles_indirect, block=6, floor=FLOOR)
    print("direct visualisation vs Cycles:", zd.summary())
    ratio = gathered.mean() / direct_vis.mean()
    print(f"final gather / direct visualisation: {ratio:.4f}")
    assert abs(ratio - 1.0) < 0.03



@pytest.fixture(scope="module")
def cycles_coated(tmp_path_factory):
    import gather_scenes
    tmp = tmp_path_factory.mktemp("fg_cycles_coat")
    scene = gather_scenes.cornell(coated_floor=True)
    return render_cycles_paths(scene, tmp, samples=128, seeds=SEEDS, diffuse_bounces=4, glossy_bounces=4,
                               transmission_bounces=4)


def test_final_gather_keeps_the_light_of_a_rough_coat(cycles_coated):
    """The box with a black coated floor under a spot (``gather_scenes.cornell(coated_floor=True)``):
    walls and ceiling are lit by the floor's rough dielectric coat, light paths L C x with no
    diffuse vertex before the camera's x.  Photons count a rough coat as a diffuse bounce, so those
    paths were global photons, which with final gathering only gather vertices read, and a gather
    ray through the coat that meets the light adds nothing (that light is the caustic map's): until
    2026-12-06 they were lost, mean 0.948 of Cycles here (9 blocks |z| > 3), the textured room's
    gathered image 0.973 (its right wall 0.940).  Now such photons (no DIFFUSE-lobe bounce behind
    them) go to the caustic map, which the camera vertex reads: mean 1.0002.  Whole images (Combined)
    against Cycles: with a coated floor the passes split its glossy reflections differently.  The
    block |z| max, 4.8, is the spot's pool on the floor seen in the coat (direct visualisation, no
    gathering: 5.1), left alone; 6 bounds it."""
    import gather_scenes
    gather_scenes.cornell(coated_floor=True)
    from addon.export import export_scene
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    bl = bpy.context.scene
    core = export_scene(bpy.context.evaluated_depsgraph_get(), lambda f, sub: bl.frame_set(f, subframe=sub))[0]
    out = []
    for s in SEEDS:
        res = render(core, RenderSettings(seed=s, final_gather_samples=8, **STPM))
        out.append(np.asarray(res.passes["Combined"][..., :3], np.float64))
    z = block_ztest(np.stack(out), cycles_coated, block=6, floor=FLOOR)
    print("coated floor, final gather vs Cycles:", z.summary(), "coat-path photons:",
          res.stats.get("photon_stats", {}).get("photons_global_coat_paths"))
    assert abs(z.mean_ratio - 1.0) < 0.02, z.summary()
    assert z.z_abs_max < 6.0, z.summary()
