"""Renders through Blender itself: ``bpy.ops.render.render`` with engine STPM.

This is the same engine call as ``blender -b file.blend -E STPM -f N``.
Pixels come back through Blender's own multilayer EXR writer, read with
OpenImageIO, so the test also covers "Blender's outputs just work".
"""
from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
oiio = pytest.importorskip("OpenImageIO")

from test_addon_scenes import ROOT, add_camera, add_light, add_mesh, fresh, node_material, set_world  # noqa: E402

import addon  # noqa: E402
from addon import batch  # noqa: E402
from addon.engine import LAST_RENDER, STPMRenderEngine  # noqa: E402

DEMO = ROOT / "blend_scenes" / "demo.blend"
addon.register()  # before any .blend is opened, so files keep engine 'STPM'

PASSES = {"Combined": "RGBA", "Depth": "Z", "Normal": "XYZ", "Emit": "RGB", "Direct": "RGB",
          "Indirect": "RGB", "Caustic": "RGB"}  # interface.md


def read_exr_passes(path) -> dict:
    """Every pass of a (multi-part or single-part) multilayer EXR -> name -> (H, W, C), row 0 = top."""
    inp = oiio.ImageInput.open(str(path))
    assert inp is not None, oiio.geterror()
    out, names, sub = {}, [], 0
    while inp.seek_subimage(sub, 0):
        spec = inp.spec()
        px = inp.read_image(sub, 0, 0, spec.nchannels, "float").reshape(spec.height, spec.width, spec.nchannels)
        for c, full in enumerate(spec.channelnames):
            names.append(full)
            layer, pass_name, chan = full.split(".")
            out.setdefault(pass_name, {})[chan] = px[..., c]
        sub += 1
    inp.close()
    passes = {p: np.stack([chans[c] for c in PASSES.get(p, "".join(chans))], -1) for p, chans in out.items()
              if p in PASSES}
    passes["_channels"] = names
    return passes


def _tiny(scene, samples=1, photons=2000):
    st = scene.stpm
    st.samples, st.photons_global, st.photons_caustic, st.k_nearest = samples, photons, photons, 20
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 32, 24, 100


def _render_to_exr(scene, path: Path) -> dict:
    """Render the scene with Blender and read back its multilayer EXR."""
    scene.render.filepath = str(path)
    scene.render.use_file_extension = False
    batch._set_format(scene.render.image_settings, "EXR")
    LAST_RENDER.clear()
    bpy.ops.render.render(write_still=True)
    return read_exr_passes(path)


def test_render_writes_every_pass_with_blender_channel_names(tmp_path):
    # The demo scene: glass sphere moving over a floor, motion blur on
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    assert scene.render.engine == "STPM" and scene.render.use_motion_blur
    _tiny(scene)
    p = _render_to_exr(scene, tmp_path / "demo.exr")
    for name, chans in PASSES.items():
        for c in chans:
            assert f"ViewLayer.{name}.{c}" in p["_channels"]
    assert set(LAST_RENDER["passes"]) == set(PASSES)
    for name in PASSES:
        assert p[name].shape[:2] == (24, 32) and np.all(np.isfinite(p[name]))
    # Combined = Direct + Indirect + Caustic + Emit, alpha 1 in the film
    parts = p["Direct"] + p["Indirect"] + p["Caustic"] + p["Emit"]
    np.testing.assert_allclose(p["Combined"][..., :3], parts, rtol=1e-4, atol=1e-5)
    assert p["Combined"][..., :3].mean() > 0
    # Orientation: the camera looks down at the floor, so the top row sees the sky
    depth = p["Depth"][..., 0]
    assert np.all(depth[0] > 1e9) and np.all(depth[-1] < 20.0)
    # The top three rows see only sky, above the sphere's whole path: Emit = world colour
    np.testing.assert_allclose(p["Emit"][:3], 0.05, rtol=1e-3)
    # The bottom rows see the static floor only: its normal is world +Z
    np.testing.assert_allclose(p["Normal"][-2:], np.broadcast_to([0, 0, 1], (2, 32, 3)), atol=1e-3)
    # The engine's own export (engine.frame_set) sampled the sphere across the shutter [0.75, 1.25]
    sphere = next(i for i in LAST_RENDER["scene"].instances if i.name == "GlassSphere")
    np.testing.assert_allclose(sphere.transform.matrices[:, 0, 3], (-0.75, -0.5, -0.25), atol=1e-5)
    assert scene.frame_current == 1
    # Statistics reach the caller
    assert LAST_RENDER["stats"]["export_s"] >= 0 and LAST_RENDER["stats"]["resolution"] in ([32, 24], (32, 24))


def test_adaptive_sampling_writes_the_sample_count_pass(tmp_path):
    """Sampling > Noise Threshold on: Blender's result gets a Sample Count pass (each pixel's samples,
    between the minimum and Samples), the render stats the mean."""
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    _tiny(scene, samples=12)
    scene.stpm.use_adaptive_sampling, scene.stpm.adaptive_min_samples = True, 4
    scene.stpm.adaptive_threshold = 0.05
    scene.render.filepath = str(tmp_path / "a.exr")
    scene.render.use_file_extension = False
    batch._set_format(scene.render.image_settings, "EXR")
    LAST_RENDER.clear()
    bpy.ops.render.render(write_still=True)
    assert "Sample Count" in LAST_RENDER["passes"]
    inp = oiio.ImageInput.open(str(tmp_path / "a.exr"))
    n, sub = None, 0
    while inp.seek_subimage(sub, 0):
        spec = inp.spec()
        px = inp.read_image(sub, 0, 0, spec.nchannels, "float").reshape(spec.height, spec.width, spec.nchannels)
        if "ViewLayer.Sample Count.X" in spec.channelnames:
            n = px[..., list(spec.channelnames).index("ViewLayer.Sample Count.X")]
        sub += 1
    inp.close()
    assert n is not None and n.shape == (24, 32)
    st = LAST_RENDER["stats"]
    assert n.min() >= 4 and n.max() <= 12 and abs(float(n.mean()) - st["samples_mean"]) < 1e-3
    assert st["adaptive"]["min_samples"] == 4


def test_cancel_stops_the_render(monkeypatch):
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    _tiny(scene)
    calls = []

    def cancel_requested(self):  # stands in for test_break (always False in background mode)
        calls.append(1)
        return len(calls) >= 2  # the user presses Esc shortly after the start

    monkeypatch.setattr(STPMRenderEngine, "cancel_requested", cancel_requested)
    LAST_RENDER.clear()
    bpy.ops.render.render()
    assert calls and len(calls) <= 3  # answered at the first check after the request
    assert LAST_RENDER == {}  # nothing written after a cancel


def test_persistent_data_keeps_the_static_bake_between_renders():
    """Blender's Render > Performance > Persistent Data: a second render of unchanged static geometry
    reuses the baked static scene; with it off nothing is kept."""
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    _tiny(scene, photons=200)
    reused = []
    for persistent in (True, True, False, False):
        scene.render.use_persistent_data = persistent
        LAST_RENDER.clear()
        bpy.ops.render.render()
        reused.append(LAST_RENDER["stats"]["caster"]["static_reused"])
    assert reused == [False, True, False, False]


def test_unsupported_node_warns_and_still_renders(tmp_path):
    scene = fresh()
    scene.render.engine = "STPM"
    _tiny(scene)
    add_camera(location=(0, -4, 1), rotation=(math.radians(80), 0, 0))
    toon, _ = node_material("Toon", "ShaderNodeBsdfToon")
    add_mesh("cube", "Odd", material=toon)
    add_light("POINT", energy=200.0, location=(0, -2, 3))
    p = _render_to_exr(scene, tmp_path / "toon.exr")
    assert any("ShaderNodeBsdfToon" in w for w in LAST_RENDER["warnings"])
    assert p["Combined"][..., :3].max() > 0  # the grey fallback is lit


def test_node_graph_messages_are_reported_once(tmp_path):
    """A graph with an unsupported shader: the exporter's compile message and the core's (the same
    text from shading_data) reach the render report once, not twice."""
    scene = fresh()
    scene.render.engine = "STPM"
    _tiny(scene, photons=0)
    add_camera(location=(0, -4, 1), rotation=(math.radians(80), 0, 0))
    mat = bpy.data.materials.new("ToonChecker")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    t = mat.node_tree
    out = next(n for n in t.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
    toon, mix = t.nodes.new("ShaderNodeBsdfToon"), t.nodes.new("ShaderNodeMixShader")
    chk = t.nodes.new("ShaderNodeTexChecker")
    t.links.new(chk.outputs["Fac"], mix.inputs["Fac"])
    t.links.new(toon.outputs[0], mix.inputs[1])
    t.links.new(t.nodes["Principled BSDF"].outputs[0], mix.inputs[2])
    t.links.new(mix.outputs[0], out.inputs["Surface"])
    add_mesh("cube", "Odd", material=mat)
    add_light("POINT", energy=200.0, location=(0, -2, 3))
    _render_to_exr(scene, tmp_path / "toon.exr")
    hits = [w for w in LAST_RENDER["warnings"] if "ShaderNodeBsdfToon" in w]
    assert len(hits) == 1, LAST_RENDER["warnings"]


def test_unbaked_node_is_named_once(tmp_path, monkeypatch):
    """An input that needs a bake (a Gabor texture, no bake cached): the exporter's bake report names
    it; the core's compiler message about the same node is not repeated (an artist's review saw
    both)."""
    monkeypatch.setenv("STPM_BAKE_CACHE", str(tmp_path / "bakes"))
    scene = fresh()
    scene.render.engine = "STPM"
    _tiny(scene, photons=0)
    add_camera(location=(0, -4, 1), rotation=(math.radians(80), 0, 0))
    mat = bpy.data.materials.new("GaborM")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    t = mat.node_tree
    gab, ramp = t.nodes.new("ShaderNodeTexGabor"), t.nodes.new("ShaderNodeValToRGB")
    t.links.new(gab.outputs[0], ramp.inputs["Fac"])           # the ramp makes it a node graph
    t.links.new(ramp.outputs["Color"], t.nodes["Principled BSDF"].inputs["Base Color"])
    add_mesh("cube", "G", material=mat)
    add_light("POINT", energy=200.0, location=(0, -2, 3))
    _render_to_exr(scene, tmp_path / "gabor.exr")
    hits = [w for w in LAST_RENDER["warnings"] if "Gabor" in w]
    assert len(hits) == 1, LAST_RENDER["warnings"]


def test_bad_setting_is_reported_not_raised_from_the_engine():
    scene = fresh()
    scene.render.engine = "STPM"
    _tiny(scene)
    add_camera()
    add_mesh("cube")
    scene.stpm.temporal_alpha = 0.5  # 0 or >= 1 only: the core's SettingsError
    LAST_RENDER.clear()
    try:
        bpy.ops.render.render()
    except RuntimeError as exc:  # Blender turns an ERROR report into an operator error
        assert "temporal_alpha" in str(exc)
    assert LAST_RENDER == {}


def test_batch_load_and_render_frames(tmp_path):
    scene, settings = batch.load_blend(DEMO, 1)
    assert settings["estimator"] == "TEMPORAL" and settings["samples"] >= 1
    assert (scene.shutter.open, scene.shutter.close) == (0.75, 1.25)  # CENTER, 0.5 frames
    import bpy
    assert scene.metadata["frame_range"] == [bpy.context.scene.frame_start, bpy.context.scene.frame_end]
    sphere = next(i for i in scene.instances if i.name == "GlassSphere")
    np.testing.assert_allclose(sphere.transform.matrices[[0, -1], 0, 3], (-0.75, -0.25), atol=1e-5)
    assert batch.parse_frames("1-3,7") == [1, 2, 3, 7]
    with pytest.raises(batch._core.StpmError):
        batch.parse_frames("3-1")
    with pytest.raises(batch._core.StpmError):
        batch.load_blend(tmp_path / "missing.blend")
    out = batch.render_blend(DEMO, "1-2", tmp_path / "shot_####.exr",
                             settings={"samples": 1, "photons_global": 1000, "photons_caustic": 1000},
                             resolution=(16, 12))
    assert [r["frame"] for r in out] == [1, 2]
    for r in out:
        assert Path(r["exr"]).name == f"shot_{r['frame']:04d}.exr" and Path(r["png"]).is_file()
        p = read_exr_passes(r["exr"])
        assert p["Combined"].shape == (12, 16, 4)


def _units_scene():
    """A diffuse floor under a point light, seen from straight above (no world)."""
    scene = fresh()
    floor, _ = node_material("Floor", "ShaderNodeBsdfDiffuse", Color=(0.5, 0.5, 0.5, 1))
    add_mesh("plane", "Floor", material=floor, size=20.0)
    add_camera(location=(0, 0, 4), rotation=(0, 0, 0), lens=35.0)
    add_light("POINT", energy=500.0, location=(0.5, 0.3, 2.0), shadow_soft_size=0.1)
    set_world((0, 0, 0), 0.0)
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 48, 36, 100
    return scene


def _floor_only(emit: np.ndarray) -> np.ndarray:
    """Pixels (H, W) bool whose 5x5 neighbourhood shows no light source (Emit = 0)."""
    lit = np.any(emit > 0, axis=-1)
    grown = np.zeros_like(lit)
    H, W = lit.shape
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            grown[max(dy, 0):H + min(dy, 0), max(dx, 0):W + min(dx, 0)] |= \
                lit[max(-dy, 0):H + min(-dy, 0), max(-dx, 0):W + min(-dx, 0)]
    return ~grown


def test_diffuse_scene_matches_cycles_brightness(tmp_path):
    # Cycles, CPU, no denoiser: the reference
    scene = _units_scene()
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples, scene.cycles.use_denoising = "CPU", 256, False
    scene.cycles.use_adaptive_sampling = False
    cycles = _render_to_exr(scene, tmp_path / "cycles.exr")["Combined"][..., :3]
    # STPM from the same scene
    scene.render.engine = "STPM"
    scene.stpm.samples, scene.stpm.photons_global, scene.stpm.photons_caustic = 64, 20000, 0
    p = _render_to_exr(scene, tmp_path / "stpm.exr")
    # Compare the lit floor (pixels that might see the light's own sphere are left out:
    # whether lights show to the camera is a separate question, see the next test)
    floor = _floor_only(p["Emit"])
    assert floor.mean() > 0.9
    stpm, ref = p["Combined"][..., :3][floor].mean(), cycles[floor].mean()
    print(f"mean brightness: STPM {stpm:.5f}, Cycles {ref:.5f}, ratio {stpm / ref:.4f}")
    assert stpm == pytest.approx(ref, rel=0.03), (stpm, ref)


def test_lights_are_hidden_from_the_camera_like_in_cycles(tmp_path):
    scene = _units_scene()
    scene.render.engine = "STPM"
    scene.stpm.samples, scene.stpm.photons_global, scene.stpm.photons_caustic = 4, 0, 0
    assert not bpy.data.objects["Light"].visible_camera  # Blender's default
    p = _render_to_exr(scene, tmp_path / "hidden.exr")
    assert LAST_RENDER["scene"].metadata["light_visible_camera"] == [False]
    assert p["Emit"].max() == 0.0
    # Switched on, the 0.1 m sphere shows with radiance I / (pi r^2) = 500 / (4 pi) / (0.01 pi) ~ 1267
    bpy.data.objects["Light"].visible_camera = True
    p = _render_to_exr(scene, tmp_path / "shown.exr")
    assert 100.0 < p["Emit"].max() <= 1267.0 * 1.001


def test_progressive_render_shows_each_pass_and_a_cancel_keeps_the_image(monkeypatch):
    """Method PROGRESSIVE through Blender: the render result is written after every pass (the image
    improves where the artist watches it), and Esc after some passes keeps them."""
    from addon import engine
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    _tiny(scene, photons=500)
    scene.stpm.method, scene.stpm.passes, scene.stpm.k_nearest = "PROGRESSIVE", 3, 10
    written = []
    real_write = engine.write_passes

    def counting_write(eng, passes, *args, **kwargs):
        written.append(float(np.asarray(passes["Combined"])[..., :3].mean()))
        return real_write(eng, passes, *args, **kwargs)

    monkeypatch.setattr(engine, "write_passes", counting_write)
    LAST_RENDER.clear()
    bpy.ops.render.render()
    prog = LAST_RENDER["stats"]["progressive"]
    assert prog["passes"] == 3 and prog["stopped_by"] == "passes"
    assert len(written) == 4                      # after each of the 3 passes, then the final result
    assert written[-1] == pytest.approx(written[-2])  # the last pass shown is the final image
    # Esc once two passes are on screen: the render stops and keeps them
    scene.stpm.passes = 50
    written.clear()
    monkeypatch.setattr(STPMRenderEngine, "cancel_requested", lambda self: len(written) >= 2)
    LAST_RENDER.clear()
    bpy.ops.render.render()
    prog = LAST_RENDER["stats"]["progressive"]
    assert prog["stopped_by"] == "cancelled" and prog["passes"] == 2, prog
    assert any("cancelled after 2 pass" in w for w in LAST_RENDER["warnings"])
