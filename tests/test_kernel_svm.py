"""The shader-node interpreter (stpm_core.kernels.svm) against the numpy oracle written from
Cycles' SVM (tests/oracles/svm_numpy.py, tests/oracles/texture_numpy.py).

Every test builds tiny node graphs, gives each its own material on a one-triangle scene with two
UV maps, runs ``shading.shading_data`` + ``kernels.svm.shade_closures`` on synthetic hits (chosen
barycentrics, normals and ray directions, some back-facing) and compares the closure rows with the
oracle's closures at the same hits.

Value nodes are read through an Emission shader twice, with Strength +1 and -1: the closure row
keeps emission >= 0, so the pair gives back the value on the whole real line (out-of-range
colours, negative results, infinities of 0 ** -2).  Float outputs reach the Emission colour
through Blender's float -> colour conversion; colour -> float (luminance) and vector -> float
(average) conversions are tested on their own.

Tolerance: 1e-9 (relative and absolute).  Kernel and oracle both compute in float64 from the same
float32 mesh attributes; only the order of a few operations differs (rounding ~1e-16).  sRGB image
textures: 2e-7 absolute (the kernel's EOTF table).

Image textures are read with associated alpha, as Cycles holds RGBA images, and un-associated
when the Alpha output is linked; the image look-up itself is tested in tests/test_textures.py.

Strict xfails mark where the kernel departs from Cycles; the reason names Cycles' file and
function (today: when an Image Texture's colour is un-associated -- channel-packed and Non-Color
images, an Alpha output linked only to a node that does not reach the output).  Coverage of what
is not Blender's: Mix Shader picks branch B with frequency Fac (hash of seed and row), constant
materials keep their constant rows, unsupported nodes are listed in ``Program.unsupported`` and
give the socket's default.
"""
from __future__ import annotations

import zlib

import numpy as np
import pytest

from oracles import svm_numpy as O
from oracles import texture_numpy as TO
from stpm_core.kernels import svm
from stpm_core.kernels.closure import (C_METAL_CONST, C_BASE, C_EMIT, C_IOR, C_METALLIC, C_PASS, C_PROGRAM, C_ROUGHNESS,
                                       C_SPECULAR, C_TINT_R, C_TINT_T, C_TRANSMISSION, C_TRANSPARENT, N_CLOSURE, pack_materials)
from stpm_core.nodes.compile import colorband, compile_graph
from stpm_core.nodes.graph import Link, Node, ShaderGraph
from stpm_core.nodes.ops import BLEND_MODES, GRADIENT_TYPES, MATH_OPS, VMATH_OPS
from stpm_core.raycast import Hits
from stpm_core.scene import Instance, Material, Mesh, Scene
from stpm_core.shading import hit_geometry, shading_data
from stpm_core.textures import Texture

RTOL = ATOL = 1e-9
SRGB_ATOL = 2e-7      # sRGB image textures: the kernel's EOTF table is within 6.7e-8 of the formula

SHADER_OUT = {"ShaderNodeBsdfPrincipled": "BSDF", "ShaderNodeBsdfDiffuse": "BSDF", "ShaderNodeBsdfGlossy": "BSDF",
              "ShaderNodeBsdfAnisotropic": "BSDF", "ShaderNodeBsdfGlass": "BSDF", "ShaderNodeEmission": "Emission",
              "ShaderNodeMixShader": "Shader", "ShaderNodeBsdfTransparent": "BSDF", "ShaderNodeAddShader": "Shader"}


def _seed(*parts) -> int:
    return zlib.crc32("/".join(str(p) for p in parts).encode())


# ----------------------------------------------------------------------------
# Graph building
# ----------------------------------------------------------------------------
# outputs the interpreter reports as unsupported: declared (= used) only where a test wants them
_UNUSED_OUTPUTS = {"ShaderNodeTexCoord": ("Normal", "Camera", "Window"),    # Normal: its own test
                   "ShaderNodeNewGeometry": ("Tangent", "Parametric", "Pointiness", "Random Per Island")}


def N(type_: str, inputs=None, props=None) -> Node:
    """A node with Blender's output socket types declared (as the exporter records the used ones)."""
    outs = {k: v for k, v in O.SOCKET_TYPES.get(type_, {}).items() if k not in _UNUSED_OUTPUTS.get(type_, ())}
    if type_ in SHADER_OUT:
        outs = {SHADER_OUT[type_]: "SHADER"}
    return Node(type_, props=dict(props or {}), inputs=dict(inputs or {}), outputs=outs)


def L(node: str, socket: str) -> Link:
    return Link(node, socket)


def surface(nodes: dict, shader: str) -> ShaderGraph:
    return ShaderGraph(nodes=dict(nodes), surface=Link(shader, SHADER_OUT[nodes[shader].type]))


def emit_graph(nodes: dict, out, strength: float) -> ShaderGraph:
    """nodes + an Emission whose Color is ``out`` (a Link or a constant) and Strength ``strength``."""
    nodes = dict(nodes)
    nodes["__emit"] = N("ShaderNodeEmission", {"Color": out, "Strength": strength})
    return surface(nodes, "__emit")


# ----------------------------------------------------------------------------
# Scene, hits, kernel
# ----------------------------------------------------------------------------
V = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.5], [0.3, 1.5, -0.4]], np.float32)
UV_MAIN = np.array([[[0.1, 0.2], [0.9, 0.15], [0.4, 0.85]]], np.float32)
UV_SECOND = np.array([[[-0.5, 1.5], [2.25, 0.75], [0.6, -1.2]]], np.float32)
NG = np.cross(V[1] - V[0], V[2] - V[0]).astype(np.float64)
NG /= np.linalg.norm(NG)


def make_scene(graphs, textures=()) -> Scene:
    mesh = Mesh(vertices=V.copy(), triangles=np.array([[0, 1, 2]], np.int32), material_ids=np.zeros(1, np.int32),
                uv_layers={"UVMap": UV_MAIN.copy(), "Second": UV_SECOND.copy()}, uv_render="UVMap", name="tri")
    mats = [g if isinstance(g, Material) else Material(graph=g, name=f"m{i}") for i, g in enumerate(graphs)]
    return Scene(meshes=[mesh], instances=[Instance(mesh=0)], materials=mats, textures=list(textures))


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def make_hits(m: int, rng, back_fraction: float = 0.25) -> dict:
    """m hits on the triangle: barycentrics inside (some on edges / corners), shading normals tilted
    off the geometric one, unit ray directions (a fraction from behind the face)."""
    bu = rng.uniform(0.0, 1.0, m)
    bv = rng.uniform(0.0, 1.0, m)
    out = bu + bv > 1.0
    bu[out], bv[out] = 1.0 - bu[out], 1.0 - bv[out]
    fixed = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.5, 0.5), (1 / 3, 1 / 3)]
    for k, (a, b) in enumerate(fixed[:m]):
        bu[k], bv[k] = a, b
    w = np.stack([1.0 - bu - bv, bu, bv], 1)
    P = w @ V.astype(np.float64)
    ns = _unit(NG + 0.4 * rng.normal(size=(m, 3)))
    D = _unit(rng.normal(size=(m, 3)))
    back = rng.uniform(size=m) < back_fraction
    d_ng = D @ NG
    D = np.where(((d_ng > 0) != back)[:, None], D - 2.0 * d_ng[:, None] * NG, D)   # mirror to the wanted side
    return {"bu": bu, "bv": bv, "P": P, "NG": np.tile(NG, (m, 1)), "NS": ns, "D": D}


def run_kernel(scene: Scene, hits: dict, mat: np.ndarray, seed: int = 0):
    sd = shading_data(scene)
    m = len(mat)
    h = Hits(t=np.ones(m), instance=np.zeros(m, np.int32), prim=np.zeros(m, np.int32), u=hits["bu"].copy(),
             v=hits["bv"].copy(), position=hits["P"].copy(), ng=hits["NG"].copy(), ns=hits["NS"].copy(),
             material=np.asarray(mat, np.int32))
    G = hit_geometry(h, hits["D"])
    C = np.zeros((m, N_CLOSURE))
    svm.shade_closures(np.asarray(mat, np.int32), sd.closures, sd.prog, sd.n_slots, G, sd.A, sd.X, seed, C)
    return C, sd


def oracle_hit(scene: Scene, hits: dict, r: int) -> O.Hit:
    return O.hit_from_scene(scene, 0, 0, hits["bu"][r], hits["bv"][r], hits["P"][r], hits["NG"][r], hits["NS"][r],
                            hits["D"][r])


def oracle_rows(scene, hits, mat, C=None, **kw) -> list:
    """Oracle closure rows (dict) per hit (tests of single closures).  A Principled BSDF with
    Alpha < 1 has two leaves (the BSDF and a Transparent BSDF): with the kernel's closures C, the
    leaf its walk chose (``C_PASS``) is the row compared."""
    rows = []
    for r, mi in enumerate(mat):
        leaves = O.evaluate(scene.materials[mi].graph, oracle_hit(scene, hits, r), scene.textures, **kw)
        if len(leaves) > 1 and C is not None:
            chosen = C[r, C_PASS] > 0
            leaves = [lf for lf in leaves if (lf[1].kind == "transparent") == chosen]
        assert len(leaves) == 1
        rows.append(O.closure_row(leaves[0][1]))
    return rows


def check_values(cases, textures=(), hits_per_case: int = 1, seed: int = 1, sd_clean: bool = True, atol=ATOL,
                 working: str = "REC709", rtol=RTOL, **kw):
    """cases: [(nodes, out)] -- ``out`` read through Emission x +-1.  Kernel vs oracle emission, in
    the working space ``working`` (the scene's metadata)."""
    graphs = [emit_graph(nodes, out, s) for nodes, out in cases for s in (1.0, -1.0)]
    rng = np.random.default_rng(seed)
    mat = np.repeat(np.arange(len(graphs)), hits_per_case)
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs, textures)
    scene.metadata["working_space"] = working
    C, sd = run_kernel(scene, hits, mat)
    if sd_clean:
        assert not sd.unsupported, sd.unsupported
    exp = np.array([row["emission"] for row in oracle_rows(scene, hits, mat, working=working, **kw)])
    got = C[:, C_EMIT:C_EMIT + 3]
    bad = ~np.isclose(got, exp, rtol=rtol, atol=atol).all(axis=1)
    if bad.any():
        lines = []
        for r in np.flatnonzero(bad)[:8]:
            case = cases[mat[r] // 2]
            desc = {k: (n.type, n.props, n.inputs) for k, n in case[0].items()}
            lines.append(f"row {r} strength {'+' if mat[r] % 2 == 0 else '-'}: kernel {got[r]} oracle {exp[r]}\n"
                         f"    case out={case[1]!r} nodes={desc}")
        raise AssertionError(f"{bad.sum()} of {len(bad)} rows differ:\n" + "\n".join(lines))
    return C, sd, scene, hits


# ----------------------------------------------------------------------------
# Inputs
# ----------------------------------------------------------------------------
def _floats(rng, n, lo=-4.0, hi=4.0):
    return [float(x) for x in rng.uniform(lo, hi, n)]


def _vec(rng, lo=-3.0, hi=3.0):
    return tuple(float(x) for x in rng.uniform(lo, hi, 3))


MATH_EDGES = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (-1.0, 0.0, 0.0), (0.0, -2.0, 0.0), (0.0, -3.0, 1.0),
              (-2.0, 0.5, 0.0), (-2.0, 3.0, 0.0), (-2.0, -2.0, 0.0), (2.0, -3.0, 0.0), (-8.0, 1.0 / 3.0, 0.0),
              (0.5, 1.0, 0.0), (2.0, 0.5, 0.0), (-1.0, 2.0, 0.0), (3.0, 3.0, 1.0), (2.5, 2.5, 2.5),
              (-2.5, -0.5, 1.5), (1.0, 1.0, 0.0), (0.0, 2.0, 0.0), (-0.75, 2.0, -1.0), (5.5, -2.0, 1.0),
              (1.0, 1.0 + 0.5, 0.75), (-3.5, 0.0, 0.0), (1.5, -1.5, -1.5), (0.999, 1.0, 0.0)]


def math_cases(rng, n_random: int = 24):
    rnd = [tuple(_floats(rng, 3)) for _ in range(n_random)]
    ints = [tuple(float(x) for x in rng.integers(-3, 4, 3)) for _ in range(6)]
    return MATH_EDGES + rnd + ints


def _math(op, a, b, c, clamp=False):
    return N("ShaderNodeMath", {"Value": a, "Value_001": b, "Value_002": c}, {"operation": op, "use_clamp": clamp})


# ----------------------------------------------------------------------------
# Math
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("op", list(MATH_OPS))
def test_math(op):
    rng = np.random.default_rng(_seed("math", op))
    cases = [({"M": _math(op, a, b, c)}, L("M", "Value")) for a, b, c in math_cases(rng)]
    check_values(cases)


@pytest.mark.parametrize("op", ["ADD", "MULTIPLY", "POWER", "SINE", "EXPONENT", "SUBTRACT", "DIVIDE"])
def test_math_use_clamp(op):
    rng = np.random.default_rng(_seed("mathclamp", op))
    cases = [({"M": _math(op, a, b, c, clamp=True)}, L("M", "Value")) for a, b, c in math_cases(rng, 12)]
    check_values(cases)


def test_math_chain_and_links():
    """Math nodes fed by other nodes' outputs: float, colour -> float (luminance), vector -> float (average)."""
    rng = np.random.default_rng(4)
    cases = []
    for _ in range(12):
        col, vec = _vec(rng, -0.5, 1.5), _vec(rng)
        nodes = {"RGB": N("ShaderNodeRGB", props={"value": col}),
                 "XYZ": N("ShaderNodeCombineXYZ", {"X": vec[0], "Y": vec[1], "Z": vec[2]}),
                 "A": N("ShaderNodeMath", {"Value": L("RGB", "Color"), "Value_001": L("XYZ", "Vector"),
                                           "Value_002": 0.0}, {"operation": "MULTIPLY_ADD"}),
                 "B": N("ShaderNodeMath", {"Value": L("A", "Value"), "Value_001": float(rng.uniform(-2, 2)),
                                           "Value_002": L("RGB", "Color")}, {"operation": "MULTIPLY_ADD"})}
        cases.append((nodes, L("B", "Value")))
        cases.append((nodes, L("A", "Value")))
    check_values(cases)


def test_math_compare_epsilon_floor():
    """Cycles kernel/svm/math_util.h svm_math NODE_MATH_COMPARE: ((a == b) || fabsf(a - b) <=
    fmaxf(c, FLT_EPSILON)) -- the epsilon floor is FLT_EPSILON (1.19e-7)."""
    cases = [({"M": _math("COMPARE", 0.0, d, c)}, L("M", "Value"))
             for d in (2e-6, 5e-6, -9e-6, 1e-7, -1.1e-7, 1.3e-7, 0.3) for c in (0.0, -1.0, 1e-7, 0.25)]
    check_values(cases)


def test_math_arctan2_signed_zeros():
    """Cycles kernel/svm/math_util.h svm_math NODE_MATH_ARCTAN2 -> util/math_base.h compatible_atan2:
    (x == 0 && y == 0) ? 0 : atan2f(y, x), whatever the signs of the zeros."""
    cases = [({"M": _math("ARCTAN2", a, b, 0.0)}, L("M", "Value"))
             for a in (-0.0, 0.0) for b in (-0.0, 0.0)]
    check_values(cases)


def test_math_arctan2_zero_zero():
    check_values([({"M": _math("ARCTAN2", 0.0, 0.0, 0.0)}, L("M", "Value"))])


def test_math_third_input_default():
    """Blender's Math node declares Value_002 with default 0.5 (nodes/shader/nodes/node_shader_math.cc)."""
    cases = [({"M": N("ShaderNodeMath", {"Value": 2.0, "Value_001": 3.0}, {"operation": op})}, L("M", "Value"))
             for op in ("MULTIPLY_ADD", "WRAP", "COMPARE", "SMOOTH_MIN", "SMOOTH_MAX")]
    C, *_ = check_values(cases)
    np.testing.assert_allclose(C[0, C_EMIT:C_EMIT + 3], 6.5)


_DEFAULT_CASES = [
    ("ShaderNodeMath", {"Value_002": 0.25}, {"operation": "MULTIPLY_ADD"}, "Value"),
    ("ShaderNodeVectorMath", {}, {"operation": "SCALE"}, "Vector"),
    ("ShaderNodeMix", {}, {"data_type": "FLOAT"}, "Result_Float"),
    ("ShaderNodeMix", {}, {"data_type": "VECTOR"}, "Result_Vector"),
    ("ShaderNodeMix", {}, {"data_type": "RGBA", "blend_type": "ADD"}, "Result_Color"),
    ("ShaderNodeMixRGB", {}, {"blend_type": "SCREEN"}, "Color"),
    ("ShaderNodeInvert", {}, {}, "Color"),
    ("ShaderNodeHueSaturation", {}, {}, "Color"),
    ("ShaderNodeBrightContrast", {}, {}, "Color"),
    ("ShaderNodeGamma", {}, {}, "Color"),
    ("ShaderNodeSeparateColor", {}, {"mode": "HSV"}, "Blue"),
    ("ShaderNodeCombineColor", {}, {"mode": "HSL"}, "Color"),
    ("ShaderNodeSeparateRGB", {}, {}, "G"),
    ("ShaderNodeCombineRGB", {}, {}, "Image"),
    ("ShaderNodeSeparateXYZ", {}, {}, "X"),
    ("ShaderNodeCombineXYZ", {}, {}, "Vector"),
    ("ShaderNodeRGBToBW", {}, {}, "Val"),
    ("ShaderNodeClamp", {}, {}, "Result"),
    ("ShaderNodeMapRange", {}, {}, "Result"),
    ("ShaderNodeValToRGB", {}, {}, "Color"),
    ("ShaderNodeTexChecker", {"Vector": (0.35, 0.1, 0.6)}, {}, "Color"),
    ("ShaderNodeMapping", {"Vector": (0.3, -0.2, 0.5)}, {}, "Vector"),
    ("ShaderNodeValue", {}, {}, "Value"),
    ("ShaderNodeRGB", {}, {}, "Color"),
]


@pytest.mark.parametrize("type_,inputs,props,output", _DEFAULT_CASES, ids=[f"{c[0]}-{c[3]}" for c in _DEFAULT_CASES])
def test_value_node_socket_defaults(type_, inputs, props, output):
    """Inputs absent from the graph read Blender's socket defaults (node_shader_*.cc declarations)."""
    check_values([({"X": N(type_, inputs, props)}, L("X", output))])


# ----------------------------------------------------------------------------
# Vector Math
# ----------------------------------------------------------------------------
def vmath_cases(rng, op):
    z = (0.0, 0.0, 0.0)
    cases = [(_vec(rng), _vec(rng), _vec(rng), float(rng.uniform(-2, 2))) for _ in range(14)]
    cases += [(_vec(rng), z, _vec(rng), 1.5), (z, _vec(rng), z, 0.0), (z, z, z, 1.0),
              ((1.0, -2.0, 0.5), (2.0, 2.0, 2.0), (1.0, -2.0, 0.5), 0.0),
              ((-2.0, -0.5, 3.0), (0.5, 2.0, -1.0), (0.0, 1.0, 0.0), 0.7),       # negative base, fractional power
              ((0.0, 2.0, -0.0), (-2.0, 0.0, -1.0), (1.0, 1.0, 1.0), 1.0),       # 0 ** -2, x ** 0
              ((0.6, -0.8, 0.0), (0.0, 1.0, 0.0), (0.0, -1.0, 0.0), 1.9),        # refract: total internal reflection
              ((0.6, -0.8, 0.0), (0.0, 3.0, 0.0), (0.0, 1.0, 0.0), 0.66),
              ((3.0, -3.0, 2.5), (1.5, 1.5, -1.0), (3.0, -3.0, 2.5), -1.0)]
    return cases


@pytest.mark.parametrize("op", list(VMATH_OPS))
def test_vector_math(op):
    rng = np.random.default_rng(_seed("vmath", op))
    cases = []
    for a, b, c, s in vmath_cases(rng, op):
        node = N("ShaderNodeVectorMath", {"Vector": a, "Vector_001": b, "Vector_002": c, "Scale": s},
                 {"operation": op})
        cases.append(({"VM": node}, L("VM", "Vector")))
        cases.append(({"VM": node}, L("VM", "Value")))
    check_values(cases)


# ----------------------------------------------------------------------------
# Mix
# ----------------------------------------------------------------------------
def mix_color_cases(rng, blend):
    cases = []
    for k in range(20):
        t = float(rng.uniform(-0.5, 1.5)) if k % 3 else float(rng.uniform(0, 1))
        cases.append((t, _vec(rng, -0.5, 1.5), _vec(rng, -0.5, 1.5)))
    grey = (0.4, 0.4, 0.4)
    cases += [(0.5, _vec(rng, 0, 1), grey), (0.7, grey, _vec(rng, 0, 1)), (0.3, (0.0, 0.5, 1.0), (0.0, 0.0, 2.0)),
              (1.0, (0.2, 0.6, 0.0), (1.0, 1.0, 1.0)), (0.0, (0.2, 0.6, 0.9), (0.3, 0.0, 0.1)),
              (1.0, (0.5, 0.5, 0.49), (0.0, 2.0, 0.25)), (2.0, (0.0, 0.3, 0.9), (0.6, 0.6, 0.6)),
              (0.6, (0.0, 0.0, 0.0), (1.0, 0.5, 0.25))]
    return cases


@pytest.mark.parametrize("blend", list(BLEND_MODES))
def test_mix_color(blend):
    """Mix node, RGBA: every blend mode; factor inside and outside [0, 1], colours outside [0, 1],
    every combination of clamp_factor / clamp_result."""
    rng = np.random.default_rng(_seed("mixc", blend))
    cases = []
    for k, (t, a, b) in enumerate(mix_color_cases(rng, blend)):
        props = {"data_type": "RGBA", "blend_type": blend, "clamp_factor": k % 2 == 0, "clamp_result": k % 4 >= 2}
        cases.append(({"X": N("ShaderNodeMix", {"Factor_Float": t, "A_Color": a, "B_Color": b}, props)},
                      L("X", "Result_Color")))
    check_values(cases)


@pytest.mark.parametrize("blend", list(BLEND_MODES))
def test_mix_rgb_legacy(blend):
    """MixRGB (legacy): the factor is always clamped (svm_node_mix), use_clamp clamps the result."""
    rng = np.random.default_rng(_seed("mixrgb", blend))
    cases = []
    for k, (t, a, b) in enumerate(mix_color_cases(rng, blend)):
        node = N("ShaderNodeMixRGB", {"Fac": t, "Color1": a, "Color2": b},
                 {"blend_type": blend, "use_clamp": k % 2 == 1})
        cases.append(({"X": node}, L("X", "Color")))
    check_values(cases)


def test_mix_float_and_vector():
    rng = np.random.default_rng(6)
    cases = []
    for k in range(24):
        t = float(rng.uniform(-1.0, 2.0))
        props = {"clamp_factor": k % 2 == 0}
        floats = {"Factor_Float": t, "A_Float": float(rng.uniform(-3, 3)), "B_Float": float(rng.uniform(-3, 3))}
        cases.append(({"X": N("ShaderNodeMix", floats, dict(props, data_type="FLOAT"))}, L("X", "Result_Float")))
        cases.append(({"X": N("ShaderNodeMix", {"Factor_Float": t, "A_Vector": _vec(rng), "B_Vector": _vec(rng)},
                              dict(props, data_type="VECTOR"))}, L("X", "Result_Vector")))
    check_values(cases)


# ----------------------------------------------------------------------------
# Colour nodes
# ----------------------------------------------------------------------------
def test_invert_hsv_bright_contrast_gamma():
    rng = np.random.default_rng(7)
    cases = []
    for k in range(20):
        col = _vec(rng, -0.5, 1.5)
        cases.append(({"X": N("ShaderNodeInvert", {"Fac": float(rng.uniform(-0.5, 1.5)), "Color": col})},
                      L("X", "Color")))
        cases.append(({"X": N("ShaderNodeHueSaturation", {
            "Hue": float(rng.uniform(-0.5, 1.5)), "Saturation": float(rng.uniform(-0.5, 2.5)),
            "Value": float(rng.uniform(-0.5, 2.5)), "Fac": float(rng.uniform(-0.5, 1.5)), "Color": col})},
            L("X", "Color")))
        cases.append(({"X": N("ShaderNodeBrightContrast", {
            "Color": col, "Bright": float(rng.uniform(-1, 1)), "Contrast": float(rng.uniform(-1.5, 1.5))})},
            L("X", "Color")))
        g = [2.2, 0.4545, -1.0, -2.5, 1.0, 0.5, 3.0, -0.3][k % 8] if k < 8 else float(rng.uniform(-3, 3))
        cases.append(({"X": N("ShaderNodeGamma", {"Color": col, "Gamma": g})}, L("X", "Color")))
    grey = (0.5, 0.5, 0.5)
    cases.append(({"X": N("ShaderNodeHueSaturation", {"Hue": 0.3, "Saturation": 2.0, "Value": 1.0, "Fac": 1.0,
                                                       "Color": grey})}, L("X", "Color")))
    cases.append(({"X": N("ShaderNodeGamma", {"Color": (0.0, 0.0, 0.0), "Gamma": -1.0})}, L("X", "Color")))
    cases.append(({"X": N("ShaderNodeGamma", {"Color": (0.2, 0.4, 0.8), "Gamma": 0.0})}, L("X", "Color")))
    check_values(cases)


def test_gamma_zero_nonpositive_channels():
    """Cycles kernel/svm/math_util.h svm_math_gamma_color: if (gamma == 0) return (1, 1, 1), channels
    <= 0 included."""
    C, *_ = check_values([({"X": N("ShaderNodeGamma", {"Color": (0.0, -0.5, 0.5), "Gamma": 0.0})},
                           L("X", "Color"))])
    np.testing.assert_array_equal(C[0, C_EMIT:C_EMIT + 3], 1.0)


@pytest.mark.parametrize("mode", ["RGB", "HSV", "HSL"])
def test_separate_combine_color(mode):
    """Colours in [-0.5, 1.5] (HSL lightness clamped to 1), hues in [-0.5, 1.5)."""
    rng = np.random.default_rng(_seed("sepcomb", mode))
    cases = []
    for k in range(24):
        col = _vec(rng, -0.5, 1.5) if k % 2 else _vec(rng, 0.0, 1.0)
        sep = N("ShaderNodeSeparateColor", {"Color": col}, {"mode": mode})
        for ch in ("Red", "Green", "Blue"):
            cases.append(({"S": sep}, L("S", ch)))
        h = float(rng.uniform(-0.5, 1.5))
        comb = N("ShaderNodeCombineColor", {"Red": h, "Green": float(rng.uniform(-0.2, 1.5)),
                                            "Blue": float(rng.uniform(-0.2, 1.5))}, {"mode": mode})
        cases.append(({"C": comb}, L("C", "Color")))
        # round trip Separate -> Combine
        nodes = {"S": sep, "C": N("ShaderNodeCombineColor", {"Red": L("S", "Red"), "Green": L("S", "Green"),
                                                             "Blue": L("S", "Blue")}, {"mode": mode})}
        cases.append((nodes, L("C", "Color")))
    for col in [(0.3, 0.3, 0.3), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)]:
        cases.append(({"S": N("ShaderNodeSeparateColor", {"Color": col}, {"mode": mode})}, L("S", "Red")))
    cases.append(({"C": N("ShaderNodeCombineColor", {"Red": 1.0, "Green": 0.5, "Blue": 0.5}, {"mode": mode})},
                  L("C", "Color")))
    check_values(cases)


def test_separate_hsl_bright_colour():
    """Cycles util/color.h rgb_to_hsl: l = min(1.0f, (cmax + cmin) / 2.0f) (bright colours,
    cmax + cmin > 2)."""
    cases = [({"S": N("ShaderNodeSeparateColor", {"Color": (3.0, 2.0, 1.0)}, {"mode": "HSL"})}, L("S", ch))
             for ch in ("Red", "Green", "Blue")]
    C, *_ = check_values(cases)
    np.testing.assert_allclose(C[4, C_EMIT:C_EMIT + 3], 1.0)                 # lightness 1 (not 2)


def test_combine_hsl_hue_outside_unit():
    """Cycles util/color.h hsl_to_rgb: nr = clamp(|6h - 3| - 1), ng = clamp(2 - |6h - 2|), nb =
    clamp(2 - |6h - 4|), rgb = (n - 1/2) chroma + l -- for a hue outside [0, 1] the terms saturate
    (no wrap to one period)."""
    cases = [({"C": N("ShaderNodeCombineColor", {"Red": h, "Green": 1.0, "Blue": 0.5}, {"mode": "HSL"})},
              L("C", "Color")) for h in (1.3, -0.2, 2.7, -1.0)]
    C, *_ = check_values(cases)
    np.testing.assert_allclose(C[0, C_EMIT:C_EMIT + 3], [1.0, 0.0, 0.0], atol=1e-12)   # h = 1.3: red, not h = 0.3


def test_legacy_rgb_xyz_bw():
    rng = np.random.default_rng(9)
    cases = []
    for _ in range(12):
        col, vec = _vec(rng, -0.5, 1.5), _vec(rng)
        s = N("ShaderNodeSeparateRGB", {"Image": col})
        cases += [({"S": s}, L("S", k)) for k in ("R", "G", "B")]
        cases.append(({"C": N("ShaderNodeCombineRGB", {"R": col[0], "G": col[1], "B": col[2]})}, L("C", "Image")))
        x = N("ShaderNodeSeparateXYZ", {"Vector": vec})
        cases += [({"S": x}, L("S", k)) for k in ("X", "Y", "Z")]
        cases.append(({"C": N("ShaderNodeCombineXYZ", {"X": vec[0], "Y": vec[1], "Z": vec[2]})}, L("C", "Vector")))
        cases.append(({"B": N("ShaderNodeRGBToBW", {"Color": col})}, L("B", "Val")))
        # RGB -> float links (luminance), vector -> float (average), float -> colour
        cases.append(({"R": N("ShaderNodeRGB", props={"value": col}),
                       "S": N("ShaderNodeSeparateXYZ", {"Vector": L("R", "Color")})}, L("S", "Y")))
        cases.append(({"V": N("ShaderNodeCombineXYZ", {"X": vec[0], "Y": vec[1], "Z": vec[2]}),
                       "B": N("ShaderNodeRGBToBW", {"Color": L("V", "Vector")})}, L("B", "Val")))
        cases.append(({"R": N("ShaderNodeRGB", props={"value": col}),
                       "M": N("ShaderNodeMath", {"Value": L("R", "Color"), "Value_001": 0.0, "Value_002": 0.0})},
                      L("M", "Value")))
        cases.append(({"V": N("ShaderNodeCombineXYZ", {"X": vec[0], "Y": vec[1], "Z": vec[2]}),
                       "M": N("ShaderNodeMath", {"Value": L("V", "Vector"), "Value_001": 0.0, "Value_002": 0.0})},
                      L("M", "Value")))
        cases.append(({"F": N("ShaderNodeValue", props={"value": float(rng.uniform(-2, 2))})}, L("F", "Value")))
        cases.append(({"R": N("ShaderNodeRGB", props={"value": col}),
                       "RR": N("NodeReroute", {"Input": L("R", "Color")})}, L("RR", "Output")))
    check_values(cases)


# ----------------------------------------------------------------------------
# Converters
# ----------------------------------------------------------------------------
def test_clamp():
    rng = np.random.default_rng(10)
    cases = []
    for k in range(30):
        lo, hi = sorted(rng.uniform(-2, 2, 2)) if k % 3 else tuple(rng.uniform(-2, 2, 2))
        node = N("ShaderNodeClamp", {"Value": float(rng.uniform(-3, 3)), "Min": float(lo), "Max": float(hi)},
                 {"clamp_type": "RANGE" if k % 2 else "MINMAX"})
        cases.append(({"X": node}, L("X", "Result")))
    check_values(cases)


@pytest.mark.parametrize("interp", ["LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP"])
def test_map_range(interp):
    """Float Map Range, both orders of the ranges, clamp on and off, values outside the range."""
    rng = np.random.default_rng(_seed("maprange", interp))
    cases = []
    for k in range(30):
        f0, f1 = (float(x) for x in rng.uniform(-2, 2, 2))
        steps = [4.0, 0.0, -2.0, 2.5, 1.0][k % 5] if interp == "STEPPED" else float(rng.uniform(0, 8))
        node = N("ShaderNodeMapRange", {"Value": float(rng.uniform(-3, 3)), "From Min": f0, "From Max": f1,
                                        "To Min": float(rng.uniform(-2, 2)), "To Max": float(rng.uniform(-2, 2)),
                                        "Steps": steps},
                 {"data_type": "FLOAT", "interpolation_type": interp, "clamp": k % 2 == 0})
        cases.append(({"X": node}, L("X", "Result")))
    node = N("ShaderNodeMapRange", {"Value": 0.25, "From Min": 0.0, "From Max": 1.0, "To Min": 0.0, "To Max": 1.0,
                                    "Steps": 4.0}, {"interpolation_type": interp})
    cases.append(({"X": node}, L("X", "Result")))
    check_values(cases)


@pytest.mark.parametrize("interp", ["LINEAR", "STEPPED", "SMOOTHSTEP", "SMOOTHERSTEP"])
def test_map_range_degenerate_from_range(interp):
    """Cycles kernel/svm/map_range.h svm_node_map_range: if (from_max == from_min) result = 0 (for every
    interpolation type), then scene/shader_nodes.cpp MapRangeNode::expand clamps to [To Min, To Max]
    when Clamp is on (every type)."""
    cases = []
    for clamp in (False, True):
        for t0, t1 in ((-1.0, 2.0), (0.5, 2.0), (2.0, 0.5)):
            node = N("ShaderNodeMapRange", {"Value": 0.5, "From Min": 1.0, "From Max": 1.0, "To Min": t0,
                                            "To Max": t1, "Steps": 4.0},
                     {"interpolation_type": interp, "clamp": clamp})
            cases.append(({"X": node}, L("X", "Result")))
    check_values(cases)


@pytest.mark.parametrize("interp", ["SMOOTHSTEP", "SMOOTHERSTEP"])
def test_map_range_clamp_smooth_types(interp):
    """MapRangeNode::expand adds the Clamp (Range) node for every interpolation type: the smooth
    types, which stay within [To Min, To Max] anyway, and reversed target ranges."""
    rng = np.random.default_rng(_seed("maprange-clamp", interp))
    cases = []
    for _ in range(16):
        f0, f1, t0, t1 = (float(x) for x in rng.uniform(-2, 2, 4))
        node = N("ShaderNodeMapRange", {"Value": float(rng.uniform(-3, 3)), "From Min": f0, "From Max": f1,
                                        "To Min": t0, "To Max": t1}, {"interpolation_type": interp, "clamp": True})
        cases.append(({"X": node}, L("X", "Result")))
    check_values(cases)


def _ramp_elements(rng, n):
    pos = np.sort(rng.uniform(0.05, 0.95, n))
    return [(float(p), tuple(float(x) for x in rng.uniform(0, 1, 4))) for p in pos]


def _ramp_cases(rng, interp):
    cases = []
    for k in range(10):
        els = _ramp_elements(rng, 1 + k % 5)
        fs = list(rng.uniform(-0.2, 1.2, 4)) + [els[0][0], els[-1][0], els[-1][0] + 0.001, els[0][0] - 0.001]
        for f in fs:
            node = N("ShaderNodeValToRGB", {"Fac": float(f)},
                     {"elements": [(p, c) for p, c in reversed(els)], "interpolation": interp})   # any order
            cases.append(({"R": node}, L("R", "Color")))
            cases.append(({"R": node}, L("R", "Alpha")))
    return cases


@pytest.mark.parametrize("interp", ["CONSTANT", "LINEAR", "EASE"])
def test_colorband(interp):
    """The compiler's colour band (``compile.colorband``, what the ramp table is sampled from) against
    Blender's BKE_colorband_evaluate, 1 to 5 stops, on and off the 1/256 grid, at the stops, outside
    [0, 1]."""
    rng = np.random.default_rng(_seed("colorband", interp))
    for k in range(10):
        els = sorted(_ramp_elements(rng, 1 + k % 5))
        x = np.concatenate([rng.uniform(-0.2, 1.2, 200), np.arange(257) / 256.0, [p for p, _ in els],
                            [p + 1e-9 for p, _ in els], [p - 1e-9 for p, _ in els]])
        exp = np.array([O.colorband_evaluate(els, interp, f) for f in x])
        np.testing.assert_allclose(colorband(els, interp, x), exp, rtol=RTOL, atol=ATOL, err_msg=f"case {k}")


@pytest.mark.parametrize("interp", ["CONSTANT", "LINEAR", "EASE"])
def test_color_ramp_cycles_table(interp):
    """Cycles does not evaluate the colour band per hit: intern/cycles/blender/util.h colorramp_to_array
    samples BKE_colorband_evaluate at i / 256 (257 entries, RAMP_TABLE_SIZE) and kernel/svm/ramp.h
    rgb_ramp_lookup reads that table (Fac clamped to [0, 1]; linear lerp, Constant: the entry at
    floor(256 f)).  1 to 5 stops, Fac outside [0, 1]."""
    rng = np.random.default_rng(_seed("ramp", interp))
    check_values(_ramp_cases(rng, interp), ramp="cycles")


def test_color_ramp_table_differs_from_band():
    """The table is really what is read: off-grid stops with Ease and Constant differ from the exact band."""
    els = [(0.1003, (0.0, 0.2, 0.9, 1.0)), (0.4071, (1.0, 0.5, 0.0, 0.5)), (0.8123, (0.3, 1.0, 0.6, 0.0))]
    cases = [({"R": N("ShaderNodeValToRGB", {"Fac": f}, {"elements": els, "interpolation": ip})}, L("R", "Color"))
             for ip in ("EASE", "CONSTANT") for f in (0.25, 0.4072, 0.6)]
    C, sd, scene, hits = check_values(cases, ramp="cycles")
    band = np.array([O.colorband_evaluate(els, ip, f)[:3] for ip in ("EASE", "CONSTANT") for f in (0.25, 0.4072, 0.6)])
    assert np.max(np.abs(C[0::2, C_EMIT:C_EMIT + 3] - band)) > 1e-6


def test_color_ramp_on_grid_matches_cycles_table():
    """With stops on the 1/256 grid, a Linear ramp is exactly Cycles' table look-up."""
    rng = np.random.default_rng(12)
    cases = []
    for k in range(8):
        pos = np.sort(rng.choice(np.arange(1, 256), 2 + k % 3, replace=False)) / 256.0
        els = [(float(p), tuple(float(x) for x in rng.uniform(0, 1, 4))) for p in pos]
        for f in rng.uniform(-0.1, 1.1, 6):
            node = N("ShaderNodeValToRGB", {"Fac": float(f)}, {"elements": els, "interpolation": "LINEAR"})
            cases.append(({"R": node}, L("R", "Color")))
    check_values(cases, ramp="cycles")


def test_rgb_curves():
    rng = np.random.default_rng(13)
    cases = []
    for k in range(16):
        n = [256, 17, 2, 5][k % 4]
        x = np.linspace(0.0, 1.0, n)
        table = np.stack([x ** rng.uniform(0.3, 3.0), np.clip(x + rng.normal(0, 0.1, n), 0, 1.2), 1.0 - x])
        node = N("ShaderNodeRGBCurve", {"Fac": float(rng.uniform(-0.5, 1.5)), "Color": _vec(rng, -0.3, 1.3)},
                 {"table": table.tolist()})
        cases.append(({"C": node}, L("C", "Color")))
    check_values(cases)


# ----------------------------------------------------------------------------
# Coordinates and geometry (per-hit values)
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("output", ["Generated", "UV", "Object", "Reflection"])
def test_texture_coordinate(output):
    nodes = {"T": N("ShaderNodeTexCoord")}
    check_values([(nodes, L("T", output))], hits_per_case=40, seed=_seed("texco", output))


@pytest.mark.parametrize("uv_map", ["", "UVMap", "Second", "Missing"])
def test_uv_map(uv_map):
    nodes = {"U": N("ShaderNodeUVMap", props={"uv_map": uv_map})}
    check_values([(nodes, L("U", "UV"))], hits_per_case=30, seed=_seed("uv", uv_map))


@pytest.mark.parametrize("output", ["Position", "Normal", "True Normal", "Incoming", "Backfacing"])
def test_geometry(output):
    nodes = {"G": N("ShaderNodeNewGeometry")}
    C, sd, scene, hits = check_values([(nodes, L("G", output))], hits_per_case=40, seed=_seed("geo", output))
    if output == "Backfacing":
        assert 0 < np.sum(hits["D"] @ NG > 0) < len(hits["D"])


def test_fresnel():
    """Fresnel (view-dependent, written with Math instructions by the compiler) against Cycles'
    formula: IORs below, at and above 1 (total internal reflection on back faces), a per-hit IOR,
    a linked Normal."""
    cases = [({"F": N("ShaderNodeFresnel", {"IOR": ior})}, L("F", "Fac")) for ior in (1.0, 1.33, 1.5, 2.4, 0.7, -1.0)]
    cases.append(({"G": N("ShaderNodeNewGeometry"),
                   "M": N("ShaderNodeMath", {"Value": L("G", "Backfacing"), "Value_001": 1.45},
                          {"operation": "ADD"}),
                   "F": N("ShaderNodeFresnel", {"IOR": L("M", "Value")})}, L("F", "Fac")))
    cases.append(({"V": N("ShaderNodeVectorMath", {"Vector": (0.3, -0.2, 0.9)}, {"operation": "NORMALIZE"}),
                   "F": N("ShaderNodeFresnel", {"IOR": 1.6, "Normal": L("V", "Vector")})}, L("F", "Fac")))
    C, sd, scene, hits = check_values(cases, hits_per_case=40, seed=_seed("fresnel"))
    assert 0 < np.sum(hits["D"] @ NG > 0) < len(hits["D"])


@pytest.mark.parametrize("output", ["Fresnel", "Facing"])
def test_layer_weight(output):
    """Layer Weight's two outputs against Cycles' formulas for blends inside, at the ends of and
    outside [0, 1] (0.5: the plain facing term), a per-hit blend, a linked Normal."""
    cases = [({"W": N("ShaderNodeLayerWeight", {"Blend": b})}, L("W", output))
             for b in (0.0, 0.2, 0.5, 0.7, 0.99, 1.0, -0.3, 1.3)]
    cases.append(({"G": N("ShaderNodeNewGeometry"),
                   "M": N("ShaderNodeMath", {"Value": L("G", "Backfacing"), "Value_001": 0.3, "Value_002": 0.35},
                          {"operation": "MULTIPLY_ADD"}),
                   "W": N("ShaderNodeLayerWeight", {"Blend": L("M", "Value")})}, L("W", output)))
    cases.append(({"V": N("ShaderNodeVectorMath", {"Vector": (-0.5, 0.1, 0.8)}, {"operation": "NORMALIZE"}),
                   "W": N("ShaderNodeLayerWeight", {"Blend": 0.3, "Normal": L("V", "Vector")})}, L("W", output)))
    check_values(cases, hits_per_case=40, seed=_seed("layer_weight", output))


@pytest.mark.parametrize("vtype", ["POINT", "TEXTURE", "VECTOR", "NORMAL"])
def test_mapping(vtype):
    rng = np.random.default_rng(_seed("mapping", vtype))
    cases = []
    for k in range(24):
        sc = _vec(rng, -2, 2)
        if k % 4 == 0:
            sc = (0.0, sc[1], sc[2])                              # a zero scale: safe division
        node = N("ShaderNodeMapping", {"Vector": _vec(rng), "Location": _vec(rng), "Rotation": _vec(rng, -4, 4),
                                       "Scale": sc}, {"vector_type": vtype})
        cases.append(({"M": node}, L("M", "Vector")))
    cases.append(({"M": N("ShaderNodeMapping", {"Vector": (0.0, 0.0, 0.0)}, {"vector_type": vtype})}, L("M", "Vector")))
    # driven by the hit's UV, unlinked sockets at Blender's defaults
    cases.append(({"T": N("ShaderNodeTexCoord"), "M": N("ShaderNodeMapping", {"Vector": L("T", "UV"),
                                                                              "Rotation": (0.3, -0.2, 1.1)},
                                                        {"vector_type": vtype})}, L("M", "Vector")))
    check_values(cases, hits_per_case=2)


# ----------------------------------------------------------------------------
# Textures
# ----------------------------------------------------------------------------
def test_checker():
    rng = np.random.default_rng(14)
    cases = []
    for _ in range(20):
        node = N("ShaderNodeTexChecker", {"Vector": _vec(rng, -2, 2), "Color1": _vec(rng, -0.5, 1.5),
                                          "Color2": _vec(rng, -0.5, 1.5), "Scale": float(rng.uniform(-6, 6))})
        cases += [({"C": node}, L("C", "Color")), ({"C": node}, L("C", "Fac"))]
    # implicit Generated coordinates (per hit)
    node = N("ShaderNodeTexChecker", {"Color1": (1.0, 0.2, 0.0), "Color2": (0.0, 0.3, 1.0), "Scale": 3.7})
    cases += [({"C": node}, L("C", "Color")), ({"C": node}, L("C", "Fac"))]
    check_values(cases, hits_per_case=12)


@pytest.mark.parametrize("gtype", list(GRADIENT_TYPES))
def test_gradient(gtype):
    rng = np.random.default_rng(_seed("gradient", gtype))
    cases = []
    for _ in range(20):
        node = N("ShaderNodeTexGradient", {"Vector": _vec(rng, -1.5, 1.5)}, {"gradient_type": gtype})
        cases += [({"G": node}, L("G", "Fac")), ({"G": node}, L("G", "Color"))]
    node = N("ShaderNodeTexGradient", {"Vector": (0.0, 0.0, 0.0)}, {"gradient_type": gtype})
    cases.append(({"G": node}, L("G", "Fac")))
    node = N("ShaderNodeTexGradient", {}, {"gradient_type": gtype})        # Generated coordinates
    cases.append(({"G": node}, L("G", "Fac")))
    # object coordinates through a Mapping, per hit
    cases.append(({"T": N("ShaderNodeTexCoord"),
                   "M": N("ShaderNodeMapping", {"Vector": L("T", "Object"), "Location": (-0.8, -0.4, 0.1),
                                                "Scale": (1.3, 0.9, 1.1)}),
                   "G": N("ShaderNodeTexGradient", {"Vector": L("M", "Vector")}, {"gradient_type": gtype})},
                  L("G", "Fac")))
    check_values(cases, hits_per_case=6)


def _textures(rng):
    return [Texture(rng.integers(0, 256, (5, 7, 4)).astype(np.uint8), colorspace="sRGB", name="rgba8"),
            Texture(rng.uniform(0, 3, (4, 3, 3)).astype(np.float32), colorspace="Linear", name="hdr"),
            Texture(rng.integers(0, 256, (3, 4, 1)).astype(np.uint8), colorspace="Non-Color", name="grey")]


@pytest.mark.parametrize("ext", ["REPEAT", "EXTEND", "CLIP", "MIRROR"])
@pytest.mark.parametrize("interp", ["Closest", "Linear", "Cubic", "Smart"])
def test_image_texture(interp, ext):
    """Image Texture: implicit UV (render-active map), a linked vector (the second UV map through a
    Mapping: several tiles, Clip's border fade), for sRGB RGBA bytes (Color with associated alpha,
    as Cycles holds it), linear HDR floats and one-channel images; Color and Alpha."""
    rng = np.random.default_rng(_seed("image", interp, ext))
    texs = _textures(rng)
    for img in range(len(texs)):
        props = {"image": img, "interpolation": interp, "extension": ext}
        implicit = N("ShaderNodeTexImage", {}, props)
        cases = [({"I": implicit}, L("I", "Color")), ({"I": implicit}, L("I", "Alpha"))]
        scale = (1.2, 1.1, 1.0) if ext == "CLIP" else (2.3, -1.7, 1.0)
        loc = (-0.1, -0.05, 0.0) if ext == "CLIP" else (0.0, 0.0, 0.0)
        linked = {"U": N("ShaderNodeUVMap", props={"uv_map": "Second" if ext != "CLIP" else "UVMap"}),
                  "M": N("ShaderNodeMapping", {"Vector": L("U", "UV"), "Scale": scale, "Location": loc}),
                  "I": N("ShaderNodeTexImage", {"Vector": L("M", "Vector")}, props)}
        cases += [(linked, L("I", "Color")), (linked, L("I", "Alpha"))]
        check_values(cases, textures=texs, hits_per_case=16, seed=img,
                     atol=SRGB_ATOL if texs[img].is_srgb else ATOL)


def test_udim_image_texture():
    """A UDIM image (``props["tiles"]``): tiles 1001, 1002 and 1011 (other sizes and kinds), 1012
    missing; the UV scaled over 3 x 2 tiles and shifted below 0: each hit reads its tile (magenta
    in the missing one and outside), Color and Alpha, every interpolation; the table follows the
    instruction in the program, and an instruction after it (a Math on the Alpha) still runs."""
    rng = np.random.default_rng(41)
    texs = _textures(rng) + [Texture(rng.uniform(0, 1, (3, 2, 4)).astype(np.float16), colorspace="Linear Rec.709",
                                     name="half")]
    tiles = [[1001, 0], [1002, 3], [1011, 1]]
    cases = []
    for interp in ("Closest", "Linear", "Cubic"):
        props = {"image": 0, "tiles": tiles, "interpolation": interp, "extension": "REPEAT"}
        nodes = {"U": N("ShaderNodeUVMap", props={"uv_map": "Second"}),
                 "M": N("ShaderNodeMapping", {"Vector": L("U", "UV"), "Scale": (3.0, 2.0, 1.0),
                                              "Location": (-0.2, -0.1, 0.0)}),
                 "I": N("ShaderNodeTexImage", {"Vector": L("M", "Vector")}, props),
                 "A": N("ShaderNodeMath", {0: L("I", "Alpha"), 1: 0.5}, {"operation": "MULTIPLY"})}
        cases += [(nodes, L("I", "Color")), (nodes, L("A", "Value"))]
    C, *_ = check_values(cases, textures=texs, hits_per_case=24, seed=7, atol=SRGB_ATOL)
    em = C[:, C_EMIT:C_EMIT + 3]
    assert np.any(np.all(np.isclose(np.abs(em), (1.0, 0.0, 1.0)), axis=1)), "no hit read the missing tile"
    # in an ACEScg scene each tile is converted by its matrix
    check_values(cases, textures=texs, hits_per_case=24, seed=8, atol=1e-6, rtol=1e-6, working="ACESCG")


def test_working_space_conversions():
    """ACEScg / Rec.2020 working spaces: a colour into a value socket and RGB to BW weigh by the
    space's luminance (Y of its RGB -> XYZ), images of other primaries are converted per texel;
    the Rec.709 weights would give other values (checked)."""
    rng = np.random.default_rng(43)
    texs = _textures(rng)
    cases = []
    for img in range(len(texs)):
        nodes = {"I": N("ShaderNodeTexImage", {}, {"image": img, "interpolation": "Linear"}),
                 "B": N("ShaderNodeRGBToBW", {"Color": L("I", "Color")}),
                 "M": N("ShaderNodeMath", {0: L("I", "Color"), 1: 1.0}, {"operation": "MULTIPLY"})}
        cases += [(nodes, L("I", "Color")), (nodes, L("B", "Val")), (nodes, L("M", "Value"))]
    for working in ("ACESCG", "REC2020"):
        check_values(cases, textures=texs, hits_per_case=12, seed=3, atol=1e-6, rtol=1e-6, working=working)
    with pytest.raises(AssertionError):          # the oracle tells the spaces apart
        g = [emit_graph(cases[1][0], cases[1][1], 1.0)]
        scene = make_scene(g, texs)
        hits = make_hits(4, np.random.default_rng(1))
        C, _ = run_kernel(scene, hits, np.zeros(4, np.int64))
        exp = [row["emission"] for row in oracle_rows(scene, hits, np.zeros(4, np.int64), working="ACESCG")]
        np.testing.assert_allclose(C[:, C_EMIT:C_EMIT + 3], exp, rtol=1e-6, atol=1e-6)


def test_image_texture_clip_far_outside():
    """Clip: coordinates well outside the image read (0, 0, 0), alpha 0 (as in Cycles)."""
    rng = np.random.default_rng(15)
    texs = _textures(rng)
    cases = []
    for interp in ("Closest", "Linear", "Cubic"):
        for loc in ((1.6, 0.3, 0.0), (-0.9, -0.95, 0.0), (0.2, 2.5, 0.0)):
            nodes = {"T": N("ShaderNodeTexCoord"),
                     "M": N("ShaderNodeMapping", {"Vector": L("T", "UV"), "Location": loc}),
                     "I": N("ShaderNodeTexImage", {"Vector": L("M", "Vector")},
                            {"image": 0, "interpolation": interp, "extension": "CLIP"})}
            cases += [(nodes, L("I", "Color")), (nodes, L("I", "Alpha"))]
    C, *_ = check_values(cases, textures=texs, hits_per_case=4)
    assert np.all(C[:, C_EMIT:C_EMIT + 3] == 0.0)


def test_image_texture_missing_image_colour():
    """No image: magenta (1, 0, 1), as Cycles (IMAGE_MISSING_RGBA); the program says so."""
    nodes = {"I": N("ShaderNodeTexImage", {}, {"image": -1})}
    C, sd, *_ = check_values([(nodes, L("I", "Color"))], sd_clean=False)
    assert any("has no image" in u for u in sd.unsupported)
    np.testing.assert_array_equal(C[0, C_EMIT:C_EMIT + 3], [1.0, 0.0, 1.0])


def test_image_texture_missing_image_alpha():
    """Cycles util/types_image.h IMAGE_MISSING_RGBA = (1, 0, 1, 1): the Alpha of an Image Texture
    without an image is 1."""
    nodes = {"I": N("ShaderNodeTexImage", {}, {"image": -1})}
    C, *_ = check_values([(nodes, L("I", "Alpha"))], sd_clean=False)
    np.testing.assert_array_equal(C[0, C_EMIT:C_EMIT + 3], 1.0)


def _one_texel_graph(out_alpha: bool):
    """Emission Color = the Image Texture's Color; Strength = its Alpha (out_alpha) or 1."""
    nodes = {"I": N("ShaderNodeTexImage", {}, {"image": 0, "interpolation": "Closest"})}
    strength = L("I", "Alpha") if out_alpha else 1.0
    nodes["E"] = N("ShaderNodeEmission", {"Color": L("I", "Color"), "Strength": strength})
    return surface(nodes, "E")


def test_image_texture_rgba_colour_is_premultiplied():
    """Blender's byte images reach Cycles with associated alpha: intern/cycles/blender/image.cpp
    load_byte_pixels premultiplies (c * a) / 255 in the stored (sRGB) encoding, and kernel/svm/image.h
    svm_image_texture divides by alpha only when the Alpha output is linked
    (NODE_IMAGE_ALPHA_UNASSOCIATE), before the sRGB conversion."""
    px = np.array([[[200, 120, 40, 128]]], np.uint8)                 # one texel, alpha ~ 0.5
    tex = Texture(px, colorspace="sRGB")
    scene = make_scene([_one_texel_graph(False), _one_texel_graph(True)], [tex])
    hits = make_hits(2, np.random.default_rng(0))
    C, _ = run_kernel(scene, hits, np.arange(2))
    a = px[0, 0, 3] / 255.0
    premult = (px[0, 0, :3].astype(np.int64) * int(px[0, 0, 3])) // 255
    np.testing.assert_allclose(C[0, C_EMIT:C_EMIT + 3], TO.srgb_to_linear(premult / 255.0), rtol=RTOL,
                               atol=SRGB_ATOL)
    np.testing.assert_allclose(C[1, C_EMIT:C_EMIT + 3], TO.srgb_to_linear(premult / 255.0 / a) * a, rtol=RTOL,
                               atol=SRGB_ATOL)


def _alpha_textures(rng):
    """RGBA images (alpha 0 and 1 texels included): straight and premultiplied ones, which Cycles
    un-associates when their Alpha is linked, and one with alpha mode NONE (alpha 1)."""
    def rgba(H, W, premul=False):
        px = rng.integers(0, 256, (H, W, 4)).astype(np.uint8)
        px[0, 0, 3], px[0, 1, 3] = 0, 255
        if premul:
            px[:, :, :3] = (px[:, :, :3].astype(np.int64) * px[:, :, 3:4]) // 255
        return px

    f = rng.uniform(0.0, 2.0, (3, 5, 4)).astype(np.float32)
    f[:, :, 3] = rng.uniform(0.0, 1.0, (3, 5))
    f[0, 0, 3] = 0.0
    return [Texture(rgba(5, 7), colorspace="sRGB", name="straight8"),
            Texture(rgba(4, 3, premul=True), colorspace="sRGB", alpha_mode="PREMUL", name="premul8"),
            Texture(rgba(3, 4), colorspace="Linear", name="straight8lin"),
            Texture(f, colorspace="Linear", name="straightf"),
            Texture(f.copy(), colorspace="Linear", alpha_mode="PREMUL", name="premulf"),
            Texture(rgba(4, 4), colorspace="sRGB", alpha_mode="NONE", name="none8")]


def _alpha_graphs(img: int, interp: str, ext: str):
    """Graphs reading an Image Texture's Color with its Alpha linked (so Cycles un-associates):
    Emission Color x Strength = Alpha; Principled Base Color with Alpha = Alpha; a Mix by Alpha.
    And the Color alone (associated) for comparison."""
    props = {"image": img, "interpolation": interp, "extension": ext}
    uv = {"U": N("ShaderNodeUVMap", props={"uv_map": "Second"}),
          "M": N("ShaderNodeMapping", {"Vector": L("U", "UV"), "Scale": (1.3, -1.1, 1.0), "Location": (0.1, 0.2, 0)})}
    img_node = lambda: N("ShaderNodeTexImage", {"Vector": L("M", "Vector")}, props)   # noqa: E731
    emit = dict(uv, I=img_node(), E=N("ShaderNodeEmission", {"Color": L("I", "Color"), "Strength": L("I", "Alpha")}))
    princ = dict(uv, I=img_node(), P=N("ShaderNodeBsdfPrincipled", {"Base Color": L("I", "Color"),
                                                                    "Alpha": L("I", "Alpha")}))
    mix = dict(uv, I=img_node(), X=N("ShaderNodeMix", {"Factor_Float": L("I", "Alpha"), "A_Color": (0.2, 0.9, 0.4),
                                                      "B_Color": L("I", "Color")},
                                     {"data_type": "RGBA", "blend_type": "MIX"}),
               E=N("ShaderNodeEmission", {"Color": L("X", "Result_Color"), "Strength": 1.0}))
    plain = dict(uv, I=img_node(), E=N("ShaderNodeEmission", {"Color": L("I", "Color"), "Strength": 1.0}))
    return [surface(emit, "E"), surface(princ, "P"), surface(mix, "E"), surface(plain, "E")]


@pytest.mark.parametrize("interp", ["Closest", "Linear", "Cubic"])
def test_image_texture_alpha_linked_unassociates(interp):
    """ImageTextureNode::compile sets NODE_IMAGE_ALPHA_UNASSOCIATE when the Alpha output is linked
    (Principled Alpha, a Mix factor, an Emission Strength): the Color output is then the
    interpolated colour divided by the interpolated alpha (svm_image_texture), straight and
    premultiplied images alike; NONE images have alpha 1 (nothing to divide)."""
    rng = np.random.default_rng(_seed("alpha-linked", interp))
    texs = _alpha_textures(rng)
    graphs = [g for img in range(len(texs)) for g in _alpha_graphs(img, interp, "REPEAT")]
    per = 12
    mat = np.repeat(np.arange(len(graphs)), per)
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs, texs)
    C, sd = run_kernel(scene, hits, mat)
    assert not sd.unsupported, sd.unsupported
    rows = oracle_rows(scene, hits, mat, C)          # Principled rows: the leaf the walk chose by Alpha
    kind = mat % 4
    emit = kind != 1
    _compare_rows(C[emit], [r for r, e in zip(rows, emit) if e], cols=("emission",), atol=SRGB_ATOL)
    _compare_rows(C[~emit], [r for r, e in zip(rows, emit) if not e], cols=("base",), atol=SRGB_ATOL)
    # the flag matters: Principled Base Color (Alpha linked: un-associated) vs the plain Emission
    # colour (Alpha not linked: associated), straight images
    for img in (0, 3):
        rows_b = slice((4 * img + 1) * per, (4 * img + 2) * per)
        rows_p = slice((4 * img + 3) * per, (4 * img + 4) * per)
        opaque = C[rows_b, C_PASS] == 0                              # the BSDF, not its Alpha's transparency
        assert opaque.any()
        assert np.max(np.abs(C[rows_b, C_BASE:C_BASE + 3][opaque]
                             - np.clip(C[rows_p, C_EMIT:C_EMIT + 3], 0, 1)[opaque])) > 1e-3


def test_image_texture_alpha_linked_channel_packed():
    rng = np.random.default_rng(31)
    px = rng.integers(1, 255, (4, 5, 4)).astype(np.uint8)
    texs = [Texture(px, colorspace="sRGB", alpha_mode="CHANNEL_PACKED")]
    graphs = _alpha_graphs(0, "Linear", "REPEAT")
    mat = np.repeat(np.arange(len(graphs)), 8)
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs, texs)
    C, _ = run_kernel(scene, hits, mat)
    rows = oracle_rows(scene, hits, mat, C)
    _compare_rows(C[mat == 0], [r for r, m in zip(rows, mat) if m == 0], cols=("emission",), atol=SRGB_ATOL)


def test_image_texture_alpha_linked_data_image():
    rng = np.random.default_rng(32)
    px = rng.integers(1, 255, (4, 5, 4)).astype(np.uint8)
    texs = [Texture(px, colorspace="Non-Color")]
    graphs = _alpha_graphs(0, "Closest", "REPEAT")
    mat = np.repeat(np.arange(len(graphs)), 8)
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs, texs)
    C, _ = run_kernel(scene, hits, mat)
    rows = oracle_rows(scene, hits, mat, C)
    _compare_rows(C[mat == 0], [r for r, m in zip(rows, mat) if m == 0], cols=("emission",), atol=SRGB_ATOL)


def test_image_texture_alpha_linked_to_unused_node():
    rng = np.random.default_rng(33)
    texs = [Texture(rng.integers(0, 256, (3, 4, 4)).astype(np.uint8), colorspace="sRGB")]
    nodes = {"I": N("ShaderNodeTexImage", {}, {"image": 0, "interpolation": "Linear"}),
             "Unused": N("ShaderNodeMath", {"Value": L("I", "Alpha"), "Value_001": 2.0}, {"operation": "ADD"})}
    check_values([(nodes, L("I", "Color"))], textures=texs, hits_per_case=12, atol=SRGB_ATOL)


# ----------------------------------------------------------------------------
# A whole material (many nodes, per-hit inputs)
# ----------------------------------------------------------------------------
def _big_graph(k: int, img: int = 0) -> ShaderGraph:
    nodes = {
        "T": N("ShaderNodeTexCoord"),
        "Map": N("ShaderNodeMapping", {"Vector": L("T", "UV"), "Location": (0.1 * k, -0.2, 0.0),
                                       "Rotation": (0.0, 0.0, 0.3 + 0.1 * k), "Scale": (1.5, 2.0, 1.0)},
                 {"vector_type": "POINT"}),
        "Chk": N("ShaderNodeTexChecker", {"Vector": L("Map", "Vector"), "Color1": (0.9, 0.2, 0.1),
                                          "Color2": (0.1, 0.6, 0.9), "Scale": 3.0}),
        "Grad": N("ShaderNodeTexGradient", {"Vector": L("T", "Object")}, {"gradient_type": "RADIAL"}),
        "Img": N("ShaderNodeTexImage", {"Vector": L("Map", "Vector")}, {"image": img, "interpolation": "Cubic"}),
        "Mix": N("ShaderNodeMix", {"Factor_Float": L("Grad", "Fac"), "A_Color": L("Chk", "Color"),
                                   "B_Color": L("Img", "Color")},
                 {"data_type": "RGBA", "blend_type": ["OVERLAY", "SCREEN", "HUE", "SOFT_LIGHT"][k % 4]}),
        "HSV": N("ShaderNodeHueSaturation", {"Hue": 0.55, "Saturation": 1.3, "Value": 0.9, "Fac": 0.8,
                                             "Color": L("Mix", "Result_Color")}),
        "Sep": N("ShaderNodeSeparateColor", {"Color": L("HSV", "Color")}, {"mode": "HSV"}),
        "Rough": N("ShaderNodeMapRange", {"Value": L("Sep", "Blue"), "From Min": 0.0, "From Max": 1.0,
                                          "To Min": 0.1, "To Max": 0.8}, {"interpolation_type": "SMOOTHSTEP"}),
        "Geo": N("ShaderNodeNewGeometry"),
        "Metal": N("ShaderNodeMath", {"Value": L("Geo", "Backfacing"), "Value_001": L("Chk", "Fac"),
                                      "Value_002": 0.0}, {"operation": "MAXIMUM"}),
        "Ramp": N("ShaderNodeValToRGB", {"Fac": L("Img", "Alpha")},
                  {"elements": [(0.0, (0, 0, 0, 1)), (0.5, (1.0, 0.5, 0.0, 1.0)), (1.0, (1, 1, 1, 1))],
                   "interpolation": "LINEAR"}),
        "Emit": N("ShaderNodeVectorMath", {"Vector": L("Ramp", "Color"), "Vector_001": L("T", "Reflection"),
                                           "Scale": 0.5}, {"operation": "SCALE"}),
        "P": N("ShaderNodeBsdfPrincipled", {"Base Color": L("HSV", "Color"), "Metallic": L("Metal", "Value"),
                                            "Roughness": L("Rough", "Result"), "IOR": 1.45,
                                            "Transmission Weight": L("Sep", "Red"), "Specular IOR Level": 0.3,
                                            "Emission Color": L("Emit", "Vector"), "Emission Strength": 2.0}),
    }
    return surface(nodes, "P")


def _compare_rows(C, rows, cols=("base", "tint_t", "tint_r", "emission", "metallic", "transmission", "roughness",
                                 "specular", "ior"), atol=ATOL):
    col = {"base": slice(C_BASE, C_BASE + 3), "tint_t": slice(C_TINT_T, C_TINT_T + 3),
           "tint_r": slice(C_TINT_R, C_TINT_R + 3),
           "emission": slice(C_EMIT, C_EMIT + 3), "metallic": C_METALLIC,
           "transmission": C_TRANSMISSION, "roughness": C_ROUGHNESS, "specular": C_SPECULAR, "ior": C_IOR}
    for name in cols:
        got = C[:, col[name]]
        exp = np.array([r[name] for r in rows])
        np.testing.assert_allclose(got, exp, rtol=RTOL, atol=atol, err_msg=name)


def test_whole_material_per_hit():
    rng = np.random.default_rng(16)
    texs = _textures(rng)
    graphs = [_big_graph(k, img=1 + k % 2) for k in range(4)]     # linear images (sRGB: test_image_texture)
    mat = np.repeat(np.arange(4), 50)
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs, texs)
    C, sd = run_kernel(scene, hits, mat)
    assert not sd.unsupported, sd.unsupported
    _compare_rows(C, oracle_rows(scene, hits, mat))
    _check_derived(C)


# ----------------------------------------------------------------------------
# Shaders and the closure row
# ----------------------------------------------------------------------------
def _check_derived(C):
    """Derived columns = pack_materials of a Material with the row's primary values."""
    for r in range(C.shape[0]):
        m = Material(base_color=C[r, C_BASE:C_BASE + 3].copy(), metallic=C[r, C_METALLIC],
                     transmission=C[r, C_TRANSMISSION], roughness=C[r, C_ROUGHNESS], specular=C[r, C_SPECULAR],
                     ior=C[r, C_IOR], emission=C[r, C_EMIT:C_EMIT + 3].copy(),
                     transmission_tint=C[r, C_TINT_T:C_TINT_T + 3].copy(),
                     reflection_tint=C[r, C_TINT_R:C_TINT_R + 3].copy(),
                     constant_fresnel=bool(C[r, C_METAL_CONST] > 0))
        ref = pack_materials([m])[0]
        keep = np.ones(N_CLOSURE, bool)
        keep[C_PROGRAM] = False
        keep[C_TRANSPARENT:C_PASS + 1] = False      # per-hit choices (test_transparent_add_and_alpha_closures)
        np.testing.assert_allclose(C[r, keep], ref[keep], rtol=0, atol=1e-12, err_msg=f"row {r}")


def _shader_graphs(rng):
    graphs = []
    for k in range(12):
        graphs.append(surface({"S": N("ShaderNodeBsdfPrincipled", {
            "Base Color": _vec(rng, -0.2, 1.2), "Metallic": float(rng.uniform(-0.2, 1.2)),
            "Roughness": float(rng.uniform(-0.2, 1.2)), "IOR": float(rng.uniform(0.5, 12.0)), "Alpha": 0.5,
            "Transmission Weight": float(rng.uniform(-0.2, 1.2)), "Specular IOR Level": float(rng.uniform(-0.2, 1.0)),
            "Emission Color": _vec(rng, -0.5, 2.0), "Emission Strength": float(rng.uniform(-1, 5))})}, "S"))
        graphs.append(surface({"S": N("ShaderNodeBsdfDiffuse", {"Color": _vec(rng, -0.2, 1.2)})}, "S"))
        for t in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            graphs.append(surface({"S": N(t, {"Color": _vec(rng, -0.2, 1.2),
                                              "Roughness": float(rng.uniform(-0.2, 1.2))})}, "S"))
        graphs.append(surface({"S": N("ShaderNodeBsdfGlass", {"Color": _vec(rng, -0.2, 1.2), "Roughness": float(
            rng.uniform(-0.2, 1.2)), "IOR": float(rng.uniform(0.5, 12.0))})}, "S"))
        graphs.append(surface({"S": N("ShaderNodeEmission", {"Color": _vec(rng, -0.5, 2.0),
                                                             "Strength": float(rng.uniform(-1, 20))})}, "S"))
    # Blender's defaults (no inputs given)
    for t in SHADER_OUT:
        if t not in ("ShaderNodeMixShader", "ShaderNodeAddShader"):
            graphs.append(surface({"S": N(t)}, "S"))
    return graphs


def test_shaders_closure_rows():
    rng = np.random.default_rng(17)
    graphs = _shader_graphs(rng)
    mat = np.arange(len(graphs))
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs)
    C, sd = run_kernel(scene, hits, mat)
    assert not sd.unsupported
    _compare_rows(C, oracle_rows(scene, hits, mat, C))
    _check_derived(C)
    # the metal lobe's Fresnel: constant (its colour) for a Glossy BSDF, Schlick for the others
    for r, g in enumerate(graphs):
        glossy = bool({n.type for n in g.nodes.values()} & {"ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"})
        assert C[r, C_METAL_CONST] == (1.0 if glossy else 0.0), r


def test_shader_inputs_linked():
    """Shader sockets fed by value nodes (colour, float -> colour, colour -> float)."""
    rng = np.random.default_rng(18)
    graphs = []
    for k in range(10):
        col = _vec(rng, 0, 1)
        nodes = {"R": N("ShaderNodeRGB", props={"value": col}),
                 "V": N("ShaderNodeValue", props={"value": float(rng.uniform(0, 1))}),
                 "S": N("ShaderNodeBsdfPrincipled", {"Base Color": L("V", "Value"), "Metallic": L("R", "Color"),
                                                     "Roughness": L("V", "Value"), "Emission Color": L("R", "Color"),
                                                     "Emission Strength": L("V", "Value")})}
        graphs.append(surface(nodes, "S"))
        graphs.append(surface({"R": nodes["R"], "S": N("ShaderNodeBsdfGlass", {"Color": L("R", "Color"),
                                                                               "IOR": L("R", "Color")})}, "S"))
    mat = np.arange(len(graphs))
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs)
    C, _ = run_kernel(scene, hits, mat)
    _compare_rows(C, oracle_rows(scene, hits, mat))


# ----------------------------------------------------------------------------
# Mix Shader
# ----------------------------------------------------------------------------
RED, GREEN, BLUE = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def _mix_shader_graph(fac, a=RED, b=GREEN):
    nodes = {"A": N("ShaderNodeBsdfDiffuse", {"Color": a}), "B": N("ShaderNodeBsdfDiffuse", {"Color": b}),
             "X": N("ShaderNodeMixShader", {"Fac": fac, "Shader": L("A", "BSDF"), "Shader_001": L("B", "BSDF")})}
    return surface(nodes, "X")


@pytest.mark.parametrize("fac", [0.0, 0.1, 0.37, 0.5, 0.9, 1.0, -0.3, 1.4])
def test_mix_shader_frequency(fac):
    m = 20000
    scene = make_scene([_mix_shader_graph(fac)])
    hits = make_hits(m, np.random.default_rng(19))
    C, sd = run_kernel(scene, hits, np.zeros(m, np.int64), seed=1234)
    assert sd.uses_mix
    is_b = C[:, C_BASE + 1] == 1.0
    assert np.all(is_b | (C[:, C_BASE] == 1.0))
    f = min(max(fac, 0.0), 1.0)
    sigma = np.sqrt(max(f * (1 - f), 1e-12) / m)
    assert abs(is_b.mean() - f) < 5 * sigma + 1e-12
    # the choice is hash_uniform(seed, row) < Fac: B for exactly those rows
    u = np.array([svm.hash_uniform(1234, r) for r in range(m)])
    np.testing.assert_array_equal(is_b, u < f)
    # the oracle's weights
    leaves = O.evaluate(scene.materials[0].graph, oracle_hit(scene, hits, 0))
    assert [w for w, _ in leaves] == pytest.approx([1 - f, f])


def test_mix_shader_seeds_differ_and_repeat():
    m = 4000
    scene = make_scene([_mix_shader_graph(0.5)])
    hits = make_hits(m, np.random.default_rng(20))
    C1, _ = run_kernel(scene, hits, np.zeros(m, np.int64), seed=1)
    C1b, _ = run_kernel(scene, hits, np.zeros(m, np.int64), seed=1)
    C2, _ = run_kernel(scene, hits, np.zeros(m, np.int64), seed=2)
    np.testing.assert_array_equal(C1, C1b)
    b1, b2 = C1[:, C_BASE + 1] == 1.0, C2[:, C_BASE + 1] == 1.0
    assert 0.4 < np.mean(b1 == b2) < 0.6                          # independent choices


def test_mix_shader_nested_and_unconnected():
    """Nested mixes: leaf frequencies = the oracle's weights; an unconnected shader socket is black."""
    m = 30000
    nodes = {"A": N("ShaderNodeBsdfDiffuse", {"Color": RED}),
             "B": N("ShaderNodeEmission", {"Color": GREEN, "Strength": 3.0}),
             "C": N("ShaderNodeBsdfGlossy", {"Color": BLUE, "Roughness": 0.2}),
             "Fac2": N("ShaderNodeValue", props={"value": 0.65}),
             "In": N("ShaderNodeMixShader", {"Fac": L("Fac2", "Value"), "Shader": L("B", "Emission"),
                                             "Shader_001": L("C", "BSDF")}),
             "Out": N("ShaderNodeMixShader", {"Fac": 0.3, "Shader": L("A", "BSDF"), "Shader_001": L("In", "Shader")})}
    half = {"A": N("ShaderNodeBsdfDiffuse", {"Color": RED}),
            "X": N("ShaderNodeMixShader", {"Fac": 0.4, "Shader": L("A", "BSDF")})}
    scene = make_scene([surface(nodes, "Out"), surface(half, "X")])
    hits = make_hits(m, np.random.default_rng(21))
    mat = np.zeros(m, np.int64)
    mat[m // 2:] = 1
    C, _ = run_kernel(scene, hits, mat, seed=99)
    for mi, sl in ((0, slice(0, m // 2)), (1, slice(m // 2, m))):
        leaves = O.evaluate(scene.materials[mi].graph, oracle_hit(scene, hits, 0))
        rows = C[sl]
        n = rows.shape[0]
        for w, clo in leaves:
            exp = O.closure_row(clo)
            hit = np.all(np.isclose(rows[:, C_BASE:C_BASE + 3], exp["base"]), axis=1) & \
                np.all(np.isclose(rows[:, C_EMIT:C_EMIT + 3], exp["emission"]), axis=1) & \
                np.isclose(rows[:, C_METALLIC], exp["metallic"])
            assert abs(hit.mean() - w) < 5 * np.sqrt(w * (1 - w) / n) + 1e-12, (mi, w, hit.mean())
        mean_base = sum(w * O.closure_row(c)["base"] for w, c in leaves)
        np.testing.assert_allclose(rows[:, C_BASE:C_BASE + 3].mean(axis=0), mean_base, atol=0.02)


# ----------------------------------------------------------------------------
# Constant materials, unsupported nodes
# ----------------------------------------------------------------------------
def test_constant_materials_keep_their_rows():
    consts = [Material.diffuse((0.2, 0.5, 0.7)), Material.mirror(roughness=0.1), Material.glass(1.33),
              Material.emitter((3.0, 2.0, 1.0)),
              Material(base_color=np.array([0.3, 0.6, 0.3]), specular=0.5, roughness=0.4)]
    g = surface({"S": N("ShaderNodeBsdfDiffuse", {"Color": (0.1, 0.2, 0.3)})}, "S")
    mats = consts[:2] + [Material(graph=g)] + consts[2:]
    scene = make_scene(mats)
    ref = pack_materials(mats)
    m = 40
    mat = np.arange(m) % (len(mats) + 1) - 1                       # -1 = a miss
    hits = make_hits(m, np.random.default_rng(22))
    C, sd = run_kernel(scene, hits, mat)
    assert sd.uses_programs and sd.closures[2, C_PROGRAM] >= 0
    for r, mi in enumerate(mat):
        if mi == 2:
            np.testing.assert_allclose(C[r, C_BASE:C_BASE + 3], [0.1, 0.2, 0.3], rtol=0, atol=1e-15)
        else:
            np.testing.assert_array_equal(C[r], ref[mi] if mi >= 0 else ref[-1])
    # a scene without graphs: no programs, shade() reads the constant rows
    scene2 = make_scene(consts)
    sd2 = shading_data(scene2)
    assert not sd2.uses_programs
    h = Hits(t=np.ones(m), instance=np.zeros(m, np.int32), prim=np.zeros(m, np.int32), u=hits["bu"], v=hits["bv"],
             position=hits["P"], ng=hits["NG"], ns=hits["NS"], material=np.zeros(m, np.int32))
    mat2 = (np.arange(m) % (len(consts) + 1) - 1).astype(np.int32)
    C2 = np.zeros((m, N_CLOSURE))
    svm.shade(sd2, mat2, hit_geometry(h, hits["D"]), 0, C2)
    ref2 = pack_materials(consts)
    np.testing.assert_array_equal(C2, ref2[mat2])


@pytest.mark.parametrize("type_,output", [("ShaderNodeTexCoord", o) for o in ("Camera", "Window")]
                         + [("ShaderNodeNewGeometry", o) for o in ("Tangent", "Parametric", "Pointiness",
                                                                    "Random Per Island")])
def test_unsupported_outputs_are_reported(type_, output):
    node = N(type_)
    node.outputs[output] = O.SOCKET_TYPES[type_][output]
    prog = compile_graph(emit_graph({"T": node}, L("T", output), 1.0))
    assert any(f"{output} output" in u for u in prog.unsupported), prog.unsupported


def test_unsupported_nodes_use_socket_defaults():
    noise = Node("ShaderNodeLightPath", outputs={"Is Camera Ray": "VALUE", "Color": "RGBA"})
    cases = {
        # an unknown node into a colour and a float socket: Diffuse Color 0.8 grey
        "noise": surface({"Nz": noise, "S": N("ShaderNodeBsdfDiffuse", {"Color": L("Nz", "Color")})}, "S"),
        # an unsupported operation: Emission Strength at its default 1
        "vround": surface({"VM": N("ShaderNodeVectorMath", {"Vector": (1.0, 2.0, 3.0)}, {"operation": "ROUND"}),
                           "S": N("ShaderNodeEmission", {"Color": L("VM", "Vector"), "Strength": 2.0})}, "S"),
        "mathfoo": surface({"M": N("ShaderNodeMath", {"Value": 1.0}, {"operation": "FOO"}),
                            "S": N("ShaderNodeEmission", {"Color": (0.5, 0.25, 1.0), "Strength": L("M", "Value")})},
                           "S"),
        "curves": surface({"Cv": N("ShaderNodeRGBCurve", {"Color": (0.2, 0.3, 0.4)}),
                           "S": N("ShaderNodeBsdfDiffuse", {"Color": L("Cv", "Color")})}, "S"),
        "vmaprange": surface({"MR": N("ShaderNodeMapRange", {"Value": 0.3}, {"data_type": "FLOAT_VECTOR"}),
                              "S": N("ShaderNodeBsdfGlossy", {"Color": (0.3, 0.3, 0.3),
                                                              "Roughness": L("MR", "Result")})}, "S"),
        "shader": ShaderGraph(nodes={"S": Node("ShaderNodeBsdfToon", inputs={"Color": (1.0, 0.0, 0.0)},
                                               outputs={"BSDF": "SHADER"})}, surface=Link("S", "BSDF")),
        "cycle": surface({"A": N("ShaderNodeMixRGB", {"Fac": 0.5, "Color1": L("B", "Color"), "Color2": RED}),
                          "B": N("ShaderNodeMixRGB", {"Fac": 0.5, "Color1": L("A", "Color"), "Color2": BLUE}),
                          "S": N("ShaderNodeBsdfDiffuse", {"Color": L("A", "Color")})}, "S"),
    }
    expect_msg = {"noise": "ShaderNodeLightPath", "vround": "operation ROUND", "mathfoo": "operation FOO",
                  "curves": "no sampled curve table", "vmaprange": "vector data type",
                  "shader": "not a supported shader",
                  "cycle": "cycle"}
    for name, g in cases.items():
        prog = compile_graph(g)
        assert any(expect_msg[name] in u for u in prog.unsupported), (name, prog.unsupported)
    graphs = list(cases.values())
    mat = np.arange(len(graphs))
    hits = make_hits(len(mat), np.random.default_rng(23))
    scene = make_scene(graphs)
    C, sd = run_kernel(scene, hits, mat)
    assert len(sd.unsupported) >= len(graphs) and all(u.startswith("material ") for u in sd.unsupported)
    got = {name: C[i] for i, name in enumerate(cases)}
    np.testing.assert_allclose(got["noise"][C_BASE:C_BASE + 3], 0.8)
    np.testing.assert_allclose(got["vround"][C_EMIT:C_EMIT + 3], 2.0)          # Color at its default (1, 1, 1)
    np.testing.assert_allclose(got["mathfoo"][C_EMIT:C_EMIT + 3], [0.5, 0.25, 1.0])
    np.testing.assert_allclose(got["curves"][C_BASE:C_BASE + 3], 0.8)
    np.testing.assert_allclose(got["vmaprange"][C_ROUGHNESS], 0.5)
    np.testing.assert_allclose(got["shader"][C_BASE:C_BASE + 3], 0.8)
    # the cycle: B reads its socket default for A (0.5 grey), A mixes B with red
    b = 0.5 * np.array([0.5, 0.5, 0.5]) + 0.5 * np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(got["cycle"][C_BASE:C_BASE + 3], 0.5 * b + 0.5 * np.array([1.0, 0.0, 0.0]))
    # the oracle treats them alike (for the node types it knows to be unsupported)
    for name in ("noise", "shader", "cycle"):
        row = O.closure_row(O.evaluate(cases[name], oracle_hit(scene, hits, 0))[0][1])
        np.testing.assert_allclose(got[name][C_BASE:C_BASE + 3], row["base"])


def test_transparent_add_and_alpha_closures():
    """Transparent BSDF: an empty closure with C_PASS = 1 and its tint.  Principled Alpha a: the
    walk picks the BSDF with probability a, else a white transparent closure.  Add Shader: one
    input per hit with probability 1/2, at weight 2 (emission, tint and colour doubled)."""
    tint = (0.9, 0.5, 0.2)
    graphs = [
        surface({"T": N("ShaderNodeBsdfTransparent", {"Color": tint})}, "T"),
        surface({"P": N("ShaderNodeBsdfPrincipled", {"Base Color": (0.3, 0.6, 0.9), "Alpha": 0.3})}, "P"),
        surface({"E": N("ShaderNodeEmission", {"Color": (1.0, 0.5, 0.25), "Strength": 2.0}),
                 "T": N("ShaderNodeBsdfTransparent", {"Color": tint}),
                 "A": N("ShaderNodeAddShader", {"Shader": L("E", "Emission"), "Shader_001": L("T", "BSDF")})}, "A"),
    ]
    per = 4000
    mat = np.repeat(np.arange(len(graphs)), per)
    rng = np.random.default_rng(5)
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs)
    C, sd = run_kernel(scene, hits, mat)
    assert not sd.unsupported, sd.unsupported
    assert sd.transparent == frozenset({0, 1, 2})
    t, p, a = (slice(i * per, (i + 1) * per) for i in range(3))
    assert np.all(C[t, C_PASS] == 1) and np.allclose(C[t, C_TRANSPARENT:C_TRANSPARENT + 3], tint)
    assert np.all(C[t, C_BASE:C_BASE + 3] == 0) and np.all(C[t, C_EMIT:C_EMIT + 3] == 0)
    # Alpha 0.3: 70 % pass (binomial sd 0.7 %), white; the others are the BSDF
    passed = C[p, C_PASS] == 1
    assert abs(passed.mean() - 0.7) < 0.03
    assert np.allclose(C[p, C_TRANSPARENT:C_TRANSPARENT + 3][passed], 1.0)
    assert np.allclose(C[p, C_BASE:C_BASE + 3][~passed], (0.3, 0.6, 0.9))
    # glass tints: a transparent closure has none, a Principled BSDF reflects untinted (white)
    assert np.all(C[t, C_TINT_R:C_TINT_R + 3] == 0) and np.all(C[p, C_TINT_R:C_TINT_R + 3][passed] == 0)
    assert np.all(C[p, C_TINT_R:C_TINT_R + 3][~passed] == 1)
    # Add: half emission x 2, half transparency x 2; the means are the sums Cycles renders
    em = C[a, C_PASS] == 0
    assert abs(em.mean() - 0.5) < 0.03
    np.testing.assert_allclose(C[a, C_EMIT:C_EMIT + 3][em], np.tile([4.0, 2.0, 1.0], (em.sum(), 1)))
    np.testing.assert_allclose(C[a, C_TRANSPARENT:C_TRANSPARENT + 3][~em], np.tile(2 * np.asarray(tint), ((~em).sum(), 1)))


def test_color_attributes_and_attribute_node():
    """Color Attribute ("" = render-active, or by name) and Attribute (Geometry: a colour attribute,
    or a UV map by name as (u, v, 0)): corner values interpolated with the hit's barycentrics;
    a missing attribute reads 0; Object attributes are named and read 0."""
    rng = np.random.default_rng(41)
    cols = {"Col": rng.uniform(0, 1, (1, 3, 4)).astype(np.float32),
            "Wear": rng.uniform(0, 1, (1, 3, 4)).astype(np.float32)}
    cases = [
        ({"A": N("ShaderNodeVertexColor", props={"layer_name": ""})}, L("A", "Color")),
        ({"A": N("ShaderNodeVertexColor", props={"layer_name": "Wear"})}, L("A", "Color")),
        ({"A": N("ShaderNodeVertexColor", props={"layer_name": "Wear"})}, L("A", "Alpha")),
        ({"A": N("ShaderNodeAttribute", props={"attribute_type": "GEOMETRY", "attribute_name": "Col"})}, L("A", "Fac")),
        ({"A": N("ShaderNodeAttribute", props={"attribute_type": "GEOMETRY", "attribute_name": "Second"})},
         L("A", "Vector")),
        ({"A": N("ShaderNodeAttribute", props={"attribute_type": "GEOMETRY", "attribute_name": "Missing"})},
         L("A", "Color")),
    ]
    graphs = [emit_graph(nodes, out, 1.0) for nodes, out in cases]
    mat = np.repeat(np.arange(len(graphs)), 6)
    hits = make_hits(len(mat), rng)
    scene = make_scene(graphs)
    scene.meshes[0].color_layers = cols
    scene.meshes[0].color_render = "Col"
    C, sd = run_kernel(scene, hits, mat)
    assert not sd.unsupported, sd.unsupported
    exp = np.array([row["emission"] for row in oracle_rows(scene, hits, mat)])
    np.testing.assert_allclose(C[:, C_EMIT:C_EMIT + 3], exp, rtol=RTOL, atol=1e-6)
    assert np.ptp(exp[mat == 0], axis=0).max() > 0.01            # varies over the triangle
    assert np.all(exp[mat == 5] == 0.0)
    # An Object attribute: named, reads 0
    g = emit_graph({"A": N("ShaderNodeAttribute", props={"attribute_type": "OBJECT", "attribute_name": "x"})},
                   L("A", "Color"), 1.0)
    prog = compile_graph(g)
    assert any("Object attributes are not supported" in u for u in prog.unsupported)
