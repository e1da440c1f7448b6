"""Fixes from the sixth artist review (an animated outdoor product shot, review/make_review6.py), through
the real bpy module: Denoise ticked by a script before it sets the engine denoises; a global photon
map too sparse to read directly (an open scene) is named in the render report.
"""
from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import add_camera, add_light, add_mesh, export_now, fresh  # noqa: E402

import addon  # noqa: E402

addon.register()


def test_denoise_ticked_before_the_engine_is_set_still_denoises():
    # The review's script set scene.stpm.denoise before render.engine = 'STPM' (the property is
    # there whatever the engine); the Render Layers node had no guide-pass sockets then, so the
    # group went in without its Albedo and Normal and every F12 said "the image is not denoised"
    from addon.denoise import GROUP, compositor_problem
    scene = fresh()
    add_camera()
    engine = scene.render.engine
    assert engine != "STPM"
    scene.stpm.denoise = True
    assert scene.render.engine == engine             # the engine the script had is left as it was
    scene.render.engine = "STPM"
    assert compositor_problem(scene) is None
    node = scene.compositing_node_group.nodes[GROUP]
    assert node.inputs["Albedo"].links and node.inputs["Normal"].links


def _open_ground(k: int, final_gather: int):
    """A sun over a wide plane and a small box (an open scene: few bounced photons are stored); the
    core's render result at 16 x 12, 1 sample, 4000 global photons."""
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    fresh()
    add_camera(location=(0, -6, 2))
    add_light("SUN", energy=3.0, location=(0, 0, 5))
    add_mesh("plane", "Ground", size=20)
    add_mesh("cube", "Box", location=(0, 0, 1))
    core, _w = export_now()
    settings = RenderSettings(samples=1, photons_global=4000, photons_caustic=0, k_nearest=k,
                              final_gather_samples=final_gather, seed=1)
    core.resolution = (16, 12)
    return render(core, settings)


@pytest.mark.parametrize("k, final_gather, named", [(50, 0, True), (50, 2, False), (1, 0, False)])
def test_a_sparse_global_map_is_named(k, final_gather, named):
    # The review's lawn stored 530 of 1 M global photons (Final, k 100): the plinth's sides, lit by
    # the lawn's bounce, came out 18 % short in green against Cycles without a word; Final Gather
    # Samples 16 brought them within 2 %
    result = _open_ground(k, final_gather)
    stored = result.stats["photons_global"]
    notes = [w for w in result.warnings if w.startswith("the global photon map holds")]
    assert 10 < stored < 500, stored                 # the scene is what the test means: open, few stored
    assert len(notes) == int(named), result.warnings
    if named:
        assert f"holds {stored} of 4000 photons" in notes[0] and "Final Gather Samples" in notes[0]
