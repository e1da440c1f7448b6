"""Colour spaces (stpm_core.colorspaces) against OpenColorIO with Blender's own config.

Blender 5.0.1's bundled ``config.ocio`` (inside the bpy wheel) is read by OpenImageIO's colour
management (``ImageBufAlgo.colorconvert``, OpenColorIO 2.4): every linear colour space Blender
offers converted into each working space must equal :func:`colorspaces.conversion` to 2e-6, the
luminance weights the Y row of the working space's RGB -> XYZ (D65) conversion, and the sRGB
space the EOTF followed by the Rec.709 matrix.  Skipped when bpy (for the config) or an
OpenImageIO with OpenColorIO is missing.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from stpm_core import colorspaces as cs
from stpm_core.schema import METADATA


def _blender_config() -> Path | None:
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        return None
    root = Path(list(spec.submodule_search_locations)[0])
    found = sorted(root.glob("*/datafiles/colormanagement/config.ocio"))
    return found[-1] if found else None


CONFIG = _blender_config()


def _ocio(src: str, dst: str, values: np.ndarray) -> np.ndarray:
    """values (n, 3) float32 converted from src to dst by OpenColorIO with Blender's config."""
    oiio = pytest.importorskip("OpenImageIO")
    n = values.shape[0]
    buf = oiio.ImageBuf(oiio.ImageSpec(n, 1, 3, "float"))
    buf.set_pixels(oiio.ROI(), np.ascontiguousarray(values, np.float32).reshape(1, n, 3))
    out = oiio.ImageBufAlgo.colorconvert(buf, src, dst, colorconfig=str(CONFIG))
    assert not out.has_error, out.geterror()
    return np.asarray(out.get_pixels(oiio.FLOAT), np.float64).reshape(n, 3)


needs_config = pytest.mark.skipif(CONFIG is None, reason="Blender's OCIO config (bpy) is not installed")


@needs_config
@pytest.mark.parametrize("working", list(cs.WORKING_SPACES))
def test_linear_spaces_match_opencolorio(working):
    """Every linear space -> every working space: the matrix equals OpenColorIO's transform."""
    for src in cs.TO_XYZ_D65:
        M = cs.conversion(src, working)
        M = np.eye(3) if M is None else M
        got = _ocio(src, cs.WORKING_SPACES[working], np.eye(3)).T          # columns: images of R, G, B
        np.testing.assert_allclose(M, got, atol=2e-6, err_msg=f"{src} -> {working}")


@needs_config
@pytest.mark.parametrize("working", list(cs.WORKING_SPACES))
def test_encoded_spaces_and_luma_match_opencolorio(working):
    """sRGB and Display P3 pixels (to_working) and the luminance weights, against OpenColorIO."""
    rng = np.random.default_rng(5)
    px = rng.uniform(0.0, 1.0, (64, 3))
    for space in ("sRGB", "Display P3", "Linear Rec.709", "ACEScg"):
        np.testing.assert_allclose(cs.to_working(px, space, working), _ocio(space, cs.WORKING_SPACES[working], px),
                                   rtol=1e-4, atol=3e-5, err_msg=space)   # (OpenColorIO's fast pow: 2e-5)
    y = _ocio(cs.WORKING_SPACES[working], "Linear CIE-XYZ D65", np.eye(3))[:, 1]
    np.testing.assert_allclose(cs.luma(working), y, atol=5e-5)


def test_working_space_ids_are_the_schema_choices():
    """The scene metadata's working_space choices are exactly the spaces the renderer knows."""
    spec = next(s for s in METADATA if s.name == "working_space")
    assert set(spec.values) == set(cs.WORKING_SPACES)
    assert spec.default == cs.DEFAULT_WORKING
    assert cs.working_space_of({}) == "REC709" and cs.working_space_of({"working_space": "acescg"}) == "ACESCG"
    with pytest.raises(ValueError):
        cs.working_space_of({"working_space": "Rec.709"})


def test_conversions_are_consistent():
    """Identity within a space, inverse pairs, white maps to white (every space shares D65 after
    adaptation, so grey stays grey), and data / already-converted spaces never convert."""
    for w in cs.WORKING_SPACES:
        assert cs.conversion(cs.WORKING_SPACES[w], w) is None
        for src in ("Linear Rec.709", "ACEScg", "Linear DCI-P3 D65", "ACES2065-1"):
            M = cs.conversion(src, w)
            if M is not None:
                np.testing.assert_allclose(M @ np.ones(3), np.ones(3), atol=2e-6, err_msg=f"{src} -> {w}")
    a, b = cs.conversion("ACEScg", "REC709"), cs.conversion("Linear Rec.709", "ACESCG")
    np.testing.assert_allclose(a @ b, np.eye(3), atol=1e-12)
    for name in cs.DATA_SPACES + cs.SCENE_LINEAR_SPACES:
        assert cs.space_of(name) == ("linear", None)


def test_outputs_name_the_working_space(tmp_path):
    """The CLI's outputs: the EXR holds the working space's values and names it (colorInteropID, as
    Blender writes it; none for Rec.709), the PNG preview converts them to Rec.709 before sRGB
    encoding (an ACEScg red preview equals the Rec.709 red it came from)."""
    pytest.importorskip("OpenImageIO")
    from stpm_core.imageio import read_exr, read_png, write_exr, write_png
    red709 = np.array([0.6, 0.1, 0.05])
    aces = cs.conversion("Linear Rec.709", "ACESCG") @ red709
    img = np.tile(aces, (2, 3, 1))
    write_png(tmp_path / "a.png", img, working="ACESCG")
    write_png(tmp_path / "r.png", np.tile(red709, (2, 3, 1)))
    np.testing.assert_array_equal(read_png(tmp_path / "a.png"), read_png(tmp_path / "r.png"))
    assert not np.array_equal(read_png(tmp_path / "a.png"), (write_png(tmp_path / "w.png", img),
                                                               read_png(tmp_path / "w.png"))[1])
    passes = {"Combined": np.concatenate([img, np.ones((2, 3, 1))], axis=2).astype(np.float32)}
    write_exr(tmp_path / "a.exr", passes, working="ACESCG")
    write_exr(tmp_path / "r.exr", passes)
    assert read_exr(tmp_path / "a.exr")["_metadata"].get("colorInteropID") == "lin_ap1_scene"
    assert "colorInteropID" not in read_exr(tmp_path / "r.exr")["_metadata"]
