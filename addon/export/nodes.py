"""Blender material node trees -> :class:`stpm_core.nodes.ShaderGraph`; images -> :class:`stpm_core.textures.Texture`.

:class:`GraphBuilder` walks upstream from the Material Output's Surface input and records every
node the surface depends on as plain data (graph format: ``stpm_core/nodes/graph.py``):

* node names are the Blender names; nodes inlined from a node group are named
  ``"<group node>/<inner node>"`` (nested groups: ``"Outer/Inner/Node"``);
* inputs are keyed by socket ``identifier``: a :class:`Link` to the feeding output, or the
  socket's ``default_value`` (float, or 3 floats for colours / vectors: alpha dropped);
  unlinked SHADER inputs and unlinked inputs without a value (``hide_value``: a texture's
  Vector, a BSDF's Normal: they take an implicit value) are left out;
* ``outputs`` lists the outputs something in the graph reads, with their socket types;
* ``props`` holds exactly the node properties :mod:`stpm_core.nodes.compile` reads (:data:`PROPS`);
  node types it does not list keep their own scalar settings (:func:`own_props`).

Links are followed as Blender evaluates them: reroutes are skipped; muted links are unlinked; a
muted node passes the input of its internal link through (an output without one is unlinked);
a node group is inlined (its Group Output input feeds the group node's output, its Group Input
outputs are the group node's inputs).  A constant that reaches an input through a group boundary
or a muted node is converted to the input's type as Blender converts it (colour -> float: Rec.709
luminance, vector -> float: the average, float -> colour / vector: the value in each channel).

:class:`TextureTable` turns each distinct ``bpy.types.Image`` into one Texture, read through
``Image.pixels`` (files on disk, packed and generated images alike) and stored natively; baked
inputs (:mod:`.bake`) are float EXR files it reads with OpenImageIO (``index_of_file``).  A UDIM
image (source ``TILED``) becomes one Texture per tile (``index_of_tiles``): ``Image.pixels`` holds
only the first tile, so each tile's file (the image's path with ``<UDIM>`` / ``<UVTILE>`` filled in,
or its packed file) is read with OpenImageIO in its stored type, as Cycles reads image files.

Colour spaces: byte images keep their colour space's name (``stpm_core.colorspaces``: sRGB,
Display P3, the linear spaces, data); the renderer converts them into the scene's working space
per texel.  Float images are already in the working space (Blender converts them when it loads
them): "Linear".  An image in a space STPM has no formula for (Rec.1886, Filmic Log, AgX Log,
ACEScc, ...) is converted into the working space with OpenColorIO and Blender's own config
(OpenImageIO's ``colorconvert``) and stored as float32, or, without OpenColorIO, read as linear
(warned).
"""
from __future__ import annotations

import numpy as np

from .._core import sub

_colorspaces = sub("colorspaces")
_graph = sub("nodes.graph")
_compile = sub("nodes.compile")
_textures = sub("textures")
Link, Node, ShaderGraph = _graph.Link, _graph.Node, _graph.ShaderGraph

__all__ = ["GraphBuilder", "TextureTable", "image_texture", "float_texture", "read_float_image", "graph_needed",
           "CONSTANT_NODES", "curve_table", "tile_textures", "working_space", "tile_path"]

# Value nodes the constant path (materials.py) reads directly
CONSTANT_NODES = ("ShaderNodeValue", "ShaderNodeRGB")
_LUMA = (0.2126, 0.7152, 0.0722)          # Blender's colour -> float conversion (Rec.709 luminance)
_MAX_DEPTH = 256                          # reroute / group / mute hops while resolving one link
CURVE_SAMPLES = _compile.CURVE_TABLE      # RGB Curves: samples per channel on [0, 1]


# ----------------------------------------------------------------------------
# Socket values
# ----------------------------------------------------------------------------
def _kind(stype: str) -> str:
    return "vec" if stype in ("RGBA", "VECTOR", "ROTATION") else "float"


def plain_value(value):
    """A socket value as plain data: float, or a 3-tuple of floats (alpha / 4th channel dropped,
    a 2D vector padded with 0); None for values that are neither (strings, matrices, objects)."""
    if isinstance(value, (bool, int, float)):
        return float(value)
    try:
        seq = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        return None
    if len(seq) >= 3:
        return seq[:3]
    if len(seq) == 2:
        return (seq[0], seq[1], 0.0)
    if len(seq) == 1:
        return seq[0]
    return None


def convert_value(value, from_type: str, to_type: str):
    """Convert a plain value between socket types as Blender does (see the module docstring)."""
    if value is None:
        return None
    src, dst = _kind(from_type), _kind(to_type)
    if src == "vec" and isinstance(value, tuple):
        if dst == "vec":
            return value
        if from_type == "RGBA":
            return float(sum(w * c for w, c in zip(_LUMA, value)))
        return float(sum(value) / 3.0)
    v = float(value if not isinstance(value, tuple) else value[0])
    return (v, v, v) if dst == "vec" else v


def _socket_default(sock):
    return plain_value(getattr(sock, "default_value", None)) if hasattr(sock, "default_value") else None


def _live_links(sock) -> list:
    """The links into an input socket that Blender evaluates (valid, not muted, not from or to an
    unavailable socket)."""
    if not sock.is_linked:
        return []
    return [l for l in sock.links if l.is_valid and not getattr(l, "is_muted", False)
            and not getattr(l, "is_hidden", False)]


def _by_identifier(sockets, identifier: str):
    for s in sockets:
        if s.identifier == identifier:
            return s
    return None


def _is_shader_node(node) -> bool:
    """A BSDF / Emission / Mix Shader ...: a node with a SHADER output (plain-data Node)."""
    return any(t == "SHADER" for t in node.outputs.values())


# ----------------------------------------------------------------------------
# Node properties: exactly what stpm_core.nodes.compile reads
# ----------------------------------------------------------------------------
def curve_table(node, samples: int = CURVE_SAMPLES) -> list:
    """An RGB Curves node's curves sampled on x in linspace(0, 1, samples): a (3, samples) list,
    row k = channel k (R, G, B) of the combined curve C applied first (Blender's order)."""
    mapping = node.mapping
    mapping.initialize()
    curves = mapping.curves            # R, G, B, C
    xs = np.linspace(0.0, 1.0, samples)
    combined = [mapping.evaluate(curves[3], float(x)) for x in xs]
    return [[float(mapping.evaluate(curves[k], c)) for c in combined] for k in range(3)]


def _ramp_props(node) -> dict:
    ramp = node.color_ramp
    return {"elements": [(float(e.position), tuple(float(c) for c in e.color)) for e in ramp.elements],
            "interpolation": str(ramp.interpolation), "color_mode": str(ramp.color_mode)}


def _attrs(*names):
    """A reader of enum (str) and flag (bool) node properties by name."""
    def read(node):
        return {n: (v if isinstance(v, bool) else str(v)) for n in names for v in (getattr(node, n),)}
    return read


def own_props(node) -> dict:
    """A node's own scalar settings (enums, flags, numbers, strings: not the base Node's, not
    pointers or arrays), for node types :data:`PROPS` does not list: what a future interpreter
    version may read, kept as plain JSON values."""
    import bpy
    base = _BASE_PROPS.get("ids")
    if base is None:
        base = _BASE_PROPS["ids"] = frozenset(p.identifier for p in bpy.types.ShaderNode.bl_rna.properties)
    out = {}
    for p in node.bl_rna.properties:
        ident = p.identifier
        if ident in base or p.is_readonly or getattr(p, "array_length", 0):
            continue
        if p.type == "ENUM" and not p.is_enum_flag or p.type == "STRING":
            out[ident] = str(getattr(node, ident))
        elif p.type == "BOOLEAN":
            out[ident] = bool(getattr(node, ident))
        elif p.type in ("INT", "FLOAT"):
            v = getattr(node, ident)
            if np.isfinite(v):
                out[ident] = int(v) if p.type == "INT" else float(v)
    return out


_BASE_PROPS: dict = {}

PROPS = {
    "ShaderNodeMath": _attrs("operation", "use_clamp"),
    "ShaderNodeVectorMath": _attrs("operation"),
    "ShaderNodeMix": _attrs("data_type", "blend_type", "clamp_factor", "clamp_result", "factor_mode"),
    "ShaderNodeMixRGB": _attrs("blend_type", "use_clamp"),
    "ShaderNodeMapping": _attrs("vector_type"),
    "ShaderNodeTexImage": _attrs("interpolation", "extension", "projection"),   # + image (index)
    "ShaderNodeTexGradient": _attrs("gradient_type"),
    "ShaderNodeClamp": _attrs("clamp_type"),
    "ShaderNodeMapRange": _attrs("data_type", "interpolation_type", "clamp"),
    "ShaderNodeValToRGB": _ramp_props,
    "ShaderNodeRGBCurve": lambda node: {"table": curve_table(node)},
    "ShaderNodeSeparateColor": _attrs("mode"),
    "ShaderNodeCombineColor": _attrs("mode"),
    "ShaderNodeUVMap": lambda node: {"uv_map": str(node.uv_map), "from_instancer": bool(node.from_instancer)},
    "ShaderNodeTexCoord": lambda node: {"object": node.object is not None},
    "ShaderNodeNormalMap": lambda node: {"space": str(node.space), "uv_map": str(node.uv_map)},
    "ShaderNodeValue": lambda node: {"value": float(node.outputs[0].default_value)},
    "ShaderNodeRGB": lambda node: {"value": tuple(float(c) for c in node.outputs[0].default_value[:3])},
}


# ----------------------------------------------------------------------------
# The graph walk
# ----------------------------------------------------------------------------
class GraphBuilder:
    """One material's surface tree -> ShaderGraph (see the module docstring).

    After :meth:`build`: ``images`` maps each Image Texture node's graph name to its
    ``bpy.types.Image`` (or None) -- the caller sets ``props["image"]`` to a texture index;
    ``grouped`` names the nodes inlined from groups; ``special`` the (node name, input id) pairs
    (node name None: the surface) whose value crossed a group boundary or a muted node;
    ``warnings`` what could not be represented.
    """

    def __init__(self):
        self.nodes: dict = {}
        self.images: dict = {}
        self.grouped: set = set()
        self.special: set = set()
        self.warnings: list = []
        self._names: dict = {}       # (context pointers, node pointer) -> graph name
        self._crossed = False        # the link being resolved crossed a group boundary / mute

    def _warn(self, msg: str) -> None:
        if msg not in self.warnings:
            self.warnings.append(msg)

    def build(self, output_node) -> ShaderGraph:
        """The graph feeding ``output_node``'s Surface input (surface None when unlinked)."""
        sock = output_node.inputs.get("Surface") if output_node is not None else None
        surface = None
        if sock is not None:
            got = self._resolve_input((), sock)
            if got is not None and got[0] == "link":
                surface = got[1]
                if self._crossed:
                    self.special.add((None, "Surface"))
        return ShaderGraph(nodes=self.nodes, surface=surface)

    # -- resolution -------------------------------------------------------------------
    def _resolve_input(self, ctx: tuple, sock, depth: int = 0):
        """What feeds input ``sock`` in group context ``ctx``: ("link", Link) to a graph node,
        ("const", value, socket type), or None (unlinked: the input's own value applies)."""
        if depth == 0:
            self._crossed = False
        links = _live_links(sock)
        if not links or depth > _MAX_DEPTH:
            return None
        link = links[0]
        return self._resolve_output(ctx, link.from_node, link.from_socket, depth + 1)

    def _resolve_output(self, ctx: tuple, node, out_sock, depth: int):
        bl = node.bl_idname
        if bl == "NodeReroute":
            return self._resolve_input(ctx, node.inputs[0], depth + 1)
        if getattr(node, "mute", False):
            self._crossed = True
            src = next((il.from_socket for il in node.internal_links
                        if il.to_socket.identifier == out_sock.identifier), None)
            if src is None:
                return None
            got = self._resolve_input(ctx, src, depth + 1)
            if got is None:
                v = _socket_default(src)
                return None if v is None else ("const", v, src.type)
            return got
        if bl == "ShaderNodeGroup":
            self._crossed = True
            tree = node.node_tree
            if tree is None:
                self._warn(f"node group {node.name!r} has no node tree: its outputs are unlinked")
                return None
            outs = [n for n in tree.nodes if n.bl_idname == "NodeGroupOutput"]
            gout = next((n for n in outs if getattr(n, "is_active_output", False)), outs[0] if outs else None)
            sock = _by_identifier(gout.inputs, out_sock.identifier) if gout is not None else None
            if sock is None:
                return None
            got = self._resolve_input(ctx + (node,), sock, depth + 1)
            if got is None:
                v = _socket_default(sock)
                return None if v is None else ("const", v, sock.type)
            return got
        if bl == "NodeGroupInput":
            self._crossed = True
            if not ctx:
                return None
            outer = ctx[-1]
            sock = _by_identifier(outer.inputs, out_sock.identifier)
            if sock is None:
                return None
            got = self._resolve_input(ctx[:-1], sock, depth + 1)
            if got is None:
                v = _socket_default(sock)
                return None if v is None else ("const", v, sock.type)
            return got
        crossed = self._crossed
        name = self._add_node(ctx, node)
        self._crossed = crossed
        self.nodes[name].outputs[out_sock.identifier] = out_sock.type
        return ("link", Link(name, out_sock.identifier))

    # -- nodes --------------------------------------------------------------------------
    def _name_for(self, ctx: tuple, node) -> tuple:
        key = (tuple(g.as_pointer() for g in ctx), node.as_pointer())
        if key in self._names:
            return self._names[key], False
        base = "/".join([g.name for g in ctx] + [node.name])
        name, k = base, 2
        while name in self.nodes:
            name, k = f"{base}#{k}", k + 1
        self._names[key] = name
        return name, True

    def _add_node(self, ctx: tuple, node) -> str:
        name, new = self._name_for(ctx, node)
        if not new:
            return name
        bl = node.bl_idname
        props = {}
        try:
            props = PROPS.get(bl, own_props)(node)
        except (AttributeError, TypeError, ValueError, IndexError) as e:   # an API change: keep going
            self._warn(f"node {name!r} ({bl}): its properties could not be read ({e})")
        if bl == "ShaderNodeTexImage":
            props["image"] = -1
            self.images[name] = node.image
        gnode = Node(type=bl, props=props)
        self.nodes[name] = gnode            # before the inputs: shared upstream nodes see it
        if ctx:
            self.grouped.add(name)
        for sock in node.inputs:
            if not getattr(sock, "enabled", True) or sock.type == "CUSTOM":
                continue
            ident = sock.identifier
            got = self._resolve_input(ctx, sock)
            if self._crossed:
                self.special.add((name, ident))
            if got is not None and got[0] == "link":
                gnode.inputs[ident] = got[1]
            elif got is not None:
                v = convert_value(got[1], got[2], sock.type)
                if v is not None:
                    gnode.inputs[ident] = v
            elif sock.type != "SHADER" and not getattr(sock, "hide_value", False):
                v = _socket_default(sock)
                if v is not None:
                    gnode.inputs[ident] = v
            if ident in gnode.inputs:
                gnode.input_types[ident] = sock.type
        return name


def reached_nodes(graph: ShaderGraph, supported=None) -> list:
    """Names of the nodes whose values the interpreter evaluates for the surface, in walk order:
    from the surface through every link, stopping at node types it does not support (their
    consumers read their own default value, as on the constant path)."""
    supported = set(_compile.SUPPORTED_NODES if supported is None else supported)
    seen, order = set(), []
    stack = [graph.surface.node] if graph.surface is not None else []
    while stack:
        name = stack.pop()
        if name in seen or name not in graph.nodes:
            continue
        seen.add(name)
        node = graph.nodes[name]
        if node.type not in supported:
            continue
        order.append(name)
        stack.extend(v.node for v in node.inputs.values() if isinstance(v, Link))
    return order


_GRAPH_ONLY_SHADERS = ("ShaderNodeBsdfTransparent", "ShaderNodeAddShader")   # no constant closure for them
# Shaders whose closure is linear in their colour inputs: a Mix Shader of Diffuse BSDFs (all with
# the same other inputs) and Emissions is exactly one Diffuse of the Fac-blended colour plus the
# Fac-blended emission (Lambertian albedo and emitted radiance Color * Strength are linear)
_LINEAR_COLOUR_SHADERS = {"ShaderNodeBsdfDiffuse": ("Color",), "ShaderNodeEmission": ("Color", "Strength")}
_EMISSION_ONLY = ("emission",)        # a signature compatible with any other


def _blend_signature(graph: ShaderGraph, link, depth: int = 0):
    """The Diffuse BSDFs' non-colour inputs (``_EMISSION_ONLY`` for Emissions alone) of a shader
    link whose Mix Shaders all blend exactly (every leaf a Diffuse BSDF or an Emission, the Diffuse
    ones with the same non-colour inputs); None otherwise (a Mix Shader there must stay two weighted
    closures)."""
    node = graph.nodes.get(link.node) if isinstance(link, Link) else None
    if node is None or depth > 32:
        return None
    if node.type == "ShaderNodeMixShader":
        a = _blend_signature(graph, node.inputs.get("Shader"), depth + 1)
        b = _blend_signature(graph, node.inputs.get("Shader_001"), depth + 1)
        if a is None or b is None:
            return None
        if a == _EMISSION_ONLY or a == b:
            return b
        return a if b == _EMISSION_ONLY else None
    if node.type == "ShaderNodeEmission":
        return _EMISSION_ONLY
    colours = _LINEAR_COLOUR_SHADERS.get(node.type)
    if colours is None:
        return None
    return tuple(sorted((k, repr(v)) for k, v in node.inputs.items() if k not in colours))


def mix_is_exact_blend(graph: ShaderGraph, name: str) -> bool:
    """Is Mix Shader ``name`` exactly the parameter blend the constant path makes of it?"""
    return _blend_signature(graph, Link(name, "Shader")) is not None


def graph_needed(graph: ShaderGraph, builder: GraphBuilder) -> bool:
    """Does the surface read something the constant path cannot represent?

    True when a value node the interpreter evaluates, other than Value / RGB, feeds the surface
    (a texture, a Math node, a Normal Map, ...), or the surface's nodes or values pass through
    a node group or a muted node, or the tree has a Transparent BSDF, an Add Shader or a
    Principled BSDF with Alpha < 1 (chosen per hit) or a Coat Weight (the coat layer: only the
    interpreter fills its closure columns), or a Mix Shader that is not exactly a
    blend of its inputs' colours (:func:`mix_is_exact_blend`: Cycles evaluates it as two weighted
    closures, whatever its Fac; blending e.g. a Diffuse and a mirror's roughness and metallic
    would turn a sharp glint into a broad highlight).  Plain shader trees (Principled, Diffuse,
    Glossy, Glass, Emission, a Mix Shader of Diffuse BSDFs differing only in colour and Emissions,
    with constant or Value / RGB inputs) keep the constant path, and so do
    trees whose only links come from nodes the interpreter does not support either (a Noise
    texture, a Bump node: both paths use the input's own value; the constant path warns).
    """
    if graph.surface is None:
        return False
    if (None, "Surface") in builder.special:
        return True
    for name in reached_nodes(graph):
        node = graph.nodes[name]
        if name in builder.grouped:
            return True
        if node.type in _GRAPH_ONLY_SHADERS:
            return True
        if node.type == "ShaderNodeMixShader" and not mix_is_exact_blend(graph, name):
            return True            # two weighted closures, as Cycles: one chosen per hit by Fac
        alpha = node.inputs.get("Alpha", 1.0) if node.type == "ShaderNodeBsdfPrincipled" else 1.0
        if isinstance(alpha, Link) or (isinstance(alpha, (int, float)) and alpha < 1.0):
            return True            # transparency: the closure is chosen per hit
        coat = node.inputs.get("Coat Weight", 0.0) if node.type == "ShaderNodeBsdfPrincipled" else 0.0
        if isinstance(coat, Link) or (isinstance(coat, (int, float)) and coat > 0.0):
            return True            # the coat layer: rendered by the interpreter (kernels.svm, C_CC_*)
        if not _is_shader_node(node) and node.type not in CONSTANT_NODES:
            return True
        if any((name, ident) in builder.special for ident in node.inputs):
            return True
    return False


# ----------------------------------------------------------------------------
# Images
# ----------------------------------------------------------------------------
def _fewest_channels(px: np.ndarray) -> np.ndarray:
    """(H, W, C) -> the same texels with the fewest of 1 / 3 / 4 channels that lose nothing:
    alpha dropped when it is 1 everywhere, RGB -> grey when R == G == B everywhere."""
    C = px.shape[2]
    one = {np.dtype(np.uint8): 255, np.dtype(np.uint16): 65535}.get(px.dtype, 1)
    if C == 4 and not np.all(px[:, :, 3] == px.dtype.type(one)):
        return px
    if C >= 3:
        if np.array_equal(px[:, :, 0], px[:, :, 1]) and np.array_equal(px[:, :, 0], px[:, :, 2]):
            return np.ascontiguousarray(px[:, :, :1])
        return np.ascontiguousarray(px[:, :, :3])
    return px


_ROWS = 256          # rows per chunk of the float-image checks (bounds their temporaries)


def _rows_all(px: np.ndarray, test) -> bool:
    """test(chunk) -> bool holds for every chunk of rows of px (H, W, C)."""
    return all(bool(test(px[y:y + _ROWS])) for y in range(0, px.shape[0], _ROWS))


def _is_u16(chunk: np.ndarray) -> bool:
    """Every value is k / 65535 within float32 rounding (|v 65535 - k| < 0.01: 1.5e-7 absolute)."""
    k = chunk * np.float32(65535.0)
    return bool(k.min(initial=0.0) >= 0.0 and k.max(initial=0.0) <= 65535.0
                and np.abs(k - np.rint(k)).max(initial=0.0) < 0.01)


def _is_half(chunk: np.ndarray) -> bool:
    return bool(np.array_equal(chunk.astype(np.float16).astype(np.float32), chunk))


def _texture(data: np.ndarray, colorspace: str, name: str, alpha_mode: str) -> "_textures.Texture":
    """A Texture of (H, W, 4) data with the fewest channels; alpha is dropped where it is unused
    (Blender's alpha mode None: it reads 1)."""
    if alpha_mode == "NONE" and data.shape[2] == 4:
        data = data[:, :, :3]
    return _textures.Texture(pixels=_fewest_channels(data), colorspace=colorspace, name=name,
                             alpha_mode=alpha_mode)


def working_space() -> str:
    """The open file's working space as a ``stpm_core.colorspaces.WORKING_SPACES`` id (Blender 4:
    always Linear Rec.709; a space STPM does not know: REC709, the exporter warns)."""
    import bpy
    cs = getattr(bpy.data, "colorspace", None)
    return _colorspaces.working_id(str(getattr(cs, "working_space", "Linear Rec.709"))) or "REC709"


def _ocio_config() -> str | None:
    """Path of the OpenColorIO config Blender uses ($OCIO, else its bundled one), or None."""
    import os
    env = os.environ.get("OCIO")
    if env and os.path.isfile(env):
        return env
    try:
        import bpy
        for kind in ("LOCAL", "SYSTEM"):
            path = os.path.join(bpy.utils.resource_path(kind), "datafiles", "colormanagement", "config.ocio")
            if os.path.isfile(path):
                return path
    except Exception:  # noqa: BLE001 -- no Blender paths: no config
        pass
    return None


def _ocio_to_working(px: np.ndarray, space: str) -> np.ndarray | None:
    """Float32 texels (H, W, C) in colour space ``space`` -> the working space by OpenColorIO with
    Blender's config (straight alpha kept), or None when OpenImageIO / OpenColorIO / the config is
    missing or the conversion fails."""
    config = _ocio_config()
    if config is None:
        return None
    try:
        import OpenImageIO as oiio
        H, W, C = px.shape
        rgb = np.ascontiguousarray(px[:, :, :3] if C >= 3 else np.repeat(px[:, :, :1], 3, axis=2), np.float32)
        buf = oiio.ImageBuf(oiio.ImageSpec(W, H, 3, "float"))
        buf.set_pixels(oiio.ROI(), rgb)
        dst = _colorspaces.WORKING_SPACES[working_space()]
        out = oiio.ImageBufAlgo.colorconvert(buf, space, dst, unpremult=False, colorconfig=config)
        if out.has_error:
            return None
        conv = np.asarray(out.get_pixels(oiio.FLOAT), np.float32).reshape(H, W, 3)
    except Exception:  # noqa: BLE001 -- any failure: the caller reads the values as linear
        return None
    return np.concatenate([conv, px[:, :, 3:4].astype(np.float32)], axis=2) if C == 4 else conv


def _space_texture(px: np.ndarray, space: str, name: str, warn, alpha_mode: str) -> "_textures.Texture":
    """Texels (H, W, C) of an image whose stored values are in colour space ``space``: a Texture
    with that space when the renderer knows it, else converted with OpenColorIO (float32 "Linear"),
    else read as linear (warned)."""
    if space in _textures.COLOR_SPACES:
        return _texture(px, space, name, alpha_mode)
    conv = _ocio_to_working(px.astype(np.float32) / (255.0 if px.dtype == np.uint8 else
                                                    65535.0 if px.dtype == np.uint16 else 1.0), space)
    if conv is not None:
        return _texture(conv, "Linear", name, alpha_mode)
    warn(f"image {name!r}: colour space {space!r} could not be converted (no OpenColorIO), its values are used "
         f"as linear (set it to sRGB, a Linear space or Non-Color)")
    return _texture(px, "Linear", name, alpha_mode)


def image_texture(image, warn) -> "_textures.Texture | None":
    """One ``bpy.types.Image`` -> Texture, or None when it has no pixels (missing file).

    ``Image.pixels`` is read once into float32 (W H C values, rows bottom-up: row 0 is v = 0).
    Byte images (``not is_float``) hold their file's values in the image's own colour space:
    stored as uint8 (round(v * 255), exact) with ``colorspace`` the image's colour space (the
    renderer converts it into the working space; a space without a formula: converted here,
    :func:`_space_texture`).  Float images are already in the working space in Blender (it
    converts them on load; their colour-space name no longer applies): ``colorspace`` "Linear",
    stored as uint16 when every value is k / 65535 (a 16-bit file read as data), float16 when
    every value is a half (a half-float EXR), else float32.
    NaN / inf texels are set to 0 (warned).  Channels: the fewest of 1 / 3 / 4 that keep every
    value (Blender always hands out 4: alpha is dropped when it is 1 everywhere or the alpha
    mode is None, RGB becomes grey when R = G = B everywhere).  ``alpha_mode`` is the image's
    (Straight, Premultiplied, Channel Packed, None: how the texture's alpha is read).
    """
    w, h = (int(x) for x in image.size[:])
    c = int(image.channels)
    if w * h == 0 or c not in (1, 2, 3, 4):
        return None
    px = np.empty(w * h * c, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, c)
    name = image.name
    alpha_mode = str(getattr(image, "alpha_mode", "STRAIGHT"))
    if not image.is_float:
        np.multiply(px, np.float32(255.0), out=px)
        np.clip(px, 0.0, 255.0, out=px)
        np.rint(px, out=px)
        return _space_texture(px.astype(np.uint8), image.colorspace_settings.name, name, warn, alpha_mode)
    return float_texture(px, name, warn, alpha_mode)


def float_texture(px: np.ndarray, name: str, warn, alpha_mode: str = "STRAIGHT") -> "_textures.Texture":
    """Scene-linear float32 texels (H, W, C), row 0 at the bottom -> a "Linear" Texture stored as
    uint16 when every value is k / 65535, float16 when every value is a half, else float32, with
    the fewest channels that keep every value; NaN / inf texels become 0 (warned).  ``px`` may be
    modified in place."""
    if not _rows_all(px, lambda ch: np.isfinite(ch).all()):
        warn(f"image {name!r}: NaN or infinite pixels are rendered as 0")
        np.nan_to_num(px, copy=False, nan=0.0, posinf=0.0, neginf=0.0)
    if _rows_all(px, _is_u16):
        np.multiply(px, np.float32(65535.0), out=px)
        np.rint(px, out=px)
        data = px.astype(np.uint16)
    elif _rows_all(px, _is_half):
        data = px.astype(np.float16)
    else:
        data = px
    return _texture(data, "Linear", name, alpha_mode)


def read_float_image(path) -> np.ndarray:
    """A float image file (a baked EXR) -> (H, W, C) float32 texels, row 0 at the bottom (as
    ``Image.pixels``), through OpenImageIO."""
    import OpenImageIO as oiio
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        px = inp.read_image(0, 0, 0, spec.nchannels, "float")
    finally:
        inp.close()
    if px is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    px = np.asarray(px, np.float32).reshape(spec.height, spec.width, spec.nchannels)
    return np.ascontiguousarray(px[::-1])


# ----------------------------------------------------------------------------
# UDIM tiles
# ----------------------------------------------------------------------------
_NATIVE = {"uint8": np.uint8, "uint16": np.uint16, "half": np.float16, "float": np.float32}


def tile_path(image, number: int) -> str:
    """The file of UDIM tile ``number`` of ``image``: its path with ``<UDIM>`` (1001) or
    ``<UVTILE>`` (u1_v1) filled in, made absolute."""
    import bpy
    path = bpy.path.abspath(image.filepath_raw or image.filepath, library=image.library)
    u, v = (number - 1001) % 10, (number - 1001) // 10
    return path.replace("<UDIM>", str(number)).replace("<UVTILE>", f"u{u + 1}_v{v + 1}")


def read_native(path) -> np.ndarray:
    """An image file -> (H, W, C) texels in its stored type (uint8, uint16, float16, else float32),
    row 0 at the bottom, colour not associated with alpha (as Blender keeps byte images), at most 4
    channels; through OpenImageIO."""
    import OpenImageIO as oiio
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    if inp is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        fmt = str(spec.format)
        dtype = fmt if fmt in _NATIVE else "float"
        px = inp.read_image(0, 0, 0, spec.nchannels, dtype)
    finally:
        inp.close()
    if px is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    px = np.asarray(px, _NATIVE[dtype]).reshape(spec.height, spec.width, spec.nchannels)
    if px.shape[2] > 4:
        px = px[:, :, :4]
    return np.ascontiguousarray(px[::-1])


def _tile_pixels(image, number: int, warn):
    """(H, W, C) native texels of tile ``number`` (its packed file, else its file on disk), or None."""
    import os
    import tempfile
    packed = next((p for p in getattr(image, "packed_files", ()) if getattr(p, "tile_number", 0) == number), None)
    if packed is not None and packed.packed_file is not None:
        suffix = os.path.splitext(packed.filepath or image.filepath_raw or "")[1] or ".png"
        fd, tmp = tempfile.mkstemp(suffix=suffix)
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(bytes(packed.packed_file.data))
            return read_native(tmp)
        except (OSError, ValueError) as e:
            warn(f"image {image.name!r}: packed UDIM tile {number} could not be read ({e}); rendered magenta "
                 f"(1, 0, 1) as a missing tile in Cycles")
            return None
        finally:
            os.unlink(tmp)
    path = tile_path(image, number)
    if not os.path.isfile(path):
        warn(f"image {image.name!r}: UDIM tile {number} has no file ({path!r}: generated or never saved?); "
             f"rendered magenta (1, 0, 1) as a missing tile in Cycles (save the image to render it)")
        return None
    try:
        return read_native(path)
    except (OSError, ValueError) as e:
        warn(f"image {image.name!r}: UDIM tile {number} ({path!r}) could not be read ({e}); rendered magenta "
             f"(1, 0, 1) as a missing tile in Cycles")
        return None


def tile_textures(image, warn) -> list:
    """[(tile number, Texture or None)] of a UDIM image, every tile in its stored type and the
    image's colour space and alpha mode (8-bit and 16-bit tiles keep their integers; half and float
    tiles are linear in the image's colour space, converted by the renderer as Blender converts
    float images on load).  A tile without pixels is None (warned: it reads magenta)."""
    if getattr(image, "is_dirty", False):
        warn(f"image {image.name!r}: unsaved edits of its UDIM tiles are not rendered (STPM reads the tile "
             f"files); save the image")
    space = image.colorspace_settings.name
    alpha_mode = str(getattr(image, "alpha_mode", "STRAIGHT"))
    out = []
    for tile in image.tiles:
        number = int(tile.number)
        px = _tile_pixels(image, number, warn)
        tex = None
        if px is not None:
            name = f"{image.name}.{number}"
            if px.dtype == np.float32 or px.dtype == np.float16:
                if not np.isfinite(px).all():
                    warn(f"image {name!r}: NaN or infinite pixels are rendered as 0")
                    px = np.nan_to_num(px, nan=0.0, posinf=0.0, neginf=0.0)
            if alpha_mode == "NONE" and px.shape[2] == 4:
                px = np.ascontiguousarray(px[:, :, :3])
            tex = _space_texture(_fewest_channels(px) if px.shape[2] in (3, 4) else px, space, name, warn,
                                 alpha_mode)
        out.append((number, tex))
    return out


class TextureTable:
    """The textures of one export: each distinct image once (``textures[i]`` = texture id i)."""

    def __init__(self):
        self.textures: list = []
        self._index: dict = {}
        self._tiles: dict = {}

    def index_of(self, image, warn) -> int:
        """Texture index of ``image`` (read on first use); -1 when it has no pixels."""
        return self._cached(image.as_pointer(), lambda: image_texture(image, warn))

    def index_of_tiles(self, image, warn) -> list:
        """[[tile number, texture index]] of a UDIM image's tiles with pixels (read on first use)."""
        key = ("tiles", image.as_pointer())
        if key not in self._tiles:
            pairs = []
            for number, tex in tile_textures(image, warn):
                if tex is not None:
                    pairs.append([number, len(self.textures)])
                    self.textures.append(tex)
            self._tiles[key] = pairs
        return [list(p) for p in self._tiles[key]]

    def _cached(self, key, make) -> int:
        """Index of the texture cached under ``key``, made by ``make()`` on first use (None: -1)."""
        if key not in self._index:
            tex = make()
            if tex is None:
                self._index[key] = -1
            else:
                self._index[key] = len(self.textures)
                self.textures.append(tex)
        return self._index[key]

    def index_of_file(self, path, name: str, warn) -> int:
        """Texture index of the float image file ``path`` (a baked EXR, read on first use with
        OpenImageIO: no ``bpy.data.images`` entry is made); -1 when it cannot be read (warned)."""
        def make():
            try:
                px = read_float_image(path)
                c = px.shape[2]
                if c == 2 or c > 4:
                    px = np.ascontiguousarray(px[:, :, :1] if c == 2 else px[:, :, :4])
                return float_texture(px, name, warn, "NONE" if px.shape[2] == 4 else "STRAIGHT")
            except (OSError, ValueError, ImportError) as e:
                warn(f"baked image {str(path)!r} could not be read ({e})")
                return None
        return self._cached(("file", str(path)), make)
