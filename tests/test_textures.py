"""Image textures: storage (stpm_core.textures), packing, and the compiled look-up
(stpm_core.kernels.texture) against the numpy oracle written from Cycles' CPU image kernel and
Cycles' / Blender's image loading (tests/oracles/texture_numpy.py).

* :class:`Texture` keeps each image in its native type (uint8, uint16, half bit patterns in
  uint16, float32; 1, 3 or 4 channels, 2 = grey + alpha) and costs exactly its own pixels;
* :func:`pack_textures`: header (offset into the kind's array, size, channels, kind, sRGB) and
  the flat arrays hold every texel, RGBA images with associated alpha as Cycles holds them;
* ``tex_lookup_batch`` / ``tex_lookup`` for every interpolation x extension x storage kind, linear
  and sRGB, every alpha mode, with and without the un-associate flag, to float rounding
  (tolerance 1e-9: the kernel and the oracle both work in float64 on the same stored texels;
  sRGB 2e-7, the kernel's EOTF table).

RGBA 16-bit, half and float images follow Blender's float32 buffers: decoded to linear per texel,
then premultiplied in float32 (tolerance 2e-7 relative); data (Non-Color) images are never
associated.
"""
from __future__ import annotations

import zlib

import numpy as np
import pytest

from oracles import texture_numpy as oracle
from stpm_core import colorspaces
from stpm_core.kernels.texture import srgb_eotf, tex_image_rows, tex_lookup, tex_lookup_batch
from stpm_core.textures import (F32, H_MATRIX, H_SRGB, HALF, HALF_TABLE, N_HEADER, SRGB_TABLE, U8, U16, Texture,
                                pack_textures, srgb_to_linear)

RTOL, ATOL = 1e-9, 1e-9
# sRGB textures: the kernel's EOTF is a 4097-entry table with linear interpolation on [0, 1], within
# 6.7e-8 of the formula (Cycles' own CPU path, color_srgb_to_linear_v4 with the SSE2 fastpow24
# approximation in float32, is no closer); 2e-7 absolute on the converted channels.
SRGB_ATOL = 2e-7
INTERPS = ("Closest", "Linear", "Cubic", "Smart")
EXTS = ("REPEAT", "EXTEND", "CLIP", "MIRROR")
KINDS = ("U8", "U16", "HALF", "F32")
MODES = oracle.ALPHA_MODES
_TOP = {"U8": 255, "U16": 65535}

# Float / 16-bit / half RGBA images whose alpha is associated are premultiplied per texel in float32,
# as Blender's float32 buffer holds them (the oracle too): float32 rounding of c * a, 2e-7 relative.
ASSOC_RTOL = 2e-7


def _seed(*parts) -> int:
    return zlib.crc32("/".join(parts).encode())


def _pixels(kind: str, H: int, W: int, C: int, rng, hdr: bool = False) -> np.ndarray:
    if kind in _TOP:
        return rng.integers(0, _TOP[kind] + 1, (H, W, C)).astype(np.uint8 if kind == "U8" else np.uint16)
    hi = 4.0 if hdr else 1.0
    v = rng.uniform(0.0, hi, (H, W, C))
    return v.astype(np.float16) if kind == "HALF" else v.astype(np.float32)


def _rgba(kind: str, H: int, W: int, rng, hdr: bool = False, premul: bool = False) -> np.ndarray:
    """RGBA pixels with some texels fully transparent and some opaque; premul: colours <= alpha
    (a valid premultiplied image; float HDR colours scale with alpha)."""
    px = _pixels(kind, H, W, 4, rng, hdr)
    one = _TOP.get(kind, 1.0)
    flat = px.reshape(-1, 4)
    if kind not in _TOP:
        flat[:, 3] = rng.uniform(0.0, 1.0, flat.shape[0])
    flat[0, 3], flat[1, 3], flat[2, 3] = 0, one, 0
    if premul:
        if kind in _TOP:
            wide = flat.astype(np.int64)
            flat[:, :3] = (wide[:, :3] * wide[:, 3:4]) // one
        else:
            flat[:, :3] = (flat[:, :3].astype(np.float32) * flat[:, 3:4].astype(np.float32)).astype(flat.dtype)
    return px


def _lookup(textures, tid: int, xy: np.ndarray, interp: str, ext: str) -> np.ndarray:
    pack = pack_textures(textures)
    out = np.zeros((xy.shape[0], 4))
    tex_lookup_batch(pack.header, pack.u8, pack.u16, pack.f32, pack.half, tid, np.ascontiguousarray(xy, np.float64),
                     oracle.INTERP[interp], oracle.EXT[ext], False, out)
    return out


def _lookup_unassociated(textures, tid: int, xy: np.ndarray, interp: str, ext: str) -> np.ndarray:
    """tex_lookup with the un-associate flag (what the Image Texture instruction runs when its Alpha
    output is used)."""
    pack = pack_textures(textures)
    return np.array([tex_lookup(pack.header, pack.u8, pack.u16, pack.f32, pack.half, tid, float(x), float(y),
                                oracle.INTERP[interp], oracle.EXT[ext], True) for x, y in xy])


def _close(got, exp, tx, **kw):
    float_assoc = tx.kind != U8 and tx.associates_alpha
    np.testing.assert_allclose(got, exp, rtol=ASSOC_RTOL if float_assoc else RTOL,
                               atol=SRGB_ATOL if tx.is_srgb else ATOL, **kw)


def _coords(rng, n: int, W: int, H: int) -> np.ndarray:
    """Random (u, v): over several tiles, in the image, near its border (within two texels either
    side: Clip's fade), plus texel centres and edges nudged off exact boundaries."""
    t = rng.uniform(0.0, 1.0, n)
    d = rng.uniform(-2.0, 2.0, n)
    side = rng.integers(0, 4, n)
    bx = np.where(side == 0, d / W, np.where(side == 1, 1 + d / W, t))
    by = np.where(side == 2, d / H, np.where(side == 3, 1 + d / H, t[::-1]))
    return np.concatenate([rng.uniform(-1.7, 2.7, (n, 2)), rng.uniform(0.0, 1.0, (n, 2)), np.stack([bx, by], 1),
                           (np.stack(np.meshgrid(np.arange(W + 1) / W, np.arange(H + 1) / H), -1).reshape(-1, 2)
                            + 1.37e-4)])


def _centres(W: int, H: int) -> np.ndarray:
    return np.array([[(i + 0.5) / W, (j + 0.5) / H] for j in range(H) for i in range(W)])


# ----------------------------------------------------------------------------
# Storage
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("channels", [1, 2, 3, 4])
@pytest.mark.parametrize("dtype,kind", [(np.uint8, U8), (np.uint16, U16), (np.float16, HALF), (np.float32, F32)])
def test_texture_storage(dtype, kind, channels):
    rng = np.random.default_rng(channels)
    H, W = 3, 5
    px = (rng.uniform(0, 1, (H, W, channels)) * (255 if dtype == np.uint8 else 65535 if dtype == np.uint16 else 1)
          ).astype(dtype)
    tx = Texture(px, colorspace="Linear")
    stored_c = 4 if channels == 2 else channels
    assert tx.kind == kind
    assert tx.pixels.shape == (H, W, stored_c)
    assert tx.pixels.dtype == (np.uint16 if dtype == np.float16 else dtype)
    assert tx.half == (dtype == np.float16)
    itemsize = np.dtype(dtype).itemsize
    assert tx.nbytes == H * W * stored_c * itemsize == tx.pixels.nbytes    # memory = its own size
    # the stored texels decode to the input values (2 channels: grey + alpha)
    T = oracle.texels(tx)
    ref = px.astype(np.float64) / (255.0 if dtype == np.uint8 else 65535.0 if dtype == np.uint16 else 1.0)
    np.testing.assert_array_equal(T[:, :, 0], ref[:, :, 0])
    if channels >= 3:
        np.testing.assert_array_equal(T[:, :, :3], ref[:, :, :3])
    if channels in (2, 4):
        np.testing.assert_array_equal(T[:, :, 3], ref[:, :, -1])
    else:
        assert np.all(T[:, :, 3] == 1.0)
    # decoded(): linear RGBA, per texel
    np.testing.assert_allclose(tx.decoded(), T, rtol=0, atol=0)
    srgb = Texture(px, colorspace="sRGB")
    exp = T.copy()
    exp[:, :, :3] = oracle.srgb_to_linear(exp[:, :, :3])
    np.testing.assert_allclose(srgb.decoded(), exp, rtol=1e-12, atol=1e-15)


def test_texture_conversions_and_errors():
    f64 = Texture(np.full((2, 2, 3), 0.25))                        # float64 is stored as float32
    assert f64.pixels.dtype == np.float32 and f64.kind == F32 and f64.nbytes == 2 * 2 * 3 * 4
    assert f64.alpha_mode == "STRAIGHT"                            # Blender's default Image.alpha_mode
    grey = Texture(np.zeros((4, 3), np.uint8))                     # (H, W) = one channel
    assert grey.pixels.shape == (4, 3, 1)
    halfbits = Texture(np.full((1, 1, 1), 0x3C00, np.uint16), half=True)   # bit patterns of 1.0
    assert halfbits.kind == HALF and oracle.texels(halfbits)[0, 0, 0] == 1.0
    assert Texture(np.zeros((1, 1, 3)), colorspace="Non-Color").is_srgb is False
    assert Texture(np.zeros((1, 1, 3)), colorspace="sRGB").is_srgb is True
    for bad in (np.zeros((2, 2, 5), np.uint8), np.zeros((0, 2, 3), np.uint8), np.zeros((2,), np.uint8),
                np.zeros((2, 2, 3), np.int32)):
        with pytest.raises(ValueError):
            Texture(bad)


def test_tables():
    bits = np.arange(65536, dtype=np.uint32).astype(np.uint16)
    np.testing.assert_array_equal(HALF_TABLE.view(np.uint32), bits.view(np.float16).astype(np.float32).view(np.uint32))
    np.testing.assert_allclose(SRGB_TABLE, oracle.srgb_to_linear(np.arange(256) / 255.0), rtol=1e-7)
    c = np.concatenate([np.linspace(-0.5, 1.5, 2001), [0.0, 0.04, 0.0405, 1.0]])
    np.testing.assert_allclose(srgb_to_linear(np.clip(c, 0, None)), oracle.srgb_to_linear(np.clip(c, 0, None)),
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose([srgb_eotf(x) for x in c], oracle.srgb_to_linear(c), rtol=0, atol=SRGB_ATOL)


def _cycles_stored(tx) -> np.ndarray:
    """The stored words of the images of test_pack_layout: a straight RGBA byte image premultiplied
    as Cycles' load_byte_pixels does ((c * a) / 255 in integers); float / 16-bit images as given
    (their association happens per texel when read, header column 6)."""
    px = tx.pixels
    if px.shape[2] != 4 or tx.alpha_mode != "STRAIGHT" or px.dtype != np.uint8 or not tx.associates_alpha:
        return px.reshape(-1)
    wide = px.astype(np.int64)
    out = wide.copy()
    out[:, :, :3] = wide[:, :, :3] * wide[:, :, 3:4] // 255
    return out.astype(np.uint8).reshape(-1)


def test_pack_layout():
    rng = np.random.default_rng(3)
    texs = [Texture(_pixels("U8", 3, 4, 4, rng)), Texture(_pixels("F32", 2, 5, 3, rng), colorspace="Linear"),
            Texture(_pixels("HALF", 4, 2, 1, rng)), Texture(_pixels("U16", 2, 3, 3, rng), colorspace="Raw"),
            Texture(_pixels("U8", 1, 6, 1, rng), colorspace="Non-Color"),
            Texture(_pixels("F32", 3, 3, 4, rng), colorspace="Linear"),
            Texture(_pixels("U16", 2, 2, 4, rng), alpha_mode="PREMUL"),
            Texture(_pixels("U8", 3, 2, 4, rng), colorspace="Linear", alpha_mode="CHANNEL_PACKED")]
    pack = pack_textures(texs)
    assert pack.header.shape == (len(texs), N_HEADER) and pack.header.dtype == np.int64
    arrays = {U8: pack.u8, U16: pack.u16, HALF: pack.u16, F32: pack.f32}
    used = {U8: 0, U16: 0, F32: 0}
    for i, tx in enumerate(texs):
        off, W, H, C, kind, srgb, assoc, matrix = pack.header[i]
        # sRGB: 1 decoded after interpolation (8-bit), 2 per texel (every other kind); no matrix in Rec.709
        assert (W, H, C, kind, srgb, matrix) == (tx.pixels.shape[1], tx.pixels.shape[0], tx.pixels.shape[2],
                                                 tx.kind, 0 if not tx.is_srgb else (1 if kind == U8 else 2), -1)
        # associate: 0 none, 1 8-bit premultiplied when packed, 2 float / 16-bit per texel, 3 PREMUL floats
        expect = 0 if not tx.associates_alpha else (1 if kind == U8 else (3 if tx.alpha_mode == "PREMUL" else 2))
        assert assoc == expect, (i, assoc, expect)
        store = U16 if kind == HALF else kind
        assert off == used[store]                                  # textures follow each other per array
        used[store] += tx.pixels.size
        flat = arrays[kind][off:off + tx.pixels.size]
        np.testing.assert_array_equal(flat, _cycles_stored(tx), err_msg=f"texture {i}")
    assert pack.u8.size == used[U8] and pack.u16.size == used[U16] and pack.f32.size == used[F32]
    assert pack.nbytes == sum(t.nbytes for t in texs)
    assert pack.half is HALF_TABLE and pack.srgb is SRGB_TABLE
    empty = pack_textures([])
    assert empty.header.shape == (1, N_HEADER) and empty.u8.size == empty.u16.size == empty.f32.size == 1
    assert len(pack.arrays()) == 6


def test_pack_alpha_none_drops_alpha():
    """alpha_mode NONE (Cycles' IMAGE_ALPHA_IGNORE): the alpha channel is not stored and reads 1."""
    rng = np.random.default_rng(4)
    texs = [Texture(_pixels("U8", 3, 4, 4, rng), alpha_mode="NONE"),
            Texture(_pixels("F32", 2, 3, 4, rng), colorspace="Linear", alpha_mode="NONE")]
    pack = pack_textures(texs)
    assert list(pack.header[:, 3]) == [3, 3]
    assert pack.u8.size == 3 * 4 * 3 and pack.f32.size == 2 * 3 * 3
    np.testing.assert_array_equal(pack.u8, texs[0].pixels[:, :, :3].reshape(-1))
    np.testing.assert_array_equal(pack.f32, texs[1].pixels[:, :, :3].reshape(-1))


# ----------------------------------------------------------------------------
# Look-ups against the oracle
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("ext", EXTS)
@pytest.mark.parametrize("interp", INTERPS)
def test_lookup_linear_space(interp, ext, kind):
    """Linear and non-colour textures of 1 and 3 channels, odd sizes; HDR values for float kinds."""
    rng = np.random.default_rng(_seed(interp, ext, kind))
    texs = [Texture(_pixels(kind, 5, 7, 3, rng, hdr=True), colorspace="Linear"),
            Texture(_pixels(kind, 3, 4, 3, rng, hdr=True), colorspace="Non-Color"),
            Texture(_pixels(kind, 4, 1, 1, rng, hdr=True), colorspace="Raw")]
    for tid, tx in enumerate(texs):
        H, W = tx.pixels.shape[:2]
        xy = _coords(rng, 300, W, H)
        got = _lookup(texs, tid, xy, interp, ext)
        exp = oracle.sample(tx, xy, interp, ext)
        _close(got, exp, tx, err_msg=f"texture {tid}")


@pytest.mark.parametrize("kind", ("U8", "F32"))
@pytest.mark.parametrize("ext", EXTS)
@pytest.mark.parametrize("interp", INTERPS)
def test_lookup_rgba_straight(interp, ext, kind):
    """Straight-alpha RGBA and grey + alpha images (Blender's default alpha mode) read with associated
    alpha, as Cycles holds them: bytes premultiplied (c * a) / 255 in integers (load_byte_pixels),
    floats c * a in float32 (Blender's IMB_premultiply_alpha)."""
    rng = np.random.default_rng(_seed(interp, ext, kind, "rgba"))
    grey = _pixels(kind, 4, 3, 2, rng, hdr=True)
    texs = [Texture(_rgba(kind, 5, 7, rng, hdr=True), colorspace="Linear"), Texture(grey, colorspace="Linear")]
    for tid, tx in enumerate(texs):
        H, W = tx.pixels.shape[:2]
        xy = _coords(rng, 300, W, H)
        _close(_lookup(texs, tid, xy, interp, ext), oracle.sample(tx, xy, interp, ext), tx, err_msg=f"texture {tid}")
    # the colour really is associated: at texel centres, Closest gives c * a (not c)
    tx = texs[0]
    got = _lookup(texs, 0, _centres(7, 5), "Closest", "REPEAT")
    T = oracle.texels(tx).reshape(-1, 4)
    straight = ~np.isin(T[:, 3], (0.0, 1.0))
    assert np.all(got[straight, :3] <= T[straight, :3]) and np.all(got[straight, :3].sum(1) < T[straight, :3].sum(1))
    np.testing.assert_allclose(got[:, 3], T[:, 3], rtol=0, atol=1e-15)


@pytest.mark.parametrize("kind", ("U16", "HALF"))
@pytest.mark.parametrize("interp", ("Closest", "Linear"))
def test_lookup_rgba_straight_16bit_half(interp, kind):
    rng = np.random.default_rng(_seed(interp, kind, "rgba16"))
    tx = Texture(_rgba(kind, 5, 7, rng, hdr=True), colorspace="Linear")
    xy = _coords(rng, 300, 7, 5)
    _close(_lookup([tx], 0, xy, interp, "REPEAT"), oracle.sample(tx, xy, interp, "REPEAT"), tx)


@pytest.mark.parametrize("ext", EXTS)
@pytest.mark.parametrize("interp", INTERPS)
def test_lookup_srgb_bytes(interp, ext):
    """8-bit sRGB: Cycles interpolates the sRGB-encoded (and associated) bytes and converts the
    result (NODE_IMAGE_COMPRESS_AS_SRGB); alpha is never converted."""
    rng = np.random.default_rng(_seed(interp, ext, "srgb"))
    texs = [Texture(_rgba("U8", 6, 5, rng)), Texture(_pixels("U8", 3, 3, 3, rng)),
            Texture(_pixels("U8", 2, 4, 1, rng), colorspace="sRGB EOTF")]
    for tid, tx in enumerate(texs):
        H, W = tx.pixels.shape[:2]
        xy = _coords(rng, 300, W, H)
        got = _lookup(texs, tid, xy, interp, ext)
        _close(got, oracle.sample(tx, xy, interp, ext, srgb="cycles"), tx)
        # and it differs from converting texels first (so the order is really tested)
        if interp != "Closest" and tid == 0:
            before = oracle.sample(tx, xy, interp, ext, srgb="before")
            assert np.max(np.abs(before - got)) > 1e-4


@pytest.mark.parametrize("kind", ("U16", "HALF", "F32"))
def test_lookup_srgb_other_kinds_closest(kind):
    """With Closest the order of conversion and interpolation does not matter."""
    rng = np.random.default_rng(11)
    tx = Texture(_pixels(kind, 5, 6, 3, rng), colorspace="sRGB")
    xy = _coords(rng, 300, 6, 5)
    _close(_lookup([tx], 0, xy, "Closest", "MIRROR"), oracle.sample(tx, xy, "Closest", "MIRROR", srgb="cycles"), tx)


@pytest.mark.parametrize("kind", ("U16", "HALF", "F32"))
@pytest.mark.parametrize("interp", ("Linear", "Cubic"))
def test_lookup_srgb_other_kinds_per_texel(interp, kind):
    """Blender passes 16-bit / half / float images to Cycles as float buffers already converted to
    scene linear (intern/cycles/blender/image.cpp, BlenderImageLoader::load_metadata: 'Float images
    are already converted on the Blender side', colorspace raw): Cycles interpolates linear values.
    RGB images, and RGBA ones whose alpha does not touch the colour (NONE, CHANNEL_PACKED)."""
    rng = np.random.default_rng(5)
    texs = [Texture(_pixels(kind, 5, 6, 3, rng), colorspace="sRGB"),
            Texture(_rgba(kind, 4, 5, rng), colorspace="sRGB", alpha_mode="NONE"),
            Texture(_rgba(kind, 3, 4, rng), colorspace="sRGB", alpha_mode="CHANNEL_PACKED")]
    for tid, tx in enumerate(texs):
        H, W = tx.pixels.shape[:2]
        xy = _coords(rng, 200, W, H)
        got = _lookup(texs, tid, xy, interp, "REPEAT")
        _close(got, oracle.sample(tx, xy, interp, "REPEAT", srgb="cycles"), tx, err_msg=f"texture {tid}")
        if tid == 0:                       # the order is really tested
            after = oracle.sample(tx, xy, interp, "REPEAT", srgb="after")
            assert np.max(np.abs(after - got)) > 1e-4


@pytest.mark.parametrize("mode", ("STRAIGHT", "PREMUL"))
@pytest.mark.parametrize("kind", ("U16", "HALF", "F32"))
def test_lookup_srgb_other_kinds_rgba(kind, mode):
    rng = np.random.default_rng(_seed(kind, mode, "srgb-rgba"))
    tx = Texture(_rgba(kind, 5, 6, rng, premul=mode == "PREMUL"), colorspace="sRGB", alpha_mode=mode)
    xy = _coords(rng, 200, 6, 5)
    _close(_lookup([tx], 0, xy, "Linear", "REPEAT"), oracle.sample(tx, xy, "Linear", "REPEAT"), tx)


# ----------------------------------------------------------------------------
# Alpha modes and the un-associate flag
# ----------------------------------------------------------------------------
_MODE_CASES = [(m, k) for m in MODES for k in KINDS]


@pytest.mark.parametrize("mode,kind", _MODE_CASES)
def test_alpha_modes(mode, kind):
    """Blender's Image.alpha_mode (Cycles' ImageAlphaType): STRAIGHT images are associated on load,
    PREMUL ones are already, CHANNEL_PACKED keep colour and alpha apart (image_associate_alpha is
    false), NONE reads alpha 1 with the colours kept (IMAGE_ALPHA_IGNORE).  Linear colour space,
    every interpolation, Repeat and Clip."""
    rng = np.random.default_rng(_seed(mode, kind, "modes"))
    tx = Texture(_rgba(kind, 4, 5, rng, hdr=True, premul=mode == "PREMUL"), colorspace="Linear", alpha_mode=mode)
    for interp in INTERPS:
        for ext in ("REPEAT", "CLIP"):
            xy = _coords(rng, 150, 5, 4)
            _close(_lookup([tx], 0, xy, interp, ext), oracle.sample(tx, xy, interp, ext), tx,
                   err_msg=f"{interp} {ext}")
    # at texel centres (Closest): what each mode stores
    got = _lookup([tx], 0, _centres(5, 4), "Closest", "EXTEND")
    T = oracle.texels(tx).reshape(-1, 4)
    if mode == "NONE":
        np.testing.assert_array_equal(got[:, 3], 1.0)
    else:
        np.testing.assert_allclose(got[:, 3], T[:, 3], rtol=0, atol=1e-15)
    if mode in ("PREMUL", "CHANNEL_PACKED", "NONE"):
        np.testing.assert_allclose(got[:, :3], T[:, :3], rtol=0, atol=1e-15)


@pytest.mark.parametrize("mode", MODES)
def test_alpha_modes_srgb_bytes(mode):
    """8-bit sRGB RGBA in every alpha mode: associated (STRAIGHT: premultiplied in the sRGB encoding,
    as load_byte_pixels does), interpolated encoded, converted after."""
    rng = np.random.default_rng(_seed(mode, "modes-srgb"))
    tx = Texture(_rgba("U8", 5, 6, rng, premul=mode == "PREMUL"), alpha_mode=mode)
    for interp in INTERPS:
        xy = _coords(rng, 150, 6, 5)
        _close(_lookup([tx], 0, xy, interp, "MIRROR"), oracle.sample(tx, xy, interp, "MIRROR"), tx, err_msg=interp)


_UNASSOC_CASES = [("U8", "sRGB", "STRAIGHT"), ("U8", "Linear", "STRAIGHT"), ("F32", "Linear", "STRAIGHT"),
                  ("U8", "sRGB", "PREMUL"), ("U8", "Linear", "PREMUL"), ("F32", "Linear", "PREMUL"),
                  ("U16", "Linear", "PREMUL"), ("HALF", "Linear", "PREMUL")]


@pytest.mark.parametrize("kind,space,mode", _UNASSOC_CASES)
def test_lookup_unassociate(kind, space, mode):
    """The un-associate flag (NODE_IMAGE_ALPHA_UNASSOCIATE, svm_image_texture): the interpolated
    colour divided by the interpolated alpha where alpha is neither 0 nor 1, before the sRGB
    conversion; alpha unchanged."""
    rng = np.random.default_rng(_seed(kind, space, mode, "unassoc"))
    tx = Texture(_rgba(kind, 5, 4, rng, hdr=kind != "U8", premul=mode == "PREMUL"), colorspace=space,
                 alpha_mode=mode)
    for interp in INTERPS:
        for ext in ("REPEAT", "CLIP"):
            xy = _coords(rng, 60, 4, 5)
            got = _lookup_unassociated([tx], 0, xy, interp, ext)
            _close(got, oracle.sample(tx, xy, interp, ext, unassociate=True), tx, err_msg=f"{interp} {ext}")
            plain = _lookup([tx], 0, xy, interp, ext)
            np.testing.assert_array_equal(got[:, 3], plain[:, 3])
            assert np.max(np.abs(got[:, :3] - plain[:, :3])) > 1e-3          # the flag does something
    # a straight byte image comes back to its colours (within one byte step of the premultiplication)
    if kind == "U8" and mode == "STRAIGHT" and space == "Linear":
        got = _lookup_unassociated([tx], 0, _centres(4, 5), "Closest", "REPEAT")
        T = oracle.texels(tx).reshape(-1, 4)
        ok = T[:, 3] > 0.0
        assert np.all(np.abs(got[ok, :3] - T[ok, :3]) <= 1.0 / (255.0 * T[ok, 3:4]) + 1e-12)


@pytest.mark.parametrize("kind", ("U8", "F32"))
def test_lookup_data_rgba_not_associated(kind):
    rng = np.random.default_rng(_seed(kind, "data-rgba"))
    tx = Texture(_rgba(kind, 4, 5, rng), colorspace="Non-Color")
    xy = _coords(rng, 150, 5, 4)
    _close(_lookup([tx], 0, xy, "Linear", "REPEAT"), oracle.sample(tx, xy, "Linear", "REPEAT"), tx)


# ----------------------------------------------------------------------------
# Borders, orientation, tiny images
# ----------------------------------------------------------------------------
def _band(rng, W, H):
    """Coordinates within 1.5 texels outside the image, and just inside its edges."""
    n = 200
    t = rng.uniform(0.0, 1.0, n)
    dx = rng.uniform(0.02, 1.45, n) / W
    dy = rng.uniform(0.02, 1.45, n) / H
    side = rng.integers(0, 4, n)
    x = np.where(side == 0, -dx, np.where(side == 1, 1 + dx, t))
    y = np.where(side == 2, -dy, np.where(side == 3, 1 + dy, t))
    return np.stack([x, y], 1)


def _outside(xy):
    return (xy[:, 0] < 0) | (xy[:, 0] > 1) | (xy[:, 1] < 0) | (xy[:, 1] > 1)


@pytest.mark.parametrize("kind", ("U8", "F32"))
@pytest.mark.parametrize("interp", ("Linear", "Cubic", "Smart"))
def test_clip_border_band(interp, kind):
    """Cycles >= 3.2 (kernel/device/cpu/image.h, ImageInterpolator::interp_linear / interp_cubic,
    EXTENSION_CLIP) samples across the border with out-of-image texels read as 0 (read_clip) and
    returns 0 only when no tap is inside: within half a texel (Linear) / 1.5 texels (Cubic) outside
    [0, 1] the result fades to 0."""
    rng = np.random.default_rng(9)
    tx = Texture(_rgba(kind, 4, 5, rng), colorspace="Linear" if kind == "F32" else "sRGB")
    xy = _band(rng, 5, 4)
    got = _lookup([tx], 0, xy, interp, "CLIP")
    _close(got, oracle.sample(tx, xy, interp, "CLIP"), tx)
    assert np.count_nonzero(got[_outside(xy), 3]) > 0.2 * np.count_nonzero(_outside(xy))   # a fade, not 0


def test_closest_clip_border_agrees_with_cycles():
    """Closest + Clip: outside the image is 0 in Cycles too (no band)."""
    rng = np.random.default_rng(10)
    tx = Texture(_rgba("U8", 4, 5, rng))
    xy = _band(rng, 5, 4)
    got = _lookup([tx], 0, xy, "Closest", "CLIP")
    _close(got, oracle.sample(tx, xy, "Closest", "CLIP"), tx)
    np.testing.assert_array_equal(got[_outside(xy)], 0.0)


def test_lookup_texel_centres_and_orientation():
    """Row 0 is the bottom (v = 0); at texel centres Linear gives the texel itself; a constant
    image is reproduced by every interpolation and extension (the B-spline weights sum to 1).
    (alpha_mode PREMUL: the texels are stored as given.)"""
    px = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
    tx = Texture(px, colorspace="Linear", alpha_mode="PREMUL")
    centres = _centres(3, 2)
    got = _lookup([tx], 0, centres, "Linear", "EXTEND")
    np.testing.assert_allclose(got, px.reshape(-1, 4), rtol=0, atol=1e-12)
    got = _lookup([tx], 0, centres, "Closest", "REPEAT")
    np.testing.assert_array_equal(got, px.reshape(-1, 4))
    const = Texture(np.full((3, 4, 4), 0.375, np.float32), colorspace="Linear", alpha_mode="PREMUL")
    xy = np.random.default_rng(1).uniform(-2, 3, (100, 2))
    for interp in INTERPS:
        for ext in ("REPEAT", "EXTEND", "MIRROR"):
            np.testing.assert_allclose(_lookup([const], 0, xy, interp, ext), 0.375, rtol=0, atol=1e-12)


@pytest.mark.parametrize("ext", EXTS)
def test_lookup_one_texel_images(ext):
    """1 x 1 and 1 x N images (every tap wraps onto the same texels)."""
    rng = np.random.default_rng(12)
    texs = [Texture(_pixels("U8", 1, 1, 4, rng)), Texture(_pixels("F32", 1, 3, 3, rng), colorspace="Linear")]
    for tid, tx in enumerate(texs):
        xy = _coords(rng, 100, tx.pixels.shape[1], 1)
        for interp in INTERPS:
            _close(_lookup(texs, tid, xy, interp, ext), oracle.sample(tx, xy, interp, ext), tx)


# ----------------------------------------------------------------------------
# Working spaces (Blender 5): images converted per texel into the scene's working space
# ----------------------------------------------------------------------------
def _lookup_in(textures, working: str, tid: int, xy: np.ndarray, interp: str, ext: str) -> np.ndarray:
    pack = pack_textures(textures, working)
    out = np.zeros((xy.shape[0], 4))
    tex_lookup_batch(pack.header, pack.u8, pack.u16, pack.f32, pack.half, tid, np.ascontiguousarray(xy, np.float64),
                     oracle.INTERP[interp], oracle.EXT[ext], False, out)
    return out


def test_pack_working_space_matrix():
    """A texture whose primaries differ from the working space's carries its float32 matrix after the
    texels (offset in H_MATRIX); one already in it (or data, or "Linear": already converted) none."""
    rng = np.random.default_rng(21)
    texs = [Texture(_pixels("U8", 2, 3, 3, rng)),                                        # sRGB
            Texture(_pixels("F32", 2, 2, 3, rng), colorspace="Linear Rec.709"),
            Texture(_pixels("U8", 2, 2, 1, rng), colorspace="Non-Color"),
            Texture(_pixels("F32", 1, 2, 3, rng), colorspace="Linear"),
            Texture(_pixels("HALF", 2, 2, 3, rng), colorspace="ACEScg"),
            Texture(_pixels("U16", 2, 2, 4, rng), colorspace="Display P3")]
    for working in ("REC709", "ACESCG", "REC2020"):
        pack = pack_textures(texs, working)
        for i, tx in enumerate(texs):
            M = colorspaces.conversion(colorspaces.SPACES[tx.colorspace][1], working)
            m = pack.header[i, H_MATRIX]
            if M is None:
                assert m == -1, (working, i)
            else:
                np.testing.assert_array_equal(pack.f32[m:m + 9], M.astype(np.float32).reshape(-1))
            # 8-bit sRGB: decoded after interpolation unless converted (then per texel, as Cycles' half floats)
            if tx.is_srgb:
                assert pack.header[i, H_SRGB] == (1 if tx.kind == U8 and M is None else 2)
        assert pack.nbytes == sum(t.nbytes for t in texs)          # matrices are not texels
    assert list(pack_textures(texs, "ACESCG").header[:, H_MATRIX] >= 0) == [True, True, False, False, False, True]


@pytest.mark.parametrize("working", ["ACESCG", "REC2020"])
@pytest.mark.parametrize("interp", ["Closest", "Linear", "Cubic"])
@pytest.mark.parametrize("kind", KINDS)
def test_lookup_converted_to_working_space(kind, interp, working):
    """sRGB, Linear Rec.709, Display P3 and ACEScg images in a working space of other primaries:
    each texel decoded, multiplied by the matrix (float32 coefficients: 2e-7 relative), then
    interpolated -- 8-bit images too -- and RGBA ones associated after the conversion (straight and
    premultiplied), as the oracle converts them."""
    rng = np.random.default_rng(_seed("working", kind, interp, working))
    texs = [Texture(_pixels(kind, 5, 7, 3, rng), colorspace="sRGB"),
            Texture(_pixels(kind, 4, 3, 3, rng, hdr=True), colorspace="Linear Rec.709"),
            Texture(_rgba(kind, 3, 5, rng), colorspace="sRGB", alpha_mode="STRAIGHT"),
            Texture(_rgba(kind, 4, 4, rng, premul=True), colorspace="Linear Rec.709", alpha_mode="PREMUL"),
            Texture(_pixels(kind, 3, 3, 3, rng), colorspace="Display P3"),
            Texture(_pixels(kind, 2, 5, 1, rng), colorspace="ACEScg")]
    for tid, tx in enumerate(texs):
        H, W = tx.pixels.shape[:2]
        xy = _coords(rng, 120, W, H)
        M = colorspaces.conversion(colorspaces.SPACES[tx.colorspace][1], working)
        got = _lookup_in(texs, working, tid, xy, interp, "REPEAT")
        exp = oracle.sample(tx, xy, interp, "REPEAT", working=M)
        np.testing.assert_allclose(got, exp, rtol=1e-6, atol=1e-6, err_msg=f"{tx.colorspace} {tx.alpha_mode}")
        # and a coloured one differs from reading the image unconverted (greys stay grey: the spaces
        # share the D65 white)
        if tx.pixels.shape[2] > 1:
            assert np.abs(exp - oracle.sample(tx, xy, interp, "REPEAT")).max() > 1e-3


def test_converted_bytes_interpolate_linear_values():
    """An 8-bit sRGB image converted into ACEScg is interpolated in linear working-space values (as
    Cycles' half-float copy), not in its sRGB encoding: halfway between a black and a white texel
    reads 0.5 x M (1, 1, 1), where the Rec.709 path reads eotf(0.5) = 0.214."""
    tx = Texture(np.array([[[0, 0, 0], [255, 255, 255]]], np.uint8), colorspace="sRGB")
    xy = np.array([[0.5, 0.5]])
    aces = _lookup_in([tx], "ACESCG", 0, xy, "Linear", "EXTEND")[0]
    rec = _lookup_in([tx], "REC709", 0, xy, "Linear", "EXTEND")[0]
    row_sums = colorspaces.conversion("Linear Rec.709", "ACESCG").sum(axis=1)
    np.testing.assert_allclose(aces[:3], 0.5 * row_sums, rtol=1e-6)
    np.testing.assert_allclose(rec[:3], srgb_to_linear(0.5), rtol=1e-6)


# ----------------------------------------------------------------------------
# UDIM: the tile from the coordinate's integer part, each tile its own texture
# ----------------------------------------------------------------------------
def _udim_lookup(textures, tiles: dict, xy, interp, ext, alpha_linked=False, working="REC709") -> np.ndarray:
    pack = pack_textures(textures, working)
    prog = np.array([w for t, i in tiles.items() for w in (float(t), float(i))] or [0.0])
    xy = np.asarray(xy, np.float64)
    n = len(xy)
    st = np.zeros((7, n))                       # the interpreter's stack: vector 0..2, colour 3..5, alpha 6
    st[0], st[1] = xy[:, 0], xy[:, 1]
    tex_image_rows(pack.header, pack.u8, pack.u16, pack.f32, pack.half, 0, oracle.INTERP[interp], oracle.EXT[ext],
                   bool(alpha_linked), st, 0, 3, 6, n, prog, 0, len(tiles))
    return st[3:7].T.copy()


def _udim_set(rng):
    """Tiles 1001 (8-bit sRGB 4 x 3), 1002 (float RGBA 5 x 2), 1011 (half 3 x 3), 1013 (16-bit grey
    2 x 2): different sizes and kinds; 1012 missing."""
    texs = [Texture(_pixels("U8", 3, 4, 3, rng), colorspace="sRGB"),
            Texture(_rgba("F32", 2, 5, rng), colorspace="Linear"),
            Texture(_pixels("HALF", 3, 3, 3, rng, hdr=True), colorspace="Linear Rec.709"),
            Texture(_pixels("U16", 2, 2, 1, rng), colorspace="Non-Color")]
    return texs, {1001: 0, 1002: 1, 1011: 2, 1013: 3}


def _udim_coords(rng, n: int) -> np.ndarray:
    """Over tiles 1001-1014 and around them (negative, past tile column 9), on tile borders, and
    texel centres / edges of each tile."""
    edges = np.array([[1.0, 0.5], [0.999999, 0.5], [1.000001, 0.5], [0.5, 1.0], [2.0, 1.5], [-0.25, 0.5],
                      [0.5, -0.25], [-1.0, 0.5], [-1.5, -1.5], [9.9, 0.2], [10.2, 0.2], [3.5, 1.5], [2.5, 1.5],
                      [0.0, 0.0], [1.9999, 1.9999], [np.nan, 0.5], [0.5, np.inf]])
    return np.concatenate([rng.uniform(-1.3, 3.3, (n, 2)), rng.uniform(0.0, 2.0, (n, 2)), edges])


@pytest.mark.parametrize("ext", EXTS)
@pytest.mark.parametrize("interp", ["Closest", "Linear", "Cubic"])
def test_udim_lookup(interp, ext):
    """Each coordinate reads its own tile (1001 + tx + 10 ty, truncated toward zero) at its
    in-tile coordinate with the node's extension (filters never reach the neighbour tile), outside
    every listed tile Cycles' magenta; mixed sizes and storage kinds; Alpha linked or not."""
    rng = np.random.default_rng(_seed("udim", interp, ext))
    texs, tiles = _udim_set(rng)
    xy = _udim_coords(rng, 400)
    # (Alpha linked under Clip: Cycles also un-associates 3-channel images, whose alpha fades at the
    # border, and STPM's single-image look-up does not -- a known difference, not UDIM's: left out)
    for linked in ((False, True) if ext != "CLIP" else (False,)):
        got = _udim_lookup(texs, tiles, xy, interp, ext, linked)
        exp = oracle.sample_udim({t: texs[i] for t, i in tiles.items()}, xy, interp, ext, linked)
        np.testing.assert_allclose(got, exp, rtol=ASSOC_RTOL, atol=SRGB_ATOL)
    # the rule itself, on a few points: tile 1012 is missing, u in (-1, 0) reads tile column 0
    pts = np.array([[1.5, 1.5], [0.5, 0.5], [-0.5, 0.5], [10.5, 0.5], [0.5, -1.5]])
    out = _udim_lookup(texs, tiles, pts, interp, ext)
    np.testing.assert_array_equal(out[0], oracle.MISSING)
    np.testing.assert_array_equal(out[3], oracle.MISSING)
    np.testing.assert_array_equal(out[4], oracle.MISSING)
    np.testing.assert_allclose(out[1], oracle.sample(texs[0], pts[1:2], interp, ext)[0], atol=SRGB_ATOL)
    np.testing.assert_allclose(out[2], oracle.sample(texs[0], pts[2:3], interp, ext)[0], atol=SRGB_ATOL)


def test_udim_lookup_in_a_working_space():
    """Each tile is converted into the working space by its own matrix (tiles of one image share
    its colour space; here they differ to show each tile's matrix is its own)."""
    rng = np.random.default_rng(33)
    texs, tiles = _udim_set(rng)
    xy = _udim_coords(rng, 300)
    M = {t: colorspaces.conversion(colorspaces.SPACES[texs[i].colorspace][1], "ACESCG") for t, i in tiles.items()}
    got = _udim_lookup(texs, tiles, xy, "Linear", "REPEAT", working="ACESCG")
    exp = oracle.sample_udim({t: texs[i] for t, i in tiles.items()}, xy, "Linear", "REPEAT", working=M)
    np.testing.assert_allclose(got, exp, rtol=1e-6, atol=1e-6)


def test_udim_tile_edges_do_not_blend_neighbours():
    """Linear interpolation at u = 1 - 1/(4W) (inside tile 1001, next to tile 1002) blends with
    tile 1001's own first column under Repeat, and reads only its last column under Extend: never
    tile 1002's texels (Cycles looks each tile up alone)."""
    a = Texture(np.array([[[10, 10, 10], [200, 200, 200]]], np.uint8), colorspace="Non-Color")
    b = Texture(np.array([[[255, 0, 0], [255, 0, 0]]], np.uint8), colorspace="Non-Color")
    xy = np.array([[1.0 - 1.0 / 8.0, 0.5]])
    rep = _udim_lookup([a, b], {1001: 0, 1002: 1}, xy, "Linear", "REPEAT")[0]
    ext = _udim_lookup([a, b], {1001: 0, 1002: 1}, xy, "Linear", "EXTEND")[0]
    np.testing.assert_allclose(rep[:3], (0.75 * 200 + 0.25 * 10) / 255.0)
    np.testing.assert_allclose(ext[:3], 200 / 255.0)
