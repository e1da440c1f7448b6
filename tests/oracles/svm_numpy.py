"""Independent evaluator of a shader-node graph at one hit: the oracle for :mod:`stpm_core.kernels.svm`.

Walks a :class:`stpm_core.nodes.graph.ShaderGraph` recursively from its Surface link and evaluates
every node in float64 from the formulas of Blender's Cycles (``intern/cycles/kernel/svm/*.h``,
``util/color.h``, ``util/math_base.h``, ``util/math_float3.h``, ``util/transform.h``), as read in
Cycles' source -- not from the project's compiler or interpreter (only the graph data classes are
imported).  The file / function each formula follows is named next to it.

Link conversions are Blender's: colour -> float is the Rec.709 luminance (0.2126, 0.7152,
0.0722), vector -> float the average, float -> colour / vector the value in every channel.
Output socket types are Blender's (``SOCKET_TYPES``; the graph's ``outputs`` declaration is only
a fallback for types not listed).

What the project defines itself (not Blender), kept to the project's documented rules:

* the closure of a shader node (``addon/export/materials.py``): Principled -> base colour, metallic,
  roughness, transmission, ior, specular = min(1, 2 Specular IOR Level), emission = Emission Color
  x Strength; Diffuse -> roughness 1; Glossy -> metallic 1; Glass -> transmission 1; Emission ->
  black base, roughness 1; an unconnected shader socket -> black; an unknown shader -> grey
  diffuse; the closure row keeps base in [0, 1], emission >= 0, metallic, transmission, roughness,
  specular in [0, 1], ior in [1, 10] (:func:`closure_row`); its transmission tint (``tint_t``) is
  Cycles' (svm/closure.h): sqrt(base) for a Principled BSDF, the (clamped) colour otherwise; its
  reflection tint (``tint_r``) too: the (clamped) colour for a Glass BSDF, a Principled BSDF's
  specular tint (white: the project has none), white for closures without a glass lobe;
* a node the interpreter does not evaluate gives the consuming socket its default
  (:data:`UNSUPPORTED` lists what the oracle treats so);
* Mix Shader: :func:`evaluate` returns every leaf closure with its weight (Cycles' closure weights,
  ``svm_node_mix_closure``: ``(1 - saturate(Fac), saturate(Fac))`` per level).

Colour Ramp: Cycles does not evaluate the colour band per hit; Blender's sync
(``intern/cycles/blender/util.h``, ``colorramp_to_array``) samples ``BKE_colorband_evaluate`` at
``i / 256`` (i = 0 .. 256) and the kernel (``svm/ramp.h``, ``rgb_ramp_lookup``) reads that table,
with a lerp unless the interpolation is Constant.  ``ramp="cycles"`` (default) evaluates that;
``ramp="colorband"`` evaluates ``BKE_colorband_evaluate`` itself (exact band, no table).

Image Texture: :func:`texture_numpy.sample` (RGBA images held with associated alpha, as Cycles
loads them); the colour is un-associated when the node's Alpha output is linked to a node that
reaches the output (``ImageTextureNode::compile`` after ``ShaderGraph::clean``; Cycles' constant
folding, which can drop a link such as ``Alpha x 0``, is not modelled: tests avoid foldable
consumers).  No image: ``IMAGE_MISSING_RGBA`` (1, 0, 1, 1).  A UDIM image (``props["tiles"]``):
:func:`texture_numpy.sample_udim`.

Working space (``evaluate(..., working=...)``): colour -> float conversions (linked colour into a
value socket, RGB to BW) weigh by the working space's luminance (Cycles' ``rgb_to_y``, the Y row of
its RGB -> XYZ matrix; ``stpm_core.colorspaces.luma``, checked against OpenColorIO there), and
images whose primaries differ are converted per texel (:func:`texture_numpy.sample` ``working``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from stpm_core import colorspaces
from stpm_core.nodes.graph import Link, ShaderGraph

from . import texture_numpy

__all__ = ["Hit", "hit_from_scene", "evaluate", "evaluate_value", "closure_row", "LUMA", "FLT_EPSILON",
           "SOCKET_TYPES", "DEFAULTS", "UNSUPPORTED", "colorband_evaluate", "ramp_cycles", "rgb_to_hsv",
           "hsv_to_rgb", "rgb_to_hsl", "hsl_to_rgb", "math_op", "vector_math", "mix_blend", "mapping",
           "gradient", "checker", "Closure"]

LUMA = np.array([0.2126, 0.7152, 0.0722])
FLT_EPSILON = float(np.finfo(np.float32).eps)
RAMP_TABLE_SIZE = 256                       # kernel/types.h; the table has RAMP_TABLE_SIZE + 1 entries

# Blender's output socket types (VALUE / RGBA / VECTOR / SHADER) by node type and output identifier
SOCKET_TYPES = {
    "ShaderNodeTexCoord": {k: "VECTOR" for k in ("Generated", "Normal", "UV", "Object", "Camera", "Window",
                                                 "Reflection")},
    "ShaderNodeUVMap": {"UV": "VECTOR"},
    "ShaderNodeAttribute": {"Color": "RGBA", "Vector": "VECTOR", "Fac": "VALUE", "Alpha": "VALUE"},
    "ShaderNodeVertexColor": {"Color": "RGBA", "Alpha": "VALUE"},
    "ShaderNodeNewGeometry": {"Position": "VECTOR", "Normal": "VECTOR", "Tangent": "VECTOR", "True Normal": "VECTOR",
                              "Incoming": "VECTOR", "Parametric": "VECTOR", "Backfacing": "VALUE",
                              "Pointiness": "VALUE", "Random Per Island": "VALUE"},
    "ShaderNodeMapping": {"Vector": "VECTOR"},
    "ShaderNodeFresnel": {"Fac": "VALUE"},
    "ShaderNodeLayerWeight": {"Fresnel": "VALUE", "Facing": "VALUE"},
    "ShaderNodeMath": {"Value": "VALUE"},
    "ShaderNodeVectorMath": {"Vector": "VECTOR", "Value": "VALUE"},
    "ShaderNodeMix": {"Result_Float": "VALUE", "Result_Vector": "VECTOR", "Result_Color": "RGBA"},
    "ShaderNodeMixRGB": {"Color": "RGBA"},
    "ShaderNodeInvert": {"Color": "RGBA"},
    "ShaderNodeHueSaturation": {"Color": "RGBA"},
    "ShaderNodeBrightContrast": {"Color": "RGBA"},
    "ShaderNodeGamma": {"Color": "RGBA"},
    "ShaderNodeSeparateColor": {"Red": "VALUE", "Green": "VALUE", "Blue": "VALUE"},
    "ShaderNodeCombineColor": {"Color": "RGBA"},
    "ShaderNodeSeparateRGB": {"R": "VALUE", "G": "VALUE", "B": "VALUE"},
    "ShaderNodeCombineRGB": {"Image": "RGBA"},
    "ShaderNodeSeparateXYZ": {"X": "VALUE", "Y": "VALUE", "Z": "VALUE"},
    "ShaderNodeCombineXYZ": {"Vector": "VECTOR"},
    "ShaderNodeRGBToBW": {"Val": "VALUE"},
    "ShaderNodeClamp": {"Result": "VALUE"},
    "ShaderNodeMapRange": {"Result": "VALUE"},
    "ShaderNodeValToRGB": {"Color": "RGBA", "Alpha": "VALUE"},
    "ShaderNodeRGBCurve": {"Color": "RGBA"},
    "ShaderNodeTexImage": {"Color": "RGBA", "Alpha": "VALUE"},
    "ShaderNodeTexChecker": {"Color": "RGBA", "Fac": "VALUE"},
    "ShaderNodeTexGradient": {"Color": "RGBA", "Fac": "VALUE"},
    "ShaderNodeValue": {"Value": "VALUE"},
    "ShaderNodeRGB": {"Color": "RGBA"},
}

# Blender's socket default values (node_shader_*.cc declarations) of the inputs read here
_G3 = (0.8, 0.8, 0.8)
DEFAULTS = {
    "ShaderNodeMapping": {"Vector": (0, 0, 0), "Location": (0, 0, 0), "Rotation": (0, 0, 0), "Scale": (1, 1, 1)},
    "ShaderNodeMath": {"Value": 0.5, "Value_001": 0.5, "Value_002": 0.5},
    "ShaderNodeFresnel": {"IOR": 1.5},
    "ShaderNodeLayerWeight": {"Blend": 0.5},
    "ShaderNodeVectorMath": {"Vector": (0, 0, 0), "Vector_001": (0, 0, 0), "Vector_002": (0, 0, 0), "Scale": 1.0},
    "ShaderNodeMix": {"Factor_Float": 0.5, "A_Float": 0.0, "B_Float": 0.0, "A_Vector": (0, 0, 0),
                      "B_Vector": (0, 0, 0), "A_Color": (0.5, 0.5, 0.5), "B_Color": (0.5, 0.5, 0.5)},
    "ShaderNodeMixRGB": {"Fac": 0.5, "Color1": (0.5, 0.5, 0.5), "Color2": (0.5, 0.5, 0.5)},
    "ShaderNodeInvert": {"Fac": 1.0, "Color": (0, 0, 0)},
    "ShaderNodeHueSaturation": {"Hue": 0.5, "Saturation": 1.0, "Value": 1.0, "Fac": 1.0, "Color": _G3},
    "ShaderNodeBrightContrast": {"Color": (1, 1, 1), "Bright": 0.0, "Contrast": 0.0},
    "ShaderNodeGamma": {"Color": (1, 1, 1), "Gamma": 1.0},
    "ShaderNodeSeparateColor": {"Color": _G3},
    "ShaderNodeCombineColor": {"Red": 0.0, "Green": 0.0, "Blue": 0.0},
    "ShaderNodeSeparateRGB": {"Image": _G3},
    "ShaderNodeCombineRGB": {"R": 0.0, "G": 0.0, "B": 0.0},
    "ShaderNodeSeparateXYZ": {"Vector": (0, 0, 0)},
    "ShaderNodeCombineXYZ": {"X": 0.0, "Y": 0.0, "Z": 0.0},
    "ShaderNodeRGBToBW": {"Color": (0.5, 0.5, 0.5)},
    "ShaderNodeClamp": {"Value": 1.0, "Min": 0.0, "Max": 1.0},
    "ShaderNodeMapRange": {"Value": 1.0, "From Min": 0.0, "From Max": 1.0, "To Min": 0.0, "To Max": 1.0,
                           "Steps": 4.0},
    "ShaderNodeValToRGB": {"Fac": 0.5},
    "ShaderNodeRGBCurve": {"Fac": 1.0, "Color": (1, 1, 1)},
    "ShaderNodeTexChecker": {"Color1": _G3, "Color2": (0.2, 0.2, 0.2), "Scale": 5.0},
    "ShaderNodeBsdfPrincipled": {"Base Color": _G3, "Metallic": 0.0, "Roughness": 0.5, "IOR": 1.5, "Alpha": 1.0,
                                 "Transmission Weight": 0.0, "Specular IOR Level": 0.5,
                                 "Emission Color": (1, 1, 1), "Emission Strength": 0.0},
    "ShaderNodeBsdfDiffuse": {"Color": _G3},
    "ShaderNodeBsdfGlossy": {"Color": _G3, "Roughness": 0.5},
    "ShaderNodeBsdfAnisotropic": {"Color": _G3, "Roughness": 0.5},
    "ShaderNodeBsdfGlass": {"Color": (1, 1, 1), "Roughness": 0.0, "IOR": 1.5},
    "ShaderNodeEmission": {"Color": (1, 1, 1), "Strength": 1.0},
    "ShaderNodeMixShader": {"Fac": 0.5},
}

# Node types whose value the project's interpreter does not evaluate (the consumer reads its default)
UNSUPPORTED = ("ShaderNodeTexNoise", "ShaderNodeTexVoronoi", "ShaderNodeTexWave", "ShaderNodeTexMagic",
               "ShaderNodeTexBrick", "ShaderNodeBump", "ShaderNodeNormalMap",
               "ShaderNodeFresnel", "ShaderNodeLayerWeight", "ShaderNodeLightPath", "ShaderNodeBlackbody",
               "ShaderNodeWavelength", "ShaderNodeObjectInfo")


# ----------------------------------------------------------------------------
# Hit geometry
# ----------------------------------------------------------------------------
@dataclass
class Hit:
    """One shading point.  P world position; N shading and Ng geometric normal (as the hit reports
    them: flipped toward the viewer here when D . Ng > 0, as Cycles' shader_setup_from_ray does);
    D the ray direction (wi = -D); uv: UV map name -> (u, v) ("" = the render-active map);
    p_obj object-space position; generated: Blender's Generated coordinate."""

    P: np.ndarray
    N: np.ndarray
    Ng: np.ndarray
    D: np.ndarray
    uv: dict = field(default_factory=dict)
    p_obj: np.ndarray = field(default_factory=lambda: np.zeros(3))
    generated: np.ndarray = field(default_factory=lambda: np.zeros(3))
    colors: dict = field(default_factory=dict)     # colour attribute name -> (4,) RGBA ("" = render-active)

    @property
    def backfacing(self) -> bool:
        return float(np.dot(self.D, self.Ng_in)) > 0.0

    def __post_init__(self):
        self.P, self.D = np.asarray(self.P, float), np.asarray(self.D, float)
        self.Ng_in = np.asarray(self.Ng, float)
        s = -1.0 if float(np.dot(self.D, self.Ng_in)) > 0.0 else 1.0
        self.N = s * np.asarray(self.N, float)
        self.Ng = s * self.Ng_in


def _texspace(V: np.ndarray):
    """Blender's automatic mesh texture space (BKE_mesh_texspace_calc): centre and half-size of the
    bounding box; a zero half-size becomes 1, a tiny one 1e-5."""
    lo, hi = V.min(axis=0).astype(np.float64), V.max(axis=0).astype(np.float64)
    loc, size = 0.5 * (lo + hi), 0.5 * (hi - lo)
    size = np.where(size == 0.0, 1.0, np.where(size < 1e-5, 1e-5, size))
    return loc, size


def hit_from_scene(scene, inst: int, prim: int, bu: float, bv: float, P, NG, NS, D) -> Hit:
    """The :class:`Hit` on triangle ``prim`` of instance ``inst`` at barycentrics (bu, bv)
    (point = (1 - bu - bv) v0 + bu v1 + bv v2), from the scene's own arrays (float32 as stored)."""
    mesh = scene.meshes[scene.instances[inst].mesh]
    V = np.asarray(mesh.vertices, np.float32)
    if V.ndim == 3:
        V = V[0]
    tri = np.asarray(mesh.triangles, np.int64)[prim]
    w = np.array([1.0 - bu - bv, bu, bv])
    corners = V[tri].astype(np.float64)
    p_obj = w @ corners
    loc, size = _texspace(V)
    generated = (p_obj - loc) / size * 0.5 + 0.5
    uv = {}
    layers = getattr(mesh, "uv_layers", None) or {}
    for name, arr in layers.items():
        c = np.asarray(arr, np.float32).reshape(-1, 3, 2)[prim].astype(np.float64)
        uv[name] = w @ c
    active = mesh.uv_render if mesh.uv_render in layers else next(iter(layers), None)
    if active is not None:
        uv[""] = uv[active]
    colors = {}
    for name, arr in (getattr(mesh, "color_layers", None) or {}).items():
        colors[name] = w @ np.asarray(arr, np.float32).reshape(-1, 3, 4)[prim].astype(np.float64)
    if getattr(mesh, "color_render", None) in colors:
        colors[""] = colors[mesh.color_render]
    return Hit(P=P, N=NS, Ng=NG, D=D, uv=uv, p_obj=p_obj, generated=generated, colors=colors)


# ----------------------------------------------------------------------------
# Scalar helpers (util/math_base.h)
# ----------------------------------------------------------------------------
def _safe_divide(a, b):
    return a / b if b != 0.0 else 0.0


def _safe_powf(a, b):
    if a < 0.0 and b != float(int(b)):
        return 0.0
    try:
        return math.pow(a, b)
    except (ValueError, ZeroDivisionError):           # C powf(0, b < 0) = +inf (-inf for -0 and odd b)
        neg = math.copysign(1.0, a) < 0.0 and float(b).is_integer() and int(b) % 2 == 1
        return -math.inf if neg else math.inf
    except OverflowError:
        return math.inf if (a > 0.0 or (float(b).is_integer() and int(b) % 2 == 0)) else -math.inf


def _safe_logf(a, b):
    if a <= 0.0 or b <= 0.0:
        return 0.0
    return _safe_divide(math.log(a), math.log(b))


def _safe_modulo(a, b):
    return math.fmod(a, b) if b != 0.0 else 0.0


def _safe_floored_modulo(a, b):
    return a - math.floor(a / b) * b if b != 0.0 else 0.0


def _wrapf(value, vmax, vmin):
    rng = vmax - vmin
    return value - rng * math.floor((value - vmin) / rng) if rng != 0.0 else vmin


def _fractf(x):
    return x - math.floor(x)


def _pingpongf(a, b):
    return abs(_fractf((a - b) / (b * 2.0)) * b * 2.0 - b) if b != 0.0 else 0.0


def _smoothminf(a, b, k):
    if k != 0.0:
        h = max(k - abs(a - b), 0.0) / k
        return min(a, b) - h * h * h * k * (1.0 / 6.0)
    return min(a, b)


def _compatible_signf(f):
    if f == 0.0:
        return 0.0
    return -1.0 if f < 0.0 else 1.0


def _compatible_atan2(y, x):
    return 0.0 if (x == 0.0 and y == 0.0) else math.atan2(y, x)


def _saturate(x):
    return min(max(x, 0.0), 1.0)


def _exp(a):
    try:
        return math.exp(a)
    except OverflowError:
        return math.inf


def _hyp(f, a):
    try:
        return f(a)
    except OverflowError:
        return math.copysign(math.inf, a) if f is math.sinh else math.inf


def math_op(op: str, a: float, b: float, c: float) -> float:
    """Cycles' ``svm_math`` (kernel/svm/math_util.h) for Blender's operation name."""
    a, b, c = float(a), float(b), float(c)
    f = {
        "ADD": lambda: a + b, "SUBTRACT": lambda: a - b, "MULTIPLY": lambda: a * b,
        "DIVIDE": lambda: _safe_divide(a, b), "POWER": lambda: _safe_powf(a, b),
        "LOGARITHM": lambda: _safe_logf(a, b), "SQRT": lambda: math.sqrt(max(a, 0.0)),
        "INVERSE_SQRT": lambda: 1.0 / math.sqrt(a) if a > 0.0 else 0.0, "ABSOLUTE": lambda: abs(a),
        "RADIANS": lambda: a * (math.pi / 180.0), "DEGREES": lambda: a * (180.0 / math.pi),
        "MINIMUM": lambda: min(a, b), "MAXIMUM": lambda: max(a, b),
        "LESS_THAN": lambda: 1.0 if a < b else 0.0, "GREATER_THAN": lambda: 1.0 if a > b else 0.0,
        "ROUND": lambda: math.floor(a + 0.5), "FLOOR": lambda: math.floor(a), "CEIL": lambda: math.ceil(a),
        "FRACT": lambda: a - math.floor(a), "MODULO": lambda: _safe_modulo(a, b),
        "FLOORED_MODULO": lambda: _safe_floored_modulo(a, b),
        "TRUNC": lambda: math.floor(a) if a >= 0.0 else math.ceil(a),
        "SNAP": lambda: math.floor(_safe_divide(a, b)) * b, "WRAP": lambda: _wrapf(a, b, c),
        "PINGPONG": lambda: _pingpongf(a, b), "SINE": lambda: math.sin(a), "COSINE": lambda: math.cos(a),
        "TANGENT": lambda: math.tan(a), "SINH": lambda: _hyp(math.sinh, a), "COSH": lambda: _hyp(math.cosh, a),
        "TANH": lambda: math.tanh(a), "ARCSINE": lambda: math.asin(min(max(a, -1.0), 1.0)),
        "ARCCOSINE": lambda: math.acos(min(max(a, -1.0), 1.0)), "ARCTANGENT": lambda: math.atan(a),
        "ARCTAN2": lambda: _compatible_atan2(a, b), "SIGN": lambda: _compatible_signf(a),
        "EXPONENT": lambda: _exp(a),
        "COMPARE": lambda: 1.0 if (a == b or abs(a - b) <= max(c, FLT_EPSILON)) else 0.0,
        "MULTIPLY_ADD": lambda: a * b + c, "SMOOTH_MIN": lambda: _smoothminf(a, b, c),
        "SMOOTH_MAX": lambda: -_smoothminf(-a, -b, c),
    }[op]
    return float(f())


def _v(x) -> np.ndarray:
    return np.asarray(x, np.float64).reshape(3)


def _safe_normalize(a):
    t = math.sqrt(float(np.dot(a, a)))
    return a * (1.0 / t) if t != 0.0 else a


def vector_math(op: str, a, b, c, scale: float):
    """(vector, value) of Cycles' ``svm_vector_math`` (kernel/svm/math_util.h, util/math_float3.h)."""
    a, b, c = _v(a), _v(b), _v(c)
    vec, val = np.zeros(3), 0.0
    per = lambda f, *xs: np.array([f(*(x[i] for x in xs)) for i in range(3)])   # noqa: E731
    if op == "ADD":
        vec = a + b
    elif op == "SUBTRACT":
        vec = a - b
    elif op == "MULTIPLY":
        vec = a * b
    elif op == "DIVIDE":
        vec = per(_safe_divide, a, b)
    elif op == "MULTIPLY_ADD":
        vec = a * b + c
    elif op == "CROSS_PRODUCT":
        vec = np.cross(a, b)
    elif op == "PROJECT":                    # project(v, v_proj)
        ls = float(np.dot(b, b))
        vec = (float(np.dot(a, b)) / ls) * b if ls != 0.0 else np.zeros(3)
    elif op == "REFLECT":                    # reflect(a, safe_normalize(b))
        n = _safe_normalize(b)
        vec = a - 2.0 * n * float(np.dot(a, n))
    elif op == "REFRACT":                    # refract(a, safe_normalize(b), eta = Scale)
        n = _safe_normalize(b)
        d = float(np.dot(n, a))
        k = 1.0 - scale * scale * (1.0 - d * d)
        vec = np.zeros(3) if k < 0.0 else scale * a - (scale * d + math.sqrt(k)) * n
    elif op == "FACEFORWARD":                # faceforward(vector, incident, reference)
        vec = a if float(np.dot(c, b)) < 0.0 else -a
    elif op == "DOT_PRODUCT":
        val = float(np.dot(a, b))
    elif op == "DISTANCE":
        val = math.sqrt(float(np.dot(a - b, a - b)))
    elif op == "LENGTH":
        val = math.sqrt(float(np.dot(a, a)))
    elif op == "SCALE":
        vec = a * scale
    elif op == "NORMALIZE":
        vec = _safe_normalize(a)
    elif op == "ABSOLUTE":
        vec = np.abs(a)
    elif op == "POWER":                      # safe_pow per component
        vec = per(_safe_powf, a, b)
    elif op == "SIGN":                       # compatible_sign
        vec = per(_compatible_signf, a)
    elif op == "MINIMUM":
        vec = per(min, a, b)
    elif op == "MAXIMUM":
        vec = per(max, a, b)
    elif op == "FLOOR":
        vec = np.floor(a)
    elif op == "CEIL":
        vec = np.ceil(a)
    elif op == "FRACTION":
        vec = a - np.floor(a)
    elif op == "MODULO":                     # safe_fmod
        vec = per(_safe_modulo, a, b)
    elif op == "WRAP":                       # wrap(value, max, min) = safe_floored_fmod(v - min, max - min) + min
        vec = per(lambda v, hi, lo: _safe_floored_modulo(v - lo, hi - lo) + lo, a, b, c)
    elif op == "SNAP":
        vec = np.floor(np.array(per(_safe_divide, a, b))) * b
    elif op == "SINE":
        vec = np.sin(a)
    elif op == "COSINE":
        vec = np.cos(a)
    elif op == "TANGENT":
        vec = np.tan(a)
    elif op == "ROUND":
        vec = np.floor(a + 0.5)
    else:
        raise KeyError(op)
    return np.asarray(vec, np.float64), float(val)


# ----------------------------------------------------------------------------
# Colour (util/color.h, kernel/svm/color_util.h)
# ----------------------------------------------------------------------------
def rgb_to_hsv(rgb) -> np.ndarray:
    r, g, b = (float(x) for x in rgb)
    cmax, cmin = max(r, max(g, b)), min(r, min(g, b))
    cdelta = cmax - cmin
    v = cmax
    s = cdelta / cmax if cmax != 0.0 else 0.0
    h = 0.0
    if s != 0.0:
        cr, cg, cb = (cmax - r) / cdelta, (cmax - g) / cdelta, (cmax - b) / cdelta
        if r == cmax:
            h = cb - cg
        elif g == cmax:
            h = 2.0 + cr - cb
        else:
            h = 4.0 + cg - cr
        h /= 6.0
        if h < 0.0:
            h += 1.0
    return np.array([h, s, v])


def hsv_to_rgb(hsv) -> np.ndarray:
    h, s, v = (float(x) for x in hsv)
    if s == 0.0:
        return np.array([v, v, v])
    if h == 1.0:
        h = 0.0
    h *= 6.0
    i = math.floor(h)
    f = h - i
    p, q, t = v * (1.0 - s), v * (1.0 - s * f), v * (1.0 - s * (1.0 - f))
    return np.array({0: (v, t, p), 1: (q, v, p), 2: (p, v, t), 3: (p, q, v), 4: (t, p, v)}.get(i, (v, p, q)))


def rgb_to_hsl(rgb) -> np.ndarray:
    r, g, b = (float(x) for x in rgb)
    cmax, cmin = max(r, max(g, b)), min(r, min(g, b))
    lum = min(1.0, (cmax + cmin) / 2.0)
    if cmax == cmin:
        h = s = 0.0
    else:
        d = cmax - cmin
        s = d / (2.0 - cmax - cmin) if lum > 0.5 else d / (cmax + cmin)
        if cmax == r:
            h = (g - b) / d + (6.0 if g < b else 0.0)
        elif cmax == g:
            h = (b - r) / d + 2.0
        else:
            h = (r - g) / d + 4.0
    return np.array([h / 6.0, s, lum])


def hsl_to_rgb(hsl) -> np.ndarray:
    h, s, lum = (float(x) for x in hsl)
    nr = min(max(abs(h * 6.0 - 3.0) - 1.0, 0.0), 1.0)
    ng = min(max(2.0 - abs(h * 6.0 - 2.0), 0.0), 1.0)
    nb = min(max(2.0 - abs(h * 6.0 - 4.0), 0.0), 1.0)
    chroma = (1.0 - abs(2.0 * lum - 1.0)) * s
    return np.array([(nr - 0.5) * chroma + lum, (ng - 0.5) * chroma + lum, (nb - 0.5) * chroma + lum])


def _interp(a, b, t):
    return a + t * (b - a)


def _dodge(t, c1, c2):
    out = c1.copy()
    for k in range(3):
        if out[k] != 0.0:
            tmp = 1.0 - t * c2[k]
            if tmp <= 0.0:
                out[k] = 1.0
            else:
                tmp = out[k] / tmp
                out[k] = 1.0 if tmp > 1.0 else tmp
    return out


def _burn(t, c1, c2):
    out = c1.copy()
    tm = 1.0 - t
    for k in range(3):
        tmp = tm + t * c2[k]
        if tmp <= 0.0:
            out[k] = 0.0
        else:
            tmp = 1.0 - (1.0 - out[k]) / tmp
            out[k] = 0.0 if tmp < 0.0 else (1.0 if tmp > 1.0 else tmp)
    return out


def _overlay(t, c1, c2):
    tm = 1.0 - t
    out = c1.copy()
    for k in range(3):
        if out[k] < 0.5:
            out[k] *= tm + 2.0 * t * c2[k]
        else:
            out[k] = 1.0 - (tm + 2.0 * t * (1.0 - c2[k])) * (1.0 - out[k])
    return out


def _div(t, c1, c2):
    tm = 1.0 - t
    out = c1.copy()
    for k in range(3):
        if c2[k] != 0.0:
            out[k] = tm * out[k] + t * out[k] / c2[k]
    return out


def mix_blend(blend: str, t: float, c1, c2) -> np.ndarray:
    """Cycles' ``svm_mix`` (kernel/svm/color_util.h) for Blender's blend_type name."""
    c1, c2 = _v(c1), _v(c2)
    one = np.ones(3)
    tm = 1.0 - t
    if blend == "MIX":
        return _interp(c1, c2, t)
    if blend == "ADD":
        return _interp(c1, c1 + c2, t)
    if blend == "MULTIPLY":
        return _interp(c1, c1 * c2, t)
    if blend == "SCREEN":
        return one - (tm + t * (one - c2)) * (one - c1)
    if blend == "OVERLAY":
        return _overlay(t, c1, c2)
    if blend == "SUBTRACT":
        return _interp(c1, c1 - c2, t)
    if blend == "DIVIDE":
        return _div(t, c1, c2)
    if blend == "DIFFERENCE":
        return _interp(c1, np.abs(c1 - c2), t)
    if blend == "EXCLUSION":
        return np.maximum(_interp(c1, c1 + c2 - 2.0 * c1 * c2, t), 0.0)
    if blend == "DARKEN":
        return _interp(c1, np.minimum(c1, c2), t)
    if blend == "LIGHTEN":
        return _interp(c1, np.maximum(c1, c2), t)
    if blend == "DODGE":
        return _dodge(t, c1, c2)
    if blend == "BURN":
        return _burn(t, c1, c2)
    if blend == "HUE":
        hsv2 = rgb_to_hsv(c2)
        if hsv2[1] != 0.0:
            hsv = rgb_to_hsv(c1)
            hsv[0] = hsv2[0]
            return _interp(c1, hsv_to_rgb(hsv), t)
        return c1
    if blend == "SATURATION":
        hsv = rgb_to_hsv(c1)
        if hsv[1] != 0.0:
            hsv2 = rgb_to_hsv(c2)
            hsv[1] = tm * hsv[1] + t * hsv2[1]
            return hsv_to_rgb(hsv)
        return c1
    if blend == "VALUE":
        hsv, hsv2 = rgb_to_hsv(c1), rgb_to_hsv(c2)
        hsv[2] = tm * hsv[2] + t * hsv2[2]
        return hsv_to_rgb(hsv)
    if blend == "COLOR":
        hsv2 = rgb_to_hsv(c2)
        if hsv2[1] != 0.0:
            hsv = rgb_to_hsv(c1)
            hsv[0], hsv[1] = hsv2[0], hsv2[1]
            return _interp(c1, hsv_to_rgb(hsv), t)
        return c1
    if blend == "SOFT_LIGHT":
        scr = one - (one - c2) * (one - c1)
        return tm * c1 + t * ((one - c1) * c2 * c1 + c1 * scr)
    if blend == "LINEAR_LIGHT":
        return c1 + t * (2.0 * c2 - 1.0)
    raise KeyError(blend)


# ----------------------------------------------------------------------------
# Mapping (kernel/svm/mapping_util.h, util/transform.h euler_to_transform)
# ----------------------------------------------------------------------------
def _euler(rot) -> np.ndarray:
    cx, cy, cz = (math.cos(r) for r in rot)
    sx, sy, sz = (math.sin(r) for r in rot)
    return np.array([[cy * cz, sy * sx * cz - cx * sz, sy * cx * cz + sx * sz],
                     [cy * sz, sy * sx * sz + cx * cz, sy * cx * sz - sx * cz],
                     [-sy, cy * sx, cy * cx]])


def mapping(vtype: str, vector, location, rotation, scale) -> np.ndarray:
    v, loc, sc = _v(vector), _v(location), _v(scale)
    R = _euler(_v(rotation))
    div = lambda a, b: np.array([_safe_divide(a[i], b[i]) for i in range(3)])   # noqa: E731
    if vtype == "POINT":
        return R @ (v * sc) + loc
    if vtype == "TEXTURE":
        return div(R.T @ (v - loc), sc)
    if vtype == "VECTOR":
        return R @ (v * sc)
    if vtype == "NORMAL":
        return _safe_normalize(R @ div(v, sc))
    return np.zeros(3)


# ----------------------------------------------------------------------------
# Textures (kernel/svm/checker.h, gradient.h)
# ----------------------------------------------------------------------------
def checker(p) -> float:
    p = (_v(p) + 0.000001) * 0.999999
    xi, yi, zi = (abs(int(math.floor(x))) for x in p)
    return 1.0 if ((xi % 2 == yi % 2) == (zi % 2 == 1)) else 0.0


def gradient(gtype: str, p) -> float:
    """svm_gradient (unclamped; the node saturates)."""
    x, y, z = (float(c) for c in _v(p))
    if gtype == "LINEAR":
        return x
    if gtype == "QUADRATIC":
        r = max(x, 0.0)
        return r * r
    if gtype == "EASING":
        r = min(max(x, 0.0), 1.0)
        t = r * r
        return 3.0 * t - 2.0 * t * r
    if gtype == "DIAGONAL":
        return (x + y) * 0.5
    if gtype == "RADIAL":
        return math.atan2(y, x) / (2.0 * math.pi) + 0.5
    r = max(0.999999 - math.sqrt(x * x + y * y + z * z), 0.0)
    if gtype == "QUADRATIC_SPHERE":
        return r * r
    if gtype == "SPHERICAL":
        return r
    return 0.0


# ----------------------------------------------------------------------------
# Colour ramp (blenkernel/intern/colorband.cc BKE_colorband_evaluate; svm/ramp.h)
# ----------------------------------------------------------------------------
def colorband_evaluate(elements, interpolation: str, f: float) -> np.ndarray:
    """RGBA of Blender's colour band (RGB colour mode) at f; elements [(pos, rgba)] sorted by pos."""
    els = [(float(p), np.asarray(tuple(c) + (1.0,) * (4 - len(c)), np.float64)[:4]) for p, c in elements]
    if interpolation not in ("CONSTANT", "LINEAR", "EASE"):
        raise NotImplementedError(interpolation)
    if len(els) == 1 or f <= els[0][0]:
        return els[0][1].copy()
    a = 0
    while a < len(els) and not (els[a][0] > f):
        a += 1
    if a == len(els):
        return els[-1][1].copy()                  # after the last stop
    right, left = els[a], els[a - 1]
    if interpolation == "CONSTANT":
        return left[1].copy()
    fac = (f - right[0]) / (left[0] - right[0]) if left[0] != right[0] else 0.0   # weight of the left stop
    if interpolation == "EASE":
        fac2 = fac * fac
        fac = 3.0 * fac2 - 2.0 * fac2 * fac
    return (1.0 - fac) * right[1] + fac * left[1]


_RAMP_TABLES: dict = {}


def ramp_cycles(elements, interpolation: str, f: float) -> np.ndarray:
    """What Cycles renders: the colour band sampled at i / 256 (colorramp_to_array), read by
    rgb_ramp_lookup (no extrapolation; a lerp unless Constant)."""
    key = (tuple((float(p), tuple(float(x) for x in c)) for p, c in elements), interpolation)
    table = _RAMP_TABLES.get(key)
    if table is None:
        n = RAMP_TABLE_SIZE + 1
        table = np.array([colorband_evaluate(elements, interpolation, i / RAMP_TABLE_SIZE) for i in range(n)])
        _RAMP_TABLES[key] = table
    return _table_lookup(table, f, interpolation != "CONSTANT")


def _table_lookup(table, f, interpolate=True):
    n = table.shape[0]
    f = _saturate(f) * (n - 1)
    i = min(max(int(f), 0), n - 1)
    t = f - i
    a = table[i].copy()
    if interpolate and t > 0.0:
        a = (1.0 - t) * a + t * table[i + 1]
    return a


# ----------------------------------------------------------------------------
# Closures
# ----------------------------------------------------------------------------
@dataclass
class Closure:
    """A closure's primary values (raw, before the closure row's ranges)."""

    base: np.ndarray
    emission: np.ndarray = field(default_factory=lambda: np.zeros(3))
    metallic: float = 0.0
    transmission: float = 0.0
    roughness: float = 0.5
    specular: float = 0.0
    ior: float = 1.5
    kind: str = "diffuse"
    transparent: np.ndarray = field(default_factory=lambda: np.zeros(3))   # kind "transparent": the tint


def closure_row(c: Closure) -> dict:
    """The closure row's primary columns for c: base [0, 1], emission >= 0, metallic,
    transmission, roughness, specular [0, 1], ior [1, 10]; tint_t the transmission tint
    (Principled: sqrt(base), Transparent: 0, else base); tint_r the reflection tint (Glass: base,
    Transparent: 0, else white)."""
    base = np.clip(c.base, 0.0, 1.0)
    if c.kind == "principled":
        tint = np.sqrt(base)                     # Cycles: transmission_tint = sqrt(base_color)
    elif c.kind == "transparent":
        tint = np.zeros(3)
    else:
        tint = base
    if c.kind == "glass":
        tint_r = base                            # Cycles: a Glass BSDF's reflection_tint = color
    elif c.kind == "transparent":
        tint_r = np.zeros(3)
    else:
        tint_r = np.ones(3)                      # Principled: specular_tint (white); others: no glass lobe
    return {"base": base, "tint_t": tint, "tint_r": tint_r, "emission": np.maximum(c.emission, 0.0),
            "metallic": _saturate(c.metallic), "transmission": _saturate(c.transmission),
            "roughness": _saturate(c.roughness), "specular": _saturate(c.specular),
            "ior": min(max(c.ior, 1.0), 10.0), "transparent": np.maximum(c.transparent, 0.0),
            "pass": 1.0 if c.kind == "transparent" else 0.0}


# ----------------------------------------------------------------------------
# The evaluator
# ----------------------------------------------------------------------------
class _Eval:
    def __init__(self, graph: ShaderGraph, hit: Hit, textures, ramp: str, srgb: str = "cycles", roots=(),
                 working: str = "REC709"):
        self.g = graph
        self.working = working                        # the working space (its luma, its image conversions)
        self.luma = np.asarray(colorspaces.luma(working))
        self.hit = hit
        self.textures = list(textures or [])
        self.ramp = ramp
        self.srgb = srgb
        self.roots = [graph.surface, *roots]
        self.memo: dict = {}
        self.unsupported: list = []
        self.busy: set = set()
        self._used: set | None = None

    def used_nodes(self) -> set:
        """Names of the nodes that reach the output (ShaderGraph::clean disconnects the others)."""
        if self._used is None:
            used, todo = set(), [r.node for r in self.roots if isinstance(r, Link)]
            while todo:
                name = todo.pop()
                node = self.g.nodes.get(name)
                if name in used or node is None:
                    continue
                used.add(name)
                todo.extend(v.node for v in node.inputs.values() if isinstance(v, Link))
            self._used = used
        return self._used

    def output_linked(self, node, socket: str) -> bool:
        """Output ``socket`` of ``node`` feeds a node that reaches the output."""
        names = [k for k, n in self.g.nodes.items() if n is node]
        return any(isinstance(v, Link) and v.node in names and v.socket == socket
                   for u in self.used_nodes() for v in self.g.nodes[u].inputs.values())

    # -- inputs ---------------------------------------------------------------------------
    def out_type(self, node_name: str, socket: str) -> str:
        node = self.g.nodes[node_name]
        t = SOCKET_TYPES.get(node.type, {}).get(socket)
        return t or node.outputs.get(socket, "RGBA")

    def default(self, node, ident: str, kind: str):
        v = node.inputs.get(ident)
        if v is None or isinstance(v, Link):
            v = DEFAULTS.get(node.type, {}).get(ident, (0.0, 0.0, 0.0) if kind == "v" else 0.0)
        return self.convert_const(v, kind)

    @staticmethod
    def convert_const(v, kind):
        if kind == "v":
            return np.full(3, float(v)) if isinstance(v, (int, float)) else np.asarray(tuple(v)[:3], np.float64)
        return float(np.mean(tuple(v)[:3])) if isinstance(v, (tuple, list, np.ndarray)) else float(v)

    def inp(self, node, ident: str, kind: str, implicit=None):
        """Input ``ident`` of ``node`` as kind 'f' (float) or 'v' (3-vector)."""
        v = node.inputs.get(ident)
        if isinstance(v, Link):
            got = self.value(v)
            if got is None:
                return self.default(node, ident, kind)
            src = self.out_type(v.node, v.socket)
            if kind == "f":
                if isinstance(got, np.ndarray):
                    return float(np.dot(self.luma, got)) if src == "RGBA" else float(np.sum(got) * (1.0 / 3.0))
                return float(got)
            return np.full(3, float(got)) if not isinstance(got, np.ndarray) else got.copy()
        if v is None and implicit is not None:
            return implicit()
        return self.default(node, ident, kind)

    # -- values ------------------------------------------------------------------------------
    def value(self, link: Link):
        node = self.g.nodes.get(link.node)
        if node is None:
            return None
        if link.node not in self.memo:
            if link.node in self.busy:
                return None
            h = _HANDLERS.get(node.type)
            if h is None:
                self.unsupported.append(link.node)
                self.memo[link.node] = None
            else:
                self.busy.add(link.node)
                try:
                    self.memo[link.node] = h(self, node)
                finally:
                    self.busy.discard(link.node)
        outs = self.memo[link.node]
        if outs is None:
            return None
        return outs.get(link.socket)

    # -- shaders -----------------------------------------------------------------------------
    def shader(self, link, weight: float, depth: int = 0) -> list:
        node = self.g.nodes.get(link.node) if isinstance(link, Link) else None
        if node is None or depth > 32:
            return [(weight, Closure(base=np.zeros(3), roughness=1.0, kind="none"))]
        t = node.type
        f = lambda ident, kind: self.inp(node, ident, kind)   # noqa: E731
        if t == "ShaderNodeMixShader":
            fac = _saturate(f("Fac", "f"))
            return (self.shader(node.inputs.get("Shader"), weight * (1.0 - fac), depth + 1)
                    + self.shader(node.inputs.get("Shader_001"), weight * fac, depth + 1))
        if t == "ShaderNodeAddShader":          # Cycles sums the closures of both inputs
            return (self.shader(node.inputs.get("Shader"), weight, depth + 1)
                    + self.shader(node.inputs.get("Shader_001"), weight, depth + 1))
        if t == "ShaderNodeBsdfTransparent":
            return [(weight, Closure(base=np.zeros(3), roughness=1.0, kind="transparent",
                                     transparent=f("Color", "v")))]
        if t == "ShaderNodeBsdfPrincipled":
            alpha = _saturate(f("Alpha", "f"))
            if alpha < 1.0:                  # Cycles: a Transparent BSDF (white) mixed in by 1 - Alpha
                clear = [(weight * (1.0 - alpha), Closure(base=np.zeros(3), roughness=1.0, kind="transparent",
                                                          transparent=np.ones(3)))]
                if alpha <= 0.0:
                    return clear
                return self._principled(node, weight * alpha) + clear
            return self._principled(node, weight)
        if t == "ShaderNodeBsdfDiffuse":
            c = Closure(base=f("Color", "v"), roughness=1.0, kind="diffuse")
        elif t in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            c = Closure(base=f("Color", "v"), metallic=1.0, roughness=f("Roughness", "f"), kind="glossy")
        elif t == "ShaderNodeBsdfGlass":
            c = Closure(base=f("Color", "v"), transmission=1.0, roughness=f("Roughness", "f"), ior=f("IOR", "f"),
                        kind="glass")
        elif t == "ShaderNodeEmission":
            c = Closure(base=np.zeros(3), roughness=1.0, emission=f("Color", "v") * f("Strength", "f"),
                        kind="emission")
        else:
            self.unsupported.append(link.node)
            c = Closure(base=np.full(3, 0.8), roughness=1.0, kind="fallback")
        return [(weight, c)]

    def _principled(self, node, weight: float) -> list:
        f = lambda ident, kind: self.inp(node, ident, kind)   # noqa: E731
        return [(weight, Closure(base=f("Base Color", "v"), metallic=f("Metallic", "f"),
                                 roughness=f("Roughness", "f"), transmission=f("Transmission Weight", "f"),
                                 ior=f("IOR", "f"), specular=min(1.0, 2.0 * f("Specular IOR Level", "f")),
                                 emission=f("Emission Color", "v") * f("Emission Strength", "f"),
                                 kind="principled"))]


# -- value-node handlers: (evaluator, node) -> {output identifier: float | (3,) array} -------------
def _h_texcoord(e, node):
    h = e.hit
    n = h.N
    refl = h.D - 2.0 * n * float(np.dot(h.D, n))        # -reflect(wi, N), wi = -D
    return {"Generated": h.generated.copy(), "UV": _uv3(h, ""), "Object": h.p_obj.copy(), "Reflection": refl}


def _uv3(h, name):
    uv = h.uv.get(name)
    return np.zeros(3) if uv is None else np.array([uv[0], uv[1], 0.0])


def _h_uvmap(e, node):
    return {"UV": _uv3(e.hit, str(node.props.get("uv_map", "") or ""))}


def _h_attribute(e, node):
    """Color Attribute / Attribute (Geometry): svm_node_attr -- a colour attribute, else a UV map of
    that name as (u, v, 0) with alpha 1, else 0; Fac = average(color)."""
    h = e.hit
    if node.type == "ShaderNodeVertexColor":
        name = str(node.props.get("layer_name", "") or "")
    else:
        name = str(node.props.get("attribute_name", "") or "")
        if node.props.get("attribute_type", "GEOMETRY") != "GEOMETRY" or not name:
            name = None
    if name is not None and name in h.colors:
        c = np.asarray(h.colors[name], np.float64)
    elif name and name in h.uv:
        c = np.array([h.uv[name][0], h.uv[name][1], 0.0, 1.0])
    else:
        c = np.zeros(4)
    return {"Color": c[:3].copy(), "Vector": c[:3].copy(), "Fac": float(np.mean(c[:3])), "Alpha": float(c[3])}


def _h_geometry(e, node):
    h = e.hit
    return {"Position": h.P.copy(), "Normal": h.N.copy(), "True Normal": h.Ng.copy(), "Incoming": -h.D,
            "Backfacing": 1.0 if h.backfacing else 0.0}


def fresnel_dielectric_cos(cosi: float, eta: float) -> float:
    """Cycles' ``fresnel_dielectric_cos`` (bsdf_util.h): unpolarised dielectric reflectance."""
    c = abs(cosi)
    g = eta * eta - 1.0 + c * c
    if g > 0.0:
        g = math.sqrt(g)
        A = (g - c) / (g + c)
        B = (c * (g + c) - 1.0) / (c * (g - c) + 1.0)
        return 0.5 * A * A * (1.0 + B * B)
    return 1.0


def _view_normal(e, node):
    h = e.hit
    N = e.inp(node, "Normal", "v") if isinstance(node.inputs.get("Normal"), Link) else h.N
    return float(np.dot(-h.D, N)), h.backfacing


def _h_fresnel(e, node):
    cosi, back = _view_normal(e, node)
    eta = max(e.inp(node, "IOR", "f"), 1e-5)
    return {"Fac": fresnel_dielectric_cos(cosi, 1.0 / eta if back else eta)}


def _h_layer_weight(e, node):
    cosi, back = _view_normal(e, node)
    blend = e.inp(node, "Blend", "f")
    eta = max(1.0 - blend, 1e-5)
    fresnel = fresnel_dielectric_cos(cosi, eta if back else 1.0 / eta)
    facing = abs(cosi)
    if blend != 0.5:
        b = min(max(blend, 0.0), 1.0 - 1e-5)
        b = 2.0 * b if b < 0.5 else 0.5 / (1.0 - b)
        facing = facing ** b
    return {"Fresnel": fresnel, "Facing": 1.0 - facing}


def _h_mapping(e, node):
    return {"Vector": mapping(node.props.get("vector_type", "POINT"), e.inp(node, "Vector", "v"),
                              e.inp(node, "Location", "v"), e.inp(node, "Rotation", "v"), e.inp(node, "Scale", "v"))}


def _h_math(e, node):
    r = math_op(node.props.get("operation", "ADD"), e.inp(node, "Value", "f"), e.inp(node, "Value_001", "f"),
                e.inp(node, "Value_002", "f"))
    if node.props.get("use_clamp"):                     # MathNode::expand: a Clamp node 0..1
        r = _saturate(r)
    return {"Value": r}


def _h_vector_math(e, node):
    vec, val = vector_math(node.props.get("operation", "ADD"), e.inp(node, "Vector", "v"),
                           e.inp(node, "Vector_001", "v"), e.inp(node, "Vector_002", "v"), e.inp(node, "Scale", "f"))
    return {"Vector": vec, "Value": val}


def _h_mix(e, node):
    dt = node.props.get("data_type", "FLOAT")
    t = e.inp(node, "Factor_Float", "f")
    if node.props.get("clamp_factor", True):
        t = _saturate(t)
    if dt == "FLOAT":                                    # svm_node_mix_float
        a, b = e.inp(node, "A_Float", "f"), e.inp(node, "B_Float", "f")
        return {"Result_Float": a * (1.0 - t) + b * t}
    if dt == "VECTOR":                                   # svm_node_mix_vector
        a, b = e.inp(node, "A_Vector", "v"), e.inp(node, "B_Vector", "v")
        return {"Result_Vector": a * (1.0 - t) + b * t}
    r = mix_blend(node.props.get("blend_type", "MIX"), t, e.inp(node, "A_Color", "v"), e.inp(node, "B_Color", "v"))
    if node.props.get("clamp_result"):                   # svm_node_mix_color
        r = np.clip(r, 0.0, 1.0)
    return {"Result_Color": r}


def _h_mix_rgb(e, node):                                 # svm_node_mix: the factor is always saturated
    t = _saturate(e.inp(node, "Fac", "f"))
    r = mix_blend(node.props.get("blend_type", "MIX"), t, e.inp(node, "Color1", "v"), e.inp(node, "Color2", "v"))
    if node.props.get("use_clamp"):
        r = np.clip(r, 0.0, 1.0)
    return {"Color": r}


def _h_invert(e, node):
    f, c = e.inp(node, "Fac", "f"), e.inp(node, "Color", "v")
    return {"Color": f * (1.0 - c) + (1.0 - f) * c}


def _h_hsv(e, node):                                     # svm_node_hsv
    fac, c0 = e.inp(node, "Fac", "f"), e.inp(node, "Color", "v")
    hsv = rgb_to_hsv(c0)
    hsv[0] = _fractf(hsv[0] + e.inp(node, "Hue", "f") + 0.5)
    hsv[1] = _saturate(hsv[1] * e.inp(node, "Saturation", "f"))
    hsv[2] *= e.inp(node, "Value", "f")
    c = hsv_to_rgb(hsv)
    return {"Color": np.maximum(fac * c + (1.0 - fac) * c0, 0.0)}


def _h_bright_contrast(e, node):                         # svm_brightness_contrast
    c = e.inp(node, "Color", "v")
    bright, contrast = e.inp(node, "Bright", "f"), e.inp(node, "Contrast", "f")
    a, b = 1.0 + contrast, bright - contrast * 0.5
    return {"Color": np.maximum(a * c + b, 0.0)}


def _h_gamma(e, node):                                   # svm_math_gamma_color
    c, g = e.inp(node, "Color", "v"), e.inp(node, "Gamma", "f")
    if g == 0.0:
        return {"Color": np.ones(3)}
    return {"Color": np.array([x ** g if x > 0.0 else x for x in c])}


_SEP = {"RGB": lambda c: c, "HSV": rgb_to_hsv, "HSL": rgb_to_hsl}
_COMB = {"RGB": lambda c: c, "HSV": hsv_to_rgb, "HSL": hsl_to_rgb}


def _h_separate_color(e, node):
    c = _SEP[node.props.get("mode", "RGB")](e.inp(node, "Color", "v"))
    return {"Red": float(c[0]), "Green": float(c[1]), "Blue": float(c[2])}


def _h_combine_color(e, node):
    c = np.array([e.inp(node, k, "f") for k in ("Red", "Green", "Blue")])
    return {"Color": _COMB[node.props.get("mode", "RGB")](c)}


def _h_separate_rgb(e, node):
    c = e.inp(node, "Image", "v")
    return {"R": float(c[0]), "G": float(c[1]), "B": float(c[2])}


def _h_combine_rgb(e, node):
    return {"Image": np.array([e.inp(node, k, "f") for k in ("R", "G", "B")])}


def _h_separate_xyz(e, node):
    v = e.inp(node, "Vector", "v")
    return {"X": float(v[0]), "Y": float(v[1]), "Z": float(v[2])}


def _h_combine_xyz(e, node):
    return {"Vector": np.array([e.inp(node, k, "f") for k in ("X", "Y", "Z")])}


def _h_rgb_to_bw(e, node):
    return {"Val": float(np.dot(e.luma, e.inp(node, "Color", "v")))}


def _clamp_node(value, lo, hi, typ):                     # svm_node_clamp
    if typ == "RANGE" and lo > hi:
        return min(max(value, hi), lo)
    return min(max(value, lo), hi)


def _h_clamp(e, node):
    return {"Result": _clamp_node(e.inp(node, "Value", "f"), e.inp(node, "Min", "f"), e.inp(node, "Max", "f"),
                                  node.props.get("clamp_type", "MINMAX"))}


def _smoothstep(e0, e1, x):
    if x < e0:
        return 0.0
    if x >= e1:
        return 1.0
    t = (x - e0) / (e1 - e0)
    return (3.0 - 2.0 * t) * (t * t)


def _smootherstep(e0, e1, x):
    x = min(max(_safe_divide(x - e0, e1 - e0), 0.0), 1.0)
    return x * x * x * (x * (x * 6.0 - 15.0) + 10.0)


def map_range(typ, value, f0, f1, t0, t1, steps, clamp):
    """svm_node_map_range, then MapRangeNode::expand's Clamp (Range) node when clamp is set."""
    if f1 != f0:
        if typ == "STEPPED":
            fac = (value - f0) / (f1 - f0)
            fac = math.floor(fac * (steps + 1.0)) / steps if steps > 0.0 else 0.0
        elif typ == "SMOOTHSTEP":
            fac = 1.0 - _smoothstep(f1, f0, value) if f0 > f1 else _smoothstep(f0, f1, value)
        elif typ == "SMOOTHERSTEP":
            fac = 1.0 - _smootherstep(f1, f0, value) if f0 > f1 else _smootherstep(f0, f1, value)
        else:
            fac = (value - f0) / (f1 - f0)
        r = t0 + fac * (t1 - t0)
    else:
        r = 0.0
    if clamp:
        r = _clamp_node(r, t0, t1, "RANGE")
    return r


def _h_map_range(e, node):
    g = lambda k: e.inp(node, k, "f")   # noqa: E731
    return {"Result": map_range(node.props.get("interpolation_type", "LINEAR"), g("Value"), g("From Min"),
                                g("From Max"), g("To Min"), g("To Max"), g("Steps"),
                                bool(node.props.get("clamp", True)))}


def _h_ramp(e, node):
    elems = sorted(node.props.get("elements", [(0.0, (0, 0, 0, 1)), (1.0, (1, 1, 1, 1))]), key=lambda x: x[0])
    interp = node.props.get("interpolation", "LINEAR")
    f = e.inp(node, "Fac", "f")
    rgba = ramp_cycles(elems, interp, f) if e.ramp == "cycles" else colorband_evaluate(elems, interp, f)
    return {"Color": rgba[:3].copy(), "Alpha": float(rgba[3])}


def _h_curves(e, node):                                  # svm_node_curves on [0, 1], no extrapolation
    table = np.asarray(node.props["table"], np.float64).reshape(3, -1)
    fac, c = e.inp(node, "Fac", "f"), e.inp(node, "Color", "v")
    looked = np.array([_table_lookup(table[k][:, None], c[k])[0] for k in range(3)])
    return {"Color": (1.0 - fac) * c + fac * looked}


def _to_working(e, tex):
    """The image's matrix into the working space (None: read as stored)."""
    prim = colorspaces.SPACES.get(tex.colorspace, ("linear", None))[1]
    return colorspaces.conversion(prim, e.working)


def _h_tex_image(e, node):
    img = int(node.props.get("image", -1))
    if img < 0 or img >= len(e.textures):
        return {"Color": np.array([1.0, 0.0, 1.0]), "Alpha": 1.0}   # IMAGE_MISSING_RGBA (1, 0, 1, 1)
    tex = e.textures[img]
    vec = e.inp(node, "Vector", "v", implicit=lambda: _uv3(e.hit, ""))
    interp, ext = node.props.get("interpolation", "Linear"), node.props.get("extension", "REPEAT")
    if node.props.get("tiles"):                                      # UDIM
        tiles = {int(t): e.textures[int(i)] for t, i in node.props["tiles"]}
        rgba = texture_numpy.sample_udim(tiles, vec[None, :2], interp, ext, e.output_linked(node, "Alpha"),
                                         working={t: _to_working(e, x) for t, x in tiles.items()})[0]
        return {"Color": rgba[:3].copy(), "Alpha": float(rgba[3])}
    # ImageTextureNode::compile: NODE_IMAGE_ALPHA_UNASSOCIATE when the Alpha output is linked
    unassociate = texture_numpy.unassociate_flag(tex, e.output_linked(node, "Alpha"))
    rgba = texture_numpy.sample(tex, vec[None, :2], interp, ext, srgb=e.srgb, unassociate=unassociate,
                                working=_to_working(e, tex))[0]
    return {"Color": rgba[:3].copy(), "Alpha": float(rgba[3])}


def _h_tex_checker(e, node):
    vec = e.inp(node, "Vector", "v", implicit=lambda: e.hit.generated.copy())
    f = checker(vec * e.inp(node, "Scale", "f"))
    col = e.inp(node, "Color1", "v") if f == 1.0 else e.inp(node, "Color2", "v")
    return {"Color": col, "Fac": f}


def _h_tex_gradient(e, node):
    vec = e.inp(node, "Vector", "v", implicit=lambda: e.hit.generated.copy())
    f = _saturate(gradient(node.props.get("gradient_type", "LINEAR"), vec))
    return {"Color": np.full(3, f), "Fac": f}


def _h_value(e, node):
    return {"Value": float(node.props.get("value", 0.5))}


def _h_rgb(e, node):
    return {"Color": np.asarray(tuple(node.props.get("value", (0.5, 0.5, 0.5)))[:3], np.float64)}


def _h_reroute(e, node):
    src = node.inputs.get("Input")
    if not isinstance(src, Link):
        return None
    got = e.value(src)
    return None if got is None else {"Output": got}


_HANDLERS = {
    "ShaderNodeTexCoord": _h_texcoord, "ShaderNodeUVMap": _h_uvmap, "ShaderNodeNewGeometry": _h_geometry,
    "ShaderNodeMapping": _h_mapping, "ShaderNodeFresnel": _h_fresnel, "ShaderNodeLayerWeight": _h_layer_weight,
    "ShaderNodeMath": _h_math, "ShaderNodeVectorMath": _h_vector_math,
    "ShaderNodeAttribute": _h_attribute, "ShaderNodeVertexColor": _h_attribute,
    "ShaderNodeMix": _h_mix, "ShaderNodeMixRGB": _h_mix_rgb, "ShaderNodeInvert": _h_invert,
    "ShaderNodeHueSaturation": _h_hsv, "ShaderNodeBrightContrast": _h_bright_contrast,
    "ShaderNodeGamma": _h_gamma, "ShaderNodeSeparateColor": _h_separate_color,
    "ShaderNodeCombineColor": _h_combine_color, "ShaderNodeSeparateRGB": _h_separate_rgb,
    "ShaderNodeCombineRGB": _h_combine_rgb, "ShaderNodeSeparateXYZ": _h_separate_xyz,
    "ShaderNodeCombineXYZ": _h_combine_xyz, "ShaderNodeRGBToBW": _h_rgb_to_bw, "ShaderNodeClamp": _h_clamp,
    "ShaderNodeMapRange": _h_map_range, "ShaderNodeValToRGB": _h_ramp, "ShaderNodeRGBCurve": _h_curves,
    "ShaderNodeTexImage": _h_tex_image, "ShaderNodeTexChecker": _h_tex_checker,
    "ShaderNodeTexGradient": _h_tex_gradient, "ShaderNodeValue": _h_value, "ShaderNodeRGB": _h_rgb,
    "NodeReroute": _h_reroute,
}


def evaluate(graph: ShaderGraph, hit: Hit, textures=(), *, ramp: str = "cycles", srgb: str = "cycles",
             working: str = "REC709") -> list:
    """[(weight, :class:`Closure`)]: every leaf closure of the surface with its Mix Shader weight
    (one entry, weight 1, without Mix Shaders).  ramp / srgb: see the module docstring and
    :func:`texture_numpy.sample`; working: the scene's working space (id)."""
    e = _Eval(graph, hit, textures, ramp, srgb, working=working)
    return e.shader(graph.surface, 1.0)


def evaluate_value(graph: ShaderGraph, link: Link, hit: Hit, textures=(), *, ramp: str = "cycles",
                   srgb: str = "cycles"):
    """The value (float or (3,) array) of output ``link`` of the graph at the hit (None if unsupported)."""
    e = _Eval(graph, hit, textures, ramp, srgb, roots=(link,))
    return e.value(link)
