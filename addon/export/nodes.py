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
inputs (:mod:`.bake`) are float EXR files it reads with OpenImageIO (``index_of_file``).
"""
from __future__ import annotations

import numpy as np

from .._core import sub

_graph = sub("nodes.graph")
_compile = sub("nodes.compile")
_textures = sub("textures")
Link, Node, ShaderGraph = _graph.Link, _graph.Node, _graph.ShaderGraph

__all__ = ["GraphBuilder", "TextureTable", "image_texture", "float_texture", "read_float_image", "graph_needed",
           "CONSTANT_NODES", "curve_table"]

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


def graph_needed(graph: ShaderGraph, builder: GraphBuilder) -> bool:
    """Does the surface read something the constant path cannot represent?

    True when a value node the interpreter evaluates, other than Value / RGB, feeds the surface
    (a texture, a Math node, a Normal Map, ...), or the surface's nodes or values pass through
    a node group or a muted node, or the tree has a Transparent BSDF, an Add Shader or a
    Principled BSDF with Alpha < 1 (chosen per hit).  Plain shader trees (Principled, Diffuse, Glossy, Glass,
    Emission, Mix Shader with constant or Value / RGB inputs) keep the constant path, and so do
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
        alpha = node.inputs.get("Alpha", 1.0) if node.type == "ShaderNodeBsdfPrincipled" else 1.0
        if isinstance(alpha, Link) or (isinstance(alpha, (int, float)) and alpha < 1.0):
            return True            # transparency: the closure is chosen per hit
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


def image_texture(image, warn) -> "_textures.Texture | None":
    """One ``bpy.types.Image`` -> Texture, or None when it has no pixels (missing file).

    ``Image.pixels`` is read once into float32 (W H C values, rows bottom-up: row 0 is v = 0).
    Byte images (``not is_float``) hold their file's values in the image's own colour space:
    stored as uint8 (round(v * 255), exact) with ``colorspace`` "sRGB" or "Linear" from the
    image's colour space (another space: "Linear", warned).  Float images are already
    scene-linear in Blender (it converts them on load; their colour-space name no longer
    applies): ``colorspace`` "Linear", stored as uint16 when every value is k / 65535 (a 16-bit
    file read as data), float16 when every value is a half (a half-float EXR), else float32.
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
        space = image.colorspace_settings.name
        if space in _textures.SRGB_SPACES:
            cs = "sRGB"
        else:
            cs = "Linear"
            if space not in _textures.LINEAR_SPACES:
                warn(f"image {name!r}: colour space {space!r} is not supported, its values are used as "
                     f"linear (set it to sRGB, Linear Rec.709 or Non-Color)")
        np.multiply(px, np.float32(255.0), out=px)
        np.clip(px, 0.0, 255.0, out=px)
        np.rint(px, out=px)
        return _texture(px.astype(np.uint8), cs, name, alpha_mode)
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


class TextureTable:
    """The textures of one export: each distinct image once (``textures[i]`` = texture id i)."""

    def __init__(self):
        self.textures: list = []
        self._index: dict = {}

    def index_of(self, image, warn) -> int:
        """Texture index of ``image`` (read on first use); -1 when it has no pixels."""
        return self._cached(image.as_pointer(), lambda: image_texture(image, warn))

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
