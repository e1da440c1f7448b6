"""Shader graph -> program words for the kernels' interpreter (layout: :mod:`stpm_core.nodes.ops`).

:func:`compile_graph` walks a :class:`~stpm_core.nodes.graph.ShaderGraph` from its Surface link.
Every value node the surface depends on is emitted once, in dependency order, into the program's
value section, which runs for every hit; the shader tree (Mix Shader choices, BSDFs, Emission)
goes to the closure section, which each hit walks to one closure.  Links are
converted as Blender converts them (colour -> float: the working space's luminance,
:func:`stpm_core.colorspaces.luma`; vector -> float: the average, float -> colour / vector: the
value in every channel).

What the interpreter cannot evaluate is never silently averaged: the node's output falls back to
the consuming socket's own default value and :class:`Program.unsupported` names the node, its type
and why (the render report lists it; issue 13 bakes such inputs where it can).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .graph import Link, ShaderGraph
from .ops import (BLEND_MODES, COLOR_MODES, CONVERT, EXTENSIONS, GRADIENT_TYPES, INTERPOLATIONS, LAYOUT,
                  MAP_RANGE_TYPES, MAPPING_TYPES, MATH_OPS, NORMAL_MAP_SPACES, OP, RAMP_INTERPOLATIONS, VMATH_OPS)

__all__ = ["Program", "compile_graph", "colorband", "SUPPORTED_NODES", "MAX_RAMP", "RAMP_TABLE", "CURVE_TABLE"]

MAX_RAMP = 32          # colour ramp elements (Blender allows 32)
LUMA_REC709 = (0.2126, 0.7152, 0.0722)   # colour -> float weights in Blender's default working space
RAMP_TABLE = 256       # a colour ramp is sampled at RAMP_TABLE + 1 points (Cycles' RAMP_TABLE_SIZE)
CURVE_TABLE = 256      # RGB Curves: samples of each channel's curve on [0, 1]

VEC, FLT = "vec", "float"
_KIND = {"VALUE": FLT, "INT": FLT, "BOOLEAN": FLT, "RGBA": VEC, "VECTOR": VEC}

CLOSURE_OPS = ("MIX_SHADER", "BSDF_PRINCIPLED", "BSDF_DIFFUSE", "BSDF_GLOSSY", "BSDF_GLASS", "EMISSION",
               "TRANSPARENT", "ADD_SHADER")
SHADERS = ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy",
           "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfGlass", "ShaderNodeEmission", "ShaderNodeMixShader",
           "ShaderNodeBsdfTransparent", "ShaderNodeAddShader")


@dataclass
class Program:
    """One material's program: ``words`` (float64) relocatable to any start (jumps are relative to
    the start and fixed by :func:`relocate`), and what was not supported."""

    words: np.ndarray
    unsupported: list = field(default_factory=list)
    uv_layers: list = field(default_factory=list)     # UV map names the program reads ("" = render-active)
    color_layers: list = field(default_factory=list)  # colour-attribute names it reads ("" = render-active)
    uses_mix: bool = False
    uses_normals: bool = False                         # rewrites the shading normal per hit
    uses_frames: bool = False                          # reads each hit's object-to-world normal matrix
    may_emit: bool = False                             # some closure's emission is not constant black
    may_pass: bool = False                             # some closure lets rays through (transparency)
    may_scatter: bool = False                          # some closure has a diffuse or glossy BSDF


class _Compiler:
    def __init__(self, graph: ShaderGraph, n_textures: int, uv_layers: list, color_layers: list | None = None,
                 luma=LUMA_REC709):
        self.g = graph
        self.luma = tuple(float(w) for w in luma)   # colour -> float weights of the working space
        self.color_layers = color_layers if color_layers is not None else []
        self.n_textures = n_textures
        self.consts: list[float] = []
        self.const_index: dict = {}
        self.code: list[float] = []
        self.n_slots = 0          # node-output slots (after the constants)
        self.outputs: dict = {}   # (node name, output id) -> (slot, kind), slot relative to the outputs area
        self.unsupported: list[str] = []
        self.uv_layers = uv_layers
        self.uses_mix = False
        self.busy: set = set()
        self.closure_code: list = []
        self.jumps: list = []
        self.offset = 0                # 1 / 2 while compiling a Bump node's displaced height
        self._reached = None           # names of the nodes that reach the surface (used())
        self.uses_normals = False      # a shader's Normal input is linked: NS is rewritten per hit
        self.uses_frames = False       # a node needs the object-to-world normal matrix of each hit
        self.may_emit = False          # an emission whose colour and strength are not constant zero
        self.may_pass = False          # a Transparent BSDF, or a Principled Alpha that is not a constant 1
        self.add_depth = 0             # Add Shaders above the shader being compiled
        self.may_scatter = False       # a Principled / Diffuse / Glossy closure (a non-delta lobe, likely)

    # -- slots ---------------------------------------------------------------------------
    # Output slots are numbered from 0 while compiling and shifted past the constants at the end:
    # a slot operand is stored as ("o", k) or ("c", k) until then.
    def const(self, values) -> tuple:
        key = tuple(float(v) for v in values)
        if key not in self.const_index:
            self.const_index[key] = len(self.consts)
            self.consts.extend(key)
        return ("c", self.const_index[key])

    def alloc(self, kind: str) -> tuple:
        s = self.n_slots
        self.n_slots += 3 if kind == VEC else 1
        return ("o", s)

    def emit(self, op: str, *operands) -> int:
        """Append an instruction: closure instructions (MIX_SHADER, BSDF_*, EMISSION) to the
        closure section, every other one to the value section; returns its index there."""
        assert len(operands) == len(LAYOUT[op]), (op, operands)
        code = self.closure_code if op in CLOSURE_OPS else self.code
        at = len(code)
        code.append(float(OP[op]))
        code.extend(operands)
        return at

    def warn(self, node_name: str, node, why: str) -> None:
        msg = f"node {node_name!r} ({node.type}): {why}"
        if msg not in self.unsupported:
            self.unsupported.append(msg)

    def _warn_anisotropy(self, node_name: str, node, ident: str) -> None:
        """Anisotropic GGX is not in the kernels: a linked or non-zero anisotropy renders isotropic."""
        v = node.inputs.get(ident, 0.0)
        if isinstance(v, Link) or (isinstance(v, (int, float)) and v != 0):
            self.warn(node_name, node, f"{ident} is not rendered (the highlight is isotropic, as with 0)")

    def used(self, name: str, ident: str) -> bool:
        """Is output ``ident`` of node ``name`` linked to an input of a node that reaches the
        surface?  (Cycles drops the rest before compiling.)"""
        if self._reached is None:
            seen, todo = set(), [self.g.surface.node] if self.g.surface is not None else []
            while todo:
                n = todo.pop()
                if n in seen or n not in self.g.nodes:
                    continue
                seen.add(n)
                todo.extend(v.node for v in self.g.nodes[n].inputs.values() if isinstance(v, Link))
            self._reached = seen
        return any(isinstance(v, Link) and v.node == name and v.socket == ident
                   for other in self._reached for v in self.g.nodes[other].inputs.values())

    # -- inputs ----------------------------------------------------------------------------
    def default(self, node, ident: str, kind: str, fallback):
        v = node.inputs.get(ident, fallback)
        if isinstance(v, Link):
            v = fallback
        if kind == VEC:
            if isinstance(v, (int, float)):
                v = (float(v),) * 3
            v = tuple(v)[:3]
            if len(v) < 3:                 # a short constant: pad with the fallback's components
                fb = fallback if isinstance(fallback, (tuple, list)) else (float(fallback),) * 3
                v = v + tuple(float(x) for x in tuple(fb)[len(v):3])
            return self.const(v)
        if isinstance(v, (tuple, list)):
            v = float(np.mean(v[:3]))
        return self.const((float(v),))

    def input(self, name: str, node, ident: str, kind: str, fallback=0.0, implicit=None):
        """Slot of input ``ident`` as ``kind``: the linked output converted, else the constant.
        implicit: a callable giving the slot of an unlinked vector input's implicit coordinate."""
        v = node.inputs.get(ident)
        if isinstance(v, Link):
            got = self.value(v)
            if got is None:
                return self.default(node, ident, kind, fallback)
            slot, k = got
            if k == kind:
                return slot
            out = self.alloc(kind)
            if kind == FLT:
                src_type = self.g.nodes[v.node].outputs.get(v.socket, "RGBA")
                self.emit("CONVERT", float(CONVERT["VECTOR_TO_FLOAT" if src_type == "VECTOR" else "COLOR_TO_FLOAT"]),
                          slot, out, self.const(self.luma))
            else:
                self.emit("CONVERT", float(CONVERT["FLOAT_TO_VEC"]), slot, out, self.const(self.luma))
            return out
        if v is None and implicit is not None:
            return implicit()
        return self.default(node, ident, kind, fallback)

    # -- value nodes ---------------------------------------------------------------------
    def value(self, link: Link):
        """(slot, kind) of a node output, compiling the node on first use; None if unsupported.
        Inside a Bump node's height input (``self.offset`` 1 or 2) the node is compiled again
        for that offset: coordinates read at the displaced point."""
        key = (link.node, link.socket, self.offset)
        if key in self.outputs:
            return self.outputs[key]
        node = self.g.nodes.get(link.node)
        if node is None:
            return None
        if link.node in self.busy:
            self.warn(link.node, node, "is part of a cycle")
            return None
        handler = _HANDLERS.get(node.type)
        if handler is None:
            self.warn(link.node, node, "is not supported by the node interpreter; the input's default is used")
            return None
        self.busy.add(link.node)
        try:
            outs = handler(self, link.node, node)
        finally:
            self.busy.discard(link.node)
        if outs is None:
            return None
        for ident, sk in outs.items():
            self.outputs[(link.node, ident, self.offset)] = sk
        return self.outputs.get(key)

    def uv_slot(self, layer: str = ""):
        key = ("__uv__", layer, self.offset)
        if key not in self.outputs:
            if layer not in self.uv_layers:
                self.uv_layers.append(layer)
            out = self.alloc(VEC)
            self.emit("UVMAP", float(self.uv_layers.index(layer)), float(self.offset), out)
            self.outputs[key] = (out, VEC)
        return self.outputs[key][0]

    def generated_slot(self):
        key = ("__generated__", "", self.offset)
        if key not in self.outputs:
            out = self.alloc(VEC)
            self.emit("TEXCOORD", float(self.offset), out, -1.0, -1.0, -1.0, -1.0)
            self.outputs[key] = (out, VEC)
        return self.outputs[key][0]

    # -- shaders ---------------------------------------------------------------------------
    def shader(self, link: Link | None, depth: int = 0) -> None:
        node = self.g.nodes.get(link.node) if link is not None else None
        if node is None or depth > 32:
            self.emit("BSDF_DIFFUSE", self.const((0.0, 0.0, 0.0)), -1.0)   # an unconnected shader: black
            return
        t = node.type
        if t == "ShaderNodeMixShader":
            self.uses_mix = True
            fac = self.input(link.node, node, "Fac", FLT, 0.5)
            at = self.emit("MIX_SHADER", fac, 0.0)
            self.shader(node.inputs.get("Shader") if isinstance(node.inputs.get("Shader"), Link) else None, depth + 1)
            self.closure_code[at + 2] = float(len(self.closure_code))   # index of branch B: fixed in finish()
            self.jumps.append(at + 2)
            second = node.inputs.get("Shader_001")
            self.shader(second if isinstance(second, Link) else None, depth + 1)
            return
        if t == "ShaderNodeAddShader":
            self.uses_mix = True          # a choice per hit: a fresh seed per bounce
            at = self.emit("ADD_SHADER", 0.0)
            self.add_depth += 1
            first = node.inputs.get("Shader")
            self.shader(first if isinstance(first, Link) else None, depth + 1)
            self.closure_code[at + 1] = float(len(self.closure_code))   # index of branch B: fixed in finish()
            self.jumps.append(at + 1)
            second = node.inputs.get("Shader_001")
            self.shader(second if isinstance(second, Link) else None, depth + 1)
            self.add_depth -= 1
            return
        n = link.node
        if t == "ShaderNodeBsdfTransparent":
            self.may_pass = True
            self.emit("TRANSPARENT", self.input(n, node, "Color", VEC, (1.0, 1.0, 1.0)))
            return
        if self.add_depth and t in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfGlass",
                                    "ShaderNodeBsdfPrincipled"):
            self.warn(n, node, "under an Add Shader: its specular lobes are weighted approximately "
                               "(the sum is estimated by picking one input at weight 2)")
        normal = self.normal_input(n, node)
        if t in ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy",
                 "ShaderNodeBsdfAnisotropic"):
            self.may_scatter = True
        if t == "ShaderNodeBsdfPrincipled":
            a = node.inputs.get("Alpha", 1.0)
            if isinstance(a, Link) or (isinstance(a, (int, float)) and a < 1.0):
                self.may_pass = True
                self.uses_mix = True      # Alpha picks the BSDF or transparency per hit
            for ident in ("Sheen Weight", "Subsurface Weight", "Diffuse Roughness", "Thin Film Thickness"):
                v = node.inputs.get(ident, 0.0)
                if isinstance(v, Link) or (isinstance(v, (int, float)) and v > 0):
                    self.warn(n, node, f"{ident} is not rendered")
            cw = node.inputs.get("Coat Weight", 0.0)
            if isinstance(cw, Link) or (isinstance(cw, (int, float)) and cw > 0):
                es = node.inputs.get("Emission Strength", 0.0)
                if isinstance(es, Link) or (isinstance(es, (int, float)) and es != 0):
                    self.warn(n, node, "Emission under a Coat is not attenuated by it (Cycles dims it by the "
                                       "coat's reflectance and tint)")
            tint = node.inputs.get("Specular Tint", (1.0, 1.0, 1.0))
            if isinstance(tint, Link) or (isinstance(tint, (tuple, list)) and any(float(c) != 1.0 for c in tint[:3])):
                self.warn(n, node, "Specular Tint is not rendered (untinted, as white)")
            self._warn_anisotropy(n, node, "Anisotropic")
            self.emit("BSDF_PRINCIPLED",
                      self.input(n, node, "Base Color", VEC, (0.8, 0.8, 0.8)),
                      self.input(n, node, "Metallic", FLT, 0.0), self.input(n, node, "Roughness", FLT, 0.5),
                      self.input(n, node, "IOR", FLT, 1.5), self.input(n, node, "Alpha", FLT, 1.0),
                      self.input(n, node, "Transmission Weight", FLT, 0.0),
                      self.input(n, node, "Specular IOR Level", FLT, 0.5),
                      *self.emission(n, node, "Emission Color", "Emission Strength", 0.0), normal,
                      self.input(n, node, "Coat Weight", FLT, 0.0), self.input(n, node, "Coat Roughness", FLT, 0.03),
                      self.input(n, node, "Coat IOR", FLT, 1.5), self.input(n, node, "Coat Tint", VEC, (1.0, 1.0, 1.0)),
                      self.normal_input(n, node, "Coat Normal", rewrites=False))
        elif t == "ShaderNodeBsdfDiffuse":
            self.emit("BSDF_DIFFUSE", self.input(n, node, "Color", VEC, (0.8, 0.8, 0.8)), normal)
        elif t in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            self._warn_anisotropy(n, node, "Anisotropy")
            self.emit("BSDF_GLOSSY", self.input(n, node, "Color", VEC, (0.8, 0.8, 0.8)),
                      self.input(n, node, "Roughness", FLT, 0.5), normal)
        elif t == "ShaderNodeBsdfGlass":
            self.emit("BSDF_GLASS", self.input(n, node, "Color", VEC, (1.0, 1.0, 1.0)),
                      self.input(n, node, "Roughness", FLT, 0.0), self.input(n, node, "IOR", FLT, 1.5), normal)
        elif t == "ShaderNodeEmission":
            self.emit("EMISSION", *self.emission(n, node, "Color", "Strength", 1.0))
        else:
            self.warn(n, node, "is not a supported shader; rendered as grey diffuse")
            self.emit("BSDF_DIFFUSE", self.const((0.8, 0.8, 0.8)), -1.0)
        for ident, v in node.inputs.items():
            if ident.endswith("Normal") and ident != "Normal" and isinstance(v, Link):
                if t == "ShaderNodeBsdfPrincipled" and ident == "Coat Normal" and self.value(v) is not None:
                    continue                   # (the coat layer's normal: BSDF_PRINCIPLED's coat_normal)
                self.warn(n, node, f"{ident} input is not evaluated (the surface normal is used)")

    def emission(self, name: str, node, color: str, strength: str, strength_default: float) -> tuple:
        """Slots of an emission's colour and strength inputs; sets ``may_emit`` unless one of
        them is a constant zero (a constant is a ("c", k) slot)."""
        c = self.input(name, node, color, VEC, (1.0, 1.0, 1.0))
        s = self.input(name, node, strength, FLT, strength_default)
        zero_c = c[0] == "c" and not any(self.consts[c[1] + i] != 0.0 for i in range(3))
        zero_s = s[0] == "c" and self.consts[s[1]] == 0.0
        if not (zero_c or zero_s):
            self.may_emit = True
        return c, s

    def normal_input(self, name: str, node, ident: str = "Normal", rewrites: bool = True):
        """Slot of a shader's linked Normal input (a world-space unit normal), or -1: the surface's.
        rewrites: the input replaces the hit's shading normal (``uses_normals``; a Coat Normal does
        not: it is the coat layer's own)."""
        v = node.inputs.get(ident)
        if not isinstance(v, Link):
            return -1.0
        got = self.value(v)
        if got is None or got[1] != VEC:
            return -1.0
        if rewrites:
            self.uses_normals = True
        return got[0]

    def finish(self) -> np.ndarray:
        """Words: [n_slots, n_const, closure_at, constants..., value code..., closure code...];
        slot operands ("c", k) -> k, ("o", k) -> n_const + k; jumps and closure_at relative to
        the program's first word."""
        n_const = len(self.consts)

        def words(code):
            return [float(w[1] if w[0] == "c" else n_const + w[1]) if isinstance(w, tuple) else float(w)
                    for w in code]
        header = [float(n_const + self.n_slots), float(n_const), 0.0] + self.consts
        values = words(self.code)
        closures = words(self.closure_code)
        closure_at = len(header) + len(values)
        header[2] = float(closure_at)
        for j in self.jumps:
            closures[j] = float(closure_at + int(self.closure_code[j]))
        return np.array(header + values + closures, np.float64)


# ----------------------------------------------------------------------------
# Value-node handlers: (compiler, name, node) -> {output id: (slot, kind)} or None
# ----------------------------------------------------------------------------
def _texcoord(c, name, node):
    if node.props.get("object"):
        c.warn(name, node, "texture coordinates from another object are not supported; this object's are used")
    outs = {}
    slots = {}
    for ident in ("Generated", "Normal", "UV", "Object", "Reflection"):
        # only the outputs something reads get a slot; the others are not computed (-1), as
        # Cycles compiles only linked outputs (an unused Normal output cost a corner-normal
        # interpolation and a square root per hit)
        if c.used(name, ident):
            slots[ident] = c.alloc(VEC)
            outs[ident] = (slots[ident], VEC)
        else:
            slots[ident] = -1.0
    for ident in ("Camera", "Window"):
        if c.used(name, ident):
            c.warn(name, node, f"the {ident} output is not supported")
    if "UV" in node.outputs and "" not in c.uv_layers:
        c.uv_layers.append("")
    c.emit("TEXCOORD", float(c.offset), slots["Generated"], slots["Normal"], slots["UV"], slots["Object"],
           slots["Reflection"])
    return outs


def _uvmap(c, name, node):
    if node.props.get("from_instancer"):
        c.warn(name, node, "From Instancer is not supported")
    return {"UV": (c.uv_slot(str(node.props.get("uv_map", "") or "")), VEC)}


def _geometry(c, name, node):
    outs = {k: (c.alloc(VEC), VEC) for k in ("Position", "Normal", "True Normal", "Incoming")}
    outs["Backfacing"] = (c.alloc(FLT), FLT)
    for ident in ("Tangent", "Parametric", "Pointiness", "Random Per Island"):
        if c.used(name, ident):
            c.warn(name, node, f"the {ident} output is not supported")
    c.emit("GEOMETRY", float(c.offset), outs["Position"][0], outs["Normal"][0], outs["True Normal"][0],
           outs["Incoming"][0],
           outs["Backfacing"][0])
    return outs


def _geometry_slots(c):
    """The Geometry outputs at the hit for the compiler's own use (one GEOMETRY per program and
    Bump offset): {"Normal", "Incoming", "Backfacing"} -> slot."""
    cache = c.__dict__.setdefault("_geometry_slots", {})
    if c.offset not in cache:
        pos, nrm, true_n, inc, back = c.alloc(VEC), c.alloc(VEC), c.alloc(VEC), c.alloc(VEC), c.alloc(FLT)
        c.emit("GEOMETRY", float(c.offset), pos, nrm, true_n, inc, back)
        cache[c.offset] = {"Normal": nrm, "Incoming": inc, "Backfacing": back}
    return cache[c.offset]


def _m(c, op, a, b=None, d=None):
    """Slot of Math ``op`` on slots a, b, d (unset: the constant 0), unclamped."""
    zero = c.const((0.0,))
    out = c.alloc(FLT)
    c.emit("MATH", float(MATH_OPS[op]), a, zero if b is None else b, zero if d is None else d, 0.0, out)
    return out


def _lerp(c, t, a, b):
    """Slot of (1 - t) a + t b (MIX_FLOAT, t unclamped)."""
    out = c.alloc(FLT)
    c.emit("MIX_FLOAT", t, a, b, 0.0, out)
    return out


def _fresnel_of(c, cosi, eta):
    """Slot of Cycles' ``fresnel_dielectric_cos(cosi, eta)`` written with Math instructions:
    c = |cosi|, g^2 = eta^2 - 1 + c^2; 1 where g^2 <= 0 (total internal reflection), else
    A = (g - c) / (g + c), B = (c (g + c) - 1) / (c (g - c) + 1), F = A^2 (1 + B^2) / 2."""
    k = lambda v: c.const((float(v),))                                         # noqa: E731
    cc = _m(c, "ABSOLUTE", cosi)
    g2 = _m(c, "MULTIPLY_ADD", cc, cc, _m(c, "MULTIPLY_ADD", eta, eta, k(-1.0)))
    g = _m(c, "SQRT", g2)                                                      # (0 where g^2 <= 0)
    gpc, gmc = _m(c, "ADD", g, cc), _m(c, "SUBTRACT", g, cc)
    A = _m(c, "DIVIDE", gmc, gpc)
    B = _m(c, "DIVIDE", _m(c, "MULTIPLY_ADD", cc, gpc, k(-1.0)), _m(c, "MULTIPLY_ADD", cc, gmc, k(1.0)))
    F = _m(c, "MULTIPLY", _m(c, "MULTIPLY", _m(c, "MULTIPLY", A, A), _m(c, "MULTIPLY_ADD", B, B, k(1.0))), k(0.5))
    return _lerp(c, _m(c, "GREATER_THAN", g2, k(0.0)), k(1.0), F)


def _cos_view(c, name, node, geo):
    """Slot of dot(wi, N): wi towards where the ray came from (Geometry Incoming), N the node's
    linked Normal, else the shading normal facing wi (Cycles' sd->N)."""
    n = c.input(name, node, "Normal", VEC, (0.0, 0.0, 1.0)) if isinstance(node.inputs.get("Normal"), Link) \
        else geo["Normal"]
    out, val = c.alloc(VEC), c.alloc(FLT)
    zero3 = c.const((0.0, 0.0, 0.0))
    c.emit("VECTOR_MATH", float(VMATH_OPS["DOT_PRODUCT"]), geo["Incoming"], n, zero3, c.const((1.0,)), out, val)
    return val


def _fresnel(c, name, node):
    """Fresnel (``svm_node_fresnel``): the dielectric reflectance for the view direction, IOR
    eta = max(IOR, 1e-5) on a front face, 1 / eta on a back face."""
    geo = _geometry_slots(c)
    eta = _m(c, "MAXIMUM", c.input(name, node, "IOR", FLT, 1.5), c.const((1e-5,)))
    eta = _lerp(c, geo["Backfacing"], eta, _m(c, "DIVIDE", c.const((1.0,)), eta))
    return {"Fac": (_fresnel_of(c, _cos_view(c, name, node, geo), eta), FLT)}


def _layer_weight(c, name, node):
    """Layer Weight (``svm_node_layer_weight``) with b = Blend: Fresnel = the dielectric
    reflectance with eta = 1 / max(1 - b, 1e-5) on a front face (its inverse on a back face);
    Facing = 1 - |dot(wi, N)|^e, e = 2 b' for b' < 1/2 else 1 / (2 (1 - b')), b' = b clamped to
    [0, 1 - 1e-5] (e = 1 at b = 1/2)."""
    geo = _geometry_slots(c)
    blend = c.input(name, node, "Blend", FLT, 0.5)
    cosv = _cos_view(c, name, node, geo)
    out = {}
    k = lambda v: c.const((float(v),))                                         # noqa: E731
    if c.used(name, "Fresnel"):
        e0 = _m(c, "MAXIMUM", _m(c, "SUBTRACT", k(1.0), blend), k(1e-5))
        eta = _lerp(c, geo["Backfacing"], _m(c, "DIVIDE", k(1.0), e0), e0)
        out["Fresnel"] = (_fresnel_of(c, cosv, eta), FLT)
    if c.used(name, "Facing"):
        b = _m(c, "MINIMUM", _m(c, "MAXIMUM", blend, k(0.0)), k(1.0 - 1e-5))
        e = _lerp(c, _m(c, "LESS_THAN", b, k(0.5)), _m(c, "DIVIDE", k(0.5), _m(c, "SUBTRACT", k(1.0), b)),
                  _m(c, "MULTIPLY", b, k(2.0)))
        out["Facing"] = (_m(c, "SUBTRACT", k(1.0), _m(c, "POWER", _m(c, "ABSOLUTE", cosv), e)), FLT)
    return out


def _attribute(c, name, node):
    """Color Attribute (``layer_name``, "" = the render-active one) and Attribute (Geometry type,
    ``attribute_name``: a colour attribute or a UV map of the mesh): the per-corner value at the
    hit (``ATTRIBUTE``).  Object / Instancer / View Layer attributes are named and read 0."""
    zeros = {"Color": (c.const((0.0, 0.0, 0.0)), VEC), "Vector": (c.const((0.0, 0.0, 0.0)), VEC),
             "Fac": (c.const((0.0,)), FLT), "Alpha": (c.const((0.0,)), FLT)}
    if node.type == "ShaderNodeVertexColor":
        layer = str(node.props.get("layer_name", "") or "")
    else:
        typ = str(node.props.get("attribute_type", "GEOMETRY"))
        layer = str(node.props.get("attribute_name", "") or "")
        if typ != "GEOMETRY":
            c.warn(name, node, f"{typ.replace('_', ' ').title()} attributes are not supported; its outputs read 0")
            return zeros
        if not layer:
            c.warn(name, node, "names no attribute; its outputs read 0")
            return zeros
    if layer not in c.color_layers:
        c.color_layers.append(layer)
    col, fac, alpha = c.alloc(VEC), c.alloc(FLT), c.alloc(FLT)
    c.emit("ATTRIBUTE", float(c.color_layers.index(layer)), float(c.offset), col, fac, alpha)
    out = {"Color": (col, VEC), "Fac": (fac, FLT), "Alpha": (alpha, FLT)}
    if node.type == "ShaderNodeAttribute":
        out["Vector"] = (col, VEC)
    return out


def _mapping(c, name, node):
    typ = node.props.get("vector_type", "POINT")
    out = c.alloc(VEC)
    c.emit("MAPPING", float(MAPPING_TYPES.get(typ, 0)), c.input(name, node, "Vector", VEC, (0.0, 0.0, 0.0)),
           c.input(name, node, "Location", VEC, (0.0, 0.0, 0.0)), c.input(name, node, "Rotation", VEC, (0.0, 0.0, 0.0)),
           c.input(name, node, "Scale", VEC, (1.0, 1.0, 1.0)), out)
    return {"Vector": (out, VEC)}


def _math(c, name, node):
    op = node.props.get("operation", "ADD")
    if op not in MATH_OPS:
        c.warn(name, node, f"operation {op} is not supported")
        return None
    out = c.alloc(FLT)
    c.emit("MATH", float(MATH_OPS[op]), c.input(name, node, "Value", FLT, 0.5),
           c.input(name, node, "Value_001", FLT, 0.5), c.input(name, node, "Value_002", FLT, 0.5),
           1.0 if node.props.get("use_clamp") else 0.0, out)
    return {"Value": (out, FLT)}


def _vector_math(c, name, node):
    op = node.props.get("operation", "ADD")
    if op not in VMATH_OPS:
        c.warn(name, node, f"operation {op} is not supported")
        return None
    out, val = c.alloc(VEC), c.alloc(FLT)
    c.emit("VECTOR_MATH", float(VMATH_OPS[op]), c.input(name, node, "Vector", VEC, (0.0, 0.0, 0.0)),
           c.input(name, node, "Vector_001", VEC, (0.0, 0.0, 0.0)), c.input(name, node, "Vector_002", VEC, (0.0, 0.0, 0.0)),
           c.input(name, node, "Scale", FLT, 1.0), out, val)
    return {"Vector": (out, VEC), "Value": (val, FLT)}


def _mix(c, name, node):
    dt = node.props.get("data_type", "FLOAT")
    clamp_fac = 1.0 if node.props.get("clamp_factor", True) else 0.0
    if dt == "FLOAT":
        out = c.alloc(FLT)
        c.emit("MIX_FLOAT", c.input(name, node, "Factor_Float", FLT, 0.5), c.input(name, node, "A_Float", FLT, 0.0),
               c.input(name, node, "B_Float", FLT, 0.0), clamp_fac, out)
        return {"Result_Float": (out, FLT)}
    if dt == "VECTOR":
        if node.props.get("factor_mode", "UNIFORM") != "UNIFORM":
            c.warn(name, node, "a non-uniform factor is not supported; its X component is used")
        out = c.alloc(VEC)
        c.emit("MIX_VECTOR", c.input(name, node, "Factor_Float", FLT, 0.5),
               c.input(name, node, "A_Vector", VEC, (0.0, 0.0, 0.0)), c.input(name, node, "B_Vector", VEC, (0.0, 0.0, 0.0)),
               clamp_fac, out)
        return {"Result_Vector": (out, VEC)}
    if dt == "RGBA":
        blend = node.props.get("blend_type", "MIX")
        if blend not in BLEND_MODES:
            c.warn(name, node, f"blend mode {blend} is not supported")
            return None
        out = c.alloc(VEC)
        c.emit("MIX_COLOR", float(BLEND_MODES[blend]), c.input(name, node, "Factor_Float", FLT, 0.5),
               c.input(name, node, "A_Color", VEC, (0.5, 0.5, 0.5)), c.input(name, node, "B_Color", VEC, (0.5, 0.5, 0.5)),
               clamp_fac, 1.0 if node.props.get("clamp_result") else 0.0, out)
        return {"Result_Color": (out, VEC)}
    c.warn(name, node, f"data type {dt} is not supported")
    return None


def _mix_rgb(c, name, node):
    blend = node.props.get("blend_type", "MIX")
    if blend not in BLEND_MODES:
        c.warn(name, node, f"blend mode {blend} is not supported")
        return None
    out = c.alloc(VEC)
    c.emit("MIX_COLOR", float(BLEND_MODES[blend]), c.input(name, node, "Fac", FLT, 0.5),
           c.input(name, node, "Color1", VEC, (0.5, 0.5, 0.5)), c.input(name, node, "Color2", VEC, (0.5, 0.5, 0.5)),
           1.0, 1.0 if node.props.get("use_clamp") else 0.0, out)
    return {"Color": (out, VEC)}


def _invert(c, name, node):
    out = c.alloc(VEC)
    c.emit("INVERT", c.input(name, node, "Fac", FLT, 1.0), c.input(name, node, "Color", VEC, (0.0, 0.0, 0.0)), out)
    return {"Color": (out, VEC)}


def _hsv(c, name, node):
    out = c.alloc(VEC)
    c.emit("HSV", c.input(name, node, "Hue", FLT, 0.5), c.input(name, node, "Saturation", FLT, 1.0),
           c.input(name, node, "Value", FLT, 1.0), c.input(name, node, "Fac", FLT, 1.0),
           c.input(name, node, "Color", VEC, (0.8, 0.8, 0.8)), out)
    return {"Color": (out, VEC)}


def _bright_contrast(c, name, node):
    out = c.alloc(VEC)
    c.emit("BRIGHT_CONTRAST", c.input(name, node, "Color", VEC, (1.0, 1.0, 1.0)),
           c.input(name, node, "Bright", FLT, 0.0), c.input(name, node, "Contrast", FLT, 0.0), out)
    return {"Color": (out, VEC)}


def _gamma(c, name, node):
    out = c.alloc(VEC)
    c.emit("GAMMA", c.input(name, node, "Color", VEC, (1.0, 1.0, 1.0)), c.input(name, node, "Gamma", FLT, 1.0), out)
    return {"Color": (out, VEC)}


def _separate_color(c, name, node, legacy: str | None = None):
    mode = COLOR_MODES.get(node.props.get("mode", "RGB"), 0) if legacy is None else 0
    r, g, b = c.alloc(FLT), c.alloc(FLT), c.alloc(FLT)
    c.emit("SEPARATE_COLOR", float(mode), c.input(name, node, legacy or "Color", VEC, (0.8, 0.8, 0.8)), r, g, b)
    if legacy:
        return {"R": (r, FLT), "G": (g, FLT), "B": (b, FLT)}
    return {"Red": (r, FLT), "Green": (g, FLT), "Blue": (b, FLT)}


def _combine_color(c, name, node, legacy: bool = False):
    mode = COLOR_MODES.get(node.props.get("mode", "RGB"), 0) if not legacy else 0
    names = ("R", "G", "B") if legacy else ("Red", "Green", "Blue")
    out = c.alloc(VEC)
    c.emit("COMBINE_COLOR", float(mode), *(c.input(name, node, k, FLT, 0.0) for k in names), out)
    return {("Image" if legacy else "Color"): (out, VEC)}


def _separate_xyz(c, name, node):
    x, y, z = c.alloc(FLT), c.alloc(FLT), c.alloc(FLT)
    c.emit("SEPARATE_XYZ", c.input(name, node, "Vector", VEC, (0.0, 0.0, 0.0)), x, y, z)
    return {"X": (x, FLT), "Y": (y, FLT), "Z": (z, FLT)}


def _combine_xyz(c, name, node):
    out = c.alloc(VEC)
    c.emit("COMBINE_XYZ", *(c.input(name, node, k, FLT, 0.0) for k in ("X", "Y", "Z")), out)
    return {"Vector": (out, VEC)}


def _rgb_to_bw(c, name, node):
    out = c.alloc(FLT)
    c.emit("CONVERT", float(CONVERT["COLOR_TO_FLOAT"]), c.input(name, node, "Color", VEC, (0.5, 0.5, 0.5)), out,
           c.const(c.luma))
    return {"Val": (out, FLT)}


def _clamp(c, name, node):
    out = c.alloc(FLT)
    c.emit("CLAMP", 1.0 if node.props.get("clamp_type", "MINMAX") == "RANGE" else 0.0,
           c.input(name, node, "Value", FLT, 1.0), c.input(name, node, "Min", FLT, 0.0),
           c.input(name, node, "Max", FLT, 1.0), out)
    return {"Result": (out, FLT)}


def _map_range(c, name, node):
    if node.props.get("data_type", "FLOAT") != "FLOAT":
        c.warn(name, node, "the vector data type is not supported")
        return None
    typ = node.props.get("interpolation_type", "LINEAR")
    out = c.alloc(FLT)
    c.emit("MAP_RANGE", float(MAP_RANGE_TYPES.get(typ, 0)), c.input(name, node, "Value", FLT, 1.0),
           c.input(name, node, "From Min", FLT, 0.0), c.input(name, node, "From Max", FLT, 1.0),
           c.input(name, node, "To Min", FLT, 0.0), c.input(name, node, "To Max", FLT, 1.0),
           c.input(name, node, "Steps", FLT, 4.0), 1.0 if node.props.get("clamp", True) else 0.0, out)
    return {"Result": (out, FLT)}


def colorband(elems, interp: str, x: np.ndarray) -> np.ndarray:
    """Blender's colour band at positions x (k,) -> (k, 4) RGBA: below the first element its
    colour, above the last the last's; in between Linear / Ease (smoothstep of the fraction)
    blends the two neighbours, Constant takes the left one (the right one exactly at its
    position).  elems: [(position, (r, g, b, a))] sorted by position."""
    pos = np.array([e[0] for e in elems], np.float64)
    col = np.array([tuple(e[1]) + (1.0,) * (4 - len(e[1])) for e in elems], np.float64)[:, :4]
    out = np.empty((x.shape[0], 4))
    for i, f in enumerate(x):
        j = int(np.searchsorted(pos, f, side="left"))          # first element at or right of f
        if j == 0 or len(pos) == 1:
            out[i] = col[0]
        elif j == len(pos):
            out[i] = col[-1]
        elif interp == "CONSTANT":
            out[i] = col[j] if pos[j] == f else col[j - 1]
        else:
            span = pos[j] - pos[j - 1]
            t = (f - pos[j - 1]) / span if span > 0 else 0.0
            if interp == "EASE":
                t = t * t * (3.0 - 2.0 * t)
            out[i] = (1.0 - t) * col[j - 1] + t * col[j]
    return out


def _ramp(c, name, node):
    """ColorRamp as Cycles runs it: the band sampled at RAMP_TABLE + 1 positions i / RAMP_TABLE,
    read with linear interpolation between samples (none for Constant), Fac clamped to [0, 1]."""
    elems = list(node.props.get("elements", [(0.0, (0.0, 0.0, 0.0, 1.0)), (1.0, (1.0, 1.0, 1.0, 1.0))]))
    elems = sorted(elems, key=lambda e: e[0])[:MAX_RAMP]
    if node.props.get("color_mode", "RGB") != "RGB":
        c.warn(name, node, f"colour mode {node.props.get('color_mode')} is interpolated in RGB")
    interp = node.props.get("interpolation", "LINEAR")
    if interp in ("CARDINAL", "B_SPLINE"):
        c.warn(name, node, f"{interp} interpolation is evaluated as Linear")
    table = colorband(elems, interp, np.arange(RAMP_TABLE + 1) / RAMP_TABLE)
    color, alpha = c.alloc(VEC), c.alloc(FLT)
    c.emit("RAMP", c.input(name, node, "Fac", FLT, 0.5), 0.0 if interp == "CONSTANT" else 1.0,
           float(table.shape[0]), color, alpha)
    c.code.extend(table.reshape(-1).tolist())
    return {"Color": (color, VEC), "Alpha": (alpha, FLT)}


def _curves(c, name, node):
    table = node.props.get("table")
    if table is None:
        c.warn(name, node, "no sampled curve table was exported")
        return None
    table = np.asarray(table, np.float64).reshape(3, -1)
    out = c.alloc(VEC)
    c.emit("CURVES", c.input(name, node, "Fac", FLT, 1.0), c.input(name, node, "Color", VEC, (1.0, 1.0, 1.0)),
           float(table.shape[1]), out)
    c.code.extend(table.reshape(-1).tolist())
    return {"Color": (out, VEC)}


def _tex_image(c, name, node):
    img = int(node.props.get("image", -1))
    color, alpha = c.alloc(VEC), c.alloc(FLT)
    if img < 0 or img >= c.n_textures:
        c.warn(name, node, "has no image (or it could not be loaded): magenta, as Cycles")
        c.emit("COMBINE_XYZ", c.const((1.0,)), c.const((0.0,)), c.const((1.0,)), color)
        c.emit("CONVERT", float(CONVERT["VECTOR_TO_FLOAT"]), c.const((1.0, 1.0, 1.0)), alpha, c.const(c.luma))
        return {"Color": (color, VEC), "Alpha": (alpha, FLT)}
    proj = node.props.get("projection", "FLAT")
    if proj != "FLAT":
        c.warn(name, node, f"projection {proj} is not supported; Flat is used")
    vec = c.input(name, node, "Vector", VEC, implicit=lambda: c.uv_slot(""))
    alpha_used = c.used(name, "Alpha")
    tiles = [(int(t), int(i)) for t, i in node.props.get("tiles", []) if 0 <= int(i) < c.n_textures]
    c.emit("TEX_IMAGE", float(img), float(INTERPOLATIONS.get(node.props.get("interpolation", "Linear"), 1)),
           float(EXTENSIONS.get(node.props.get("extension", "REPEAT"), 0)), 1.0 if alpha_used else 0.0, vec, color,
           alpha, float(len(tiles)))
    for t, i in tiles:                         # UDIM: (tile number, texture id) pairs after the instruction
        c.code.extend((float(t), float(i)))
    return {"Color": (color, VEC), "Alpha": (alpha, FLT)}


def _tex_checker(c, name, node):
    color, fac = c.alloc(VEC), c.alloc(FLT)
    c.emit("TEX_CHECKER", c.input(name, node, "Vector", VEC, implicit=c.generated_slot),
           c.input(name, node, "Color1", VEC, (0.8, 0.8, 0.8)), c.input(name, node, "Color2", VEC, (0.2, 0.2, 0.2)),
           c.input(name, node, "Scale", FLT, 5.0), color, fac)
    return {"Color": (color, VEC), "Fac": (fac, FLT)}


def _tex_gradient(c, name, node):
    color, fac = c.alloc(VEC), c.alloc(FLT)
    c.emit("TEX_GRADIENT", float(GRADIENT_TYPES.get(node.props.get("gradient_type", "LINEAR"), 0)),
           c.input(name, node, "Vector", VEC, implicit=c.generated_slot), color, fac)
    return {"Color": (color, VEC), "Fac": (fac, FLT)}


def _dims(node, prop: str) -> float:
    from ..kernels.procedural import DIMENSIONS
    return float(DIMENSIONS.get(node.props.get(prop, "3D"), 3))


def _enum(c, name, node, prop: str, table: dict, default: str) -> float:
    v = node.props.get(prop, default)
    if v not in table:
        c.warn(name, node, f"{prop} {v} is not supported; {default} is used")
        v = default
    return float(table[v])


def _tex_noise(c, name, node):
    from ..kernels.procedural import NOISE_TYPES
    fac, color = c.alloc(FLT), c.alloc(VEC)
    inp = lambda k, d: c.input(name, node, k, FLT, d)        # noqa: E731
    c.emit("TEX_NOISE", _dims(node, "noise_dimensions"), _enum(c, name, node, "noise_type", NOISE_TYPES, "FBM"),
           1.0 if node.props.get("normalize", True) else 0.0, 1.0 if c.used(name, "Color") else 0.0,
           c.input(name, node, "Vector", VEC, implicit=c.generated_slot), inp("W", 0.0), inp("Scale", 5.0),
           inp("Detail", 2.0), inp("Roughness", 0.5), inp("Lacunarity", 2.0), inp("Offset", 0.0), inp("Gain", 1.0),
           inp("Distortion", 0.0), fac, color)
    return {"Fac": (fac, FLT), "Color": (color, VEC)}


def _tex_voronoi(c, name, node):
    from ..kernels.procedural import VORONOI_FEATURES, VORONOI_METRICS
    dist, color, pos, w, radius = c.alloc(FLT), c.alloc(VEC), c.alloc(VEC), c.alloc(FLT), c.alloc(FLT)
    inp = lambda k, d: c.input(name, node, k, FLT, d)        # noqa: E731
    c.emit("TEX_VORONOI", _dims(node, "voronoi_dimensions"),
           _enum(c, name, node, "feature", VORONOI_FEATURES, "F1"),
           _enum(c, name, node, "distance", VORONOI_METRICS, "EUCLIDEAN"),
           1.0 if node.props.get("normalize", False) else 0.0,
           c.input(name, node, "Vector", VEC, implicit=c.generated_slot), inp("W", 0.0), inp("Scale", 5.0),
           inp("Detail", 0.0), inp("Roughness", 0.5), inp("Lacunarity", 2.0), inp("Smoothness", 1.0),
           inp("Exponent", 0.5), inp("Randomness", 1.0), dist, color, pos, w, radius)
    return {"Distance": (dist, FLT), "Color": (color, VEC), "Position": (pos, VEC), "W": (w, FLT),
            "Radius": (radius, FLT)}


def _tex_wave(c, name, node):
    from ..kernels.procedural import WAVE_BANDS_DIRECTIONS, WAVE_PROFILES, WAVE_RINGS_DIRECTIONS, WAVE_TYPES
    color, fac = c.alloc(VEC), c.alloc(FLT)
    inp = lambda k, d: c.input(name, node, k, FLT, d)        # noqa: E731
    c.emit("TEX_WAVE", _enum(c, name, node, "wave_type", WAVE_TYPES, "BANDS"),
           _enum(c, name, node, "bands_direction", WAVE_BANDS_DIRECTIONS, "X"),
           _enum(c, name, node, "rings_direction", WAVE_RINGS_DIRECTIONS, "X"),
           _enum(c, name, node, "wave_profile", WAVE_PROFILES, "SIN"),
           c.input(name, node, "Vector", VEC, implicit=c.generated_slot), inp("Scale", 5.0), inp("Distortion", 0.0),
           inp("Detail", 2.0), inp("Detail Scale", 1.0), inp("Detail Roughness", 0.5), inp("Phase Offset", 0.0),
           color, fac)
    return {"Color": (color, VEC), "Fac": (fac, FLT)}


def _tex_brick(c, name, node):
    color, fac = c.alloc(VEC), c.alloc(FLT)
    inp = lambda k, d: c.input(name, node, k, FLT, d)        # noqa: E731
    p = node.props
    c.emit("TEX_BRICK", float(p.get("offset", 0.5)), float(p.get("offset_frequency", 2)), float(p.get("squash", 1.0)),
           float(p.get("squash_frequency", 2)), c.input(name, node, "Vector", VEC, implicit=c.generated_slot),
           c.input(name, node, "Color1", VEC, (0.8, 0.8, 0.8)), c.input(name, node, "Color2", VEC, (0.2, 0.2, 0.2)),
           c.input(name, node, "Mortar", VEC, (0.0, 0.0, 0.0)), inp("Scale", 5.0), inp("Mortar Size", 0.02),
           inp("Mortar Smooth", 0.1), inp("Bias", 0.0), inp("Brick Width", 0.5), inp("Row Height", 0.25), color, fac)
    return {"Color": (color, VEC), "Fac": (fac, FLT)}


def _tex_magic(c, name, node):
    color, fac = c.alloc(VEC), c.alloc(FLT)
    c.emit("TEX_MAGIC", float(node.props.get("turbulence_depth", 2)),
           c.input(name, node, "Vector", VEC, implicit=c.generated_slot), c.input(name, node, "Scale", FLT, 5.0),
           c.input(name, node, "Distortion", FLT, 1.0), color, fac)
    return {"Color": (color, VEC), "Fac": (fac, FLT)}


def _tex_white_noise(c, name, node):
    value, color = c.alloc(FLT), c.alloc(VEC)
    c.emit("TEX_WHITE_NOISE", _dims(node, "noise_dimensions"),
           c.input(name, node, "Vector", VEC, implicit=c.generated_slot), c.input(name, node, "W", FLT, 0.0),
           value, color)
    return {"Value": (value, FLT), "Color": (color, VEC)}


def _normal_map(c, name, node):
    space = node.props.get("space", "TANGENT")
    if space not in NORMAL_MAP_SPACES:
        c.warn(name, node, f"space {space} is not supported")
        return None
    layer = str(node.props.get("uv_map", "") or "")
    if space == "TANGENT" and layer not in c.uv_layers:
        c.uv_layers.append(layer)
    if space != "WORLD" and space != "BLENDER_WORLD":
        c.uses_frames = True
    out = c.alloc(VEC)
    c.emit("NORMAL_MAP", float(NORMAL_MAP_SPACES[space]), float(c.uv_layers.index(layer)) if space == "TANGENT" else 0.0,
           c.input(name, node, "Color", VEC, (0.5, 0.5, 1.0)), c.input(name, node, "Strength", FLT, 1.0), out)
    return {"Normal": (out, VEC)}


def _bump(c, name, node):
    """Bump: the Height input compiled three times (at the hit and displaced along the surface's
    two differentials), then the perturbed normal (see ``kernels.svm._bump``)."""
    heights = []
    saved = c.offset
    for off in (0, 1, 2):
        c.offset = off
        heights.append(c.input(name, node, "Height", FLT, 1.0))
    c.offset = saved
    normal = c.input(name, node, "Normal", VEC) if isinstance(node.inputs.get("Normal"), Link) else -1.0
    c.uses_frames = True
    out = c.alloc(VEC)
    c.emit("BUMP", 1.0 if node.props.get("invert") else 0.0, c.input(name, node, "Strength", FLT, 1.0),
           c.input(name, node, "Distance", FLT, 1.0), heights[0], heights[1], heights[2], normal, out)
    return {"Normal": (out, VEC)}


def _constant_output(c, name, node):
    v = node.props.get("value")
    if node.type == "ShaderNodeRGB":
        return {"Color": (c.const(tuple(v if v is not None else (0.5, 0.5, 0.5))[:3]), VEC)}
    return {"Value": (c.const((float(v if v is not None else 0.5),)), FLT)}


def _reroute(c, name, node):
    src = node.inputs.get("Input")
    if isinstance(src, Link):
        got = c.value(src)
        if got is not None:
            return {"Output": got}
    return None


_HANDLERS = {
    "ShaderNodeTexCoord": _texcoord,
    "ShaderNodeUVMap": _uvmap,
    "ShaderNodeNewGeometry": _geometry,
    "ShaderNodeFresnel": _fresnel,
    "ShaderNodeLayerWeight": _layer_weight,
    "ShaderNodeMapping": _mapping,
    "ShaderNodeAttribute": _attribute,
    "ShaderNodeVertexColor": _attribute,
    "ShaderNodeMath": _math,
    "ShaderNodeVectorMath": _vector_math,
    "ShaderNodeMix": _mix,
    "ShaderNodeMixRGB": _mix_rgb,
    "ShaderNodeInvert": _invert,
    "ShaderNodeHueSaturation": _hsv,
    "ShaderNodeBrightContrast": _bright_contrast,
    "ShaderNodeGamma": _gamma,
    "ShaderNodeSeparateColor": _separate_color,
    "ShaderNodeSeparateRGB": lambda c, n, node: _separate_color(c, n, node, legacy="Image"),
    "ShaderNodeCombineColor": _combine_color,
    "ShaderNodeCombineRGB": lambda c, n, node: _combine_color(c, n, node, legacy=True),
    "ShaderNodeSeparateXYZ": _separate_xyz,
    "ShaderNodeCombineXYZ": _combine_xyz,
    "ShaderNodeRGBToBW": _rgb_to_bw,
    "ShaderNodeClamp": _clamp,
    "ShaderNodeMapRange": _map_range,
    "ShaderNodeValToRGB": _ramp,
    "ShaderNodeRGBCurve": _curves,
    "ShaderNodeTexImage": _tex_image,
    "ShaderNodeTexChecker": _tex_checker,
    "ShaderNodeTexGradient": _tex_gradient,
    "ShaderNodeNormalMap": _normal_map,
    "ShaderNodeTexNoise": _tex_noise,
    "ShaderNodeTexVoronoi": _tex_voronoi,
    "ShaderNodeTexWave": _tex_wave,
    "ShaderNodeTexBrick": _tex_brick,
    "ShaderNodeTexMagic": _tex_magic,
    "ShaderNodeTexWhiteNoise": _tex_white_noise,
    "ShaderNodeBump": _bump,
    "ShaderNodeValue": _constant_output,
    "ShaderNodeRGB": _constant_output,
    "NodeReroute": _reroute,
}
SUPPORTED_NODES = tuple(sorted(set(_HANDLERS) | set(SHADERS)))


def compile_graph(graph: ShaderGraph, n_textures: int = 0, uv_layers: list | None = None,
                  color_layers: list | None = None, luma=LUMA_REC709) -> Program:
    """Compile ``graph`` (textures referenced by index < n_textures).

    luma: the working space's colour -> float weights (:func:`stpm_core.colorspaces.luma`).

    uv_layers: the scene-wide list of UV-map names (extended in place with the names this program
    reads; "" = each mesh's render-active map); the program's UVMAP operands index it.
    color_layers: likewise the colour-attribute names (ATTRIBUTE operands; "" = each mesh's
    render-active colour attribute).
    """
    layers = uv_layers if uv_layers is not None else []
    c = _Compiler(graph, n_textures, layers, color_layers, luma)
    c.shader(graph.surface)         # value nodes go to the value section as they are first read
    return Program(words=c.finish(), unsupported=c.unsupported, uv_layers=layers, color_layers=c.color_layers,
                   uses_mix=c.uses_mix,
                   uses_normals=c.uses_normals, uses_frames=c.uses_frames, may_emit=c.may_emit,
                   may_pass=c.may_pass, may_scatter=c.may_scatter)
