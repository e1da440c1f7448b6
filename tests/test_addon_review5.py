"""Fixes from the fifth artist review (an animated kitchen corner, review/make_interior5.py), through
the real bpy module: what ``stpm render`` of a .blend leaves out that ``blender -b -f`` renders (a
second view layer, the compositor) is named; geometry-nodes instances are named after their mesh.
"""
from __future__ import annotations

import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import add_camera, add_light, add_mesh, export_now, fresh  # noqa: E402

import addon  # noqa: E402
from addon import batch  # noqa: E402

addon.register()


def _save_layered(tmp_path, *, second_layer: bool, glare: bool, use_first: bool = True):
    """A floor, a cube, a camera and a light; optionally a second view layer (with a collection
    excluded, as the review's) and a compositor with a Glare node; saved, its path returned."""
    scene = fresh()
    add_camera()
    add_light("POINT", energy=300.0, location=(1, -1, 3))
    add_mesh("plane", "Floor", size=6)
    cube = add_mesh("cube", "Fruit", location=(0, 0, 1))
    coll = bpy.data.collections.new("FruitColl")
    scene.collection.children.link(coll)
    for c in cube.users_collection:
        c.objects.unlink(cube)
    coll.objects.link(cube)
    scene.view_layers[0].name = "Main"
    scene.view_layers[0].use = use_first
    if second_layer:
        vl = scene.view_layers.new("NoFruit")
        vl.layer_collection.children["FruitColl"].exclude = True
    if glare:
        tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
        scene.compositing_node_group = tree
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        rl, gl, out = (tree.nodes.new(t) for t in ("CompositorNodeRLayers", "CompositorNodeGlare", "NodeGroupOutput"))
        tree.links.new(rl.outputs["Image"], gl.inputs["Image"])
        tree.links.new(gl.outputs["Image"], out.inputs[0])
        scene.render.use_compositing = True
    path = tmp_path / "layered.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return path


@pytest.mark.parametrize("second_layer, glare, use_first, expect", [
    (False, False, True, ()),
    (True, False, True, ("view layers: Blender renders 2 of this file ('Main', 'NoFruit'); stpm exports the active "
                         "one, 'Main', alone",)),
    (False, True, True, ("compositor: its nodes (Glare) are not run by stpm",)),
    (True, False, False, ("view layers: Blender renders 1 of this file ('NoFruit'); stpm exports the active one, "
                          "'Main', alone",)),
])
def test_command_line_names_what_blender_would_render_besides(tmp_path, second_layer, glare, use_first, expect):
    # The review's kitchen (two view layers, a Glare compositor) came out of `stpm render` as one
    # layer named ViewLayer, without the glare, and without a word
    path = _save_layered(tmp_path, second_layer=second_layer, glare=glare, use_first=use_first)
    scene, _settings = batch.load_blend(path, 1)
    warnings = scene.metadata["warnings"]
    notes = [w for w in warnings if w.startswith(("view layers:", "compositor:"))]
    assert len(notes) == len(expect), warnings
    for text in expect:
        assert sum(w.startswith(text) for w in notes) == 1, warnings
    # the excluded collection stays in the exported (active) layer
    assert {i.name for i in scene.instances} == {"Floor", "Fruit"}


def test_geometry_nodes_instances_are_named_after_their_mesh():
    # The review's fruit scatter (Object Info, As Instance off -> Instance on Points) was listed by
    # the effects plan as 'FruitBed@FruitBed' four times
    fresh()
    add_camera()
    add_light()
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.1, location=(0, 0, -5))
    orange = bpy.context.object
    orange.name, orange.data.name = "Orange", "OrangeMesh"
    orange.hide_render = True
    bed = add_mesh("plane", "FruitBed", size=1)
    tree = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    gi, go = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    inst = tree.nodes.new("GeometryNodeInstanceOnPoints")
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = orange
    tree.links.new(gi.outputs[0], inst.inputs["Points"])      # the plane's 4 vertices
    tree.links.new(info.outputs["Geometry"], inst.inputs["Instance"])
    tree.links.new(inst.outputs["Instances"], go.inputs[0])
    bed.modifiers.new("Scatter", "NODES").node_group = tree
    out, _warnings = export_now()
    names = sorted(i.name for i in out.instances if "@" in i.name)      # (the source sphere is 'Orange')
    assert names == ["OrangeMesh@FruitBed"] * 4, names


def _region_scene():
    """A floor, a cube and a sphere under a point light, 192 x 128 (3 x 2 tiles of 64 pixels)."""
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = 192, 128
    add_camera()
    add_light("POINT", energy=400.0, location=(1, -2, 4))
    add_mesh("plane", "Floor", size=10)
    add_mesh("cube", "Box", location=(-1, 0, 1))
    add_mesh("sphere", "Ball", location=(1.2, 0, 0.8))
    return scene


@pytest.mark.parametrize("adaptive", [False, True])
def test_render_region_traces_its_pixels_only(adaptive):
    # The review's region covered 68 % of the frame and the whole frame was traced (a region, the
    # artist's way to look at a detail quickly, saved no time); now only its pixels (without
    # adaptive sampling: of the tile the region's edges cross, the region's pixels alone)
    import numpy as np
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    _region_scene()
    core, _w = export_now()
    settings = RenderSettings(samples=16, photons_global=3000, photons_caustic=0, seed=5,
                              use_adaptive_sampling=adaptive, adaptive_threshold=0.05, adaptive_min_samples=8)
    full = render(core, settings)
    win = (10, 20, 50, 60)                                  # x0, y0, x1, y1: inside the first tile
    part = render(core, settings, window=win)
    a, b = full.passes["Combined"], part.passes["Combined"]
    inside = np.zeros(a.shape[:2], bool)
    inside[20:60, 10:50] = True
    assert np.all(b[inside][:, 3] > 0)
    assert np.all(b[~inside] == 0)
    # other random numbers for the shading (adaptive: other batches; fixed: the tile's stream over
    # fewer paths): equal in the mean (tests/test_render_region.py tests it within noise)
    assert abs(b[inside][:, :3].mean() / a[inside][:, :3].mean() - 1) < 0.05
    if adaptive:
        assert part.stats["adaptive"]["samples_min"] >= 8
    else:
        assert part.stats["camera_rays"] == 40 * 40 * 16, part.stats["camera_rays"]
    assert part.stats["camera_rays"] < 0.3 * full.stats["camera_rays"], (part.stats["camera_rays"],
                                                                        full.stats["camera_rays"])


@pytest.mark.parametrize("method", ["PHOTON", "PROGRESSIVE"])
def test_region_pixels_have_the_whole_frames_camera_rays_with_depth_of_field(method):
    # Emission seen through a thin lens: the camera's film, time and lens uniforms are the only
    # randomness, so a region's pixels equal the whole frame's bit for bit, also where the region's
    # edges cross a tile (its uniforms, the lens's too, are drawn for the whole tile)
    import numpy as np
    import dof_scenes
    from stpm_core.render import render
    from stpm_core.settings import RenderSettings
    dof_scenes.build("f1.4_round")
    core, _w = export_now()
    st = RenderSettings(method=method, passes=2, samples=4, photons_global=0, photons_caustic=0, seed=2,
                        use_adaptive_sampling=False)
    full = render(core, st)
    part = render(core, st, window=(10, 5, 40, 30))          # 30 x 25 pixels of the 64 x 48 frame's one tile
    a, b = full.passes["Combined"][5:30, 10:40], part.passes["Combined"][5:30, 10:40]
    assert a[..., :3].std() > 0.1                              # (a picture: blurred checker edges)
    np.testing.assert_array_equal(a, b)
    assert part.stats["camera_rays"] == 30 * 25 * 4 * (2 if method == "PROGRESSIVE" else 1)


@pytest.mark.parametrize("method", ["PHOTON", "PROGRESSIVE"])
def test_f12_render_region_traces_its_pixels_only(method):
    # The Render panel's path: Render Region on (Crop off) -> the camera rays of its pixels only
    # (PROGRESSIVE traced the whole frame in every pass before)
    from addon.engine import LAST_RENDER
    scene = _region_scene()
    scene.render.engine = "STPM"
    s = scene.stpm
    s.samples, s.photons_global, s.photons_caustic, s.use_adaptive_sampling = 4, 2000, 0, False
    s.method, s.passes, s.time_limit, s.noise_threshold = method, 2, 0.0, 0.0
    rays = {}
    for border in (False, True):
        scene.render.use_border, scene.render.use_crop_to_border = border, False
        scene.render.border_min_x, scene.render.border_max_x = 0.05, 0.3
        scene.render.border_min_y, scene.render.border_max_y = 0.5, 0.9
        LAST_RENDER.clear()
        bpy.ops.render.render()
        rays[border] = LAST_RENDER["stats"]["camera_rays"]
    per_pixel = 4 * (2 if method == "PROGRESSIVE" else 1)
    assert rays[False] == 192 * 128 * per_pixel, rays
    # the region: columns 9..56, rows 64..114 from the bottom (Blender's int(fraction x size))
    assert rays[True] == 48 * 51 * per_pixel, rays


def test_a_frame_range_prints_each_warning_once(tmp_path):
    # `stpm render --frame 1-3` of the review's kitchen printed the view-layer and compositor lines
    # once per frame (a 250-frame shot: 500 identical lines)
    from test_cli_review import stpm
    path = _save_layered(tmp_path, second_layer=True, glare=True)
    r = stpm("render", path, "--frame", "1-2", "--samples", "1", "--photons-global", "0", "--photons-caustic", "0",
             "--resolution", "16x12", "-o", tmp_path / "r_####.exr", "--quiet")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "r_0001.exr").exists() and (tmp_path / "r_0002.exr").exists()
    lines = r.stderr.splitlines()
    for start in ("stpm: warning: view layers:", "stpm: warning: compositor:"):
        assert sum(line.startswith(start) for line in lines) == 1, r.stderr
