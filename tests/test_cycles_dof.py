"""Depth of field against Cycles (bpy 5.0): the same blur, block by block.

``dof_scenes``: an emissive checker strip inclined to a 200 mm camera (depth 1.2 to 1.9) and small
emissive spheres far behind it (depth 9, bokeh 5 to 13 px wide), at f/1.4 and f/4 with a round
aperture, at f/2 with 5 blades rotated 25 degrees and an anamorphic ratio of 1.5, and an
orthographic camera at f/4 with 5 blades.  Emission
only, so the image is the camera's sampling alone.  Each block's mean must agree within noise
(``cycles_ref.block_ztest``).  On main (depth of field ignored: a pinhole, with a warning) the
blurred strip and the bokeh fail it: block |z| max 94, 71, 40 and 74 for f/1.4, f/4, f/2 and the
orthographic case (2026-12-07).
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

import dof_scenes  # noqa: E402
from cycles_ref import block_ztest, render_cycles, render_stpm  # noqa: E402

SPP = 64
SEEDS = (0, 1, 2, 3)
Z_MAX = 4.5
MEAN_TOL = 0.02


@pytest.mark.parametrize("case", sorted(dof_scenes.CASES))
def test_depth_of_field_matches_cycles(case, tmp_path):
    dof_scenes.build(case)
    cyc = render_cycles(bpy.context.scene, tmp_path, samples=SPP, seeds=SEEDS, max_bounces=0)
    stpm, _ = render_stpm(bpy.context.scene, samples=SPP, seeds=SEEDS, max_depth=1)
    r = block_ztest(stpm, cyc)
    print(f"{case}: {r.summary()}")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < MEAN_TOL, r.summary()
