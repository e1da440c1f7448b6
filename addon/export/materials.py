"""Blender node materials -> :class:`stpm_core.scene.Material`.

Walks from the active Material Output's Surface link.  Understood nodes:

=================  ==============================================================
Principled BSDF    Base Color, Metallic, Roughness, Transmission Weight, IOR,
                   Specular IOR Level (0.5 = Blender's default -> specular 1),
                   Emission Color * Emission Strength; refraction tinted by
                   sqrt(Base Color) as Cycles (``Material.transmission_tint``); a Coat
                   (Weight, Roughness, IOR, Tint) makes the material carry its node graph
                   (``nodes.graph_needed``), whose interpreter renders the coat layer
Diffuse BSDF       Color (Lambertian, no coat)
Glossy BSDF        Color, Roughness (metallic 1; ``constant_fresnel``: Cycles 5.0 gives it no
                   Fresnel, it reflects its colour at every angle)
Glass BSDF         Color (also its refraction and reflection tints, as Cycles:
                   ``Material.reflection_tint``), Roughness, IOR (transmission 1)
Emission           Color * Strength (radiance, W m^-2 sr^-1, as in Cycles)
Mix Shader         Diffuse BSDFs differing only in colour, and Emissions: colours
                   and emission blended by Fac (exact); any other mix:
                   the representative constants blend every parameter and the
                   material carries its graph, which renders the two closures
                   weighted by Fac as Cycles (one chosen per hit)
Image Texture      on a colour input: the image's mean linear colour
=================  ==============================================================

Anything else becomes the grey diffuse default and a warning; nothing raises.

These constants are every material's *representative* parameters (what the effects plan and
the photon budgets read).  When the surface reads something they cannot represent (a texture,
a Math node, a node group, ...), the material also carries its node graph
(:mod:`.nodes`, ``Material.graph``), which the renderer evaluates per hit; its images become
the scene's textures (:attr:`MaterialExporter.textures`).  For such materials the constant
path's warnings about what the graph renders (mean colours, linked inputs, Mix Shader
blending, bump / normal inputs, unsupported shaders) are dropped and the node compiler's own
messages name what the graph cannot render (a Noise texture, Coat, a Box projection, ...).

Inputs the interpreter cannot evaluate are baked (:mod:`.bake`): with a ``BakeResolver``,
:meth:`MaterialExporter.index_of` looks them up per object, a material with cached bakes is
exported once per distinct set of bake keys with those inputs read from the baked textures, and
every such input gets one message (baked, needs a bake, or why it cannot be baked) in place of
the constant path's and the compiler's messages about its nodes.
"""
from __future__ import annotations

import os

import numpy as np

from .._core import scene_model, sub
from . import nodes as node_export

_colorspaces = sub("colorspaces")

# Cycles' colour for an image that cannot be loaded
MISSING_IMAGE = np.array([1.0, 0.0, 1.0])
# Image means: at most this many pixels are read for one mean (a regular strided grid)
MAX_MEAN_PIXELS = 256 * 1024
# Means of images already seen in this Blender session: key (see _image_key) -> (3,) float64
_IMAGE_MEANS: dict = {}
_IMAGE_MEANS_MAX = 512

FIELDS = ("base_color", "metallic", "transmission", "roughness", "specular", "ior", "emission")

# Anisotropic GGX (Principled Anisotropic, the Glossy BSDF's Anisotropy) is not in the kernels: such
# lobes render isotropic with their Roughness, and the render report says so
ANISOTROPY_IGNORED = "{what} is not rendered (the highlight is isotropic, as with 0)"


def _anisotropic(node, name: str) -> bool:
    """Is ``node``'s input ``name`` (an anisotropy amount, or another amount whose 0 is what the
    kernels render) linked or non-zero?"""
    sock = node.inputs.get(name)
    return sock is not None and (sock.is_linked or abs(float(sock.default_value)) > 0.0)


def _uses_nodes(idblock) -> bool:
    """Blender < 5 has a use_nodes switch; 5.0 always uses the node tree (and deprecates the flag)."""
    import bpy
    if bpy.app.version >= (5, 0, 0):
        return idblock.node_tree is not None
    return bool(idblock.use_nodes)


uses_nodes = _uses_nodes


def find_output(tree) -> tuple:
    """(Material Output node STPM renders or None, EEVEE-only: bool): the active one of those for
    All / Cycles, else the first such; with only EEVEE outputs, an EEVEE one (flag True)."""
    every = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial"]
    for outs in ([n for n in every if getattr(n, "target", "ALL") in ("ALL", "CYCLES")], every):
        active = [n for n in outs if getattr(n, "is_active_output", False)]
        node = (active or outs or [None])[0]
        if node is not None:
            return node, getattr(node, "target", "ALL") not in ("ALL", "CYCLES")
    return None, False


def _image_key(image) -> tuple | None:
    """What identifies an image's pixels within this process, or None (unsaved edits: no caching).

    Name, size, channels, source, file path, colour space and the generator's
    settings; an image with unsaved edits (``is_dirty``, e.g. painted or set
    by a script) is read every time.
    """
    if getattr(image, "is_dirty", False):
        return None
    gen = (image.generated_type, image.generated_width, image.generated_height, tuple(image.generated_color),
           bool(image.use_generated_float)) if image.source == "GENERATED" else ()
    return (image.name_full, getattr(image, "session_uid", 0), tuple(image.size), image.channels,
            bool(image.is_float), image.source, image.filepath_raw, image.colorspace_settings.name, gen)


def sampled_mean(image, max_pixels: int = MAX_MEAN_PIXELS) -> np.ndarray:
    """Mean linear RGB (3,) float64 of ``image`` from at most ``max_pixels`` pixels.

    The pixels are read once as float32 (Blender's ``pixels`` has no partial
    read).  The image is cut into ``s x s`` cells, ``s = ceil(sqrt(W H /
    max_pixels))``, and one pixel at a jittered position (fixed seed) is taken
    from each cell: stratified, so a smooth image is sampled evenly and a
    pattern with period ``s`` (a 1-pixel checker and stride 2) cannot alias the
    way a plain ``[::s, ::s]`` grid does.  Only those pixels are converted
    (sRGB -> linear for 8-bit sRGB images) and averaged.
    """
    w, h = image.size[:]
    c = image.channels
    px = np.empty(w * h * c, dtype=np.float32)
    image.pixels.foreach_get(px)
    step = max(1, int(np.ceil(np.sqrt(w * h / float(max_pixels)))))
    if step == 1:
        rgb = px.reshape(-1, c)[:, :3]
    else:
        rng = np.random.default_rng(0x5EED)
        ny, nx = -(-h // step), -(-w // step)
        ys = np.minimum(np.arange(ny)[:, None] * step + rng.integers(0, step, (ny, nx)), h - 1)
        xs = np.minimum(np.arange(nx)[None, :] * step + rng.integers(0, step, (ny, nx)), w - 1)
        rgb = px.reshape(-1, c)[(ys * w + xs).reshape(-1), :3]
    del px
    return linear_rgb(rgb, image).mean(axis=0, dtype=np.float64)


def linear_rgb(rgb: np.ndarray, image) -> np.ndarray:
    """Pixel values (..., 3) float32 of ``image`` (``Image.pixels``) in the working space: byte
    images are converted from their colour space (sRGB decoded, primaries changed); float images
    already are (Blender converts them on load); a byte image in a space without a formula is
    read as linear."""
    if image.is_float:
        return rgb
    space = image.colorspace_settings.name
    if space not in _colorspaces.SPACES:
        return rgb
    return _colorspaces.to_working(rgb, space, node_export.working_space()).astype(np.float32)


def image_mean(image) -> np.ndarray:
    """:func:`sampled_mean` of ``image``, cached per image (:func:`_image_key`) for the process."""
    key = _image_key(image)
    if key is not None and key in _IMAGE_MEANS:
        return _IMAGE_MEANS[key].copy()
    mean = sampled_mean(image)
    if key is not None:
        if len(_IMAGE_MEANS) >= _IMAGE_MEANS_MAX:
            _IMAGE_MEANS.pop(next(iter(_IMAGE_MEANS)))
        _IMAGE_MEANS[key] = mean
    return mean.copy()


def sub_bake():
    """:mod:`.bake` (imported on first use)."""
    from . import bake
    return bake


def bake_hint() -> str:
    return sub_bake().OPERATOR_HINT


def default_material(name: str = "STPM default") -> "scene_model.Material":
    """What Cycles (Blender 5.0) renders on an object without a material: a Principled BSDF at its
    defaults (base colour 0.8, roughness 0.5, IOR 1.5, Specular IOR Level 0.5), bit for bit the
    same image as a default Principled material there.  It was a Lambertian grey: 11 % brighter
    than Cycles on a floor lit at 50-70 degrees, whose Principled base loses the specular layer's
    Fresnel (artist review 4)."""
    return scene_model.Material(base_color=np.full(3, 0.8), metallic=0.0, transmission=0.0, roughness=0.5,
                                specular=1.0, ior=1.5, emission=np.zeros(3), name=name)


def _params(**kw) -> dict:
    """A full parameter dict (base_color (3,), emission (3,) float64, scalars float)."""
    p = {"base_color": np.full(3, 0.8), "metallic": 0.0, "transmission": 0.0, "roughness": 0.5,
         "specular": 0.0, "ior": 1.5, "emission": np.zeros(3), "transmission_tint": None,
         "reflection_tint": None, "constant_fresnel": False}
    p.update(kw)
    return p


def _transparent_graph():
    """A graph of one white Transparent BSDF: what Cycles renders where a surface has no closure."""
    g = sub("nodes.graph")
    node = g.Node(type="ShaderNodeBsdfTransparent", inputs={"Color": (1.0, 1.0, 1.0)},
                  outputs={"BSDF": "SHADER"}, input_types={"Color": "RGBA"})
    return g.ShaderGraph(nodes={"Transparent BSDF": node}, surface=g.Link("Transparent BSDF", "BSDF"))


def _tint(p: dict) -> np.ndarray:
    """The transmission tint (3,) of parameters p: theirs, else the base colour (a Glass BSDF's)."""
    t = p.get("transmission_tint")
    return np.clip(np.asarray(p["base_color"] if t is None else t, dtype=np.float64), 0.0, 1.0)


def _tint_r(p: dict) -> np.ndarray:
    """The reflection tint (3,) of parameters p: theirs, else white (a Principled BSDF's)."""
    t = p.get("reflection_tint")
    return np.clip(np.ones(3) if t is None else np.asarray(t, dtype=np.float64), 0.0, 1.0)


def _blend_is_exact(a: dict, b: dict) -> bool:
    """Is blending parameters a and b by a Mix Shader's Fac exactly the mix of their closures?
    True for two Lambertian-plus-emission closures with the same scalars (Diffuse BSDFs, Emissions):
    both are linear in base colour and emission.  Any specular, metallic or transmissive side is not (roughness, metallic, IOR blends change the lobe's shape)."""
    if any(p.get("transmission_tint") is not None or p.get("reflection_tint") is not None for p in (a, b)):
        return False
    if any(float(p[k]) != 0.0 for p in (a, b) for k in ("metallic", "transmission", "specular")):
        return False
    return all(float(a[k]) == float(b[k]) for k in ("roughness", "ior"))


class MaterialExporter:
    """Converts and caches materials; ``warnings`` collects what was approximated."""

    def __init__(self, warnings: list, bakes=None):
        self.warnings = warnings
        self.materials: list = []
        self._index: dict = {}
        self.textures = node_export.TextureTable()   # .textures: the scene's Texture list
        self._graph_mode = False   # the material being converted carries its node graph
        # Baking (:mod:`.bake`): a BakeResolver, or None (inputs the interpreter cannot evaluate
        # fall back to defaults, as before).  While a material is converted: the (node, socket)
        # inputs and the node names whose messages the bake report gives instead
        self.bakes = bakes
        self._covered_sockets: set = set()
        self._covered_nodes: set = set()
        self._unread: set = set()          # bake keys whose EXR could not be read
        self._cover = False                # the material being converted gets a bake report

    # Public entry
    def tangent_maps(self, indices) -> list:
        """UV map names ("" = render-active) whose tangents the materials ``indices`` (into
        ``self.materials``) read: their graphs' tangent-space Normal Map nodes."""
        names = []
        for i in indices:
            graph = getattr(self.materials[i], "graph", None)
            for node in (graph.nodes.values() if graph is not None else ()):
                if node.type == "ShaderNodeNormalMap" and node.props.get("space", "TANGENT") == "TANGENT":
                    name = str(node.props.get("uv_map", "") or "")
                    if name not in names:
                        names.append(name)
        return names

    def color_maps(self, indices) -> list:
        """Colour-attribute names ("" = render-active) the materials ``indices`` read: their
        graphs' Color Attribute nodes and Geometry-type Attribute nodes (an Attribute may also
        name a UV map: the mesh's UV maps are exported anyway)."""
        names = []
        for i in indices:
            graph = getattr(self.materials[i], "graph", None)
            for node in (graph.nodes.values() if graph is not None else ()):
                if node.type == "ShaderNodeVertexColor":
                    name = str(node.props.get("layer_name", "") or "")
                elif node.type == "ShaderNodeAttribute" and node.props.get("attribute_type", "GEOMETRY") == "GEOMETRY":
                    name = str(node.props.get("attribute_name", "") or "")
                    if not name:
                        continue
                else:
                    continue
                if name not in names:
                    names.append(name)
        return names

    def index_of(self, mat, obj=None, is_instance: bool = False) -> int:
        """Index into ``self.materials`` of a Blender material (None -> the grey default) on the
        evaluated object ``obj`` (None: no baking).

        With baking (``self.bakes``), the material's inputs that the interpreter cannot evaluate
        are looked up per object: a material with cached bakes is exported once per distinct set
        of bake keys (objects with other UVs or meshes get their own copy, linked duplicates
        share one), and every such input is named in the warnings (baked, not yet baked, or why
        it cannot be)."""
        statuses = []
        if mat is not None and obj is not None and self.bakes is not None:
            try:
                statuses = self.bakes.status(mat, obj, is_instance)
            except Exception as e:  # noqa: BLE001 -- never fail an export on the bake look-up
                text = f"material {mat.name!r}: the bake look-up failed ({type(e).__name__}: {e}); inputs are not baked"
                if text not in self.warnings:
                    self.warnings.append(text)
        baked = [s for s in statuses if s.state == "baked"]
        key = mat.name_full if mat is not None else None
        if baked:
            key = (key, tuple(sorted(s.key for s in baked)))
        if key not in self._index:
            self._index[key] = len(self.materials)
            self._cover = bool(statuses)
            try:
                self.materials.append(self.convert(mat, baked) if mat is not None else default_material())
            finally:
                self._cover = False
        if statuses:
            self._report_bakes(mat, obj, statuses)
        return self._index[key]

    def _report_bakes(self, mat, obj, statuses) -> None:
        """One message per input to bake (module :mod:`.bake`)."""
        self._where = f"material {mat.name!r}"
        on = f" on object {obj.name!r}"
        for s in statuses:
            c = s.cand
            state = "unread" if s.state == "baked" and s.key in self._unread else s.state
            if state == "baked":
                r = self.bakes.resolution
                self._warn(f"{c.label}{on} baked to a {r}x{r} texture ({c.cause()})")
                continue
            fallback = ", ".join(repr(n) for n, _t, _w in c.unsupported[:3])
            fallback = (f"the sockets fed by {fallback}{' ...' if len(c.unsupported) > 3 else ''} "
                        f"use their own default values")
            if state == "missing":
                self._warn(f"{c.label}{on} needs a bake ({c.cause()}) and none is cached: {fallback} until it is "
                           f"baked ({bake_hint()})")
            elif state == "unread":
                self._warn(f"{c.label}{on}: its baked texture could not be read; {fallback}")
            elif state == "failed":
                self._warn(f"{c.label}{on} could not be baked ({c.cause()}): {'; '.join(s.reasons)}; {fallback}")
            else:   # blocked: by the subtree (said once per material) or by this object
                where = "" if c.blockers else on
                self._warn(f"{c.label}{where} cannot be baked ({c.cause()}): {'; '.join(s.reasons)}; {fallback}")

    def _apply_bakes(self, mat, graph, builder, baked) -> None:
        """Note what the bake report covers; replace the baked inputs by their textures."""
        self._covered_sockets, self._covered_nodes = set(), set()
        if self.bakes is None or not self._cover:
            return
        bake_mod = sub_bake()
        for c in self.bakes.inputs(mat).candidates:
            self._covered_sockets.add((c.consumer, c.socket))
            self._covered_nodes.update(n for n, _t, _w in c.unsupported)
        if graph is None or not baked:
            return
        applied = 0
        for s in baked:
            if s.cand.consumer not in graph.nodes:
                continue
            idx = self.textures.index_of_file(s.path, f"{mat.name}: {s.cand.label} (baked)", self._warn)
            if idx < 0:
                self._unread.add(s.key)
                continue
            bake_mod.substitute(graph, s.cand, idx, s.uv_map)
            applied += 1
        if applied:
            for name in bake_mod.prune(graph):
                builder.images.pop(name, None)
                builder.grouped.discard(name)

    def convert(self, mat, baked=()) -> "scene_model.Material":
        """One Blender material -> Material (never raises for unsupported setups); ``baked``: the
        :class:`.bake.Status` of its inputs with a cached bake on the object being exported."""
        self._where = f"material {mat.name!r}"
        self._covered_sockets, self._covered_nodes = set(), set()
        tree = mat.node_tree if _uses_nodes(mat) else None
        graph = None
        if tree is None:
            p = _params(base_color=np.array(mat.diffuse_color[:3], dtype=np.float64),
                        metallic=float(mat.metallic), roughness=float(mat.roughness))
        else:
            out = self._output_node(tree)
            sock = out.inputs.get("Surface") if out is not None else None
            no_surface = sock is None or not sock.is_linked
            vol = out.inputs.get("Volume") if out is not None else None
            volume_only = no_surface and vol is not None and vol.is_linked
            for ignored in ("Displacement", "Volume"):
                other = out.inputs.get(ignored) if out is not None else None
                if other is not None and other.is_linked and not (ignored == "Volume" and volume_only):
                    self._warn(f"Material Output {ignored} is ignored (STPM renders the Surface only)")
            builder = node_export.GraphBuilder()
            try:
                graph = builder.build(out) if out is not None else None
            except RecursionError:
                self._warn("the node tree is too deep to export as a graph; rendered with constant parameters")
                graph = None
            try:
                self._apply_bakes(mat, graph, builder, baked)
            except Exception as e:  # noqa: BLE001 -- never fail an export on a bake
                self._warn(f"the baked textures could not be applied ({type(e).__name__}: {e})")
            if graph is None or not node_export.graph_needed(graph, builder):
                graph = None
            self._graph_mode = graph is not None
            try:
                if volume_only:
                    # Cycles: a material with a Volume and no Surface has no surface at all (rays
                    # cross its boundary); STPM has no volumes, so what is behind shows through
                    # (it rendered an opaque grey box: artist review 4's fog cube)
                    self._warn("volume-only material: the Volume is not rendered (STPM has no volumes) and "
                               "its surface is transparent, as in Cycles (no Surface shader)")
                    p = _params()
                    graph = _transparent_graph()
                elif no_surface:
                    # Cycles renders a Material Output with nothing linked black (it rendered grey)
                    self._warn("no surface shader connected: rendered black, as in Cycles")
                    p = _params(base_color=np.zeros(3), roughness=1.0)
                else:
                    p = self._shader(self._follow(sock.links[0]), depth=0)
            finally:
                self._graph_mode = False
            if graph is not None:
                graph = self._finish_graph(graph, builder)
        return self._material(p, mat.name, graph)

    def _finish_graph(self, graph, builder):
        """Resolve the graph's images to texture indices and report what it cannot render.

        The node interpreter's compiler is run once here: its messages (unsupported node types,
        operations, outputs, shader inputs ...) become the material's export warnings (the
        constant path's own warnings about what the graph renders were dropped).  Returns the
        graph (None if it could not be compiled: the constants are rendered, warned).
        """
        for msg in builder.warnings:
            self._warn(msg)
        for name, image in builder.images.items():
            node = graph.nodes[name]
            if image is None:
                self._warn(f"image texture {name!r} has no image, rendered magenta (1, 0, 1) as in Cycles")
                continue
            if image.source == "TILED":            # UDIM: one texture per tile, the node holds the table
                tiles = self.textures.index_of_tiles(image, self._warn)
                if tiles:
                    node.props["tiles"] = tiles
                    node.props["image"] = tiles[0][1]
                else:
                    self._warn(f"image {image.name!r}: no UDIM tile could be read, rendered magenta (1, 0, 1) "
                               f"as in Cycles")
                continue
            problem = self._image_problem(image)
            if problem is not None:
                # naming the node lets the renderer's own "has no image" line for it be dropped
                # as already said (artist review 4 read both)
                self._warn(f"node {name!r} ({node.type}): {problem}")
                continue
            if image.source in ("SEQUENCE", "MOVIE"):
                self._warn(f"image {image.name!r}: an image {image.source.lower()} is rendered as the one frame "
                           f"Blender has loaded")
            node.props["image"] = self.textures.index_of(image, self._warn)
        compile_mod = sub("nodes.compile")
        try:
            prog = compile_mod.compile_graph(graph, n_textures=len(self.textures.textures), uv_layers=[])
        except Exception as e:  # noqa: BLE001 -- never fail an export on the interpreter's compiler
            self._warn(f"the node graph could not be compiled ({type(e).__name__}: {e}); "
                       f"rendered with constant parameters")
            return None
        for msg in prog.unsupported:
            name = next((k for k in graph.nodes if msg.startswith(f"node {k!r} (")), None)
            node = graph.nodes.get(name) if name is not None else None
            if node is not None and node.type == "ShaderNodeTexImage" and "has no image" in msg:
                continue  # warned above, with the image's name and path
            if name is not None and name in self._covered_nodes:
                continue  # the bake report names it (baked, to be baked, or why not)
            self._warn(msg)
        return graph

    # Helpers
    def _warn(self, msg: str, graph_carries: bool = False) -> None:
        """Record ``msg`` once; ``graph_carries``: an approximation of the constant path that the
        material's node graph renders exactly (dropped when the material carries its graph)."""
        if graph_carries and self._graph_mode:
            return
        text = f"{self._where}: {msg}"
        if text not in self.warnings:
            self.warnings.append(text)

    def _output_node(self, tree):
        """The Material Output STPM renders: the active one of those for All / Cycles, else the first such;
        with only EEVEE outputs, an EEVEE one (warned: Cycles would not use it)."""
        node, eevee = find_output(tree)
        if eevee:
            self._warn(f"the only Material Output ({node.name!r}) has target {node.target} (EEVEE only); "
                       f"STPM renders it anyway (Cycles would ignore it): set its target to All")
        return node

    @staticmethod
    def _follow(link):
        """The node feeding a link, skipping reroutes."""
        node = link.from_node
        while node.bl_idname == "NodeReroute" and node.inputs[0].is_linked:
            node = node.inputs[0].links[0].from_node
        return node

    def _material(self, p: dict, name: str, graph=None) -> "scene_model.Material":
        base = np.asarray(p["base_color"], dtype=np.float64)
        if np.any(base > 1.0):
            self._warn("base colour above 1 clipped (energy conservation)")
        if np.any(np.asarray(p["emission"], float) < 0.0):
            self._warn("negative emission is not supported, clamped to 0")
        tint = None
        if p.get("transmission_tint") is not None:
            tint = _tint(p)
            if np.array_equal(tint, np.clip(base, 0.0, 1.0)):
                tint = None                     # the default: the base colour
        tint_r = None
        if p.get("reflection_tint") is not None:
            tint_r = _tint_r(p)
            if np.all(tint_r == 1.0):
                tint_r = None                   # the default: white
        return scene_model.Material(
            base_color=np.clip(base, 0.0, 1.0), transmission_tint=tint, reflection_tint=tint_r,
            metallic=float(np.clip(p["metallic"], 0, 1)), transmission=float(np.clip(p["transmission"], 0, 1)),
            roughness=float(np.clip(p["roughness"], 0, 1)), specular=float(np.clip(p["specular"], 0, 1)),
            ior=float(np.clip(p["ior"], 1.0, 10.0)), emission=np.maximum(np.asarray(p["emission"], float), 0.0),
            constant_fresnel=bool(p.get("constant_fresnel", False)), name=name, graph=graph)

    def _value(self, node, name: str, default: float) -> float:
        """A scalar input's value (linked inputs: their default, with a warning)."""
        sock = node.inputs.get(name)
        if sock is None:
            return default
        if sock.is_linked:
            src = self._follow(sock.links[0])
            if src.bl_idname == "ShaderNodeValue":
                return float(src.outputs[0].default_value)
            if (node.name, sock.identifier) not in self._covered_sockets:   # else the bake report names it
                self._warn(f"{node.name}.{name} driven by {src.bl_idname} is not supported, using its value",
                           graph_carries=True)
        return float(sock.default_value)

    def _color(self, node, name: str, default=(0.8, 0.8, 0.8)) -> np.ndarray:
        """A colour input (3,) linear RGB; image textures give their mean colour."""
        sock = node.inputs.get(name)
        if sock is None:
            return np.asarray(default, dtype=np.float64)
        if sock.is_linked:
            src = self._follow(sock.links[0])
            if src.bl_idname == "ShaderNodeTexImage":
                mean, loaded = self._image_mean(src.image)
                if mean is not None:
                    if loaded:
                        self._warn(f"image texture {src.image.name!r} approximated by its mean colour",
                                   graph_carries=True)
                    return mean
            elif src.bl_idname == "ShaderNodeRGB":
                return np.array(src.outputs[0].default_value[:3], dtype=np.float64)
            elif (node.name, sock.identifier) not in self._covered_sockets:   # else the bake report names it
                self._warn(f"{node.name}.{name} driven by {src.bl_idname} is not supported, using its colour",
                           graph_carries=True)
        return np.array(sock.default_value[:3], dtype=np.float64)

    def _image_mean(self, image) -> tuple:
        """(mean linear RGB (3,) or None, loaded: bool) of an image node's image.

        No image: (None, False), the socket's colour is used.  A file that is
        missing or cannot be loaded: Cycles' magenta, (MISSING_IMAGE, False), warned
        with the path.
        """
        if image is None:
            self._warn("image texture without an image, using its colour", graph_carries=True)
            return None, False
        problem = self._image_problem(image)
        if problem is not None:
            self._warn(problem, graph_carries=True)     # the graph's own line names the node
            return MISSING_IMAGE.copy(), False
        return image_mean(image), True

    @staticmethod
    def _image_problem(image) -> str | None:
        """Why ``image`` has no pixels to render (missing file, unloadable), or None."""
        import bpy
        if image.source in ("FILE", "SEQUENCE", "MOVIE") and image.packed_file is None:
            path = bpy.path.abspath(image.filepath, library=image.library)
            if not os.path.exists(path):
                return f"image {image.name!r}: file {path!r} is missing, rendered magenta (1, 0, 1) as in Cycles"
        w, h = image.size[:]
        if w * h == 0 or image.channels < 3:
            where = f"file {bpy.path.abspath(image.filepath, library=image.library)!r}" if image.filepath else "it"
            return f"image {image.name!r}: {where} could not be loaded, rendered magenta (1, 0, 1) as in Cycles"
        return None

    # The shader tree walk
    def _shader(self, node, depth: int) -> dict:
        """Parameters of the closure produced by ``node`` (recursive through Mix Shader)."""
        kind = node.bl_idname
        if depth > 16:
            self._warn("shader tree too deep, using grey diffuse")
            return _params()
        for sock in node.inputs:  # Normal, Coat Normal, Clearcoat Normal, ...
            if sock.is_linked and sock.name.endswith("Normal") and sock.type == "VECTOR":
                src = self._follow(sock.links[0])
                self._warn(f"{node.name}.{sock.name} driven by {src.bl_idname} is ignored "
                           f"(no bump or normal mapping: the surface normal is used)", graph_carries=True)
        if kind == "ShaderNodeHoldout":
            self._warn("Holdout shader is not supported, rendered as grey diffuse", graph_carries=True)
            return _params()
        if kind == "ShaderNodeBsdfPrincipled":
            for name in ("Coat Weight", "Sheen Weight", "Subsurface Weight"):
                # (a Coat Weight keeps the node graph, which renders the coat: this line is dropped
                # then; it stays for a graph that could not be exported)
                if self._value(node, name, 0.0) > 0:
                    self._warn(f"Principled {name} is ignored", graph_carries=True)
            for name in ("Diffuse Roughness", "Thin Film Thickness"):   # (Blender 4.2 / 4.3 on)
                if _anisotropic(node, name):
                    self._warn(f"Principled {name} is ignored", graph_carries=True)
            tint = node.inputs.get("Specular Tint")
            if tint is not None and (tint.is_linked or any(float(c) != 1.0 for c in tuple(tint.default_value)[:3])):
                self._warn("Principled Specular Tint is ignored (untinted, as white)", graph_carries=True)
            if _anisotropic(node, "Anisotropic"):
                self._warn(ANISOTROPY_IGNORED.format(what="Principled Anisotropic"), graph_carries=True)
            alpha = node.inputs.get("Alpha")
            alpha_linked = alpha is not None and alpha.is_linked and \
                self._follow(alpha.links[0]).bl_idname != "ShaderNodeValue"
            if self._value(node, "Alpha", 1.0) < 1.0 or (alpha_linked and self._graph_mode):
                self._warn("Principled Alpha is ignored (opaque)", graph_carries=True)   # the graph renders it
            emission = self._color(node, "Emission Color", (0, 0, 0)) * self._value(node, "Emission Strength", 0.0)
            base = self._color(node, "Base Color")
            # Cycles tints the Principled BSDF's refraction by sqrt(base colour) (svm/closure.h)
            return _params(base_color=base, transmission_tint=np.sqrt(np.clip(base, 0.0, 1.0)),
                           metallic=self._value(node, "Metallic", 0.0),
                           roughness=self._value(node, "Roughness", 0.5),
                           transmission=self._value(node, "Transmission Weight", 0.0),
                           ior=self._value(node, "IOR", 1.5),
                           specular=min(1.0, 2.0 * self._value(node, "Specular IOR Level", 0.5)),
                           emission=emission)
        if kind == "ShaderNodeBsdfDiffuse":
            return _params(base_color=self._color(node, "Color"), roughness=1.0, specular=0.0)
        if kind in ("ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic"):
            if _anisotropic(node, "Anisotropy"):
                self._warn(ANISOTROPY_IGNORED.format(what=f"{node.name}.Anisotropy"), graph_carries=True)
            # Cycles 5.0 gives the Glossy BSDF no Fresnel: its colour at every angle
            return _params(base_color=self._color(node, "Color"), metallic=1.0, constant_fresnel=True,
                           roughness=self._value(node, "Roughness", 0.5))
        if kind == "ShaderNodeBsdfGlass":
            color = self._color(node, "Color", (1, 1, 1))
            # Cycles tints a Glass BSDF's reflection by its colour too (svm/closure.h)
            return _params(base_color=color, reflection_tint=np.clip(color, 0.0, 1.0), transmission=1.0,
                           roughness=self._value(node, "Roughness", 0.0), ior=self._value(node, "IOR", 1.5))
        if kind == "ShaderNodeEmission":
            return _params(base_color=np.zeros(3), roughness=1.0,
                           emission=self._color(node, "Color", (1, 1, 1)) * self._value(node, "Strength", 1.0))
        if kind == "ShaderNodeMixShader":
            fac = float(np.clip(self._value(node, "Fac", 0.5), 0.0, 1.0))
            sides = []
            for sock in (node.inputs[1], node.inputs[2]):
                sides.append(self._shader(self._follow(sock.links[0]), depth + 1) if sock.is_linked
                             else _params(base_color=np.zeros(3)))
            if not _blend_is_exact(sides[0], sides[1]):
                # the material carries its graph (nodes.graph_needed), which renders the two weighted
                # closures; only without one (it could not be built or compiled, warned) is this blend rendered
                self._warn("Mix Shader approximated by blending the two shaders' parameters", graph_carries=True)
            mixed = {k: (1 - fac) * np.asarray(sides[0][k], float) + fac * np.asarray(sides[1][k], float)
                     for k in FIELDS}
            if any(sd.get("transmission_tint") is not None for sd in sides):
                mixed["transmission_tint"] = (1 - fac) * _tint(sides[0]) + fac * _tint(sides[1])
            if any(sd.get("reflection_tint") is not None for sd in sides):
                mixed["reflection_tint"] = (1 - fac) * _tint_r(sides[0]) + fac * _tint_r(sides[1])
            # the metal lobe's Fresnel: the side that carries more of it decides
            metal_w = ((1 - fac) * float(sides[0]["metallic"]), fac * float(sides[1]["metallic"]))
            mixed["constant_fresnel"] = bool(sides[int(metal_w[1] > metal_w[0])].get("constant_fresnel", False))
            return mixed
        # with a graph, the node compiler names the shader (the graph renders the same grey; a
        # group's shaders it inlines)
        self._warn(f"shader node {node.bl_idname} ({node.name!r}) is not supported, using grey diffuse",
                   graph_carries=True)
        return _params()
