"""Numpy image-texture sampling: the oracle for :mod:`stpm_core.kernels.texture`.

Written from Cycles' CPU image kernel (``intern/cycles/kernel/device/cpu/image.h``,
``ImageInterpolator``; Blender >= 3.2 behaviour at Clip borders), the SVM image node
(``kernel/svm/image.h``, ``svm_image_texture``), Cycles' image loading (``scene/image.cpp``,
``blender/image.cpp``) and what Blender does to an image before Cycles sees it
(``imbuf``: ``imb_handle_alpha``, ``colormanage_imbuf_make_linear``) -- not from the project's
kernel:

* pixel space: ``x = u W``, ``y = v H`` (row 0 is the bottom row of the image);
* Closest: texel ``(floor x, floor y)``;
* Linear: the four texels around ``(x - 1/2, y - 1/2)``, weights ``(1 - t)`` and ``t``;
* Cubic (and Smart, on the CPU): the 4 x 4 texels around it, uniform cubic B-spline weights
  (``SET_CUBIC_SPLINE_WEIGHTS``);
* extensions: Repeat (periodic), Extend (clamp the index), Mirror
  (``m = |i + (i < 0)| mod 2W``, reflected when ``m >= W``), Clip (a texel index outside the image
  reads transparent black, ``read_clip``: Linear / Cubic fade to 0 across the border; for Closest
  a coordinate outside reads black).

Texels decode as Cycles reads them (bytes / 255, ushort / 65535, half, float); a one-channel image
is grey with alpha 1.

Colour space.  Cycles keeps byte sRGB images in their sRGB encoding
(``ImageMetaData::is_compressible_as_srgb``) and applies ``color_srgb_to_linear`` to the
*interpolated* colour (``NODE_IMAGE_COMPRESS_AS_SRGB``; alpha untouched).  Images that reach Cycles
from Blender as float buffers (16-bit, half and float files) were converted to scene linear by
Blender when loaded (``BlenderImageLoader``: "Float images are already converted on the Blender
side"), i.e. per texel, before interpolation.  :func:`sample` takes the order as a parameter
(``srgb="after" | "before" | "cycles"``, the last picking by storage kind).

Alpha (``Texture.alpha_mode``, Blender's ``Image.alpha_mode``: STRAIGHT, PREMUL, CHANNEL_PACKED,
NONE).  Cycles holds RGBA images with *associated* alpha:

* ``image_associate_alpha`` (scene/image.cpp): associate unless the colour space is data
  (Non-Color; :data:`DATA_SPACES`), the alpha is ignored (NONE) or channel packed;
* byte images (Blender keeps bytes straight): ``load_byte_pixels`` premultiplies in the stored
  (sRGB) encoding, ``c' = (c a) / 255`` in integers (truncating);
* float buffers (16-bit, half, float): ``imb_handle_alpha`` premultiplies a STRAIGHT image
  (``IMB_premultiply_alpha``, float32) and leaves PREMUL / data / channel-packed alone; the
  conversion to linear is then done on the un-associated colour (``predivide``: divide by alpha,
  convert, multiply; not for channel-packed images, nor where alpha is 0 or 1), so an sRGB texel
  holds ``a * eotf(c)``;
* NONE: alpha reads 1, colours are kept (``IMAGE_ALPHA_IGNORE``);
* PREMUL bytes are taken as stored.  (Blender un-premultiplies premultiplied bytes on load and
  Cycles premultiplies them again, a round trip within one byte step that also caps the colour at
  alpha; not modelled.)

Working space (Blender 5).  Cycles converts an image whose colour space is neither raw nor
sRGB-in-Rec.709 into the scene's working space when it loads it, byte images included
(``ImageMetaData::detect_colorspace`` makes them half floats; ``ColorSpaceManager::to_scene_linear``
with OpenColorIO): per texel, on the un-associated colour, the colour space's transfer function
then the primaries' 3x3 matrix, then the alpha associated again (:func:`cycles_texels` with
``working``: the matrix, from ``stpm_core.colorspaces`` -- checked against OpenColorIO there).  A
converted image is therefore interpolated in linear working-space values, whatever its storage.
(Cycles' half storage rounds to 2^-11 relative; not modelled: the kernel keeps float precision.)

UDIM (:func:`sample_udim`; ``svm_node_tex_image``): ``tx = (int) x``, ``ty = (int) y`` (C truncation),
tile ``1001 + 10 ty + tx`` when ``tx, ty >= 0`` and ``tx < 10``; found: the tile's image at
``(x - tx, y - ty)``; not found: ``TEX_IMAGE_MISSING`` (1, 0, 1, 1) (no sRGB decoding, no
un-association: ``svm_image_texture`` returns it before both).

``svm_image_texture`` divides the interpolated colour by its alpha (alpha not 0 or 1) when the
instruction has ``NODE_IMAGE_ALPHA_UNASSOCIATE``, before the sRGB conversion (no clamp: Cycles
>= 3.0).  ``ImageTextureNode::compile`` sets that flag when the Alpha output is linked (after
``ShaderGraph::clean`` removed the nodes that do not reach the output) and the image associates
(:func:`unassociate_flag`).  :func:`sample`'s ``unassociate`` is the instruction's flag itself.
"""
from __future__ import annotations

import numpy as np

__all__ = ["texels", "cycles_texels", "srgb_to_linear", "wrap_index", "bspline_weights", "sample", "INTERP", "EXT",
           "DATA_SPACES", "ALPHA_MODES", "is_data", "has_alpha", "associates", "unassociate_flag", "sample_udim",
           "MISSING"]

INTERP = {"Closest": 0, "Linear": 1, "Cubic": 2, "Smart": 2}
EXT = {"REPEAT": 0, "EXTEND": 1, "CLIP": 2, "MIRROR": 3}
ALPHA_MODES = ("STRAIGHT", "PREMUL", "CHANNEL_PACKED", "NONE")
# Blender's data colour spaces (OCIO ``isdata: true``): Non-Color and its aliases
DATA_SPACES = ("Non-Color", "Raw", "Generic Data", "Non-Colour Data", "Utility - Raw")

_U8, _U16, _HALF, _F32 = 0, 1, 2, 3
MISSING = np.array([1.0, 0.0, 1.0, 1.0])          # TEX_IMAGE_MISSING_R/G/B/A


def srgb_to_linear(c):
    """Cycles' ``color_srgb_to_linear``: c < 0.04045 -> max(c, 0) / 12.92, else ((c + 0.055) / 1.055)^2.4."""
    c = np.asarray(c, np.float64)
    lo = np.where(c < 0.0, 0.0, c / 12.92)
    hi = ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4
    return np.where(c < 0.04045, lo, hi)


def _kind(tex) -> int:
    px = tex.pixels
    if px.dtype == np.uint8:
        return _U8
    if px.dtype == np.uint16:
        return _HALF if getattr(tex, "half", False) else _U16
    return _F32


def _alpha_mode(tex) -> str:
    return getattr(tex, "alpha_mode", "STRAIGHT")


def has_alpha(tex) -> bool:
    return np.asarray(tex.pixels).shape[2] in (2, 4)


def is_data(tex) -> bool:
    """ColorSpaceManager::colorspace_is_data for Blender's colour-space names."""
    return tex.colorspace in DATA_SPACES


def associates(tex) -> bool:
    """Cycles' ``image_associate_alpha``: not for data colour spaces, NONE or CHANNEL_PACKED."""
    return not (is_data(tex) or _alpha_mode(tex) in ("NONE", "CHANNEL_PACKED"))


def unassociate_flag(tex, alpha_linked: bool) -> bool:
    """``NODE_IMAGE_ALPHA_UNASSOCIATE`` of ``ImageTextureNode::compile``: the Alpha output is linked
    and the image is neither data, nor channel packed, nor without alpha (IGNORE)."""
    return bool(alpha_linked) and associates(tex)


def texels(tex) -> np.ndarray:
    """(H, W, 4) float64 stored values as Cycles reads them (no alpha or colour-space handling)."""
    px = np.asarray(tex.pixels)
    k = _kind(tex)
    if k == _U8:
        v = px.astype(np.float64) / 255.0
    elif k == _U16:
        v = px.astype(np.float64) / 65535.0
    elif k == _HALF:
        v = px.view(np.float16).astype(np.float64)
    else:
        v = px.astype(np.float64)
    H, W, C = v.shape
    out = np.ones((H, W, 4))
    if C == 1:
        out[:, :, :3] = v[:, :, :1]
    elif C == 2:                             # grey + alpha
        out[:, :, :3] = v[:, :, :1]
        out[:, :, 3] = v[:, :, 1]
    else:
        out[:, :, :3] = v[:, :, :3]
        if C == 4:
            out[:, :, 3] = v[:, :, 3]
    return out


def _converted_texels(tex, M) -> np.ndarray:
    """(H, W, 4) texels of an image Cycles converts into the working space (matrix M (3, 3)): the
    straight colour (PREMUL ones divided by alpha where it is not 0 or 1), sRGB-decoded if sRGB,
    times M, then associated with alpha (unless data, NONE or channel packed)."""
    T = texels(tex)
    mode = _alpha_mode(tex)
    alpha = has_alpha(tex)
    if alpha and mode == "NONE":
        T[:, :, 3] = 1.0
    a = T[:, :, 3:4]
    c = T[:, :, :3]
    if alpha and mode == "PREMUL":
        div = (a != 0.0) & (a != 1.0)
        c = np.where(div, c / np.where(div, a, 1.0), c)
    if tex.is_srgb:
        c = srgb_to_linear(c)
    c = c @ np.asarray(M, np.float64).T
    if alpha and associates(tex):
        c = c * a
    T[:, :, :3] = c
    return T


def cycles_texels(tex, srgb_before: bool | None = None, working=None) -> np.ndarray:
    """(H, W, 4) texels as Cycles' image kernel holds them: alpha handled per the module docstring
    (associated alpha), float buffers of sRGB images converted to linear per texel.  srgb_before:
    convert an sRGB image per texel here (default: for every kind but uint8).  working: the 3x3
    matrix into the working space, or None (see "Working space" above)."""
    if working is not None:
        return _converted_texels(tex, working)
    T = texels(tex)
    k = _kind(tex)
    mode = _alpha_mode(tex)
    alpha = has_alpha(tex)
    if alpha and mode == "NONE":
        T[:, :, 3] = 1.0
    straight = alpha and associates(tex) and mode == "STRAIGHT"
    if k == _U8:
        if straight:                         # load_byte_pixels: (c * a) / 255 in integers
            px = np.asarray(tex.pixels).astype(np.int64)
            if px.shape[2] == 2:
                px = np.concatenate([px[:, :, :1]] * 3 + [px[:, :, 1:]], axis=2)
            T[:, :, :3] = ((px[:, :, :3] * px[:, :, 3:4]) // 255) / 255.0
    elif straight:                           # IMB_premultiply_alpha on Blender's float32 buffer
        T32 = T.astype(np.float32)
        T[:, :, :3] = (T32[:, :, :3] * T32[:, :, 3:4]).astype(np.float64)
    if srgb_before is None:
        srgb_before = k != _U8
    if tex.is_srgb and srgb_before:
        if k == _U8:                         # (the order Cycles does *not* use for bytes)
            T[:, :, :3] = srgb_to_linear(T[:, :, :3])
        else:                                # colormanage_imbuf_make_linear, predivide
            a = T[:, :, 3:4]
            div = (alpha and mode != "CHANNEL_PACKED") & (a != 0.0) & (a != 1.0)
            c = np.where(div, T[:, :, :3] / np.where(div, a, 1.0), T[:, :, :3])
            lin = srgb_to_linear(c)
            T[:, :, :3] = np.where(div, lin * a, lin)
    return T


def wrap_index(i, n: int, ext: int) -> np.ndarray:
    """Texel index i (int array) of an axis of n texels; -1 marks a Clip texel outside the image."""
    i = np.asarray(i, np.int64)
    if ext == 0:                                     # REPEAT (wrap_periodic)
        return np.mod(i, n)
    if ext == 1:                                     # EXTEND (wrap_clamp)
        return np.clip(i, 0, n - 1)
    if ext == 3:                                     # MIRROR (wrap_mirror)
        m = np.abs(i + (i < 0)) % (2 * n)
        return np.where(m >= n, 2 * n - m - 1, m)
    return np.where((i >= 0) & (i < n), i, -1)       # CLIP (read_clip)


def bspline_weights(t) -> np.ndarray:
    """(4, ...) uniform cubic B-spline weights of the texels at offsets -1, 0, 1, 2."""
    t = np.asarray(t, np.float64)
    return np.stack([(((-1.0 / 6.0) * t + 0.5) * t - 0.5) * t + 1.0 / 6.0,
                     ((0.5 * t - 1.0) * t) * t + 2.0 / 3.0,
                     ((-0.5 * t + 0.5) * t + 0.5) * t + 1.0 / 6.0,
                     (1.0 / 6.0) * t * t * t])


def _fetch(T, ix, iy):
    """T (H, W, 4) at wrapped indices (-1 -> 0)."""
    ok = (ix >= 0) & (iy >= 0)
    v = T[np.where(ok, iy, 0), np.where(ok, ix, 0)]
    return np.where(ok[..., None], v, 0.0)


def sample(tex, xy, interp="Linear", ext="REPEAT", srgb="cycles", unassociate: bool = False,
           working=None) -> np.ndarray:
    """(n, 4) RGBA of texture ``tex`` (a :class:`stpm_core.textures.Texture`) at (u, v) rows of xy.

    interp / ext: names or codes (``INTERP`` / ``EXT``).  srgb: where the sRGB EOTF goes for an
    sRGB texture: "after" interpolation (Cycles' byte images), "before" (per texel: Blender's
    float buffers), "cycles" (after for uint8 storage, before for every other kind).
    unassociate: the instruction's NODE_IMAGE_ALPHA_UNASSOCIATE flag (see :func:`unassociate_flag`
    for when Cycles sets it): the interpolated colour divided by its alpha (alpha not 0 or 1).
    working: the 3x3 matrix into the working space (the image is converted per texel), or None.
    """
    interp = INTERP.get(interp, interp)
    ext = EXT.get(ext, ext)
    xy = np.atleast_2d(np.asarray(xy, np.float64))
    order = srgb if srgb != "cycles" else ("after" if _kind(tex) == _U8 else "before")
    if working is not None:
        order = "before"
    T = cycles_texels(tex, srgb_before=order == "before", working=working)
    H, W = T.shape[:2]
    x = xy[:, 0] * W
    y = xy[:, 1] * H
    if interp == 0:
        ix = wrap_index(np.floor(x).astype(np.int64), W, ext)
        iy = wrap_index(np.floor(y).astype(np.int64), H, ext)
        out = _fetch(T, ix, iy)
    elif interp == 1:
        fx, fy = np.floor(x - 0.5), np.floor(y - 0.5)
        tx, ty = (x - 0.5) - fx, (y - 0.5) - fy
        ix0, iy0 = fx.astype(np.int64), fy.astype(np.int64)
        out = np.zeros((xy.shape[0], 4))
        for j, wy in ((0, 1.0 - ty), (1, ty)):
            iy = wrap_index(iy0 + j, H, ext)
            for i, wx in ((0, 1.0 - tx), (1, tx)):
                out += (wy * wx)[:, None] * _fetch(T, wrap_index(ix0 + i, W, ext), iy)
    else:
        fx, fy = np.floor(x - 0.5), np.floor(y - 0.5)
        u = bspline_weights((x - 0.5) - fx)
        v = bspline_weights((y - 0.5) - fy)
        ix0, iy0 = fx.astype(np.int64), fy.astype(np.int64)
        out = np.zeros((xy.shape[0], 4))
        for j in range(4):
            iy = wrap_index(iy0 + j - 1, H, ext)
            for i in range(4):
                out += (v[j] * u[i])[:, None] * _fetch(T, wrap_index(ix0 + i - 1, W, ext), iy)
    if unassociate:                                  # svm_image_texture
        a = out[:, 3:4]
        div = (a != 0.0) & (a != 1.0)
        out[:, :3] = np.where(div, out[:, :3] / np.where(div, a, 1.0), out[:, :3])
    if tex.is_srgb and order == "after":
        out[:, :3] = srgb_to_linear(out[:, :3])
    return out


def sample_udim(tiles: dict, xy, interp="Linear", ext="REPEAT", unassociate: bool = False,
                working=None) -> np.ndarray:
    """(n, 4) RGBA of a UDIM image at (u, v) rows of xy; tiles: {tile number: Texture}; working:
    {tile number: matrix or None} (or one matrix / None for every tile).  See "UDIM" above."""
    xy = np.atleast_2d(np.asarray(xy, np.float64))
    out = np.tile(MISSING, (xy.shape[0], 1))
    finite = np.isfinite(xy).all(axis=1)
    out[~finite] = 0.0
    ok = finite & (xy[:, 0] > -1.0) & (xy[:, 1] > -1.0) & (xy[:, 0] < 10.0)
    tx = np.where(ok, np.trunc(np.where(ok, xy[:, 0], 0.0)), 0).astype(np.int64)
    ty = np.where(ok, np.trunc(np.where(ok, xy[:, 1], 0.0)), 0).astype(np.int64)
    number = 1001 + 10 * ty + tx
    for t, tex in tiles.items():
        rows = ok & (number == t)
        if not rows.any():
            continue
        M = working.get(t) if isinstance(working, dict) else working
        local = xy[rows] - np.stack([tx[rows], ty[rows]], 1)
        out[rows] = sample(tex, local, interp, ext, unassociate=unassociate_flag(tex, unassociate), working=M)
    return out
