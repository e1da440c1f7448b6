"""The STPM scene file: one versioned file holding a whole :class:`~stpm_core.scene.Scene`.

A render can then run outside Blender (``stpm render scene.stpm``), on a farm
or in a test, from exactly the data the add-on exported.

Container
---------
A numpy ``.npz`` archive (zip, deflate-compressed, written with
``np.savez_compressed`` and read with ``allow_pickle=False``: loading a scene
never executes code).  It holds

* ``header``: (B,) uint8, the UTF-8 bytes of a JSON object with the format
  name ``"stpm-scene"``, the format ``version`` and every scalar, enum,
  colour and list field of the scene (and optionally the render settings);
* named arrays for everything bulky: mesh vertices / triangles / material ids /
  normals / vertex times / UV maps, the times and matrices of every motion
  transform, the shutter curve and texture pixels.  Array names are listed in
  ``docs/scene-format.md``.

Shader-node graphs (``Material.graph``) are JSON in the header (materials[i].graph,
:meth:`~stpm_core.nodes.ShaderGraph.to_json`); textures are ``textures/<i>/pixels``
(H, W, C) in their native dtype (uint8, uint16, or float32; half floats as their
uint16 bit patterns with ``half`` true) plus ``name`` / ``colorspace`` / ``half`` in
the header (and ``alpha_mode``); a mesh's UV maps are ``meshes/<i>/uv/<j>`` (F, 3, 2)
float32 with the names in meshes[i].uv_layers and the render-active name in
meshes[i].uv_render, its tangents ``meshes/<i>/tangents/<j>`` (F, 3, 4) float32 with
their UV map names in meshes[i].tangents, its colour attributes ``meshes/<i>/colors/<j>``
(F, 3, 4) float32 linear RGBA with the names in meshes[i].color_layers and the render-active
name in meshes[i].color_render.  These keys are optional: a file without them loads with no
graphs, textures, UVs, tangents or colour attributes.  A UDIM Image Texture holds its tile table
in its node's ``props["tiles"]`` ([tile, texture index] pairs, one texture per tile), and
``metadata.working_space`` names the scene's working colour space; a file using either is
written as version 3 (:func:`_version_needed`), every other one as version 2.  A deforming
mesh's ``normals`` may be (K, F, 3, 3), one (F, 3, 3) set per vertex step; a file with such
normals is written as version 4; a camera with a thin lens (``aperture_radius > 0``) writes the
lens fields (``aperture_radius``, ``focus_distance``, ``aperture_blades``, ``aperture_rotation``,
``aperture_ratio``) into its header entry and is written as version 5.

Loading
-------
:func:`load_scene` checks the container, the header's format and version,
every header field's type and every array's shape, dtype and finiteness,
builds the scene and runs :func:`~stpm_core.scene.validate_scene`.  The first
problem raises :class:`~stpm_core.errors.SceneError` with one line naming the
field (``lights[0] ('Key').power must be in [0.0, inf], got -5.0``).  Nothing
is returned half-loaded.
"""
from __future__ import annotations

import json
import math
import os
import tokenize
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .errors import SceneError, SettingsError
from .motion import MotionTransform
from .schema import check_metadata
from .nodes.compile import MAX_RAMP, compile_graph
from .nodes.graph import ShaderGraph
from .scene import (SCENE_FORMAT_VERSION, Camera, Instance, Light, Material, Mesh, Scene,
                    World, check_tiles, validate_scene)
from .settings import RenderSettings
from .shutter import Shutter
from .textures import COLOR_SPACES, Texture

__all__ = ["save_scene", "load_scene", "load_scene_with_settings", "FORMAT_NAME",
           "SCENE_FORMAT_VERSION", "SCENE_SUFFIXES"]

FORMAT_NAME = "stpm-scene"
# File name endings the CLI treats as core scene files.
SCENE_SUFFIXES = (".stpm", ".npz")

# Scalar fields written to the header, per dataclass: name -> kind.
# kinds: 'num' float, 'int' integer, 'bool', 'str', 'vec3' three floats, enum tuples.
_CAMERA_FIELDS = {
    "type": ("PERSP", "ORTHO"), "lens": "num", "sensor_width": "num", "sensor_height": "num",
    "sensor_fit": ("AUTO", "HORIZONTAL", "VERTICAL"), "ortho_scale": "num",
    "shift_x": "num", "shift_y": "num", "clip_start": "num", "clip_end": "num",
}
# The thin lens (depth of field): written only when camera.aperture_radius > 0 (format version 5)
_LENS_FIELDS = {"aperture_radius": "num", "focus_distance": "num", "aperture_blades": "int",
                "aperture_rotation": "num", "aperture_ratio": "num"}
_LIGHT_FIELDS = {
    "name": "str", "type": ("POINT", "SPOT", "AREA", "SUN"), "color": "vec3", "power": "num",
    "radius": "num", "use_soft_falloff": "bool", "spot_size": "num", "spot_blend": "num",
    "shape": ("SQUARE", "RECTANGLE", "DISK", "ELLIPSE"), "size": "num", "size_y": "num",
    "angle": "num",
}
_MATERIAL_FIELDS = {
    "name": "str", "base_color": "vec3", "metallic": "num", "transmission": "num",
    "roughness": "num", "specular": "num", "ior": "num", "emission": "vec3",
}
_WORLD_FIELDS = {"color": "vec3", "strength": "num"}
_TEXTURE_FIELDS = {"name": "str", "colorspace": COLOR_SPACES, "half": "bool"}
_ALPHA_MODES = ("STRAIGHT", "PREMUL", "CHANNEL_PACKED", "NONE")      # Texture.alpha_mode (Blender's names)
_TEXTURE_DTYPES = (np.dtype(np.uint8), np.dtype(np.uint16), np.dtype(np.float32))

# Node properties the compiler (stpm_core.nodes.compile) reads, by the JSON type they must have
_ENUM_PROPS = ("operation", "blend_type", "data_type", "factor_mode", "vector_type", "interpolation",
               "extension", "projection", "gradient_type", "clamp_type", "interpolation_type", "color_mode",
               "mode", "uv_map", "space", "noise_dimensions", "noise_type", "voronoi_dimensions", "feature",
               "distance", "wave_type", "bands_direction", "rings_direction", "wave_profile")
_BOOL_PROPS = ("use_clamp", "clamp_factor", "clamp_result", "clamp", "from_instancer", "object", "normalize",
               "invert")
_NUM_PROPS = ("offset", "offset_frequency", "squash", "squash_frequency", "turbulence_depth")


# ----------------------------------------------------------------------------
# Saving
# ----------------------------------------------------------------------------
def _scalar_to_json(kind, value):
    """A dataclass field value -> its JSON form (floats stay exact: JSON keeps repr)."""
    if kind == "vec3":
        return [float(x) for x in np.asarray(value, dtype=np.float64).ravel()]
    if kind == "num":
        return float(value)
    if kind == "int":
        return int(value)
    if kind == "bool":
        return bool(value)
    return str(value)


def _fields_to_json(obj, spec: dict) -> dict:
    return {name: _scalar_to_json(kind, getattr(obj, name)) for name, kind in spec.items()}


def _put_transform(arrays: dict, key: str, tf: MotionTransform) -> None:
    """Store a motion transform as ``key/times`` (K,) float64 and ``key/matrices`` (K, 4, 4) float64."""
    arrays[f"{key}/times"] = np.asarray(tf.times, dtype=np.float64)
    arrays[f"{key}/matrices"] = np.asarray(tf.matrices, dtype=np.float64)


def scene_to_arrays(scene: Scene, settings: RenderSettings | None = None) -> tuple[dict, dict]:
    """Split a scene into (header dict, arrays dict) exactly as :func:`save_scene` writes them."""
    validate_scene(scene)
    arrays: dict[str, np.ndarray] = {}

    # Meshes: bulky data as arrays, flags in the header
    meshes = []
    for i, m in enumerate(scene.meshes):
        p = f"meshes/{i}"
        arrays[f"{p}/vertices"] = np.asarray(m.vertices, dtype=np.float32)
        arrays[f"{p}/triangles"] = np.asarray(m.triangles, dtype=np.int32)
        arrays[f"{p}/material_ids"] = np.asarray(m.material_ids, dtype=np.int32)
        if m.vertex_times is not None:
            arrays[f"{p}/vertex_times"] = np.asarray(m.vertex_times, dtype=np.float64)
        if m.normals is not None:
            arrays[f"{p}/normals"] = np.asarray(m.normals, dtype=np.float32)
        entry = {"name": str(m.name), "has_vertex_times": m.vertex_times is not None,
                 "has_normals": m.normals is not None}
        if getattr(m, "orco", None) is not None:
            arrays[f"{p}/orco"] = np.asarray(m.orco, dtype=np.float32)
            entry["has_orco"] = True
        if getattr(m, "texspace", None) is not None:
            arrays[f"{p}/texspace"] = np.asarray(m.texspace, dtype=np.float64)
            entry["has_texspace"] = True
        uv_names = _put_uv_layers(arrays, p, m, f"meshes[{i}] ({m.name!r})")
        if uv_names:
            entry["uv_layers"] = uv_names
            entry["uv_render"] = None if m.uv_render is None else str(m.uv_render)
        tan_names = _put_tangents(arrays, p, m, f"meshes[{i}] ({m.name!r})", uv_names)
        if tan_names:
            entry["tangents"] = tan_names
        col_names = _put_colors(arrays, p, m, f"meshes[{i}] ({m.name!r})")
        if col_names:
            entry["color_layers"] = col_names
            entry["color_render"] = None if m.color_render is None else str(m.color_render)
        meshes.append(entry)

    # Materials (with their node graphs) and textures
    textures = []
    for i, tx in enumerate(getattr(scene, "textures", None) or []):
        textures.append(_put_texture(arrays, i, tx))
    materials = []
    for i, m in enumerate(scene.materials):
        d = _fields_to_json(m, _MATERIAL_FIELDS)
        for tint_name in ("transmission_tint", "reflection_tint"):      # written only when set
            if getattr(m, tint_name, None) is not None:
                d[tint_name] = _scalar_to_json("vec3", getattr(m, tint_name))
        if getattr(m, "constant_fresnel", False):                       # written only when set
            d["constant_fresnel"] = True
        if getattr(m, "graph", None) is not None:
            d["graph"] = _graph_to_json(m.graph, f"materials[{i}] ({m.name!r}).graph", len(textures))
        materials.append(d)

    # Instances, camera and lights: motion transforms as arrays
    instances = []
    for i, inst in enumerate(scene.instances):
        _put_transform(arrays, f"instances/{i}/transform", inst.transform)
        instances.append({"name": str(inst.name), "mesh": int(inst.mesh),
                          "shadow_terminator_geometry_offset": float(inst.shadow_terminator_geometry_offset),
                          "shadow_terminator_shading_offset": float(inst.shadow_terminator_shading_offset)})
    _put_transform(arrays, "camera/transform", scene.camera.transform)
    lights = []
    for i, light in enumerate(scene.lights):
        _put_transform(arrays, f"lights/{i}/transform", light.transform)
        lights.append(_fields_to_json(light, _LIGHT_FIELDS))
        if float(getattr(light, "photon_weight", 1.0)) != 1.0:          # written only when set
            lights[-1]["photon_weight"] = float(light.photon_weight)
    portals = []
    for i, portal in enumerate(getattr(scene, "portals", None) or ()):
        _put_transform(arrays, f"portals/{i}/transform", portal.transform)
        portals.append(_fields_to_json(portal, _LIGHT_FIELDS))

    # Shutter curve (optional)
    if scene.shutter.curve is not None:
        arrays["shutter/curve"] = np.asarray(scene.shutter.curve, dtype=np.float64)

    try:   # NaN passes this first step, so that a typed key holding one is named below
        metadata = json.loads(json.dumps(scene.metadata))
    except (TypeError, ValueError, RecursionError) as e:
        raise SceneError(f"metadata must be JSON-serialisable: {e}") from None
    check_metadata(metadata)                        # never write what cannot load
    try:
        json.dumps(metadata, allow_nan=False)
    except ValueError as e:
        raise SceneError(f"metadata must be JSON-serialisable: {e}") from None
    header = {
        "format": FORMAT_NAME,
        "version": _version_needed(scene, materials),
        "frame": float(scene.frame),
        "resolution": [int(scene.resolution[0]), int(scene.resolution[1])],
        "shutter": {"open": float(scene.shutter.open), "close": float(scene.shutter.close),
                    "has_curve": scene.shutter.curve is not None},
        "camera": _camera_to_json(scene.camera),
        "world": _world_to_json(arrays, scene.world),
        "materials": materials,
        "lights": lights,
        "meshes": meshes,
        "instances": instances,
        "metadata": metadata,
    }
    if portals:
        header["portals"] = portals
    if textures:
        header["textures"] = textures
    if settings is not None:
        header["settings"] = settings.validate().to_dict()
    return header, arrays


def _camera_to_json(cam: Camera) -> dict:
    """The camera's header entry; the lens fields only for a thin lens (aperture_radius > 0)."""
    d = _fields_to_json(cam, _CAMERA_FIELDS)
    if float(cam.aperture_radius) > 0.0:
        d.update(_fields_to_json(cam, _LENS_FIELDS))
    return d


def _version_needed(scene: Scene, materials: list) -> int:
    """The lowest format version that reads this scene as written: 5 when the camera has a thin
    lens (a version-4 reader would ignore it and render a pinhole: it must refuse instead); 4 when a deforming mesh has
    normals per vertex step (K, F, 3, 3); else 3 when it uses UDIM tile tables or a working space
    other than Linear Rec.709 (a version-2 reader would render the first tile only, or the colours
    unconverted: it must refuse the file instead); else 2."""
    udim = any("tiles" in n.get("props", {}) for m in materials for n in m.get("graph", {}).get("nodes", {}).values())
    working = str(scene.metadata.get("working_space", "REC709")).upper() != "REC709"
    keyed = any(m.normals is not None and np.ndim(m.normals) == 4 for m in scene.meshes)
    if float(scene.camera.aperture_radius) > 0.0:
        return 5
    return 4 if keyed else 3 if udim or working else 2


def _put_corner_layers(arrays: dict, p: str, m: Mesh, where: str, attr: str, sub: str, width: int,
                       allowed: list | None = None) -> list:
    """Store mesh m's per-corner layers ``m.<attr>`` ({name: (F, 3, width)}) as ``p/<sub>/<j>``
    float32 -> their names (checked: strings, shape, finite; in ``allowed`` when given)."""
    layers = getattr(m, attr, None) or {}
    if not isinstance(layers, dict):
        raise SceneError(f"{where}.{attr} must be a dict of name -> (F, 3, {width}) array")
    F = int(np.asarray(m.triangles).shape[0])
    names = []
    for j, (name, value) in enumerate(layers.items()):
        if not isinstance(name, str):
            raise SceneError(f"{where}.{attr} names must be strings, got {name!r}")
        if allowed is not None and name not in allowed:
            raise SceneError(f"{where}.{attr}[{name!r}] names no UV map of the mesh {allowed}")
        a = np.asarray(value, dtype=np.float32)
        if a.shape != (F, 3, width):
            raise SceneError(f"{where}.{attr}[{name!r}] must have shape ({F}, 3, {width}), got {a.shape}")
        if not np.all(np.isfinite(a)):
            raise SceneError(f"{where}.{attr}[{name!r}] contains NaN or inf")
        arrays[f"{p}/{sub}/{j}"] = a
        names.append(name)
    return names


def _put_uv_layers(arrays: dict, p: str, m: Mesh, where: str) -> list:
    """Store mesh m's UV maps as ``p/uv/<j>`` (F, 3, 2) float32 -> their names (checked)."""
    names = _put_corner_layers(arrays, p, m, where, "uv_layers", "uv", 2)
    if m.uv_render is not None and (not isinstance(m.uv_render, str) or m.uv_render not in names):
        raise SceneError(f"{where}.uv_render {m.uv_render!r} is not one of its UV maps {names}")
    return names


def _put_tangents(arrays: dict, p: str, m: Mesh, where: str, uv_names: list) -> list:
    """Store mesh m's tangents as ``p/tangents/<j>`` (F, 3, 4) float32 -> their UV map names."""
    return _put_corner_layers(arrays, p, m, where, "tangents", "tangents", 4, allowed=uv_names)


def _put_colors(arrays: dict, p: str, m: Mesh, where: str) -> list:
    """Store mesh m's colour attributes as ``p/colors/<j>`` (F, 3, 4) float32 -> their names."""
    names = _put_corner_layers(arrays, p, m, where, "color_layers", "colors", 4)
    render = getattr(m, "color_render", None)
    if render is not None and (not isinstance(render, str) or render not in names):
        raise SceneError(f"{where}.color_render {render!r} is not one of its colour attributes {names}")
    return names


def _world_to_json(arrays: dict, world) -> dict:
    """The world's header entry; an environment image goes to ``world/image`` (H, W, 3) float32 and
    its mapping to ``world/mapping/times`` and ``world/mapping/matrices``."""
    d = _fields_to_json(world, _WORLD_FIELDS)
    if float(getattr(world, "photon_weight", 1.0)) != 1.0:
        d["photon_weight"] = float(world.photon_weight)
    if world.image is not None:
        d["has_image"] = True
        d["interpolation"] = str(world.interpolation)
        arrays["world/image"] = np.ascontiguousarray(world.image, dtype=np.float32)
        _put_transform(arrays, "world/mapping", world.mapping)
    if getattr(world, "camera_image", None) is not None:
        d["has_camera_image"] = True
        arrays["world/camera_image"] = np.ascontiguousarray(world.camera_image, dtype=np.float32)
    return d


def _world_from_json(f: "_Fields", arr: "_Arrays") -> World:
    """World from its header entry (``has_image``, ``interpolation``, ``has_camera_image`` optional:
    older files have none of them)."""
    fields = f.read(_WORLD_FIELDS)
    if "photon_weight" in f.d:                       # optional (written when not 1)
        fields["photon_weight"] = f.num("photon_weight")
    cam = None
    if "has_camera_image" in f.d and f.bool("has_camera_image"):
        cam = np.ascontiguousarray(arr.get("world/camera_image", "world.camera_image", kind="f", ndim=3, tail=(3,)),
                                   dtype=np.float32)
    if "has_image" not in f.d or not f.bool("has_image"):
        return World(**fields, camera_image=cam)
    img = arr.get("world/image", "world.image", kind="f", ndim=3, tail=(3,))
    return World(**fields, image=np.ascontiguousarray(img, dtype=np.float32),
                 mapping=arr.transform("world/mapping", "world.mapping"),
                 interpolation=f.enum("interpolation", ("LINEAR", "CLOSEST")), camera_image=cam)


def _put_texture(arrays: dict, i: int, tx) -> dict:
    """Store texture i's pixels as ``textures/<i>/pixels`` (native dtype) -> its header entry."""
    where = f"textures[{i}] ({getattr(tx, 'name', '?')!r})"
    if not isinstance(tx, Texture):
        raise SceneError(f"{where} must be a stpm_core.textures.Texture, got {type(tx).__name__}")
    entry = {"name": str(tx.name), "colorspace": str(tx.colorspace), "half": bool(tx.half),
             "alpha_mode": str(getattr(tx, "alpha_mode", "STRAIGHT"))}
    _check_texture(where, tx.pixels, entry)
    arrays[f"textures/{i}/pixels"] = np.ascontiguousarray(tx.pixels)
    return entry


def _check_texture(where: str, px: np.ndarray, entry: dict) -> None:
    """Texture pixels (H, W, C) and header entry: dtype, shape, finiteness, colour space."""
    if entry["alpha_mode"] not in _ALPHA_MODES:
        raise SceneError(f"{where}.alpha_mode must be one of {', '.join(_ALPHA_MODES)}, got {entry['alpha_mode']!r:.60}")
    if entry["colorspace"] not in _TEXTURE_FIELDS["colorspace"]:
        raise SceneError(f"{where}.colorspace must be one of {', '.join(_TEXTURE_FIELDS['colorspace'])}, "
                         f"got {entry['colorspace']!r:.60}")
    if px.dtype not in _TEXTURE_DTYPES:
        raise SceneError(f"{where}.pixels must be a uint8, uint16 or float32 array, got dtype {px.dtype}")
    if px.ndim != 3 or px.shape[0] < 1 or px.shape[1] < 1 or px.shape[2] not in (1, 3, 4):
        raise SceneError(f"{where}.pixels must have shape (H, W, 1|3|4) with H, W >= 1, got {px.shape}")
    if entry["half"]:
        if px.dtype != np.uint16:
            raise SceneError(f"{where}.pixels must be uint16 half-float bit patterns when half is true, "
                             f"got dtype {px.dtype}")
        if np.any((px & 0x7C00) == 0x7C00):
            raise SceneError(f"{where}.pixels contains NaN or inf")
    elif px.dtype == np.float32 and not np.all(np.isfinite(px)):
        raise SceneError(f"{where}.pixels contains NaN or inf")


def _graph_to_json(graph, where: str, n_textures: int) -> dict:
    """A material's ShaderGraph -> its (checked) JSON form."""
    if not callable(getattr(graph, "to_json", None)):
        raise SceneError(f"{where} must be a stpm_core.nodes.ShaderGraph, got {type(graph).__name__}")
    try:
        d = json.loads(json.dumps(graph.to_json(), allow_nan=False))
    except (TypeError, ValueError) as e:
        raise SceneError(f"{where} must be JSON-serialisable with finite numbers: {e}".splitlines()[0]) from None
    _graph_from_json(d, where, n_textures)          # the loader's checks: never write what cannot load
    return d


def save_scene(scene: Scene, path, settings: RenderSettings | None = None, *, compress: bool = True) -> Path:
    """Write ``scene`` (and optionally its render settings) to one file at ``path``.

    The scene is validated first (a malformed scene is never written).  The
    file is written to a temporary name and renamed, so a crash never leaves a
    truncated scene behind.  Returns the path written (numpy would append
    ``.npz`` to a bare name; we do not: the name is used as given).
    ``compress=False`` stores the members without deflate (a file read once at
    once, such as a .blend reader's hand-over: faster to write and read).
    """
    header, arrays = scene_to_arrays(scene, settings)
    blob = np.frombuffer(json.dumps(header, allow_nan=False).encode("utf-8"), dtype=np.uint8)
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        (np.savez_compressed if compress else np.savez)(f, header=blob, **arrays)
    os.replace(tmp, path)
    return path


# ----------------------------------------------------------------------------
# Loading: typed access to the header, naming every field
# ----------------------------------------------------------------------------
class _Fields:
    """Typed reads from one JSON object; every error names ``prefix.key``."""

    def __init__(self, d, prefix: str):
        if not isinstance(d, dict):
            raise SceneError(f"{prefix or 'header'} must be a JSON object, got {type(d).__name__}")
        self.d, self.prefix = d, prefix

    def name(self, key: str) -> str:
        return f"{self.prefix}.{key}" if self.prefix else key

    def raw(self, key: str):
        if key not in self.d:
            raise SceneError(f"missing key {self.name(key)!r}")
        return self.d[key]

    def num(self, key: str) -> float:
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise SceneError(f"{self.name(key)} must be a number, got {v!r:.60}")
        try:
            v = float(v)
        except OverflowError:  # an integer too large for a float
            raise SceneError(f"{self.name(key)} is too large, got {v!r:.40}") from None
        if not math.isfinite(v):
            raise SceneError(f"{self.name(key)} must be finite, got {v}")
        return v

    def int(self, key: str, lo: int = -2**62, hi: int = 2**62) -> int:
        v = self.raw(key)
        if isinstance(v, bool) or not isinstance(v, int):
            raise SceneError(f"{self.name(key)} must be an integer, got {v!r:.60}")
        if not lo <= v <= hi:
            raise SceneError(f"{self.name(key)} must be in [{lo}, {hi}], got {v}")
        return v

    def bool(self, key: str) -> bool:
        v = self.raw(key)
        if not isinstance(v, bool):
            raise SceneError(f"{self.name(key)} must be true or false, got {v!r:.60}")
        return v

    def str(self, key: str) -> str:
        v = self.raw(key)
        if not isinstance(v, str):
            raise SceneError(f"{self.name(key)} must be a string, got {v!r:.60}")
        return v

    def enum(self, key: str, allowed: tuple) -> str:
        v = self.raw(key)
        if v not in allowed:
            raise SceneError(f"{self.name(key)} must be one of {', '.join(allowed)}, got {v!r:.60}")
        return v

    def vec3(self, key: str) -> np.ndarray:
        v = self.raw(key)
        if (not isinstance(v, list) or len(v) != 3
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            raise SceneError(f"{self.name(key)} must be a list of 3 numbers, got {v!r:.60}")
        try:
            a = np.array(v, dtype=np.float64)
        except OverflowError:
            raise SceneError(f"{self.name(key)} has a number too large for a float") from None
        if not np.all(np.isfinite(a)):
            raise SceneError(f"{self.name(key)} contains NaN or inf")
        return a

    def list(self, key: str) -> list:
        v = self.raw(key)
        if not isinstance(v, list):
            raise SceneError(f"{self.name(key)} must be a list, got {type(v).__name__}")
        return v

    def sub(self, key: str) -> "_Fields":
        return _Fields(self.raw(key), self.name(key))

    def read(self, spec: dict) -> dict:
        """All fields of a dataclass spec (see ``_LIGHT_FIELDS``) -> keyword arguments."""
        out = {}
        for key, kind in spec.items():
            out[key] = self.enum(key, kind) if isinstance(kind, tuple) else getattr(self, kind)(key)
        return out


class _Arrays:
    """Typed reads of the named arrays; every error names the array's field."""

    def __init__(self, data: dict[str, np.ndarray]):
        self.data = data

    def get(self, key: str, field: str, *, kind: str, ndim: int, tail: tuple = (),
            optional: bool = False) -> np.ndarray | None:
        """Array ``key`` checked to have dtype kind 'f' / 'i' and shape (..., *tail).

        Float arrays must be finite.  Returns a copy in the canonical dtype
        (float32 / int32 as stored; times and matrices float64).
        """
        if key not in self.data:
            if optional:
                return None
            raise SceneError(f"missing array {key!r} ({field})")
        a = self.data[key]
        ok_kind = a.dtype.kind in ("f" if kind == "f" else "iu")
        if not ok_kind:
            want = "floating-point" if kind == "f" else "integer"
            raise SceneError(f"{field} must be a {want} array, got dtype {a.dtype}")
        if a.ndim != ndim or (tail and a.shape[ndim - len(tail):] != tail):
            shape = "(" + ", ".join(["N"] * (ndim - len(tail)) + [str(t) for t in tail]) + ")"
            raise SceneError(f"{field} must have shape {shape}, got {a.shape}")
        if kind == "f" and not np.all(np.isfinite(a)):
            raise SceneError(f"{field} contains NaN or inf")
        return a

    def transform(self, key: str, field: str) -> MotionTransform:
        """A motion transform from ``key/times`` (K,) and ``key/matrices`` (K, 4, 4)."""
        times = self.get(f"{key}/times", f"{field}.times", kind="f", ndim=1)
        mats = self.get(f"{key}/matrices", f"{field}.matrices", kind="f", ndim=3, tail=(4, 4))
        if times.shape[0] < 1 or mats.shape[0] != times.shape[0]:
            raise SceneError(f"{field} has {mats.shape[0]} matrices for {times.shape[0]} times "
                             "(need the same number, at least 1)")
        if times.shape[0] > 1 and np.any(np.diff(times) <= 0):
            raise SceneError(f"{field}.times must be strictly increasing")
        if np.any(times < 0) or np.any(times > 1):
            raise SceneError(f"{field}.times must lie in [0, 1] (normalised shutter time)")
        if not np.array_equal(mats[:, 3, :], np.broadcast_to([0.0, 0.0, 0.0, 1.0], (mats.shape[0], 4))):
            raise SceneError(f"{field}.matrices must be affine (last row 0 0 0 1)")
        if np.abs(mats).max() > 1e15:
            raise SceneError(f"{field}.matrices has entries beyond 1e15")
        try:
            return MotionTransform(times=times.astype(np.float64), matrices=mats.astype(np.float64))
        except SceneError as e:
            raise SceneError(f"{field}: {e}") from None


def _is_num(v) -> bool:
    """A JSON number that is a finite float (an integer too large for a float is not)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return False
    try:
        return math.isfinite(float(v))
    except OverflowError:
        return False


def _is_nums(v, n: int | None = None) -> bool:
    return isinstance(v, list) and (n is None or len(v) == n) and all(_is_num(x) for x in v)


def _check_prop_value(v, where: str, depth: int = 0) -> None:
    """A property of a node the compiler does not read: JSON scalars and lists of them."""
    if v is None or isinstance(v, (bool, str)) or _is_num(v):
        return
    if isinstance(v, list) and depth < 4:
        for k, x in enumerate(v):
            _check_prop_value(x, f"{where}[{k}]", depth + 1)
        return
    raise SceneError(f"{where} must be a string, boolean, finite number or a list of them, got {v!r:.60}")


def _check_props(props: dict, ntype: str, where: str, n_textures: int) -> None:
    """The properties :mod:`stpm_core.nodes.compile` reads, each with the JSON type it needs."""
    for key, v in props.items():
        w = f"{where}.props[{key!r}]"
        if key == "image":
            if isinstance(v, bool) or not isinstance(v, int) or not -1 <= v < n_textures:
                raise SceneError(f"{w} must be a texture index in [-1, {n_textures}), got {v!r:.60}")
        elif key == "tiles" and ntype == "ShaderNodeTexImage":
            check_tiles(v, w, n_textures)
        elif key == "elements":
            ok = isinstance(v, list) and 1 <= len(v) <= MAX_RAMP and all(
                isinstance(e, list) and len(e) == 2 and _is_num(e[0]) and isinstance(e[1], list)
                and len(e[1]) in (3, 4) and _is_nums(e[1]) for e in v)
            if not ok:
                raise SceneError(f"{w} must be 1 to {MAX_RAMP} [position, [r, g, b, a]] pairs of finite numbers")
        elif key == "table":
            ok = (isinstance(v, list) and len(v) == 3 and all(_is_nums(row) for row in v)
                  and len({len(row) for row in v}) == 1 and len(v[0]) >= 2)
            if not ok:
                raise SceneError(f"{w} must be 3 equally long lists (at least 2) of finite numbers")
        elif key == "value" and ntype == "ShaderNodeRGB":
            if not _is_nums(v, 3):
                raise SceneError(f"{w} must be a list of 3 finite numbers, got {v!r:.60}")
        elif key == "value" and ntype == "ShaderNodeValue":
            if not _is_num(v):
                raise SceneError(f"{w} must be a finite number, got {v!r:.60}")
        elif key in _ENUM_PROPS:
            if not isinstance(v, str):
                raise SceneError(f"{w} must be a string, got {v!r:.60}")
        elif key in _BOOL_PROPS:
            if not isinstance(v, bool):
                raise SceneError(f"{w} must be true or false, got {v!r:.60}")
        elif key in _NUM_PROPS:
            if not _is_num(v):
                raise SceneError(f"{w} must be a finite number, got {v!r:.60}")
        else:
            _check_prop_value(v, w)


def _str_map(f: "_Fields", key: str) -> dict:
    d = f.raw(key)
    if not isinstance(d, dict) or not all(isinstance(v, str) for v in d.values()):
        raise SceneError(f"{f.name(key)} must be a JSON object of socket types (strings)")
    return d


def _graph_from_json(d, where: str, n_textures: int) -> ShaderGraph:
    """A material's node graph from its JSON form, every field checked (links name existing
    nodes, inputs are finite numbers / 3 numbers / links, properties have the types the
    compiler reads); SceneError naming the field otherwise."""
    g = _Fields(d, where)
    nodes = g.raw("nodes")
    if not isinstance(nodes, dict):
        raise SceneError(f"{where}.nodes must be a JSON object of nodes by name")

    def check_link(v, w):
        if not (isinstance(v, list) and len(v) == 2 and all(isinstance(x, str) for x in v)):
            raise SceneError(f"{w} must be a [node name, socket identifier] pair of strings, got {v!r:.60}")
        if v[0] not in nodes:
            raise SceneError(f"{w} links to unknown node {v[0]!r}")

    for name, nd in nodes.items():
        f = _Fields(nd, f"{where}.nodes[{name!r}]")
        ntype = f.str("type")
        props = f.raw("props")
        if not isinstance(props, dict):
            raise SceneError(f"{f.name('props')} must be a JSON object")
        _check_props(props, ntype, f.prefix, n_textures)
        inputs = f.raw("inputs")
        if not isinstance(inputs, dict):
            raise SceneError(f"{f.name('inputs')} must be a JSON object")
        for ident, v in inputs.items():
            w = f"{f.prefix}.inputs[{ident!r}]"
            if isinstance(v, dict):
                if set(v) != {"link"}:
                    raise SceneError(f"{w} must be a number, 3 numbers or {{\"link\": [node, socket]}}")
                check_link(v["link"], w)
            elif not (_is_num(v) or _is_nums(v, 3)):
                raise SceneError(f"{w} must be a finite number, 3 finite numbers or a link, got {v!r:.60}")
        _str_map(f, "outputs")
        _str_map(f, "input_types")
    surface = g.raw("surface")
    if surface is not None:
        check_link(surface, f"{where}.surface")
    graph = ShaderGraph.from_json(d)
    try:   # whatever loads must compile (the checks above name the usual problems first)
        compile_graph(graph, n_textures, [])
    except Exception as e:  # noqa: BLE001 -- a malformed graph is the file's problem: one line
        raise SceneError(f"{where} cannot be compiled ({type(e).__name__}: {e})".splitlines()[0]) from None
    return graph


# Loading limits (docs/scene-format.md, "Limits"): an array is read only up to the size its own
# .npy header declares, that size must fit in its zip member, and all arrays together may take at
# most LOAD_MEMORY_FRACTION of the memory available (a small file that inflates to gigabytes, or
# a header declaring 10^12 vertices, is refused before anything is allocated or inflated).
LOAD_MEMORY_FRACTION = 0.5
_MAX_NPY_HEADER = 65536


def _load_cap() -> int | None:
    """Bytes all the arrays of one scene file may take when read (None: memory unknown, no cap)."""
    from .command_common import available_memory
    avail = available_memory()
    return None if avail is None else int(avail * LOAD_MEMORY_FRACTION)


def _fmt_bytes(n: int) -> str:
    for unit, size in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= size:
            return f"{n / size:.1f} {unit}"
    return f"{n} B"


def _brief(e: BaseException) -> str:
    """An exception's text for a one-line error: its first line, at most 160 characters (zipfile
    quotes whole garbled headers)."""
    text = (str(e).splitlines() or [""])[0]
    return text if len(text) <= 160 else text[:157] + "..."


def _npy_header(stream, key: str) -> tuple:
    """(shape, dtype, fortran_order, header bytes) of one .npy member, read from its first bytes."""
    from numpy.lib import format as npf
    try:
        version = npf.read_magic(stream)
        if version not in ((1, 0), (2, 0), (3, 0)):
            raise ValueError(f"unknown .npy version {version}")
        shape, fortran, dtype = npf._read_array_header(stream, version, max_header_size=_MAX_NPY_HEADER)
    except (ValueError, SyntaxError, tokenize.TokenError, TypeError, KeyError, EOFError, UnicodeError,
            zipfile.BadZipFile, zlib.error, OverflowError, RecursionError, MemoryError) as e:
        raise SceneError(f"array {key!r:.80} has a corrupt .npy header ({type(e).__name__}: {_brief(e)})"
                         .splitlines()[0]) from None
    if dtype.hasobject:
        raise SceneError(f"array {key!r} holds Python objects (dtype {dtype}): not allowed in a scene file")
    if not isinstance(shape, tuple) or any(isinstance(n, bool) or not isinstance(n, int) or n < 0 for n in shape):
        raise SceneError(f"array {key!r} has an invalid shape {shape!r:.60}")
    return shape, dtype, fortran, stream.tell()


def _read_container(path: Path) -> dict[str, np.ndarray]:
    """All arrays of the .npz at ``path``, read eagerly; SceneError if it is not one.

    Every member's .npy header is read first: its declared size must fit in the
    member (no more inflated bytes than that are ever read), and the arrays
    together must fit in :data:`LOAD_MEMORY_FRACTION` of the memory available.
    """
    if not path.exists():
        raise SceneError(f"scene file not found: {path}")
    if path.is_dir():
        raise SceneError(f"scene file is a directory: {path}")
    if not zipfile.is_zipfile(path):
        raise SceneError("not an STPM scene file (not a zip/npz archive; truncated or another format)")
    try:
        with zipfile.ZipFile(path) as zf:
            # 1. Headers only: declared shapes against the members and the memory available
            plan = []
            total = 0
            for info in zf.infolist():
                if not info.filename:            # a corrupt directory entry (ZipInfo.is_dir would IndexError)
                    raise SceneError("the archive has a member without a name (corrupt)")
                if info.is_dir():
                    continue
                key = info.filename[:-4] if info.filename.endswith(".npy") else info.filename
                with zf.open(info) as stream:
                    shape, dtype, fortran, head = _npy_header(stream, key)
                count = math.prod(shape)
                nbytes = count * dtype.itemsize
                shape_text = "x".join(map(str, shape)) or "scalar"
                if head + nbytes > info.file_size:
                    raise SceneError(f"array {key!r} declares {shape_text} {dtype} ({_fmt_bytes(nbytes)}) but its "
                                     f"member holds {_fmt_bytes(max(info.file_size - head, 0))} "
                                     "(corrupt or truncated)")
                if head + nbytes < info.file_size:
                    raise SceneError(f"array {key!r} declares {shape_text} {dtype} ({_fmt_bytes(nbytes)}) but its "
                                     f"member inflates to {_fmt_bytes(info.file_size - head)} (corrupt, or a zip bomb)")
                total += nbytes
                plan.append((info, key, shape, dtype, fortran, head, nbytes))
            cap = _load_cap()
            if cap is not None and total > cap:
                biggest = max(plan, key=lambda r: r[6])
                raise SceneError(f"its arrays take {_fmt_bytes(total)} once inflated (the largest, {biggest[1]!r}, "
                                 f"{_fmt_bytes(biggest[6])}), more than the {_fmt_bytes(cap)} a scene may take "
                                 f"here ({LOAD_MEMORY_FRACTION:.0%} of the memory available)")
            # 2. The data: exactly the declared bytes of each member, no more
            out = {}
            for info, key, shape, dtype, fortran, head, nbytes in plan:
                with zf.open(info) as stream:
                    stream.read(head)
                    buf = stream.read(nbytes)
                if len(buf) != nbytes:
                    raise SceneError(f"array {key!r} is truncated ({len(buf)} of {nbytes} bytes)")
                a = np.frombuffer(buf, dtype=dtype)
                a = a.reshape(shape[::-1]).transpose() if fortran else a.reshape(shape)
                out[key] = np.array(a)            # writeable, owning its memory
            return out
    except SceneError:
        raise
    except (zipfile.BadZipFile, zlib.error, ValueError, EOFError, KeyError, NotImplementedError,
            RuntimeError, UnicodeError, OSError, SyntaxError, tokenize.TokenError, MemoryError,
            OverflowError) as e:
        # OSError also covers a file that vanished; a CRC mismatch is a BadZipFile; it is still one line.
        raise SceneError(f"corrupt or truncated scene file ({type(e).__name__}: {_brief(e)})") from None


def _read_header(data: dict[str, np.ndarray]) -> _Fields:
    """The JSON header: checks presence, encoding, format name and version."""
    if "header" not in data:
        raise SceneError("missing array 'header' (not an STPM scene file)")
    blob = data["header"]
    if blob.dtype != np.uint8 or blob.ndim != 1:
        raise SceneError(f"header must be a (B,) uint8 array of UTF-8 JSON, got {blob.dtype} {blob.shape}")
    try:
        header = json.loads(blob.tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError) as e:
        raise SceneError(f"header is not valid UTF-8 JSON ({e})".splitlines()[0]) from None
    except RecursionError:
        raise SceneError("header JSON is nested too deeply") from None
    h = _Fields(header, "")
    fmt = h.raw("format")
    if fmt != FORMAT_NAME:
        raise SceneError(f"format must be {FORMAT_NAME!r}, got {fmt!r:.60} (not an STPM scene file)")
    version = h.raw("version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise SceneError(f"version must be an integer, got {version!r:.60}")
    if version > SCENE_FORMAT_VERSION:
        raise SceneError(f"version {version} is newer than this STPM reads ({SCENE_FORMAT_VERSION}); "
                         "update STPM")
    if version < 1:
        raise SceneError(f"version {version} is unknown (versions start at 1)")
    return h


def _build_scene(h: _Fields, arr: _Arrays) -> Scene:
    """Build the Scene from a checked header and arrays (version 1)."""
    # Textures (optional)
    textures = []
    tex_list = h.d.get("textures", [])
    if not isinstance(tex_list, list):
        raise SceneError(f"textures must be a list, got {type(tex_list).__name__}")
    for i, d in enumerate(tex_list):
        f = _Fields(d, f"textures[{i}]")
        entry = f.read(_TEXTURE_FIELDS)
        entry["alpha_mode"] = f.enum("alpha_mode", _ALPHA_MODES) if "alpha_mode" in f.d else "STRAIGHT"
        key = f"textures/{i}/pixels"
        if key not in arr.data:
            raise SceneError(f"missing array {key!r} (textures[{i}].pixels)")
        px = arr.data[key]
        _check_texture(f"textures[{i}]", px, entry)
        try:
            textures.append(Texture(pixels=px.copy(), colorspace=entry["colorspace"], name=entry["name"],
                                    half=entry["half"], alpha_mode=entry["alpha_mode"]))
        except ValueError as e:
            raise SceneError(f"textures[{i}]: {e}".splitlines()[0]) from None

    # Materials (node graphs optional)
    materials = []
    for i, d in enumerate(h.list("materials")):
        f = _Fields(d, f"materials[{i}]")
        m = Material(**f.read(_MATERIAL_FIELDS))
        for tint_name in ("transmission_tint", "reflection_tint"):      # absent or null: None
            if f.d.get(tint_name) is not None:
                setattr(m, tint_name, f.vec3(tint_name))
        if f.d.get("constant_fresnel") is not None:                      # absent: Schlick
            m.constant_fresnel = f.bool("constant_fresnel")
        if f.d.get("graph") is not None:
            m.graph = _graph_from_json(f.d["graph"], f"materials[{i}].graph", len(textures))
        materials.append(m)

    # Meshes
    meshes = []
    for i, d in enumerate(h.list("meshes")):
        f, p, a = _Fields(d, f"meshes[{i}]"), f"meshes/{i}", f"meshes[{i}]"
        name = f.str("name")
        has_times, has_normals = f.bool("has_vertex_times"), f.bool("has_normals")
        if has_times:
            V = arr.get(f"{p}/vertices", f"{a}.vertices", kind="f", ndim=3, tail=(3,))
            vt = arr.get(f"{p}/vertex_times", f"{a}.vertex_times", kind="f", ndim=1)
            if V.shape[0] < 1:
                raise SceneError(f"{a}.vertices must have at least one time step, got shape {V.shape}")
        else:
            V = arr.get(f"{p}/vertices", f"{a}.vertices", kind="f", ndim=2, tail=(3,))
            vt = None
        tri = arr.get(f"{p}/triangles", f"{a}.triangles", kind="i", ndim=2, tail=(3,))
        mid = arr.get(f"{p}/material_ids", f"{a}.material_ids", kind="i", ndim=1)
        N = None
        if has_normals:
            # (F, 3, 3), or (K, F, 3, 3) per vertex step of a deforming mesh (format version 4)
            keyed = has_times and np.ndim(arr.data.get(f"{p}/normals")) == 4
            N = arr.get(f"{p}/normals", f"{a}.normals", kind="f", ndim=4 if keyed else 3, tail=(3, 3))
        orco = None
        if d.get("has_orco") is True:
            orco = arr.get(f"{p}/orco", f"{a}.orco", kind="f", ndim=2, tail=(3,))
            if orco.shape[0] != V.shape[-2] or np.abs(orco).max(initial=0.0) > 1e15:
                raise SceneError(f"{a}.orco must have shape ({V.shape[-2]}, 3) and coordinates within 1e15, "
                                 f"got shape {orco.shape}")
        texspace = None
        if d.get("has_texspace") is True:
            texspace = arr.get(f"{p}/texspace", f"{a}.texspace", kind="f", ndim=2, tail=(3,))
            if texspace.shape != (2, 3) or np.abs(texspace).max(initial=0.0) > 1e15:
                raise SceneError(f"{a}.texspace must have shape (2, 3) (location, size) and values within 1e15, "
                                 f"got shape {texspace.shape}")
        if np.abs(V).max(initial=0.0) > 1e15:
            raise SceneError(f"{a}.vertices has coordinates beyond 1e15")
        # Range-check integer arrays before narrowing them to int32
        nv = V.shape[-2]
        if tri.size and (tri.min() < 0 or tri.max() >= nv):
            raise SceneError(f"{a}.triangles index out of range [0, {nv})")
        if mid.size and (mid.min() < 0 or mid.max() >= len(materials)):
            raise SceneError(f"{a}.material_ids index out of range [0, {len(materials)})")
        uv_layers, uv_render = _read_uv_layers(f, arr, p, a, tri.shape[0])
        tangents = _read_tangents(f, arr, p, a, tri.shape[0], uv_layers)
        color_layers, color_render = _read_colors(f, arr, p, a, tri.shape[0])
        meshes.append(Mesh(vertices=V.astype(np.float32), triangles=tri.astype(np.int32),
                           material_ids=mid.astype(np.int32),
                           vertex_times=None if vt is None else vt.astype(np.float64),
                           normals=None if N is None else N.astype(np.float32), name=name,
                           uv_layers=uv_layers, uv_render=uv_render, tangents=tangents,
                           color_layers=color_layers, color_render=color_render,
                           orco=None if orco is None else orco.astype(np.float32),
                           texspace=None if texspace is None else texspace.astype(np.float64)))

    # Instances
    instances = []
    for i, d in enumerate(h.list("instances")):
        f = _Fields(d, f"instances[{i}]")
        mesh = f.int("mesh", 0, max(len(meshes) - 1, 0))
        if not meshes:
            raise SceneError(f"instances[{i}].mesh refers to a mesh but the scene has none")
        # Blender's defaults where a file written before these settings has none
        terminator = {key: f.num(key) if key in d else default for key, default in
                      (("shadow_terminator_geometry_offset", 0.1), ("shadow_terminator_shading_offset", 0.0))}
        instances.append(Instance(mesh=mesh, name=f.str("name"),
                                  transform=arr.transform(f"instances/{i}/transform", f"instances[{i}].transform"),
                                  **terminator))

    # Camera, lights, world
    fc = h.sub("camera")
    lens = fc.read(_LENS_FIELDS) if "aperture_radius" in fc.d else {}      # optional (version 5)
    cam = Camera(**fc.read(_CAMERA_FIELDS), **lens,
                 transform=arr.transform("camera/transform", "camera.transform"))
    lights = []
    for i, d in enumerate(h.list("lights")):
        f = _Fields(d, f"lights[{i}]")
        extra = {"photon_weight": f.num("photon_weight")} if "photon_weight" in f.d else {}
        lights.append(Light(**f.read(_LIGHT_FIELDS), **extra,
                            transform=arr.transform(f"lights/{i}/transform", f"lights[{i}].transform")))
    portals = []
    for i, d in enumerate(h.list("portals") if "portals" in h.d else ()):   # optional (light portals)
        f = _Fields(d, f"portals[{i}]")
        portals.append(Light(**f.read(_LIGHT_FIELDS),
                             transform=arr.transform(f"portals/{i}/transform", f"portals[{i}].transform")))
    world = _world_from_json(h.sub("world"), arr)

    # Shutter
    s = h.sub("shutter")
    s_open, s_close = s.num("open"), s.num("close")
    curve = arr.get("shutter/curve", "shutter.curve", kind="f", ndim=1) if s.bool("has_curve") else None
    try:
        shutter = Shutter(open=s_open, close=s_close,
                          curve=None if curve is None else curve.astype(np.float64))
    except SceneError as e:
        raise SceneError(str(e) if str(e).startswith("shutter") else f"shutter: {e}") from None

    # Scene-wide fields
    res = h.list("resolution")
    if len(res) != 2 or any(isinstance(x, bool) or not isinstance(x, int) or not 1 <= x <= 65536 for x in res):
        raise SceneError(f"resolution must be two integers in [1, 65536], got {res!r:.60}")
    metadata = check_metadata(h.raw("metadata"))   # the keys STPM reads, typed (stpm_core.schema.METADATA)

    scene = Scene(meshes=meshes, instances=instances, camera=cam, lights=lights,
                  materials=materials, world=world, shutter=shutter,
                  resolution=(res[0], res[1]), frame=h.num("frame"), metadata=metadata,
                  textures=textures, portals=portals)
    validate_scene(scene)
    return scene


def _read_corner_layers(f: _Fields, arr: _Arrays, p: str, a: str, n_tri: int, key: str, sub: str,
                        width: int, allowed=None) -> dict:
    """A mesh's per-corner layers listed under header key ``key`` ({name: (F, 3, width) float32},
    arrays ``p/<sub>/<j>``); optional ({} when the key is absent)."""
    if key not in f.d:
        return {}
    names = f.list(key)
    if not all(isinstance(n, str) for n in names) or len(set(names)) != len(names):
        raise SceneError(f"{a}.{key} must be a list of distinct strings, got {names!r:.80}")
    out = {}
    for j, name in enumerate(names):
        if allowed is not None and name not in allowed:
            raise SceneError(f"{a}.{key}[{name!r}] names no UV map of the mesh")
        v = arr.get(f"{p}/{sub}/{j}", f"{a}.{key}[{name!r}]", kind="f", ndim=3, tail=(3, width))
        if v.shape[0] != n_tri:
            raise SceneError(f"{a}.{key}[{name!r}] must have shape ({n_tri}, 3, {width}), got {v.shape}")
        if np.abs(v).max(initial=0.0) > 1e15:
            raise SceneError(f"{a}.{key}[{name!r}] has values beyond 1e15")
        out[name] = v.astype(np.float32)
    return out


def _read_tangents(f: _Fields, arr: _Arrays, p: str, a: str, n_tri: int, uv_layers: dict) -> dict:
    """A mesh's tangents ({UV map name: (F, 3, 4) float32}); optional."""
    return _read_corner_layers(f, arr, p, a, n_tri, "tangents", "tangents", 4, allowed=uv_layers)


def _read_uv_layers(f: _Fields, arr: _Arrays, p: str, a: str, n_tri: int) -> tuple:
    """A mesh's UV maps ({name: (F, 3, 2) float32}, render-active name or None); optional."""
    layers = _read_corner_layers(f, arr, p, a, n_tri, "uv_layers", "uv", 2)
    render = f.d.get("uv_render")
    if render is not None and (not isinstance(render, str) or render not in layers):
        raise SceneError(f"{a}.uv_render must be null or one of {list(layers)!r:.80}, got {render!r:.60}")
    return layers, render


def _read_colors(f: _Fields, arr: _Arrays, p: str, a: str, n_tri: int) -> tuple:
    """A mesh's colour attributes ({name: (F, 3, 4) float32}, render-active name or None); optional."""
    layers = _read_corner_layers(f, arr, p, a, n_tri, "color_layers", "colors", 4)
    render = f.d.get("color_render")
    if render is not None and (not isinstance(render, str) or render not in layers):
        raise SceneError(f"{a}.color_render must be null or one of {list(layers)!r:.80}, got {render!r:.60}")
    return layers, render


def load_scene_with_settings(path) -> tuple[Scene, RenderSettings | None]:
    """Load and validate a scene file -> (Scene, RenderSettings or None if the file has none).

    Raises :class:`SceneError` (one line, prefixed with the file name) on the
    first problem: not a zip, truncated, unknown format or version, missing
    key or array, wrong shape or dtype, NaN/inf, index out of range,
    impossible value (negative power, albedo > 1 ...), bad settings.
    """
    path = Path(path)
    try:
        data = _read_container(path)
        h = _read_header(data)
        scene = _build_scene(h, _Arrays(data))
        settings = None
        if "settings" in h.d and h.d["settings"] is not None:
            sd = h.d["settings"]
            if not isinstance(sd, dict):
                raise SceneError(f"settings must be a JSON object, got {type(sd).__name__}")
            try:
                settings = RenderSettings.from_dict(sd)
            except SettingsError as e:
                raise SceneError(f"settings: {e}") from None
            except (TypeError, ValueError, OverflowError) as e:  # a value the dataclass cannot take
                raise SceneError(f"settings: {e}".splitlines()[0]) from None
    except SceneError as e:
        raise SceneError(_one_line(f"{path.name}: {e}")) from None
    return scene, settings


# An error line quotes the file's own text (names, keys, values): at most this many characters
MAX_ERROR_LINE = 400


def _one_line(text: str) -> str:
    """``text``'s first line, cut to :data:`MAX_ERROR_LINE` characters (a name or value from the
    file can be megabytes long)."""
    line = (text.splitlines() or [""])[0]
    return line if len(line) <= MAX_ERROR_LINE else line[:MAX_ERROR_LINE - 3] + "..."


def load_scene(path) -> Scene:
    """Load and validate a scene file (see :func:`load_scene_with_settings`)."""
    return load_scene_with_settings(path)[0]
