"""The shader-node interpreter: one compiled kernel evaluates every material's node program
per hit (in the manner of Cycles' SVM; programs: :mod:`stpm_core.nodes.compile`, opcodes and
operand layouts: :mod:`stpm_core.nodes.ops`).

:func:`shade_closures` fills each hit's closure row (:mod:`.closure`): the material's constant
row, then, for materials with a program, the program's closure instruction overwrites the
primary columns and :func:`.closure.finish_closure` derives the rest.  Node formulas follow
Blender's (``intern/cycles/kernel/svm/*.h``; equations with these names: docs/shader-nodes.md).

Per-hit inputs (G, the bounce's hits): P, NG, NS, D (m, 3) world position, geometric and
shading normals, ray directions; inst, prim (m,) int32 instance and mesh-local triangle;
bu, bv (m,) barycentrics (point = (1 - bu - bv) v0 + bu v1 + bv v2); NM (m, 3, 3) each hit's
object-to-world normal matrix (inverse transpose of the instance's linear part at the hit's
time; (1, 3, 3) identity when no node needs it).  A shader whose Normal input is linked rewrites
NS of its hits.  Scene attributes (A, :func:`stpm_core.shading.scene_attributes`): inst_mesh (I,),
mesh_tri0 (M,), uv_off (M, L), corner_uv (N, 3, 2) float32, corner_obj (T, 3, 3) float32 (object
space, the mesh's undeformed shape ``Mesh.orco`` or its shape at the frame), gen_lo, gen_inv (M, 3)
(Generated = (p_obj - gen_lo) gen_inv),
corner_nrm (T, 3, 3) float32 object-space corner normals (flat faces: the face normal), tan_off
(M, L) and corner_tan (N, 3, 4) float32 per-corner tangents and bitangent signs of UV map l, col_off
(M, Lc) and corner_col (N', 3, 4) float32 per-corner RGBA of colour layer c (-1: none), inst_obj
(I, 4, 4) world -> object at the frame for instances of deforming meshes (Object = inst_obj P), else 0,
gen_tri0 (M,) and corner_gen (T', 3, 3) float32 the undeformed corners Generated reads (-1: corner_obj).
Textures (X):
:class:`stpm_core.textures.TexturePack` arrays.

Mix Shader picks one branch per hit with probability Fac, from a hash of (seed, row): the
expected closure is Blender's blend and no random number of the integrator's streams is used.
"""
from __future__ import annotations

import math

import numpy as np

from ..numba_probe import njit
from .closure import (C_CC_HAS_N, C_CC_N, C_CC_IOR, C_CC_ROUGH, C_CC_TINT, C_CC_WEIGHT, C_BASE, C_TINT_R, C_TINT_T, C_BUMPED, C_EMIT, C_PASS, C_TRANSPARENT, C_IOR, C_METALLIC, C_NS, C_PROGRAM, C_ROUGHNESS, C_SPECULAR,
                      C_TRANSMISSION, C_METAL_CONST, closure_row, finish_closure_at)
from .sampling import JIT, JIT_INLINE

from .procedural import (brick_color, brick_texture, magic_texture, noise_texture, voronoi_texture, wave_texture,
                         white_noise_texture)
from .texture import tex_image_rows
from ..nodes.ops import OP

__all__ = ["shade", "shade_rows", "shade_closures", "shade_closure_rows", "constant_closures", "closure_rows", "hash_uniform",
           "max_slots"]

# Opcodes as module constants (numba folds globals)
_END = OP["END"]
_CONVERT = OP["CONVERT"]
_TEXCOORD = OP["TEXCOORD"]
_UVMAP = OP["UVMAP"]
_GEOMETRY = OP["GEOMETRY"]
_MAPPING = OP["MAPPING"]
_MATH = OP["MATH"]
_VECTOR_MATH = OP["VECTOR_MATH"]
_MIX_FLOAT = OP["MIX_FLOAT"]
_MIX_VECTOR = OP["MIX_VECTOR"]
_MIX_COLOR = OP["MIX_COLOR"]
_INVERT = OP["INVERT"]
_HSV = OP["HSV"]
_BRIGHT_CONTRAST = OP["BRIGHT_CONTRAST"]
_GAMMA = OP["GAMMA"]
_SEPARATE_COLOR = OP["SEPARATE_COLOR"]
_COMBINE_COLOR = OP["COMBINE_COLOR"]
_SEPARATE_XYZ = OP["SEPARATE_XYZ"]
_COMBINE_XYZ = OP["COMBINE_XYZ"]
_CLAMP = OP["CLAMP"]
_MAP_RANGE = OP["MAP_RANGE"]
_RAMP = OP["RAMP"]
_CURVES = OP["CURVES"]
_TEX_IMAGE = OP["TEX_IMAGE"]
_TEX_CHECKER = OP["TEX_CHECKER"]
_TEX_GRADIENT = OP["TEX_GRADIENT"]
_BSDF_PRINCIPLED = OP["BSDF_PRINCIPLED"]
_BSDF_DIFFUSE = OP["BSDF_DIFFUSE"]
_BSDF_GLOSSY = OP["BSDF_GLOSSY"]
_BSDF_GLASS = OP["BSDF_GLASS"]
_EMISSION = OP["EMISSION"]
_MIX_SHADER = OP["MIX_SHADER"]
_TRANSPARENT = OP["TRANSPARENT"]
_ADD_SHADER = OP["ADD_SHADER"]
_ATTRIBUTE = OP["ATTRIBUTE"]
_NORMAL_MAP = OP["NORMAL_MAP"]
_BUMP = OP["BUMP"]
_TEX_NOISE = OP["TEX_NOISE"]
_TEX_VORONOI = OP["TEX_VORONOI"]
_TEX_WAVE = OP["TEX_WAVE"]
_TEX_BRICK = OP["TEX_BRICK"]
_TEX_MAGIC = OP["TEX_MAGIC"]
_TEX_WHITE_NOISE = OP["TEX_WHITE_NOISE"]

# Which opcodes this module's interpreter evaluates: every one.  The dispatching functions test
# ``_USE_<op> and op == _<op>``; a variant of the interpreter for the opcodes one scene's programs
# use (:mod:`.svm_variants`) compiles these same functions again with the others False, and numba
# drops those branches (and never compiles what only they call) before typing.
_USE_CONVERT = _USE_TEXCOORD = _USE_UVMAP = _USE_GEOMETRY = _USE_MAPPING = _USE_MATH = _USE_VECTOR_MATH = True
_USE_MIX_FLOAT = _USE_MIX_VECTOR = _USE_MIX_COLOR = _USE_INVERT = _USE_HSV = _USE_BRIGHT_CONTRAST = True
_USE_GAMMA = _USE_SEPARATE_COLOR = _USE_COMBINE_COLOR = _USE_SEPARATE_XYZ = _USE_COMBINE_XYZ = True
_USE_CLAMP = _USE_MAP_RANGE = _USE_RAMP = _USE_CURVES = _USE_TEX_IMAGE = _USE_TEX_CHECKER = True
_USE_TEX_GRADIENT = _USE_BSDF_PRINCIPLED = _USE_BSDF_DIFFUSE = _USE_BSDF_GLOSSY = _USE_BSDF_GLASS = True
_USE_EMISSION = _USE_MIX_SHADER = _USE_TRANSPARENT = _USE_ADD_SHADER = _USE_ATTRIBUTE = True
_USE_NORMAL_MAP = _USE_BUMP = _USE_TEX_NOISE = _USE_TEX_VORONOI = _USE_TEX_WAVE = _USE_TEX_BRICK = True
_USE_TEX_MAGIC = _USE_TEX_WHITE_NOISE = True
# and the parts of an instruction some programs never reach: each Mix Color blend mode, a shader's
# Normal input (its closure rewrites the hit's shading normal); the Image Texture's kinds of
# look-up have theirs in kernels.texture
_USE_BLEND_MIX = _USE_BLEND_DARKEN = _USE_BLEND_MULTIPLY = _USE_BLEND_BURN = _USE_BLEND_LIGHTEN = True
_USE_BLEND_SCREEN = _USE_BLEND_DODGE = _USE_BLEND_ADD = _USE_BLEND_OVERLAY = _USE_BLEND_SOFT_LIGHT = True
_USE_BLEND_LINEAR_LIGHT = _USE_BLEND_DIFFERENCE = _USE_BLEND_EXCLUSION = _USE_BLEND_SUBTRACT = True
_USE_BLEND_DIVIDE = _USE_BLEND_HUE = _USE_BLEND_SATURATION = _USE_BLEND_COLOR = _USE_BLEND_VALUE = True
_USE_SET_NORMAL = True
_USE_ALPHA = True                      # a Principled BSDF's Alpha that is not a constant 1
_USE_TEXCOORD_UV = _USE_TEXCOORD_GENERATED = _USE_TEXCOORD_OBJECT = True     # Texture Coordinate's outputs
_USE_TEXCOORD_NORMAL = _USE_TEXCOORD_REFLECTION = True



# ----------------------------------------------------------------------------
# Stack helpers
# ----------------------------------------------------------------------------
@njit(**JIT)
def _v3(st, s, k):
    """The vec3 in slots s .. s + 2 of batch row k (st: (n_slots, n))."""
    return st[s, k], st[s + 1, k], st[s + 2, k]


@njit(**JIT)
def _put3(st, k, s, v0, v1, v2):
    if s >= 0:
        st[s, k] = v0
        st[s + 1, k] = v1
        st[s + 2, k] = v2


@njit(**JIT)
def _put1(st, k, s, v):
    if s >= 0:
        st[s, k] = v


@njit(**JIT)
def _clamp01(x):
    return min(max(x, 0.0), 1.0)


@njit(**JIT)
def _safe_div(a, b):
    return a / b if b != 0.0 else 0.0


@njit(**JIT)
def _fract(x):
    return x - math.floor(x)


@njit(**JIT)
def hash_uniform(seed, r):
    """A uniform number in [0, 1) from (seed, r): a 64-bit integer mix (splitmix64 finaliser)."""
    z = np.uint64(seed) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(r) + np.uint64(0x632BE59BD9B4E019)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return float(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


# ----------------------------------------------------------------------------
# Colour helpers (Blender's util/color.h)
# ----------------------------------------------------------------------------
@njit(**JIT)
def rgb_to_hsv(r, g, b):
    cmax = max(r, max(g, b))
    cmin = min(r, min(g, b))
    cdelta = cmax - cmin
    v = cmax
    s = cdelta / cmax if cmax != 0.0 else 0.0
    h = 0.0
    if s != 0.0:
        cr = (cmax - r) / cdelta
        cg = (cmax - g) / cdelta
        cb = (cmax - b) / cdelta
        if r == cmax:
            h = cb - cg
        elif g == cmax:
            h = 2.0 + cr - cb
        else:
            h = 4.0 + cg - cr
        h /= 6.0
        if h < 0.0:
            h += 1.0
    return h, s, v


@njit(**JIT)
def hsv_to_rgb(h, s, v):
    if s == 0.0:
        return v, v, v
    if h == 1.0:
        h = 0.0
    h *= 6.0
    i = math.floor(h)
    f = h - i
    p = v * (1.0 - s)
    q = v * (1.0 - s * f)
    t = v * (1.0 - s * (1.0 - f))
    if i == 0.0:
        return v, t, p
    if i == 1.0:
        return q, v, p
    if i == 2.0:
        return p, v, t
    if i == 3.0:
        return p, q, v
    if i == 4.0:
        return t, p, v
    return v, p, q


@njit(**JIT)
def rgb_to_hsl(r, g, b):
    cmax = max(r, max(g, b))
    cmin = min(r, min(g, b))
    l = min(1.0, 0.5 * (cmax + cmin))
    if cmax == cmin:
        return 0.0, 0.0, l
    d = cmax - cmin
    s = d / (2.0 - cmax - cmin) if l > 0.5 else d / (cmax + cmin)
    if cmax == r:
        h = (g - b) / d + (6.0 if g < b else 0.0)
    elif cmax == g:
        h = (b - r) / d + 2.0
    else:
        h = (r - g) / d + 4.0
    return h / 6.0, s, l


@njit(**JIT)
def hsl_to_rgb(h, s, l):
    """Cycles' hsl_to_rgb: channel ramps clamp(|6h - 3| - 1), clamp(2 - |6h - 2|), clamp(2 - |6h - 4|)
    scaled by the chroma (1 - |2l - 1|) s about l (no hue wrap)."""
    nr = min(max(abs(h * 6.0 - 3.0) - 1.0, 0.0), 1.0)
    ng = min(max(2.0 - abs(h * 6.0 - 2.0), 0.0), 1.0)
    nb = min(max(2.0 - abs(h * 6.0 - 4.0), 0.0), 1.0)
    chroma = (1.0 - abs(2.0 * l - 1.0)) * s
    return (nr - 0.5) * chroma + l, (ng - 0.5) * chroma + l, (nb - 0.5) * chroma + l


# ----------------------------------------------------------------------------
# Math
# ----------------------------------------------------------------------------
@njit(**JIT)
def _safe_pow(a, b):
    """a^b; 0 where a < 0 and b is not an integer (Blender's safe_powf)."""
    if a >= 0.0 or b == math.floor(b):
        return a ** b
    return 0.0


@njit(**JIT)
def _sign(a):
    return 1.0 if a > 0.0 else (-1.0 if a < 0.0 else 0.0)


@njit(**JIT)
def _fmod(a, b):
    """Truncated modulo (C fmodf); 0 where b = 0."""
    return np.fmod(a, b) if b != 0.0 else 0.0


@njit(**JIT)
def _wrap(a, b, c):
    """a wrapped into [c, b) (Blender's wrapf); c where the range is empty."""
    rng = b - c
    return a - rng * math.floor((a - c) / rng) if rng != 0.0 else c


@njit(**JIT)
def _snap(a, b):
    return math.floor(_safe_div(a, b)) * b


@njit(**JIT)
def math_op(op, a, b, c):
    """Blender's Math node (``svm_math``); op = ``ops.MATH_OPS`` code."""
    if op == 0:
        return a + b
    if op == 1:
        return a - b
    if op == 2:
        return a * b
    if op == 3:
        return _safe_div(a, b)
    if op == 4:
        return a * b + c
    if op == 5:                      # POWER (safe: a < 0 needs an integer b)
        return _safe_pow(a, b)
    if op == 6:                      # LOGARITHM of a to base b
        return math.log(a) / math.log(b) if (a > 0.0 and b > 0.0 and b != 1.0) else 0.0
    if op == 7:
        return math.sqrt(a) if a > 0.0 else 0.0
    if op == 8:
        return 1.0 / math.sqrt(a) if a > 0.0 else 0.0
    if op == 9:
        return abs(a)
    if op == 10:
        return math.exp(a)
    if op == 11:
        return min(a, b)
    if op == 12:
        return max(a, b)
    if op == 13:
        return 1.0 if a < b else 0.0
    if op == 14:
        return 1.0 if a > b else 0.0
    if op == 15:
        return _sign(a)
    if op == 16:                     # COMPARE within epsilon c (at least float32's epsilon)
        return 1.0 if (a == b or abs(a - b) <= max(c, 1.1920928955078125e-07)) else 0.0
    if op == 17 or op == 18:         # SMOOTH_MIN / SMOOTH_MAX
        s = 1.0 if op == 17 else -1.0
        x, y = s * a, s * b
        if c != 0.0:
            h = max(c - abs(x - y), 0.0) / c
            r = min(x, y) - h * h * h * c * (1.0 / 6.0)
        else:
            r = min(x, y)
        return s * r
    if op == 19:
        return math.floor(a + 0.5)
    if op == 20:
        return math.floor(a)
    if op == 21:
        return math.ceil(a)
    if op == 22:
        return math.floor(a) if a >= 0.0 else math.ceil(a)
    if op == 23:
        return a - math.floor(a)
    if op == 24:                     # MODULO: fmod (truncated)
        return _fmod(a, b)
    if op == 25:                     # FLOORED_MODULO
        return a - math.floor(a / b) * b if b != 0.0 else 0.0
    if op == 26:                     # WRAP a into [c, b)
        return _wrap(a, b, c)
    if op == 27:                     # SNAP
        return _snap(a, b)
    if op == 28:                     # PINGPONG
        return abs(_fract((a - b) / (b * 2.0)) * b * 2.0 - b) if b != 0.0 else 0.0
    if op == 29:
        return math.sin(a)
    if op == 30:
        return math.cos(a)
    if op == 31:
        return math.tan(a)
    if op == 32:
        return math.asin(min(max(a, -1.0), 1.0))
    if op == 33:
        return math.acos(min(max(a, -1.0), 1.0))
    if op == 34:
        return math.atan(a)
    if op == 35:                     # ARCTAN2 (Cycles' compatible_atan2: 0 at the origin)
        return 0.0 if (a == 0.0 and b == 0.0) else math.atan2(a, b)
    if op == 36:
        return math.sinh(a)
    if op == 37:
        return math.cosh(a)
    if op == 38:
        return math.tanh(a)
    if op == 39:
        return a * (math.pi / 180.0)
    if op == 40:
        return a * (180.0 / math.pi)
    return 0.0


@njit(**JIT)
def vector_math(op, a0, a1, a2, b0, b1, b2, c0, c1, c2, sc):
    """Blender's Vector Math node (``svm_vector_math``): (o0, o1, o2, value); op = ``ops.VMATH_OPS``."""
    o0 = o1 = o2 = 0.0
    val = 0.0
    if op == 0:
        o0, o1, o2 = a0 + b0, a1 + b1, a2 + b2
    elif op == 1:
        o0, o1, o2 = a0 - b0, a1 - b1, a2 - b2
    elif op == 2:
        o0, o1, o2 = a0 * b0, a1 * b1, a2 * b2
    elif op == 3:
        o0, o1, o2 = _safe_div(a0, b0), _safe_div(a1, b1), _safe_div(a2, b2)
    elif op == 4:
        o0, o1, o2 = a0 * b0 + c0, a1 * b1 + c1, a2 * b2 + c2
    elif op == 5:
        o0, o1, o2 = a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0
    elif op == 6:                    # PROJECT a onto b
        bb = b0 * b0 + b1 * b1 + b2 * b2
        k = (a0 * b0 + a1 * b1 + a2 * b2) / bb if bb != 0.0 else 0.0
        o0, o1, o2 = b0 * k, b1 * k, b2 * k
    elif op == 7 or op == 8:         # REFLECT / REFRACT about normalize(b)
        L = math.sqrt(b0 * b0 + b1 * b1 + b2 * b2)
        n0, n1, n2 = (b0 / L, b1 / L, b2 / L) if L > 0.0 else (0.0, 0.0, 0.0)
        d = n0 * a0 + n1 * a1 + n2 * a2
        if op == 7:
            o0, o1, o2 = a0 - 2.0 * d * n0, a1 - 2.0 * d * n1, a2 - 2.0 * d * n2
        else:
            eta = sc
            k = 1.0 - eta * eta * (1.0 - d * d)
            if k >= 0.0:
                f = eta * d + math.sqrt(k)
                o0, o1, o2 = eta * a0 - f * n0, eta * a1 - f * n1, eta * a2 - f * n2
    elif op == 9:                    # FACEFORWARD a, b (incident), c (reference)
        s = 1.0 if (c0 * b0 + c1 * b1 + c2 * b2) < 0.0 else -1.0
        o0, o1, o2 = s * a0, s * a1, s * a2
    elif op == 10:
        val = a0 * b0 + a1 * b1 + a2 * b2
    elif op == 11:
        val = math.sqrt((a0 - b0) ** 2 + (a1 - b1) ** 2 + (a2 - b2) ** 2)
    elif op == 12:
        val = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    elif op == 13:
        o0, o1, o2 = a0 * sc, a1 * sc, a2 * sc
    elif op == 14:
        L = math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        if L > 0.0:
            o0, o1, o2 = a0 / L, a1 / L, a2 / L
    elif op == 15:
        o0, o1, o2 = abs(a0), abs(a1), abs(a2)
    elif op == 16:
        o0, o1, o2 = _safe_pow(a0, b0), _safe_pow(a1, b1), _safe_pow(a2, b2)
    elif op == 17:
        o0, o1, o2 = _sign(a0), _sign(a1), _sign(a2)
    elif op == 18:
        o0, o1, o2 = min(a0, b0), min(a1, b1), min(a2, b2)
    elif op == 19:
        o0, o1, o2 = max(a0, b0), max(a1, b1), max(a2, b2)
    elif op == 20:
        o0, o1, o2 = math.floor(a0), math.floor(a1), math.floor(a2)
    elif op == 21:
        o0, o1, o2 = math.ceil(a0), math.ceil(a1), math.ceil(a2)
    elif op == 22:
        o0, o1, o2 = _fract(a0), _fract(a1), _fract(a2)
    elif op == 23:
        o0, o1, o2 = _fmod(a0, b0), _fmod(a1, b1), _fmod(a2, b2)
    elif op == 24:
        o0, o1, o2 = _wrap(a0, b0, c0), _wrap(a1, b1, c1), _wrap(a2, b2, c2)
    elif op == 25:
        o0, o1, o2 = _snap(a0, b0), _snap(a1, b1), _snap(a2, b2)
    elif op == 26:
        o0, o1, o2 = math.sin(a0), math.sin(a1), math.sin(a2)
    elif op == 27:
        o0, o1, o2 = math.cos(a0), math.cos(a1), math.cos(a2)
    elif op == 28:
        o0, o1, o2 = math.tan(a0), math.tan(a1), math.tan(a2)
    return o0, o1, o2, val


# ----------------------------------------------------------------------------
# Colour nodes
# ----------------------------------------------------------------------------
@njit(**JIT)
def _burn(t, a, b):
    tmp = (1.0 - t) + t * b
    if tmp <= 0.0:
        return 0.0
    v = 1.0 - (1.0 - a) / tmp
    return 0.0 if v < 0.0 else (1.0 if v > 1.0 else v)


@njit(**JIT)
def _dodge(t, a, b):
    if a == 0.0:
        return a
    tmp = 1.0 - t * b
    if tmp <= 0.0:
        return 1.0
    v = a / tmp
    return 1.0 if v > 1.0 else v


@njit(**JIT)
def _overlay(t, a, b):
    tm = 1.0 - t
    if a < 0.5:
        return a * (tm + 2.0 * t * b)
    return 1.0 - (tm + 2.0 * t * (1.0 - b)) * (1.0 - a)


@njit(**JIT)
def mix_color(blend, t, a0, a1, a2, b0, b1, b2):
    """Blender's MixRGB blend modes (``svm_mix``); blend = ``ops.BLEND_MODES`` code, t the factor."""
    tm = 1.0 - t
    if _USE_BLEND_MIX and blend == 0:
        return tm * a0 + t * b0, tm * a1 + t * b1, tm * a2 + t * b2
    if _USE_BLEND_DARKEN and blend == 1:
        return tm * a0 + t * min(a0, b0), tm * a1 + t * min(a1, b1), tm * a2 + t * min(a2, b2)
    if _USE_BLEND_MULTIPLY and blend == 2:
        return a0 * (tm + t * b0), a1 * (tm + t * b1), a2 * (tm + t * b2)
    if _USE_BLEND_BURN and blend == 3:                   # BURN
        return _burn(t, a0, b0), _burn(t, a1, b1), _burn(t, a2, b2)
    if _USE_BLEND_LIGHTEN and blend == 4:
        return tm * a0 + t * max(a0, b0), tm * a1 + t * max(a1, b1), tm * a2 + t * max(a2, b2)
    if _USE_BLEND_SCREEN and blend == 5:                   # SCREEN
        return (1.0 - (tm + t * (1.0 - b0)) * (1.0 - a0), 1.0 - (tm + t * (1.0 - b1)) * (1.0 - a1),
                1.0 - (tm + t * (1.0 - b2)) * (1.0 - a2))
    if _USE_BLEND_DODGE and blend == 6:                   # DODGE
        return _dodge(t, a0, b0), _dodge(t, a1, b1), _dodge(t, a2, b2)
    if _USE_BLEND_ADD and blend == 7:
        return a0 + t * b0, a1 + t * b1, a2 + t * b2
    if _USE_BLEND_OVERLAY and blend == 8:                   # OVERLAY
        return _overlay(t, a0, b0), _overlay(t, a1, b1), _overlay(t, a2, b2)
    if _USE_BLEND_SOFT_LIGHT and blend == 9:                   # SOFT_LIGHT
        s0 = 1.0 - (1.0 - b0) * (1.0 - a0)
        s1 = 1.0 - (1.0 - b1) * (1.0 - a1)
        s2 = 1.0 - (1.0 - b2) * (1.0 - a2)
        return (tm * a0 + t * ((1.0 - a0) * b0 * a0 + a0 * s0), tm * a1 + t * ((1.0 - a1) * b1 * a1 + a1 * s1),
                tm * a2 + t * ((1.0 - a2) * b2 * a2 + a2 * s2))
    if _USE_BLEND_LINEAR_LIGHT and blend == 10:                  # LINEAR_LIGHT
        return a0 + t * (2.0 * b0 - 1.0), a1 + t * (2.0 * b1 - 1.0), a2 + t * (2.0 * b2 - 1.0)
    if _USE_BLEND_DIFFERENCE and blend == 11:
        return tm * a0 + t * abs(a0 - b0), tm * a1 + t * abs(a1 - b1), tm * a2 + t * abs(a2 - b2)
    if _USE_BLEND_EXCLUSION and blend == 12:                  # EXCLUSION
        return (max(tm * a0 + t * (a0 + b0 - 2.0 * a0 * b0), 0.0), max(tm * a1 + t * (a1 + b1 - 2.0 * a1 * b1), 0.0),
                max(tm * a2 + t * (a2 + b2 - 2.0 * a2 * b2), 0.0))
    if _USE_BLEND_SUBTRACT and blend == 13:
        return a0 - t * b0, a1 - t * b1, a2 - t * b2
    if _USE_BLEND_DIVIDE and blend == 14:                  # DIVIDE
        return (tm * a0 + t * a0 / b0 if b0 != 0.0 else a0, tm * a1 + t * a1 / b1 if b1 != 0.0 else a1,
                tm * a2 + t * a2 / b2 if b2 != 0.0 else a2)
    if _USE_BLEND_HUE and blend == 15:                  # HUE
        h2, s2, v2 = rgb_to_hsv(b0, b1, b2)
        if s2 != 0.0:
            h, s, v = rgb_to_hsv(a0, a1, a2)
            r, g, b = hsv_to_rgb(h2, s, v)
            return tm * a0 + t * r, tm * a1 + t * g, tm * a2 + t * b
        return a0, a1, a2
    if _USE_BLEND_SATURATION and blend == 16:                  # SATURATION
        h, s, v = rgb_to_hsv(a0, a1, a2)
        if s != 0.0:
            h2, s2, v2 = rgb_to_hsv(b0, b1, b2)
            return hsv_to_rgb(h, tm * s + t * s2, v)
        return a0, a1, a2
    if _USE_BLEND_COLOR and blend == 17:                  # COLOR
        h2, s2, v2 = rgb_to_hsv(b0, b1, b2)
        if s2 != 0.0:
            h, s, v = rgb_to_hsv(a0, a1, a2)
            r, g, b = hsv_to_rgb(h2, s2, v)
            return tm * a0 + t * r, tm * a1 + t * g, tm * a2 + t * b
        return a0, a1, a2
    if _USE_BLEND_VALUE and blend == 18:                  # VALUE
        h, s, v = rgb_to_hsv(a0, a1, a2)
        h2, s2, v2 = rgb_to_hsv(b0, b1, b2)
        return hsv_to_rgb(h, s, tm * v + t * v2)
    return a0, a1, a2


@njit(**JIT)
def _color_node(op, prog, pc, st, n):
    """INVERT, HSV, BRIGHT_CONTRAST, GAMMA, SEPARATE_COLOR, COMBINE_COLOR."""
    for k in range(n):
        if _USE_INVERT and op == _INVERT:
            f = st[int(prog[pc + 1]), k]
            c0, c1, c2 = _v3(st, int(prog[pc + 2]), k)
            _put3(st, k, int(prog[pc + 3]), (1.0 - f) * c0 + f * (1.0 - c0), (1.0 - f) * c1 + f * (1.0 - c1),
                  (1.0 - f) * c2 + f * (1.0 - c2))
        elif _USE_HSV and op == _HSV:
            hue, sat, val, f = st[int(prog[pc + 1]), k], st[int(prog[pc + 2]), k], st[int(prog[pc + 3]), k], st[int(prog[pc + 4]), k]
            c0, c1, c2 = _v3(st, int(prog[pc + 5]), k)
            h, s, v = rgb_to_hsv(c0, c1, c2)
            h = _fract(h + hue + 0.5)
            s = _clamp01(s * sat)
            v *= val
            r, g, b = hsv_to_rgb(h, s, v)
            _put3(st, k, int(prog[pc + 6]), max(f * r + (1.0 - f) * c0, 0.0), max(f * g + (1.0 - f) * c1, 0.0),
                  max(f * b + (1.0 - f) * c2, 0.0))
        elif _USE_BRIGHT_CONTRAST and op == _BRIGHT_CONTRAST:
            c0, c1, c2 = _v3(st, int(prog[pc + 1]), k)
            bright, contrast = st[int(prog[pc + 2]), k], st[int(prog[pc + 3]), k]
            a = 1.0 + contrast
            b = bright - contrast * 0.5
            _put3(st, k, int(prog[pc + 4]), max(a * c0 + b, 0.0), max(a * c1 + b, 0.0), max(a * c2 + b, 0.0))
        elif _USE_GAMMA and op == _GAMMA:
            c0, c1, c2 = _v3(st, int(prog[pc + 1]), k)
            gm = st[int(prog[pc + 2]), k]
            if gm == 0.0:
                _put3(st, k, int(prog[pc + 3]), 1.0, 1.0, 1.0)
            else:
                _put3(st, k, int(prog[pc + 3]), c0 ** gm if c0 > 0.0 else c0, c1 ** gm if c1 > 0.0 else c1,
                      c2 ** gm if c2 > 0.0 else c2)
        elif _USE_SEPARATE_COLOR and op == _SEPARATE_COLOR:
            mode = int(prog[pc + 1])
            c0, c1, c2 = _v3(st, int(prog[pc + 2]), k)
            if mode == 1:
                c0, c1, c2 = rgb_to_hsv(c0, c1, c2)
            elif mode == 2:
                c0, c1, c2 = rgb_to_hsl(c0, c1, c2)
            _put1(st, k, int(prog[pc + 3]), c0)
            _put1(st, k, int(prog[pc + 4]), c1)
            _put1(st, k, int(prog[pc + 5]), c2)
        elif _USE_COMBINE_COLOR and op == _COMBINE_COLOR:
            mode = int(prog[pc + 1])
            c0, c1, c2 = st[int(prog[pc + 2]), k], st[int(prog[pc + 3]), k], st[int(prog[pc + 4]), k]
            if mode == 1:
                c0, c1, c2 = hsv_to_rgb(c0, c1, c2)
            elif mode == 2:
                c0, c1, c2 = hsl_to_rgb(c0, c1, c2)
            _put3(st, k, int(prog[pc + 5]), c0, c1, c2)


@njit(**JIT)
def _smoothstep(e0, e1, x):
    if x <= e0:
        return 0.0
    if x >= e1:
        return 1.0
    t = (x - e0) / (e1 - e0)
    return t * t * (3.0 - 2.0 * t)


@njit(**JIT)
def _value_node(op, prog, pc, st, n):
    """MATH, MIX_FLOAT, MIX_VECTOR, MIX_COLOR, CLAMP, MAP_RANGE, CONVERT, SEPARATE/COMBINE_XYZ.

    The operands are read from the program once per batch, before the rows' loop: inside it,
    every store to the stack might change a program word as far as the compiler knows (both are
    float64 arrays), so words read there are read and converted again on every row."""
    if _USE_MATH and op == _MATH:
        mop, sa, sb, sc, cl, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), \
            int(prog[pc + 5]), int(prog[pc + 6])
        for k in range(n):
            r = math_op(mop, st[sa, k], st[sb, k], st[sc, k])
            if cl:
                r = _clamp01(r)
            st[out, k] = r
    elif _USE_MIX_FLOAT and op == _MIX_FLOAT:
        sf, sa, sb, cl, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), int(prog[pc + 5])
        for k in range(n):
            t = st[sf, k]
            if cl:
                t = _clamp01(t)
            st[out, k] = (1.0 - t) * st[sa, k] + t * st[sb, k]
    elif _USE_MIX_VECTOR and op == _MIX_VECTOR:
        sf, sa, sb, cl, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), int(prog[pc + 5])
        for k in range(n):
            t = st[sf, k]
            if cl:
                t = _clamp01(t)
            a0, a1, a2 = _v3(st, sa, k)
            b0, b1, b2 = _v3(st, sb, k)
            _put3(st, k, out, (1.0 - t) * a0 + t * b0, (1.0 - t) * a1 + t * b1, (1.0 - t) * a2 + t * b2)
    elif _USE_MIX_COLOR and op == _MIX_COLOR:
        blend, sf, sa, sb, cl, cr, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), \
            int(prog[pc + 5]), int(prog[pc + 6]), int(prog[pc + 7])
        for k in range(n):
            t = st[sf, k]
            if cl:
                t = _clamp01(t)
            a0, a1, a2 = _v3(st, sa, k)
            b0, b1, b2 = _v3(st, sb, k)
            r, g, b = mix_color(blend, t, a0, a1, a2, b0, b1, b2)
            if cr:
                r, g, b = _clamp01(r), _clamp01(g), _clamp01(b)
            _put3(st, k, out, r, g, b)
    elif _USE_CLAMP and op == _CLAMP:
        typ, sv, slo, shi, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), int(prog[pc + 5])
        for k in range(n):
            v, lo, hi = st[sv, k], st[slo, k], st[shi, k]
            if typ == 1 and lo > hi:
                lo, hi = hi, lo
            st[out, k] = min(max(v, lo), hi)
    elif _USE_MAP_RANGE and op == _MAP_RANGE:
        typ, sv, sf0, sf1, st0, st1, ssteps, cl, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), \
            int(prog[pc + 4]), int(prog[pc + 5]), int(prog[pc + 6]), int(prog[pc + 7]), int(prog[pc + 8]), int(prog[pc + 9])
        for k in range(n):
            v, f0, f1 = st[sv, k], st[sf0, k], st[sf1, k]
            t0, t1, steps = st[st0, k], st[st1, k], st[ssteps, k]
            if typ == 0 or typ == 1:
                fac = _safe_div(v - f0, f1 - f0)
                if typ == 1:
                    fac = math.floor(fac * (steps + 1.0)) / steps if steps > 0.0 else 0.0
            elif typ == 2:
                fac = 1.0 - _smoothstep(f1, f0, v) if f0 > f1 else _smoothstep(f0, f1, v)
            else:
                if f0 > f1:
                    x = _clamp01(_safe_div(v - f1, f0 - f1))
                    fac = 1.0 - x * x * x * (x * (x * 6.0 - 15.0) + 10.0)
                else:
                    x = _clamp01(_safe_div(v - f0, f1 - f0))
                    fac = x * x * x * (x * (x * 6.0 - 15.0) + 10.0)
            r = t0 + fac * (t1 - t0) if f1 != f0 else 0.0
            if cl:
                r = min(max(r, t1), t0) if t0 > t1 else min(max(r, t0), t1)
            st[out, k] = r
    elif _USE_CONVERT and op == _CONVERT:
        kind, s, o, w = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4])
        if kind == 0:
            # the working space's luminance weights (a constant)
            for k in range(n):
                st[o, k] = st[w, k] * st[s, k] + st[w + 1, k] * st[s + 1, k] + st[w + 2, k] * st[s + 2, k]
        elif kind == 1:
            for k in range(n):
                st[o, k] = (st[s, k] + st[s + 1, k] + st[s + 2, k]) * (1.0 / 3.0)
        else:
            for k in range(n):
                _put3(st, k, o, st[s, k], st[s, k], st[s, k])
    elif _USE_SEPARATE_XYZ and op == _SEPARATE_XYZ:
        sv, ox, oy, oz = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4])
        for k in range(n):
            x, y, z = _v3(st, sv, k)
            _put1(st, k, ox, x)
            _put1(st, k, oy, y)
            _put1(st, k, oz, z)
    elif _USE_COMBINE_XYZ and op == _COMBINE_XYZ:
        sx, sy, sz, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4])
        for k in range(n):
            _put3(st, k, out, st[sx, k], st[sy, k], st[sz, k])


@njit(**JIT)
def _euler_rows(rx, ry, rz):
    """Rows of R = Rz Ry Rx for Euler XYZ angles (radians)."""
    c1, c2, c3 = math.cos(rx), math.cos(ry), math.cos(rz)
    n1, n2, n3 = math.sin(rx), math.sin(ry), math.sin(rz)
    return (c2 * c3, n1 * n2 * c3 - c1 * n3, c1 * n2 * c3 + n1 * n3,
            c2 * n3, c1 * c3 + n1 * n2 * n3, c1 * n2 * n3 - n1 * c3,
            -n2, c2 * n1, c2 * c1)


@njit(**JIT)
def _mapping(prog, pc, st, n):
    """MAPPING #type, *vector, *location, *rotation (Euler XYZ, radians), *scale, *out.

    POINT: R (v s) + l; TEXTURE: R^T (v - l) / s; VECTOR: R (v s); NORMAL: normalize(R (v / s)).
    The rotation's sines and cosines are recomputed only when a row's angles differ from the
    previous row's (constant rotations: once per batch)."""
    typ, vs, ls, rs, ss, out = (int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]),
                                int(prog[pc + 5]), int(prog[pc + 6]))
    prx = pry = prz = np.nan
    r00 = r01 = r02 = r10 = r11 = r12 = r20 = r21 = r22 = 0.0
    for k in range(n):
        v0, v1, v2 = _v3(st, vs, k)
        l0, l1, l2 = _v3(st, ls, k)
        rx, ry, rz = _v3(st, rs, k)
        s0, s1, s2 = _v3(st, ss, k)
        if not (rx == prx and ry == pry and rz == prz):
            r00, r01, r02, r10, r11, r12, r20, r21, r22 = _euler_rows(rx, ry, rz)
            prx, pry, prz = rx, ry, rz
        if typ == 1:                       # TEXTURE: the inverse of POINT
            x0, x1, x2 = v0 - l0, v1 - l1, v2 - l2
            o0 = _safe_div(r00 * x0 + r10 * x1 + r20 * x2, s0)
            o1 = _safe_div(r01 * x0 + r11 * x1 + r21 * x2, s1)
            o2 = _safe_div(r02 * x0 + r12 * x1 + r22 * x2, s2)
        else:
            if typ == 3:                   # NORMAL: divide by the scale, normalise after
                x0, x1, x2 = _safe_div(v0, s0), _safe_div(v1, s1), _safe_div(v2, s2)
            else:
                x0, x1, x2 = v0 * s0, v1 * s1, v2 * s2
            o0 = r00 * x0 + r01 * x1 + r02 * x2
            o1 = r10 * x0 + r11 * x1 + r12 * x2
            o2 = r20 * x0 + r21 * x1 + r22 * x2
            if typ == 0:
                o0, o1, o2 = o0 + l0, o1 + l1, o2 + l2
            elif typ == 3:
                L = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
                if L > 0.0:
                    o0, o1, o2 = o0 / L, o1 / L, o2 / L
        _put3(st, k, out, o0, o1, o2)


@njit(**JIT)
def _ramp(prog, pc, st, n):
    """RAMP fac, #interp, #n, *color, alpha; then the ramp sampled at n points on [0, 1]
    (``compile.colorband``), read as Cycles' rgb_ramp_lookup: Fac clamped, then the sample below
    it, blended linearly with the next one when interp.  Returns the instruction's length."""
    fs, interp, nt, cs, as_ = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), \
        int(prog[pc + 5])
    tab = pc + 6
    for k in range(n):
        x = _clamp01(st[fs, k]) * (nt - 1)
        i = min(max(int(x), 0), nt - 1)
        t = x - i
        e = tab + 4 * i
        r, g, b, a = prog[e], prog[e + 1], prog[e + 2], prog[e + 3]
        if interp and t > 0.0:
            r = (1.0 - t) * r + t * prog[e + 4]
            g = (1.0 - t) * g + t * prog[e + 5]
            b = (1.0 - t) * b + t * prog[e + 6]
            a = (1.0 - t) * a + t * prog[e + 7]
        _put3(st, k, cs, r, g, b)
        _put1(st, k, as_, a)
    return 6 + 4 * nt


@njit(**JIT)
def _curve(prog, tab, n, f, x0):
    """One channel of RGB Curves: the table tab (n words on [0, 1]) at x0, blended by f."""
    x = _clamp01(x0) * (n - 1)
    i0 = min(int(math.floor(x)), n - 2) if n > 1 else 0
    t = x - i0
    v = prog[tab + i0] if n == 1 else (1.0 - t) * prog[tab + i0] + t * prog[tab + i0 + 1]
    return (1.0 - f) * x0 + f * v


@njit(**JIT)
def _curves(prog, pc, st, n):
    """CURVES fac, *color, #n, *out; then the R, G, B tables (nt each) on [0, 1].  Returns the length."""
    fs, c, nt, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4])
    tab = pc + 5
    for k in range(n):
        f = st[fs, k]
        _put3(st, k, out, _curve(prog, tab, nt, f, st[c, k]), _curve(prog, tab + nt, nt, f, st[c + 1, k]),
              _curve(prog, tab + 2 * nt, nt, f, st[c + 2, k]))
    return 5 + 3 * nt


@njit(**JIT)
def _vector_math(prog, pc, st, n):
    """VECTOR_MATH #op, *a, *b, *c, scale, *out, value over the batch."""
    op, sa, sb, sc_, ss = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), \
        int(prog[pc + 5])
    out, val = int(prog[pc + 6]), int(prog[pc + 7])
    for k in range(n):
        a0, a1, a2 = _v3(st, sa, k)
        b0, b1, b2 = _v3(st, sb, k)
        c0, c1, c2 = _v3(st, sc_, k)
        o0, o1, o2, v = vector_math(op, a0, a1, a2, b0, b1, b2, c0, c1, c2, st[ss, k])
        _put3(st, k, out, o0, o1, o2)
        _put1(st, k, val, v)


@njit(**JIT)
def _checker(x, y, z):
    x = (x + 0.000001) * 0.999999
    y = (y + 0.000001) * 0.999999
    z = (z + 0.000001) * 0.999999
    xi = abs(int(math.floor(x)))
    yi = abs(int(math.floor(y)))
    zi = abs(int(math.floor(z)))
    return 1.0 if ((xi % 2 == yi % 2) == (zi % 2 == 1)) else 0.0


@njit(**JIT)
def gradient(typ, x, y, z):
    """Blender's Gradient Texture (``svm_gradient``)."""
    if typ == 0:
        return x
    if typ == 1:
        r = max(x, 0.0)
        return r * r
    if typ == 2:
        r = min(max(x, 0.0), 1.0)
        t = r * r
        return 3.0 * t - 2.0 * t * r
    if typ == 3:
        return (x + y) * 0.5
    if typ == 6:
        return math.atan2(y, x) / (2.0 * math.pi) + 0.5
    r = max(0.999999 - math.sqrt(x * x + y * y + z * z), 0.0)
    return r * r if typ == 5 else r


# ----------------------------------------------------------------------------
# Geometry
# ----------------------------------------------------------------------------
@njit(**JIT_INLINE)            # called with literal modes: one compile per literal otherwise
def _displacement(mode, r, G, A):
    """The hit moved along one of its surface differentials (mode 1: x, 2: y; Bump's offsets):
    (dbu, dbv, dPo (3), dPw (3)) -- barycentric steps, object- and world-space displacements.

    dPo = eps e, with e = the unit first edge of the triangle (mode 1) or the unit in-plane
    direction perpendicular to it (mode 2), eps = 1e-3 of the first edge's length; dbu, dbv
    solve dPo = dbu (v1 - v0) + dbv (v2 - v0); dPw = M dPo, M = NM^-T the instance's linear part.
    """
    inst, prim, NM = G[4], G[5], G[8]
    inst_mesh, mesh_tri0, co = A[0], A[1], A[4]
    t = mesh_tri0[inst_mesh[inst[r]]] + prim[r]
    x0_, y0_, z0_ = float(co[t, 0, 0]), float(co[t, 0, 1]), float(co[t, 0, 2])
    e10, e11, e12 = float(co[t, 1, 0]) - x0_, float(co[t, 1, 1]) - y0_, float(co[t, 1, 2]) - z0_
    e20, e21, e22 = float(co[t, 2, 0]) - x0_, float(co[t, 2, 1]) - y0_, float(co[t, 2, 2]) - z0_
    L = math.sqrt(e10 * e10 + e11 * e11 + e12 * e12)
    if L == 0.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    eps = 1e-3 * L
    x0, x1, x2 = e10 / L, e11 / L, e12 / L
    if mode == 2:
        n0, n1, n2 = e11 * e22 - e12 * e21, e12 * e20 - e10 * e22, e10 * e21 - e11 * e20
        x0, x1, x2 = _unit(n1 * x2 - n2 * x1, n2 * x0 - n0 * x2, n0 * x1 - n1 * x0)
    d0, d1, d2 = eps * x0, eps * x1, eps * x2
    g11 = e10 * e10 + e11 * e11 + e12 * e12
    g12 = e10 * e20 + e11 * e21 + e12 * e22
    g22 = e20 * e20 + e21 * e21 + e22 * e22
    r1 = e10 * d0 + e11 * d1 + e12 * d2
    r2 = e20 * d0 + e21 * d1 + e22 * d2
    det = g11 * g22 - g12 * g12
    dbu = (g22 * r1 - g12 * r2) / det if det != 0.0 else 0.0
    dbv = (g11 * r2 - g12 * r1) / det if det != 0.0 else 0.0
    j = r if NM.shape[0] > 1 else 0
    w0, w1, w2 = _normal_to_linear(NM, j, d0, d1, d2)
    return dbu, dbv, d0, d1, d2, w0, w1, w2


@njit(**JIT)
def _normal_to_linear(NM, j, x, y, z):
    """M v for M = (NM[j])^-T: the instance's linear part from its normal matrix."""
    a, b, c = NM[j, 0, 0], NM[j, 0, 1], NM[j, 0, 2]
    d, e, f = NM[j, 1, 0], NM[j, 1, 1], NM[j, 1, 2]
    g, h, i = NM[j, 2, 0], NM[j, 2, 1], NM[j, 2, 2]
    # inverse of NM by cofactors; M = inverse^T, so (M v)_k = sum_l inv[l, k] v_l
    A_, B_, C_ = e * i - f * h, -(d * i - f * g), d * h - e * g
    D_, E_, F_ = -(b * i - c * h), a * i - c * g, -(a * h - b * g)
    G_, H_, I_ = b * f - c * e, -(a * f - c * d), a * e - b * d
    det = a * A_ + b * B_ + c * C_
    if det == 0.0:
        return x, y, z
    s = 1.0 / det
    # inv = adj / det with adj[k, l] = cofactor[l, k]; (inv^T v)_k = sum_l inv[l, k] v_l = sum_l cof[k, l] v_l / det
    return (s * (A_ * x + B_ * y + C_ * z), s * (D_ * x + E_ * y + F_ * z), s * (G_ * x + H_ * y + I_ * z))


@njit(**JIT)
def _geometry_node(op, prog, pc, st, n, rows, G, A):
    """TEXCOORD, UVMAP, GEOMETRY (at the hit, or displaced for Bump: ``#offset``), NORMAL_MAP,
    BUMP for the batch's hits rows (n,)."""
    P, NG, NS, D, inst, prim, bu, bv, NM = G
    inst_mesh, mesh_tri0, uv_off, corner_uv, co, gen_lo, gen_inv, cn, tan_off, corner_tan, col_off, corner_col, \
        inst_obj, gen_tri0, corner_gen = A
    if _USE_ATTRIBUTE and op == _ATTRIBUTE:
        _attribute(prog, pc, st, n, rows, G, A)
        return
    if _USE_NORMAL_MAP and op == _NORMAL_MAP:
        _normal_map(prog, pc, st, n, rows, G, A)
        return
    if _USE_BUMP and op == _BUMP:
        _bump(prog, pc, st, n, rows, G, A)
        return
    if op == _UVMAP:
        layer, mode, out = 0 + int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3])
    elif op == _TEXCOORD:
        layer, mode, out = 0, int(prog[pc + 1]), int(prog[pc + 4])
    else:
        layer, mode, out = 0, int(prog[pc + 1]), -1
    # (#offset != 0 only in a Bump node's height inputs: without BUMP no displacement is compiled)
    if (_USE_UVMAP and op == _UVMAP) or (_USE_TEXCOORD_UV and op == _TEXCOORD):
        if out >= 0:
            for k in range(n):
                r = rows[k]
                mesh = inst_mesh[inst[r]]
                off = uv_off[mesh, layer] if layer < uv_off.shape[1] else -1
                if off < 0:
                    _put3(st, k, out, 0.0, 0.0, 0.0)
                    continue
                t = off + prim[r]
                w1, w2 = bu[r], bv[r]
                if _USE_BUMP and mode != 0:
                    dbu, dbv, _, _, _, _, _, _ = _displacement(mode, r, G, A)
                    w1, w2 = w1 + dbu, w2 + dbv
                w0 = 1.0 - w1 - w2
                _put3(st, k, out, w0 * corner_uv[t, 0, 0] + w1 * corner_uv[t, 1, 0] + w2 * corner_uv[t, 2, 0],
                      w0 * corner_uv[t, 0, 1] + w1 * corner_uv[t, 1, 1] + w2 * corner_uv[t, 2, 1], 0.0)
    if _USE_TEXCOORD and op == _TEXCOORD:
        gs, ns_, obs, rfs = int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 5]), int(prog[pc + 6])
        for k in range(n):
            r = rows[k]
            if (_USE_TEXCOORD_GENERATED and gs >= 0) or (_USE_TEXCOORD_OBJECT and obs >= 0):
                mesh = inst_mesh[inst[r]]
                t = mesh_tri0[mesh] + prim[r]
                w1, w2 = bu[r], bv[r]
                w0 = 1.0 - w1 - w2
                p0 = w0 * co[t, 0, 0] + w1 * co[t, 1, 0] + w2 * co[t, 2, 0]
                p1 = w0 * co[t, 0, 1] + w1 * co[t, 1, 1] + w2 * co[t, 2, 1]
                p2 = w0 * co[t, 0, 2] + w1 * co[t, 1, 2] + w2 * co[t, 2, 2]
                d0 = d1 = d2 = 0.0
                if _USE_BUMP and mode != 0:
                    _, _, d0, d1, d2, _, _, _ = _displacement(mode, r, G, A)
                    p0, p1, p2 = p0 + d0, p1 + d1, p2 + d2
                if _USE_TEXCOORD_GENERATED and gs >= 0:
                    q0, q1, q2 = p0, p1, p2
                    if gen_tri0[mesh] >= 0:
                        # the undeformed corners (Mesh.orco): Generated sticks to a deforming surface
                        g = gen_tri0[mesh] + prim[r]
                        q0 = w0 * corner_gen[g, 0, 0] + w1 * corner_gen[g, 1, 0] + w2 * corner_gen[g, 2, 0] + d0
                        q1 = w0 * corner_gen[g, 0, 1] + w1 * corner_gen[g, 1, 1] + w2 * corner_gen[g, 2, 1] + d1
                        q2 = w0 * corner_gen[g, 0, 2] + w1 * corner_gen[g, 1, 2] + w2 * corner_gen[g, 2, 2] + d2
                    _put3(st, k, gs, (q0 - gen_lo[mesh, 0]) * gen_inv[mesh, 0], (q1 - gen_lo[mesh, 1]) * gen_inv[mesh, 1],
                          (q2 - gen_lo[mesh, 2]) * gen_inv[mesh, 2])
                j = inst[r]
                if _USE_TEXCOORD_OBJECT and obs >= 0 and inst_obj[j, 3, 3] != 0.0:
                    # a deforming mesh: Object = world -> object of the hit point at its own time
                    p0 = inst_obj[j, 0, 0] * P[r, 0] + inst_obj[j, 0, 1] * P[r, 1] + inst_obj[j, 0, 2] * P[r, 2] \
                        + inst_obj[j, 0, 3] + d0
                    p1 = inst_obj[j, 1, 0] * P[r, 0] + inst_obj[j, 1, 1] * P[r, 1] + inst_obj[j, 1, 2] * P[r, 2] \
                        + inst_obj[j, 1, 3] + d1
                    p2 = inst_obj[j, 2, 0] * P[r, 0] + inst_obj[j, 2, 1] * P[r, 1] + inst_obj[j, 2, 2] * P[r, 2] \
                        + inst_obj[j, 2, 3] + d2
                if _USE_TEXCOORD_OBJECT:
                    _put3(st, k, obs, p0, p1, p2)
            if _USE_TEXCOORD_NORMAL and ns_ >= 0:
                # Normal: the object-space shading normal, facing the viewer (Cycles' N in object space)
                q = mesh_tri0[inst_mesh[inst[r]]] + prim[r]
                w1, w2 = bu[r], bv[r]
                w0 = 1.0 - w1 - w2
                f = -1.0 if D[r, 0] * NG[r, 0] + D[r, 1] * NG[r, 1] + D[r, 2] * NG[r, 2] > 0.0 else 1.0
                x, y, z = _unit(w0 * cn[q, 0, 0] + w1 * cn[q, 1, 0] + w2 * cn[q, 2, 0],
                                w0 * cn[q, 0, 1] + w1 * cn[q, 1, 1] + w2 * cn[q, 2, 1],
                                w0 * cn[q, 0, 2] + w1 * cn[q, 1, 2] + w2 * cn[q, 2, 2])
                _put3(st, k, ns_, f * x, f * y, f * z)
            if _USE_TEXCOORD_REFLECTION and rfs >= 0:
                s = -1.0 if D[r, 0] * NG[r, 0] + D[r, 1] * NG[r, 1] + D[r, 2] * NG[r, 2] > 0.0 else 1.0
                n0, n1, n2 = s * NS[r, 0], s * NS[r, 1], s * NS[r, 2]
                d = D[r, 0] * n0 + D[r, 1] * n1 + D[r, 2] * n2
                _put3(st, k, rfs, D[r, 0] - 2.0 * d * n0, D[r, 1] - 2.0 * d * n1, D[r, 2] - 2.0 * d * n2)
    elif _USE_GEOMETRY and op == _GEOMETRY:
        for k in range(n):
            r = rows[k]
            back = D[r, 0] * NG[r, 0] + D[r, 1] * NG[r, 1] + D[r, 2] * NG[r, 2] > 0.0
            s = -1.0 if back else 1.0          # Cycles flips N and Ng on back faces
            p0, p1, p2 = P[r, 0], P[r, 1], P[r, 2]
            if _USE_BUMP and mode != 0:
                _, _, _, _, _, w0, w1, w2 = _displacement(mode, r, G, A)
                p0, p1, p2 = p0 + w0, p1 + w1, p2 + w2
            _put3(st, k, int(prog[pc + 2]), p0, p1, p2)
            _put3(st, k, int(prog[pc + 3]), s * NS[r, 0], s * NS[r, 1], s * NS[r, 2])
            _put3(st, k, int(prog[pc + 4]), s * NG[r, 0], s * NG[r, 1], s * NG[r, 2])
            _put3(st, k, int(prog[pc + 5]), -D[r, 0], -D[r, 1], -D[r, 2])
            _put1(st, k, int(prog[pc + 6]), 1.0 if back else 0.0)


@njit(**JIT)
def _attribute(prog, pc, st, n, rows, G, A):
    """ATTRIBUTE: the per-corner RGBA of colour layer ``#layer`` (``shading.scene_attributes``:
    a colour attribute, or a UV map of that name as (u, v, 0, 1)) interpolated with the hit's
    barycentrics (displaced for Bump: ``#offset``); Color, Fac = the RGB average, Alpha.  A mesh
    without that layer reads 0 everywhere (as Cycles reads a missing attribute)."""
    inst, prim, bu, bv = G[4], G[5], G[6], G[7]
    inst_mesh, col_off, corner_col = A[0], A[10], A[11]
    layer, mode = int(prog[pc + 1]), int(prog[pc + 2])
    cs, fs, als = int(prog[pc + 3]), int(prog[pc + 4]), int(prog[pc + 5])
    for k in range(n):
        r = rows[k]
        mesh = inst_mesh[inst[r]]
        off = col_off[mesh, layer] if layer < col_off.shape[1] else -1
        c0 = c1 = c2 = a = 0.0
        if off >= 0:
            t = off + prim[r]
            w1, w2 = bu[r], bv[r]
            if _USE_BUMP and mode != 0:
                dbu, dbv, _, _, _, _, _, _ = _displacement(mode, r, G, A)
                w1, w2 = w1 + dbu, w2 + dbv
            w0 = 1.0 - w1 - w2
            c0 = w0 * corner_col[t, 0, 0] + w1 * corner_col[t, 1, 0] + w2 * corner_col[t, 2, 0]
            c1 = w0 * corner_col[t, 0, 1] + w1 * corner_col[t, 1, 1] + w2 * corner_col[t, 2, 1]
            c2 = w0 * corner_col[t, 0, 2] + w1 * corner_col[t, 1, 2] + w2 * corner_col[t, 2, 2]
            a = w0 * corner_col[t, 0, 3] + w1 * corner_col[t, 1, 3] + w2 * corner_col[t, 2, 3]
        if cs >= 0:
            _put3(st, k, cs, c0, c1, c2)
        if fs >= 0:
            _put1(st, k, fs, (c0 + c1 + c2) * (1.0 / 3.0))
        if als >= 0:
            _put1(st, k, als, a)


@njit(**JIT)
def _bump(prog, pc, st, n, rows, G, A):
    """BUMP #invert, strength, distance, hc, hx, hy, *normal, *out (Cycles' ``svm_node_set_bump``):
    with dPx, dPy the world displacements of the height samples hx, hy (``_displacement``) and N
    the input normal (default: the facing shading normal), Rx = dPy x N, Ry = N x dPx,
    det = dPx . Rx, g = (hx - hc) Rx + (hy - hc) Ry; N' = normalize(|det| N - d sign(det) g)
    (d = distance, negated by invert), then normalize(s N' + (1 - s) N), s = max(strength, 0)."""
    NG, NS, D = G[1], G[2], G[3]
    inv, ss, ds, hc, hx, hy, ns_in, out = (int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]),
                                           int(prog[pc + 4]), int(prog[pc + 5]), int(prog[pc + 6]),
                                           int(prog[pc + 7]), int(prog[pc + 8]))
    for k in range(n):
        r = rows[k]
        if ns_in >= 0:
            N0, N1, N2 = _v3(st, ns_in, k)
        else:
            f = -1.0 if D[r, 0] * NG[r, 0] + D[r, 1] * NG[r, 1] + D[r, 2] * NG[r, 2] > 0.0 else 1.0
            N0, N1, N2 = f * NS[r, 0], f * NS[r, 1], f * NS[r, 2]
        _, _, _, _, _, x0, x1, x2 = _displacement(1, r, G, A)
        _, _, _, _, _, y0, y1, y2 = _displacement(2, r, G, A)
        rx0, rx1, rx2 = y1 * N2 - y2 * N1, y2 * N0 - y0 * N2, y0 * N1 - y1 * N0
        ry0, ry1, ry2 = N1 * x2 - N2 * x1, N2 * x0 - N0 * x2, N0 * x1 - N1 * x0
        det = x0 * rx0 + x1 * rx1 + x2 * rx2
        dx, dy = st[hx, k] - st[hc, k], st[hy, k] - st[hc, k]
        g0, g1, g2 = dx * rx0 + dy * ry0, dx * rx1 + dy * ry1, dx * rx2 + dy * ry2
        dist = -st[ds, k] if inv else st[ds, k]
        sg = 1.0 if det > 0.0 else (-1.0 if det < 0.0 else 0.0)
        a = abs(det)
        o0, o1, o2 = _unit(a * N0 - dist * sg * g0, a * N1 - dist * sg * g1, a * N2 - dist * sg * g2)
        if o0 == 0.0 and o1 == 0.0 and o2 == 0.0:
            o0, o1, o2 = N0, N1, N2
        else:
            s = max(st[ss, k], 0.0)
            o0, o1, o2 = _unit(s * o0 + (1.0 - s) * N0, s * o1 + (1.0 - s) * N1, s * o2 + (1.0 - s) * N2)
        _put3(st, k, out, o0, o1, o2)


@njit(**JIT_INLINE)            # tiny; called with float32 corner data in some paths: inlined, one copy
def _unit(x, y, z):
    L = math.sqrt(x * x + y * y + z * z)
    return (x / L, y / L, z / L) if L > 0.0 else (0.0, 0.0, 0.0)


@njit(**JIT)
def _normal_map(prog, pc, st, n, rows, G, A):
    """NORMAL_MAP #space, #layer, *color, strength, *out (Cycles' ``svm_node_normal_map``).

    c = 2 (color - 1/2).  TANGENT: with the interpolated object-space corner tangent T and sign,
    and the object-space normal N0 (interpolated corner normals; flat faces: the face normal),
    N = normalize(c_x T + c_y sign (N0 x T) + c_z N0), then to world space by the hit's normal
    matrix (NM, (m, 3, 3)).  OBJECT: N = NM c (BLENDER_OBJECT negates c_y, c_z first); WORLD:
    N = c.  Strength s: TANGENT scales c in tangent space first, c_x s, c_y s, 1 + (c_z - 1)
    sat(s) (Cycles, for meshes without displacement); the other spaces blend the result from the
    facing shading normal Nf: normalize(Nf + (N - Nf) max(s, 0)).  Then normalised, negated on
    back faces; zero -> Nf.  Without tangents (no such UV map) TANGENT gives Nf."""
    P, NG, NS, D, inst, prim, bu, bv, NM = G
    inst_mesh, mesh_tri0, uv_off, corner_uv, co, gen_lo, gen_inv, cn, tan_off, corner_tan, col_off, corner_col, \
        inst_obj, gen_tri0, corner_gen = A
    space, layer, cs, ss, out = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]), \
        int(prog[pc + 5])
    for k in range(n):
        r = rows[k]
        back = D[r, 0] * NG[r, 0] + D[r, 1] * NG[r, 1] + D[r, 2] * NG[r, 2] > 0.0
        f = -1.0 if back else 1.0
        nf0, nf1, nf2 = f * NS[r, 0], f * NS[r, 1], f * NS[r, 2]
        c0, c1, c2 = 2.0 * (st[cs, k] - 0.5), 2.0 * (st[cs + 1, k] - 0.5), 2.0 * (st[cs + 2, k] - 0.5)
        m = NM.shape[0] > 1
        j = r if m else 0
        ok = True
        if space == 0:
            mesh = inst_mesh[inst[r]]
            off = tan_off[mesh, layer] if layer < tan_off.shape[1] else -1
            if off < 0:
                ok = False
                x = y = z = 0.0
            else:
                t = off + prim[r]
                w1, w2 = bu[r], bv[r]
                w0 = 1.0 - w1 - w2
                tx = w0 * corner_tan[t, 0, 0] + w1 * corner_tan[t, 1, 0] + w2 * corner_tan[t, 2, 0]
                ty = w0 * corner_tan[t, 0, 1] + w1 * corner_tan[t, 1, 1] + w2 * corner_tan[t, 2, 1]
                tz = w0 * corner_tan[t, 0, 2] + w1 * corner_tan[t, 1, 2] + w2 * corner_tan[t, 2, 2]
                sg = w0 * corner_tan[t, 0, 3] + w1 * corner_tan[t, 1, 3] + w2 * corner_tan[t, 2, 3]
                q = mesh_tri0[mesh] + prim[r]
                a0 = w0 * cn[q, 0, 0] + w1 * cn[q, 1, 0] + w2 * cn[q, 2, 0]
                a1 = w0 * cn[q, 0, 1] + w1 * cn[q, 1, 1] + w2 * cn[q, 2, 1]
                a2 = w0 * cn[q, 0, 2] + w1 * cn[q, 1, 2] + w2 * cn[q, 2, 2]
                b0, b1, b2 = sg * (a1 * tz - a2 * ty), sg * (a2 * tx - a0 * tz), sg * (a0 * ty - a1 * tx)
                # strength in tangent space, as Cycles (meshes without displacement)
                sv = st[ss, k]
                c0, c1 = c0 * sv, c1 * sv
                c2 = 1.0 + (c2 - 1.0) * _clamp01(sv)
                x0, y0, z0 = _unit(c0 * tx + c1 * b0 + c2 * a0, c0 * ty + c1 * b1 + c2 * a1, c0 * tz + c1 * b2 + c2 * a2)
                x = NM[j, 0, 0] * x0 + NM[j, 0, 1] * y0 + NM[j, 0, 2] * z0
                y = NM[j, 1, 0] * x0 + NM[j, 1, 1] * y0 + NM[j, 1, 2] * z0
                z = NM[j, 2, 0] * x0 + NM[j, 2, 1] * y0 + NM[j, 2, 2] * z0
        else:
            if space == 3 or space == 4:
                c1, c2 = -c1, -c2
            if space == 1 or space == 3:
                x = NM[j, 0, 0] * c0 + NM[j, 0, 1] * c1 + NM[j, 0, 2] * c2
                y = NM[j, 1, 0] * c0 + NM[j, 1, 1] * c1 + NM[j, 1, 2] * c2
                z = NM[j, 2, 0] * c0 + NM[j, 2, 1] * c1 + NM[j, 2, 2] * c2
            else:
                x, y, z = c0, c1, c2
        if not ok:
            _put3(st, k, out, nf0, nf1, nf2)
            continue
        x, y, z = _unit(x, y, z)
        if back:
            x, y, z = -x, -y, -z
        sv = st[ss, k]
        if sv != 1.0 and space != 0:
            sv = max(sv, 0.0)
            x, y, z = _unit(nf0 + (x - nf0) * sv, nf1 + (y - nf1) * sv, nf2 + (z - nf2) * sv)
        if x == 0.0 and y == 0.0 and z == 0.0:
            x, y, z = nf0, nf1, nf2
        _put3(st, k, out, x, y, z)


@njit(**JIT)
def _texture_node(op, prog, pc, st, n):
    """TEX_CHECKER, TEX_GRADIENT over the batch (TEX_IMAGE: ``texture.tex_image_rows``, called by
    :func:`_shade` itself)."""
    if _USE_TEX_CHECKER and op == _TEX_CHECKER:
        vs, c1, c2, ss, cs, fs = (int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4]),
                                  int(prog[pc + 5]), int(prog[pc + 6]))
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            sc = st[ss, k]
            f = _checker(x * sc, y * sc, z * sc)
            c = c1 if f == 1.0 else c2
            _put3(st, k, cs, st[c, k], st[c + 1, k], st[c + 2, k])
            _put1(st, k, fs, f)
    elif _USE_TEX_GRADIENT and op == _TEX_GRADIENT:
        typ, vs, cs, fs = int(prog[pc + 1]), int(prog[pc + 2]), int(prog[pc + 3]), int(prog[pc + 4])
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            f = _clamp01(gradient(typ, x, y, z))
            _put3(st, k, cs, f, f, f)
            _put1(st, k, fs, f)


@njit(**JIT)
def _procedural_node(op, prog, pc, st, n):
    """Noise, Voronoi, Wave, Brick, Magic, White Noise over the batch (formulas:
    :mod:`.procedural`, Blender 5.0's)."""
    w_ = lambda j: int(prog[pc + j])                                   # noqa: E731
    if _USE_TEX_NOISE and op == _TEX_NOISE:
        dims, typ, norm, col, vs = w_(1), w_(2), w_(3) != 0, w_(4) != 0, w_(5)
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            f, r, g, b = noise_texture(x, y, z, st[w_(6), k], dims, st[w_(7), k], st[w_(8), k], st[w_(9), k],
                                       st[w_(10), k], st[w_(13), k], norm, typ, st[w_(11), k], st[w_(12), k], col)
            _put1(st, k, w_(14), f)
            _put3(st, k, w_(15), r, g, b)
    elif _USE_TEX_VORONOI and op == _TEX_VORONOI:
        dims, feat, metric, norm, vs = w_(1), w_(2), w_(3), w_(4) != 0, w_(5)
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            d, r, g, b, px, py, pz, wo, rad = voronoi_texture(
                x, y, z, st[w_(6), k], dims, st[w_(7), k], st[w_(8), k], st[w_(9), k], st[w_(10), k], st[w_(11), k],
                st[w_(12), k], st[w_(13), k], feat, metric, norm)
            _put1(st, k, w_(14), d)
            _put3(st, k, w_(15), r, g, b)
            _put3(st, k, w_(16), px, py, pz)
            _put1(st, k, w_(17), wo)
            _put1(st, k, w_(18), rad)
    elif _USE_TEX_WAVE and op == _TEX_WAVE:
        typ, bd, rd, prof, vs = w_(1), w_(2), w_(3), w_(4), w_(5)
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            f, _, _, _ = wave_texture(x, y, z, typ, bd, rd, prof, st[w_(6), k], st[w_(7), k], st[w_(8), k],
                                      st[w_(9), k], st[w_(10), k], st[w_(11), k])
            _put3(st, k, w_(12), f, f, f)
            _put1(st, k, w_(13), f)
    elif _USE_TEX_BRICK and op == _TEX_BRICK:
        off, off_f, sq, sq_f, vs = prog[pc + 1], w_(2), prog[pc + 3], w_(4), w_(5)
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            f, tint = brick_texture(x, y, z, st[w_(9), k], st[w_(10), k], st[w_(11), k], st[w_(12), k],
                                    st[w_(13), k], st[w_(14), k], off, off_f, sq, sq_f)
            c1, c2, m = w_(6), w_(7), w_(8)
            r, g, b = brick_color(f, tint, st[c1, k], st[c1 + 1, k], st[c1 + 2, k], st[c2, k], st[c2 + 1, k],
                                  st[c2 + 2, k], st[m, k], st[m + 1, k], st[m + 2, k])
            _put3(st, k, w_(15), r, g, b)
            _put1(st, k, w_(16), f)
    elif _USE_TEX_MAGIC and op == _TEX_MAGIC:
        depth, vs = w_(1), w_(2)
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            f, r, g, b = magic_texture(x, y, z, depth, st[w_(3), k], st[w_(4), k])
            _put3(st, k, w_(5), r, g, b)
            _put1(st, k, w_(6), f)
    elif _USE_TEX_WHITE_NOISE and op == _TEX_WHITE_NOISE:
        dims, vs = w_(1), w_(2)
        for k in range(n):
            x, y, z = _v3(st, vs, k)
            v, r, g, b = white_noise_texture(x, y, z, st[w_(3), k], dims)
            _put1(st, k, w_(4), v)
            _put3(st, k, w_(5), r, g, b)


# ----------------------------------------------------------------------------
# Closures
# ----------------------------------------------------------------------------
@njit(**JIT_INLINE)            # per hit: inlined into the closure loop (a call there cost ~25 % of it)
def _closure(op, prog, pc, st, k, C, r, w):
    """Write the primary columns of closure row C[r] from a closure instruction (BSDF_*, EMISSION)
    at batch row k, then its derived columns (``closure.finish_closure``).  w: the weight of the
    closure (2^d under d Add Shaders) on its colour, emission and glass tints (C_TINT_T, C_TINT_R)."""
    metallic = transmission = specular = 0.0
    rough = 0.5
    ior = 1.5
    e0 = e1 = e2 = 0.0
    b0 = b1 = b2 = 0.0
    # Blender's Coat: a Principled BSDF's layer over all lobes; without one (Coat Weight 0, other
    # closures) the columns of pack_materials' rows (every column of a program's row is written)
    _no_coat(C, r)
    if _USE_BSDF_PRINCIPLED and op == _BSDF_PRINCIPLED:
        cw = _clamp01(st[int(prog[pc + 11]), k])
        if cw > 0.0:
            C[r, C_CC_WEIGHT] = cw
            C[r, C_CC_ROUGH] = _clamp01(st[int(prog[pc + 12]), k])
            C[r, C_CC_IOR] = min(max(st[int(prog[pc + 13]), k], 1.0), 10.0)
            t0, t1, t2 = _v3(st, int(prog[pc + 14]), k)
            C[r, C_CC_TINT], C[r, C_CC_TINT + 1], C[r, C_CC_TINT + 2] = max(t0, 0.0), max(t1, 0.0), max(t2, 0.0)
            cn = int(prog[pc + 15])
            if cn >= 0:                # a linked Coat Normal (world, as the node outputs it)
                x, y, z = _unit(st[cn, k], st[cn + 1, k], st[cn + 2, k])
                if x != 0.0 or y != 0.0 or z != 0.0:
                    C[r, C_CC_N], C[r, C_CC_N + 1], C[r, C_CC_N + 2] = x, y, z
                    C[r, C_CC_HAS_N] = 1.0
        b0, b1, b2 = _v3(st, int(prog[pc + 1]), k)
        metallic = st[int(prog[pc + 2]), k]
        rough = st[int(prog[pc + 3]), k]
        ior = st[int(prog[pc + 4]), k]
        transmission = st[int(prog[pc + 6]), k]
        specular = min(1.0, 2.0 * st[int(prog[pc + 7]), k])
        s = st[int(prog[pc + 9]), k]
        e0, e1, e2 = _v3(st, int(prog[pc + 8]), k)
        e0, e1, e2 = e0 * s, e1 * s, e2 * s
    elif _USE_BSDF_DIFFUSE and op == _BSDF_DIFFUSE:
        b0, b1, b2 = _v3(st, int(prog[pc + 1]), k)
        rough = 1.0
    elif _USE_BSDF_GLOSSY and op == _BSDF_GLOSSY:
        b0, b1, b2 = _v3(st, int(prog[pc + 1]), k)
        metallic = 1.0
        rough = st[int(prog[pc + 2]), k]
    elif _USE_BSDF_GLASS and op == _BSDF_GLASS:
        b0, b1, b2 = _v3(st, int(prog[pc + 1]), k)
        transmission = 1.0
        rough = st[int(prog[pc + 2]), k]
        ior = st[int(prog[pc + 3]), k]
    elif _USE_EMISSION:                # EMISSION
        rough = 1.0
        s = st[int(prog[pc + 2]), k]
        e0, e1, e2 = _v3(st, int(prog[pc + 1]), k)
        e0, e1, e2 = e0 * s, e1 * s, e2 * s
    b0, b1, b2 = _clamp01(b0), _clamp01(b1), _clamp01(b2)
    _primary(C, r, w * b0, w * b1, w * b2, w * max(e0, 0.0), w * max(e1, 0.0),
             w * max(e2, 0.0), metallic, transmission, rough, specular, ior)
    # Cycles' glass reflection tint (svm/closure.h): a Glass BSDF's colour, a Principled BSDF's
    # specular tint (white: STPM has none); white for the others (they have no glass lobe)
    # (each "_USE_<op> and op == ...": a variant without the opcode drops the test)
    if _USE_BSDF_GLASS and op == _BSDF_GLASS:
        C[r, C_TINT_R], C[r, C_TINT_R + 1], C[r, C_TINT_R + 2] = w * b0, w * b1, w * b2
    else:
        C[r, C_TINT_R] = C[r, C_TINT_R + 1] = C[r, C_TINT_R + 2] = w
    if _USE_BSDF_PRINCIPLED and op == _BSDF_PRINCIPLED:
        # Cycles' Principled BSDF tints its refraction by sqrt(base colour) (svm/closure.h), the
        # Glass BSDF by its colour
        b0, b1, b2 = math.sqrt(b0), math.sqrt(b1), math.sqrt(b2)
    C[r, C_TINT_T] = w * b0
    C[r, C_TINT_T + 1] = w * b1
    C[r, C_TINT_T + 2] = w * b2
    C[r, C_TRANSPARENT] = C[r, C_TRANSPARENT + 1] = C[r, C_TRANSPARENT + 2] = 0.0
    C[r, C_PASS] = 0.0
    # Cycles 5.0's Glossy BSDF has no Fresnel: its colour at every angle (Principled: Schlick)
    C[r, C_METAL_CONST] = 1.0 if (_USE_BSDF_GLOSSY and op == _BSDF_GLOSSY) else 0.0


@njit(**JIT_INLINE)            # (inlined: no call left in the closure loop)
def _transparent(C, r, t0, t1, t2):
    """Closure row C[r] := a transparent closure of tint (t0, t1, t2) (a Transparent BSDF, or the
    white one a Principled BSDF's Alpha mixes in): nothing scatters, C_PASS = 1."""
    _no_coat(C, r)
    _primary(C, r, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 1.5)
    C[r, C_TINT_T] = C[r, C_TINT_T + 1] = C[r, C_TINT_T + 2] = 0.0
    C[r, C_TINT_R] = C[r, C_TINT_R + 1] = C[r, C_TINT_R + 2] = 0.0
    C[r, C_TRANSPARENT] = max(t0, 0.0)
    C[r, C_TRANSPARENT + 1] = max(t1, 0.0)
    C[r, C_TRANSPARENT + 2] = max(t2, 0.0)
    C[r, C_PASS] = 1.0
    C[r, C_METAL_CONST] = 0.0


@njit(**JIT_INLINE)            # (inlined with _closure, _transparent)
def _no_coat(C, r):
    """Closure row C[r]'s coat-layer columns as ``closure.pack_materials`` writes them: no coat."""
    C[r, C_CC_WEIGHT] = 0.0
    C[r, C_CC_ROUGH] = 0.0
    C[r, C_CC_IOR] = 1.5
    C[r, C_CC_TINT] = C[r, C_CC_TINT + 1] = C[r, C_CC_TINT + 2] = 1.0
    C[r, C_CC_N] = C[r, C_CC_N + 1] = C[r, C_CC_N + 2] = 0.0
    C[r, C_CC_HAS_N] = 0.0


@njit(**JIT_INLINE)            # (inlined with _closure, _transparent)
def _primary(C, r, b0, b1, b2, e0, e1, e2, metallic, transmission, rough, specular, ior):
    """Closure row C[r]'s primary columns (colour, emission >= 0, the rest clamped to their ranges)
    and its derived columns."""
    C[r, C_BASE] = b0
    C[r, C_BASE + 1] = b1
    C[r, C_BASE + 2] = b2
    C[r, C_EMIT] = e0
    C[r, C_EMIT + 1] = e1
    C[r, C_EMIT + 2] = e2
    C[r, C_METALLIC] = _clamp01(metallic)
    C[r, C_TRANSMISSION] = _clamp01(transmission)
    C[r, C_ROUGHNESS] = _clamp01(rough)
    C[r, C_SPECULAR] = _clamp01(specular)
    C[r, C_IOR] = min(max(ior, 1.0), 10.0)
    finish_closure_at(C, r)


# ----------------------------------------------------------------------------
# The interpreter
# ----------------------------------------------------------------------------
@njit(**JIT)
def _constants(prog, start, st, n):
    """The program's constants into slots 0 .. n_const - 1 of the first n columns of st.  No
    instruction writes these slots: a material's batches fill them once (:func:`shade_closures`)."""
    n_const = int(prog[start + 1])
    for j in range(n_const):
        v = prog[start + 3 + j]
        for k in range(n):
            st[j, k] = v


@njit(**JIT)
def _closures(prog, start, closure_at, st, rows, C, NG, NS, D, seed, U, closures, cr):
    """The closure section of a batch (:func:`_shade`): each hit rows[k] walks it to one closure (NG, NS,
    D: the hits' normals and directions, for a Normal input)."""
    n = rows.shape[0]
    for k in range(n):
        r = rows[k]
        if cr >= 0:
            for c in range(C_PROGRAM, C_BUMPED + 1):
                C[r, c] = closures[cr, c]
        u = -1.0                       # the hit's uniform, drawn at its first choice (U[r] or hash_uniform)
        q = closure_at
        w = 1.0
        while True:
            op = int(prog[q])
            if _USE_MIX_SHADER and op == _MIX_SHADER:
                if u < 0.0:
                    u = U[r] if U.shape[0] > 0 else hash_uniform(seed, r)
                f = _clamp01(st[int(prog[q + 1]), k])
                if u < f:
                    u = u / f
                    q = start + int(prog[q + 2])
                else:
                    u = (u - f) / (1.0 - f)
                    q += 3
                continue
            if _USE_ADD_SHADER and op == _ADD_SHADER:
                if u < 0.0:
                    u = U[r] if U.shape[0] > 0 else hash_uniform(seed, r)
                w *= 2.0
                if u < 0.5:
                    u = 2.0 * u
                    q += 2
                else:
                    u = 2.0 * u - 1.0
                    q = start + int(prog[q + 1])
                continue
            if _USE_TRANSPARENT and op == _TRANSPARENT:
                t0, t1, t2 = _v3(st, int(prog[q + 1]), k)
                _transparent(C, r, w * t0, w * t1, w * t2)
                break
            if _USE_ALPHA and op == _BSDF_PRINCIPLED:
                a = _clamp01(st[int(prog[q + 5]), k])
                if a < 1.0:
                    # Alpha: Cycles' mix of a Transparent BSDF (1 - alpha) and the BSDF (alpha)
                    if u < 0.0:
                        u = U[r] if U.shape[0] > 0 else hash_uniform(seed, r)
                    if u >= a:
                        _transparent(C, r, w, w, w)
                        break
                    u = u / a
            if op >= _BSDF_PRINCIPLED and op <= _EMISSION:
                _closure(op, prog, q, st, k, C, r, w)
                if _USE_SET_NORMAL:
                    ns = -1
                    if op == _BSDF_PRINCIPLED:
                        ns = int(prog[q + 10])
                    elif op != _EMISSION:
                        ns = int(prog[q + (op - _BSDF_DIFFUSE) + 2])      # DIFFUSE +2, GLOSSY +3, GLASS +4
                    if ns >= 0:
                        _set_normal(NG, NS, D, C, r, st[ns, k], st[ns + 1, k], st[ns + 2, k])
            elif cr >= 0:
                # not a closure instruction (the compiler ends every branch with one): the
                # material's constant row, as before the program ran
                for c in range(C.shape[1]):
                    C[r, c] = closures[cr, c]
            break


@njit(**JIT)
def _set_normal(NG, NS, D, C, r, x, y, z):
    """Hit r's shading normal := the shader's Normal input (world, facing the viewer as Cycles' N),
    stored on the geometric normal's side as the hit arrays keep it; the smooth normal it replaces
    goes to the closure's C_NS columns (C_BUMPED = 1) for the BSDF's bump shadowing term."""
    x, y, z = _unit(x, y, z)
    if x == 0.0 and y == 0.0 and z == 0.0:
        return
    if D[r, 0] * NG[r, 0] + D[r, 1] * NG[r, 1] + D[r, 2] * NG[r, 2] > 0.0:
        x, y, z = -x, -y, -z
    C[r, C_NS], C[r, C_NS + 1], C[r, C_NS + 2] = NS[r, 0], NS[r, 1], NS[r, 2]
    C[r, C_BUMPED] = 1.0
    NS[r, 0], NS[r, 1], NS[r, 2] = x, y, z


# _closures copies the columns C_PROGRAM .. C_BUMPED of the constant row as one run
assert C_NS == C_PROGRAM + 1 and C_BUMPED == C_NS + 3

BATCH = 256          # hits interpreted together (the stack of a batch stays in the CPU's cache)


def _entry(ops):
    """The compiled interpreter for programs using only the opcode names ops (None: any opcode):
    :func:`.svm_variants.interpreter`."""
    if ops is None:
        return _shade
    from .svm_variants import interpreter
    return interpreter(ops)


def shade_closures(mat, closures, prog, n_slots, G, A, X, seed, C, U=None, ops=None) -> None:
    """C[r] = the closure of hit r (m,) on material mat[r] (-1 = miss: the inert row).

    closures (M + 1, N_CLOSURE) from ``closure.pack_materials``: the constant rows, with
    C_PROGRAM >= 0 where the material has a node program in prog; n_slots the largest slot count
    of any program; G, A, X as in the module docstring; seed: the bounce's Mix Shader seed; U
    (m,) float64 or None: hit r's Mix Shader / Alpha uniform (``hash_uniform(seed, r)`` if None).
    Hits are grouped by material (stable order) and each material's program runs over batches of
    up to ``BATCH`` of its hits.  (A Python function: the compiled entry is :func:`_shade`, one
    level for both entries, since every compiled level re-optimises and re-emits all it calls.)
    ops: the names of the opcodes the programs use (``ShadingData.ops``): the interpreter compiled
    for those only (:mod:`.svm_variants`); None: every opcode's.
    """
    _entry(ops)(mat, closures, prog, n_slots, G, A, X, seed, _NO_U if U is None else U, C, _NO_ROWS, False)


def shade_closure_rows(mat, closures, prog, n_slots, G, A, X, seed, C, crow, U=None, ops=None) -> None:
    """:func:`shade_closures` with the closure of hit r in row crow[r] of C (m + M + 1, N_CLOSURE):
    the hits on materials with a program get their own row r, the others (constant materials,
    misses) row m + their material's row, where the material table is copied.  A 280-byte row
    is copied for no hit that has none of its own (a miss, a flat material): 8 bytes of crow
    instead (:func:`shade_rows`)."""
    _entry(ops)(mat, closures, prog, n_slots, G, A, X, seed, _NO_U if U is None else U, C, crow, True)


_NO_ROWS = np.empty(0, np.int64)
_NO_U = np.empty(0, np.float64)


@njit(**JIT)
def _shade(mat, closures, prog, n_slots, G, A, X, seed, U, C, crow, compact):
    """:func:`shade_closures` (compact False) and :func:`shade_closure_rows` (compact True).

    Rows on materials with a program are not copied from the constant row first: the program
    writes every column of them, so each such row is written once."""
    m = mat.shape[0]
    nc = closures.shape[0]
    nw = closures.shape[1]
    key = np.empty(m, np.int64)
    count = np.zeros(nc + 1, np.int64)
    if compact:
        for c in range(nc):
            for k in range(nw):
                C[m + c, k] = closures[c, k]
    for r in range(m):
        cr = closure_row(closures, mat[r])
        if closures[cr, C_PROGRAM] >= 0.0:
            key[r] = cr
            if compact:
                crow[r] = r
        else:
            key[r] = -1
            if compact:
                crow[r] = m + cr
            else:
                for k in range(nw):
                    C[r, k] = closures[cr, k]
        count[key[r] + 1] += 1
    # rows grouped by material, in row order within a material (a counting sort)
    first = np.empty(nc + 1, np.int64)
    acc = 0
    for c in range(nc + 1):
        first[c] = acc
        acc += count[c]
    fill = first.copy()
    order = np.empty(m, np.int64)
    for r in range(m):
        order[fill[key[r] + 1]] = r
        fill[key[r] + 1] += 1
    st = np.empty((max(n_slots, 1), BATCH))
    for cr in range(nc):
        i, j = first[cr + 1], first[cr + 1] + count[cr + 1]
        if j > i:
            start = int(closures[cr, C_PROGRAM])
            _constants(prog, start, st, min(BATCH, j - i))      # once per material: no slot overwrites them
            for b in range(i, j, BATCH):
                # The program at word start for the batch's hits rows (n,) into their closure rows
                # of C, the constants in st already.  The value section runs instruction by
                # instruction over the whole batch; then each hit walks the closure section to one
                # closure (_closures), its Mix Shader choices drawn from U[row] (U (m,): the camera
                # paths' per-pixel stratified uniforms), or hash_uniform(seed, row) when U is empty
                # (rescaled at each choice, so nested mixes stay independent).  Each hit's row first
                # gets the columns no closure instruction writes (C_PROGRAM, C_NS, C_BUMPED) from
                # row cr of closures (the material's constant row), so the row is whole without a
                # copy of it.  (Written here rather than in a function of its own that _shade
                # inlines: numba's IR inlining copies a callee's IR block by block, a cost that
                # grows as blocks x variables.)
                rows = order[b:min(b + BATCH, j)]
                n = rows.shape[0]
                n_const = int(prog[start + 1])
                closure_at = start + int(prog[start + 2])
                pc = start + 3 + n_const
                while pc < closure_at:
                    op = int(prog[pc])
                    # (each test is "_USE_<op> and op == _<op>": a variant without the opcode has no branch for it)
                    if (_USE_MATH and op == _MATH) or (_USE_MIX_FLOAT and op == _MIX_FLOAT) \
                            or (_USE_MIX_VECTOR and op == _MIX_VECTOR) or (_USE_MIX_COLOR and op == _MIX_COLOR) \
                            or (_USE_CLAMP and op == _CLAMP) or (_USE_MAP_RANGE and op == _MAP_RANGE) \
                            or (_USE_CONVERT and op == _CONVERT) or (_USE_SEPARATE_XYZ and op == _SEPARATE_XYZ) \
                            or (_USE_COMBINE_XYZ and op == _COMBINE_XYZ):
                        _value_node(op, prog, pc, st, n)
                    elif _USE_VECTOR_MATH and op == _VECTOR_MATH:
                        _vector_math(prog, pc, st, n)
                    elif (_USE_INVERT or _USE_HSV or _USE_BRIGHT_CONTRAST or _USE_GAMMA or _USE_SEPARATE_COLOR
                          or _USE_COMBINE_COLOR) and op >= _INVERT and op <= _COMBINE_COLOR:
                        _color_node(op, prog, pc, st, n)
                    elif (_USE_TEXCOORD and op == _TEXCOORD) or (_USE_UVMAP and op == _UVMAP) \
                            or (_USE_GEOMETRY and op == _GEOMETRY) or (_USE_NORMAL_MAP and op == _NORMAL_MAP) \
                            or (_USE_BUMP and op == _BUMP) or (_USE_ATTRIBUTE and op == _ATTRIBUTE):
                        _geometry_node(op, prog, pc, st, n, rows, G, A)
                    elif _USE_MAPPING and op == _MAPPING:
                        _mapping(prog, pc, st, n)
                    elif _USE_TEX_IMAGE and op == _TEX_IMAGE:
                        # (called from here, not from _texture_node: one compiled level less above it)
                        tex_image_rows(X[0], X[1], X[2], X[3], X[4], int(prog[pc + 1]), int(prog[pc + 2]),
                                       int(prog[pc + 3]), int(prog[pc + 4]) != 0, st, int(prog[pc + 5]),
                                       int(prog[pc + 6]), int(prog[pc + 7]), n, prog, pc + 9, int(prog[pc + 8]))
                        pc += _LEN[op] + 2 * int(prog[pc + 8])      # then the UDIM tile table
                        continue
                    elif (_USE_TEX_CHECKER and op == _TEX_CHECKER) or (_USE_TEX_GRADIENT and op == _TEX_GRADIENT):
                        _texture_node(op, prog, pc, st, n)
                    elif (_USE_TEX_NOISE or _USE_TEX_VORONOI or _USE_TEX_WAVE or _USE_TEX_BRICK or _USE_TEX_MAGIC
                          or _USE_TEX_WHITE_NOISE) and op >= _TEX_NOISE and op <= _TEX_WHITE_NOISE:
                        _procedural_node(op, prog, pc, st, n)
                    elif _USE_RAMP and op == _RAMP:
                        pc += _ramp(prog, pc, st, n)
                        continue
                    elif _USE_CURVES and op == _CURVES:
                        pc += _curves(prog, pc, st, n)
                        continue
                    pc += _LEN[op]
                _closures(prog, start, closure_at, st, rows, C, G[1], G[2], G[3], seed, U, closures, cr)


@njit(**JIT)
def constant_closures(mat, closures, C):
    """C[r] = the constant closure row of hit r's material (scenes without node programs: the
    interpreter is then neither compiled nor run)."""
    for r in range(mat.shape[0]):
        cr = closure_row(closures, mat[r])
        for k in range(closures.shape[1]):
            C[r, k] = closures[cr, k]


def shade(sd, mat, G, seed, C, U=None) -> None:
    """The closures C (m, N_CLOSURE) of hits with materials mat (m,) and geometry G for a
    ``shading.ShadingData`` sd: :func:`shade_closures` when the scene has node programs, else
    :func:`constant_closures`; U (m,) or None: the hits' Mix Shader uniforms (:func:`shade_closures`)."""
    if sd.uses_programs:
        shade_closures(mat, sd.closures, sd.prog, sd.n_slots, G, sd.A, sd.X, seed, C, U, ops=sd.ops)
    else:
        constant_closures(mat, sd.closures, C)


@njit(**JIT)
def closure_rows(mat, closures, crow):
    """crow[r] = the row of ``closures`` (M + 1, N_CLOSURE) that is hit r's constant closure (a miss,
    material -1: the inert last row)."""
    for r in range(mat.shape[0]):
        crow[r] = closure_row(closures, mat[r])


@njit(**JIT)
def _identity_rows(crow):
    for r in range(crow.shape[0]):
        crow[r] = r


def shade_rows(sd, mat, G, seed, C, crow, U=None) -> np.ndarray:
    """The closures of hits with materials mat (m,) and geometry G for a ``shading.ShadingData`` sd,
    as rows of an array: returns the array and fills crow (m,) int64 with the row of each hit.

    Without node programs every hit's closure is its material's constant row: the array is the
    material table ``sd.closures`` itself and crow the material rows (:func:`closure_rows`), 8
    bytes per hit instead of a copied N_CLOSURE row of 280 (a tile of 65k hits would write and
    then read 18 MB of copies, several times what the caches hold).  With node programs, C
    (m, N_CLOSURE) receives one row per hit (:func:`shade`) and crow[r] = r.  The camera-path
    kernels (``kernels.paths``) read hit r's closure as row crow[r].

    With node programs and room for the material table after the hits' rows (C of at least
    m + M + 1 rows), only the hits on materials with a program get a row of their own, the
    others point into that copy of the table (:func:`shade_closure_rows`); the returned array is
    C.  Transparent materials need a row per hit (``transparency.pass_through`` rewrites them):
    then C[:m] is filled and returned, crow[r] = r.  U (m,) float64 or None: hit r's uniform for
    its Mix Shader and Alpha choices (camera paths: each pixel's stratified, ``integrator``), else
    ``hash_uniform(seed, r)``."""
    m = mat.shape[0]
    if sd.transparent or (sd.uses_programs and C.shape[0] < m + sd.closures.shape[0]):
        C = C[:m]
        shade(sd, mat, G, seed, C, U)
        _identity_rows(crow)
        return C
    if sd.uses_programs:
        shade_closure_rows(mat, sd.closures, sd.prog, sd.n_slots, G, sd.A, sd.X, seed, C, crow, U, ops=sd.ops)
        return C
    closure_rows(mat, sd.closures, crow)
    return sd.closures


def max_slots(prog: np.ndarray, starts) -> int:
    """The largest slot count of the programs starting at ``starts``."""
    return max([int(prog[s]) for s in starts] + [1])


def _lengths() -> np.ndarray:
    from ..nodes.ops import LAYOUT
    out = np.zeros(len(LAYOUT), np.int64)
    for name, ops in LAYOUT.items():
        out[OP[name]] = 1 + len(ops)
    return out


_LEN = _lengths()          # words per instruction (RAMP / CURVES add their tables, TEX_IMAGE its tiles)
