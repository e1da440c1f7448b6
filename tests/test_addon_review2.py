"""Fixes from the second artist review (a perfume-bottle product shot, review/make_bottle.py), each
through the real bpy module: a NaN keyframe, light node trees with a constant Emission or
Blackbody, a zoom during the shutter.
"""
from __future__ import annotations

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")
pytest.importorskip("OpenImageIO")

from test_addon_render import _render_to_exr, _tiny  # noqa: E402
from test_addon_scenes import add_camera, add_light, add_mesh, export_now, fresh, node_material, set_world  # noqa: E402
from cycles_ref import block_ztest, render_cycles, render_stpm  # noqa: E402

import addon  # noqa: E402
from addon.engine import LAST_RENDER  # noqa: E402

addon.register()


def _scene(box: bool = True):
    scene = fresh()
    scene.render.engine = "STPM"
    _tiny(scene, samples=2, photons=0)
    floor, _ = node_material("Floor", "ShaderNodeBsdfDiffuse")
    add_mesh("plane", "Floor", material=floor, size=8.0)
    add_camera()
    add_light("POINT", energy=800.0, location=(1, -1, 3))
    set_world((0.05, 0.05, 0.05), 1.0)
    return add_mesh("cube", "Box", location=(0, 0, 1)) if box else None


# 1. A NaN in a keyframe: Cycles leaves the object out; STPM failed the whole render with
#    "transform contains NaN or inf", naming neither the object nor the frame.
@pytest.mark.parametrize("channel", ["location", "scale"])
def test_nan_keyframe_leaves_the_object_out_with_a_warning_naming_it(tmp_path, channel):
    box = _scene()
    scene = bpy.context.scene
    box.keyframe_insert(channel, frame=1)
    getattr(box, channel)[0] = float("nan") if channel == "location" else float("inf")
    box.keyframe_insert(channel, frame=2)
    scene.render.use_motion_blur = True
    scene.frame_set(1)
    LAST_RENDER.clear()
    got = _render_to_exr(scene, tmp_path / "nan.exr")["Combined"]
    warns = [w for w in LAST_RENDER["warnings"] if "'Box'" in w]
    assert warns and "NaN or infinite" in warns[0] and "frame 1." in warns[0], LAST_RENDER["warnings"]
    # The image is the scene without the box (Cycles: 0.4338 both, measured in the review)
    _scene(box=False)
    want = _render_to_exr(bpy.context.scene, tmp_path / "none.exr")["Combined"]
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


def test_nan_light_transform_leaves_the_light_out():
    # Cycles: a second light at x = nan gives the image without it (0.5443 both, 32x24, 16 spp)
    _scene()
    scene = bpy.context.scene
    add_light("POINT", name="L2", energy=300.0, location=(-1, -1, 2)).location.x = float("nan")
    core, warnings = export_now(scene)
    assert [lt.name for lt in core.lights] == ["Light"]
    assert any("light 'L2'" in w and "NaN or infinite" in w for w in warnings), warnings


def test_nan_camera_transform_is_one_error_naming_the_camera():
    _scene()
    scene = bpy.context.scene
    scene.camera.location.x = float("nan")
    with pytest.raises(Exception, match="camera 'Cam'.*NaN or infinite"):
        export_now(scene)


# 2. Light node trees: Cycles multiplies the light by its Emission node's Color x Strength; STPM
#    ignored the tree (white, strength 1) whatever its constants.
def test_constant_light_emission_node_scales_colour_and_power():
    _scene()
    lamp = bpy.data.lights["Light"]
    lamp.color = (0.9, 0.8, 0.7)
    lamp.use_nodes = True
    em = lamp.node_tree.nodes["Emission"]
    em.inputs["Color"].default_value = (1.0, 0.3, 0.2, 1.0)
    em.inputs["Strength"].default_value = 2.5
    core, warnings = export_now(bpy.context.scene)
    light = core.lights[0]
    np.testing.assert_allclose(light.color, np.array([0.9, 0.8, 0.7]) * [1.0, 0.3, 0.2], rtol=1e-6)
    assert light.power == pytest.approx(800.0 * 2.5)
    assert not [w for w in warnings if "node tree" in w], warnings
    # A Blackbody of constant temperature on Color: Blender's blackbody colour (= the light's own
    # Temperature colour), Strength still counts, no warning
    bb = lamp.node_tree.nodes.new("ShaderNodeBlackbody")
    bb.inputs[0].default_value = 3000.0
    lamp.node_tree.links.new(bb.outputs[0], em.inputs["Color"])
    core, warnings = export_now(bpy.context.scene)
    assert core.lights[0].power == pytest.approx(800.0 * 2.5)
    probe = bpy.data.lights.new("probe", "POINT")
    probe.use_temperature, probe.temperature = True, 3000.0
    np.testing.assert_allclose(core.lights[0].color, np.array([0.9, 0.8, 0.7]) * probe.temperature_color[:],
                               rtol=3e-3)
    assert not [w for w in warnings if "node tree" in w], warnings
    # Anything else linked (a texture on Strength) is read as 1 and named
    tex = lamp.node_tree.nodes.new("ShaderNodeTexChecker")
    lamp.node_tree.links.new(tex.outputs["Fac"], em.inputs["Strength"])
    core, warnings = export_now(bpy.context.scene)
    assert core.lights[0].power == pytest.approx(800.0)
    assert any("Strength <- 'Checker Texture'" in w and "not evaluated" in w for w in warnings), warnings


def test_blackbody_table_is_blenders():
    from addon.export.blackbody import TABLE, blackbody, table_from_blender
    np.testing.assert_allclose(table_from_blender(), TABLE, rtol=1e-4, atol=1e-5)
    probe = bpy.data.lights.new("probe", "POINT")
    probe.use_temperature = True
    for t in (900.0, 1234.0, 2500.0, 5400.0, 6500.0, 9000.0, 11999.0, 20000.0):
        probe.temperature = t
        want = np.array(probe.temperature_color[:])
        assert np.abs(blackbody(t) - want).max() <= 2e-3 * want.max(), (t, blackbody(t), want)


@pytest.mark.parametrize("blackbody", [False, True])
def test_constant_light_emission_node_matches_cycles(tmp_path, blackbody):
    _scene()
    scene = bpy.context.scene
    scene.render.resolution_x, scene.render.resolution_y = 48, 32
    lamp = bpy.data.lights["Light"]
    lamp.use_nodes = True
    em = lamp.node_tree.nodes["Emission"]
    em.inputs["Color"].default_value = (1.0, 0.3, 0.2, 1.0)
    em.inputs["Strength"].default_value = 2.5
    if blackbody:       # the review's softbox: a 4000 K Blackbody (STPM rendered it white: red 0.71x Cycles)
        bb = lamp.node_tree.nodes.new("ShaderNodeBlackbody")
        bb.inputs[0].default_value = 4000.0
        lamp.node_tree.links.new(bb.outputs[0], em.inputs["Color"])
    seeds = (0, 1, 2)
    # Cycles without bounces against STPM without them: the Box has no material, a default Principled
    # in both (artist review 4), whose specular layer reflects the lit floor along STPM's glossy paths
    stpm, _ = render_stpm(scene, samples=16, seeds=seeds, glossy_bounces=0)
    cyc = render_cycles(scene, tmp_path, samples=16, seeds=seeds, max_bounces=0)
    r = block_ztest(stpm, cyc)
    assert r.z_abs_max < 4.0, r.summary()
    for c in range(3):    # per channel: the node's red tint
        assert stpm[..., c].mean() / cyc[..., c].mean() == pytest.approx(1.0, abs=0.03)


# 3. A camera zooming during the shutter: Cycles blurs the zoom (its field of view at each motion
#    step; measured: cubes at the frame's edge smeared from columns 6-12 to 0-10 at 64 px); STPM's
#    camera has one lens, and the zoom rendered sharp without a warning.
def test_lens_animated_during_the_shutter_is_warned():
    _scene()
    scene = bpy.context.scene
    scene.render.use_motion_blur = True
    scene.frame_set(1)
    assert not [w for w in export_now(scene)[1] if "animated during the shutter" in w]
    cam = scene.camera.data
    cam.keyframe_insert("lens", frame=1)
    cam.lens = 80.0
    cam.keyframe_insert("lens", frame=2)
    scene.frame_set(1)
    warns = [w for w in export_now(scene)[1] if "animated during the shutter" in w]
    assert warns and "camera 'Cam'" in warns[0] and "lens" in warns[0], warns
    scene.render.use_motion_blur = False          # no shutter, nothing to blur: no warning
    assert not [w for w in export_now(scene)[1] if "animated during the shutter" in w]


# 4. Film > Transparent > Transparent Glass (Cycles): a product shot's glass over a transparent
#    background; Cycles gives alpha 0.0625 at a glass sphere's centre (16 spp), STPM alpha 1, silently.
def test_transparent_glass_is_warned():
    _scene()
    scene = bpy.context.scene
    scene.render.film_transparent = True
    assert not [w for w in export_now(scene)[1] if "Transparent Glass" in w]
    scene.cycles.film_transparent_glass = True
    assert [w for w in export_now(scene)[1] if "Transparent Glass is not supported" in w]


# 5. Cycles' Motion Blur > Rolling Shutter: ignored without a word.
def test_rolling_shutter_is_warned():
    _scene()
    scene = bpy.context.scene
    scene.render.use_motion_blur = True
    assert not [w for w in export_now(scene)[1] if "Rolling Shutter" in w]
    scene.cycles.rolling_shutter_type = "TOP"
    assert [w for w in export_now(scene)[1] if "Rolling Shutter is not supported" in w]
    scene.render.use_motion_blur = False     # no shutter: nothing to roll
    assert not [w for w in export_now(scene)[1] if "Rolling Shutter" in w]


# 6. Object > Visibility: Shadow Catcher and Ray Visibility > Diffuse / Glossy / Transmission were
#    ignored without a word (Camera and Shadow off were warned already).
def test_shadow_catcher_and_ray_visibility_are_warned():
    box = _scene()
    scene = bpy.context.scene
    assert not [w for w in export_now(scene)[1] if "'Box'" in w]
    box.is_shadow_catcher = True
    box.visible_glossy = False
    warns = [w for w in export_now(scene)[1] if "'Box'" in w]
    assert any("Shadow Catcher is not supported" in w for w in warns), warns
    assert any("Ray Visibility > Glossy off is ignored" in w for w in warns), warns
