"""Procedural worlds baked by Cycles (addon/export/world.py, addon/export/world_bake_child.py).

A world the exporter does not read directly (a Sky Texture, a linked Strength, Light Path tricks)
is rendered alone by Cycles in the bake child through a panoramic equirectangular camera and
exported as ``World.image`` like an Environment Texture:

* orientation: a baked Environment Texture world equals its image, texel by texel;
* a Sky Texture world lights a diffuse floor and sphere like Cycles (direct light, block Z-test);
  Blender 5's sky types are SINGLE_SCATTERING, MULTIPLE_SCATTERING (the default, Nishita's
  successor), PREETHAM and HOSEK_WILKIE: the default run checks MULTIPLE_SCATTERING, the others
  are slow tests (STPM_SLOW=1);
* Light Path "Is Camera Ray": the camera view and the lighting view are two bakes, both exported
  (``World.camera_image``, ``World.image``) and kept by the scene file;
* the cache: a second export starts no child; baking off or a failed bake falls back, warned.
"""
from __future__ import annotations

import math
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from addon import batch  # noqa: E402
from addon.export import bake  # noqa: E402
from addon.export import world as world_export  # noqa: E402
from test_addon_scenes import add_camera, add_mesh, export_now, fresh  # noqa: E402

SKY_TYPES = [e.identifier for e in bpy.types.ShaderNodeTexSky.bl_rna.properties["sky_type"].enum_items]


@pytest.fixture
def cache(monkeypatch, tmp_path):
    monkeypatch.setenv("STPM_BAKE_CACHE", str(tmp_path / "cache"))
    world_export.LAST_FAILED.clear()
    return tmp_path / "cache"


def _new_world(name: str):
    world = bpy.data.worlds.new(name)
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    bpy.context.scene.world = world
    return world


def _test_image(w: int = 64, h: int = 32):
    """An asymmetric float image (h, w, 4), row 0 at the bottom: red = u, green = v, blue 0.1 with
    a bright 3 x 3 texel spot at u ~ 0.2, v ~ 0.7 (it is refined by the bake)."""
    img = bpy.data.images.new("uv test", w, h, float_buffer=True)
    px = np.ones((h, w, 4), np.float32)
    px[..., 0] = ((np.arange(w) + 0.5) / w)[None, :]
    px[..., 1] = ((np.arange(h) + 0.5) / h)[:, None]
    px[..., 2] = 0.1
    px[22:25, 12:15, 2] = 5.0
    img.pixels.foreach_set(px.ravel())
    img.pack()
    return img, px[..., :3]


def test_baked_environment_texture_world_is_its_image(cache, monkeypatch):
    """Orientation and pixel layout: an Environment Texture (Closest) whose Strength is linked (so
    the world is baked) bakes to its own image, 4 x 4 bake pixels per texel."""
    monkeypatch.setattr(world_export, "WORLD_BAKE_RESOLUTION", (256, 128))
    scene = fresh()
    add_camera()
    img, want = _test_image()
    world = _new_world("Env")
    t = world.node_tree
    env = t.nodes.new("ShaderNodeTexEnvironment")
    env.image, env.interpolation = img, "Closest"
    t.links.new(env.outputs["Color"], t.nodes["Background"].inputs["Color"])
    val = t.nodes.new("ShaderNodeValue")
    val.outputs[0].default_value = 1.0
    t.links.new(val.outputs[0], t.nodes["Background"].inputs["Strength"])
    report = batch.bake_current(scene)
    assert report["child"] and len(report["baked"]) == 1 and not report["failed"], report
    core, warnings = export_now()
    assert any("world 'Env' baked by Cycles to a 256x128 environment" in w and "Strength is linked" in w
               for w in warnings), warnings
    wd = core.world
    assert wd.image.shape == (128, 256, 3) and wd.camera_image is None
    assert wd.strength == 1.0 and np.all(wd.color == 1.0) and wd.interpolation == "LINEAR"
    np.testing.assert_allclose(wd.mapping.matrices[0], np.eye(4))
    got = wd.image.reshape(32, 4, 64, 4, 3).mean(axis=(1, 3))
    err = np.abs(got - want)
    rel = err / np.maximum(want, 0.02)
    print(f"orientation: max |bake - image| per channel {err.max(axis=(0, 1))}, max relative {rel.max():.4f}, "
          f"mean relative {rel.mean():.2e}")
    assert rel.max() < 0.02, (rel.max(), np.argwhere(rel > 0.02)[:5])
    # The bright spot where the image has it (mirrored or turned worlds put it elsewhere)
    j, i = np.unravel_index(np.argmax(got[..., 2]), got.shape[:2])
    assert (22 <= j <= 24) and (12 <= i <= 14), (i, j)


def _sky_scene(sky_type: str = "MULTIPLE_SCATTERING", strength: float = 0.05):
    """A diffuse floor, sphere and box under a Sky Texture (sun 35 degrees up, behind the camera's view)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    world = _new_world("Sky")
    t = world.node_tree
    sky = t.nodes.new("ShaderNodeTexSky")
    sky.sky_type = sky_type
    if hasattr(sky, "sun_elevation"):
        sky.sun_elevation, sky.sun_rotation = math.radians(35.0), math.radians(60.0)
    if sky_type in ("PREETHAM", "HOSEK_WILKIE"):
        el, rot = math.radians(35.0), math.radians(60.0)
        sky.sun_direction = (math.cos(el) * math.sin(rot), math.cos(el) * math.cos(rot), math.sin(el))
    t.links.new(sky.outputs["Color"], t.nodes["Background"].inputs["Color"])
    t.nodes["Background"].inputs["Strength"].default_value = strength
    mat = bpy.data.materials.new("White")
    p = mat.node_tree.nodes["Principled BSDF"]
    p.inputs["Base Color"].default_value = (0.8, 0.8, 0.8, 1.0)
    p.inputs["Roughness"].default_value = 1.0
    p.inputs["Specular IOR Level"].default_value = 0.0
    add_mesh("plane", "Floor", material=mat, size=6.0)
    add_mesh("cube", "Box", location=(-0.7, -0.2, 0.35), material=mat, size=0.7)
    add_mesh("sphere", "Ball", location=(0.6, 0.3, 0.5), material=mat, radius=0.5, segments=32, ring_count=16)
    bpy.ops.object.shade_smooth()           # the sphere (a smooth-shaded box has Cycles' terminator offsets)
    add_camera(location=(0, -5.5, 2.2), rotation=(math.radians(76), 0, 0), lens=30)
    return scene


def _sky_matches_cycles(tmp_path, sky_type: str, seeds=(0, 1, 2), working_space: str | None = None):
    from cycles_ref import block_ztest, render_cycles, render_stpm
    scene = _sky_scene(sky_type)
    if working_space is not None:              # Blender 5: the whole file in another working space
        assert "FINISHED" in bpy.ops.wm.set_working_color_space(convert_colors=True, working_space=working_space)
    t0 = time.perf_counter()
    report = batch.bake_current(scene)
    bake_s = time.perf_counter() - t0
    assert report["child"] and len(report["baked"]) == 1 and not report["failed"], report
    core, warnings = export_now()
    assert any("world 'Sky' baked by Cycles to a 1024x512 environment" in w and "ShaderNodeTexSky" in w
               for w in warnings), warnings
    assert core.world.image.shape == (512, 1024, 3)
    t0 = time.perf_counter()
    cyc = render_cycles(scene, tmp_path, samples=64, seeds=seeds)
    t1 = time.perf_counter()
    stpm, _res = render_stpm(scene, samples=64, seeds=seeds)
    t2 = time.perf_counter()
    r = block_ztest(stpm, cyc)
    print(f"sky {sky_type}: bake {bake_s:.1f} s, Cycles {t1 - t0:.1f} s, STPM {t2 - t1:.1f} s; {r.summary()}")
    assert r.z_abs_max < 4.5, (r.summary(), np.round(r.z, 1))
    assert abs(r.mean_ratio - 1.0) < 0.02, r.summary()


def test_sky_texture_world_lights_like_cycles(cache, tmp_path):
    _sky_matches_cycles(tmp_path, "MULTIPLE_SCATTERING")


@pytest.mark.slow
def test_sky_world_in_an_acescg_file_lights_like_cycles(cache, tmp_path):
    """The bake holds the working space's values (Cycles computes the sky into it), read unconverted."""
    _sky_matches_cycles(tmp_path, "MULTIPLE_SCATTERING", working_space="ACEScg")


@pytest.mark.slow
@pytest.mark.parametrize("sky_type", [s for s in SKY_TYPES if s != "MULTIPLE_SCATTERING"])
def test_other_sky_types_light_like_cycles(cache, tmp_path, sky_type):
    """Six seeds: the sun-less Preetham and Hosek-Wilkie skies light a dim, smooth scene whose
    3-seed variance estimates are too shaky for the Z-test."""
    _sky_matches_cycles(tmp_path, sky_type, seeds=tuple(range(6)))


def test_blender_5_sky_types_are_known():
    if bpy.app.version >= (5, 0, 0):
        assert set(SKY_TYPES) == {"SINGLE_SCATTERING", "MULTIPLE_SCATTERING", "PREETHAM", "HOSEK_WILKIE"}


def _camera_ray_world():
    """Camera rays see grey 0.5; the light is a blue-ish Preetham sky: Mix(Is Camera Ray, sky, grey)."""
    world = _new_world("Trick")
    t = world.node_tree
    sky = t.nodes.new("ShaderNodeTexSky")
    sky.sky_type = "PREETHAM" if "PREETHAM" in SKY_TYPES else SKY_TYPES[0]
    lp = t.nodes.new("ShaderNodeLightPath")
    mix = t.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    mix.inputs["B"].default_value = (0.5, 0.5, 0.5, 1.0)
    t.links.new(lp.outputs["Is Camera Ray"], mix.inputs["Factor"])
    t.links.new(sky.outputs["Color"], mix.inputs["A"])
    t.links.new(mix.outputs["Result"], t.nodes["Background"].inputs["Color"])
    t.nodes["Background"].inputs["Strength"].default_value = 0.1
    return world


def test_light_path_camera_ray_world_exports_both_views(cache, monkeypatch, tmp_path):
    from stpm_core.scene import validate_scene
    from stpm_core.scenefile import load_scene, save_scene
    monkeypatch.setattr(world_export, "WORLD_BAKE_RESOLUTION", (128, 64))
    scene = fresh()
    add_camera()
    _camera_ray_world()
    plan = world_export.bake_plan(bpy.context.scene.world)
    assert plan.camera and plan.views == ("light", "camera") and "Is Camera Ray" in plan.cause()
    report = batch.bake_current(scene)
    assert report["child"] and len(report["baked"]) == 2 and not report["failed"], report
    core, warnings = export_now()
    assert any("camera rays see a second bake" in w for w in warnings), warnings
    wd = core.world
    assert wd.image.shape == wd.camera_image.shape == (64, 128, 3)
    np.testing.assert_allclose(wd.camera_image, 0.05, rtol=1e-3)          # grey 0.5 x strength 0.1
    sky = wd.image
    up = sky[48:].mean(axis=(0, 1))
    assert up[2] > 1.2 * up[0] and np.abs(sky - 0.05).max() > 0.01, up       # a blue sky, not the grey
    validate_scene(core)
    path = tmp_path / "trick.stpm"
    save_scene(core, path)
    back = load_scene(path)
    np.testing.assert_array_equal(back.world.image, wd.image)
    np.testing.assert_array_equal(back.world.camera_image, wd.camera_image)
    # A world without a camera image stays without one; a camera image needs an image
    core.world.camera_image = None
    save_scene(core, path)
    assert load_scene(path).world.camera_image is None
    from stpm_core.scene import SceneError
    core.world.camera_image, core.world.image = wd.image, None
    with pytest.raises(SceneError, match="camera_image needs world.image"):
        validate_scene(core)
    core.world.image, core.world.camera_image = sky, sky[:, :, :2].copy()
    with pytest.raises(SceneError, match=r"camera_image must be an \(H, W, 3\) array"):
        validate_scene(core)
    core.world.camera_image = sky.astype(np.float64)
    with pytest.raises(SceneError, match="camera_image must be float32"):
        validate_scene(core)


def test_the_cache_is_reused_and_missing_or_failed_bakes_fall_back(cache, monkeypatch):
    monkeypatch.setattr(world_export, "WORLD_BAKE_RESOLUTION", (128, 64))
    scene = fresh()
    add_camera()
    world = _new_world("Grad")
    t = world.node_tree
    grad = t.nodes.new("ShaderNodeTexGradient")
    t.links.new(grad.outputs["Color"], t.nodes["Background"].inputs["Color"])
    # Not baked yet: named, the Background node's own colour used
    _core, warnings = export_now()
    assert any("world 'Grad' needs a Cycles bake (node 'Gradient Texture' (ShaderNodeTexGradient) feeds the "
               "Background colour) and none is cached" in w for w in warnings), warnings
    # Baking off
    w2 = []
    out = world_export.export_world(world, w2, bakes=None)
    assert out.image is None and any("baking is off" in w for w in w2), w2
    # A child that fails: named with the cause, then the fallback
    monkeypatch.setattr(bake, "CHILD_SCRIPT", str(cache / "no_such_child.py"))
    report = batch.bake_current(scene)
    assert report["child"] and len(report["failed"]) == 1, report
    _core, warnings = export_now()
    assert any("world 'Grad' could not be baked" in w and "the Cycles bake failed" in w for w in warnings), warnings
    monkeypatch.undo()
    monkeypatch.setenv("STPM_BAKE_CACHE", str(cache))
    monkeypatch.setattr(world_export, "WORLD_BAKE_RESOLUTION", (128, 64))
    # Baked once by the first export with baking on; the second starts no child
    runs = bake.STATS["child_runs"]
    t0 = time.perf_counter()
    first, _settings = batch.export_current(scene, bake=True)
    t1 = time.perf_counter()
    again, _settings = batch.export_current(scene, bake=True)
    t2 = time.perf_counter()
    print(f"cache: first export {t1 - t0:.2f} s (one child), second {t2 - t1:.2f} s (none)")
    assert bake.STATS["child_runs"] == runs + 1
    assert first.world.image is not None and again.world.image is not None
    np.testing.assert_array_equal(first.world.image, again.world.image)
    # The gradient: dark below the horizon... Blender's linear gradient runs along x in [0, 1]
    assert first.world.image.std() > 0.05
    # An edit of the tree makes a new key, to bake again
    key = world_export.world_bake_key(world, "light")
    grad.gradient_type = "QUADRATIC"
    assert world_export.world_bake_key(world, "light") != key
    (job,) = world_export.plan_world_jobs(world, bake.cache_dirs(None))
    assert job.view == "light" and job.resolution == [128, 64]


def test_light_path_inside_a_node_group_is_zeroed_in_a_copy_of_the_group(cache):
    """The lighting view's rewiring (world_bake_child.zero_camera_ray) reaches into node groups,
    copying them, so the camera view and other users of the group keep Is Camera Ray."""
    from addon.export import world_bake_child
    fresh()
    world = _new_world("Grouped")
    grp = bpy.data.node_groups.new("CamOrSky", "ShaderNodeTree")
    grp.interface.new_socket("Color", in_out="OUTPUT", socket_type="NodeSocketColor")
    gout = grp.nodes.new("NodeGroupOutput")
    lp = grp.nodes.new("ShaderNodeLightPath")
    mix = grp.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    grp.links.new(lp.outputs["Is Camera Ray"], mix.inputs["Factor"])
    grp.links.new(mix.outputs["Result"], gout.inputs[0])
    t = world.node_tree
    node = t.nodes.new("ShaderNodeGroup")
    node.node_tree = grp
    t.links.new(node.outputs[0], t.nodes["Background"].inputs["Color"])
    plan = world_export.bake_plan(world)
    assert plan is not None and plan.camera and "ShaderNodeGroup" in plan.cause()
    light = world.copy()
    assert world_bake_child.zero_camera_ray(light.node_tree) == 1
    inner = next(n for n in light.node_tree.nodes if n.bl_idname == "ShaderNodeGroup").node_tree
    assert inner is not grp and grp.nodes[lp.name].outputs["Is Camera Ray"].is_linked
    fac = next(n for n in inner.nodes if n.bl_idname == "ShaderNodeMix").inputs["Factor"]
    assert fac.links[0].from_node.bl_idname == "ShaderNodeValue" and fac.links[0].from_socket.default_value == 0.0
    assert world_export.bake_plan(light).camera is False


def test_an_unreadable_bake_falls_back_with_its_cause(cache):
    fresh()
    world = _new_world("Noisy")
    t = world.node_tree
    noise = t.nodes.new("ShaderNodeTexNoise")
    t.links.new(noise.outputs["Color"], t.nodes["Background"].inputs["Color"])
    key = world_export.world_bake_key(world, "light")
    cache.mkdir(parents=True, exist_ok=True)
    (cache / f"{key}.exr").write_bytes(b"not an EXR")
    warnings: list = []
    out = world_export.export_world(world, warnings)
    assert out.image is None and np.allclose(out.color, t.nodes["Background"].inputs["Color"].default_value[:3])
    assert any("world 'Noisy': its baked image" in w and "could not be read" in w for w in warnings), warnings
    assert any("ShaderNodeTexNoise on the background is not supported" in w for w in warnings), warnings
