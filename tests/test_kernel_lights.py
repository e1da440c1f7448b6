"""The light-sampling kernels (stpm_core/kernels/lights.py) against the numpy oracle (tests/oracles/lights_numpy.py).

Same random numbers in, the same numbers out to rounding: every light type and shape, static and
moving (rotating, scaled) lights, deforming and moving mesh lights, spot blends, soft falloff on
and off, radius 0 and > 0, points inside sphere lights, dead lights, rotated area lights from
float32 matrices, sheared and mirrored area lights, far and near points.  Plus the light shapes
seen along rays (``seen_light``) against ``integrator._seen_lights``' logic, and the spherical
rectangle on its own.

Tolerances: rtol 1e-9, atol 1e-12 (times the weight's scale for weights) everywhere.  The kernels
do the numpy code's float operations in its order, so most rows agree bit for bit; the measured
maxima are printed with ``pytest -s`` (``MAX_DIFF``).
"""
from __future__ import annotations

import numpy as np
import pytest

from oracles import lights_numpy
from scenes import make_scene, look_at, ortho_camera_down, plane_mesh, translate
from stpm_core.kernels.light_params import light_poses
from stpm_core.kernels.lights import seen_batch, spherical_rect_batch
from stpm_core.lights import LightSet
from stpm_core.motion import MotionTransform
from stpm_core.scene import Light, Material, Mesh
from stpm_core.shutter import Shutter

RTOL, ATOL = 1e-9, 1e-12
MAX_DIFF: dict[str, float] = {}          # worst relative difference per case (printed at the end)


# ----------------------------------------------------------------------------
# Scenes and transforms
# ----------------------------------------------------------------------------
def _rot(axis, angle):
    """3 x 3 rotation about a unit axis (Rodrigues)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * K + (1 - np.cos(angle)) * K @ K


def _M(pos, R=None, scale=(1.0, 1.0, 1.0), shear=None):
    M = np.eye(4)
    A = np.diag(scale).astype(float)
    if shear is not None:
        A = shear @ A
    M[:3, :3] = (np.eye(3) if R is None else R) @ A
    M[:3, 3] = pos
    return M


def _static(pos, R=None, **kw):
    return MotionTransform.static(_M(pos, R, **kw))


def _moving(pos0, pos1, pos2=None, scale=(1.0, 1.0, 1.0)):
    """2 or 3 keys: translating, rotating about a tilted axis, scaled."""
    keys = [_M(pos0, _rot((0.3, 1.0, 0.2), -0.4), scale), _M(pos1, _rot((0.3, 1.0, 0.2), 0.5), scale)]
    times = [0.0, 1.0]
    if pos2 is not None:
        keys.append(_M(pos2, _rot((1.0, 0.2, 0.1), 1.1), scale))
        times = [0.0, 0.4, 1.0]
    return MotionTransform(times=np.array(times), matrices=np.stack(keys))


def _lightset(lights=(), objects=None, world=(0.0, 0.0, 0.0)):
    mats = [Material.diffuse((0.5, 0.5, 0.5)), Material.emitter((2.0, 1.5, 0.7))]
    objs = [plane_mesh(6.0)] if objects is None else objects
    scene = make_scene(objs, mats, ortho_camera_down(), list(lights), world=world, shutter=Shutter(1.0, 1.0))
    return LightSet(scene)


def _points(n, rng, center=(0.0, 0.0, 0.0), spread=3.0):
    """Shading points: half near the light (within `spread` of center), a quarter far, a quarter on the floor."""
    c = np.asarray(center, float)
    p = c + rng.uniform(-spread, spread, (n, 3))
    p[: n // 4] = c + rng.normal(0.0, 60.0, (n // 4, 3))                  # far
    p[n // 4: n // 2, 2] = 0.0                                           # on the floor
    return p


# ----------------------------------------------------------------------------
# Comparison
# ----------------------------------------------------------------------------
def _record(name, a, b):
    """Keep the worst difference of a against b, relative to each row's size (|b| or the row norm)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    a, b = a.reshape(b.shape[0], -1), b.reshape(b.shape[0], -1)
    fin = np.all(np.isfinite(b), axis=1)
    a, b = a[fin], b[fin]
    scale = np.linalg.norm(b, axis=1)
    diff = np.max(np.abs(a - b), axis=1, initial=0.0)
    rel = np.where(scale > 0, diff / np.where(scale > 0, scale, 1.0), np.where(diff > 0, np.inf, 0.0))
    MAX_DIFF[name] = max(MAX_DIFF.get(name, 0.0), float(np.max(rel, initial=0.0)))


def _compare(ls, li, p, times, u, normals=None, name="", wscale=None):
    """Kernel (LightSet.sample_direct) against the oracle for light li; returns the kernel's output."""
    wi, dist, w = ls.sample_direct(li, p, times, u, normals=normals)
    with np.errstate(over="ignore", invalid="ignore"):          # (a dead light's inf * 0, zeroed after)
        owi, odist, ow = lights_numpy.sample_direct(ls, li, p, times, u, normals=normals)
    n = p.shape[0]
    owi, ow = np.broadcast_to(owi, (n, 3)), np.broadcast_to(ow, (n, 3))
    assert wi.shape == (n, 3) and dist.shape == (n,) and w.shape == (n, 3)
    assert np.all(np.isfinite(wi)) and np.all(np.isfinite(w))
    np.testing.assert_allclose(wi, owi, rtol=RTOL, atol=ATOL, err_msg=f"{name}: wi")
    np.testing.assert_array_equal(np.isinf(dist), np.isinf(odist))
    np.testing.assert_allclose(dist, odist, rtol=RTOL, atol=ATOL, err_msg=f"{name}: dist")
    ws = float(np.max(np.abs(ow), initial=0.0)) if wscale is None else wscale
    np.testing.assert_allclose(w, ow, rtol=RTOL, atol=ATOL * max(ws, 1.0), err_msg=f"{name}: weight")
    _record(name + " wi", wi, owi)
    _record(name + " dist", dist, odist)
    _record(name + " weight", w, ow)
    return wi, dist, w


def _run(ls, li, name, n=4000, seed=0, center=(0.0, 0.0, 0.0), spread=3.0, one_time=False, normals=None):
    rng = np.random.default_rng(seed)
    p = _points(n, rng, center, spread)
    times = np.full(1, 0.37) if one_time else rng.random(n)
    u = rng.random((n, 2))
    u[:8] = [[0.0, 0.0], [0.0, 0.5], [0.5, 0.0], [0.5, 0.5], [1 - 1e-16, 0.3], [0.3, 1 - 1e-16], [0.25, 0.75],
             [1 - 1e-16, 1 - 1e-16]]
    return _compare(ls, li, p, times, u, normals=normals, name=name)


# ----------------------------------------------------------------------------
# POINT / SPOT
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("moving", [False, True])
@pytest.mark.parametrize("radius, soft", [(0.0, False), (0.4, True), (0.4, False)])
def test_point_lights(radius, soft, moving):
    tr = _moving((0.2, 0.1, 1.5), (-0.5, 0.4, 1.2), (0.3, -0.6, 1.8)) if moving else _static((0.2, 0.1, 1.5))
    ls = _lightset([Light(type="POINT", power=250.0, color=np.array([1.0, 0.6, 0.3]), radius=radius,
                          use_soft_falloff=soft, transform=tr)])
    name = f"point r={radius} soft={soft} moving={moving}"
    _run(ls, 0, name, center=(0.2, 0.1, 1.5))
    _run(ls, 0, name + " one time", one_time=True, seed=1)


@pytest.mark.parametrize("blend", [0.0, 0.35])
@pytest.mark.parametrize("radius, soft", [(0.0, False), (0.3, True), (0.3, False)])
@pytest.mark.parametrize("moving", [False, True])
def test_spot_lights(blend, radius, soft, moving):
    # Aimed down and tilted; a non-uniform scale (removed from the axis, as LightSet._frame does)
    R = _rot((1.0, 0.3, 0.0), 0.5)
    tr = (_moving((0.0, 0.0, 2.0), (0.6, -0.3, 1.6), (-0.4, 0.2, 2.2), scale=(0.5, 2.0, 3.0)) if moving
          else _static((0.0, 0.0, 2.0), R, scale=(0.5, 2.0, 3.0)))
    ls = _lightset([Light(type="SPOT", power=400.0, color=np.array([0.9, 1.0, 0.8]), radius=radius,
                          use_soft_falloff=soft, spot_size=1.2, spot_blend=blend, transform=tr)])
    name = f"spot blend={blend} r={radius} soft={soft} moving={moving}"
    _, _, w = _run(ls, 0, name, center=(0.0, 0.0, 1.0))
    assert np.any(w > 0) and np.any(w == 0)                       # inside and outside the cone


def test_points_inside_and_at_the_centre_of_a_sphere_light():
    ls = _lightset([Light(type="POINT", power=100.0, radius=0.5, use_soft_falloff=False,
                          transform=_static((0.0, 0.0, 1.0)))])
    rng = np.random.default_rng(4)
    n = 2000
    p = np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.35, 0.35, (n, 3))
    p[0] = (0.0, 0.0, 1.0)                                       # the very centre
    p[1] = (0.0, 0.0, 1.5)                                       # on the sphere
    p[2] = (0.0, 0.0, 1.5 + 1e-12)
    _compare(ls, 0, p, rng.random(n), rng.random((n, 2)), name="inside sphere")
    # and the soft-falloff disc seen from its own centre and from just off it
    ls2 = _lightset([Light(type="POINT", power=100.0, radius=0.5, use_soft_falloff=True,
                           transform=_static((0.0, 0.0, 1.0)))])
    _compare(ls2, 0, p, rng.random(n), rng.random((n, 2)), name="soft disc near centre")
    # a radius-0 light sampled at its own position: weight 0
    ls3 = _lightset([Light(type="POINT", power=100.0, transform=_static((0.0, 0.0, 1.0)))])
    _, _, w = _compare(ls3, 0, p[:1], np.zeros(1), np.full((1, 2), 0.5), name="point at itself")
    assert np.all(w == 0.0)


# ----------------------------------------------------------------------------
# AREA
# ----------------------------------------------------------------------------
_FLOAT32_R = look_at((0.3, -0.2, 1.5), (0.35, -0.1, 0.0), up=(0.3, 1.0, 0.2)).astype(np.float32).astype(np.float64)
_AREA_TRANSFORMS = {
    "static": lambda: _static((0.1, -0.2, 1.4)),
    "float32 rotated": lambda: MotionTransform.static(_FLOAT32_R),
    "sheared": lambda: MotionTransform.static(_M((0.0, 0.0, 1.3), _rot((1, 0, 0), 0.3),
                                                 shear=np.array([[1.0, 0.4, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]))),
    "scaled": lambda: _static((0.0, 0.3, 1.2), _rot((0.2, 1.0, 0.0), 0.7), scale=(2.0, 0.5, 1.5)),
    "mirrored z": lambda: _static((0.0, 0.0, 1.2), scale=(1.0, 1.0, -1.0)),
    "mirrored x": lambda: _static((0.0, 0.0, 1.2), scale=(-1.0, 1.0, 1.0)),
    "moving": lambda: _moving((0.0, 0.0, 1.5), (0.8, 0.2, 1.2), (-0.3, 0.5, 1.9), scale=(1.0, 1.5, 1.0)),
}


@pytest.mark.parametrize("shape", ["SQUARE", "RECTANGLE", "DISK", "ELLIPSE"])
@pytest.mark.parametrize("pose", list(_AREA_TRANSFORMS))
def test_area_lights(shape, pose):
    tr = _AREA_TRANSFORMS[pose]()
    ls = _lightset([Light(type="AREA", shape=shape, size=1.5, size_y=0.6, power=300.0,
                          color=np.array([1.0, 0.8, 0.6]), transform=tr)])
    name = f"area {shape} {pose}"
    _, _, w = _run(ls, 0, name, center=tuple(tr.at(0.5)[:3, 3]), spread=2.0)
    assert np.any(w > 0) and np.any(w == 0)                      # in front and behind
    # very near the light (the spherical rectangle's large solid angles, grazing points)
    rng = np.random.default_rng(7)
    M = tr.at(np.full(500, 0.5))
    p = M[:, :3, 3] + rng.normal(0.0, 0.02, (500, 3)) + 0.05 * M[:, :3, 2] * rng.choice([-1.0, 1.0], (500, 1))
    _compare(ls, 0, p, np.full(500, 0.5), rng.random((500, 2)), name=f"area {shape} {pose} near")


def test_area_light_paths_taken():
    """The rectangle cases above reach both samplers: solid angle (orthogonal, S > 1e-7) and area."""
    ls = _lightset([Light(type="AREA", shape="SQUARE", size=1.0, power=100.0, transform=_static((0, 0, 1.0)))])
    far = np.array([[0.0, 0.0, -2e4]])       # S below 1e-7 sr: area sampling (and behind: weight 0)
    near = np.array([[0.1, 0.2, 0.0]])
    for p in (far, near):
        _compare(ls, 0, p, np.zeros(1), np.full((1, 2), 0.3), name="area paths")


# ----------------------------------------------------------------------------
# SUN
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("angle", [0.0, 0.1, 1.0])
@pytest.mark.parametrize("moving", [False, True])
def test_sun_lights(angle, moving):
    tr = _moving((0, 0, 5), (1, 0, 5), (0, 1, 5), scale=(1.0, 1.0, 2.0)) if moving else _static(
        (0, 0, 5), _rot((1.0, 0.5, 0.0), 0.6), scale=(1.0, 1.0, 0.3))
    ls = _lightset([Light(type="SUN", power=3.0, angle=angle, color=np.array([1.0, 0.9, 0.7]), transform=tr)])
    name = f"sun angle={angle} moving={moving}"
    _run(ls, 0, name)
    _run(ls, 0, name + " one time", one_time=True, seed=2)


def test_sun_with_zero_z_scale_at_one_key_only():
    """Alive (some key has a direction), but rows at the dead key's time get +Z and weight 0."""
    keys = np.stack([_M((0, 0, 5), scale=(1.0, 1.0, 0.0)), _M((0, 0, 5), _rot((1, 0, 0), 0.4))])
    ls = _lightset([Light(type="SUN", power=2.0, transform=MotionTransform(np.array([0.0, 1.0]), keys))])
    assert not ls._dead[0]
    rng = np.random.default_rng(3)
    times = rng.random(1000)
    times[:10] = 0.0
    _, _, w = _compare(ls, 0, rng.normal(size=(1000, 3)), times, rng.random((1000, 2)), name="sun zero z at t=0")
    assert np.all(w[:10] == 0.0) and np.all(w[10:] > 0.0)


# ----------------------------------------------------------------------------
# Dead lights
# ----------------------------------------------------------------------------
@pytest.mark.parametrize("typ", ["SPOT", "SUN", "AREA"])
def test_dead_lights_give_nothing(typ):
    tr = _static((0.0, 0.0, 2.0), scale=(1.0, 1.0, 0.0))       # zero Z scale: no direction
    if typ == "AREA":
        tr = _static((0.0, 0.0, 2.0), scale=(0.0, 1.0, 1.0))   # zero X scale: zero area
    ls = _lightset([Light(type=typ, power=1e9, transform=tr, radius=0.0)])
    assert ls._dead[0]
    _, _, w = _run(ls, 0, f"dead {typ}", n=500)
    assert np.all(w == 0.0)


# ----------------------------------------------------------------------------
# MESH
# ----------------------------------------------------------------------------
def _emitter(deforming: bool) -> Mesh:
    """Two emitting quads of different sizes (4 triangles) plus one non-emitting triangle."""
    v = np.array([[-0.4, -0.3, 0.0], [0.4, -0.3, 0.0], [0.4, 0.3, 0.0], [-0.4, 0.3, 0.0],
                  [0.6, 0.0, 0.2], [0.8, 0.0, 0.2], [0.8, 0.1, 0.5], [0.6, 0.1, 0.5],
                  [0.0, 0.0, 0.3], [0.1, 0.0, 0.3], [0.0, 0.1, 0.3]], np.float32)
    tri = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10]], np.int32)
    mid = np.array([1, 1, 1, 1, 0], np.int32)
    if not deforming:
        return Mesh(vertices=v, triangles=tri, material_ids=mid, name="emitter")
    V = np.stack([v, v * np.float32(1.3) + np.float32(0.1), v * np.float32(0.7) - np.float32(0.05)])
    return Mesh(vertices=V, triangles=tri, material_ids=mid, vertex_times=np.array([0.0, 0.3, 1.0]), name="emitter")


@pytest.mark.parametrize("deforming", [False, True])
@pytest.mark.parametrize("moving", [False, True])
def test_mesh_lights(deforming, moving):
    tr = _moving((0.0, 0.0, 1.2), (0.5, 0.2, 1.0), (-0.2, 0.4, 1.5), scale=(1.2, 0.8, 1.0)) if moving else \
        _M((0.1, 0.0, 1.2), _rot((0.0, 1.0, 0.3), 0.4))
    ls = _lightset(objects=[plane_mesh(6.0), (_emitter(deforming), tr)])
    assert [l.type for l in ls.lights] == ["MESH"] and ls.lights[0].prims.size == 4
    name = f"mesh deforming={deforming} moving={moving}"
    _run(ls, 0, name, center=(0.0, 0.0, 1.2), spread=1.5)
    _run(ls, 0, name + " one time", one_time=True, seed=5)
    # u0 at the cdf's steps: the triangle choice and the rescaled u0 at the interval ends
    l = ls.lights[0]
    u = np.stack([np.concatenate([l.cdf, np.nextafter(l.cdf, 0.0), [0.0]]), np.full(2 * l.cdf.size + 1, 0.4)], axis=1)
    u[:, 0] = np.clip(u[:, 0], 0.0, 1.0 - 1e-16)
    n = u.shape[0]
    _compare(ls, 0, np.tile([0.2, -0.1, 0.3], (n, 1)), np.linspace(0, 1, n), u, name=name + " cdf steps")


# ----------------------------------------------------------------------------
# WORLD
# ----------------------------------------------------------------------------
def test_world_light():
    ls = _lightset(world=(0.4, 0.5, 0.6))
    assert [l.type for l in ls.lights] == ["WORLD"]
    rng = np.random.default_rng(6)
    n = 4000
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[:4] = [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0, -1, 0]]
    _run(ls, 0, "world cosine", normals=normals)
    _run(ls, 0, "world uniform sphere")


# ----------------------------------------------------------------------------
# Several lights in one LightSet (indices, caching of the packed rows)
# ----------------------------------------------------------------------------
def test_mixed_lightset_every_entry():
    lights = [Light(type="POINT", power=50.0, radius=0.1, transform=_static((1, 1, 2))),
              Light(type="SPOT", power=80.0, transform=_static((0, 0, 3))),
              Light(type="AREA", shape="ELLIPSE", size=1.0, size_y=2.0, power=60.0, transform=_static((0, 1, 2))),
              Light(type="SUN", power=2.0, angle=0.05, transform=_static((0, 0, 5), _rot((0, 1, 0), 0.3)))]
    ls = _lightset(lights, objects=[plane_mesh(6.0), (_emitter(False), translate(0, 0, 1.5))], world=(0.1, 0.1, 0.1))
    assert [l.type for l in ls.lights] == ["POINT", "SPOT", "AREA", "SUN", "MESH", "WORLD"]
    for li in range(len(ls)):
        for seed in (0, 1):                                      # second call: the cached row
            _run(ls, li, f"mixed {ls.lights[li].type}", n=1000, seed=seed)


# ----------------------------------------------------------------------------
# Spherical rectangle
# ----------------------------------------------------------------------------
def test_spherical_rectangle_kernel_matches_numpy():
    rng = np.random.default_rng(8)
    n = 20000
    R = np.stack([_rot(rng.normal(size=3), rng.uniform(0, 3)) for _ in range(n)])
    lx, ly = rng.uniform(0.01, 3.0, n), rng.uniform(0.01, 3.0, n)
    ex, ey = R[:, :, 0] * lx[:, None], R[:, :, 1] * ly[:, None]
    s = rng.normal(size=(n, 3))
    o = rng.normal(size=(n, 3)) * rng.choice([0.01, 1.0, 30.0], (n, 1))
    u = rng.random((n, 2))
    q, S = np.empty((n, 3)), np.empty(n)
    spherical_rect_batch(o, s, ex, ey, u, q, S)
    oq, oS = lights_numpy.spherical_rect_sample(o, s, ex, ey, u)
    np.testing.assert_allclose(S, oS, rtol=RTOL, atol=ATOL)
    np.testing.assert_allclose(q, oq, rtol=RTOL, atol=ATOL * np.max(np.abs(oq)))
    _record("spherical rect q", q, oq)
    _record("spherical rect S", S, oS)


# ----------------------------------------------------------------------------
# Light shapes seen along rays
# ----------------------------------------------------------------------------
def _seen_scene():
    lights = [
        Light(type="AREA", shape="SQUARE", size=1.0, power=100.0, transform=_static((0.0, 0.0, 2.0))),
        Light(type="AREA", shape="ELLIPSE", size=1.5, size_y=0.7, power=80.0, color=np.array([1.0, 0.5, 0.2]),
              transform=_moving((1.5, 0.0, 2.0), (1.2, 0.4, 1.8), (1.6, -0.3, 2.3), scale=(1.0, 2.0, 1.0))),
        Light(type="AREA", shape="RECTANGLE", size=1.0, size_y=0.5, power=70.0,
              transform=MotionTransform.static(_FLOAT32_R)),
        Light(type="POINT", power=60.0, radius=0.3, use_soft_falloff=True, transform=_static((-1.5, 0.0, 1.5))),
        Light(type="POINT", power=60.0, radius=0.2, use_soft_falloff=False,
              transform=_moving((-1.0, 1.0, 1.0), (-0.7, 1.2, 1.3))),
        Light(type="SPOT", power=90.0, radius=0.4, spot_size=1.0, spot_blend=0.3,
              transform=_static((0.0, -1.5, 1.5), _rot((1, 0, 0), -0.6), scale=(1.0, 1.0, 2.5))),
        Light(type="SPOT", power=90.0, radius=0.4, spot_size=1.0, spot_blend=0.0,
              transform=_moving((1.0, -1.5, 1.5), (1.3, -1.2, 1.4), scale=(1.0, 1.0, 0.5))),
        Light(type="POINT", power=60.0, radius=0.0, transform=_static((0.0, 1.5, 1.0))),     # not visible
        Light(type="SUN", power=2.0, angle=0.2, transform=_static((0, 0, 5))),                # seen where rays escape
        Light(type="AREA", shape="DISK", size=1.0, power=0.0, transform=_static((0.0, 0.0, 3.0))),   # power 0
        Light(type="AREA", shape="SQUARE", size=0.7, power=50.0, transform=_static((0, 0, 1.0), scale=(0, 1, 1))),
    ]
    return _lightset(lights, objects=[plane_mesh(6.0), (_emitter(False), translate(0, 0, 1.5))], world=(0.1, 0.1, 0.1))


def test_seen_light_matches_seen_lights():
    ls = _seen_scene()
    rng = np.random.default_rng(9)
    n = 6000
    o = rng.uniform(-2.5, 2.5, (n, 3))
    o[:, 2] = rng.uniform(-0.5, 3.5, n)
    t = rng.random(n)
    # aim most rays at a light's position (plus scatter), some anywhere
    targets = np.array([l.transform.at(0.5)[:3, 3] for l in ls.lights])
    aim = targets[rng.integers(0, len(targets), n)] + rng.normal(0.0, 0.4, (n, 3))
    d = aim - o
    d[: n // 5] = rng.normal(size=(n // 5, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    t_scene = np.where(rng.random(n) < 0.3, rng.uniform(0.0, 4.0, n), np.inf)
    want = lights_numpy.seen_lights_numpy(ls, o, d, t, t_scene)
    got = np.zeros((n, 3))
    L = np.empty((n, 3))
    hits = 0
    for li in range(len(ls)):
        prm = ls.kernel_light(li)[0]
        seen_batch(prm, light_poses(ls, li, t), o, d, t_scene, False, L)
        hits += int(np.count_nonzero(L[:, 0]))
        got += L
    assert hits > n // 10
    np.testing.assert_allclose(got, want, rtol=RTOL, atol=ATOL)
    _record("seen_light", got, want)
    # camera rays: seen_batch leaves Blender's visibility flag to the caller (camera_ray only passed on)
    vis = [li % 2 == 0 for li in range(len(ls))]
    want_cam = lights_numpy.seen_lights_numpy(ls, o, d, t, t_scene, camera_ray=True, visible_camera=vis)
    got_cam = np.zeros((n, 3))
    for li in range(len(ls)):
        if vis[li]:
            seen_batch(ls.kernel_light(li)[0], light_poses(ls, li, t), o, d, t_scene, True, L)
            got_cam += L
    np.testing.assert_allclose(got_cam, want_cam, rtol=RTOL, atol=ATOL)


def test_zz_report_max_differences():
    """Print the worst relative difference of every case (pytest -s)."""
    for k in sorted(MAX_DIFF):
        print(f"{k:60s} {MAX_DIFF[k]:.3e}")
    assert all(v <= 1e-9 for v in MAX_DIFF.values())
