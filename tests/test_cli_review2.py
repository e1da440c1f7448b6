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
    # The region's pixels are traced alone (tests/test_render_region.py): their camera rays are the
    # whole frame's (Depth and Normal equal), their shading draws other random numbers (Combined
    # equal within noise)
    def same_pixels(a, b):
        for name in ("Depth", "Normal"):
            np.testing.assert_allclose(a[name], b[name], rtol=1e-5, atol=1e-6, err_msg=name)
        ca, cb = a["Combined"], b["Combined"]
        assert abs(ca[..., :3].mean() / cb[..., :3].mean() - 1) < 0.1, (ca[..., :3].mean(), cb[..., :3].mean())
        np.testing.assert_array_equal(ca[..., 3], cb[..., 3])
    if crop:
        assert g.shape[:2] == (12, 20)
        same_pixels(got, {k: ref[k][15:27, 10:30] for k in ("Depth", "Normal", "Combined")})
    else:
        assert g.shape[:2] == (30, 40)
        same_pixels({k: got[k][15:27, 10:30] for k in ("Depth", "Normal", "Combined")},
                    {k: ref[k][15:27, 10:30] for k in ("Depth", "Normal", "Combined")})
        assert np.all(g[:15] == 0) and np.all(g[:, 30:] == 0)
        assert np.all(got["Depth"][:15] == 1e10)


# The PNG of ``stpm render``: Blender writes a PNG through the file's colour management (AgX by
# default in Blender 4+); ``stpm render`` wrote the sRGB curve of clipped values whatever the file
# said (on the review's AgX product shot: mean |difference| 24/255, max 60, 4 % of pixels clipped
# white where Blender's PNG has none).
_BLENDER_PNG = """
import sys, numpy as np, OpenImageIO as oiio, bpy
blend, exr, out = sys.argv[1:4]
bpy.ops.wm.open_mainfile(filepath=blend)
s = bpy.context.scene; s.render.dither_intensity = 0.0
inp = oiio.ImageInput.open(exr); sub = 0
while inp.seek_subimage(sub, 0):
    sp = inp.spec(); n = list(sp.channelnames)
    if "ViewLayer.Combined.R" in n:
        px = inp.read_image(sub, 0, 0, sp.nchannels, "float").reshape(sp.height, sp.width, sp.nchannels)
        rgb = np.ascontiguousarray(px[..., [n.index("ViewLayer.Combined." + c) for c in "RGB"]])
    sub += 1
b = oiio.ImageBuf(oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, "float")); b.set_pixels(oiio.ROI(), rgb)
b.write(out + ".lin.exr")
img = bpy.data.images.load(out + ".lin.exr"); img.colorspace_settings.name = "Linear Rec.709"
f = s.render.image_settings; f.media_type = "IMAGE"; f.file_format = "PNG"; f.color_mode = "RGB"
img.save_render(out, scene=s)
"""


@needs_blend
@pytest.mark.parametrize("view,exposure,gamma", [("AgX", 0.0, 1.0), ("Filmic", 0.7, 1.3)])
def test_stpm_render_png_follows_the_files_view_transform(tmp_path, view, exposure, gamma):
    import OpenImageIO as oiio
    blend = tmp_path / "view.blend"
    code = (f"import bpy; bpy.ops.wm.open_mainfile(filepath={str(STATIC_BLEND)!r}); s = bpy.context.scene; "
            f"r = s.render; r.resolution_x, r.resolution_y, r.resolution_percentage = 40, 30, 100; "
            f"v = s.view_settings; v.view_transform = {view!r}; v.exposure = {exposure}; v.gamma = {gamma}; "
            f"bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})")
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, env=_env(), timeout=120)
    r = stpm("render", blend, "--frame", "1", "--samples", "2", "--photons-global", "500", "--photons-caustic",
             "500", "--quiet", "-o", tmp_path / "r.exr")
    assert r.returncode == 0, r.stderr
    ref = tmp_path / "blender.png"
    subprocess.run([sys.executable, "-c", _BLENDER_PNG, str(blend), str(tmp_path / "r.exr"), str(ref)],
                   check=True, capture_output=True, env=_env(), timeout=120)
    got = oiio.ImageBuf(str(tmp_path / "r.png")).get_pixels(oiio.UINT8).astype(int)
    want = oiio.ImageBuf(str(ref)).get_pixels(oiio.UINT8).astype(int)[..., :3]
    assert got.shape == want.shape
    assert np.abs(got - want).max() <= 1, (np.abs(got - want).max(), np.abs(got - want).mean())


# Partials of one frame from the .blend at two paths: the exporter records the path it was given
# (metadata.source), which went into the scene hash and the fingerprint's header, so `stpm merge`
# refused them as "partials of different scenes" (a copy of the review's bottle under another name;
# on a farm: workers mounting the project at different paths, or run from another folder).
def test_scene_hash_ignores_where_the_scene_came_from():
    from stpm_core.demo import demo_scene
    from stpm_core.partial import fingerprint_difference, scene_fingerprint, scene_hash
    a, b = demo_scene(resolution=(8, 6)), demo_scene(resolution=(8, 6))
    a.metadata.update(source="/mnt/proj/shot.blend", warnings=["image '/mnt/proj/tex/wood.png' is missing"])
    b.metadata.update(source="P:/proj/shot.blend", warnings=["image 'P:/proj/tex/wood.png' is missing"])
    assert scene_hash(a) == scene_hash(b)
    assert fingerprint_difference(scene_fingerprint(a), scene_fingerprint(b)) is None
    b.metadata["film_transparent"] = True            # what changes pixels still counts
    assert scene_hash(a) != scene_hash(b)
    assert fingerprint_difference(scene_fingerprint(a), scene_fingerprint(b)) is not None


@needs_blend
def test_partials_of_one_blend_at_two_paths_merge(tmp_path):
    import shutil
    other = tmp_path / "elsewhere" / "copy.blend"
    other.parent.mkdir()
    shutil.copy(STATIC_BLEND, other)
    opts = ["--frame", "1", "--method", "progressive", "--samples", "1", "--photons-global", "200",
            "--photons-caustic", "200", "--resolution", "16x12", "--quiet"]
    one = stpm("render", STATIC_BLEND, *opts, "--passes", "4", "-o", tmp_path / "one.exr")
    a = stpm("render", STATIC_BLEND, *opts, "--pass-offset", "0", "--passes", "2", "-o", tmp_path / "a.exr")
    b = stpm("render", other, *opts, "--pass-offset", "2", "--passes", "2", "-o", tmp_path / "b.exr")
    assert one.returncode == a.returncode == b.returncode == 0, (one.stderr, a.stderr, b.stderr)
    m = stpm("merge", tmp_path / "a.exr", tmp_path / "b.exr", "-o", tmp_path / "m.exr")
    assert m.returncode == 0, m.stderr
    np.testing.assert_array_equal(read_exr(tmp_path / "m.exr")["Combined"], read_exr(tmp_path / "one.exr")["Combined"])
