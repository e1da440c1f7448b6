"""Image textures as the compiled kernels read them.

A :class:`Texture` is one image in its native storage type; a scene's textures
are packed once per render into a few flat arrays (:func:`pack_textures`) that
the shader-node interpreter (:mod:`stpm_core.kernels.svm`) samples per hit
(:mod:`stpm_core.kernels.texture`).  Storage is compact: a texel costs what the
image file stores, not a float32 RGBA copy.

===========  ===================  =========================================================
kind         storage              decoded value (before the colour-space conversion)
===========  ===================  =========================================================
``U8``       uint8 per channel    c / 255
``U16``      uint16 per channel   c / 65535
``HALF``     uint16 bit patterns  the IEEE half value (``HALF_TABLE``; numba has no float16
                                  arithmetic on the CPU)
``F32``      float32              the value
===========  ===================  =========================================================

Colour spaces (``Texture.colorspace``, Blender's names; :mod:`stpm_core.colorspaces`): ``"sRGB"``
decodes the sRGB transfer function to linear Rec.709, ``"Linear Rec.709"``, ``"Linear Rec.2020"``,
``"ACEScg"``, ... are linear in their primaries, ``"Linear"`` holds values already in the scene's
working space (Blender's float buffers), ``"Non-Color"`` (and other data spaces) holds data.  When
packed for a working space (:func:`pack_textures`), a texture whose primaries differ gets the 3x3
matrix that takes its linear colour into the working space, applied per texel (as Cycles converts
such images when it loads them).  Channels: 1 (grey), 3 (RGB) or 4 (RGBA, alpha straight); a
missing alpha reads 1.

Units: texels are reflectances / colours, unitless; texture coordinates are
Blender's (u, v) in [0, 1) across the image, v up (row 0 of ``pixels`` is the
*bottom* row, as ``bpy.types.Image.pixels``).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import colorspaces as _cs
from .colorspaces import DATA_SPACES, srgb_to_linear

__all__ = ["Texture", "pack_textures", "TexturePack", "KINDS", "U8", "U16", "HALF", "F32", "HALF_TABLE",
           "SRGB_TABLE", "LINEAR_SPACES", "SRGB_SPACES", "COLOR_SPACES", "srgb_to_linear"]

U8, U16, HALF, F32 = 0, 1, 2, 3
KINDS = {"U8": U8, "U16": U16, "HALF": HALF, "F32": F32}

# Blender colour-space names (bpy.types.ColorManagedInputColorspaceSettings.name) by transfer function
COLOR_SPACES = tuple(_cs.SPACES)
SRGB_SPACES = tuple(n for n, (t, _p) in _cs.SPACES.items() if t == "srgb")
LINEAR_SPACES = tuple(n for n, (t, _p) in _cs.SPACES.items() if t == "linear")

# Header columns of TexturePack.header
H_OFFSET, H_WIDTH, H_HEIGHT, H_CHANNELS, H_KIND, H_SRGB, H_ASSOCIATE, H_MATRIX = range(8)
N_HEADER = 8
# H_SRGB: 0 no transfer function; 1 sRGB decoded after interpolation (8-bit images read as stored,
# as Cycles keeps byte sRGB images); 2 sRGB decoded per texel, before interpolation
SRGB_AFTER, SRGB_PER_TEXEL = 1, 2


def _half_table() -> np.ndarray:
    return np.arange(65536, dtype=np.uint32).astype(np.uint16).view(np.float16).astype(np.float32)


HALF_TABLE = _half_table()                                           # (65536,) float32: half bits -> value
SRGB_TABLE = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)   # (256,) float32: sRGB byte -> linear


@dataclass
class Texture:
    """One image.

    Attributes
    ----------
    pixels : (H, W, C) array, C in {1, 3, 4}, row 0 at the bottom (v = 0): uint8 (kind ``U8``),
        uint16 (``U16``, or half bit patterns when ``half``), float32 (``F32``), or float16
        (stored as ``HALF``).
    colorspace : "sRGB", "Linear" or a data space ("Non-Color", ...; linear values whose alpha
        is never associated) (see the module docstring).
    name : for messages.
    half : uint16 ``pixels`` hold half-float bit patterns (not normalised integers).
    alpha_mode : Blender's ``Image.alpha_mode`` for 4-channel pixels: "STRAIGHT" (colours not
        multiplied by alpha; packing premultiplies them, as Cycles loads images), "PREMUL"
        (already premultiplied), "CHANNEL_PACKED" (alpha is unrelated data: kept, colours
        untouched), "NONE" (alpha ignored: reads 1).
    """

    pixels: np.ndarray
    colorspace: str = "sRGB"
    name: str = "image"
    half: bool = False
    alpha_mode: str = "STRAIGHT"

    def __post_init__(self):
        px = np.asarray(self.pixels)
        if px.ndim == 2:
            px = px[:, :, None]
        if px.ndim != 3 or px.shape[2] not in (1, 2, 3, 4) or px.shape[0] < 1 or px.shape[1] < 1:
            raise ValueError(f"texture {self.name!r}: pixels must be (H, W, 1|3|4), got {px.shape}")
        if px.shape[2] == 2:                       # grey + alpha -> RGBA
            px = np.concatenate([px[:, :, :1]] * 3 + [px[:, :, 1:]], axis=2)
        if px.dtype == np.float16:
            px, self.half = px.view(np.uint16), True
        elif px.dtype == np.float64:
            px = px.astype(np.float32)
        elif px.dtype not in (np.uint8, np.uint16, np.float32):
            raise ValueError(f"texture {self.name!r}: unsupported pixel type {px.dtype}")
        self.pixels = np.ascontiguousarray(px)

    @property
    def kind(self) -> int:
        dt = self.pixels.dtype
        if dt == np.uint8:
            return U8
        if dt == np.uint16:
            return HALF if self.half else U16
        return F32

    @property
    def is_srgb(self) -> bool:
        return self.colorspace in SRGB_SPACES

    @property
    def primaries(self) -> str | None:
        """The key of :data:`stpm_core.colorspaces.TO_XYZ_D65` of its linear colour, None for data
        and for values already in the working space (and for unknown names: read as they are)."""
        return _cs.SPACES.get(self.colorspace, ("linear", None))[1]

    def to_working(self, working: str = _cs.DEFAULT_WORKING) -> np.ndarray | None:
        """(3, 3) matrix from its linear colour to the working space ``working`` (an id of
        :data:`stpm_core.colorspaces.WORKING_SPACES`), None when it needs none."""
        return _cs.conversion(self.primaries, working)

    @property
    def associates_alpha(self) -> bool:
        """Is the colour multiplied by alpha on load (and divided again where Alpha is linked)?
        As Cycles: RGBA images that are not data, STRAIGHT or PREMUL."""
        return (self.pixels.shape[2] == 4 and self.colorspace not in DATA_SPACES
                and self.alpha_mode in ("STRAIGHT", "PREMUL"))

    @property
    def nbytes(self) -> int:
        return int(self.pixels.nbytes)

    def decoded(self, working: str | None = None) -> np.ndarray:
        """(H, W, 4) float64 linear RGBA (numpy; tests and oracles), straight alpha; with a working
        space id, its colour converted into that space."""
        px = self.pixels
        k = self.kind
        if k == U8:
            v = px.astype(np.float64) / 255.0
        elif k == U16:
            v = px.astype(np.float64) / 65535.0
        elif k == HALF:
            v = HALF_TABLE[px].astype(np.float64)
        else:
            v = px.astype(np.float64)
        H, W, C = v.shape
        out = np.ones((H, W, 4))
        if C == 1:
            out[:, :, :3] = v
        else:
            out[:, :, :3] = v[:, :, :3]
            if C == 4:
                out[:, :, 3] = v[:, :, 3]
        if self.is_srgb:
            out[:, :, :3] = srgb_to_linear(np.clip(out[:, :, :3], 0.0, None)) if k != F32 else \
                np.where(out[:, :, :3] <= 0.04045, out[:, :, :3] / 12.92,
                         ((np.maximum(out[:, :, :3], 0.04045) + 0.055) / 1.055) ** 2.4)
        M = self.to_working(working) if working is not None else None
        if M is not None:
            out[:, :, :3] = out[:, :, :3] @ M.T
        return out


@dataclass
class TexturePack:
    """Every texture of a scene in the arrays the kernels read.

    header (T, N_HEADER) int64, per texture: offset into the kind's array, width, height, channels,
    kind, sRGB mode (``H_SRGB``: 0 none, 1 decoded after interpolation, 2 per texel), associate
    flag (``H_ASSOCIATE``; 2: premultiply each texel when read: RGBA float / 16-bit images, which
    Blender hands to Cycles as premultiplied linear floats, and images converted per texel; 3:
    already premultiplied, divided before decoding; 1: 8-bit images premultiplied when packed;
    0: alpha not associated), matrix (``H_MATRIX``: offset into f32 of the 3x3 row-major float32
    matrix into the working space, -1 none); u8 (N8,) uint8, u16 (N16,) uint16 (U16 and HALF),
    f32 (N32,) float32 texels, row-major (row, column, channel) per texture, then the matrices;
    half (65536,) and srgb (256,) float32 tables.
    """

    header: np.ndarray
    u8: np.ndarray
    u16: np.ndarray
    f32: np.ndarray
    half: np.ndarray
    srgb: np.ndarray
    n_matrices: int = 0

    @property
    def nbytes(self) -> int:
        """Bytes of texels (the matrices, 36 bytes each, not counted)."""
        return int(self.u8.nbytes + self.u16.nbytes + self.f32.nbytes) - 36 * self.n_matrices

    def arrays(self) -> tuple:
        return self.header, self.u8, self.u16, self.f32, self.half, self.srgb


def _per_texel(tx: Texture, M) -> bool:
    """Is the texture decoded per texel (every kind but 8-bit, and 8-bit ones with a matrix)?"""
    return tx.kind != U8 or M is not None


def _associated(tx: Texture, M=None) -> np.ndarray:
    """The texture's pixels as the kernels store them: 8-bit STRAIGHT RGBA read as stored
    premultiplied in their stored (sRGB-encoded) bytes, truncating as Cycles' byte loader; NONE
    images without their alpha channel; everything else as given (float / 16-bit RGBA, and images
    converted per texel, are premultiplied per texel as read, after decoding and conversion:
    header column ``H_ASSOCIATE``)."""
    px = tx.pixels
    if px.shape[2] == 4 and tx.alpha_mode == "NONE":
        return np.ascontiguousarray(px[:, :, :3])
    if px.shape[2] != 4 or _per_texel(tx, M) or tx.alpha_mode != "STRAIGHT" or not tx.associates_alpha:
        return px
    wide = px.astype(np.int64)
    out = wide.copy()
    out[:, :, :3] = (wide[:, :, :3] * wide[:, :, 3:4]) // 255
    return out.astype(np.uint8)


def pack_textures(textures, working: str = _cs.DEFAULT_WORKING) -> TexturePack:
    """Pack a list of :class:`Texture` (texture id = list index) for the kernels, their colours
    read in the working space ``working`` (an id of :data:`stpm_core.colorspaces.WORKING_SPACES`)."""
    textures = list(textures)
    header = np.zeros((max(len(textures), 1), N_HEADER), np.int64)
    header[:, H_MATRIX] = -1
    parts = {U8: [], U16: [], F32: []}
    sizes = {U8: 0, U16: 0, F32: 0}
    mats = []
    for i, tx in enumerate(textures):
        k = tx.kind
        store = U16 if k == HALF else k
        M = tx.to_working(working)
        per_texel = _per_texel(tx, M)
        px = _associated(tx, M)
        flat = px.reshape(-1)
        H, W, C = px.shape
        assoc = 0 if not tx.associates_alpha else (2 if per_texel else 1)
        if tx.alpha_mode == "PREMUL" and assoc == 2:
            assoc = 3                          # already premultiplied: divide before decoding sRGB
        srgb = 0 if not tx.is_srgb else (SRGB_PER_TEXEL if per_texel else SRGB_AFTER)
        header[i, :H_MATRIX] = (sizes[store], W, H, C, k, srgb, assoc)
        if M is not None:
            header[i, H_MATRIX] = len(mats)          # made an offset below, past the texels
            mats.append(np.asarray(M, np.float32).reshape(-1))
        parts[store].append(flat)
        sizes[store] += flat.size

    def cat(k, dt):
        return np.concatenate(parts[k]).astype(dt, copy=False) if parts[k] else np.zeros(1, dt)

    f32 = cat(F32, np.float32)
    if mats:
        base = f32.size
        f32 = np.concatenate([f32, np.concatenate(mats)])
        has = header[:, H_MATRIX] >= 0
        header[has, H_MATRIX] = base + 9 * header[has, H_MATRIX]
    return TexturePack(header=header, u8=cat(U8, np.uint8), u16=cat(U16, np.uint16), f32=f32,
                       half=HALF_TABLE, srgb=SRGB_TABLE, n_matrices=len(mats))
