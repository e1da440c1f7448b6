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
from stpm_core.nodes import Link, Node, ShaderGraph, compile_graph
from stpm_core.scene import (SCENE_FORMAT_VERSION, Camera, Instance, Light, Material, Mesh, Scene,
                             World, validate_scene)
from stpm_core.scenefile import (FORMAT_NAME, load_scene, load_scene_with_settings, save_scene,
                                 scene_to_arrays)
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter
from stpm_core.textures import Texture

from loader_fuzz import _json_paths  # every path tuple to a value inside a JSON object


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
    rigid = Mesh(vertices=V, triangles=tri, material_ids=np.array([0, 1, 2], np.int32), normals=N, name="rigid",
                 uv_layers={"UVMap": rng.random((3, 3, 2)).astype(np.float32),
                            "Second/map": rng.normal(size=(3, 3, 2)).astype(np.float32)},
                 uv_render="Second/map",
                 tangents={"UVMap": np.concatenate([rng.normal(size=(3, 3, 3)), np.sign(rng.normal(size=(3, 3, 1)))],
                                                   axis=2).astype(np.float32)},
                 color_layers={"Col": rng.random((3, 3, 4)).astype(np.float32),
                               "Wear": rng.random((3, 3, 4)).astype(np.float32)},
                 color_render="Wear")
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
    materials[0].graph = node_graph()
    textures = [Texture(pixels=rng.integers(0, 256, (2, 3, 3)).astype(np.uint8), colorspace="sRGB", name="rgb8"),
                Texture(pixels=rng.normal(size=(2, 2, 1)).astype(np.float16), colorspace="Linear", name="half"),
                Texture(pixels=rng.normal(size=(1, 2, 4)).astype(np.float32), colorspace="Non-Color", name="f32",
                        alpha_mode="PREMUL"),
                Texture(pixels=rng.integers(0, 65536, (2, 1, 4)).astype(np.uint16), colorspace="Linear", name="u16")]
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
                 resolution=(37, 23), frame=10.0, metadata={"source": "test", "n": 3, "nested": {"x": [1, 2]}},
                 textures=textures)


def node_graph() -> ShaderGraph:
    """A small graph with every kind of node data: links, constants, enums, a ramp, a curve table,
    a texture index and a UV map name."""
    return ShaderGraph(nodes={
        "UV": Node("ShaderNodeUVMap", props={"uv_map": "Second/map", "from_instancer": False},
                   outputs={"UV": "VECTOR"}),
        "Image": Node("ShaderNodeTexImage", props={"image": 0, "interpolation": "Closest", "extension": "EXTEND",
                                                   "projection": "FLAT"},
                      inputs={"Vector": Link("UV", "UV")}, input_types={"Vector": "VECTOR"},
                      outputs={"Color": "RGBA", "Alpha": "VALUE"}),
        "Ramp": Node("ShaderNodeValToRGB",
                     props={"elements": [(0.0, (0.0, 0.0, 0.0, 1.0)), (0.625, (1.0, 0.5, 0.25, 1.0))],
                            "interpolation": "EASE", "color_mode": "RGB"},
                     inputs={"Fac": Link("Image", "Alpha")}, input_types={"Fac": "VALUE"},
                     outputs={"Color": "RGBA"}),
        "Curves": Node("ShaderNodeRGBCurve", props={"table": [[0.0, 0.5, 1.0], [0.0, 0.25, 1.0], [0.1, 0.2, 0.3]]},
                       inputs={"Fac": 1.0, "Color": Link("Ramp", "Color")},
                       input_types={"Fac": "VALUE", "Color": "RGBA"}, outputs={"Color": "RGBA"}),
        "Noise": Node("ShaderNodeTexNoise", props={"noise_dimensions": "3D", "noise_type": "FBM", "normalize": True},
                      inputs={"Scale": 5.0, "Detail": 2.0}, input_types={"Scale": "VALUE", "Detail": "VALUE"},
                      outputs={"Fac": "VALUE"}),
        "Math": Node("ShaderNodeMath", props={"operation": "MULTIPLY", "use_clamp": True},
                     inputs={"Value": Link("Image", "Alpha"), "Value_001": Link("Noise", "Fac")},
                     input_types={"Value": "VALUE", "Value_001": "VALUE"}, outputs={"Value": "VALUE"}),
        "BSDF": Node("ShaderNodeBsdfPrincipled",
                     inputs={"Base Color": Link("Curves", "Color"), "Roughness": Link("Math", "Value"),
                             "Metallic": 0.25, "Emission Color": (0.1, 0.2, 0.3)},
                     input_types={"Base Color": "RGBA", "Roughness": "VALUE", "Metallic": "VALUE",
                                  "Emission Color": "RGBA"},
                     outputs={"BSDF": "SHADER"}),
    }, surface=Link("BSDF", "BSDF"))


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


def test_round_trip_keeps_orco_and_constant_fresnel(tmp_path):
    """Mesh.orco (Generated's undeformed positions) and Material.constant_fresnel (a Glossy BSDF's
    metal) survive a save and load; a file without them reads None / False."""
    scene = rich_scene()
    m = scene.meshes[1]
    m.orco = (np.asarray(m.vertices_at(0.0), np.float32) * 1.5).astype(np.float32)
    scene.materials[0].constant_fresnel = True
    loaded = load_scene(save_scene(scene, tmp_path / "s.stpm"))
    assert np.array_equal(loaded.meshes[1].orco, m.orco) and loaded.meshes[0].orco is None
    assert loaded.materials[0].constant_fresnel and not loaded.materials[1].constant_fresnel
    m.orco = m.orco[:-1]
    with pytest.raises(SceneError, match="orco"):
        save_scene(scene, tmp_path / "bad.stpm")


def test_round_trip_keeps_graphs_textures_and_uvs(tmp_path):
    """Node graphs compile to the same program, textures keep their native storage, UV maps
    their names (even with a '/') and the render-active one."""
    scene = rich_scene()
    loaded = load_scene(save_scene(scene, tmp_path / "g.stpm"))
    a, b = compile_graph(scene.materials[0].graph, 4, []), compile_graph(loaded.materials[0].graph, 4, [])
    assert np.array_equal(a.words, b.words) and a.unsupported == b.unsupported
    assert [m.graph is None for m in loaded.materials] == [False, True, True, True]
    kinds = [(t.pixels.dtype, t.half, t.colorspace, t.alpha_mode) for t in loaded.textures]
    assert kinds == [(np.uint8, False, "sRGB", "STRAIGHT"), (np.uint16, True, "Linear", "STRAIGHT"),
                     (np.float32, False, "Non-Color", "PREMUL"), (np.uint16, False, "Linear", "STRAIGHT")]
    for t0, t1 in zip(scene.textures, loaded.textures):
        np.testing.assert_array_equal(t0.decoded(), t1.decoded())
    m = loaded.meshes[0]
    assert list(m.uv_layers) == ["UVMap", "Second/map"] and m.uv_render == "Second/map"
    assert all(uv.dtype == np.float32 for uv in m.uv_layers.values())
    assert list(m.tangents) == ["UVMap"] and m.tangents["UVMap"].shape == (3, 3, 4)
    assert loaded.meshes[1].uv_layers == {} and loaded.meshes[1].uv_render is None
    assert loaded.meshes[1].tangents == {}
    assert list(m.color_layers) == ["Col", "Wear"] and m.color_render == "Wear"
    for name in ("Col", "Wear"):
        np.testing.assert_array_equal(m.color_layers[name], scene.meshes[0].color_layers[name])
    assert loaded.meshes[1].color_layers == {} and loaded.meshes[1].color_render is None


def test_round_trip_keeps_udim_tiles_and_the_working_space(tmp_path):
    """A UDIM Image Texture's tile table, the textures' colour spaces of every kind Blender 5 offers
    and the scene's working space come back as written, and compile to the same program."""
    scene = rich_scene()
    scene.materials[0].graph.nodes["Image"].props["tiles"] = [[1001, 0], [1002, 3], [1011, 1]]
    scene.textures[1].colorspace = "ACEScg"
    scene.textures[3].colorspace = "Display P3"
    scene.metadata["working_space"] = "ACESCG"
    loaded = load_scene(save_scene(scene, tmp_path / "u.stpm"))
    assert loaded.materials[0].graph.nodes["Image"].props["tiles"] == [[1001, 0], [1002, 3], [1011, 1]]
    assert [t.colorspace for t in loaded.textures] == ["sRGB", "ACEScg", "Non-Color", "Display P3"]
    assert loaded.metadata["working_space"] == "ACESCG"
    a, b = compile_graph(scene.materials[0].graph, 4, []), compile_graph(loaded.materials[0].graph, 4, [])
    assert np.array_equal(a.words, b.words)
    assert 1011.0 in a.words and 1002.0 in a.words                     # the tile table is in the program


def test_files_without_the_node_fields_still_load(tmp_path):
    """The graph, texture and UV keys are optional (files written before they existed)."""
    header, arrays = _parts()
    del header["textures"]
    for m in header["materials"]:
        m.pop("graph", None)
    for m in header["meshes"]:
        m.pop("uv_layers", None), m.pop("uv_render", None), m.pop("tangents", None)
    arrays = {k: v for k, v in arrays.items()
              if not k.startswith("textures/") and "/uv/" not in k and "/tangents/" not in k}
    _write_raw(tmp_path / "old.stpm", header, arrays)
    scene = load_scene(tmp_path / "old.stpm")
    assert scene.textures == [] and all(m.graph is None for m in scene.materials)
    assert all(m.uv_layers == {} and m.uv_render is None and m.tangents == {} for m in scene.meshes)


def _bad_graph_nan(sc):
    sc.materials[0].graph.nodes["BSDF"].inputs["Metallic"] = float("nan")


def _bad_graph_object(sc):
    sc.materials[0].graph.nodes["Math"].props["operation"] = object()


def _bad_graph_image(sc):
    sc.materials[0].graph.nodes["Image"].props["image"] = 9


def _bad_graph_type(sc):
    sc.materials[1].graph = {"nodes": {}}


def _bad_texture_type(sc):
    sc.textures.append(np.zeros((2, 2, 3), np.uint8))


def _bad_texture_space(sc):
    sc.textures[0].colorspace = "AgX Log"


def _bad_texture_nan(sc):
    sc.textures[2].pixels[0, 0, 0] = np.inf


def _bad_uv_shape(sc):
    sc.meshes[0].uv_layers["UVMap"] = np.zeros((2, 3, 2), np.float32)


def _bad_uv_render(sc):
    sc.meshes[0].uv_render = "nope"


def _bad_tangent_name(sc):
    sc.meshes[0].tangents["Other"] = sc.meshes[0].tangents["UVMap"]


def _bad_color_render(sc):
    sc.meshes[0].color_render = "nope"


def _bad_color_shape(sc):
    sc.meshes[0].color_layers["Col"] = np.zeros((3, 3, 3), np.float32)


def _bad_alpha_mode(sc):
    sc.textures[1].alpha_mode = "MULTIPLY"


def _bad_tiles_number(sc):
    sc.materials[0].graph.nodes["Image"].props["tiles"] = [[1001, 0], [999, 1]]


def _bad_tiles_index(sc):
    sc.materials[0].graph.nodes["Image"].props["tiles"] = [[1001, 0], [1002, 4]]


def _bad_tiles_twice(sc):
    sc.materials[0].graph.nodes["Image"].props["tiles"] = [[1001, 0], [1001, 1]]


def _bad_tiles_shape(sc):
    sc.materials[0].graph.nodes["Image"].props["tiles"] = [1001, 0]


def _bad_working_space(sc):
    sc.metadata["working_space"] = "Linear Rec.709"


BAD_SCENES = [
    ("NaN graph input", _bad_graph_nan, "materials[0] ('d').graph"),
    ("non-JSON property", _bad_graph_object, "materials[0] ('d').graph"),
    ("texture index out of range", _bad_graph_image, "props['image']"),
    ("graph not a ShaderGraph", _bad_graph_type, "materials[1] ('m').graph"),
    ("texture not a Texture", _bad_texture_type, "textures[4]"),
    ("unknown colour space", _bad_texture_space, "textures[0] ('rgb8').colorspace"),
    ("inf texel", _bad_texture_nan, "textures[2] ('f32').pixels"),
    ("UV shape", _bad_uv_shape, "uv_layers['UVMap']"),
    ("unknown render UV map", _bad_uv_render, "uv_render"),
    ("tangents of no UV map", _bad_tangent_name, "tangents['Other']"),
    ("unknown alpha mode", _bad_alpha_mode, "textures[1] ('half').alpha_mode"),
    ("unknown render colour attribute", _bad_color_render, "color_render"),
    ("colour attribute shape", _bad_color_shape, "color_layers['Col']"),
    ("UDIM tile number", _bad_tiles_number, "props['tiles']"),
    ("UDIM tile texture", _bad_tiles_index, "props['tiles']"),
    ("UDIM tile listed twice", _bad_tiles_twice, "props['tiles']"),
    ("UDIM tiles not pairs", _bad_tiles_shape, "props['tiles']"),
    ("unknown working space", _bad_working_space, "metadata.working_space"),
]


@pytest.mark.parametrize("label,spoil,field", BAD_SCENES, ids=[b[0] for b in BAD_SCENES])
def test_bad_graphs_textures_and_uvs_are_never_written(tmp_path, label, spoil, field):
    scene = rich_scene()
    spoil(scene)
    with pytest.raises(SceneError) as info:
        save_scene(scene, tmp_path / "bad.stpm")
    assert field in str(info.value) and "\n" not in str(info.value), str(info.value)
    assert not (tmp_path / "bad.stpm").exists()


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


def _mut_tex_dtype(h, a):
    a["textures/0/pixels"] = a["textures/0/pixels"].astype(np.int16)


def _mut_tex_shape(h, a):
    a["textures/0/pixels"] = np.zeros((2, 3, 2), np.uint8)


def _mut_tex_nan(h, a):
    a["textures/2/pixels"] = np.full((1, 2, 4), np.nan, np.float32)


def _mut_tex_half_inf(h, a):
    a["textures/1/pixels"] = np.full((2, 2, 1), np.inf, np.float16).view(np.uint16)


def _mut_tex_half_dtype(h, a):
    a["textures/1/pixels"] = np.zeros((2, 2, 1), np.float32)


def _mut_tex_space(h, a):
    h["textures"][3]["colorspace"] = "Rec.2020"


def _mut_tex_missing(h, a):
    del a["textures/3/pixels"]


def _mut_graph_link(h, a):
    h["materials"][0]["graph"]["nodes"]["Math"]["inputs"]["Value"] = {"link": ["Gone", "Alpha"]}


def _mut_graph_input(h, a):
    h["materials"][0]["graph"]["nodes"]["BSDF"]["inputs"]["Emission Color"] = [0.1, 0.2]


def _mut_graph_image(h, a):
    h["materials"][0]["graph"]["nodes"]["Image"]["props"]["image"] = 4


def _mut_graph_ramp(h, a):
    h["materials"][0]["graph"]["nodes"]["Ramp"]["props"]["elements"] = [[0.0, [1, 1]]]


def _mut_graph_table(h, a):
    h["materials"][0]["graph"]["nodes"]["Curves"]["props"]["table"] = [[0.0, 1.0], [0.0, 1.0]]


def _mut_graph_enum(h, a):
    h["materials"][0]["graph"]["nodes"]["Math"]["props"]["operation"] = ["ADD"]


def _mut_graph_surface(h, a):
    h["materials"][0]["graph"]["surface"] = ["BSDF"]


def _mut_graph_noise(h, a):
    h["materials"][0]["graph"]["nodes"]["Noise"]["props"]["noise_type"] = {"x": 1}


def _mut_graph_type(h, a):
    del h["materials"][0]["graph"]["nodes"]["UV"]["type"]


def _mut_uv_shape(h, a):
    a["meshes/0/uv/1"] = np.zeros((4, 3, 2), np.float32)


def _mut_uv_nan(h, a):
    a["meshes/0/uv/0"] = np.full((3, 3, 2), np.nan, np.float32)


def _mut_uv_render(h, a):
    h["meshes"][0]["uv_render"] = "Missing"


def _mut_uv_names(h, a):
    h["meshes"][0]["uv_layers"] = ["UVMap", "UVMap"]


def _mut_uv_missing(h, a):
    del a["meshes/0/uv/1"]


def _mut_tangent_shape(h, a):
    a["meshes/0/tangents/0"] = np.zeros((3, 3, 3), np.float32)


def _mut_tangent_name(h, a):
    h["meshes"][0]["tangents"] = ["Nope"]


def _mut_alpha_mode(h, a):
    h["textures"][0]["alpha_mode"] = "premul"


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
    ("texture dtype", _mut_tex_dtype, "textures[0].pixels"),
    ("texture channels", _mut_tex_shape, "textures[0].pixels"),
    ("NaN texels", _mut_tex_nan, "textures[2].pixels"),
    ("inf half texels", _mut_tex_half_inf, "textures[1].pixels"),
    ("half texture not uint16", _mut_tex_half_dtype, "textures[1].pixels"),
    ("texture colour space", _mut_tex_space, "textures[3].colorspace"),
    ("missing texture pixels", _mut_tex_missing, "textures/3/pixels"),
    ("link to unknown node", _mut_graph_link, "materials[0].graph.nodes['Math'].inputs['Value']"),
    ("short vector input", _mut_graph_input, "materials[0].graph.nodes['BSDF'].inputs['Emission Color']"),
    ("image index out of range", _mut_graph_image, "materials[0].graph.nodes['Image'].props['image']"),
    ("bad ramp", _mut_graph_ramp, "nodes['Ramp'].props['elements']"),
    ("bad curve table", _mut_graph_table, "nodes['Curves'].props['table']"),
    ("enum not a string", _mut_graph_enum, "nodes['Math'].props['operation']"),
    ("bad surface link", _mut_graph_surface, "materials[0].graph.surface"),
    ("node without type", _mut_graph_type, "materials[0].graph.nodes['UV'].type"),
    ("enum property not a string", _mut_graph_noise, "nodes['Noise'].props['noise_type']"),
    ("UV map shape", _mut_uv_shape, "meshes[0].uv_layers['Second/map']"),
    ("NaN UVs", _mut_uv_nan, "meshes[0].uv_layers['UVMap']"),
    ("unknown render UV map", _mut_uv_render, "meshes[0].uv_render"),
    ("repeated UV map names", _mut_uv_names, "meshes[0].uv_layers"),
    ("missing UV array", _mut_uv_missing, "meshes/0/uv/1"),
    ("tangent shape", _mut_tangent_shape, "meshes[0].tangents['UVMap']"),
    ("tangents of an unknown UV map", _mut_tangent_name, "meshes[0].tangents['Nope']"),
    ("unknown alpha mode", _mut_alpha_mode, "textures[0].alpha_mode"),
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


def test_zip_member_without_a_name(tmp_path):
    """A corrupted central directory can leave a member's name empty (found by test_fuzz_bytes):
    zipfile's ``ZipInfo.is_dir`` then raised a bare IndexError through the loader."""
    import zipfile
    path = tmp_path / "noname.stpm"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr(zipfile.ZipInfo(""), b"y")
        zf.writestr(zipfile.ZipInfo("header.npy"), b"x")
    msg = _load_error(path)
    assert "without a name" in msg


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
    for m in scene.materials:  # ... and its node graphs compile (the loader checked what the compiler reads)
        if m.graph is not None:
            compile_graph(m.graph, len(scene.textures), [])


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
    """A file says the lowest version that reads it as written: 2 unless it uses UDIM tiles or a
    working space other than Rec.709 (3, which a version-2 reader refuses rather than misread), or
    per-step normals of a deforming mesh (4: tests/test_deforming_normals.py), or a camera with a thin
    lens (5: tests/test_depth_of_field.py)."""
    header, _ = _parts()
    assert header["format"] == FORMAT_NAME == "stpm-scene"
    assert header["version"] == 2 and SCENE_FORMAT_VERSION == 5
    scene = rich_scene()
    scene.metadata["working_space"] = "ACESCG"
    assert scene_to_arrays(scene)[0]["version"] == 3
    scene = rich_scene()
    scene.materials[0].graph.nodes["Image"].props["tiles"] = [[1001, 0]]
    assert scene_to_arrays(scene)[0]["version"] == 3


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


# ----------------------------------------------------------------------------
# Material.transmission_tint (a Principled glass's sqrt(base_color), Cycles' transmission tint) and
# Material.reflection_tint (a Glass BSDF's colour, Cycles' reflection tint)
# ----------------------------------------------------------------------------
TINTS = ("transmission_tint", "reflection_tint")


@pytest.mark.parametrize("key", TINTS)
def test_glass_tint_round_trip(tmp_path, key):
    """A set tint survives bit-exact; None (the default: base_color / white) is not written and loads as None."""
    scene = rich_scene()
    scene.materials[2].base_color = np.array([0.8, 0.3, 0.2])
    setattr(scene.materials[2], key, np.sqrt(np.array([0.8, 0.3, 0.2])))
    header, _arrays = scene_to_arrays(scene, RenderSettings())
    assert header["materials"][2][key] == [float(x) for x in np.sqrt([0.8, 0.3, 0.2])]
    assert all(k not in d for i, d in enumerate(header["materials"]) for k in TINTS if (i, k) != (2, key))
    loaded = load_scene(save_scene(scene, tmp_path / "t.stpm"))
    _assert_same(scene, loaded)
    assert all(getattr(loaded.materials[0], k) is None for k in TINTS)
    assert getattr(loaded.materials[2], key).dtype == np.float64


@pytest.mark.parametrize("key", TINTS)
@pytest.mark.parametrize("tint, match", [
    (np.array([0.5, 0.5]), r"materials\[2\] \('g'\)\.{key} must have shape \(3,\)"),
    (np.array([0.5, -0.1, 0.5]), r"materials\[2\] \('g'\)\.{key} must be non-negative"),
    (np.array([0.5, 1.5, 0.5]), r"materials\[2\] \('g'\)\.{key} must be <= 1"),
    (np.array([0.5, np.nan, 0.5]), r"materials\[2\] \('g'\)\.{key} contains NaN"),
])
def test_bad_glass_tint_is_never_written(tmp_path, key, tint, match):
    scene = rich_scene()
    setattr(scene.materials[2], key, tint)
    with pytest.raises(SceneError, match=match.format(key=key)):
        save_scene(scene, tmp_path / "bad.stpm")
    assert not (tmp_path / "bad.stpm").exists()


@pytest.mark.parametrize("key", TINTS)
@pytest.mark.parametrize("value, words", [
    ([0.5, 0.5], "must be a list of 3 numbers"),
    ([0.5, -0.5, 0.5], "must be non-negative"),
    ([0.5, 2.0, 0.5], "must be <= 1"),
    ("red", "must be a list of 3 numbers"),
])
def test_malformed_glass_tint_in_a_file(tmp_path, key, value, words):
    header, arrays = _parts()
    header["materials"][2][key] = value
    _write_raw(tmp_path / "bad.stpm", header, arrays)
    msg = _load_error(tmp_path / "bad.stpm")
    assert "materials[2]" in msg and key in msg and words in msg, msg
