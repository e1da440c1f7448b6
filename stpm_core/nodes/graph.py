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

__all__ = ["Link", "Node", "ShaderGraph"]


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
