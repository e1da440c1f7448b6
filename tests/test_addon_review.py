"""Fixes from the add-on review (/work/review_addon r01..r09), each through the real bpy module.

Render Region, a non-camera scene camera, unexpected exceptions, world lighting,
hidden-from-render objects in the operators' export, stereoscopy, particle hair,
silently ignored settings, big image textures, resolution percentage and
missing images.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_addon_render import _render_to_exr, _tiny, read_exr_passes  # noqa: E402
from test_addon_scenes import add_camera, add_light, add_mesh, export_now, fresh, node_material, set_world  # noqa: E402

import addon  # noqa: E402
from addon import batch, engine  # noqa: E402
from addon.engine import LAST_RENDER  # noqa: E402

addon.register()


def _lit_scene(w=32, h=24, world=(0.0, 0.0, 0.0)):
    """Floor + cube + camera + point light, STPM, tiny settings, fixed seed."""
    scene = fresh()
    scene.render.engine = "STPM"
    _tiny(scene, samples=1, photons=500)
    scene.render.resolution_x, scene.render.resolution_y = w, h
    floor, _ = node_material("Floor", "ShaderNodeBsdfDiffuse")
    add_mesh("plane", "Floor", material=floor, size=8.0)
    add_mesh("cube", "Box", location=(0, 0, 1))
    add_camera()
    add_light("POINT", energy=800.0, location=(1, -1, 3))
    set_world(world, 1.0)
    return scene


def _render_ops(scene):
    """bpy.ops.render.render(); returns the text of an ERROR report ('' when none)."""
    LAST_RENDER.clear()
    try:
        bpy.ops.render.render()
    except RuntimeError as exc:  # Blender turns an ERROR report into an operator error
        return str(exc)
    return ""


# 1. Render Region
@pytest.mark.parametrize("crop", [True, False])
def test_render_region_writes_the_full_frames_pixels_at_the_region(tmp_path, crop):
    scene = _lit_scene(32, 24)
    full = _render_to_exr(scene, tmp_path / "full.exr")
    scene.render.use_border, scene.render.use_crop_to_border = True, crop
    r = scene.render
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.25, 0.75, 0.125, 0.5
    assert engine.border_region(r, 32, 24) == (8, 3, 16, 9)  # x, y from the bottom, w, h
    part = _render_to_exr(scene, tmp_path / "part.exr")
    assert LAST_RENDER["passes"]  # the render finished and wrote its passes
    rows = slice(24 - 3 - 9, 24 - 3)  # region rows counted from the top
    cols = slice(8, 24)
    for name in ("Combined", "Depth", "Normal", "Direct"):
        want = full[name][rows, cols]
        if crop:
            assert part[name].shape[:2] == (9, 16)
            got = part[name]
        else:  # Blender pastes the region into a full-size, otherwise empty frame
            assert part[name].shape[:2] == (24, 32)
            got = part[name][rows, cols]
            outside = np.ones((24, 32), bool)
            outside[rows, cols] = False
            if name == "Combined":  # (Blender fills Depth outside with its own far value)
                assert np.all(part[name][outside] == 0)
        if name in ("Depth", "Normal"):   # the region's camera rays are the whole frame's
            np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-7, err_msg=name)
        else:   # its shading draws other random numbers (tests/test_render_region.py): equal in the mean
            assert abs(got[..., :3].mean() / want[..., :3].mean() - 1) < 0.1, (name, got.mean(), want.mean())
    np.testing.assert_array_equal(got_alpha(part, crop, rows, cols), full["Combined"][rows, cols, 3])
    assert full["Combined"][rows, cols, :3].mean() > 0.01  # the region is not black


def got_alpha(part, crop, rows, cols):
    """The region's Combined alpha in a Render Region's EXR (cropped or not)."""
    return part["Combined"][..., 3] if crop else part["Combined"][rows, cols, 3]


def test_border_region_matches_blenders_rounding():
    scene = fresh()
    r = scene.render
    assert engine.border_region(r, 64, 48) is None  # off
    r.use_border = True
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.0, 1.0, 0.0, 1.0
    assert engine.border_region(r, 64, 48) is None  # the whole frame
    r.border_min_x, r.border_max_x, r.border_min_y, r.border_max_y = 0.1, 0.3, 0.33, 0.9
    assert engine.border_region(r, 29, 29) == (2, 9, 6, 17)  # (int)(0.1f * 29) = 2, ...


# 2. Scene camera that is not a camera; unexpected exceptions
@pytest.mark.parametrize("kind", ["EMPTY", "LIGHT"])
def test_non_camera_scene_camera_is_one_error_line(kind, capsys):
    scene = _lit_scene()
    if kind == "EMPTY":
        obj = bpy.data.objects.new("ViewEmpty", None)
        scene.collection.objects.link(obj)
    else:
        obj = add_light("SPOT", "ViewSpot", location=(0, -6, 2))
    obj.rotation_euler = (math.radians(75), 0, 0)
    scene.camera = obj
    err = _render_ops(scene)
    assert f"STPM: the scene camera {obj.name!r} is not a camera object" in err
    assert "Traceback" not in capsys.readouterr().err
    assert LAST_RENDER == {}


def test_unexpected_exception_is_reported_as_one_error_line(monkeypatch, capsys):
    scene = _lit_scene()

    def broken(*args, **kwargs):
        raise RuntimeError("injected failure")

    monkeypatch.setattr(engine, "export_scene", broken)
    err = _render_ops(scene)
    assert "STPM: render failed (RuntimeError: injected failure)" in err
    assert err.count("\n") <= 1  # one line
    assert "injected failure" in capsys.readouterr().err  # the traceback stays in the console
    assert LAST_RENDER == {}


def test_kernels_unavailable_is_one_error_line_in_the_render_report(monkeypatch, capsys):
    """numba missing or disabled: Blender's render report shows the one line naming the cause."""
    from stpm_core import kernels
    scene = _lit_scene()
    monkeypatch.setattr(kernels, "AVAILABLE", False)
    monkeypatch.setattr(kernels, "IMPORT_ERROR", "ModuleNotFoundError: No module named 'numba'")
    monkeypatch.setattr(kernels, "_CHECKED", False)
    err = _render_ops(scene)
    assert "STPM: the compiled kernels need numba, which is unavailable here (ModuleNotFoundError" in err
    assert err.count("\n") <= 1
    assert "Traceback" not in capsys.readouterr().err
    assert LAST_RENDER == {}


# 9. Resolution percentage
@pytest.mark.parametrize("w, h, pct", [(100, 100, 29), (90, 60, 70)])
def test_resolution_percentage_matches_blenders_size(tmp_path, w, h, pct):
    scene = _lit_scene()
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = w, h, pct
    scene.stpm.photons_global = scene.stpm.photons_caustic = 0
    p = _render_to_exr(scene, tmp_path / "pct.exr")
    size = (w * pct // 100, h * pct // 100)
    assert tuple(LAST_RENDER["scene"].resolution) == size
    assert p["Combined"].shape[:2] == (size[1], size[0])
    assert np.all(p["Combined"][..., 3] == 1.0)  # every pixel written, including the last row and column


# 3. World lighting
def test_world_lights_the_scene_as_in_cycles(tmp_path):
    """A diffuse sphere under a constant world and no lamp: radiance rho L, as Cycles gives (the review
    measured Cycles 1.001 for rho = 1, L = 1; STPM rendered it black before the world became a light)."""
    fresh()
    scene = bpy.context.scene
    scene.render.engine = "STPM"
    _tiny(scene, samples=4, photons=500)
    scene.render.resolution_x, scene.render.resolution_y = 32, 32
    mat, bsdf = node_material("White", "ShaderNodeBsdfDiffuse")
    bsdf.inputs["Color"].default_value = (0.5, 0.5, 0.5, 1.0)
    add_mesh("sphere", "Ball", material=mat, segments=32, ring_count=16)
    add_camera()
    set_world((1.0, 1.0, 1.0), 0.8)
    _, warnings = export_now()
    assert not any("does not light" in w or "no lights" in w for w in warnings), warnings
    p = _render_to_exr(scene, tmp_path / "world.exr")
    ball = p["Emit"][..., 0] == 0.0                            # pixels the sphere covers wholly (no background)
    assert ball.sum() > 50
    np.testing.assert_allclose(p["Combined"][ball][:, :3], 0.5 * 0.8, rtol=0.01)
    np.testing.assert_allclose(p["Combined"][~ball & (p["Direct"][..., 0] == 0)][:, :3], 0.8)  # background: L


# 4. The operators' export sees what F12 renders
def _visibility_scene():
    """Objects and collections whose viewport and render visibility differ, and a Subdivision modifier
    with viewport level 0 / render level 2."""
    scene = _lit_scene()
    add_mesh("cube", "HiddenFromRender", location=(2, 0, 1)).hide_render = True
    add_mesh("cube", "EyeHidden", location=(0, 2, 1)).hide_set(True)
    add_mesh("cube", "MonitorHidden", location=(0, -2, 1)).hide_viewport = True
    sub = add_mesh("cube", "Subdivided", location=(-2, 0, 1))
    mod = sub.modifiers.new("Sub", "SUBSURF")
    mod.levels, mod.render_levels = 0, 2
    off = sub.modifiers.new("Wire", "WIREFRAME")
    off.show_render = False  # viewport only: must not be exported
    for name, flags in (("NoRenderColl", {"hide_render": True}), ("NoViewportColl", {"hide_viewport": True}),
                        ("EyeColl", {})):
        coll = bpy.data.collections.new(name)
        scene.collection.children.link(coll)
        for k, v in flags.items():
            setattr(coll, k, v)
        bpy.ops.mesh.primitive_cube_add(location=(3, 3, 1))
        obj = bpy.context.object
        obj.name = "In" + name
        for c in list(obj.users_collection):
            c.objects.unlink(obj)
        coll.objects.link(obj)
    bpy.context.view_layer.layer_collection.children["EyeColl"].hide_viewport = True
    return scene


def _shapes(stpm_scene) -> dict:
    return {i.name: stpm_scene.meshes[i.mesh].triangles.shape[0] for i in stpm_scene.instances}


def test_operator_export_has_the_same_objects_as_the_render():
    scene = _visibility_scene()
    assert _render_ops(scene) == ""
    rendered = _shapes(LAST_RENDER["scene"])
    assert set(rendered) == {"Floor", "Box", "EyeHidden", "MonitorHidden", "Subdivided", "InNoViewportColl",
                             "InEyeColl"}
    assert rendered["Subdivided"] == 6 * 16 * 2  # render level 2, no wireframe
    exported, _settings = batch.export_current(scene)
    assert _shapes(exported) == rendered
    # the user's viewport flags are back
    assert bpy.data.objects["EyeHidden"].hide_get() and bpy.data.objects["MonitorHidden"].hide_viewport
    assert bpy.data.collections["NoViewportColl"].hide_viewport
    assert bpy.context.view_layer.layer_collection.children["EyeColl"].hide_viewport
    mods = bpy.data.objects["Subdivided"].modifiers
    assert mods["Sub"].levels == 0 and mods["Wire"].show_viewport
    assert _shapes(export_now()[0])["Subdivided"] != rendered["Subdivided"]  # the viewport itself is unchanged


def test_compute_plan_operator_exports_render_visibility(monkeypatch):
    scene = _visibility_scene()
    plan_mod = addon._core.sub("plan")
    seen = []
    real = plan_mod.make_plan

    def spy(stpm_scene, settings):
        seen.append(set(_shapes(stpm_scene)))
        return real(stpm_scene, settings)

    monkeypatch.setattr(plan_mod, "make_plan", spy)
    assert bpy.ops.stpm.compute_plan() == {"FINISHED"}
    assert seen == [{"Floor", "Box", "EyeHidden", "MonitorHidden", "Subdivided", "InNoViewportColl", "InEyeColl"}]
    assert scene.get("stpm_plan")


# 5. Stereoscopy
def test_stereo_views_both_get_the_image_and_a_warning(tmp_path):
    import OpenImageIO as oiio
    scene = _lit_scene(world=(0.05, 0.05, 0.05))
    scene.render.use_multiview, scene.render.views_format = True, "STEREO_3D"
    scene.render.filepath = str(tmp_path / "stereo.png")
    scene.render.use_file_extension = False
    batch._set_format(scene.render.image_settings, "PNG")
    scene.render.image_settings.views_format = "INDIVIDUAL"
    LAST_RENDER.clear()
    bpy.ops.render.render(write_still=True)
    eyes = {}
    for eye in "LR":
        px = oiio.ImageBuf(str(tmp_path / f"stereo_{eye}.png")).get_pixels(oiio.FLOAT)
        assert px.shape == (24, 32, 4)
        assert px[..., 3].min() == 1.0 and px[..., :3].mean() > 0.05  # written, not empty
        eyes[eye] = px
    np.testing.assert_array_equal(eyes["L"], eyes["R"])  # both eyes: the scene camera's mono image
    assert any("stereoscopy" in w and "left, right" in w for w in LAST_RENDER["warnings"])


# 6. Particle-system hair
@pytest.mark.parametrize("render_type, warned", [("PATH", True), ("NONE", False)])
def test_particle_hair_is_warned(render_type, warned):
    scene = _lit_scene()
    ball = add_mesh("sphere", "Hairy", location=(0, 0, 1))
    ps = ball.modifiers.new("Hair", "PARTICLE_SYSTEM").particle_system.settings
    ps.type, ps.count, ps.hair_length, ps.render_type = "HAIR", 50, 0.5, render_type
    assert _render_ops(scene) == ""
    hits = [w for w in LAST_RENDER["warnings"] if "hair particles" in w and "'Hairy'" in w]
    assert len(hits) == int(warned), LAST_RENDER["warnings"]
    assert "Hairy" in {i.name for i in LAST_RENDER["scene"].instances}  # the emitter mesh itself still renders


def test_volume_object_is_warned_not_skipped_silently():
    """Add > Volume (an OpenVDB Volume object) was dropped from the export without a warning
    (artist review, review/odd_inputs.py); Cycles renders it."""
    scene = fresh()
    add_camera(); add_light(); set_world((0.1, 0.1, 0.1))
    bpy.ops.object.volume_add(location=(0, 0, 1))
    bpy.context.object.name = "Smoke"
    core = export_now(scene)
    core = core[0] if isinstance(core, tuple) else core
    hits = [w for w in core.metadata.get("warnings", []) if "'Smoke'" in w and "Volume objects are not rendered" in w]
    assert len(hits) == 1, core.metadata.get("warnings")


# 7. Settings a Cycles render honours and STPM ignores: each one warned
def _bump(obj):
    tree = obj.data.materials[0].node_tree
    bump = tree.nodes.new("ShaderNodeBump")
    noise = tree.nodes.new("ShaderNodeTexNoise")
    tree.links.new(noise.outputs[0], bump.inputs["Height"])
    tree.links.new(bump.outputs[0], tree.nodes["Principled BSDF"].inputs["Normal"])


def _displacement(obj):
    tree = obj.data.materials[0].node_tree
    disp = tree.nodes.new("ShaderNodeDisplacement")
    tree.links.new(tree.nodes.new("ShaderNodeTexNoise").outputs[0], disp.inputs["Height"])
    tree.links.new(disp.outputs[0], tree.nodes["Material Output"].inputs["Displacement"])


def _holdout_collection(obj):
    coll = bpy.data.collections.new("Masks")
    bpy.context.scene.collection.children.link(coll)
    bpy.context.view_layer.layer_collection.children["Masks"].holdout = True


IGNORED = {
    "camera off": (lambda o: setattr(o, "visible_camera", False), "'Box': Ray Visibility > Camera off is ignored"),
    "shadow off": (lambda o: setattr(o, "visible_shadow", False), "'Box': Ray Visibility > Shadow off is ignored"),
    "holdout object": (lambda o: setattr(o, "is_holdout", True), "'Box': Holdout is not supported"),
    "holdout collection": (_holdout_collection, "'Masks': Holdout is not supported"),
    "cast shadow off": (lambda o: setattr(bpy.data.lights["Light"], "use_shadow", False),
                        "'Light': Cast Shadow off is ignored"),
    "negative power": (lambda o: setattr(bpy.data.lights["Light"], "energy", -800.0),
                       "'Light': negative power -800 W is not supported"),
    "displacement": (_displacement, "Material Output Displacement is ignored"),
}


@pytest.mark.parametrize("case", list(IGNORED))
def test_ignored_settings_are_warned(case):
    change, text = IGNORED[case]
    _lit_scene()
    box = bpy.data.objects["Box"]
    mat, _ = node_material("BoxMat", "ShaderNodeBsdfPrincipled")
    box.data.materials.append(mat)
    _scene, before = export_now()
    assert not any(text in w for w in before)
    change(box)
    scene, after = export_now()
    assert sum(text in w for w in after) == 1, after
    if case == "negative power":
        assert scene.lights[0].power == 0.0


def test_bump_from_noise_is_rendered_not_warned():
    # Since the node interpreter: a Noise -> Bump -> Principled Normal tree exports as a graph
    # (rendered per hit) and is no longer reported as ignored
    _lit_scene()
    box = bpy.data.objects["Box"]
    mat, _ = node_material("BoxMat", "ShaderNodeBsdfPrincipled")
    box.data.materials.append(mat)
    _bump(box)
    scene, warnings = export_now()
    assert next(m for m in scene.materials if m.name == "BoxMat").graph is not None
    assert not any("Bump" in w for w in warnings), warnings


def test_unproduced_view_layer_passes_are_listed_in_one_warning():
    scene = _lit_scene()
    scene.stpm.photons_global = scene.stpm.photons_caustic = 0
    assert _render_ops(scene) == ""
    assert not any("passes STPM does not produce" in w for w in LAST_RENDER["warnings"])
    vl = bpy.context.view_layer
    vl.use_pass_mist = vl.use_pass_ambient_occlusion = vl.use_pass_diffuse_direct = True
    vl.use_pass_object_index = vl.use_pass_z = vl.use_pass_normal = True  # Depth and Normal are produced
    assert _render_ops(scene) == ""
    hits = [w for w in LAST_RENDER["warnings"] if "passes STPM does not produce" in w]
    assert len(hits) == 1
    for name in ("Mist", "Ambient Occlusion", "Diffuse Direct", "Object Index"):
        assert name in hits[0]
    listed = hits[0].split("stay empty:")[1].split("(STPM writes")[0]
    assert "Z" not in listed.split(", ") and "Normal" not in listed


# 8. Big image textures: a strided sample, cached
def _gradient_image(tmp_path, w=1100, h=700):
    """An 8-bit sRGB image with a smooth gradient and a fine checker, saved and reloaded (not dirty)."""
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    px = np.ones((h, w, 4), np.float32)
    px[..., 0] = x / (w - 1)
    px[..., 1] = y / (h - 1)
    px[..., 2] = 0.2 + 0.6 * ((x.astype(int) + y.astype(int)) % 2)  # 1-pixel checker
    img = bpy.data.images.new("Gradient", w, h)
    img.pixels.foreach_set(px.reshape(-1))
    img.filepath_raw = str(tmp_path / "gradient.png")
    img.file_format = "PNG"
    img.save()
    bpy.data.images.remove(img)
    img = bpy.data.images.load(str(tmp_path / "gradient.png"))
    full = np.empty(w * h * 4, np.float32)
    img.pixels.foreach_get(full)
    rgb = full.reshape(-1, 4)[:, :3].astype(np.float64)
    linear = np.where(rgb <= 0.04045, rgb / 12.92, ((rgb + 0.055) / 1.055) ** 2.4)
    return img, linear.mean(axis=0)


def test_image_mean_is_a_cached_strided_sample_within_one_percent(tmp_path, monkeypatch):
    from addon.export import materials
    _lit_scene()
    img, full_mean = _gradient_image(tmp_path)
    assert not img.is_dirty and img.size[0] * img.size[1] > materials.MAX_MEAN_PIXELS  # the stride is used
    materials._IMAGE_MEANS.clear()
    calls = []
    real = materials.sampled_mean
    monkeypatch.setattr(materials, "sampled_mean", lambda image, *a: calls.append(image.name) or real(image, *a))
    tex, shader = node_material("Tex", "ShaderNodeBsdfDiffuse")
    node = tex.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = img
    tex.node_tree.links.new(node.outputs["Color"], shader.inputs["Color"])
    bpy.data.objects["Box"].data.materials.append(tex)
    for _ in range(2):  # two exports (two renders): the pixels are read once
        stpm_scene, warnings = export_now()
        got = next(m for m in stpm_scene.materials if m.name == "Tex").base_color
        np.testing.assert_allclose(got, full_mean, rtol=0.01)
    assert calls == ["gradient.png"]
    # the texture itself renders from its texels (a node graph), so no mean-colour warning
    assert next(m for m in stpm_scene.materials if m.name == "Tex").graph is not None
    assert not any("approximated by its mean colour" in w for w in warnings)
    # an image with unsaved edits is read again
    img.pixels[0] = 0.5
    assert img.is_dirty
    export_now()
    assert calls == ["gradient.png", "gradient.png"]


# 10. Missing image files; EEVEE-only Material Output
def test_missing_image_file_is_named_and_magenta(tmp_path):
    _lit_scene()
    gone = tmp_path / "textures" / "gone.png"
    img = bpy.data.images.new("Gone", 4, 4)
    img.source, img.filepath = "FILE", str(gone)
    tex, shader = node_material("Tex", "ShaderNodeBsdfDiffuse")
    node = tex.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = img
    tex.node_tree.links.new(node.outputs["Color"], shader.inputs["Color"])
    bpy.data.objects["Box"].data.materials.append(tex)
    scene, warnings = export_now()
    mat = next(m for m in scene.materials if m.name == "Tex")
    np.testing.assert_array_equal(mat.base_color, [1.0, 0.0, 1.0])
    hits = [w for w in warnings if "'Gone'" in w]
    assert len(hits) == 1 and str(gone) in hits[0] and "missing" in hits[0] and "magenta" in hits[0]


def _two_outputs(targets):
    """A material with one Diffuse + Material Output per target: red for the first, green for the second, ..."""
    mat = bpy.data.materials.new("Outs")
    tree = mat.node_tree
    for n in list(tree.nodes):
        tree.nodes.remove(n)
    outs = []
    for target, colour in zip(targets, ((1, 0, 0, 1), (0, 1, 0, 1))):
        out = tree.nodes.new("ShaderNodeOutputMaterial")
        out.target = target
        diff = tree.nodes.new("ShaderNodeBsdfDiffuse")
        diff.inputs["Color"].default_value = colour
        tree.links.new(diff.outputs[0], out.inputs["Surface"])
        outs.append(out)
    return mat, outs


def test_eevee_only_material_output_is_said_and_all_output_preferred():
    _lit_scene()
    box = bpy.data.objects["Box"]
    mat, outs = _two_outputs(["EEVEE", "ALL"])
    outs[0].is_active_output = True  # the EEVEE one is active: STPM still takes the All one
    box.data.materials.append(mat)
    scene, warnings = export_now()
    np.testing.assert_allclose(next(m for m in scene.materials if m.name == "Outs").base_color, [0, 1, 0])
    assert not any("EEVEE" in w for w in warnings)
    # only an EEVEE output: used, and said
    mat.node_tree.nodes.remove(outs[1])
    scene, warnings = export_now()
    np.testing.assert_allclose(next(m for m in scene.materials if m.name == "Outs").base_color, [1, 0, 0])
    hits = [w for w in warnings if "EEVEE" in w]
    assert len(hits) == 1 and "target EEVEE" in hits[0] and "'Outs'" in hits[0]


def _env_world(image):
    world = bpy.data.worlds.new("EnvWorld")
    if bpy.app.version < (5, 0, 0):
        world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    env = nodes.new("ShaderNodeTexEnvironment")
    env.image = image
    links.new(env.outputs["Color"], nodes["Background"].inputs["Color"])
    nodes["Background"].inputs["Strength"].default_value = 2.0
    bpy.context.scene.world = world
    return world


def test_environment_texture_exports_its_image_and_its_mean_over_the_sphere():
    """An equirectangular sky bright above the horizon only: the image itself is exported (row 0 at
    the bottom), the Background strength kept, and the world's mean radiance over directions is
    half its value (rows weighted by solid angle); a plain pixel mean would say the same here, so
    the image is also bright in a polar cap only, where the two differ."""
    fresh()
    add_camera()
    add_mesh("plane", "Floor")
    img = bpy.data.images.new("sky", 64, 32, float_buffer=True)
    px = np.zeros((32, 64, 4), np.float32)
    px[..., 3] = 1.0
    px[16:, :, :3] = (1.0, 0.5, 0.25)                       # rows 16..31: the upper hemisphere
    img.pixels.foreach_set(px.ravel())
    _env_world(img)
    scene, warnings = export_now()
    assert scene.world.image is not None and scene.world.image.shape == (32, 64, 3)
    np.testing.assert_allclose(scene.world.image, px[..., :3], rtol=1e-6)
    np.testing.assert_allclose(scene.world.radiance, (1.0, 0.5, 0.25), rtol=1e-3)   # strength 2 x mean 1/2
    assert scene.world.strength == 2.0
    assert not any("mean radiance" in w for w in warnings), warnings
    # A cap: only the top 4 rows (latitude above 67.5 deg) bright: solid-angle share 1 - sin(67.5 deg)
    px[..., :3] = 0.0
    px[28:, :, :3] = 1.0
    img.pixels.foreach_set(px.ravel())
    img.update()
    scene, _ = export_now()
    want = 0.5 * (1 - np.sin(np.radians(67.5)))             # 0.0381, the plain pixel mean is 0.125
    np.testing.assert_allclose(scene.world.radiance, 2.0 * want, rtol=1e-6)
