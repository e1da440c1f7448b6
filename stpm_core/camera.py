"""Blender's camera model: primary rays for continuous pixel coordinates at
each ray's own shutter time.

Conventions (docs/camera.md has the derivation and a picture):

* Pixel coordinates: ``px`` in [0, W) left -> right, ``py`` in [0, H) top ->
  bottom; pixel i's centre is i + 0.5.  Row 0 is the TOP row.
* The camera looks down its local -Z axis, +X right, +Y up.  Its pose at time
  t is ``camera.transform.at(t)``; scale is ignored (rotation columns are
  normalised), so a scaled camera object renders like Blender's.
* Sensor fit decides which image axis the sensor size (or ortho_scale) spans:
  AUTO -> the longer image axis spans ``sensor_width``; HORIZONTAL -> the image
  width spans ``sensor_width``; VERTICAL -> the image height spans
  ``sensor_height``.  Call the spanned length (in mm at focal distance ``lens``
  for perspective, in scene units for ortho) the *fitted size* F and the number
  of pixels along the fitted axis N_fit.  One pixel is F / N_fit wide on the
  image plane (square pixels).
* Shift: ``shift_x`` / ``shift_y`` move the frame by that fraction of the
  fitted size F (Blender: shift 1.0 moves by one full fitted width).
* Depth of field: a thin lens of radius ``aperture_radius`` (scene units) in the camera's XY
  plane, focused at ``focus_distance`` along the view axis; round, or a regular polygon of
  ``aperture_blades`` sides (``kernels.paths.aperture_point``).  0 = a pinhole.
"""
from __future__ import annotations

import numpy as np

__all__ = ["generate_rays", "view_axis", "camera_to_world", "image_plane", "lens_args"]


def camera_to_world(camera, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rotation (n, 3, 3) with unit columns (X right, Y up, Z back) and position (n, 3) at times (n,).

    A static camera returns read-only broadcast views of its single pose.
    """
    times = np.atleast_1d(np.asarray(times, dtype=np.float64))
    if camera.transform.is_static:
        # One pose for every time: normalise once, broadcast (read-only views)
        M0 = camera.transform.matrices[0]
        R0 = M0[:3, :3] / np.maximum(np.linalg.norm(M0[:3, :3], axis=0, keepdims=True), 1e-300)
        n = times.shape[0]
        pos0 = M0[:3, 3]
        return np.broadcast_to(R0, (n, 3, 3)), np.broadcast_to(pos0, (n, 3))
    # One pose per time, scale ignored (each rotation column normalised): kernels.motion.camera_rows
    from .kernels.motion import camera_rows
    tr = camera.transform
    n = times.shape[0]
    R, pos = np.empty((n, 3, 3)), np.empty((n, 3))
    def c(a):                                # contiguous, writeable float64 copies: one compiled signature
        return np.array(a, np.float64)       # whatever the caller's arrays are (read-only ones included)
    camera_rows(c(tr.times), c(tr._T), c(tr._Q), c(tr._S), c(times), R, pos)
    return R, pos


def image_plane(camera, resolution) -> tuple[float, float, float, float]:
    """Image-plane extent of the frame: (half_w, half_h, centre_x, centre_y).

    Units: for PERSP, tangent of the view angle (the plane at distance 1); for
    ORTHO, scene units.  The frame spans x in [cx - half_w, cx + half_w] (left
    -> right) and y in [cy - half_h, cy + half_h] (bottom -> top).
    """
    W, H = (int(resolution[0]), int(resolution[1]))
    # Fitted axis and fitted size F
    fit = camera.sensor_fit
    if fit == "AUTO":
        fit = "HORIZONTAL" if W >= H else "VERTICAL"
        sensor = camera.sensor_width
    elif fit == "HORIZONTAL":
        sensor = camera.sensor_width
    else:
        sensor = camera.sensor_height
    if camera.type == "ORTHO":
        F = float(camera.ortho_scale)
    else:
        F = float(sensor) / float(camera.lens)
    # Square pixels: pixel size = F / N_fit
    n_fit = W if fit == "HORIZONTAL" else H
    pixel = F / n_fit
    half_w, half_h = 0.5 * W * pixel, 0.5 * H * pixel
    return half_w, half_h, camera.shift_x * F, camera.shift_y * F


def lens_args(camera) -> tuple[float, float, int, float, float]:
    """The thin lens as ``kernels.paths.camera_rays`` takes it: (aperture radius, focus distance,
    blades, rotation, ratio); radius 0 for an orthographic or perspective pinhole."""
    return (float(getattr(camera, "aperture_radius", 0.0)), float(getattr(camera, "focus_distance", 10.0)),
            int(getattr(camera, "aperture_blades", 0)), float(getattr(camera, "aperture_rotation", 0.0)),
            float(getattr(camera, "aperture_ratio", 1.0)))


_NO_LENS = np.zeros((0, 2))


def generate_rays(camera, resolution, px: np.ndarray, py: np.ndarray, times: np.ndarray,
                  lens_uv: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Primary rays through continuous pixel positions at their own times (``kernels.paths.camera_rays``,
    the tracer's own kernel).

    Parameters
    ----------
    camera : scene.Camera.
    resolution : (W, H) pixels.
    px, py : (n,) float pixel coordinates (px left -> right, py top -> bottom).
    times : (n,) normalised shutter times.
    lens_uv : (n, 2) uniforms in [0, 1)^2 placing each ray on the camera's thin lens
        (``camera.aperture_radius > 0``); None: every ray through the lens centre (the pinhole).

    Returns
    -------
    origins : (n, 3) world positions (PERSP: the camera position, or the lens point; ORTHO: on
        the plane at ``clip_start`` in front of the camera).
    dirs : (n, 3) unit world directions.
    """
    from .kernels import kernel_array
    from .kernels.paths import camera_rays

    px = np.ascontiguousarray(px, dtype=np.float64)
    py = np.ascontiguousarray(py, dtype=np.float64)
    times = np.broadcast_to(np.asarray(times, dtype=np.float64), px.shape)
    W, H = int(resolution[0]), int(resolution[1])
    half_w, half_h, cx, cy = image_plane(camera, resolution)
    static = camera.transform.is_static
    R, pos = camera_to_world(camera, times[:1] if static else times)
    n = px.shape[0]
    aperture, focus, blades, rotation, ratio = lens_args(camera)
    if lens_uv is None or aperture <= 0.0:
        aperture, uv = 0.0, _NO_LENS
    else:
        uv = np.ascontiguousarray(np.broadcast_to(np.asarray(lens_uv, np.float64), (n, 2)))
    o, d, tmax0 = np.empty((n, 3)), np.empty((n, 3)), np.empty(n)
    camera_rays(kernel_array(px), kernel_array(py), W, H, float(half_w), float(half_h), float(cx), float(cy),
                kernel_array(R), kernel_array(pos), camera.type == "ORTHO", float(camera.clip_start),
                float(camera.clip_end), kernel_array(uv), aperture, focus, blades, rotation, ratio, o, d, tmax0)
    return o, d


def view_axis(camera, times: np.ndarray) -> np.ndarray:
    """Unit forward direction (camera -Z in world) (n, 3) at times (n,), for the Depth pass."""
    R, _ = camera_to_world(camera, times)
    return -R[:, :, 2].copy()
