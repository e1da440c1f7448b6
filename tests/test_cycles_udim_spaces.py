"""UDIM images and Blender 5 working colour spaces against Cycles (bpy 5.0): direct-only renders,
block Z-test over 3 seeds of each renderer (``cycles_ref.block_ztest``), as tests/test_cycles_textures.py.

* A plane whose UV map spans four UDIM tiles (1001, 1002, 1011 on disk as 8-bit sRGB PNGs of
  different sizes, 1012 listed in Blender with no file): each quarter shows its own tile, Linear
  interpolation wraps within a tile (Repeat), and the missing tile reads Cycles' magenta.
* The same kind of scene in an ACEScg and a Linear Rec.2020 file (``bpy.ops.wm.set_working_color_space``):
  an 8-bit sRGB image converted into the working space, a coloured sun (its colour given in the
  working space), and a colour -> float conversion (RGB to BW driving an emission strength: the
  space's own luminance weights).  Each test also checks that the Rec.709 reading of the same
  file is far from Cycles, so it cannot pass by accident.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_addon_scenes import add_mesh  # noqa: E402
from test_cycles_textures import (Z_MAX, _assert_matches, _compare, _empty_material, _pattern,  # noqa: E402
                                  _top_down_scene, _write_png)

TILES = {1001: 8, 1002: 6, 1011: 5}          # tile -> its image's size (square, texels)


def _udim_files(tmp_path) -> str:
    """8-bit sRGB tiles of different sizes on disk; the path of the first."""
    for k, (tile, n) in enumerate(TILES.items()):
        _write_png(tmp_path / f"paint.{tile}.png", _pattern(n, seed=20 + k))
    return str(tmp_path / "paint.1001.png")


def _udim_plane(tmp_path, interpolation: str = "Linear"):
    """The top-down plane with its UVs scaled to [0, 2]^2 (tiles 1001, 1002, 1011, 1012), a Diffuse
    BSDF coloured by the UDIM image (tile 1012 added in Blender without a file)."""
    img = bpy.data.images.load(_udim_files(tmp_path))
    img.source = "TILED"
    img.tiles.new(1012)
    assert sorted(t.number for t in img.tiles) == [1001, 1002, 1011, 1012]
    mat, tree, out = _empty_material("Udim")
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation, tex.extension = img, interpolation, "REPEAT"
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    plane = add_mesh("plane", "Floor", material=mat, size=2.0)
    uv = plane.data.uv_layers.active.data
    for d in uv:
        d.uv = (2.0 * d.uv[0], 2.0 * d.uv[1])
    return img


@pytest.mark.parametrize("interpolation", ["Linear", "Closest"])
def test_udim_plane_over_four_tiles_matches_cycles(tmp_path, interpolation):
    _top_down_scene()
    _udim_plane(tmp_path, interpolation)
    r, stpm, cyc = _compare(tmp_path, f"UDIM 4 tiles ({interpolation})")
    _assert_matches(r, "UDIM")
    # Each quarter is its own tile: the block means differ between quarters as Cycles' do, and the
    # missing tile (u, v in [1, 2): the top-right quarter of the image) is magenta: red = blue, no green
    q = 3                                                   # 48 px / 8-px blocks = 6 x 6; quarters 3 x 3
    quarters = [r.cycles[:q, :q], r.cycles[:q, q:], r.cycles[q:, :q], r.cycles[q:, q:]]
    assert len({round(float(x.mean()), 3) for x in quarters}) == 4
    top_right = stpm.mean(axis=0)[2:22, 26:46]                  # (inside: the pixel filter blends edges)
    assert top_right[..., 1].max() < 1e-6 < top_right[..., 0].min()
    np.testing.assert_allclose(top_right[..., 0], top_right[..., 2], rtol=1e-6)
    # The first tile alone (what STPM did before: tile 1001 everywhere) is far from Cycles
    first = cyc.mean(axis=0)[24:, :24]                          # tile 1001: bottom-left quarter
    assert np.abs(cyc.mean(axis=0)[:24, :24].mean() - first.mean()) > 0.02


def _working_space_scene(tmp_path, space: str):
    """A file in working space ``space``: left, a plane with an 8-bit sRGB image under a warm sun;
    right, an emitter of constant colour whose strength is RGB to BW of the same image (the
    space's luminance).  Colours are set after the switch, so they are working-space values."""
    scene = _top_down_scene()
    if space != "Linear Rec.709":
        assert "FINISHED" in bpy.ops.wm.set_working_color_space(convert_colors=True, working_space=space)
    assert bpy.data.colorspace.working_space == space
    bpy.data.objects["Light"].data.color = (1.0, 0.8, 0.6)
    png = tmp_path / "photo.png"
    rng = np.random.default_rng(8)
    _write_png(png, rng.uniform(0.05, 0.95, (6, 6, 3)) * np.array([1.0, 0.5, 0.9]))
    img = bpy.data.images.load(str(png))
    img.colorspace_settings.name = "sRGB"
    mat, tree, out = _empty_material("Photo")
    bsdf = tree.nodes.new("ShaderNodeBsdfDiffuse")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image, tex.interpolation = img, "Linear"
    tree.links.new(tex.outputs["Color"], bsdf.inputs["Color"])
    tree.links.new(bsdf.outputs[0], out.inputs["Surface"])
    add_mesh("plane", "Floor", material=mat, size=1.0, location=(-0.5, 0.0, 0.0))
    emat, etree, eout = _empty_material("Luma")
    em = etree.nodes.new("ShaderNodeEmission")
    em.inputs["Color"].default_value = (0.3, 0.6, 0.9, 1.0)
    etex = etree.nodes.new("ShaderNodeTexImage")
    etex.image, etex.interpolation = img, "Closest"
    bw = etree.nodes.new("ShaderNodeRGBToBW")
    etree.links.new(etex.outputs["Color"], bw.inputs["Color"])
    etree.links.new(bw.outputs["Val"], em.inputs["Strength"])
    etree.links.new(em.outputs[0], eout.inputs["Surface"])
    add_mesh("plane", "Screen", material=emat, size=1.0, location=(0.5, 0.0, 0.0))
    return scene


@pytest.mark.parametrize("space", ["ACEScg", "Linear Rec.2020"])
def test_working_space_image_light_and_luma_match_cycles(tmp_path, space):
    _working_space_scene(tmp_path, space)
    r, stpm, cyc = _compare(tmp_path, f"working space {space}")
    _assert_matches(r, space)
    # Reading the image as Rec.709 (the old behaviour) would be far from Cycles: render that too
    from addon.export import nodes as node_export
    import cycles_ref
    old = node_export.working_space
    try:
        node_export.working_space = lambda: "REC709"       # the scene then claims Rec.709: no conversion
        as709, _ = cycles_ref.render_stpm(bpy.context.scene, samples=16, seeds=(0, 1))
    finally:
        node_export.working_space = old
    wrong = cycles_ref.block_ztest(as709, cyc)
    print(f"{space} read as Rec.709: {wrong.summary()}")
    assert wrong.z_abs_max > 3 * Z_MAX, wrong.summary()
