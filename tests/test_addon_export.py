"""Blender -> stpm_core scene export, checked field by field against what was built."""
from __future__ import annotations

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import (add_camera, add_light, add_mesh, export_now, fresh,  # noqa: E402
                               linear_keys, node_material, set_world)


def _moving_cube(frame: int, *, shutter: float, position: str):
    """A cube whose x equals the frame number (linear keys), the scene at ``frame``."""
    scene = fresh()
    add_camera()
    cube = add_mesh("cube", "Mover")
    for f in (frame - 3, frame + 3):
        cube.location.x = float(f)
        cube.keyframe_insert("location", index=0, frame=f)
    linear_keys(cube)
    scene.render.use_motion_blur = True
    scene.render.motion_blur_shutter = shutter
    scene.render.motion_blur_position = position
    scene.frame_set(frame)
    return scene, cube


def _instance(scene, name):
    return next(i for i in scene.instances if i.name == name)


@pytest.mark.parametrize("position, expect_open", [("START", 5.0), ("CENTER", 4.75), ("END", 4.5)])
@pytest.mark.parametrize("steps", [3, 5])
def test_motion_samples_sit_at_the_shutter_subframes(position, expect_open, steps):
    # x(frame) = frame, so each sampled matrix reveals the subframe it was taken at
    _moving_cube(5, shutter=0.5, position=position)
    out, warnings = export_now(motion_steps=steps)
    assert out.shutter.open == pytest.approx(expect_open) and out.shutter.close == pytest.approx(expect_open + 0.5)
    tr = _instance(out, "Mover").transform
    np.testing.assert_allclose(tr.times, np.linspace(0, 1, steps))
    np.testing.assert_allclose(tr.matrices[:, 0, 3], expect_open + 0.5 * tr.times, atol=1e-5)
    # In between the steps the core interpolates: still x = frame for linear motion
    np.testing.assert_allclose(tr.at(np.array([0.3]))[0, 0, 3], expect_open + 0.15, atol=1e-5)
    # The frame is restored afterwards
    assert bpy.context.scene.frame_current == 5 and bpy.context.scene.frame_subframe == 0.0


def test_static_objects_and_motion_blur_off_carry_no_motion():
    scene, _ = _moving_cube(5, shutter=0.5, position="CENTER")
    add_mesh("plane", "Still", location=(0, 0, -1))
    out, _ = export_now()
    assert _instance(out, "Still").transform.is_static
    assert not _instance(out, "Mover").transform.is_static
    scene.render.use_motion_blur = False
    out, _ = export_now()
    assert out.shutter.is_instant and not out.has_motion
    assert _instance(out, "Mover").transform.matrices[0, 0, 3] == pytest.approx(5.0)


def test_per_object_motion_blur_toggle():
    _, cube = _moving_cube(5, shutter=1.0, position="CENTER")
    if not hasattr(cube, "cycles") or not hasattr(cube.cycles, "use_motion_blur"):
        pytest.skip("object.cycles.use_motion_blur absent (Cycles not registered)")
    cube.cycles.use_motion_blur = False
    out, _ = export_now()
    tr = _instance(out, "Mover").transform
    assert tr.is_static and tr.matrices[0, 0, 3] == pytest.approx(5.0)


def test_shutter_curve_becomes_the_time_density():
    scene, _ = _moving_cube(5, shutter=1.0, position="CENTER")
    cm = scene.render.motion_blur_shutter_curve
    pts = cm.curves[0].points
    while len(pts) > 2:
        pts.remove(pts[1])
    pts[0].location, pts[1].location = (0.0, 0.0), (1.0, 0.0)
    pts.new(0.5, 1.0)
    for p in pts:
        p.handle_type = "VECTOR"  # a straight-sided triangle
    cm.update()
    out, _ = export_now()
    curve = out.shutter.curve
    assert curve is not None
    u = np.linspace(0, 1, len(curve))
    np.testing.assert_allclose(curve, 1 - np.abs(2 * u - 1), atol=1e-3)
    # The triangle density has CDF(u) = 2 u^2 for u < 0.5: 12.5 % of the times fall before u = 0.25
    assert out.shutter.sample(np.array([0.125]))[0] == pytest.approx(0.25, abs=1e-3)


def test_deformation_is_sampled_per_step():
    # A shape key lifts every vertex by 1; its value goes 0 -> 1 over frames 4 -> 6
    scene = fresh()
    add_camera()
    obj = add_mesh("plane", "Cloth")
    obj.shape_key_add(name="Basis")
    key = obj.shape_key_add(name="Up")
    for p in key.data:
        p.co.z += 1.0
    for f, v in ((4, 0.0), (6, 1.0)):
        key.value = v
        key.keyframe_insert("value", frame=f)
    linear_keys(obj.data.shape_keys)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 1.0
    scene.frame_set(5)
    out, warnings = export_now()
    mesh = out.meshes[_instance(out, "Cloth").mesh]
    assert mesh.is_deforming and warnings == []
    np.testing.assert_allclose(mesh.vertex_times, [0, 0.5, 1])
    np.testing.assert_allclose(mesh.vertices[:, :, 2], np.array([[0.25], [0.5], [0.75]]).repeat(4, 1), atol=1e-6)
    assert mesh.normals is None  # a flat plane (smooth deforming meshes: test_cycles_deforming_normals)
    assert _instance(out, "Cloth").transform.is_static


def test_changing_vertex_count_warns_and_keeps_the_frame_shape():
    scene = fresh()
    add_camera()
    obj = add_mesh("sphere", "Melting", segments=16, ring_count=8)
    mod = obj.modifiers.new("Decimate", "DECIMATE")
    for f, ratio in ((4, 1.0), (6, 0.2)):
        mod.ratio = ratio
        mod.keyframe_insert("ratio", frame=f)
    linear_keys(obj)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 1.0
    scene.frame_set(5)
    n_frame = len(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()).data.vertices)
    out, warnings = export_now()
    mesh = out.meshes[_instance(out, "Melting").mesh]
    assert not mesh.is_deforming and mesh.vertices.shape == (n_frame, 3)
    assert any("vertex count changes" in w for w in warnings)


def test_camera_fields_and_motion():
    scene = fresh()
    cam = add_camera(location=(1, -5, 2), lens=42.0, sensor_width=30.0, sensor_height=20.0,
                     sensor_fit="VERTICAL", shift_x=0.1, shift_y=-0.2, clip_start=0.2, clip_end=50.0)
    cam.scale = (2, 2, 2)  # Blender ignores camera scale; so must we
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 200, 100, 50
    add_mesh("cube")
    out, _ = export_now()
    c = out.camera
    assert (c.type, c.lens, c.sensor_width, c.sensor_height, c.sensor_fit) == ("PERSP", 42.0, 30.0, 20.0, "VERTICAL")
    assert (c.shift_x, c.shift_y) == pytest.approx((0.1, -0.2))
    assert (c.clip_start, c.clip_end) == pytest.approx((0.2, 50.0))
    assert out.resolution == (100, 50)
    M = c.transform.matrices[0]
    np.testing.assert_allclose(np.linalg.norm(M[:3, :3], axis=0), 1.0, atol=1e-6)
    np.testing.assert_allclose(M[:3, 3], (1, -5, 2), atol=1e-6)
    # Orthographic, and a camera that moves during the shutter
    cam.data.type, cam.data.ortho_scale = "ORTHO", 7.5
    for f, y in ((0, -10.0), (2, -6.0)):
        cam.location.y = y
        cam.keyframe_insert("location", index=1, frame=f)
    linear_keys(cam)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 1.0
    scene.frame_set(1)
    out, _ = export_now()
    assert out.camera.type == "ORTHO" and out.camera.ortho_scale == 7.5
    np.testing.assert_allclose(out.camera.transform.matrices[:, 1, 3], [-9, -8, -7], atol=1e-5)


def test_light_units_and_shapes():
    fresh()
    add_camera()
    add_mesh("plane")
    add_light("POINT", "P", energy=100.0, shadow_soft_size=0.2, use_soft_falloff=False, color=(1.0, 0.5, 0.25))
    add_light("SPOT", "S", energy=50.0, spot_size=math.radians(40), spot_blend=0.3, exposure=1.0)
    area = add_light("AREA", "A", energy=20.0, shape="RECTANGLE", size=2.0, size_y=0.5)
    area.scale = (2.0, 1.0, 1.0)
    add_light("AREA", "N", energy=10.0, shape="DISK", size=2.0, normalize=False)
    add_light("SUN", "Sun", energy=3.0, angle=math.radians(1.0))
    out, _ = export_now()
    L = {l.name: l for l in out.lights}
    assert (L["P"].type, L["P"].power, L["P"].radius, L["P"].use_soft_falloff) == ("POINT", 100.0, pytest.approx(0.2), False)
    np.testing.assert_allclose(L["P"].color, (1.0, 0.5, 0.25))
    assert L["S"].power == pytest.approx(100.0)  # exposure 1 doubles it, as in Cycles
    assert (L["S"].spot_size, L["S"].spot_blend) == (pytest.approx(math.radians(40)), pytest.approx(0.3))
    assert (L["A"].shape, L["A"].size, L["A"].size_y, L["A"].power) == ("RECTANGLE", pytest.approx(4.0), pytest.approx(0.5), 20.0)
    np.testing.assert_allclose(np.linalg.norm(L["A"].transform.matrices[0, :3, :3], axis=0), 1.0, atol=1e-6)
    assert L["N"].power == pytest.approx(10.0 * math.pi)  # not normalised: per m^2 of a 2 m disk
    assert (L["Sun"].type, L["Sun"].power, L["Sun"].angle) == ("SUN", 3.0, pytest.approx(math.radians(1.0)))
    # Camera visibility (Blender's default for lights: hidden) travels in the metadata
    assert out.metadata["light_visible_camera"] == [False] * 5
    bpy.data.objects["P"].visible_camera = True
    out, _ = export_now()
    seen = dict(zip((l.name for l in out.lights), out.metadata["light_visible_camera"]))
    assert seen == {"P": True, "S": False, "A": False, "N": False, "Sun": False}


def test_materials_from_node_trees():
    fresh()
    add_camera()
    specs = {
        "Principled": node_material("Principled", "ShaderNodeBsdfPrincipled", **{
            "Base Color": (0.2, 0.4, 0.6, 1), "Metallic": 0.3, "Roughness": 0.25, "Transmission Weight": 0.5,
            "IOR": 1.33, "Specular IOR Level": 0.25, "Emission Color": (1, 0.5, 0, 1), "Emission Strength": 2.0}),
        "Diffuse": node_material("Diffuse", "ShaderNodeBsdfDiffuse", Color=(0.5, 0.5, 0.5, 1)),
        "Glossy": node_material("Glossy", "ShaderNodeBsdfGlossy", Color=(0.9, 0.8, 0.7, 1), Roughness=0.1),
        "Glass": node_material("Glass", "ShaderNodeBsdfGlass", IOR=1.7, Roughness=0.0),
        "Tinted": node_material("Tinted", "ShaderNodeBsdfGlass", Color=(0.8, 0.3, 0.2, 1), Roughness=0.3),
        "Emission": node_material("Emission", "ShaderNodeEmission", Color=(1, 1, 1, 1), Strength=5.0),
    }
    for i, (name, (mat, _)) in enumerate(specs.items()):
        add_mesh("cube", name, location=(3 * i, 0, 0), material=mat)
    out, warnings = export_now()
    M = {m.name: m for m in out.materials}
    p = M["Principled"]
    np.testing.assert_allclose(p.base_color, (0.2, 0.4, 0.6), atol=1e-6)
    assert (p.metallic, p.roughness, p.transmission, p.ior, p.specular) == pytest.approx((0.3, 0.25, 0.5, 1.33, 0.5))
    np.testing.assert_allclose(p.emission, (2.0, 1.0, 0.0), atol=1e-6)
    # Cycles tints a Principled BSDF's refraction by sqrt(base colour), a Glass BSDF's by its colour
    np.testing.assert_allclose(p.transmission_tint, np.sqrt((0.2, 0.4, 0.6)), atol=1e-6)
    assert M["Glass"].transmission_tint is None and M["Diffuse"].transmission_tint is None
    # ... and a Glass BSDF's reflection by its colour too (white, the default, is left None)
    np.testing.assert_allclose(M["Tinted"].reflection_tint, (0.8, 0.3, 0.2), atol=1e-6)
    assert M["Tinted"].transmission_tint is None and M["Tinted"].roughness == pytest.approx(0.3)
    assert all(M[k].reflection_tint is None for k in ("Glass", "Principled", "Diffuse", "Glossy", "Emission"))
    assert (M["Diffuse"].metallic, M["Diffuse"].specular, M["Diffuse"].transmission) == (0, 0, 0)
    assert M["Glossy"].metallic == 1.0 and M["Glossy"].roughness == pytest.approx(0.1)
    assert M["Glass"].transmission == 1.0 and M["Glass"].ior == pytest.approx(1.7)
    np.testing.assert_allclose(M["Emission"].emission, 5.0)
    assert warnings == []
    # Per-face materials: a cube with two slots, three faces in the second
    index = {m.name: i for i, m in enumerate(out.materials)}
    two = add_mesh("cube", "TwoSlots", location=(0, 5, 0), material=specs["Diffuse"][0])
    two.data.materials.append(specs["Glass"][0])
    for poly in two.data.polygons[:3]:
        poly.material_index = 1
    out, _ = export_now()
    index = {m.name: i for i, m in enumerate(out.materials)}
    ids = out.meshes[next(i for i in out.instances if i.name == "TwoSlots").mesh].material_ids
    assert sorted(ids.tolist()) == sorted([index["Diffuse"]] * 6 + [index["Glass"]] * 6)


def test_mix_image_and_unsupported_nodes_warn_and_approximate():
    fresh()
    add_camera()
    mat, mix = node_material("Mix", "ShaderNodeMixShader", Fac=0.25)
    tree = mat.node_tree
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    glossy = tree.nodes.new("ShaderNodeBsdfGlossy")
    diffuse.inputs["Color"].default_value = (0.4, 0.4, 0.4, 1)
    glossy.inputs["Color"].default_value = (0.8, 0.8, 0.8, 1)
    tree.links.new(diffuse.outputs[0], mix.inputs[1])
    tree.links.new(glossy.outputs[0], mix.inputs[2])
    add_mesh("cube", "Mixed", material=mat)
    # Image texture on base colour: its mean linear colour
    img = bpy.data.images.new("Checker", 4, 4, float_buffer=True)
    px = np.zeros((4, 4, 4), np.float32)
    px[..., 3] = 1
    px[:2, :, 0] = 1.0  # half the pixels red
    img.pixels.foreach_set(px.ravel())
    tex_mat, bsdf = node_material("Textured", "ShaderNodeBsdfPrincipled")
    tex = tex_mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    tex_mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    add_mesh("cube", "Textured", location=(3, 0, 0), material=tex_mat)
    toon, _ = node_material("Toon", "ShaderNodeBsdfToon")
    add_mesh("cube", "Toon", location=(6, 0, 0), material=toon)
    # A tinted Glass BSDF mixed with a Principled BSDF: the glass tints blend as the parameters
    gmix, gm = node_material("GlassMix", "ShaderNodeMixShader", Fac=0.25)
    glass = gmix.node_tree.nodes.new("ShaderNodeBsdfGlass")
    glass.inputs["Color"].default_value = (0.8, 0.3, 0.2, 1)
    gmix.node_tree.links.new(glass.outputs[0], gm.inputs[1])
    gmix.node_tree.links.new(gmix.node_tree.nodes.new("ShaderNodeBsdfPrincipled").outputs[0], gm.inputs[2])
    add_mesh("cube", "GlassMix", location=(9, 0, 0), material=gmix)
    out, warnings = export_now()
    M = {m.name: m for m in out.materials}
    assert M["Mix"].metallic == pytest.approx(0.25)
    np.testing.assert_allclose(M["Mix"].base_color, 0.75 * 0.4 + 0.25 * 0.8, atol=1e-6)
    np.testing.assert_allclose(M["Textured"].base_color, (0.5, 0.0, 0.0), atol=1e-6)
    np.testing.assert_allclose(M["Toon"].base_color, 0.8)
    assert M["Toon"].metallic == 0 and M["Toon"].transmission == 0
    np.testing.assert_allclose(M["GlassMix"].reflection_tint, 0.75 * np.array([0.8, 0.3, 0.2]) + 0.25, atol=1e-6)
    assert M["Mix"].reflection_tint is None
    text = "\n".join(warnings)
    # The image is rendered from its texels (the material carries its node graph), not as the
    # mean colour: no mean-colour warning; the Toon BSDF still warns
    assert M["Textured"].graph is not None and out.textures
    assert "ShaderNodeBsdfToon" in text and "mean colour" not in text
    # A constant-Fac Mix Shader of two different closures is two closures, as Cycles (the graph's
    # per-hit choice; the constants above are only representative): nothing approximated, no warning
    assert M["Mix"].graph is not None and M["GlassMix"].graph is not None
    assert "Mix Shader" not in text


def test_a_mix_of_two_diffuse_colours_stays_one_exact_constant_closure():
    """Two Diffuse BSDFs differing only in colour: the blend of their colours is exactly their closure
    mix (Lambertian is linear in albedo): one constant closure, no graph, no warning; a different
    Roughness on one side makes it two closures."""
    fresh()
    add_camera()
    mat, mix = node_material("TwoDiffuse", "ShaderNodeMixShader", Fac=0.3)
    tree = mat.node_tree
    a, b = tree.nodes.new("ShaderNodeBsdfDiffuse"), tree.nodes.new("ShaderNodeBsdfDiffuse")
    a.inputs["Color"].default_value = (0.8, 0.1, 0.1, 1)
    b.inputs["Color"].default_value = (0.1, 0.2, 0.8, 1)
    tree.links.new(a.outputs[0], mix.inputs[1])
    tree.links.new(b.outputs[0], mix.inputs[2])
    add_mesh("cube", "TwoDiffuse", material=mat)
    out, warnings = export_now()
    (m,) = out.materials
    assert m.graph is None
    np.testing.assert_allclose(m.base_color, 0.7 * np.array([0.8, 0.1, 0.1]) + 0.3 * np.array([0.1, 0.2, 0.8]),
                               atol=1e-6)
    assert not [w for w in warnings if "Mix Shader" in w]
    b.inputs["Roughness"].default_value = 0.5
    out, warnings = export_now()
    assert out.materials[0].graph is not None


def test_instances_share_one_mesh_and_smooth_normals_follow_the_surface():
    fresh()
    add_camera()
    parent = add_mesh("plane", "Emitter", size=4.0)
    child = add_mesh("sphere", "Ball", radius=0.25, segments=16, ring_count=8)
    bpy.ops.object.shade_smooth()
    child.parent = parent
    parent.instance_type = "VERTS"
    out, _ = export_now()
    balls = [i for i in out.instances if i.name.startswith("Ball")]
    assert len(balls) == 4 and len({i.mesh for i in balls}) == 1
    corners = sorted(tuple(np.round(i.transform.matrices[0, :2, 3], 6)) for i in balls)
    assert corners == [(-2, -2), (-2, 2), (2, -2), (2, 2)]
    mesh = out.meshes[balls[0].mesh]
    # Smooth corner normals of a sphere at the origin point along the position
    p = mesh.vertices[mesh.triangles]
    n = mesh.normals
    np.testing.assert_allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-5)
    cos = np.sum(n * p, axis=-1) / np.linalg.norm(p, axis=-1)
    assert cos.min() > 0.999


def test_modifiers_are_evaluated_and_world_is_exported():
    fresh()
    add_camera()
    cube = add_mesh("cube", "Smooth")
    cube.modifiers.new("Sub", "SUBSURF").levels = 1
    set_world((0.1, 0.2, 0.3), 2.0)
    out, _ = export_now()
    assert out.meshes[0].triangles.shape[0] == 12 * 4
    np.testing.assert_allclose(out.world.radiance, (0.2, 0.4, 0.6), atol=1e-6)


def test_geometry_nodes_instances_move_with_their_object():
    # Instance on Points: a 2 x 2 grid of points, an icosphere on each; the object slides in x
    scene = fresh()
    add_camera()
    obj = add_mesh("plane", "Scatter")
    ng = bpy.data.node_groups.new("Scatter", "GeometryNodeTree")
    ng.interface.new_socket(name="Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    ng.interface.new_socket(name="Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    out_node = ng.nodes.new("NodeGroupOutput")
    grid = ng.nodes.new("GeometryNodeMeshGrid")
    grid.inputs["Vertices X"].default_value = grid.inputs["Vertices Y"].default_value = 2
    grid.inputs["Size X"].default_value = grid.inputs["Size Y"].default_value = 2.0
    ico = ng.nodes.new("GeometryNodeMeshIcoSphere")
    ico.inputs["Radius"].default_value = 0.2
    inst = ng.nodes.new("GeometryNodeInstanceOnPoints")
    ng.links.new(grid.outputs["Mesh"], inst.inputs["Points"])
    ng.links.new(ico.outputs["Mesh"], inst.inputs["Instance"])
    ng.links.new(inst.outputs["Instances"], out_node.inputs[0])
    obj.modifiers.new("GN", "NODES").node_group = ng
    for f, x in ((4, 0.0), (6, 2.0)):
        obj.location.x = x
        obj.keyframe_insert("location", index=0, frame=f)
    linear_keys(obj)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 1.0
    scene.frame_set(5)
    out, warnings = export_now()
    spheres = [i for i in out.instances if "@" in i.name]
    assert len(spheres) == 4 and len({i.mesh for i in spheres}) == 1 and warnings == []
    for i in spheres:
        x = i.transform.matrices[:, 0, 3]
        np.testing.assert_allclose(x - x[0], [0.0, 0.5, 1.0], atol=1e-5)  # 1 unit/frame over 1 frame


def test_text_and_curve_objects_become_meshes():
    fresh()
    add_camera()
    bpy.ops.object.text_add(location=(0, 0, 0))
    bpy.ops.curve.primitive_bezier_circle_add(location=(3, 0, 0))
    bpy.context.object.name = "Circle"
    bpy.context.object.data.extrude = 0.1
    bpy.ops.object.metaball_add(location=(0, -3, 0))
    bpy.ops.object.empty_add(location=(0, 3, 0))  # no geometry: ignored
    out, warnings = export_now()
    # Each appears once (Blender lists their evaluated mesh as an instance of the object)
    names = sorted(i.name.split("@")[0] for i in out.instances)
    assert names == ["Circle", "Mball", "Text"] and warnings == []
    assert all(out.meshes[i.mesh].triangles.shape[0] > 10 for i in out.instances)


def test_moving_light_and_depth_of_field_without_warning():
    scene = fresh()
    cam = add_camera()
    cam.data.dof.use_dof = True
    add_mesh("plane")
    light = add_light("SPOT", "Swing", energy=10.0)
    for f, z in ((0, 2.0), (2, 4.0)):
        light.location.z = z
        light.keyframe_insert("location", index=2, frame=f)
    linear_keys(light)
    scene.render.use_motion_blur, scene.render.motion_blur_shutter = True, 1.0
    scene.render.motion_blur_position = "START"
    scene.frame_set(1)
    out, warnings = export_now()
    np.testing.assert_allclose(out.lights[0].transform.matrices[:, 2, 3], [3.0, 3.5, 4.0], atol=1e-5)
    # depth of field is exported now (tests/test_addon_dof.py): no "not supported" warning
    assert out.has_motion and not any("depth of field" in w for w in warnings) and out.camera.aperture_radius > 0
