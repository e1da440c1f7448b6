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
  normals / vertex times, the times and matrices of every motion transform and
  the shutter curve.  Array names are listed in ``docs/scene-format.md``.

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
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .errors import SceneError, SettingsError
from .motion import MotionTransform
from .scene import (SCENE_FORMAT_VERSION, Camera, Instance, Light, Material, Mesh, Scene,
                    World, validate_scene)
from .settings import RenderSettings
from .shutter import Shutter

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
        meshes.append({"name": str(m.name), "has_vertex_times": m.vertex_times is not None,
                       "has_normals": m.normals is not None})

    # Instances, camera and lights: motion transforms as arrays
    instances = []
    for i, inst in enumerate(scene.instances):
        _put_transform(arrays, f"instances/{i}/transform", inst.transform)
        instances.append({"name": str(inst.name), "mesh": int(inst.mesh)})
    _put_transform(arrays, "camera/transform", scene.camera.transform)
    lights = []
    for i, light in enumerate(scene.lights):
        _put_transform(arrays, f"lights/{i}/transform", light.transform)
        lights.append(_fields_to_json(light, _LIGHT_FIELDS))

    # Shutter curve (optional)
    if scene.shutter.curve is not None:
        arrays["shutter/curve"] = np.asarray(scene.shutter.curve, dtype=np.float64)

    try:
        metadata = json.loads(json.dumps(scene.metadata, allow_nan=False))
    except (TypeError, ValueError) as e:
        raise SceneError(f"metadata must be JSON-serialisable: {e}") from None
    header = {
        "format": FORMAT_NAME,
        "version": SCENE_FORMAT_VERSION,
        "frame": float(scene.frame),
        "resolution": [int(scene.resolution[0]), int(scene.resolution[1])],
        "shutter": {"open": float(scene.shutter.open), "close": float(scene.shutter.close),
                    "has_curve": scene.shutter.curve is not None},
        "camera": _fields_to_json(scene.camera, _CAMERA_FIELDS),
        "world": _fields_to_json(scene.world, _WORLD_FIELDS),
        "materials": [_fields_to_json(m, _MATERIAL_FIELDS) for m in scene.materials],
        "lights": lights,
        "meshes": meshes,
        "instances": instances,
        "metadata": metadata,
    }
    if settings is not None:
        header["settings"] = settings.validate().to_dict()
    return header, arrays


def save_scene(scene: Scene, path, settings: RenderSettings | None = None) -> Path:
    """Write ``scene`` (and optionally its render settings) to one file at ``path``.

    The scene is validated first (a malformed scene is never written).  The
    file is written to a temporary name and renamed, so a crash never leaves a
    truncated scene behind.  Returns the path written (numpy would append
    ``.npz`` to a bare name; we do not: the name is used as given).
    """
    header, arrays = scene_to_arrays(scene, settings)
    blob = np.frombuffer(json.dumps(header, allow_nan=False).encode("utf-8"), dtype=np.uint8)
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "wb") as f:
        np.savez_compressed(f, header=blob, **arrays)
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
            raise SceneError(f"{self.name(key)} must be a number, got {v!r}")
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
            raise SceneError(f"{self.name(key)} must be an integer, got {v!r}")
        if not lo <= v <= hi:
            raise SceneError(f"{self.name(key)} must be in [{lo}, {hi}], got {v}")
        return v

    def bool(self, key: str) -> bool:
        v = self.raw(key)
        if not isinstance(v, bool):
            raise SceneError(f"{self.name(key)} must be true or false, got {v!r}")
        return v

    def str(self, key: str) -> str:
        v = self.raw(key)
        if not isinstance(v, str):
            raise SceneError(f"{self.name(key)} must be a string, got {v!r}")
        return v

    def enum(self, key: str, allowed: tuple) -> str:
        v = self.raw(key)
        if v not in allowed:
            raise SceneError(f"{self.name(key)} must be one of {', '.join(allowed)}, got {v!r}")
        return v

    def vec3(self, key: str) -> np.ndarray:
        v = self.raw(key)
        if (not isinstance(v, list) or len(v) != 3
                or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in v)):
            raise SceneError(f"{self.name(key)} must be a list of 3 numbers, got {v!r}")
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


def _read_container(path: Path) -> dict[str, np.ndarray]:
    """All arrays of the .npz at ``path``, read eagerly; SceneError if it is not one."""
    if not path.exists():
        raise SceneError(f"scene file not found: {path}")
    if path.is_dir():
        raise SceneError(f"scene file is a directory: {path}")
    if not zipfile.is_zipfile(path):
        raise SceneError("not an STPM scene file (not a zip/npz archive; truncated or another format)")
    try:
        with np.load(path, allow_pickle=False) as npz:
            return {k: np.array(npz[k]) for k in npz.files}
    except (zipfile.BadZipFile, zlib.error, ValueError, EOFError, KeyError,
            NotImplementedError, RuntimeError, UnicodeError, OSError) as e:
        # OSError also covers a file that vanished; it is still one line.
        raise SceneError(f"corrupt or truncated scene file ({type(e).__name__}: {e})".splitlines()[0]) from None


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
        raise SceneError(f"format must be {FORMAT_NAME!r}, got {fmt!r} (not an STPM scene file)")
    version = h.raw("version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise SceneError(f"version must be an integer, got {version!r}")
    if version > SCENE_FORMAT_VERSION:
        raise SceneError(f"version {version} is newer than this STPM reads ({SCENE_FORMAT_VERSION}); "
                         "update STPM")
    if version < 1:
        raise SceneError(f"version {version} is unknown (versions start at 1)")
    return h


def _build_scene(h: _Fields, arr: _Arrays) -> Scene:
    """Build the Scene from a checked header and arrays (version 1)."""
    # Materials
    materials = []
    for i, d in enumerate(h.list("materials")):
        f = _Fields(d, f"materials[{i}]")
        materials.append(Material(**f.read(_MATERIAL_FIELDS)))

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
        N = arr.get(f"{p}/normals", f"{a}.normals", kind="f", ndim=3, tail=(3, 3)) if has_normals else None
        if np.abs(V).max(initial=0.0) > 1e15:
            raise SceneError(f"{a}.vertices has coordinates beyond 1e15")
        # Range-check integer arrays before narrowing them to int32
        nv = V.shape[-2]
        if tri.size and (tri.min() < 0 or tri.max() >= nv):
            raise SceneError(f"{a}.triangles index out of range [0, {nv})")
        if mid.size and (mid.min() < 0 or mid.max() >= len(materials)):
            raise SceneError(f"{a}.material_ids index out of range [0, {len(materials)})")
        meshes.append(Mesh(vertices=V.astype(np.float32), triangles=tri.astype(np.int32),
                           material_ids=mid.astype(np.int32),
                           vertex_times=None if vt is None else vt.astype(np.float64),
                           normals=None if N is None else N.astype(np.float32), name=name))

    # Instances
    instances = []
    for i, d in enumerate(h.list("instances")):
        f = _Fields(d, f"instances[{i}]")
        mesh = f.int("mesh", 0, max(len(meshes) - 1, 0))
        if not meshes:
            raise SceneError(f"instances[{i}].mesh refers to a mesh but the scene has none")
        instances.append(Instance(mesh=mesh, name=f.str("name"),
                                  transform=arr.transform(f"instances/{i}/transform", f"instances[{i}].transform")))

    # Camera, lights, world
    cam = Camera(**h.sub("camera").read(_CAMERA_FIELDS),
                 transform=arr.transform("camera/transform", "camera.transform"))
    lights = []
    for i, d in enumerate(h.list("lights")):
        f = _Fields(d, f"lights[{i}]")
        lights.append(Light(**f.read(_LIGHT_FIELDS),
                            transform=arr.transform(f"lights/{i}/transform", f"lights[{i}].transform")))
    world = World(**h.sub("world").read(_WORLD_FIELDS))

    # Shutter
    s = h.sub("shutter")
    s_open, s_close = s.num("open"), s.num("close")
    curve = arr.get("shutter/curve", "shutter.curve", kind="f", ndim=1) if s.bool("has_curve") else None
    try:
        shutter = Shutter(open=s_open, close=s_close,
                          curve=None if curve is None else curve.astype(np.float64))
    except SceneError as e:
        raise SceneError(f"shutter: {e}") from None

    # Scene-wide fields
    res = h.list("resolution")
    if len(res) != 2 or any(isinstance(x, bool) or not isinstance(x, int) or not 1 <= x <= 65536 for x in res):
        raise SceneError(f"resolution must be two integers in [1, 65536], got {res!r}")
    metadata = h.raw("metadata")
    if not isinstance(metadata, dict):
        raise SceneError(f"metadata must be a JSON object, got {type(metadata).__name__}")

    scene = Scene(meshes=meshes, instances=instances, camera=cam, lights=lights,
                  materials=materials, world=world, shutter=shutter,
                  resolution=(res[0], res[1]), frame=h.num("frame"), metadata=metadata)
    validate_scene(scene)
    return scene


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
        raise SceneError(f"{path.name}: {e}") from None
    return scene, settings


def load_scene(path) -> Scene:
    """Load and validate a scene file (see :func:`load_scene_with_settings`)."""
    return load_scene_with_settings(path)[0]
