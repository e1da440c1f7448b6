"""Image output: multilayer EXR with Blender's channel names; sRGB PNG preview."""
from __future__ import annotations

import json

import numpy as np
import pytest

from stpm_core.film import PASSES
from stpm_core.imageio import linear_to_srgb, read_exr, read_png, write_exr, write_png


def _passes(H=5, W=7, seed=3):
    rng = np.random.default_rng(seed)
    return {name: (rng.random((H, W, c)) * 10 - 2).astype(np.float32) for name, c, _ in PASSES}


def _blender_channel_names():
    """What Blender writes for these passes: ViewLayer.<Pass>.<channel id>."""
    return {f"ViewLayer.{name}.{ids[i]}" for name, c, ids in PASSES for i in range(c)}


def test_exr_round_trip_exact_channels_and_values(tmp_path):
    passes = _passes()
    path = write_exr(tmp_path / "r.exr", passes, metadata={"plan": {"caustics": True}, "note": "hello"})
    back = read_exr(path)
    assert set(back["_channels"]) == _blender_channel_names()
    assert "ViewLayer.Combined.R" in back["_channels"] and "ViewLayer.Depth.Z" in back["_channels"]
    assert "ViewLayer.Normal.X" in back["_channels"] and "ViewLayer.Emit.B" in back["_channels"]
    for name, c, _ in PASSES:
        assert back[name].shape == passes[name].shape
        assert np.array_equal(back[name], passes[name]), name  # float32: bit exact
    meta = back["_metadata"]
    assert json.loads(meta["stpm:plan"]) == {"caustics": True}
    assert meta["stpm:note"] == "hello"
    assert meta["compression"] == "zip"


def test_exr_rows_top_first(tmp_path):
    """Row 0 of the array is the top scanline of the file (a gradient keeps its direction)."""
    H, W = 4, 3
    ramp = np.repeat(np.arange(H, dtype=np.float32)[:, None, None], W, axis=1)
    passes = {"Depth": ramp}
    import OpenImageIO as oiio
    path = write_exr(tmp_path / "d.exr", passes)
    buf = oiio.ImageBuf(str(path))
    assert buf.getpixel(0, 0)[0] == 0.0 and buf.getpixel(0, H - 1)[0] == H - 1


def test_exr_half_rounds_colours_keeps_depth_float(tmp_path):
    passes = _passes()
    passes["Depth"][0, 0, 0] = 1e10  # Blender's background depth: beyond half's range
    back = read_exr(write_exr(tmp_path / "h.exr", passes, half=True))
    for name in passes:
        want = passes[name] if name == "Depth" else passes[name].astype(np.float16).astype(np.float32)
        assert np.array_equal(back[name], want), name


def test_exr_with_result_object_stores_stats(tmp_path):
    class Result:
        passes = _passes(2, 2)
        stats = {"wall_s": 1.5, "samples": np.int64(4), "resolution": np.array([2, 2])}
    back = read_exr(write_exr(tmp_path / "s.exr", Result()))
    assert json.loads(back["_metadata"]["stpm:stats"]) == {"wall_s": 1.5, "samples": 4, "resolution": [2, 2]}


def test_srgb_encoding_inverts_the_standard_decoding():
    """Every 8-bit code decoded with the IEC 61966-2-1 inverse curve encodes back to itself."""
    code = np.arange(256)
    s = code / 255.0
    linear = np.where(s <= 0.04045, s / 12.92, ((s + 0.055) / 1.055) ** 2.4)
    assert np.array_equal(np.round(linear_to_srgb(linear) * 255).astype(int), code)


def test_png_known_values(tmp_path):
    # 0.5 linear is sRGB 0.7354 (188); 0.18 (mid grey) is 0.4614 (118); 0.0031308 is the linear-segment end
    rgb = np.array([[[0.0, 0.5, 1.0], [0.18, 0.0031308, 0.001]],
                    [[np.nan, np.inf, -np.inf], [-1.0, 2.0, 1e30]]], dtype=np.float32)
    png = read_png(write_png(tmp_path / "p.png", rgb))
    assert png.shape == (2, 2, 3)
    assert png[0, 0].tolist() == [0, 188, 255]
    assert png[0, 1].tolist() == [118, 10, 3]
    # NaN -> 0, +inf -> 255, -inf -> 0; negative clips to 0, above 1 to 255
    assert png[1, 0].tolist() == [0, 255, 0]
    assert png[1, 1].tolist() == [0, 255, 255]


def test_png_drops_alpha_and_rejects_bad_shapes(tmp_path):
    from stpm_core.errors import StpmError
    rgba = np.ones((3, 2, 4), np.float32)
    assert read_png(write_png(tmp_path / "a.png", rgba)).shape == (3, 2, 3)
    with pytest.raises(StpmError):
        write_png(tmp_path / "b.png", np.ones((3, 2), np.float32))


@pytest.mark.bpy
def test_blender_reads_the_exr_as_multilayer(tmp_path):
    """Blender itself opens the file as a multilayer EXR and finds every pass by name."""
    bpy = pytest.importorskip("bpy")
    path = write_exr(tmp_path / "b.exr", _passes(4, 6))
    img = bpy.data.images.load(str(path))
    img.reload()
    _ = len(img.pixels)  # force the load
    assert img.type == "MULTILAYER"
    tree = bpy.data.node_groups.new("stpm_test", "CompositorNodeTree")
    node = tree.nodes.new("CompositorNodeImage")
    node.image = img
    outputs = {o.name for o in node.outputs}
    assert {name for name, _, _ in PASSES} <= outputs
    bpy.data.node_groups.remove(tree)
    bpy.data.images.remove(img)
