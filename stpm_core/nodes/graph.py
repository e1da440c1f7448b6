"""Shader node graphs as plain data: what the add-on exports from a Blender node tree and what
:mod:`stpm_core.nodes.compile` turns into a program for the kernels' interpreter.

No ``bpy`` here: a graph is nodes keyed by name, each with its Blender type (``bl_idname``), the
properties the node's formula reads (``operation``, ``blend_type``, ``interpolation``, a colour
ramp's elements, ...) and its inputs keyed by socket *identifier* (``"Value_001"``, ``"A_Color"``;
Blender's identifiers are unique where names repeat).  An input is either a constant (float, or a
3-tuple for colours and vectors; a colour's alpha is dropped) or a :class:`Link` to another node's
output identifier.  ``outputs`` records each used output's socket type (``VALUE``, ``RGBA``,
``VECTOR``, ``SHADER``) so a link can be converted as Blender converts it.

Example (a checker-textured diffuse surface)::

    ShaderGraph(nodes={
        "Checker": Node("ShaderNodeTexChecker", inputs={"Scale": 8.0, "Color1": (1, 1, 1),
                        "Color2": (0.1, 0.1, 0.1)}, outputs={"Color": "RGBA", "Fac": "VALUE"}),
        "Diffuse": Node("ShaderNodeBsdfDiffuse", inputs={"Color": Link("Checker", "Color")},
                        outputs={"BSDF": "SHADER"}),
    }, surface=Link("Diffuse", "BSDF"))

Images are referred to by index into ``Scene.textures`` (node property ``image``; -1 = none).
"""
from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["Link", "Node", "ShaderGraph", "shader_lobes"]


@dataclass(frozen=True)
class Link:
    """The output ``socket`` (identifier) of node ``node`` (name)."""

    node: str
    socket: str


@dataclass
class Node:
    """One node: Blender type, properties, inputs (constant or Link) and used outputs' types."""

    type: str
    props: dict = field(default_factory=dict)
    inputs: dict = field(default_factory=dict)
    outputs: dict = field(default_factory=dict)
    input_types: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        ins = {k: ({"link": [v.node, v.socket]} if isinstance(v, Link) else v) for k, v in self.inputs.items()}
        return {"type": self.type, "props": self.props, "inputs": ins, "outputs": self.outputs,
                "input_types": self.input_types}

    @classmethod
    def from_json(cls, d: dict) -> "Node":
        ins = {}
        for k, v in d.get("inputs", {}).items():
            if isinstance(v, dict) and "link" in v:
                ins[k] = Link(str(v["link"][0]), str(v["link"][1]))
            elif isinstance(v, (list, tuple)):
                ins[k] = tuple(float(x) for x in v)
            else:
                ins[k] = v
        return cls(type=str(d["type"]), props=dict(d.get("props", {})), inputs=ins,
                   outputs=dict(d.get("outputs", {})), input_types=dict(d.get("input_types", {})))


@dataclass
class ShaderGraph:
    """A material's node graph: ``nodes`` by name and the link feeding the output's Surface."""

    nodes: dict = field(default_factory=dict)
    surface: Link | None = None

    def to_json(self) -> dict:
        return {"nodes": {k: n.to_json() for k, n in self.nodes.items()},
                "surface": [self.surface.node, self.surface.socket] if self.surface else None}

    @classmethod
    def from_json(cls, d: dict) -> "ShaderGraph":
        s = d.get("surface")
        return cls(nodes={str(k): Node.from_json(v) for k, v in d.get("nodes", {}).items()},
                   surface=Link(str(s[0]), str(s[1])) if s else None)


# ----------------------------------------------------------------------------
# Which lobes a graph can produce (what the effects plan and the caustic tracer's aiming read)
# ----------------------------------------------------------------------------
def _may_be_nonzero(v) -> bool:
    """A linked input may be anything; a constant (float or colour tuple) must be non-zero."""
    if isinstance(v, Link):
        return True
    if isinstance(v, (tuple, list)):
        return any(float(x) != 0.0 for x in v[:3])
    return float(v) != 0.0


def _may_be(v, pred) -> bool:
    """A linked input may be anything; a constant float must satisfy ``pred``."""
    return True if isinstance(v, Link) else bool(pred(float(v if not isinstance(v, (tuple, list)) else v[0])))


def shader_lobes(graph: "ShaderGraph") -> tuple[bool, bool]:
    """(caustic, diffuse): can some hit on this graph's surface scatter through a lobe the caustic
    tracer follows / through a diffuse lobe?

    Walks the shader tree from the surface through every Mix Shader branch whose weight can be
    non-zero (a constant Fac 0 drops ``Shader_001``, 1 drops ``Shader``; a linked Fac keeps both:
    it may be anything per hit) and both Add Shader inputs.  Caustic lobes are the ones
    ``photons.trace.has_delta`` counts on a material's constants: any Glass BSDF or Glossy /
    Anisotropic BSDF (a delta at roughness 0, a glossy caustic above), a Principled BSDF whose
    Metallic or Transmission Weight may be non-zero, or whose dielectric coat may be smooth
    (Roughness may be 0 with Specular IOR Level non-zero) or whose coat layer may be smooth (Coat
    Weight non-zero, Coat Roughness may be 0).  Diffuse lobes: a Diffuse BSDF, a
    Principled base (Metallic and Transmission Weight may be below 1), any shader the interpreter
    renders as grey diffuse.  A BSDF whose colour is a constant black adds nothing.  Linked inputs
    count as "may be anything", so the answer can only err towards a lobe that never shows.

    Representative constants cannot answer this: a Mix Shader's blended roughness hides a smooth
    coat, and a textured Fac whose socket value is 0 or 1 hides a whole branch.
    """
    caustic = diffuse = False
    seen = set()
    stack = [(graph.surface, 0)]
    while stack:
        link, depth = stack.pop()
        node = graph.nodes.get(link.node) if isinstance(link, Link) else None
        if node is None or depth > 64 or link.node in seen:
            continue
        seen.add(link.node)
        t, ins = node.type, node.inputs
        if t == "ShaderNodeMixShader":
            fac = ins.get("Fac", 0.5)
            if _may_be(fac, lambda f: f < 1.0):
                stack.append((ins.get("Shader"), depth + 1))
            if _may_be(fac, lambda f: f > 0.0):
                stack.append((ins.get("Shader_001"), depth + 1))
        elif t == "ShaderNodeAddShader":
            stack += [(ins.get("Shader"), depth + 1), (ins.get("Shader_001"), depth + 1)]
        elif t in ("ShaderNodeEmission", "ShaderNodeBsdfTransparent", "ShaderNodeHoldout"):
            continue
        elif t == "ShaderNodeBsdfDiffuse":
            diffuse |= _may_be_nonzero(ins.get("Color", (0.8, 0.8, 0.8)))
        elif t in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfGlass"):
            caustic |= _may_be_nonzero(ins.get("Color", (0.8, 0.8, 0.8) if t != "ShaderNodeBsdfGlass"
                                               else (1.0, 1.0, 1.0)))
        elif t == "ShaderNodeBsdfPrincipled":
            metallic, trans = ins.get("Metallic", 0.0), ins.get("Transmission Weight", 0.0)
            smooth = _may_be(ins.get("Roughness", 0.5), lambda r: r <= 0.0)
            coat = _may_be_nonzero(ins.get("Specular IOR Level", 0.5))
            base = _may_be_nonzero(ins.get("Base Color", (0.8, 0.8, 0.8)))
            caustic |= (_may_be_nonzero(metallic) and base) or _may_be_nonzero(trans) or (smooth and coat)
            # the coat layer (Coat Weight): a delta mirror at Coat Roughness 0 (kernels.bsdf CLEARCOAT)
            caustic |= (_may_be_nonzero(ins.get("Coat Weight", 0.0))
                        and _may_be(ins.get("Coat Roughness", 0.03), lambda r: r <= 0.0))
            diffuse |= (base and _may_be(metallic, lambda m: m < 1.0) and _may_be(trans, lambda w: w < 1.0))
        else:
            diffuse = True          # an unsupported shader renders as grey diffuse (nodes.compile)
    return caustic, diffuse
