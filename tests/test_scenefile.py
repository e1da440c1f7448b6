"""The scene file: bit-exact round trip, one clear line per malformed case, fuzzing.

Every malformed file must raise SceneError whose single-line message names the
bad field; random corruptions of a valid file either load a valid scene or
raise SceneError, never anything else.
"""
from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings as hsettings, strategies as st

from stpm_core.errors import SceneError
from stpm_core.motion import MotionTransform
from stpm_core.scene import (SCENE_FORMAT_VERSION, Camera, Instance, Light, Material, Mesh, Scene,
                             World, validate_scene)
from stpm_core.scenefile import (FORMAT_NAME, load_scene, load_scene_with_settings, save_scene,
                                 scene_to_arrays)
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter


# ----------------------------------------------------------------------------
# A scene using every feature of the format
# ----------------------------------------------------------------------------
def _rot_z(angle: float, t=(0.0, 0.0, 0.0), s: float = 1.0) -> np.ndarray:
    c, si = np.cos(angle), np.sin(angle)
    M = np.eye(4)
    M[:3, :3] = s * np.array([[c, -si, 0], [si, c, 0], [0, 0, 1]])
    M[:3, 3] = t
    return M


def rich_scene() -> Scene:
    rng = np.random.default_rng(7)
    V = rng.normal(size=(5, 3)).astype(np.float32)
    tri = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 4]], np.int32)
    N = rng.normal(size=(3, 3, 3)).astype(np.float32)
    rigid = Mesh(vertices=V, triangles=tri, material_ids=np.array([0, 1, 2], np.int32), normals=N, name="rigid")
    deform = Mesh(vertices=rng.normal(size=(3, 5, 3)).astype(np.float32), triangles=tri.copy(),
                  material_ids=np.array([3, 0, 1], np.int32),
                  vertex_times=np.array([0.0, 0.4, 1.0]), name="deforming")
    moving = MotionTransform(times=np.array([0.0, 0.3, 1.0]),
                             matrices=np.stack([_rot_z(0.1, (0.1, 0, 0)), _rot_z(0.7, (0.2, 0.1, 0), 1.5),
                                                _rot_z(1.3, (1 / 3, 0.2, 0.5), 2.0)]))
    materials = [Material.diffuse((0.1, 0.2, 0.3), name="d"), Material.mirror(roughness=0.25, name="m"),
                 Material.glass(ior=1.45, name="g"),
                 Material(base_color=np.array([0.5, 0.25, 1 / 3]), specular=0.5, roughness=0.1,
                          emission=np.array([1.5, 0.0, 2 / 7]), name="coat")]
    lights = [
        Light(type="POINT", color=np.array([1.0, 0.9, 0.8]), power=123.456, radius=0.05, name="pt",
              transform=MotionTransform(times=np.array([0.0, 1.0]),
                                        matrices=np.stack([_rot_z(0, (0, 0, 3)), _rot_z(0, (1, 0, 3))]))),
        Light(type="SPOT", power=50.0, spot_size=0.7, spot_blend=0.3, use_soft_falloff=False, name="spot",
              transform=MotionTransform.static(_rot_z(0.2, (0, 1, 2)))),
        Light(type="AREA", shape="ELLIPSE", size=0.5, size_y=0.25, power=10.0, name="area"),
        Light(type="SUN", power=3.0, angle=0.01, name="sun"),
    ]
    camera = Camera(type="ORTHO", lens=35.0, sensor_width=32.0, sensor_height=18.0, sensor_fit="VERTICAL",
                    ortho_scale=4.5, shift_x=0.1, shift_y=-0.05, clip_start=0.01, clip_end=250.0,
                    transform=MotionTransform(times=np.array([0.0, 1.0]),
                                              matrices=np.stack([_rot_z(0, (0, -5, 1)), _rot_z(0.05, (0, -4.9, 1))])))
    return Scene(meshes=[rigid, deform],
                 instances=[Instance(mesh=0, name="a"), Instance(mesh=1, transform=moving, name="b"),
                            Instance(mesh=0, transform=MotionTransform.static(_rot_z(0.3, (2, 0, 0))), name="c")],
                 camera=camera, lights=lights, materials=materials,
                 world=World(color=np.array([0.05, 0.1, 0.2]), strength=0.7),
                 shutter=Shutter(open=9.75, close=10.25, curve=np.array([0.0, 1.0, 1.0, 0.5])),
                 resolution=(37, 23), frame=10.0, metadata={"source": "test", "n": 3, "nested": {"x": [1, 2]}})


def _assert_same(a, b, path="scene"):
    """Recursive bit-exact comparison of two scene objects."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for f in dataclasses.fields(a):
            _assert_same(getattr(a, f.name), getattr(b, f.name), f"{path}.{f.name}")
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        assert a.shape == b.shape, path
        assert a.tobytes() == b.astype(a.dtype).tobytes(), path
        assert np.array_equal(a, b), path
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            _assert_same(a[k], b[k], f"{path}[{k!r}]")
    elif isinstance(a, float):
        assert float(b) == a and np.float64(b).tobytes() == np.float64(a).tobytes(), path
    else:
        assert a == b, path


def test_round_trip_is_bit_exact(tmp_path):
    scene = rich_scene()
    settings = RenderSettings(method="ACCUMULATION", estimator="KD4D", samples=3, time_scale=1.25, seed=99)
    path = save_scene(scene, tmp_path / "s.stpm", settings=settings)
    loaded, s2 = load_scene_with_settings(path)
    _assert_same(scene, loaded)
    assert s2 == settings
    # Mesh arrays keep their canonical dtypes
    assert loaded.meshes[0].vertices.dtype == np.float32 and loaded.meshes[0].triangles.dtype == np.int32
    # Moving transforms interpolate identically after the round trip
    u = np.linspace(0, 1, 11)
    assert np.array_equal(scene.instances[1].transform.at(u), loaded.instances[1].transform.at(u))
    assert np.array_equal(scene.shutter.sample(u), loaded.shutter.sample(u))
    assert loaded.has_motion and loaded.meshes[1].is_deforming


def test_settings_are_optional(tmp_path):
    path = save_scene(rich_scene(), tmp_path / "s.npz")
    scene, settings = load_scene_with_settings(path)
    assert settings is None
    assert isinstance(load_scene(path), Scene)


def test_invalid_scene_is_never_written(tmp_path):
    scene = rich_scene()
    scene.lights[0].power = -1.0
    with pytest.raises(SceneError, match="power"):
        save_scene(scene, tmp_path / "bad.stpm")
    assert not (tmp_path / "bad.stpm").exists()


# ----------------------------------------------------------------------------
# Malformed files: one per case, the message names the field
# ----------------------------------------------------------------------------
def _write_raw(path, header: dict, arrays: dict) -> None:
    blob = np.frombuffer(json.dumps(header).encode(), np.uint8)
    with open(path, "wb") as f:
        np.savez_compressed(f, header=blob, **arrays)


def _parts():
    header, arrays = scene_to_arrays(rich_scene(), RenderSettings())
    return json.loads(json.dumps(header)), dict(arrays)


def _load_error(path) -> str:
    with pytest.raises(SceneError) as info:
        load_scene(path)
    msg = str(info.value)
    assert "\n" not in msg and msg
    return msg


def _mut_shape(h, a):
    a["meshes/0/triangles"] = np.zeros((3, 4), np.int32)


def _mut_nan_vertices(h, a):
    a["meshes/0/vertices"] = a["meshes/0/vertices"].copy()
    a["meshes/0/vertices"][1, 2] = np.nan


def _mut_inf_matrix(h, a):
    a["instances/1/transform/matrices"] = a["instances/1/transform/matrices"].copy()
    a["instances/1/transform/matrices"][0, 0, 3] = np.inf


def _mut_tri_range(h, a):
    a["meshes/0/triangles"] = a["meshes/0/triangles"].copy()
    a["meshes/0/triangles"][2, 1] = 5


def _mut_mat_range(h, a):
    a["meshes/1/material_ids"] = np.array([0, 4, 1], np.int32)


def _mut_version(h, a):
    h["version"] = SCENE_FORMAT_VERSION + 1


def _mut_format(h, a):
    h["format"] = "not-stpm"


def _mut_power(h, a):
    h["lights"][2]["power"] = -5.0


def _mut_missing_key(h, a):
    del h["lights"][0]["power"]


def _mut_missing_array(h, a):
    del a["camera/transform/matrices"]


def _mut_json_nan(h, a):
    h["camera"]["lens"] = float("nan")


def _mut_albedo(h, a):
    h["materials"][0]["base_color"] = [0.5, 1.5, 0.5]


def _mut_instance_mesh(h, a):
    h["instances"][1]["mesh"] = 7


def _mut_enum(h, a):
    h["lights"][1]["type"] = "LASER"


def _mut_time_order(h, a):
    a["meshes/1/vertex_times"] = np.array([0.0, 0.5, 0.5])


def _mut_settings(h, a):
    h["settings"]["samples"] = 0


def _mut_dtype(h, a):
    a["meshes/0/triangles"] = a["meshes/0/triangles"].astype(np.float32)


def _mut_vec(h, a):
    h["world"]["color"] = [0.1, 0.2]


def _mut_curve(h, a):
    a["shutter/curve"] = np.array([1.0, -1.0, 1.0])


MALFORMED = [
    ("wrong shape", _mut_shape, "meshes[0].triangles"),
    ("NaN in vertices", _mut_nan_vertices, "meshes[0].vertices"),
    ("inf in a matrix", _mut_inf_matrix, "instances[1].transform.matrices"),
    ("triangle index out of range", _mut_tri_range, "meshes[0]"),
    ("material index out of range", _mut_mat_range, "material_ids"),
    ("unknown version", _mut_version, "version"),
    ("unknown format", _mut_format, "format"),
    ("negative power", _mut_power, "lights[2]"),
    ("missing key", _mut_missing_key, "lights[0].power"),
    ("missing array", _mut_missing_array, "camera/transform/matrices"),
    ("NaN in header", _mut_json_nan, "camera.lens"),
    ("albedo above 1", _mut_albedo, "materials[0]"),
    ("instance mesh out of range", _mut_instance_mesh, "instances[1].mesh"),
    ("unknown enum", _mut_enum, "lights[1].type"),
    ("vertex times not increasing", _mut_time_order, "vertex_times"),
    ("bad settings", _mut_settings, "samples"),
    ("float triangles", _mut_dtype, "meshes[0].triangles"),
    ("short colour", _mut_vec, "world.color"),
    ("negative shutter curve", _mut_curve, "shutter"),
]


@pytest.mark.parametrize("label,mutate,field", MALFORMED, ids=[m[0] for m in MALFORMED])
def test_malformed_file_names_the_field(tmp_path, label, mutate, field):
    header, arrays = _parts()
    mutate(header, arrays)
    path = tmp_path / "bad.stpm"
    _write_raw(path, header, arrays)
    msg = _load_error(path)
    assert field in msg, msg
    assert msg.startswith("bad.stpm: ")


def test_negative_power_message(tmp_path):
    header, arrays = _parts()
    _mut_power(header, arrays)
    _write_raw(tmp_path / "p.stpm", header, arrays)
    msg = _load_error(tmp_path / "p.stpm")
    assert "power" in msg and "-5.0" in msg


def test_not_a_zip_file(tmp_path):
    path = tmp_path / "text.stpm"
    path.write_text("hello, I am not a scene\n")
    assert "not a zip" in _load_error(path)


def test_truncated_file(tmp_path):
    good = save_scene(rich_scene(), tmp_path / "good.stpm")
    data = good.read_bytes()
    for cut in (len(data) // 3, len(data) - 30):
        path = tmp_path / f"cut{cut}.stpm"
        path.write_bytes(data[:cut])
        msg = _load_error(path)
        assert "truncated" in msg or "not a zip" in msg


def test_missing_file(tmp_path):
    assert "not found" in _load_error(tmp_path / "nope.stpm")


def test_header_edge_cases(tmp_path):
    """Integers too large for a float, deeply nested JSON, an empty deforming mesh."""
    header, arrays = _parts()
    header["camera"]["lens"] = 10**400
    _write_raw(tmp_path / "big.stpm", header, arrays)
    assert "camera.lens" in _load_error(tmp_path / "big.stpm")
    header, arrays = _parts()
    header["world"]["color"] = [1, 10**400, 0]
    _write_raw(tmp_path / "bigv.stpm", header, arrays)
    assert "world.color" in _load_error(tmp_path / "bigv.stpm")
    path = tmp_path / "deep.stpm"
    with open(path, "wb") as f:
        np.savez_compressed(f, header=np.frombuffer(b"[" * 100_000 + b"]" * 100_000, np.uint8))
    assert "header" in _load_error(path)
    header, arrays = _parts()
    arrays["meshes/1/vertices"] = np.zeros((0, 5, 3), np.float32)
    arrays["meshes/1/vertex_times"] = np.zeros(0)
    _write_raw(tmp_path / "k0.stpm", header, arrays)
    assert "meshes[1].vertices" in _load_error(tmp_path / "k0.stpm")
    header, arrays = _parts()
    header["settings"]["temporal_alpha"] = 10**400
    _write_raw(tmp_path / "s.stpm", header, arrays)
    assert "settings" in _load_error(tmp_path / "s.stpm")


def test_header_not_json(tmp_path):
    path = tmp_path / "h.stpm"
    with open(path, "wb") as f:
        np.savez_compressed(f, header=np.frombuffer(b"{not json", np.uint8))
    assert "header" in _load_error(path)


# ----------------------------------------------------------------------------
# Property-based: random corruptions load a valid scene or raise SceneError
# ----------------------------------------------------------------------------
@pytest.fixture(scope="module")
def valid_bytes(tmp_path_factory):
    path = tmp_path_factory.mktemp("fuzz") / "valid.stpm"
    save_scene(rich_scene(), path, settings=RenderSettings())
    return path.read_bytes()


def _load_or_scene_error(path) -> None:
    try:
        scene, _ = load_scene_with_settings(path)
    except SceneError as e:
        assert "\n" not in str(e)
        return
    validate_scene(scene)  # whatever loads is a valid scene


FUZZ = hsettings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])


@FUZZ
@given(data=st.data())
def test_fuzz_bytes(tmp_path, valid_bytes, data):
    """Flip, overwrite or cut bytes anywhere in the file."""
    raw = bytearray(valid_bytes)
    edits = data.draw(st.lists(st.tuples(st.integers(0, len(raw) - 1), st.integers(0, 255)), min_size=1, max_size=8))
    for pos, val in edits:
        raw[pos] = val
    cut = data.draw(st.one_of(st.none(), st.integers(0, len(raw))))
    if cut is not None:
        raw = raw[:cut]
    path = tmp_path / "fuzz.stpm"
    path.write_bytes(bytes(raw))
    _load_or_scene_error(path)


def _json_paths(obj, prefix=()):
    """Every (path tuple) to a value inside a JSON object."""
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _json_paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _json_paths(v, prefix + (i,))


JSON_VALUES = st.recursive(
    st.one_of(st.none(), st.booleans(), st.integers(-10**20, 10**20), st.sampled_from([10**400, -10**400]), st.floats(allow_nan=True, allow_infinity=True),
              st.text(max_size=8), st.sampled_from(["POINT", "AREA", "PERSP", "DISK", "PHOTON"])),
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
    max_leaves=6)


@FUZZ
@given(data=st.data())
def test_fuzz_header_values(tmp_path, data):
    """Replace or delete any value anywhere in the JSON header."""
    header, arrays = _parts()
    paths = [p for p in _json_paths(header) if p]
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(paths))
        parent = header
        try:
            for k in path[:-1]:
                parent = parent[k]
            if data.draw(st.booleans()) and isinstance(parent, dict):
                del parent[path[-1]]
            else:
                parent[path[-1]] = data.draw(JSON_VALUES)
        except (KeyError, IndexError, TypeError):
            continue  # an earlier edit removed this path
    f = tmp_path / "fuzz.stpm"
    _write_raw(f, header, arrays)
    _load_or_scene_error(f)


ARRAYS = st.one_of(
    st.builds(lambda shape, v, dt: np.full(shape, v, dtype=dt),
              st.lists(st.integers(0, 5), min_size=0, max_size=4).map(tuple),
              st.sampled_from([0, 1, -1, 7, 1e30, np.nan, np.inf, 0.5]),
              st.sampled_from([np.float32, np.float64, np.int32, np.int64, np.uint8, np.int8, np.bool_])),
    st.just(np.array(["text"])),
    st.just(np.zeros(3, dtype=np.complex64)),
)


@pytest.mark.filterwarnings("ignore:invalid value encountered in cast")
@FUZZ
@given(data=st.data())
def test_fuzz_arrays(tmp_path, data):
    """Replace, delete or add named arrays with arbitrary shapes and dtypes."""
    header, arrays = _parts()
    names = sorted(arrays)
    for _ in range(data.draw(st.integers(1, 3))):
        name = data.draw(st.sampled_from(names + ["header", "extra"]))
        if data.draw(st.booleans()) and name in arrays:
            del arrays[name]
        else:
            arrays[name] = data.draw(ARRAYS)
    f = tmp_path / "fuzz.stpm"
    h = arrays.pop("header", None)
    if h is None:
        _write_raw(f, header, arrays)
    else:
        with open(f, "wb") as fh:
            np.savez_compressed(fh, header=h, **arrays)
    _load_or_scene_error(f)


def test_format_constants():
    header, _ = _parts()
    assert header["format"] == FORMAT_NAME == "stpm-scene"
    assert header["version"] == SCENE_FORMAT_VERSION


def test_scene_bounds_follow_the_vertices_and_motion():
    """Scene.bounds: all vertices (every deformation step) through the motion over the shutter;
    Mesh.vertex_bounds is cached per vertex array and recomputed when the array is replaced."""
    from scenes import box_mesh, make_scene, moving, persp_camera
    sc = make_scene([box_mesh((0, 0, 0), (1, 2, 3))], [Material.diffuse((0.5, 0.5, 0.5))],
                    persp_camera((0, -5, 1), (0, 0, 0)))
    mesh = sc.meshes[0]
    v = np.asarray(mesh.vertices, np.float64).reshape(-1, 3)
    lo, hi = sc.bounds()
    np.testing.assert_array_equal(lo, v.min(0))
    np.testing.assert_array_equal(hi, v.max(0))
    assert mesh.vertex_bounds()[0] is mesh.vertex_bounds()[0]          # cached
    mesh.vertices = np.asarray(mesh.vertices) * 2.0                    # a new array: recomputed
    np.testing.assert_array_equal(sc.bounds()[1], 2 * v.max(0))
    # A moving instance: (conservatively) the union of its bounds over the shutter
    sc.instances[0].transform = moving((0, 0, 0), (5, 0, 0))
    lo, hi = sc.bounds()
    assert 2 * v.min(0)[0] - 0.5 < lo[0] <= 2 * v.min(0)[0]
    assert 2 * v.max(0)[0] + 5 <= hi[0] < 2 * v.max(0)[0] + 5.5
