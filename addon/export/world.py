"""Blender world -> :class:`stpm_core.scene.World`: a constant colour, an equirectangular
Environment Texture (turned by a Mapping node), or any other world baked by Cycles, as background
and light.

Read directly: a Background node whose Colour is unlinked or fed by an Environment Texture
(equirectangular, an image that loads, its vector unlinked or from a Mapping node with unlinked
inputs on Texture Coordinate *Generated*), its Strength unlinked, no Light Path node upstream.

Everything else on the World Output (Sky Texture of every type, Gradient / Noise / Voronoi
textures, Mix nodes, a Mirror Ball projection, a linked Strength, Mix / Add Shaders of
backgrounds, node groups, Light Path tricks) is **baked**: a child process renders the world
alone with Cycles through a panoramic equirectangular camera (:data:`WORLD_BAKE_RESOLUTION`,
:data:`WORLD_BAKE_SAMPLES` samples, box filter one pixel wide, no denoising, 32-bit linear EXR;
pixels far brighter than the rest, a sun disc, are rendered again in small crops at up to
:data:`WORLD_REFINE_SAMPLES` samples) and the image is exported as ``World.image`` with colour 1,
strength 1 (the Background's whole radiance, colour x strength, is baked), identity mapping,
Linear interpolation -- exactly like an Environment Texture.  Child, copy of the .blend and
cache folders are :mod:`.bake`'s (:func:`.bake.run_jobs`, :func:`.bake.cache_dirs`); the child's
world job is :mod:`.world_bake_child`.

Light Path in the world tree: Cycles evaluates the world with "Is Camera Ray" = 1 for camera
rays and with every "Is ... Ray" output 0 when it samples the world as a light (next-event
estimation, its importance map).  When "Is Camera Ray" is read, two images are baked: the
camera view (as rendered: Is Camera Ray 1) becomes ``World.camera_image`` and the lighting view
(each Is Camera Ray link replaced by a Value node 0, node groups copied first) ``World.image``.
In both, the other outputs keep what a camera ray reaching the background gives them: Is
Shadow / Diffuse / Glossy / Singular / Reflection / Transmission / Volume Scatter Ray 0, the
depths 0 -- what Cycles' light sampling from a first hit sees; Cycles' bounce rays that hit the
world see other values (a warning names the outputs read).

Cache key (:func:`world_bake_key`): the world node tree's whole signature
(:func:`.bake.tree_signature`: nodes, values, images, node groups), the view, resolution,
samples, refinement settings, :data:`WORLD_BAKE_VERSION` and Blender's version.  Animated world
trees are baked at the current frame (animated values change the signature, so each frame gets
its own bake; animation within the shutter is not baked, warned).

When a bake is needed: the export reads the cache; a missing bake is made when baking is on
(``stpm render``, the Bake Unsupported Inputs operator: :func:`.bake.bake_scene` plans it with
:func:`plan_world_jobs`), else the world renders as read directly (today's fallbacks) with a
warning naming the cause.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field

import numpy as np

from .._core import scene_model
from .materials import linear_rgb

WORLD_BAKE_VERSION = 1
WORLD_BAKE_RESOLUTION = (1024, 512)       # (width, height) of a world bake
WORLD_BAKE_SAMPLES = 16                   # Cycles samples per pixel of the whole image
WORLD_REFINE_SAMPLES = 1024               # at most, in the crops around very bright pixels
WORLD_REFINE_SHARE = 1e-4                 # a pixel carrying more than this share of the power is refined
WORLD_VIEW_NODES = {"ShaderNodeCameraData": "depends on the camera"}
WORLD_VIEW_OUTPUTS = {"ShaderNodeTexCoord": ("Camera", "Window")}

# Bake failures of this process ({key: reason}), noted by :func:`note_bake_results`, for the
# export's messages when its caller passes no BakeResolver
LAST_FAILED: dict = {}


def _uses_nodes(idblock) -> bool:
    """Blender < 5 has a use_nodes switch; 5.0 always uses the node tree (and deprecates the flag)."""
    import bpy
    if bpy.app.version >= (5, 0, 0):
        return idblock.node_tree is not None
    return bool(idblock.use_nodes)


def _output_node(tree):
    """The active World Output node of a node tree, or None."""
    outs = [n for n in tree.nodes if n.bl_idname == "ShaderNodeOutputWorld"]
    active = [n for n in outs if getattr(n, "is_active_output", False)]
    return (active or outs or [None])[0]


def export_world(world, warnings: list, times=None, mapping_keys=None, bakes="default") -> "scene_model.World":
    """The world's Background node: colour * strength, or an Environment Texture's image.

    The core lights the scene with it as Cycles does (stpm_core/world_light.py): a constant
    environment, or an equirectangular image, importance-sampled.  An Environment Texture's vector
    may come through a Mapping node (rotation; :func:`mapping_rotation`); ``mapping_keys`` (K, 3,
    3) are its map-to-world rotations at the shutter ``times`` (K,) when the rotation is animated
    (:func:`mapping_is_animated`), else it is read now.  What is not supported is warned and
    replaced by the closest thing that is (a mean colour, the node's own colour, black).

    A world the exporter does not read directly uses its Cycles bake (module docstring):
    ``bakes`` is a :class:`.bake.BakeResolver` (its cache folders and failures), "default" (the
    open file's cache folders) or None (baking off: the direct reading, warned).

    The world's photon budget is ``world.stpm.photon_weight`` (addon/properties.py; 1 without it).
    """
    out = _export_world(world, warnings, times, mapping_keys, bakes)
    out.photon_weight = float(getattr(getattr(world, "stpm", None), "photon_weight", 1.0)) if world is not None else 1.0
    return out


def background_nodes(world):
    """(Background node, Environment Texture node or None, Mapping node or None) feeding the
    world's output, or None when the output is not a Background node."""
    tree = world.node_tree if world is not None and _uses_nodes(world) else None
    if tree is None:
        return None
    out = _output_node(tree)
    sock = out.inputs.get("Surface") if out is not None else None
    if sock is None or not sock.is_linked:
        return None
    node = sock.links[0].from_node
    if node.bl_idname != "ShaderNodeBackground":
        return None
    color_in = node.inputs["Color"]
    env = color_in.links[0].from_node if color_in.is_linked else None
    if env is None or env.bl_idname != "ShaderNodeTexEnvironment":
        return node, None, None
    vec = env.inputs.get("Vector")
    mapping = vec.links[0].from_node if vec is not None and vec.is_linked else None
    return node, env, mapping if mapping is not None and mapping.bl_idname == "ShaderNodeMapping" else None


def _euler_xyz(rx: float, ry: float, rz: float) -> np.ndarray:
    """Blender's XYZ Euler rotation matrix (3, 3): Rz @ Ry @ Rx."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def mapping_rotation(mapping, warnings: list | None = None, where: str = "world") -> np.ndarray:
    """Map-to-world rotation (3, 3) of a Mapping node on an Environment Texture's vector.

    Cycles turns the ray direction d into the image's frame by m = R (S d) + T (Point), R (S d)
    (Vector), R^-1 ((d - T) / S) (Texture), R (d / S) (Normal), R the XYZ Euler rotation; the
    texture normalises m.  A direction only turns: STPM keeps R (its inverse maps the image's
    frame to the world, R itself for Texture) and warns about a location or a non-uniform or
    negative scale, which it ignores.
    """
    if mapping is None:
        return np.eye(3)
    kind = getattr(mapping, "vector_type", "POINT")
    def value(name):
        sock = mapping.inputs.get(name)
        if sock is None:
            return np.zeros(3) if name != "Scale" else np.ones(3)
        if sock.is_linked and warnings is not None:
            warnings.append(f"{where}: the Mapping node's linked {name} is not supported, using its value")
        return np.array(sock.default_value[:3], dtype=np.float64)
    R = _euler_xyz(*value("Rotation"))
    if warnings is not None:
        if kind in ("POINT", "TEXTURE") and np.any(np.abs(value("Location")) > 1e-9):
            warnings.append(f"{where}: the Mapping node's Location is ignored (a direction has no position)")
        sc = value("Scale")
        if np.ptp(sc) > 1e-6 * max(np.abs(sc).max(), 1e-30) or np.any(sc <= 0):
            warnings.append(f"{where}: the Mapping node's Scale {np.round(sc, 4).tolist()} is ignored "
                            f"(only its rotation turns the environment)")
    return R if kind == "TEXTURE" else R.T


def mapping_is_animated(world) -> bool:
    """Does an F-curve (or a driver) animate a Mapping node of the world's tree?"""
    tree = world.node_tree if world is not None and _uses_nodes(world) else None
    ad = getattr(tree, "animation_data", None) if tree is not None else None
    if ad is None:
        return False
    from .bake import _fcurves                     # layered actions (Blender 4.4+), legacy ones, drivers
    paths = [fc.data_path for fc in _fcurves(ad)]
    names = [n.name for n in tree.nodes if n.bl_idname == "ShaderNodeMapping"]
    return any(f'nodes["{nm}"]' in p for p in paths for nm in names)


def _mapping_transform(rotations, times) -> "scene_model.MotionTransform":
    mats = []
    for R in rotations:
        M = np.eye(4)
        M[:3, :3] = R
        mats.append(M)
    if len(mats) == 1 or all(np.allclose(m, mats[0], atol=1e-12) for m in mats):
        return scene_model.MotionTransform.static(mats[0])
    return scene_model.MotionTransform(times=np.asarray(times, np.float64), matrices=np.array(mats))


def _export_world(world, warnings: list, times=None, mapping_keys=None, bakes="default") -> "scene_model.World":
    plan = None
    if world is not None:
        try:
            plan = bake_plan(world)
        except (AttributeError, KeyError, RuntimeError, ReferenceError) as e:   # an odd tree: read it directly
            warnings.append(f"world {world.name!r}: its node tree could not be checked for a bake "
                            f"({type(e).__name__}: {e}); read without one")
    if plan is not None:
        got = _baked_world(world, plan, warnings, bakes)
        if got is not None:
            return got
    return _direct_world(world, warnings, times, mapping_keys)


def _direct_world(world, warnings: list, times=None, mapping_keys=None) -> "scene_model.World":
    """What the exporter reads without a bake: a constant, or an Environment Texture."""
    if world is None:
        return scene_model.World(color=np.zeros(3), strength=1.0)
    tree = world.node_tree if _uses_nodes(world) else None
    if tree is None:
        return scene_model.World(color=np.array(world.color[:3], dtype=np.float64), strength=1.0)
    out = _output_node(tree)
    sock = out.inputs.get("Surface") if out is not None else None
    if sock is None or not sock.is_linked:
        return scene_model.World(color=np.zeros(3), strength=1.0)
    node = sock.links[0].from_node
    if node.bl_idname != "ShaderNodeBackground":
        warnings.append(f"world {world.name!r}: {node.bl_idname} is not supported, using black")
        return scene_model.World(color=np.zeros(3), strength=1.0)
    color_in, strength_in = node.inputs["Color"], node.inputs["Strength"]
    color = np.maximum(np.array(color_in.default_value[:3], dtype=np.float64), 0.0)
    if strength_in.is_linked:
        warnings.append(f"world {world.name!r}: linked background strength is not supported, using its default value")
    strength = max(float(strength_in.default_value), 0.0)
    if not color_in.is_linked:
        return scene_model.World(color=color, strength=strength)
    src = color_in.links[0].from_node
    if src.bl_idname != "ShaderNodeTexEnvironment":
        warnings.append(f"world {world.name!r}: {src.bl_idname} on the background is not supported, using "
                        f"the Background node's own colour")
        return scene_model.World(color=color, strength=strength)
    image = getattr(src, "image", None)
    if image is None or image.size[0] * image.size[1] == 0 or image.channels < 3:
        what = "has no image" if image is None else f"image {image.name!r} could not be loaded"
        warnings.append(f"world {world.name!r}: the environment texture {what}, using the Background "
                        f"node's own colour")
        return scene_model.World(color=color, strength=strength)
    where = f"world {world.name!r}"
    if getattr(src, "projection", "EQUIRECTANGULAR") != "EQUIRECTANGULAR":
        mean = np.maximum(environment_mean(image), 0.0)
        warnings.append(f"{where}: the {src.projection} projection is not supported; environment texture "
                        f"{image.name!r} is used as its mean radiance {np.round(mean, 4).tolist()}")
        return scene_model.World(color=mean, strength=strength)
    vec = src.inputs.get("Vector")
    mapping = None
    if vec is not None and vec.is_linked:
        mapping = vec.links[0].from_node
        if mapping.bl_idname != "ShaderNodeMapping":
            warnings.append(f"{where}: {mapping.bl_idname} on the environment's vector is not supported, "
                            f"using the view direction")
            mapping = None
        else:
            mv = mapping.inputs.get("Vector")
            feed = mv.links[0].from_node if mv is not None and mv.is_linked else None
            if feed is not None and not (feed.bl_idname == "ShaderNodeTexCoord" and
                                         mv.links[0].from_socket.name == "Generated"):
                warnings.append(f"{where}: the Mapping node's vector comes from {feed.bl_idname} "
                                f"{mv.links[0].from_socket.name!r}, rendered as the view direction")
    interp = getattr(src, "interpolation", "Linear")
    if interp in ("Cubic", "Smart"):
        warnings.append(f"{where}: {interp} interpolation of the environment is rendered Linear")
    if mapping_keys is not None and times is not None and len(mapping_keys) == len(times):
        mapping_tf = _mapping_transform(list(mapping_keys), times)
        mapping_rotation(mapping, warnings, where)              # (the warnings, once)
    else:
        mapping_tf = _mapping_transform([mapping_rotation(mapping, warnings, where)], [0.5])
    return scene_model.World(color=np.ones(3), strength=strength, image=environment_pixels(image),
                             mapping=mapping_tf, interpolation="CLOSEST" if interp == "Closest" else "LINEAR")


def environment_pixels(image) -> np.ndarray:
    """An environment image's pixels (H, W, 3) float32 linear RGB, row 0 at the bottom (Blender's
    order); 8-bit sRGB images linearised, negative values clamped to 0."""
    w, h = image.size[:]
    c = image.channels
    px = np.empty(w * h * c, dtype=np.float32)
    image.pixels.foreach_get(px)
    rgb = np.ascontiguousarray(px.reshape(h, w, c)[:, :, :3])
    del px
    rgb = linear_rgb(rgb, image)
    return np.ascontiguousarray(np.maximum(np.nan_to_num(rgb, nan=0.0, posinf=0.0), 0.0), dtype=np.float32)


def environment_mean(image, max_rows: int = 512) -> np.ndarray:
    """Mean radiance (3,) over the sphere of an equirectangular environment image (linear RGB).

    Row y (of h, bottom-up) spans latitude ``phi = -pi/2 + pi (y + 1/2) / h``; a pixel's solid
    angle is proportional to cos(phi), so the mean over directions is
    ``sum_y cos(phi_y) rowmean_y / sum_y cos(phi_y)``.  At most ``max_rows`` rows (evenly
    strided) are averaged, each over all its pixels; 8-bit sRGB images are linearised.
    """
    w, h = image.size[:]
    c = image.channels
    px = np.empty(w * h * c, dtype=np.float32)
    image.pixels.foreach_get(px)
    rows = np.unique(np.linspace(0, h - 1, min(h, max_rows)).round().astype(np.int64))
    rgb = px.reshape(h, w, c)[rows, :, :3]
    del px
    rgb = linear_rgb(rgb, image)
    weight = np.cos(-0.5 * np.pi + np.pi * (rows + 0.5) / h)
    return (weight[:, None] * rgb.mean(axis=1, dtype=np.float64)).sum(axis=0) / weight.sum()


# ----------------------------------------------------------------------------
# Baked worlds (module docstring)
# ----------------------------------------------------------------------------
@dataclass
class WorldBakePlan:
    """Why a world is baked and what its bake reads."""

    reasons: list                                     # why the exporter cannot read it directly
    camera: bool = False                              # Light Path "Is Camera Ray" is read: two views
    light_path_outputs: list = field(default_factory=list)   # other Light Path outputs read
    view_nodes: list = field(default_factory=list)    # camera-dependent nodes read (warned)

    @property
    def views(self) -> tuple:
        return ("light", "camera") if self.camera else ("light",)

    def cause(self) -> str:
        return "; ".join(self.reasons)


@dataclass
class WorldJob:
    """One world bake for the child (:mod:`.world_bake_child`): plain data (``to_json``)."""

    key: str
    world: str
    view: str                     # "light" (Is Camera Ray = 0) or "camera" (as rendered)
    resolution: list
    samples: int
    refine_samples: int
    refine_share: float
    label: str
    path: str = ""

    def to_json(self) -> dict:
        d = dict(self.__dict__)
        d["type"] = "world"
        return d


def _link(sock):
    """The socket's first link that is not muted, or None."""
    if sock is None or not sock.is_linked:
        return None
    for lk in sock.links:
        if not getattr(lk, "is_muted", False):
            return lk
    return None


def _surface_socket(world):
    tree = world.node_tree if world is not None and _uses_nodes(world) else None
    if tree is None:
        return None
    out = _output_node(tree)
    return out.inputs.get("Surface") if out is not None else None


def upstream_nodes(sock) -> list:
    """Every node feeding ``sock`` through links (muted links not followed); a node group's whole
    tree counts (recursively)."""
    out, seen, trees = [], set(), set()
    stack = [lk.from_node for lk in (sock.links if sock is not None and sock.is_linked else ())
             if not getattr(lk, "is_muted", False)]
    while stack:
        n = stack.pop()
        if n.as_pointer() in seen:
            continue
        seen.add(n.as_pointer())
        out.append(n)
        for s in n.inputs:
            if s.is_linked:
                stack.extend(lk.from_node for lk in s.links if not getattr(lk, "is_muted", False))
        tree = getattr(n, "node_tree", None) if n.bl_idname == "ShaderNodeGroup" else None
        if tree is not None and tree.as_pointer() not in trees:
            trees.add(tree.as_pointer())
            stack.extend(tree.nodes)
    return out


def _env_problems(lk) -> list:
    """Why the Environment Texture path of the Background colour cannot be read directly."""
    src = lk.from_node
    what = f"node {src.name!r} ({src.bl_idname})"
    if src.bl_idname != "ShaderNodeTexEnvironment":
        return [f"{what} feeds the Background colour"]
    if src.mute:
        return [f"{what} is muted"]
    if lk.from_socket.identifier != "Color":
        return [f"the {lk.from_socket.name} output of {what} feeds the Background colour"]
    image = getattr(src, "image", None)
    if image is None or image.size[0] * image.size[1] == 0 or image.channels < 3:
        return []                   # read directly: the missing image is warned there
    if getattr(src, "projection", "EQUIRECTANGULAR") != "EQUIRECTANGULAR":
        return [f"{what} uses the {src.projection} projection"]
    v = _link(src.inputs.get("Vector"))
    if v is None:
        return []
    m = v.from_node
    if m.bl_idname != "ShaderNodeMapping" or m.mute:
        return [f"node {m.name!r} ({m.bl_idname}){' (muted)' if m.mute else ''} feeds the Environment Texture's vector"]
    out = []
    linked = [s.name for s in m.inputs if s.identifier != "Vector" and s.is_linked]
    if linked:
        out.append(f"the Mapping node {m.name!r} has its {', '.join(linked)} linked")
    f = _link(m.inputs.get("Vector"))
    if f is not None and not (f.from_node.bl_idname == "ShaderNodeTexCoord" and f.from_socket.name == "Generated"):
        out.append(f"the Mapping node's vector comes from node {f.from_node.name!r} ({f.from_node.bl_idname}) "
                   f"{f.from_socket.name!r}")
    return out


def bake_plan(world) -> WorldBakePlan | None:
    """The bake a world needs (None: the exporter reads it directly; module docstring)."""
    sock = _surface_socket(world)
    lk = _link(sock)
    if lk is None:
        return None
    reasons = []
    node = lk.from_node
    if node.bl_idname != "ShaderNodeBackground":
        reasons.append(f"node {node.name!r} ({node.bl_idname}) feeds the World Output")
    elif node.mute:
        reasons.append(f"the Background node {node.name!r} is muted")
    else:
        s = _link(node.inputs["Strength"])
        if s is not None:
            reasons.append(f"the Background Strength is linked (from node {s.from_node.name!r} "
                           f"({s.from_node.bl_idname}))")
        c = _link(node.inputs["Color"])
        if c is not None:
            reasons.extend(_env_problems(c))
    camera, outputs, view = False, [], []
    for n in upstream_nodes(sock):
        if n.bl_idname == "ShaderNodeLightPath":
            used = [o.name for o in n.outputs if o.is_linked]
            if "Is Camera Ray" in used:
                camera = True
            outputs.extend(o for o in used if o != "Is Camera Ray" and o not in outputs)
            if used:
                reasons.append(f"node {n.name!r} (ShaderNodeLightPath) reads the light path "
                               f"({', '.join(used)})")
        elif n.bl_idname in WORLD_VIEW_NODES:
            view.append(f"node {n.name!r} ({n.bl_idname}) {WORLD_VIEW_NODES[n.bl_idname]}")
        else:
            bad = [o.name for o in n.outputs if o.name in WORLD_VIEW_OUTPUTS.get(n.bl_idname, ()) and o.is_linked]
            if bad:
                view.append(f"node {n.name!r} ({n.bl_idname}): its {', '.join(bad)} output depends on the camera")
    if not reasons:
        return None
    return WorldBakePlan(reasons=reasons, camera=camera, light_path_outputs=outputs, view_nodes=view)


def world_bake_key(world, view: str, memo: dict | None = None) -> str:
    """The cache key of one view of a world bake (module docstring)."""
    import bpy
    from .bake import tree_signature
    data = [WORLD_BAKE_VERSION, bpy.app.version_string, "world", view, [int(x) for x in WORLD_BAKE_RESOLUTION],
            int(WORLD_BAKE_SAMPLES), int(WORLD_REFINE_SAMPLES), repr(float(WORLD_REFINE_SHARE)),
            tree_signature(world.node_tree, {} if memo is None else memo)]
    from .nodes import working_space
    if working_space() != "REC709":           # the bake holds working-space values (older keys unchanged)
        data.append(working_space())
    return hashlib.sha256(json.dumps(data, default=repr).encode()).hexdigest()[:24]


def _find(key: str, dirs) -> str | None:
    for d in dirs:
        p = os.path.join(d, key + ".exr")
        if os.path.isfile(p):
            return p
    return None


def plan_world_jobs(world, dirs) -> list:
    """The missing bakes of ``world`` (one :class:`WorldJob` per view), none when it is read directly
    or its bakes are cached in ``dirs``."""
    if world is None:
        return []
    plan = bake_plan(world)
    if plan is None:
        return []
    jobs, memo = [], {}
    w, h = (int(x) for x in WORLD_BAKE_RESOLUTION)
    for view in plan.views:
        key = world_bake_key(world, view, memo)
        if _find(key, dirs) is None:
            jobs.append(WorldJob(key=key, world=world.name_full, view=view, resolution=[w, h],
                                 samples=int(WORLD_BAKE_SAMPLES), refine_samples=int(WORLD_REFINE_SAMPLES),
                                 refine_share=float(WORLD_REFINE_SHARE),
                                 label=f"world {world.name!r} ({'camera' if view == 'camera' else 'lighting'} view)"))
    return jobs


def note_bake_results(jobs, report: dict) -> None:
    """Remember which world bakes of :func:`.bake.run_jobs`' ``report`` failed (and forget those made)."""
    failed = report.get("failed", {}) or {}
    for j in jobs:
        if j.key in failed:
            LAST_FAILED[j.key] = failed[j.key]
        else:
            LAST_FAILED.pop(j.key, None)


def _bake_source(bakes):
    """(cache folders, {key: failure}) for ``bakes`` ("default" or a BakeResolver)."""
    import bpy
    from .bake import cache_dirs
    failed = dict(LAST_FAILED)
    if isinstance(bakes, str):
        return cache_dirs(bpy.data.filepath or None), failed
    dirs = getattr(bakes, "dirs", None)
    failed.update(getattr(bakes, "failed", None) or {})
    return (list(dirs) if dirs else cache_dirs(bpy.data.filepath or None)), failed


def _read_bake(path: str) -> np.ndarray:
    """A baked world EXR -> (H, W, 3) float32 linear RGB, row 0 at the bottom, finite, >= 0."""
    from .nodes import read_float_image
    px = read_float_image(path)
    if px.ndim != 3 or px.shape[2] < 3 or min(px.shape[:2]) < 1:
        raise ValueError(f"it has shape {px.shape}, not (H, W, 3)")
    rgb = np.nan_to_num(px[:, :, :3], nan=0.0, posinf=0.0, neginf=0.0)
    return np.ascontiguousarray(np.maximum(rgb, 0.0), dtype=np.float32)


def _baked_world(world, plan: WorldBakePlan, warnings: list, bakes) -> "scene_model.World | None":
    """The baked world (None: no bake to use, warned: the caller reads the world directly)."""
    from .bake import OPERATOR_HINT
    where = f"world {world.name!r}"
    fallback = "it renders as the exporter reads the Background node directly"
    if bakes is None:
        warnings.append(f"{where} needs a Cycles bake ({plan.cause()}) and baking is off: {fallback}")
        return None
    try:
        dirs, failed = _bake_source(bakes)
        memo: dict = {}
        keys = {v: world_bake_key(world, v, memo) for v in plan.views}
    except Exception as e:  # noqa: BLE001 -- never fail an export on the bake cache
        warnings.append(f"{where} needs a Cycles bake ({plan.cause()}) and the bake cache could not be opened "
                        f"({type(e).__name__}: {e}): {fallback}")
        return None
    images = {}
    for view, key in keys.items():
        path = _find(key, dirs)
        if path is None:
            if key in failed:
                warnings.append(f"{where} could not be baked ({plan.cause()}): {failed[key]}; {fallback}")
            else:
                warnings.append(f"{where} needs a Cycles bake ({plan.cause()}) and none is cached: until it is "
                                f"baked ({OPERATOR_HINT}), {fallback}")
            return None
        try:
            images[view] = _read_bake(path)
        except (OSError, ValueError, ImportError) as e:
            warnings.append(f"{where}: its baked image {path!r} could not be read ({e}); {fallback}")
            return None
    img = images["light"]
    warnings.append(f"{where} baked by Cycles to a {img.shape[1]}x{img.shape[0]} environment ({plan.cause()})")
    cam = images.get("camera")
    if cam is not None:
        warnings.append(f"{where}: camera rays see a second bake with Light Path 'Is Camera Ray' = 1 "
                        f"(World.camera_image); the light it casts has Is Camera Ray = 0")
    if plan.light_path_outputs:
        warnings.append(f"{where}: Light Path output(s) {', '.join(repr(o) for o in plan.light_path_outputs)} are "
                        f"baked with what a camera ray gives them (Is ... Ray 0, depths 0, as Cycles' light "
                        f"sampling sees them); Cycles' reflected, refracted and bounced rays that see the world "
                        f"get other values")
    if plan.view_nodes:
        warnings.append(f"{where}: {'; '.join(plan.view_nodes)}: baked as seen by the bake's panoramic camera at "
                        f"the origin, not the scene camera")
    from .bake import animated_nodes
    anim = animated_nodes(world.node_tree)
    if anim:
        warnings.append(f"{where}: {', '.join(repr(n) for n in sorted(anim))} animated: the world is baked at "
                        f"the current frame (animation within the shutter is not baked)")
    return scene_model.World(color=np.ones(3), strength=1.0, image=img, camera_image=cam,
                             mapping=scene_model.MotionTransform.static(np.eye(4)), interpolation="LINEAR")
