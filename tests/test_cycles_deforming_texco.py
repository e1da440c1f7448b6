"""Object and Generated texture coordinates of a deforming mesh, as in Cycles.

Cycles reads Object coordinates as the hit point taken to object space (``svm_node_tex_coord``:
the inverse object transform of P), so on a surface that deforms during the shutter the texture
stays put in object space and the surface slides through it (sharp with motion blur).  Generated
reads the mesh's undeformed positions (``ATTR_STD_GENERATED`` from Blender's orco: the shape keys'
reference, the mesh before its modifiers) in the original mesh's texture space, so the texture
sticks to the surface (blurred with motion blur, not moved by a shape key's value).  STPM read both
from a deforming mesh's first motion step at the hit's barycentrics (and, without motion blur, from
the deformed shape), while its normals read the frame's step.

The scene (``deform_texco_scenes``): a plane bent by a shape key over the shutter, emitting a
Checker through Object or Generated coordinates, seen from above.  Measured (48 x 48, 16 spp,
seeds 0-3, 8 x 8 blocks; block |z| max / mean ratio STPM / Cycles):

| coordinates, motion blur | old (first step, deformed Generated) | this, seeds 0-3 | this, seeds 4-7 |
| --- | --- | --- | --- |
| Object, on | 40.1, 1.002 (29 blocks over 3) | 3.44, 1.002 | 4.09, 1.000 |
| Generated, off | 61.0, 0.976 (18) | 4.10, 1.001 | 3.82, 1.001 |
| Generated, on | 34.3, 0.988 (16) | 2.48, 1.001 | 3.59, 1.002 |

Emission only: the noise is the pixel filter's and the shutter's, so the 0.2 % floor of
``block_ztest`` sets most z; the largest sit on checker edges.  About 10 s here.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

import deform_texco_scenes as dts  # noqa: E402
from cycles_ref import block_ztest, render_cycles, render_stpm  # noqa: E402

SPP = 16
SEEDS = (0, 1, 2, 3)
Z_MAX = 5.0


@pytest.mark.parametrize("coords, blur", [("Object", True), ("Generated", False), ("Generated", True)])
def test_deforming_plane_texture_coordinates_match_cycles(tmp_path, coords, blur):
    dts.build(coords, blur)
    scene = bpy.context.scene
    cyc = render_cycles(scene, tmp_path, samples=SPP, seeds=SEEDS)
    stpm, _ = render_stpm(scene, samples=SPP, seeds=SEEDS, max_depth=1)
    r = block_ztest(stpm, cyc)
    print(f"{coords}, motion blur {blur}: {r.summary()}")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))


def test_export_carries_the_undeformed_positions():
    """The exporter writes Mesh.orco (the shape keys' reference) for the bent plane; a plain
    plane gets none."""
    from test_addon_scenes import export_now
    dts.build("Generated", True)
    core = export_now()[0]
    m = core.meshes[0]
    assert m.is_deforming and m.orco is not None and m.orco.shape == (m.vertices.shape[1], 3)
    assert np.abs(m.orco[:, 0]).max() <= 1.0 + 1e-6          # the flat 2 x 2 grid
    assert np.abs(m.vertices[0] - m.orco).max() > 0.1          # deformed at the shutter's start
    bpy.data.objects["Sheet"].shape_key_clear()
    assert export_now()[0].meshes[0].orco is None


def test_manual_texture_space_matches_cycles(tmp_path):
    """Auto Texture Space off, a location and size that are not the plane's bounds: Generated is
    normalised by them (``Mesh.texspace``), as in Cycles; the exporter carries them and the scene
    file keeps them.  (Before, STPM used the plane's bounds: cells 1.1-1.7x too large and shifted, block |z| max 389.)"""
    from test_addon_scenes import export_now
    from stpm_core import scenefile
    scene = dts.build_texspace()
    core = export_now()[0]
    np.testing.assert_allclose(core.meshes[0].texspace, np.array(dts.TEXSPACE), atol=1e-6)
    path = tmp_path / "ts.stpm"
    scenefile.save_scene(core, str(path))
    np.testing.assert_allclose(scenefile.load_scene(str(path)).meshes[0].texspace, core.meshes[0].texspace)
    cyc = render_cycles(scene, tmp_path, samples=SPP, seeds=SEEDS)
    stpm, _ = render_stpm(scene, samples=SPP, seeds=SEEDS, max_depth=1)
    r = block_ztest(stpm, cyc)
    print(f"manual texture space: {r.summary()}")
    assert r.z_abs_max < Z_MAX, (r.summary(), np.round(r.z, 1))
    bpy.data.objects["Sheet"].data.use_auto_texspace = True
    assert export_now()[0].meshes[0].texspace is None
