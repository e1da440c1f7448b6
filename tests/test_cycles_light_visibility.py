"""Light objects' Ray Visibility switches (Diffuse, Glossy, Transmission), as Cycles honours them.

Cycles leaves a hidden kind's closures out of a light sample's BSDF (``SHADER_EXCLUDE_*``): Diffuse
off, the light no longer lights diffuse surfaces (the floor and the Principled base go dark, the
glints stay); Glossy off, the glints of the Principled's specular layer go; its glass closures
(a Glass BSDF, a Principled's transmission) are left out only with Glossy *and* Transmission off
(measured in bpy 5.0.1: a rough glass pane lit from behind keeps all its light with either off).
STPM exported only Camera visibility; next-event estimation now keeps only the visible lobes
(``kernels.bsdf.bsdf_eval_lobes``), and rays leaving a surface do not see such a light
(``scene.light_visibility``; photons ignore the switches: a render warning says so).

The scene (``light_visibility_scenes``): a diffuse floor, a red Principled sphere and a rough glass
sphere under two radius-0 point lights, direct light only.  Measured (64 x 48, 32 spp, seeds
0-3, 8 x 8 blocks; block |z| max, mean ratio STPM / Cycles):

| switches off | old (switches ignored) | this |
| --- | --- | --- |
| Diffuse | 999, 56.7 (33 blocks over 3) | 3.54, 0.956 |
| Glossy | 45.6, 1.009 (5) | 2.96, 1.000 |
| Glossy + Transmission | 315, 1.017 (9) | 2.96, 1.000 |
| Diffuse, 1 m AREA lights (no MIS for them now) | | 2.62, 1.046 |

The mean ratios off 1 are the few glint pixels' noise (Diffuse off, 256 spp, seeds 4-7: 1.012).
About 2 minutes for all cases here (under load).
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

import light_visibility_scenes as lvs  # noqa: E402
from cycles_ref import block_ztest, render_cycles, render_stpm  # noqa: E402

SPP = 32
SEEDS = (0, 1, 2, 3)
Z_MAX = 4.5
DIRECT_ONLY = dict(max_depth=1, glossy_bounces=0, transmission_bounces=0, diffuse_bounces=0)


@pytest.mark.parametrize("off, area", [(("diffuse",), False), (("glossy",), False),
                                       (("glossy", "transmission"), False), (("diffuse",), True)])
def test_light_ray_visibility_matches_cycles(tmp_path, off, area):
    lvs.build(off, area=area)
    scene = bpy.context.scene
    cyc = render_cycles(scene, tmp_path, samples=SPP, seeds=SEEDS)
    stpm, res = render_stpm(scene, samples=SPP, seeds=SEEDS, **DIRECT_ONLY)
    r = block_ztest(stpm, cyc)
    print(f"{'+'.join(off)} off{', area lights' if area else ''}: {r.summary()}")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert any("Ray Visibility" in w and "photons" in w for w in res.warnings), res.warnings


def test_export_writes_the_switches():
    from test_addon_scenes import export_now
    lvs.build(("glossy",))
    core = export_now()[0]
    md = core.metadata
    assert md["light_visible_glossy"] == [False, False]
    assert md["light_visible_diffuse"] == md["light_visible_transmission"] == [True, True]
    from stpm_core.scene import light_visibility
    assert light_visibility(core).tolist() == [5, 5]
