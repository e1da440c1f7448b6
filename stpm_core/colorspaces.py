"""Colour spaces: what an image's colour-space name means, and the scene's working space.

Blender renders in a *working space* (scene linear): every colour of a scene -- material and light
colours, the world, texture look-ups, the film -- is an RGB triple in that space.  Blender 4 always
works in Linear Rec.709; Blender 5 lets a file choose one of :data:`WORKING_SPACES`
(``bpy.data.colorspace.working_space``, changed with ``bpy.ops.wm.set_working_color_space``, which
converts the file's colours).  Blender hands STPM every colour already in the working space (it
converts float images when it loads them, too); only byte images (and image files STPM reads
itself: UDIM tiles) arrive in their own colour space, and Cycles converts those into the working
space when it loads them.  STPM does the same per texel, in the kernel (``textures.pack_textures``
gives each such texture its matrix).

An image's colour space is a **transfer function** (``"srgb"``: the sRGB EOTF; ``"linear"``) and
**primaries** (a key of :data:`TO_XYZ_D65`; None for data and for values already in the working
space).  :func:`conversion` is the 3x3 matrix taking linear RGB of one set of primaries to
another, through CIE XYZ with a D65 white (Blender's OpenColorIO config: its ``Standard`` view is
XYZ E -> D65, the ACES spaces use OpenColorIO's Bradford-adapted built-ins).  The matrices below
are the config's own (its ``MatrixTransform`` entries and ``xyz_E_to_D65.spimtx``), inverted
where the config stores XYZ -> RGB; ACES AP0 / AP1 are built from their primaries and the ACES
white point with the Bradford cone response, as OpenColorIO's ``..._to_CIE-XYZ-D65_BFD``
built-ins are.  ``tests/test_colorspaces.py`` checks every pair against OpenColorIO with
Blender's bundled config (through OpenImageIO) to 2e-6.

Luminance (:func:`luma`): Blender converts a colour to a float (a colour socket into a value
socket, RGB to BW) by the working space's luminance weights, the Y row of its RGB -> XYZ
matrix, as Cycles does (``ShaderManager::init_xyz_transforms``, ``rgb_to_y``); for Linear
Rec.709 the config's ``luma: [0.2126, 0.7152, 0.0722]`` (the Y row to 4e-5).
"""
from __future__ import annotations

import numpy as np

__all__ = ["WORKING_SPACES", "WORKING_NAMES", "DEFAULT_WORKING", "TO_XYZ_D65", "SPACES", "DATA_SPACES",
           "SCENE_LINEAR_SPACES", "space_of", "conversion", "luma", "working_space_of", "to_working",
           "working_id", "srgb_to_linear"]

# Blender 5's working spaces: the scene file's metadata id -> Blender's name
WORKING_SPACES = {"REC709": "Linear Rec.709", "REC2020": "Linear Rec.2020", "ACESCG": "ACEScg"}
WORKING_NAMES = {v: k for k, v in WORKING_SPACES.items()}
DEFAULT_WORKING = "REC709"


def _rgb_to_xyz(primaries, white) -> np.ndarray:
    """RGB -> XYZ of primaries ((xr, yr), (xg, yg), (xb, yb)) with the given white (x, y) as RGB 1."""
    P = np.array([[x / y, 1.0, (1.0 - x - y) / y] for x, y in primaries]).T      # columns: XYZ of R, G, B
    wx, wy = white
    Wxyz = np.array([wx / wy, 1.0, (1.0 - wx - wy) / wy])
    return P * np.linalg.solve(P, Wxyz)[None, :]


def _bradford(src_white, dst_white) -> np.ndarray:
    """Bradford chromatic adaptation XYZ(src white) -> XYZ(dst white)."""
    B = np.array([[0.8951, 0.2664, -0.1614], [-0.7502, 1.7135, 0.0367], [0.0389, -0.0685, 1.0296]])

    def xyz(w):
        return np.array([w[0] / w[1], 1.0, (1.0 - w[0] - w[1]) / w[1]])
    s, d = B @ xyz(src_white), B @ xyz(dst_white)
    return np.linalg.inv(B) @ np.diag(d / s) @ B


_D65 = (0.3127, 0.3290)
_ACES_WHITE = (0.32168, 0.33767)
_AP0 = ((0.7347, 0.2653), (0.0, 1.0), (0.0001, -0.0770))
_AP1 = ((0.713, 0.293), (0.165, 0.830), (0.128, 0.044))


def _inv(rows) -> np.ndarray:
    return np.linalg.inv(np.array(rows, np.float64))


# Linear RGB -> CIE XYZ (D65 white) per set of primaries (Blender 5.0's config.ocio)
TO_XYZ_D65 = {
    "Linear Rec.709": _inv([[3.2409699, -1.5373832, -0.4986108], [-0.9692436, 1.8759675, 0.0415551],
                            [0.0556301, -0.2039770, 1.0569715]]),
    "Linear DCI-P3 D65": _inv([[2.4934969, -0.9313836, -0.4027108], [-0.8294890, 1.7626641, 0.0236247],
                               [0.0358458, -0.0761724, 0.9568845]]),
    "Linear Rec.2020": _inv([[1.7166512, -0.3556708, -0.2533663], [-0.6666844, 1.6164812, 0.0157685],
                             [0.0176399, -0.0427706, 0.9421031]]),
    "Linear CIE-XYZ D65": np.eye(3),
    "Linear CIE-XYZ E": np.array([[0.95318743, -0.02659057, 0.02387315], [-0.03824666, 1.02884062, 0.00940604],
                                  [0.00260677, -0.00303325, 1.08925647]]),
    "Linear FilmLight E-Gamut": _inv([[1.5250528, -0.3159135, -0.1226583], [-0.5091526, 1.3333274, 0.1382844],
                                      [0.0957153, 0.0508974, 0.7879558]]),
    "ACES2065-1": _bradford(_ACES_WHITE, _D65) @ _rgb_to_xyz(_AP0, _ACES_WHITE),
    "ACEScg": _bradford(_ACES_WHITE, _D65) @ _rgb_to_xyz(_AP1, _ACES_WHITE),
}

# Data: never converted (Cycles' colorspace_is_data; also no alpha association)
DATA_SPACES = ("Non-Color", "Raw", "Generic Data", "Data", "Non-Colour Data", "Utility - Raw")
# Values already in the working space: "Linear" is what STPM's exporter writes for Blender's float
# buffers (converted by Blender on load) and for bakes; "Working Space" is Blender 5's own name
SCENE_LINEAR_SPACES = ("Linear", "Working Space", "scene_linear")

# colour-space name -> (transfer, primaries); primaries None: no conversion
SPACES: dict = {name: ("linear", name) for name in TO_XYZ_D65}
SPACES.update({
    "sRGB": ("srgb", "Linear Rec.709"),
    "sRGB EOTF": ("srgb", "Linear Rec.709"),
    "Filmic sRGB": ("srgb", "Linear Rec.709"),    # (a display space; read as sRGB, as before)
    "Display P3": ("srgb", "Linear DCI-P3 D65"),
})
SPACES.update({name: ("linear", None) for name in DATA_SPACES + SCENE_LINEAR_SPACES})


def space_of(name: str) -> tuple:
    """(transfer "srgb" | "linear", primaries key or None) of a colour-space name; KeyError if unknown."""
    return SPACES[name]


def working_space_of(metadata) -> str:
    """The working-space id (a key of :data:`WORKING_SPACES`) of a scene's metadata (default REC709)."""
    ws = (metadata or {}).get("working_space", DEFAULT_WORKING)
    ws = str(ws).upper()
    if ws not in WORKING_SPACES:
        raise ValueError(f"unknown working space {ws!r}")
    return ws


def working_id(blender_name: str) -> str | None:
    """Blender's working-space name ("ACEScg") -> its id ("ACESCG"), None if STPM does not know it."""
    return WORKING_NAMES.get(blender_name)


def conversion(src_primaries: str | None, working: str = DEFAULT_WORKING) -> np.ndarray | None:
    """3x3 matrix: linear RGB of ``src_primaries`` -> the working space ``working`` (an id), or None
    when no conversion is needed (no primaries, or the same space)."""
    dst = WORKING_SPACES[working]
    if src_primaries is None or src_primaries == dst:
        return None
    return np.linalg.solve(TO_XYZ_D65[dst], TO_XYZ_D65[src_primaries])


def luma(working: str = DEFAULT_WORKING) -> tuple:
    """Blender's colour -> float weights (r, g, b) in the working space ``working`` (an id)."""
    if working == "REC709":
        return (0.2126, 0.7152, 0.0722)
    return tuple(float(x) for x in TO_XYZ_D65[WORKING_SPACES[working]][1])


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """The sRGB EOTF, c in [0, 1] (numpy; the kernels use the same formula)."""
    c = np.asarray(c, np.float64)
    return np.where(c <= 0.04045, c / 12.92, ((np.maximum(c, 0.04045) + 0.055) / 1.055) ** 2.4)


def to_working(rgb: np.ndarray, space: str, working: str = DEFAULT_WORKING) -> np.ndarray:
    """Encoded pixel values (..., 3) of an image in colour space ``space`` -> the working space
    (numpy, float64; the exporter's image means and environment images).  Unknown spaces: KeyError."""
    transfer, prim = space_of(space)
    out = srgb_to_linear(rgb) if transfer == "srgb" else np.asarray(rgb, np.float64)
    M = conversion(prim, working)
    return out if M is None else out @ M.T
