"""Image texture look-ups in compiled code (the arrays of :func:`stpm_core.textures.pack_textures`).

:func:`tex_lookup` samples texture ``tid`` at Blender coordinates (x, y) (u, v; (0, 0) the
bottom-left corner of the image, 1 one image across) as Cycles' CPU image kernel does:

* Closest: the texel floor(x W), floor(y H);
* Linear: bilinear between the four texels around (x W - 1/2, y H - 1/2);
* Cubic (and Smart): the uniform cubic B-spline over the 4 x 4 texels around it, weights
  w0 = (1 - t)^3 / 6, w1 = (3 t^3 - 6 t^2 + 4) / 6, w2 = (-3 t^3 + 3 t^2 + 3 t + 1) / 6, w3 = t^3 / 6;
* extension Repeat (wrap), Extend (clamp to the edge texel), Clip (texels outside the image read
  0: within a texel or two of the border the result fades to 0, as in Cycles 3.2+), Mirror
  (reflect every other tile).

An 8-bit sRGB image is interpolated as stored (sRGB-encoded, as Cycles keeps byte images) and the
result decoded by the sRGB EOTF; 16-bit, half and float sRGB images are decoded per texel first
(Blender hands them to Cycles as linear float buffers).  Alpha is never converted.  RGBA images
that are not data have associated (premultiplied) alpha, as Cycles loads them: 8-bit ones
premultiplied when packed (``textures.pack_textures``), float / 16-bit ones per texel as read,
after decoding; the colour is divided by alpha again only when the node's Alpha output is used.  Returns
(r, g, b, a) linear, a = 1 for images without alpha.

Working space.  A texture whose colour space has other primaries than the scene's working space
(``colorspaces``; e.g. an sRGB image in an ACEScg scene) carries a 3x3 matrix (header column
``H_MATRIX``): each texel is decoded (sRGB EOTF), multiplied by the matrix and premultiplied by its
alpha before interpolation -- 8-bit ones too, as Cycles converts such images to linear half
floats when it loads them (``ImageMetaData::detect_colorspace``); STPM keeps the bytes and
converts per texel in float.

UDIM (:func:`tex_image_rows` with a tile table, as Cycles' ``svm_node_tex_image``): the tile is
``1001 + tx + 10 ty`` with ``tx = int(x)``, ``ty = int(y)`` (truncated toward zero; only for
``x > -1``, ``y > -1``, ``tx < 10``); the look-up reads that tile's own texture at ``(x - tx,
y - ty)`` with the node's interpolation and extension (Repeat wraps within the tile, bilinear and
cubic filters never reach into the neighbouring tile); a coordinate in no listed tile reads
Cycles' missing-image magenta ``(1, 0, 1, 1)``.
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .sampling import JIT, JIT_INLINE

def _eotf_table() -> np.ndarray:
    c = np.arange(4097) / 4096.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


_EOTF = _eotf_table()

__all__ = ["tex_lookup", "tex_image_rows", "srgb_eotf", "tex_lookup_batch", "udim_tile", "MISSING"]

MISSING = (1.0, 0.0, 1.0, 1.0)        # Cycles' TEX_IMAGE_MISSING_R/G/B/A


@njit(**JIT)
def srgb_eotf(c):
    """sRGB-encoded c -> linear (negative values clamp to 0): c / 12.92 up to 0.04045, else
    ((c + 0.055) / 1.055)^2.4; on [0, 1] through the table ``_EOTF`` (4097 samples, linear
    interpolation: within 1e-7 of the formula), outside it by the formula."""
    if c <= 0.04045:
        return max(c, 0.0) / 12.92
    if c < 1.0:
        x = c * 4096.0
        i = int(x)
        t = x - i
        return (1.0 - t) * _EOTF[i] + t * _EOTF[i + 1]
    return ((c + 0.055) / 1.055) ** 2.4


@njit(**JIT)
def _wrap(i, n, ext):
    """Texel index i of an axis of n texels under extension ext; -1 = outside (Clip)."""
    if ext == 0:                       # REPEAT
        if n & (n - 1) == 0:
            return i & (n - 1)         # a power-of-two axis: the same number without a division
        i = i % n
        return i + n if i < 0 else i
    if ext == 1:                       # EXTEND
        return min(max(i, 0), n - 1)
    if ext == 2:                       # CLIP
        return i if 0 <= i < n else -1
    m = i % (2 * n)                    # MIRROR
    if m < 0:
        m += 2 * n
    return m if m < n else 2 * n - 1 - m


@njit(**JIT)
def _chan(kind, u8, u16, f32, half, i):
    """Decoded value of stored word i of a texture of this kind (U8, U16, HALF, F32)."""
    if kind == 0:
        return u8[i] * (1.0 / 255.0)
    if kind == 1:
        return u16[i] * (1.0 / 65535.0)
    if kind == 2:
        return float(half[u16[i]])
    return float(f32[i])


@njit(**JIT)
def _to_working(f32, m, r, g, b):
    """(r, g, b) times the row-major 3x3 matrix at f32[m:m + 9]."""
    return (f32[m] * r + f32[m + 1] * g + f32[m + 2] * b, f32[m + 3] * r + f32[m + 4] * g + f32[m + 5] * b,
            f32[m + 6] * r + f32[m + 7] * g + f32[m + 8] * b)


@njit(**JIT)
def _texel(hdr, u8, u16, f32, half, tid, ix, iy):
    """(r, g, b, a) of texel (ix, iy) (already wrapped; -1 -> 0): 8-bit values as stored (an sRGB
    image stays encoded), other kinds, and 8-bit images converted into the working space, decoded
    to linear working-space colour here, per texel."""
    if ix < 0 or iy < 0:
        return 0.0, 0.0, 0.0, 0.0
    C = hdr[tid, 3]
    kind = hdr[tid, 4]
    base = hdr[tid, 0] + (iy * hdr[tid, 1] + ix) * C
    r = _chan(kind, u8, u16, f32, half, base)
    if C == 1:
        g = b = r
        a = 1.0
    else:
        g = _chan(kind, u8, u16, f32, half, base + 1)
        b = _chan(kind, u8, u16, f32, half, base + 2)
        a = _chan(kind, u8, u16, f32, half, base + 3) if C == 4 else 1.0
    m = hdr[tid, 7]
    if kind != 0 or m >= 0:
        # Blender's linear float32 buffer: straight images decoded (and converted) then premultiplied
        # in float32; premultiplied ones kept (sRGB ones: decoded on the straight colour, alpha 0 / 1
        # directly)
        assoc = hdr[tid, 6]
        srgb = hdr[tid, 5] == 2
        if assoc == 3:
            if srgb:
                if a != 0.0 and a != 1.0:
                    a32 = np.float32(a)
                    r = float(np.float32(srgb_eotf(r / a)) * a32)
                    g = float(np.float32(srgb_eotf(g / a)) * a32)
                    b = float(np.float32(srgb_eotf(b / a)) * a32)
                else:
                    r, g, b = srgb_eotf(r), srgb_eotf(g), srgb_eotf(b)
            if m >= 0:
                r, g, b = _to_working(f32, m, r, g, b)
        else:
            if srgb:
                r, g, b = srgb_eotf(r), srgb_eotf(g), srgb_eotf(b)
            if m >= 0:
                r, g, b = _to_working(f32, m, r, g, b)
            if assoc == 2:
                a32 = np.float32(a)
                r, g, b = float(np.float32(r) * a32), float(np.float32(g) * a32), float(np.float32(b) * a32)
    return r, g, b, a


@njit(**JIT)
def _bspline(t):
    t2 = t * t
    t3 = t2 * t
    return ((1.0 - t) ** 3 / 6.0, (3.0 * t3 - 6.0 * t2 + 4.0) / 6.0, (-3.0 * t3 + 3.0 * t2 + 3.0 * t + 1.0) / 6.0,
            t3 / 6.0)


@njit(**JIT)
def _plain8(hdr, tid):
    """Are texture tid's texels its stored bytes / 255 (8-bit, no working-space matrix: nothing to
    decode or convert per texel)?  Then :func:`_texel8` reads them."""
    return hdr[tid, 4] == 0 and hdr[tid, 7] < 0


@njit(**JIT)
def _texel8(u8, base, W, C, ix, iy):
    """:func:`_texel` of a :func:`_plain8` texture whose bytes start at word base (W texels a row, C
    channels): the same values, without the per-texel look-ups of the texture's header and kind
    (a call per texel that LLVM did not inline cost 4x the bilinear look-up, measured 2026-12)."""
    if ix < 0 or iy < 0:
        return 0.0, 0.0, 0.0, 0.0
    i = base + (iy * W + ix) * C
    r = u8[i] * (1.0 / 255.0)
    if C == 1:
        return r, r, r, 1.0
    g = u8[i + 1] * (1.0 / 255.0)
    b = u8[i + 2] * (1.0 / 255.0)
    a = u8[i + 3] * (1.0 / 255.0) if C == 4 else 1.0
    return r, g, b, a


@njit(**JIT)
def _closest(hdr, u8, u16, f32, half, tid, x, y, ext):
    W, H = hdr[tid, 1], hdr[tid, 2]
    ix, iy = _wrap(int(math.floor(x * W)), W, ext), _wrap(int(math.floor(y * H)), H, ext)
    if _plain8(hdr, tid):
        return _texel8(u8, hdr[tid, 0], W, hdr[tid, 3], ix, iy)
    return _texel(hdr, u8, u16, f32, half, tid, ix, iy)


@njit(**JIT_INLINE)
def _footprint(x, y, W, H):
    """Bilinear footprint of (x, y) in a W x H texture: (ix0, iy0, tx, ty), the lower texel (not
    yet wrapped) and the weights toward the next one (texel centres at half-integers)."""
    fx = x * W - 0.5
    fy = y * H - 0.5
    x0 = math.floor(fx)
    y0 = math.floor(fy)
    return int(x0), int(y0), fx - x0, fy - y0


@njit(**JIT_INLINE)
def _blend4(a0, a1, a2, a3, b0, b1, b2, b3, c0, c1, c2, c3, d0, d1, d2, d3, tx, ty):
    """Bilinear blend of the four RGBA texels a (ix0, iy0), b (ix1, iy0), c (ix0, iy1), d (ix1, iy1)."""
    wa, wb, wc, wd = (1.0 - tx) * (1.0 - ty), tx * (1.0 - ty), (1.0 - tx) * ty, tx * ty
    return (wa * a0 + wb * b0 + wc * c0 + wd * d0, wa * a1 + wb * b1 + wc * c1 + wd * d1,
            wa * a2 + wb * b2 + wc * c2 + wd * d2, wa * a3 + wb * b3 + wc * c3 + wd * d3)


@njit(**JIT_INLINE)            # inlined into tex_image_rows' loop of 8-bit Linear look-ups: no call left in it
def _bilinear8(u8, base, W, H, C, x, y, ext):
    """:func:`_bilinear` of a :func:`_plain8` texture (bytes from word base, W x H texels of C
    channels): the same operations in the same order."""
    ix0, iy0, tx, ty = _footprint(x, y, W, H)
    if ext == 0:
        # Repeat: one wrap per axis (a mask on power-of-two sizes); the next texel wraps to 0 at the edge
        ix0, iy0 = _wrap(ix0, W, ext), _wrap(iy0, H, ext)     # (ext, not a literal 0: one compiled _wrap)
        ix1 = ix0 + 1 if ix0 + 1 < W else 0
        iy1 = iy0 + 1 if iy0 + 1 < H else 0
    else:
        ix1, iy1 = _wrap(ix0 + 1, W, ext), _wrap(iy0 + 1, H, ext)
        ix0, iy0 = _wrap(ix0, W, ext), _wrap(iy0, H, ext)
    a0, a1, a2, a3 = _texel8(u8, base, W, C, ix0, iy0)
    b0, b1, b2, b3 = _texel8(u8, base, W, C, ix1, iy0)
    c0, c1, c2, c3 = _texel8(u8, base, W, C, ix0, iy1)
    d0, d1, d2, d3 = _texel8(u8, base, W, C, ix1, iy1)
    return _blend4(a0, a1, a2, a3, b0, b1, b2, b3, c0, c1, c2, c3, d0, d1, d2, d3, tx, ty)


@njit(**JIT)
def _bilinear(hdr, u8, u16, f32, half, tid, x, y, ext):
    if _plain8(hdr, tid):
        return _bilinear8(u8, hdr[tid, 0], hdr[tid, 1], hdr[tid, 2], hdr[tid, 3], x, y, ext)
    W, H = hdr[tid, 1], hdr[tid, 2]
    ix0, iy0, tx, ty = _footprint(x, y, W, H)
    ix1, iy1 = _wrap(ix0 + 1, W, ext), _wrap(iy0 + 1, H, ext)
    ix0, iy0 = _wrap(ix0, W, ext), _wrap(iy0, H, ext)
    a0, a1, a2, a3 = _texel(hdr, u8, u16, f32, half, tid, ix0, iy0)
    b0, b1, b2, b3 = _texel(hdr, u8, u16, f32, half, tid, ix1, iy0)
    c0, c1, c2, c3 = _texel(hdr, u8, u16, f32, half, tid, ix0, iy1)
    d0, d1, d2, d3 = _texel(hdr, u8, u16, f32, half, tid, ix1, iy1)
    return _blend4(a0, a1, a2, a3, b0, b1, b2, b3, c0, c1, c2, c3, d0, d1, d2, d3, tx, ty)


@njit(**JIT)
def _bicubic(hdr, u8, u16, f32, half, tid, x, y, ext):
    W, H = hdr[tid, 1], hdr[tid, 2]
    fx = x * W - 0.5
    fy = y * H - 0.5
    x0 = math.floor(fx)
    y0 = math.floor(fy)
    wx = _bspline(fx - x0)
    wy = _bspline(fy - y0)
    ix0, iy0 = int(x0), int(y0)
    r = g = b = a = 0.0
    plain = _plain8(hdr, tid)
    base, C = hdr[tid, 0], hdr[tid, 3]
    for j in range(4):
        iy = _wrap(iy0 + j - 1, H, ext)
        for i in range(4):
            w = wy[j] * wx[i]
            ix = _wrap(ix0 + i - 1, W, ext)
            if plain:
                t0, t1, t2, t3 = _texel8(u8, base, W, C, ix, iy)
            else:
                t0, t1, t2, t3 = _texel(hdr, u8, u16, f32, half, tid, ix, iy)
            r += w * t0
            g += w * t1
            b += w * t2
            a += w * t3
    return r, g, b, a


@njit(**JIT)
def tex_lookup(hdr, u8, u16, f32, half, tid, x, y, interp, ext, unassociate):
    """(r, g, b, a) of texture tid at (x, y); interp 0 Closest, 1 Linear, 2 Cubic; ext 0 Repeat,
    1 Extend, 2 Clip, 3 Mirror (see the module docstring).  unassociate: divide the colour by
    alpha (0 < alpha < 1; images whose alpha is associated), as Cycles does when the Alpha output
    is used."""
    if not (math.isfinite(x) and math.isfinite(y)):
        return 0.0, 0.0, 0.0, 0.0
    if interp == 0:
        r, g, b, a = _closest(hdr, u8, u16, f32, half, tid, x, y, ext)
    elif interp == 1:
        r, g, b, a = _bilinear(hdr, u8, u16, f32, half, tid, x, y, ext)
    else:
        r, g, b, a = _bicubic(hdr, u8, u16, f32, half, tid, x, y, ext)
    if unassociate and hdr[tid, 6] != 0 and a != 1.0 and a != 0.0:
        r, g, b = r / a, g / a, b / a
    if hdr[tid, 5] == 1:
        r, g, b = srgb_eotf(r), srgb_eotf(g), srgb_eotf(b)
    return r, g, b, a


@njit(**JIT)
def udim_tile(prog, at, n_tiles, x, y):
    """(texture id, x, y) of the UDIM tile holding (x, y) in the tile table prog[at:at + 2 n_tiles]
    ((tile number, texture id) pairs), coordinates made relative to the tile; texture id -1 when
    no listed tile holds it (coordinates unchanged), as Cycles' ``svm_node_tex_image``."""
    if not (x > -1.0 and y > -1.0 and x < 10.0 and y < 1.0e6):
        return -1, x, y
    tx = int(x)                    # truncated toward zero, as C's (int) cast: (-1, 0) -> tile column 0
    ty = int(y)
    tile = 1001 + tx + 10 * ty
    for i in range(n_tiles):
        if int(prog[at + 2 * i]) == tile:
            return int(prog[at + 2 * i + 1]), x - tx, y - ty
    return -1, x, y


# The kinds of look-up tex_image_rows makes: all of them here.  The shader interpreter's variants
# (kernels.svm_variants) compile tex_image_rows again with the ones a scene's Image Textures do not
# use False: Closest, Linear (LINEAR8: an 8-bit image without a working-space matrix, _plain8),
# Cubic, UDIM tiles.
_USE_IMAGE_CLOSEST = _USE_IMAGE_LINEAR = _USE_IMAGE_LINEAR8 = _USE_IMAGE_CUBIC = _USE_IMAGE_UDIM = True


@njit(**JIT)
def tex_image_rows(hdr, u8, u16, f32, half, tid, interp, ext, unassociate, st, vs, cs, as_, n, prog, tiles_at,
                   n_tiles):
    """Image Texture over a batch of the interpreter's stack st (n_slots, >= n): the vector in
    slots vs .. vs + 2 of each row k < n -> colour (slots cs ..) and alpha (slot as_; -1 unused).
    The same values as :func:`tex_lookup`, with the interpolation chosen once per batch.  A UDIM
    image (n_tiles > 0) reads the tile table prog[tiles_at:tiles_at + 2 n_tiles] (:func:`udim_tile`;
    tid unused): each row its tile's texture, magenta outside the listed tiles."""
    if _USE_IMAGE_UDIM and n_tiles > 0:
        for k in range(n):
            x, y = st[vs, k], st[vs + 1, k]
            if not (math.isfinite(x) and math.isfinite(y)):
                r = g = b = a = 0.0
            else:
                t, x, y = udim_tile(prog, tiles_at, n_tiles, x, y)
                if t < 0:
                    r, g, b, a = MISSING
                else:
                    r, g, b, a = tex_lookup(hdr, u8, u16, f32, half, t, x, y, interp, ext, unassociate)
            _put(st, k, cs, as_, r, g, b, a)
        return
    srgb = hdr[tid, 5] == 1
    unassociate = unassociate and hdr[tid, 6] != 0
    if _USE_IMAGE_LINEAR8 and interp == 1 and _plain8(hdr, tid):
        # the common case (an 8-bit image, Linear) in a loop of its own: no call is left in it
        base, W, H, C = hdr[tid, 0], hdr[tid, 1], hdr[tid, 2], hdr[tid, 3]
        for k in range(n):
            x, y = st[vs, k], st[vs + 1, k]
            if not (math.isfinite(x) and math.isfinite(y)):
                r = g = b = a = 0.0
            else:
                r, g, b, a = _bilinear8(u8, base, W, H, C, x, y, ext)
            _store(st, k, cs, as_, r, g, b, a, unassociate, srgb)
        return
    if not (_USE_IMAGE_CLOSEST or _USE_IMAGE_LINEAR or _USE_IMAGE_CUBIC):
        # (a variant whose programs only read 8-bit images linearly: no loop of the general look-ups)
        for k in range(n):
            _put(st, k, cs, as_, 0.0, 0.0, 0.0, 0.0)
        return
    for k in range(n):
        x, y = st[vs, k], st[vs + 1, k]
        if not (math.isfinite(x) and math.isfinite(y)):
            r = g = b = a = 0.0
        elif _USE_IMAGE_CLOSEST and interp == 0:
            r, g, b, a = _closest(hdr, u8, u16, f32, half, tid, x, y, ext)
        elif _USE_IMAGE_LINEAR and interp == 1:
            r, g, b, a = _bilinear(hdr, u8, u16, f32, half, tid, x, y, ext)
        elif _USE_IMAGE_CUBIC:
            r, g, b, a = _bicubic(hdr, u8, u16, f32, half, tid, x, y, ext)
        else:                          # (a variant without this look-up: no program has it)
            r = g = b = a = 0.0
        _store(st, k, cs, as_, r, g, b, a, unassociate, srgb)


@njit(**JIT_INLINE)            # (tex_image_rows' loops: no call left in them)
def _store(st, k, cs, as_, r, g, b, a, unassociate, srgb):
    """Row k of :func:`tex_image_rows`: the colour (divided by alpha when unassociate, then decoded
    when srgb) into slots cs .. cs + 2, the alpha into slot as_ (-1: not used)."""
    if unassociate and a != 1.0 and a != 0.0:
        r, g, b = r / a, g / a, b / a
    if srgb:
        r, g, b = srgb_eotf(r), srgb_eotf(g), srgb_eotf(b)
    _put(st, k, cs, as_, r, g, b, a)


@njit(**JIT_INLINE)            # (tex_image_rows' loops: no call left in them)
def _put(st, k, cs, as_, r, g, b, a):
    """Row k's colour into slots cs .. cs + 2 and its alpha into slot as_ (-1: not used)."""
    if cs >= 0:
        st[cs, k] = r
        st[cs + 1, k] = g
        st[cs + 2, k] = b
    if as_ >= 0:
        st[as_, k] = a


@njit(**JIT)
def tex_lookup_batch(hdr, u8, u16, f32, half, tid, xy, interp, ext, unassociate, out):
    """:func:`tex_lookup` per row of xy (n, 2) into out (n, 4) (tests)."""
    for i in range(xy.shape[0]):
        r, g, b, a = tex_lookup(hdr, u8, u16, f32, half, tid, xy[i, 0], xy[i, 1], interp, ext, unassociate)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = r, g, b, a
