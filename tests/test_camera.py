"""Blender camera model: pinhole projection, sensor fit, shift, ortho, motion."""
import numpy as np
import pytest

from stpm_core.camera import generate_rays, view_axis
from stpm_core.motion import MotionTransform
from stpm_core.scene import Camera


def _pose(angle_z=0.3, angle_x=1.1, pos=(1.0, -2.0, 0.5)):
    """Camera-to-world: rotation about x then z, then translation."""
    cx, sx, cz, sz = np.cos(angle_x), np.sin(angle_x), np.cos(angle_z), np.sin(angle_z)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    M = np.eye(4)
    M[:3, :3] = Rz @ Rx
    M[:3, 3] = pos
    return M


def _pixel_grid(W, H):
    py, px = np.mgrid[0:H, 0:W]
    return px.ravel() + 0.5, py.ravel() + 0.5


def _project(M, dirs, f_px, W, H, shift_px=(0.0, 0.0)):
    """Independent pinhole: direction -> continuous pixel coords of a frame shifted by shift_px (right, up)."""
    d = dirs @ M[:3, :3]            # world -> camera (M orthonormal)
    x, y = d[:, 0] / -d[:, 2], d[:, 1] / -d[:, 2]
    return W / 2 + f_px * x - shift_px[0], H / 2 - f_px * y + shift_px[1]


@pytest.mark.parametrize("fit,W,H,fitted_px,sensor", [
    ("AUTO", 64, 48, 64, "w"),        # landscape: width spans sensor_width
    ("AUTO", 30, 50, 50, "w"),        # portrait: height spans sensor_width
    ("HORIZONTAL", 30, 50, 30, "w"),
    ("VERTICAL", 64, 48, 48, "h"),
])
def test_perspective_rays_project_back_through_pixel_centres(fit, W, H, fitted_px, sensor):
    M = _pose()
    cam = Camera(transform=MotionTransform.static(M), lens=35.0, sensor_width=36.0, sensor_height=20.0,
                 sensor_fit=fit, shift_x=0.1, shift_y=-0.05)
    px, py = _pixel_grid(W, H)
    o, d = generate_rays(cam, (W, H), px, py, np.full(px.shape, 0.5))
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0)
    assert np.allclose(o, M[:3, 3])
    size = cam.sensor_width if sensor == "w" else cam.sensor_height
    f_px = cam.lens / size * fitted_px
    qx, qy = _project(M, d, f_px, W, H, shift_px=(cam.shift_x * fitted_px, cam.shift_y * fitted_px))
    assert np.allclose(qx, px, atol=1e-9) and np.allclose(qy, py, atol=1e-9)


def test_blender_default_field_of_view():
    """50 mm on a 36 mm sensor: Blender shows a 39.6 degree horizontal field of view."""
    cam = Camera(lens=50.0, sensor_width=36.0)
    _, d = generate_rays(cam, (1920, 1080), np.array([0.0, 1920.0]), np.array([540.0, 540.0]), np.zeros(2))
    fov = np.degrees(np.arccos(np.dot(d[0], d[1])))
    assert abs(fov - 39.5978) < 1e-3
    # Identity camera looks down -Z: centre ray
    _, c = generate_rays(cam, (1920, 1080), np.array([960.0]), np.array([540.0]), np.zeros(1))
    assert np.allclose(c, [[0, 0, -1]])


def test_shift_one_moves_frame_by_fitted_width():
    base = Camera(lens=50.0, sensor_width=36.0)
    shifted = Camera(lens=50.0, sensor_width=36.0, shift_x=1.0)
    W, H = 40, 20
    # Pixel x in the shifted frame sees what pixel x + W saw in the unshifted one
    _, d1 = generate_rays(shifted, (W, H), np.array([5.5]), np.array([7.5]), np.zeros(1))
    _, d0 = generate_rays(base, (W, H), np.array([5.5 + W]), np.array([7.5]), np.zeros(1))
    assert np.allclose(d0, d1)
    shifted_y = Camera(lens=50.0, sensor_width=36.0, shift_y=0.5)
    _, d2 = generate_rays(shifted_y, (W, H), np.array([5.5]), np.array([7.5]), np.zeros(1))
    _, d3 = generate_rays(base, (W, H), np.array([5.5]), np.array([7.5 - 0.5 * W]), np.zeros(1))
    assert np.allclose(d2, d3)


@pytest.mark.parametrize("fit,W,H,span_axis", [("AUTO", 80, 40, 0), ("AUTO", 40, 80, 1),
                                               ("HORIZONTAL", 40, 80, 0), ("VERTICAL", 80, 40, 1)])
def test_ortho_extents(fit, W, H, span_axis):
    M = _pose()
    cam = Camera(type="ORTHO", transform=MotionTransform.static(M), ortho_scale=4.0, sensor_fit=fit)
    # Frame edges: left/right at px = 0, W; top/bottom at py = 0, H
    px = np.array([0.0, W, W / 2, W / 2])
    py = np.array([H / 2, H / 2, 0.0, H])
    o, d = generate_rays(cam, (W, H), px, py, np.zeros(4))
    assert np.allclose(d, -M[:3, 2])
    local = (o - M[:3, 3]) @ M[:3, :3]
    assert np.allclose(local[:, 2], -cam.clip_start)
    width, height = local[1, 0] - local[0, 0], local[2, 1] - local[3, 1]
    spans = (width, height)
    assert np.isclose(spans[span_axis], 4.0)
    assert np.isclose(spans[1 - span_axis], 4.0 * (H / W if span_axis == 0 else W / H))


def test_moving_camera_matches_its_matrices_at_0_and_1():
    M0, M1 = _pose(0.0, 1.0, (0, 0, 0)), _pose(0.4, 1.2, (1, 2, 3))
    moving = Camera(transform=MotionTransform(times=np.array([0.0, 1.0]), matrices=np.stack([M0, M1])))
    px, py = _pixel_grid(8, 6)
    for t, M in ((0.0, M0), (1.0, M1)):
        still = Camera(transform=MotionTransform.static(M))
        om, dm = generate_rays(moving, (8, 6), px, py, np.full(px.shape, t))
        os_, ds = generate_rays(still, (8, 6), px, py, np.full(px.shape, t))
        assert np.allclose(om, os_) and np.allclose(dm, ds)
        assert np.allclose(view_axis(moving, np.array([t])), -M[:3, 2])
    # Mixed times in one batch
    times = np.where(np.arange(px.size) % 2 == 0, 0.0, 1.0)
    o, _ = generate_rays(moving, (8, 6), px, py, times)
    assert np.allclose(o[0::2], M0[:3, 3]) and np.allclose(o[1::2], M1[:3, 3])


def test_scaled_camera_ignores_scale():
    M = _pose()
    S = M.copy()
    S[:3, :3] = M[:3, :3] @ np.diag([2.0, 3.0, 0.5])
    px, py = _pixel_grid(6, 4)
    a = generate_rays(Camera(transform=MotionTransform.static(M)), (6, 4), px, py, np.zeros(px.size))
    b = generate_rays(Camera(transform=MotionTransform.static(S)), (6, 4), px, py, np.zeros(px.size))
    assert np.allclose(a[0], b[0]) and np.allclose(a[1], b[1], atol=1e-9)
