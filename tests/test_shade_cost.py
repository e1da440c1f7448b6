"""What the camera paths compute once instead of twice gives the values it replaced (branch shade-cost).

* ``kernels.bsdf.bsdf_eval_split`` (next-event estimation's f and the continuation's part of it from
  one set-up of the hit) is ``bsdf_eval_pdf``'s f and ``bsdf_eval_cont``'s (c, p_c), bit for bit;
* an AREA light's sample carries ``light_pdf``'s density of its own direction, bit for bit (the
  sampler no longer calls ``light_pdf``);
* ``shading.normal_matrices`` (``kernels.motion.normal_matrix_rows``): a static instance's matrix is
  ``np.linalg.inv(M).T`` exactly, a moving one's the inverse transpose of ``MotionTransform.at``;
  ``camera.camera_to_world`` of a moving camera is ``at`` with unit columns;
* a render that reads normal matrices of a moving instance through a moving camera is the same
  image with the same seed, whatever the thread count.
"""
from __future__ import annotations

import numpy as np
import pytest

from scenes import look_at, make_scene, persp_camera, plane_mesh, sphere_mesh, translate
from stpm_core.bsdf import MaterialTable
from stpm_core.camera import camera_to_world
from stpm_core.kernels import bsdf as kb
from stpm_core.kernels.closure import closure_row
from stpm_core.kernels.light_params import kernel_light, light_poses
from stpm_core.kernels.lights import light_pdf_batch, sample_pdf_batch
from stpm_core.kernels.motion import transform_rows
from stpm_core.motion import MotionTransform
from stpm_core.nodes import Link, Node, ShaderGraph
from stpm_core.render import render
from stpm_core.scene import Instance, Light, Material
from stpm_core.settings import RenderSettings
from stpm_core.shading import normal_keys, normal_matrices
from stpm_core.shutter import Shutter
from test_kernel_bsdf import _geometry, _materials
from test_light_mis import AREA, _lights, _rot_x


def _rot_z(a):
    c, s = np.cos(a), np.sin(a)
    M = np.eye(4)
    M[:2, :2] = [[c, -s], [s, c]]
    return M


def _scale(x, y, z):
    return np.diag([x, y, z, 1.0])


def _tumbling() -> MotionTransform:
    """Three keys: translation, rotation about two axes, non-uniform scale (stretch lerp)."""
    keys = [translate(0.0, 0.0, 0.5) @ _rot_z(0.0) @ _scale(1.0, 1.0, 1.0),
            translate(0.3, -0.2, 0.7) @ _rot_z(0.9) @ _rot_x(0.4) @ _scale(1.3, 0.8, 1.0),
            translate(0.5, 0.1, 0.6) @ _rot_z(2.0) @ _rot_x(-0.3) @ _scale(0.7, 1.1, 1.6)]
    return MotionTransform(np.array([0.0, 0.4, 1.0]), np.stack(keys))


def test_bsdf_eval_split_is_eval_pdf_and_eval_cont_bit_for_bit():
    rng = np.random.default_rng(7)
    mats = _materials(rng)
    table = MaterialTable(mats)
    C = np.ascontiguousarray(table.closures)
    E, E_avg = kb.ggx_albedo_tables()
    n = 4000
    mat = rng.integers(0, len(mats), n)
    wo, wi, ns, ng = _geometry(rng, n)
    some_c = 0
    for stop_coat in (False, True):
        for i in range(n):
            cr = closure_row(C, int(mat[i]))
            a = tuple(float(x) for x in wo[i]), tuple(float(x) for x in wi[i])
            b = tuple(float(x) for x in ns[i]), tuple(float(x) for x in ng[i])
            f = kb.bsdf_eval_pdf(C, cr, E, E_avg, *a, *b)[:3]
            c = kb.bsdf_eval_cont(C, cr, E, E_avg, *a, *b, stop_coat)
            got = kb.bsdf_eval_split(C, cr, E, E_avg, *a, *b, stop_coat)
            assert got == f + c, (i, stop_coat, got, f + c)
            some_c += c[3] > 0
    assert some_c > n // 4                  # the case has rough continuation lobes


@pytest.mark.parametrize("case", ["rectangle", "disk", "ellipse", "moving rectangle", "tiny rectangle"])
def test_area_sample_density_is_light_pdf_bit_for_bit(case):
    rng = np.random.default_rng(3)
    M = translate(0.1, 0.2, 1.5) @ _rot_x(0.3)
    if case == "moving rectangle":
        tr = MotionTransform(np.array([0.0, 1.0]), np.stack([M, translate(0.8, 0.0, 1.2) @ _rot_x(-0.2)]))
        light = Light(type="AREA", power=80.0, transform=tr, **AREA["rectangle"])
    elif case == "tiny rectangle":            # solid angle under 1e-7 sr: the uniform-area sampler
        light = Light(type="AREA", power=80.0, transform=MotionTransform.static(M), shape="RECTANGLE",
                      size=1e-4, size_y=1e-4)
    else:
        light = Light(type="AREA", power=80.0, transform=MotionTransform.static(M), **AREA[case])
    ls = _lights(light)
    n = 5000
    p = rng.uniform(-2.0, 2.0, (n, 3)) * [1, 1, 0.5]
    times = rng.random(n)
    k = kernel_light(ls, 0)
    poses = light_poses(ls, 0, times)
    S = np.empty((n, 8))
    sample_pdf_batch(k[0], poses, *k[2:], p, times, rng.random((n, 2)), np.zeros_like(p), S)
    pdf = np.empty(n)
    light_pdf_batch(k[0], poses, p, np.ascontiguousarray(S[:, :3]), pdf)
    assert np.isfinite(S[:, 7]).sum() > n // 4
    assert np.array_equal(S[:, 7], pdf)


def test_normal_matrices_are_the_inverse_transpose():
    rng = np.random.default_rng(11)
    statics = [MotionTransform.static(translate(1, 2, 3) @ _rot_x(0.7) @ _scale(2.0, 0.5, 1.5)),
               MotionTransform.static(_rot_z(-1.2) @ _scale(1.0, 3.0, 0.25))]
    tumbling = _tumbling()
    instances = [Instance(0, statics[0]), Instance(0, tumbling), Instance(0, statics[1]),
                 Instance(0, MotionTransform(np.array([0.0, 1.0]), np.stack([translate(0, 0, 0), translate(1, 0, 0)])))]
    m = 20_000
    inst = rng.integers(0, len(instances), m).astype(np.int32)
    t = rng.random(m)
    t[:50] = rng.choice([0.0, 0.4, 1.0], 50)          # at the keys
    NM = normal_matrices(instances, inst, t, normal_keys(instances))
    for i, ins in enumerate(instances):
        rows = inst == i
        tr = ins.transform
        if tr.is_static:
            want = np.broadcast_to(np.linalg.inv(tr.matrices[0][:3, :3]).T, (rows.sum(), 3, 3))
            assert np.array_equal(NM[rows], want)
        else:
            want = np.transpose(np.linalg.inv(tr.at(t[rows])[:, :3, :3]), (0, 2, 1))
            np.testing.assert_allclose(NM[rows], want, rtol=1e-12, atol=1e-13)
    # the kernel's pose is MotionTransform.at (to rounding), and so is a moving camera's
    out = np.empty((m, 4, 4))
    transform_rows(tumbling.times, tumbling._T, tumbling._Q, tumbling._S, t, out)
    np.testing.assert_allclose(out, tumbling.at(t), rtol=1e-13, atol=1e-14)
    cam = persp_camera((0, -4, 2), (0, 0, 0))
    cam.transform = tumbling
    R, pos = camera_to_world(cam, t)
    A = tumbling.at(t)[:, :3, :3]
    np.testing.assert_allclose(R, A / np.linalg.norm(A, axis=1, keepdims=True), rtol=1e-13, atol=1e-14)
    np.testing.assert_allclose(pos, tumbling.at(t)[:, :3, 3], rtol=1e-13, atol=1e-14)


def _mapped_scene():
    """An object-space normal-mapped sphere (the Normal Map node reads each hit's normal matrix)
    tumbling over a floor, seen by a moving camera, lit by an area light and the world."""
    graph = ShaderGraph(nodes={
        "Map": Node("ShaderNodeNormalMap", props={"space": "OBJECT", "uv_map": ""},
                    inputs={"Color": (0.7, 0.4, 0.8), "Strength": 1.0}, outputs={"Normal": "VECTOR"}),
        "BSDF": Node("ShaderNodeBsdfPrincipled", inputs={"Base Color": (0.8, 0.5, 0.3), "Roughness": 0.4,
                                                         "Normal": Link("Map", "Normal")},
                     outputs={"BSDF": "SHADER"}),
    }, surface=Link("BSDF", "BSDF"))
    mats = [Material.diffuse((0.6, 0.6, 0.6)), Material(graph=graph)]
    cam = persp_camera((0.2, -3.5, 1.6), (0, 0, 0.4), lens=35.0)
    cam.transform = MotionTransform(np.array([0.0, 1.0]), np.stack([
        look_at((0.2, -3.5, 1.6), (0, 0, 0.4)), look_at((0.5, -3.3, 1.7), (0, 0, 0.4))]))
    objs = [plane_mesh(6.0), (sphere_mesh(0.5, 12, 24, material=1), _tumbling())]
    lights = [Light(type="AREA", shape="RECTANGLE", size=1.0, size_y=0.6, power=120.0,
                    transform=MotionTransform.static(look_at((1.0, -1.0, 2.5), (0, 0, 0))))]
    return make_scene(objs, mats, cam, lights, world=(0.05, 0.05, 0.06), resolution=(24, 16),
                      shutter=Shutter(1.0, 1.5))


def test_moving_mapped_render_is_the_same_image_whatever_the_threads():
    scene = _mapped_scene()
    st = dict(samples=8, photons_global=3000, photons_caustic=0, max_depth=4, seed=5)
    a = render(scene, RenderSettings(threads=1, **st))
    # (3000 photons over an open floor: the global map's sparseness is named, render._sparse_global_map)
    assert not [w for w in a.warnings if not w.startswith("the global photon map holds")], a.warnings
    b = render(scene, RenderSettings(threads=2, **st))
    img = a.passes["Combined"][..., :3]
    assert np.array_equal(img, b.passes["Combined"][..., :3])
    assert (img > 0).all(axis=-1).mean() > 0.5 and np.isfinite(img).all()
    # the map tilts the sphere's normals: its pixels differ from the unmapped closure's
    plain = _mapped_scene()
    plain.materials[1] = Material(base_color=np.array([0.8, 0.5, 0.3]), roughness=0.4)
    c = render(plain, RenderSettings(threads=1, **st)).passes["Combined"][..., :3]
    assert np.abs(c - img).max() > 0.01


def test_image_world_sample_density_is_world_nee_pdf_bit_for_bit():
    """An environment image without portals: the sampler's density is world_nee_pdf's (it no longer
    calls it), from points with a normal and without one (uniform sphere part)."""
    from stpm_core.kernels.lights import world_nee_pdf_batch
    from portal_scenes import room_scene
    from test_portals import _sky, _world
    ls, li = _world(room_scene(portal=False, image=_sky()))
    k = kernel_light(ls, li)
    env = k[-1]
    assert env[5].shape[0] == 0                  # no portal rows: the image sampler's branch
    poses = light_poses(ls, li, np.zeros(1))
    rng = np.random.default_rng(9)
    n = 20_000
    p = rng.uniform(-0.5, 0.5, (n, 3))
    nrm = rng.normal(size=(n, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm[: n // 4] = 0.0
    S = np.empty((n, 8))
    sample_pdf_batch(k[0], poses, *k[2:], p, np.zeros(n), rng.random((n, 2)), nrm, S)
    again = np.empty(n)
    world_nee_pdf_batch(env, poses, p, nrm, np.ascontiguousarray(S[:, :3]), again)
    assert (S[:, 7] > 0).mean() > 0.9
    assert np.array_equal(S[:, 7], again)


def test_normal_matrices_follow_a_transform_replaced_between_renders():
    """The shading data outlives a render (cached on the scene); the normal matrices it keeps are
    rebuilt when an instance's transform is replaced."""
    from stpm_core.shading import frame_keys, shading_data
    scene = _mapped_scene()
    sd = shading_data(scene)
    assert sd.uses_frames
    k0 = frame_keys(sd)
    assert frame_keys(sd) is k0
    M = translate(0.1, 0.0, 0.5) @ _rot_z(0.8) @ _scale(2.0, 1.0, 1.0)
    scene.instances[1].transform = MotionTransform.static(M)
    assert shading_data(scene) is sd
    k1 = frame_keys(sd)
    assert k1 is not k0
    inst = np.array([1, 1], np.int32)
    NM = normal_matrices(sd.instances, inst, np.array([0.2, 0.7]), k1)
    assert np.array_equal(NM[0], np.linalg.inv(M[:3, :3]).T) and np.array_equal(NM[1], NM[0])
