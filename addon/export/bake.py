"""Baking the shader inputs the node interpreter cannot evaluate (issue 13, item 5).

Nothing renders as a mean colour: a shader input whose upstream nodes include one the
interpreter does not evaluate (:data:`stpm_core.nodes.compile.SUPPORTED_NODES`, and the few
outputs / settings of supported nodes that fall back to a default, :func:`unsupported_reason`)
is baked by Cycles into a float texture on the object's UV map, and the exported graph reads that
texture instead (an Image Texture on a UV Map node, :func:`substitute`).  What cannot be baked is
named in the render report with the reason, and its nodes fall back to the consuming sockets'
defaults (the interpreter's own rule).

Three parts:

* **Planning** (pure Python on the exported :class:`~stpm_core.nodes.graph.ShaderGraph`, no
  ``bpy``): :func:`find_candidates` lists, per material, the shader inputs to bake (Base Color,
  Roughness, Metallic, IOR, Transmission, Specular, Emission Color / Strength, Alpha of Principled;
  Color / Roughness / IOR / Strength of Diffuse, Glossy, Glass, Emission; a Mix Shader's Fac),
  and on a shader's Normal input the Height of a Bump node and the Color of a Normal Map node
  (the Bump / Normal Map node itself keeps running in the interpreter on the baked value).  Each
  candidate carries its *blockers*: view- or path-dependent nodes (:data:`VIEW_NODES`; Geometry
  Incoming / Backfacing; Texture Coordinate Camera / Window / Reflection; a Wireframe in pixel
  units), per-instance values (:data:`INSTANCE_NODES`, Object Info Random, From Instancer,
  Instancer attributes), OSL scripts, animated nodes (keyframes or drivers on the node tree), a
  consumer inside a node group.
* **Resolving** (:class:`BakeResolver`, Blender side): per (material, object) each candidate is
  ``baked`` (a cached texture matches its key), ``missing`` (bakeable, not cached: a
  :class:`Job` for the child), ``failed`` (the child said why) or ``blocked`` (reasons).  Object
  reasons: no UV map; a bake map that leaves [0, 1] or overlaps itself (its UV triangles cover
  more than the unit square); an instance whose subtree reads world-space or per-object values.
  The bake map is a UV map named ``stpm_bake`` when the mesh has one, else its render-active map.
* **Baking** (:func:`run_jobs`): ONE child process per call, on a copy of the .blend saved with
  ``save_as_mainfile(copy=True)`` (an unsaved session likewise): real Blender runs
  ``blender -b --factory-startup copy.blend --python bake_child.py -- spec.json``; the pip ``bpy``
  module (``bpy.app.binary_path`` empty) runs ``python bake_child.py spec.json``, which opens the
  copy.  The child (:mod:`.bake_child`) rewires each input's source socket into an Emission
  shader on the Material Output, bakes EMIT with Cycles (:data:`BAKE_SAMPLES` samples, margin
  ``max(4, res // 64)`` texels, Extend) into a float image on the bake UV map and writes a 32-bit
  EXR into the cache.

The cache key (:meth:`BakeResolver.key`) hashes the Blender-side subtree feeding the input (node
types, every property including colour ramps, curves and image users, unlinked socket values,
links, whole node-group trees, images by file size and modification time / packed bytes /
generator settings / pixels when edited, other objects by transform), the evaluated mesh (every
attribute but selection and hiding: positions, topology, UV maps, colour attributes; texture
space), the bake map, resolution, samples, kind and Blender's version; with a world-space or
per-object subtree also the object's matrix, colour, pass index and custom properties.  Names are
not hashed: linked duplicates and renamed materials share bakes.

Cache folder (:func:`cache_dirs`): ``$STPM_BAKE_CACHE`` when set; else ``stpm_bake_cache`` next to
the saved .blend, then the user cache (``$XDG_CACHE_HOME/stpm/bake``, ``~/.cache/stpm/bake``),
which is the only one for an unsaved file.  Look-ups search every folder; bakes are written to
the first writable one.  Files: ``<key>.exr`` and ``<key>.json`` (what was baked, for people).

Worlds the exporter cannot read directly (a Sky Texture, Light Path tricks, ...) are baked by the
same child into equirectangular images (:mod:`.world`: :func:`.world.plan_world_jobs` adds their
jobs in :func:`bake_scene`; the child runs :mod:`.world_bake_child` for them).

A material used by several objects is exported once per distinct set of bakes (one material per
(material, bake keys) pair): objects with different UVs or meshes get their own textures, linked
duplicates share one.

No heavy work at import: ``bpy`` and ``numpy`` are imported where used.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

from .._core import sub

_graph = sub("nodes.graph")
Link, Node, ShaderGraph = _graph.Link, _graph.Node, _graph.ShaderGraph

__all__ = ["Candidate", "find_candidates", "substitute", "prune", "BakeResolver", "Status", "Job",
           "cache_dirs", "run_jobs", "bake_scene", "plan_jobs", "STATS", "DEFAULT_RESOLUTION", "BAKE_UV_MAP"]

BAKE_VERSION = 1
DEFAULT_RESOLUTION = 512
BAKE_SAMPLES = 8
BAKE_UV_MAP = "stpm_bake"           # a UV map of this name is the bake map when the mesh has one
CACHE_DIRNAME = "stpm_bake_cache"
CHILD_SCRIPT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "bake_child.py")
OPERATOR_HINT = "Render Properties > Baking > Bake Unsupported Inputs (stpm.bake_inputs), or `stpm render`"

# What the bakes of this process did: child processes started, jobs baked, seconds (tests, UI)
STATS = {"child_runs": 0, "jobs": 0, "seconds": 0.0, "last": None}

# Shader inputs that the interpreter reads, per shader type: (identifier, kind).  kind "color"
# (a colour), "float" (a scalar: baked as grey, Non-Color), "data" (a colour that is data: a
# Normal Map's Color, Non-Color).
SHADER_INPUTS = {
    "ShaderNodeBsdfPrincipled": (("Base Color", "color"), ("Metallic", "float"), ("Roughness", "float"),
                                 ("IOR", "float"), ("Transmission Weight", "float"),
                                 ("Specular IOR Level", "float"), ("Emission Color", "color"),
                                 ("Emission Strength", "float"), ("Alpha", "float")),
    "ShaderNodeBsdfDiffuse": (("Color", "color"),),
    "ShaderNodeBsdfGlossy": (("Color", "color"), ("Roughness", "float")),
    "ShaderNodeBsdfAnisotropic": (("Color", "color"), ("Roughness", "float")),
    "ShaderNodeBsdfGlass": (("Color", "color"), ("Roughness", "float"), ("IOR", "float")),
    "ShaderNodeEmission": (("Color", "color"), ("Strength", "float")),
    "ShaderNodeBsdfTransparent": (("Color", "color"),),
    "ShaderNodeMixShader": (("Fac", "float"),),
}
NORMAL_SHADERS = ("ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy",
                  "ShaderNodeBsdfAnisotropic", "ShaderNodeBsdfGlass")

# Nodes whose value depends on the view direction, the light path or rays traced around the hit:
# a texture cannot hold them
VIEW_NODES = {
    "ShaderNodeLightPath": "depends on the light path",
    "ShaderNodeFresnel": "depends on the view direction",
    "ShaderNodeLayerWeight": "depends on the view direction",
    "ShaderNodeCameraData": "depends on the camera",
    "ShaderNodeAmbientOcclusion": "traces rays around the hit (ambient occlusion)",
    "ShaderNodeBevel": "traces rays around the hit (bevel)",
    "ShaderNodeLightFalloff": "depends on the light path",
    "ShaderNodeShaderToRGB": "works in EEVEE only",
}
# Nodes whose value differs per particle / instance / hair strand
INSTANCE_NODES = {
    "ShaderNodeParticleInfo": "differs per particle",
    "ShaderNodeHairInfo": "differs per hair strand",
    "ShaderNodePointInfo": "differs per point",
    "ShaderNodeVolumeInfo": "is a volume attribute",
}
VIEW_OUTPUTS = {
    "ShaderNodeTexCoord": ("Camera", "Window", "Reflection"),
    "ShaderNodeNewGeometry": ("Incoming", "Backfacing"),
}
# Outputs of nodes the interpreter supports that it does not evaluate (their consumers read
# their default): a subtree reading them is baked
UNSUPPORTED_OUTPUTS = {
    "ShaderNodeNewGeometry": ("Tangent", "Parametric", "Pointiness", "Random Per Island"),
    "ShaderNodeTexCoord": ("Camera", "Window"),
}
# Nodes whose values are in world space or per object: with them the object's transform is part
# of the bake key (and an instance cannot use its original object's bake)
WORLD_NODES = ("ShaderNodeNewGeometry", "ShaderNodeObjectInfo", "ShaderNodeVectorTransform", "ShaderNodeTangent",
               "ShaderNodeNormal", "ShaderNodeTexEnvironment", "ShaderNodeTexSky", "ShaderNodeTexPointDensity",
               "ShaderNodeTexIES")


# ----------------------------------------------------------------------------
# Planning: pure Python on the exported graph
# ----------------------------------------------------------------------------
@dataclass
class Candidate:
    """One input to bake: ``socket`` (identifier) of node ``consumer`` (graph name)."""

    consumer: str
    socket: str
    kind: str                                   # "color" / "float" / "data"
    label: str                                  # for messages: "Base Color of 'Principled BSDF'"
    unsupported: list = field(default_factory=list)   # [(node name, node type, why)]: why it is baked
    nodes: list = field(default_factory=list)         # every node of the subtree, walk order
    blockers: list = field(default_factory=list)      # why it cannot be baked (empty: bakeable)
    world: bool = False                               # reads world-space or per-object values

    @property
    def bakeable(self) -> bool:
        return not self.blockers

    def cause(self) -> str:
        """'node 'Gabor Texture' (ShaderNodeTexGabor) is not supported by the interpreter'."""
        parts = [f"node {n!r} ({t}) {why}" for n, t, why in self.unsupported[:3]]
        if len(self.unsupported) > 3:
            parts.append(f"{len(self.unsupported) - 3} more")
        return "; ".join(parts)


def _supported_set(supported=None) -> set:
    return set(sub("nodes.compile").SUPPORTED_NODES if supported is None else supported)


def upstream(graph: ShaderGraph, link: Link, stop=None) -> tuple:
    """(names, used) of the subtree feeding ``link``: node names in walk order and the set of
    (node, output id) pairs read inside it (``link``'s own included).  ``stop(name, input id)``
    True: that input is not followed."""
    names, used, seen = [], {(link.node, link.socket)}, set()
    stack = [link.node]
    while stack:
        name = stack.pop()
        if name in seen or name not in graph.nodes:
            continue
        seen.add(name)
        names.append(name)
        for ident, v in graph.nodes[name].inputs.items():
            if isinstance(v, Link) and not (stop is not None and stop(name, ident)):
                used.add((v.node, v.socket))
                stack.append(v.node)
    return names, used


def unsupported_reason(node: Node, outputs: set, supported: set) -> str | None:
    """Why the interpreter falls back to a default for ``node`` (with its read ``outputs``), or
    None when it evaluates it (approximations such as a Box projection or a Cardinal ramp are
    the interpreter's own, named by its compiler, and not baked)."""
    ops = sub("nodes.ops")
    t, p = node.type, node.props
    if t not in supported:
        return "is not supported by the interpreter"
    bad = [o for o in UNSUPPORTED_OUTPUTS.get(t, ()) if o in outputs]
    if bad:
        return f"has its {', '.join(bad)} output read, which the interpreter does not evaluate"
    if t == "ShaderNodeTexCoord" and p.get("object"):
        return "reads coordinates from another object, which the interpreter does not"
    if t == "ShaderNodeMath" and p.get("operation", "ADD") not in ops.MATH_OPS:
        return f"has operation {p.get('operation')}, which the interpreter does not evaluate"
    if t == "ShaderNodeVectorMath" and p.get("operation", "ADD") not in ops.VMATH_OPS:
        return f"has operation {p.get('operation')}, which the interpreter does not evaluate"
    if t in ("ShaderNodeMix", "ShaderNodeMixRGB"):
        if t == "ShaderNodeMix" and p.get("data_type", "FLOAT") not in ("FLOAT", "VECTOR", "RGBA"):
            return f"has data type {p.get('data_type')}, which the interpreter does not evaluate"
        if (t == "ShaderNodeMixRGB" or p.get("data_type") == "RGBA") and \
                p.get("blend_type", "MIX") not in ops.BLEND_MODES:
            return f"has blend mode {p.get('blend_type')}, which the interpreter does not evaluate"
    if t == "ShaderNodeMapRange" and p.get("data_type", "FLOAT") != "FLOAT":
        return "has the vector data type, which the interpreter does not evaluate"
    if t == "ShaderNodeNormalMap" and p.get("space", "TANGENT") not in ops.NORMAL_MAP_SPACES:
        return f"has space {p.get('space')}, which the interpreter does not evaluate"
    if t == "ShaderNodeRGBCurve" and p.get("table") is None:
        return "has no sampled curve table"
    return None


def blocker_reason(name: str, node: Node, outputs: set) -> str | None:
    """Why a subtree holding ``node`` (with its read ``outputs``) cannot be baked, or None."""
    t, p = node.type, node.props
    if t in VIEW_NODES:
        return f"node {name!r} ({t}) {VIEW_NODES[t]}"
    if t in INSTANCE_NODES:
        return f"node {name!r} ({t}) {INSTANCE_NODES[t]}"
    if t == "ShaderNodeScript":
        return f"node {name!r} ({t}) is an OSL script"
    view = [o for o in VIEW_OUTPUTS.get(t, ()) if o in outputs]
    if view:
        return f"node {name!r} ({t}): its {', '.join(view)} output depends on the view"
    if t == "ShaderNodeWireframe" and p.get("use_pixel_size"):
        return f"node {name!r} ({t}) has its width in pixels (depends on the view)"
    if t == "ShaderNodeObjectInfo" and "Random" in outputs:
        return f"node {name!r} ({t}): its Random output differs per object instance"
    if p.get("from_instancer"):
        return f"node {name!r} ({t}) reads From Instancer (differs per instance)"
    if t == "ShaderNodeAttribute" and p.get("attribute_type") == "INSTANCER":
        return f"node {name!r} ({t}) reads an instancer attribute (differs per instance)"
    return None


def _world(node: Node) -> bool:
    t, p = node.type, node.props
    return (t in WORLD_NODES or (t == "ShaderNodeTexCoord" and bool(p.get("object")))
            or (t == "ShaderNodeAttribute" and p.get("attribute_type", "GEOMETRY") != "GEOMETRY"))


def _matches(name: str, names) -> str | None:
    """``name`` or the node group it was inlined from ("Group/Inner": "Group") when in ``names``."""
    parts = name.split("/")
    for k in range(len(parts), 0, -1):
        if "/".join(parts[:k]) in names:
            return "/".join(parts[:k])
    return None


def _candidate(graph, consumer: str, socket: str, kind: str, label: str, link: Link, supported: set,
               grouped, extra: dict, stop=None) -> Candidate | None:
    names, used = upstream(graph, link, stop)
    outputs: dict = {}
    for n, o in used:
        outputs.setdefault(n, set()).add(o)
    unsupported = []
    for n in names:
        why = unsupported_reason(graph.nodes[n], outputs.get(n, set()), supported)
        if why is not None:
            unsupported.append((n, graph.nodes[n].type, why))
    if not unsupported:
        return None
    blockers = []
    for n in names:
        why = blocker_reason(n, graph.nodes[n], outputs.get(n, set()))
        if why is not None:
            blockers.append(why)
        hit = _matches(n, extra)
        if hit is not None and extra[hit] not in blockers:
            blockers.append(extra[hit])
    if consumer in grouped:
        blockers.append(f"its node {consumer!r} is inside a node group (only top-level inputs are baked)")
    world = any(_world(graph.nodes[n]) for n in names)
    return Candidate(consumer=consumer, socket=socket, kind=kind, label=label, unsupported=unsupported,
                     nodes=names, blockers=blockers, world=world)


def shader_nodes(graph: ShaderGraph) -> list:
    """The shader nodes the surface reaches through shader links, in walk order."""
    out, seen = [], set()
    stack = [graph.surface.node] if graph.surface is not None else []
    while stack:
        name = stack.pop()
        if name in seen or name not in graph.nodes:
            continue
        seen.add(name)
        node = graph.nodes[name]
        out.append(name)
        for v in node.inputs.values():
            if isinstance(v, Link) and graph.nodes.get(v.node) is not None and \
                    graph.nodes[v.node].outputs.get(v.socket) == "SHADER":
                stack.append(v.node)
    return out


def find_candidates(graph: ShaderGraph, grouped=(), extra_blockers=None, supported=None) -> list:
    """The inputs of ``graph`` to bake, each with its blockers (see the module docstring).

    grouped : graph names of nodes inlined from node groups.
    extra_blockers : {graph name (or node-group prefix): reason} known on the Blender side
        (animated nodes).
    supported : node types the interpreter evaluates (default: ``SUPPORTED_NODES``).
    """
    supported = _supported_set(supported)
    extra = dict(extra_blockers or {})
    grouped = set(grouped)
    out = []
    for name in shader_nodes(graph):
        node = graph.nodes[name]
        for ident, kind in SHADER_INPUTS.get(node.type, ()):
            v = node.inputs.get(ident)
            if isinstance(v, Link):
                c = _candidate(graph, name, ident, kind, f"{ident} of {name!r}", v, supported, grouped, extra)
                if c is not None:
                    out.append(c)
        v = node.inputs.get("Normal")
        if node.type in NORMAL_SHADERS and isinstance(v, Link):
            out.extend(_normal_candidates(graph, name, v, supported, grouped, extra))
    return out


def _normal_candidates(graph, shader: str, link: Link, supported, grouped, extra) -> list:
    """Candidates on a shader's Normal input: each Bump Height and Normal Map Color along the
    chain (Bump Normal inputs followed), and one blocked candidate for unsupported nodes
    elsewhere in the Normal subtree (a normal is not baked as such)."""
    out, todo, seen = [], [link], set()
    keep = {"ShaderNodeBump": ("Height", "float"), "ShaderNodeNormalMap": ("Color", "data")}

    def stop(name, ident):
        node = graph.nodes[name]
        return node.type in keep and (ident == keep[node.type][0] or (node.type == "ShaderNodeBump"
                                                                      and ident == "Normal"))
    while todo:
        lk = todo.pop()
        node = graph.nodes.get(lk.node)
        if node is None or lk.node in seen or node.type not in keep:
            continue
        seen.add(lk.node)
        ident, kind = keep[node.type]
        v = node.inputs.get(ident)
        if isinstance(v, Link):
            c = _candidate(graph, lk.node, ident, kind, f"{ident} of {lk.node!r} (the Normal of {shader!r})", v,
                           supported, grouped, extra)
            if c is not None:
                out.append(c)
        nv = node.inputs.get("Normal")
        if node.type == "ShaderNodeBump" and isinstance(nv, Link):
            todo.append(nv)
    rest = _candidate(graph, shader, "Normal", "data", f"Normal of {shader!r}", link, supported, grouped, extra,
                      stop=stop)
    if rest is not None:
        rest.blockers.insert(0, "a normal is baked only as a Bump node's Height or a Normal Map node's Color")
        out.append(rest)
    return out


def substitute(graph: ShaderGraph, cand: Candidate, texture: int, uv_map: str) -> None:
    """Replace ``cand``'s input in ``graph`` by an Image Texture (Linear, Extend) of texture
    index ``texture`` read on UV map ``uv_map`` (in place)."""
    base = f"stpm bake/{cand.consumer}/{cand.socket}"
    graph.nodes[base + "/uv"] = Node(type="ShaderNodeUVMap", props={"uv_map": uv_map, "from_instancer": False},
                                     outputs={"UV": "VECTOR"})
    graph.nodes[base + "/image"] = Node(
        type="ShaderNodeTexImage",
        props={"interpolation": "Linear", "extension": "EXTEND", "projection": "FLAT", "image": int(texture)},
        inputs={"Vector": Link(base + "/uv", "UV")}, input_types={"Vector": "VECTOR"}, outputs={"Color": "RGBA"})
    consumer = graph.nodes[cand.consumer]
    consumer.inputs[cand.socket] = Link(base + "/image", "Color")
    consumer.input_types.setdefault(cand.socket, "VALUE" if cand.kind == "float" else "RGBA")


def prune(graph: ShaderGraph) -> list:
    """Drop the nodes the surface no longer reaches (after :func:`substitute`); returns their names."""
    keep = set()
    if graph.surface is not None:
        keep = set(upstream(graph, graph.surface)[0])
    gone = [n for n in graph.nodes if n not in keep]
    for n in gone:
        del graph.nodes[n]
    return gone


# ----------------------------------------------------------------------------
# Blender side: signatures, cache, resolving
# ----------------------------------------------------------------------------
def user_cache_dir() -> str:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    if sys.platform == "win32":
        base = os.environ.get("LOCALAPPDATA") or base
    elif sys.platform == "darwin":
        base = os.path.join(os.path.expanduser("~"), "Library", "Caches")
    return os.path.join(base, "stpm", "bake")


def cache_dirs(blend_path: str | None = None) -> list:
    """Folders searched for bakes, the first writable one written to (module docstring)."""
    env = os.environ.get("STPM_BAKE_CACHE")
    if env:
        return [os.path.abspath(env)]
    dirs = []
    if blend_path:
        dirs.append(os.path.join(os.path.dirname(os.path.abspath(blend_path)), CACHE_DIRNAME))
    dirs.append(user_cache_dir())
    return dirs


def writable_dir(dirs) -> str:
    """The first folder of ``dirs`` that exists or can be made and takes files."""
    for d in dirs:
        try:
            os.makedirs(d, exist_ok=True)
            fd, probe = tempfile.mkstemp(prefix=".probe-", dir=d)
            os.close(fd)
            os.unlink(probe)
            return d
        except OSError:
            continue
    raise OSError(f"no writable bake cache folder among {', '.join(dirs)}")


def _plain(v):
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (bool, int, str)) or v is None:
        return v
    try:
        return [_plain(x) for x in v]
    except TypeError:
        return repr(v)


_BASE_NODE_PROPS: dict = {}
_SKIP_PROPS = {"rna_type", "name", "label", "location", "location_absolute", "width", "height", "dimensions",
               "select", "show_options", "show_preview", "show_texture", "hide", "color", "use_custom_color",
               "parent", "inputs", "outputs", "internal_links", "bl_idname", "bl_label", "bl_description",
               "bl_icon", "bl_static_type", "bl_width_default", "bl_width_min", "bl_width_max",
               "bl_height_default", "bl_height_min", "bl_height_max", "type", "id_data", "warning_propagation",
               "color_tag", "is_active_output"}


def _file_sig(path: str):
    try:
        st = os.stat(path)
        return [st.st_size, st.st_mtime_ns]
    except OSError:
        return None


def image_signature(image) -> list:
    """What identifies an image's pixels for the bake key (module docstring)."""
    import bpy
    sig = [image.source, image.colorspace_settings.name, str(getattr(image, "alpha_mode", "")),
           list(image.size), bool(image.is_float)]
    if getattr(image, "is_dirty", False):
        import numpy as np
        px = np.empty(len(image.pixels), np.float32)
        image.pixels.foreach_get(px)
        sig.append(hashlib.sha256(px.tobytes()).hexdigest())
    elif image.packed_file is not None:
        sig.append(hashlib.sha256(bytes(image.packed_file.data)).hexdigest())
    elif image.source == "GENERATED":
        sig.append([image.generated_type, image.generated_width, image.generated_height,
                    _plain(tuple(image.generated_color)), bool(image.use_generated_float)])
    else:
        path = bpy.path.abspath(image.filepath, library=image.library)
        sig.extend([os.path.normpath(path), _file_sig(path)])
    return sig


def _id_signature(idb, memo: dict):
    import bpy
    if isinstance(idb, bpy.types.Image):
        return ["IMAGE", image_signature(idb)]
    if isinstance(idb, bpy.types.Object):
        return ["OBJECT", idb.name_full, _plain([tuple(r) for r in idb.matrix_world])]
    if isinstance(idb, bpy.types.NodeTree):
        return ["TREE", tree_signature(idb, memo)]
    if isinstance(idb, bpy.types.Text):
        return ["TEXT", hashlib.sha256(idb.as_string().encode()).hexdigest()]
    return [type(idb).__name__, getattr(idb, "name_full", "")]


def _rna_signature(struct, memo: dict, depth: int = 0, skip=_SKIP_PROPS):
    """Every property of an RNA struct as plain data: numbers, enums, strings, arrays; ID
    pointers by :func:`_id_signature`; nested structs (colour ramps, curve mappings, image
    users, texture mappings) and collections recursively (depth <= 4, 1024 items)."""
    import bpy
    out = {}
    for p in struct.bl_rna.properties:
        ident = p.identifier
        if ident in skip:
            continue
        try:
            v = getattr(struct, ident)
        except (AttributeError, RuntimeError):
            continue
        if p.type == "POINTER":
            if v is None:
                out[ident] = None
            elif isinstance(v, bpy.types.ID):
                out[ident] = _id_signature(v, memo)
            elif depth < 4:
                out[ident] = _rna_signature(v, memo, depth + 1, skip={"rna_type", "id_data"})
        elif p.type == "COLLECTION":
            if depth < 4:
                out[ident] = [(_id_signature(x, memo) if isinstance(x, bpy.types.ID)
                               else _rna_signature(x, memo, depth + 1, skip={"rna_type", "id_data"}))
                              for x in list(v)[:1024]]
        elif p.type == "ENUM" and getattr(p, "is_enum_flag", False):
            out[ident] = sorted(v)
        else:
            out[ident] = _plain(v)
    return out


def _node_props_signature(node, memo: dict):
    import bpy
    base = _BASE_NODE_PROPS.get("ids")
    if base is None:
        base = _BASE_NODE_PROPS["ids"] = frozenset(p.identifier for p in bpy.types.ShaderNode.bl_rna.properties)
    return _rna_signature(node, memo, 0, skip=_SKIP_PROPS | (base - {"mute"}))


def _socket_value(sock):
    return _plain(getattr(sock, "default_value", None)) if hasattr(sock, "default_value") else None


def _node_signature(node, memo: dict) -> list:
    ins = []
    for s in node.inputs:
        links = [[l.from_node.name, l.from_socket.identifier, bool(getattr(l, "is_muted", False))]
                 for l in s.links] if s.is_linked else []
        ins.append([s.identifier, bool(getattr(s, "enabled", True)), None if links else _socket_value(s), links])
    outs = [[o.identifier, _socket_value(o)] for o in node.outputs if hasattr(o, "default_value")]
    return [node.bl_idname, node.name, bool(node.mute), _node_props_signature(node, memo), ins, outs]


def tree_signature(tree, memo: dict) -> str:
    """A node tree's whole content (every node and link), hashed; memoised per tree."""
    key = tree.as_pointer()
    if key in memo:
        return memo[key]
    memo[key] = "cycle"
    data = [tree.bl_idname, sorted((_node_signature(n, memo) for n in tree.nodes), key=lambda x: x[1])]
    memo[key] = hashlib.sha256(json.dumps(data, sort_keys=True, default=repr).encode()).hexdigest()
    return memo[key]


def socket_signature(node, ident: str, memo: dict) -> str:
    """The Blender-side subtree feeding input ``ident`` of ``node`` (module docstring), hashed.
    Every node reached through links (any input) is included; a node group by its whole tree."""
    sock = next((s for s in node.inputs if s.identifier == ident), None)
    if sock is None:
        return ""
    stack = [l.from_node for l in sock.links] if sock.is_linked else []
    seen, data = set(), [[sock.identifier, [[l.from_node.name, l.from_socket.identifier,
                                             bool(getattr(l, "is_muted", False))] for l in sock.links]]]
    while stack:
        n = stack.pop()
        if n.as_pointer() in seen:
            continue
        seen.add(n.as_pointer())
        data.append(_node_signature(n, memo))
        for s in n.inputs:
            if s.is_linked:
                stack.extend(l.from_node for l in s.links)
    return hashlib.sha256(json.dumps(data, sort_keys=True, default=repr).encode()).hexdigest()


_ATTR = {"FLOAT": (1, "value", "f4"), "INT": (1, "value", "i4"), "INT8": (1, "value", "i4"),
         "BOOLEAN": (1, "value", "?"), "FLOAT_VECTOR": (3, "vector", "f4"), "FLOAT2": (2, "vector", "f4"),
         "INT32_2D": (2, "value", "i4"), "FLOAT_COLOR": (4, "color", "f4"), "BYTE_COLOR": (4, "color", "f4"),
         "QUATERNION": (4, "value", "f4"), "FLOAT4X4": (16, "value", "f4")}
_ATTR_SKIP = (".select", ".uv_select", ".hide", "select", ".sculpt")


def mesh_signature(me) -> str:
    """The evaluated mesh's attributes (positions, topology, UV maps, colours, ...; not selection
    or hiding), polygon starts and texture space, hashed."""
    import numpy as np
    h = hashlib.sha256()
    h.update(repr((len(me.vertices), len(me.edges), len(me.loops), len(me.polygons))).encode())
    for a in sorted(me.attributes, key=lambda a: a.name):
        if a.name.startswith(_ATTR_SKIP):
            continue
        h.update(f"|{a.name}|{a.domain}|{a.data_type}|".encode())
        spec = _ATTR.get(a.data_type)
        if spec is None:
            continue
        comp, key, dt = spec
        buf = np.empty(len(a.data) * comp, dtype=dt)
        try:
            a.data.foreach_get(key, buf)
        except (TypeError, RuntimeError, AttributeError):
            continue
        h.update(buf.tobytes())
    ls = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("loop_start", ls)
    h.update(ls.tobytes())
    h.update(repr((bool(getattr(me, "use_auto_texspace", True)), _plain(tuple(me.texspace_location)),
                   _plain(tuple(me.texspace_size)))).encode())
    return h.hexdigest()


def bake_uv_map(me) -> str | None:
    """The bake map of mesh ``me``: ``stpm_bake`` when present, else the render-active UV map."""
    layers = getattr(me, "uv_layers", None)
    if layers is None or len(layers) == 0:
        return None
    if BAKE_UV_MAP in layers:
        return BAKE_UV_MAP
    return next((l.name for l in layers if getattr(l, "active_render", False)), layers[0].name)


def uv_problem(me, name: str) -> str | None:
    """Why UV map ``name`` of ``me`` cannot hold a bake: it leaves [0, 1], or its triangles cover
    more than the unit square (it overlaps itself); None when it can."""
    import numpy as np
    n = len(me.loops)
    if n == 0:
        return None
    uv = np.empty(n * 2, np.float32)
    layer = me.uv_layers[name]
    if hasattr(layer, "uv"):
        layer.uv.foreach_get("vector", uv)
    else:
        layer.data.foreach_get("uv", uv)
    uv = uv.reshape(-1, 2)
    lo, hi = float(uv.min()), float(uv.max())
    if lo < -1e-4 or hi > 1.0 + 1e-4:
        return f"its UV map {name!r} leaves the [0, 1] square (u, v from {lo:.3g} to {hi:.3g})"
    me.calc_loop_triangles()
    F = len(me.loop_triangles)
    loops = np.empty(F * 3, np.int32)
    me.loop_triangles.foreach_get("loops", loops)
    t = uv[loops].reshape(F, 3, 2).astype(np.float64)
    e1, e2 = t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]
    area = 0.5 * float(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum())
    if area > 1.001:
        return f"its UV map {name!r} overlaps itself (its triangles cover {area:.3g} times the [0, 1] square)"
    return None


def _fcurves(anim) -> list:
    """F-curves of an AnimData: its action's (layered actions of Blender 4.4+ and legacy) and drivers."""
    curves = list(getattr(anim, "drivers", []) or [])
    action = getattr(anim, "action", None)
    if action is not None:
        curves.extend(getattr(action, "fcurves", []) or [])
        for layer in getattr(action, "layers", []) or []:
            for strip in layer.strips:
                for bag in getattr(strip, "channelbags", []) or []:
                    curves.extend(bag.fcurves)
    return curves


_NODE_PATH = re.compile(r'nodes\["((?:[^"\\]|\\.)*)"\]')


def animated_nodes(tree, prefix: str = "", memo=None) -> dict:
    """{graph name: reason} of the nodes of ``tree`` that keyframes or drivers change (a node
    group instance whose tree is animated: the group node's name, covering its inlined nodes)."""
    memo = {} if memo is None else memo
    out = {}
    anim = getattr(tree, "animation_data", None)
    for fc in (_fcurves(anim) if anim is not None else []):
        m = _NODE_PATH.match(fc.data_path or "")
        if m:
            name = m.group(1).replace('\\"', '"')
            out[prefix + name] = f"node {prefix + name!r} is animated (keyframes or drivers): a bake holds one frame"
    for node in tree.nodes:
        if node.bl_idname == "ShaderNodeGroup" and node.node_tree is not None:
            key = node.node_tree.as_pointer()
            if key not in memo:
                memo[key] = False
                memo[key] = bool(animated_nodes(node.node_tree, "", memo))
            if memo[key]:
                out[prefix + node.name] = (f"node group {prefix + node.name!r} is animated (keyframes or drivers): "
                                           f"a bake holds one frame")
    return out


@dataclass
class Job:
    """One bake for the child (plain data: ``to_json``)."""

    key: str
    object: str
    material: str
    node: str
    socket: str
    kind: str
    uv_map: str
    resolution: int
    path: str
    label: str

    def to_json(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Status:
    """What happens to one candidate on one object: state ``baked`` / ``missing`` / ``failed`` /
    ``blocked``."""

    cand: Candidate
    state: str
    reasons: list = field(default_factory=list)
    key: str | None = None
    path: str | None = None
    uv_map: str | None = None
    job: Job | None = None


@dataclass
class MaterialInputs:
    candidates: list
    signatures: dict           # (consumer, socket) -> Blender-side subtree signature


class BakeResolver:
    """Per (material, object): the status of each input to bake (module docstring).

    depsgraph : the evaluated depsgraph of the export (its scene gives the resolution).
    resolution : bake size in texels (square); default ``scene.stpm.bake_resolution``.
    dirs : cache folders (default :func:`cache_dirs` of the open file).
    failed : {key: error} of bakes the child could not make (reported instead of "missing").
    """

    def __init__(self, depsgraph=None, *, resolution: int | None = None, dirs=None, failed=None,
                 samples: int = BAKE_SAMPLES):
        import bpy
        scene = getattr(depsgraph, "scene", None) if depsgraph is not None else None
        if resolution is None:
            resolution = int(getattr(getattr(scene, "stpm", None), "bake_resolution", DEFAULT_RESOLUTION))
        self.resolution = max(4, int(resolution))
        self.samples = int(samples)
        self.dirs = list(dirs) if dirs is not None else cache_dirs(bpy.data.filepath or None)
        self.failed = dict(failed or {})
        self.depsgraph = depsgraph
        self._inputs: dict = {}
        self._mesh: dict = {}
        self._uv: dict = {}
        self._memo: dict = {}

    # -- per material ---------------------------------------------------------------------
    def inputs(self, mat) -> MaterialInputs:
        """The material's candidates (memoised)."""
        key = mat.name_full
        if key in self._inputs:
            return self._inputs[key]
        from . import nodes as node_export
        from .materials import find_output, uses_nodes
        cands, sigs = [], {}
        tree = mat.node_tree if uses_nodes(mat) else None
        out = find_output(tree)[0] if tree is not None else None
        if out is not None:
            builder = node_export.GraphBuilder()
            try:
                graph = builder.build(out)
            except RecursionError:
                graph = None
            if graph is not None:
                extra = animated_nodes(tree)
                cands = find_candidates(graph, grouped=builder.grouped, extra_blockers=extra)
                for c in cands:
                    node = tree.nodes.get(c.consumer)
                    if c.bakeable and node is not None:
                        sigs[(c.consumer, c.socket)] = socket_signature(node, c.socket, self._memo)
        self._inputs[key] = MaterialInputs(cands, sigs)
        return self._inputs[key]

    # -- per object -----------------------------------------------------------------------
    def _mesh_sig(self, me) -> str:
        k = me.as_pointer()
        if k not in self._mesh:
            self._mesh[k] = mesh_signature(me)
        return self._mesh[k]

    def key(self, info: MaterialInputs, cand: Candidate, obj, me, uv_map: str) -> str:
        import bpy
        data = [BAKE_VERSION, bpy.app.version_string, info.signatures.get((cand.consumer, cand.socket), ""),
                cand.kind, self.resolution, self.samples, uv_map, self._mesh_sig(me)]
        from .nodes import working_space
        working = working_space()
        if working != "REC709":               # bakes hold working-space values (older keys unchanged)
            data.append(working)
        if cand.world:
            props = {k: _plain(obj.get(k)) for k in obj.keys()} if hasattr(obj, "keys") else {}
            data.append([_plain([tuple(r) for r in obj.matrix_world]), _plain(tuple(obj.color)),
                         int(getattr(obj, "pass_index", 0)), json.dumps(props, sort_keys=True, default=repr)])
        return hashlib.sha256(json.dumps(data, default=repr).encode()).hexdigest()[:24]

    def find(self, key: str) -> str | None:
        for d in self.dirs:
            p = os.path.join(d, key + ".exr")
            if os.path.isfile(p):
                return p
        return None

    def status(self, mat, obj, is_instance: bool = False) -> list:
        """[Status] of every candidate of ``mat`` on the evaluated object ``obj``."""
        import bpy
        info = self.inputs(mat)
        if not info.candidates:
            return []
        me = obj.data if isinstance(getattr(obj, "data", None), bpy.types.Mesh) else None
        oname = obj.name
        uv = bake_uv_map(me) if me is not None else None
        obj_reasons = []
        if me is None:
            obj_reasons.append(f"object {oname!r} has no mesh of its own")
        elif uv is None:
            obj_reasons.append(f"object {oname!r} has no UV map (unwrap it: a bake is stored on a UV map)")
        else:
            k = (me.as_pointer(), uv)
            if k not in self._uv:
                self._uv[k] = uv_problem(me, uv)
            why = self._uv[k]
            if why is not None:
                obj_reasons.append(f"object {oname!r}: {why} (add a non-overlapping map named {BAKE_UV_MAP!r} "
                                   f"inside [0, 1])")
        original = getattr(obj, "original", obj)
        if is_instance and me is not None and not obj_reasons:
            try:   # the instance draws its original object's evaluated mesh (not generated geometry)
                ev = original.evaluated_get(self.depsgraph) if self.depsgraph is not None else original
                own = isinstance(ev.data, bpy.types.Mesh) and ev.data.as_pointer() == me.as_pointer()
            except (AttributeError, ReferenceError, RuntimeError):
                own = False
            if not own:
                obj_reasons.append(f"object {oname!r} is an instance of generated geometry (no object of its own "
                                   f"to bake)")
        out = []
        for cand in info.candidates:
            reasons = list(cand.blockers)
            if not reasons:
                reasons = list(obj_reasons)
                if is_instance and cand.world:
                    reasons.append(f"object {oname!r} is an instance and the input reads world-space or per-object "
                                   f"values (they differ per instance)")
            if reasons:
                out.append(Status(cand, "blocked", reasons))
                continue
            key = self.key(info, cand, obj, me, uv)
            path = self.find(key)
            if path is not None:
                out.append(Status(cand, "baked", key=key, path=path, uv_map=uv))
            elif key in self.failed:
                out.append(Status(cand, "failed", [self.failed[key]], key=key, uv_map=uv))
            else:
                job = Job(key=key, object=original.name, material=mat.name, node=cand.consumer, socket=cand.socket,
                          kind=cand.kind, uv_map=uv, resolution=self.resolution, path="", label=cand.label)
                out.append(Status(cand, "missing", key=key, uv_map=uv, job=job))
        return out


# ----------------------------------------------------------------------------
# Planning a scene and running the child
# ----------------------------------------------------------------------------
def plan_jobs(depsgraph, resolver: BakeResolver) -> list:
    """The missing bakes of every object the export renders, one Job per key."""
    from . import rendered_meshes
    jobs = {}
    for obj, is_instance, mats in rendered_meshes(depsgraph):
        for m in mats:
            if m is None:
                continue
            for s in resolver.status(m, obj, is_instance):
                if s.state == "missing" and s.key not in jobs:
                    jobs[s.key] = s.job
    return list(jobs.values())


def child_command(blend_copy: str, spec_path: str) -> list:
    """How the child is started: real Blender, or this Python with the ``bpy`` module."""
    import bpy
    binary = getattr(bpy.app, "binary_path", "") or ""
    if binary and os.path.isfile(binary) and os.access(binary, os.X_OK) and \
            os.path.realpath(binary) != os.path.realpath(sys.executable):
        return [binary, "-b", "--factory-startup", blend_copy, "--python-exit-code", "3", "--python", CHILD_SCRIPT,
                "--", spec_path]
    return [sys.executable, CHILD_SCRIPT, spec_path]


def run_jobs(jobs: list, scene, view_layer=None, *, samples: int = BAKE_SAMPLES, dirs=None, log=None) -> dict:
    """Bake ``jobs`` in one child process on a copy of the open file.

    Returns {"baked": [keys], "failed": {key: error}, "seconds": wall time, "child": bool}.
    ``log(text)``: progress lines (default: stderr).
    """
    import bpy
    log = log or (lambda text: print(f"STPM bake: {text}", file=sys.stderr, flush=True))
    if not jobs:
        return {"baked": [], "failed": {}, "seconds": 0.0, "child": False}
    t0 = time.perf_counter()
    dirs = dirs or cache_dirs(bpy.data.filepath or None)
    try:
        out_dir = writable_dir(dirs)
    except OSError as e:
        return {"baked": [], "failed": {j.key: str(e) for j in jobs}, "seconds": 0.0, "child": False}
    for j in jobs:
        j.path = os.path.join(out_dir, j.key + ".exr")
    tmp = tempfile.mkdtemp(prefix="stpm_bake_")
    try:
        copy = os.path.join(tmp, "bake_copy.blend")
        bpy.ops.wm.save_as_mainfile(filepath=copy, copy=True)
        view_layer = view_layer or bpy.context.view_layer
        spec = {"blend": copy, "scene": scene.name, "view_layer": view_layer.name,
                "frame": float(scene.frame_current) + float(scene.frame_subframe), "samples": int(samples),
                "jobs": [j.to_json() for j in jobs], "result": os.path.join(tmp, "result.json")}
        spec_path = os.path.join(tmp, "spec.json")
        with open(spec_path, "w", encoding="utf-8") as f:
            json.dump(spec, f)
        cmd = child_command(copy, spec_path)
        log(f"baking {len(jobs)} input(s) in a child process ({os.path.basename(cmd[0])})")
        STATS["child_runs"] += 1
        env = dict(os.environ)
        env.pop("PYTHONSTARTUP", None)
        with open(os.path.join(tmp, "child.log"), "w", encoding="utf-8") as logf:
            proc = subprocess.run(cmd, stdout=logf, stderr=subprocess.STDOUT, env=env, cwd=tmp)
        try:
            with open(spec["result"], encoding="utf-8") as f:
                results = json.load(f)
        except (OSError, ValueError):
            results = []
        done = {r["key"]: r for r in results}
        baked, failed = [], {}
        for j in jobs:
            r = done.get(j.key)
            if r is not None and r.get("ok") and os.path.isfile(j.path):
                baked.append(j.key)
            else:
                why = (r or {}).get("error")
                if why is None:
                    with open(os.path.join(tmp, "child.log"), encoding="utf-8", errors="replace") as f:
                        tail = [ln for ln in f.read().splitlines() if ln.strip()][-3:]
                    why = f"the bake process stopped (exit {proc.returncode}): {' | '.join(tail)}"
                failed[j.key] = f"the Cycles bake failed ({why})"
        seconds = time.perf_counter() - t0
        STATS["jobs"] += len(baked)
        STATS["seconds"] += seconds
        STATS["last"] = {"jobs": len(jobs), "baked": len(baked), "failed": len(failed), "seconds": seconds,
                         "per_job_s": [done[k].get("seconds") for k in done]}
        log(f"{len(baked)} baked, {len(failed)} failed in {seconds:.1f} s")
        return {"baked": baked, "failed": failed, "seconds": seconds, "child": True}
    finally:
        if not os.environ.get("STPM_DEBUG"):
            shutil.rmtree(tmp, ignore_errors=True)


def bake_scene(scene=None, depsgraph=None, *, resolution: int | None = None, log=None) -> tuple:
    """Plan and run the missing bakes of ``scene`` (default: the context's) at its current frame.

    The caller sets the frame and render visibility (``addon.batch.export_current`` and the
    operator do).  Returns (BakeResolver knowing the failures, run_jobs' report).

    The scene's world is baked too when the exporter cannot read it directly
    (:func:`.world.plan_world_jobs`: one more job per view, in the same child).
    """
    import bpy
    from . import world as world_export
    scene = scene or bpy.context.scene
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    resolver = BakeResolver(depsgraph, resolution=resolution)
    jobs = plan_jobs(depsgraph, resolver)
    try:
        world_jobs = world_export.plan_world_jobs(scene.world, resolver.dirs)
    except Exception as e:  # noqa: BLE001 -- the material bakes go on; the export names the world's state
        print(f"STPM bake: the world's bake could not be planned ({type(e).__name__}: {e})", file=sys.stderr)
        world_jobs = []
    report = run_jobs(jobs + world_jobs, scene, getattr(depsgraph, "view_layer", None), samples=resolver.samples,
                      dirs=resolver.dirs, log=log)
    world_export.note_bake_results(world_jobs, report)
    return BakeResolver(depsgraph, resolution=resolver.resolution, dirs=resolver.dirs, failed=report["failed"]), report
