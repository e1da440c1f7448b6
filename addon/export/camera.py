"""Blender camera -> :class:`stpm_core.scene.Camera` (motion added by the caller); a 3D view's
matrices -> Camera (:func:`view_camera`, the rendered viewport)."""
from __future__ import annotations

import numpy as np

from .._core import MotionTransform, scene_model
from .motion import transform_from_samples, without_scale


def render_resolution(render) -> tuple[int, int]:
    """Output size in pixels (width, height), with ``resolution_percentage`` applied.

    Integer arithmetic exactly as Blender's ``(size * xsch) / 100``: 29 % of 100 is 29, not
    ``int(100 * 0.29) = 28``.
    """
    pct = int(render.resolution_percentage)
    return max(1, int(render.resolution_x) * pct // 100), max(1, int(render.resolution_y) * pct // 100)


#: Relative change of the focus distance within the shutter that is warned (a moving camera with a focus
#: object changes it a little: 0.04 % in the review's bottle shot, invisible)
_FOCUS_WARN = 0.01


def focus_distance(cam_obj) -> float:
    """The camera's focus distance in scene units (Blender's ``cam.dof``), as Cycles reads it: the
    ``focus_distance`` property, or with a ``focus_object`` (and optionally its pose bone
    ``focus_subtarget``) that point's distance from the camera along the view axis, |dot(Z, camera
    - point)| with Z the camera's normalised local Z axis, at the current frame."""
    dof = cam_obj.data.dof
    target = getattr(dof, "focus_object", None)
    if target is None:
        return float(dof.focus_distance)
    M = np.array(target.matrix_world, dtype=np.float64)
    sub = getattr(dof, "focus_subtarget", "")
    pose = getattr(target, "pose", None)
    if sub and pose is not None and pose.bones.get(sub) is not None:
        M = M @ np.array(pose.bones[sub].matrix, dtype=np.float64)
    C = np.array(cam_obj.matrix_world, dtype=np.float64)
    z = C[:3, 2] / max(float(np.linalg.norm(C[:3, 2])), 1e-300)
    return float(abs(np.dot(z, C[:3, 3] - M[:3, 3])))


def thin_lens(cam_obj, ctype: str) -> dict:
    """The Camera's lens fields from Blender's depth of field settings at the current frame ({}
    without ``use_dof``): radius ``lens / (2 fstop)`` with the lens in mm taken as 1e-3 scene units
    (perspective; Cycles' convention, whatever the scene's unit scale), ``1 / (2 fstop)``
    (orthographic), the f-stop clamped to >= 1e-5 as Cycles; blades, rotation and ratio as
    they are."""
    cam = cam_obj.data
    dof = getattr(cam, "dof", None)
    if dof is None or not dof.use_dof:
        return {}
    fstop = max(float(dof.aperture_fstop), 1e-5)
    radius = 1.0 / (2.0 * fstop) if ctype == "ORTHO" else float(cam.lens) * 1e-3 / (2.0 * fstop)
    return dict(aperture_radius=radius, focus_distance=max(focus_distance(cam_obj), 1e-5),
                aperture_blades=int(dof.aperture_blades), aperture_rotation=float(dof.aperture_rotation),
                aperture_ratio=float(dof.aperture_ratio))


def export_camera(cam_obj, times, matrices, warnings: list, focus_steps=None) -> "scene_model.Camera":
    """Camera data + sampled camera-to-world matrices (K, 4, 4) -> Camera.

    Scale is removed from the matrices (Blender cameras ignore it too).  Depth of field
    (:func:`thin_lens`) is read at the current frame; ``focus_steps`` (the focus distances at the
    shutter's steps, or None) only warns when the focus moves by more than 1 % during the shutter.
    """
    cam = cam_obj.data
    ctype = cam.type
    if ctype not in ("PERSP", "ORTHO"):
        warnings.append(f"camera {cam_obj.name!r}: {ctype} projection is not supported, rendered as perspective")
        ctype = "PERSP"
    lens = thin_lens(cam_obj, ctype)
    if lens and focus_steps is not None and len(focus_steps) > 1:
        lo, hi = min(focus_steps), max(focus_steps)
        if hi - lo > _FOCUS_WARN * max(hi, 1e-6):
            warnings.append(f"camera {cam_obj.name!r}: the focus distance changes during the shutter "
                            f"({lo:.4g} to {hi:.4g}); rendered with the frame's value {lens['focus_distance']:.4g}")
    return scene_model.Camera(
        type=ctype,
        transform=transform_from_samples(times, without_scale(matrices)),
        lens=float(cam.lens),
        sensor_width=float(cam.sensor_width),
        sensor_height=float(cam.sensor_height),
        sensor_fit=cam.sensor_fit,
        ortho_scale=float(cam.ortho_scale),
        shift_x=float(cam.shift_x),
        shift_y=float(cam.shift_y),
        clip_start=float(cam.clip_start),
        clip_end=float(cam.clip_end),
        **lens,
    )


_OPTICS = ("lens", "ortho_scale", "shift_x", "shift_y")


def optics(cam_obj) -> tuple:
    """The camera data values that change the frame's field of view: lens, ortho scale, shifts."""
    return tuple(float(getattr(cam_obj.data, k)) for k in _OPTICS)


def optics_changed(steps: list) -> list:
    """Names of the :func:`optics` values that differ between motion steps (relative 1e-6)."""
    if len(steps) < 2:
        return []
    a = np.asarray(steps, dtype=np.float64)
    spread = a.max(axis=0) - a.min(axis=0)
    return [k for k, d, m in zip(_OPTICS, spread, np.abs(a).max(axis=0)) if d > 1e-6 * max(m, 1e-6)]


# Sensor width given to a view's camera: any value works, the lens is derived from it
_VIEW_SENSOR = 36.0


def view_camera(view_matrix, window_matrix, width: int, height: int) -> "scene_model.Camera":
    """The camera of a 3D view: its world-to-view matrix and its projection (OpenGL clip space,
    Blender's ``RegionView3D.view_matrix`` / ``window_matrix``), for an image of width x height
    pixels covering the whole region.  No bpy: the matrices are plain 4 x 4 arrays.

    Perspective when the projection's last row is (0, 0, -1, 0), else orthographic.  With
    ``P`` the projection, a view-space point (x, y, z) lands at NDC ``x_ndc = (P00 x + P02 z) /
    -z`` (perspective), so the frame spans the image-plane tangents ``(+-1 + P02) / P00``: half
    width ``1 / P00``, centre ``P02 / P00``; the core's horizontally fitted camera has half width
    ``sensor / (2 lens)`` and centre ``shift_x * sensor / lens`` (stpm_core/camera.py), so
    ``lens = sensor P00 / 2``, ``shift_x = P02 / 2``, ``shift_y = P12 P00 / (2 P11)``.
    Orthographic: ``x_ndc = P00 x + P03``, ``ortho_scale = 2 / P00``, ``shift_x = -P03 / 2``,
    ``shift_y = -P13 P00 / (2 P11)``.  Clipping distances come from P's third row; an orthographic
    view whose near plane lies behind its eye (Blender's ortho views clip symmetrically around
    it) moves the eye back along the view axis until it is in front.
    """
    V = np.asarray(view_matrix, dtype=np.float64).reshape(4, 4)
    P = np.asarray(window_matrix, dtype=np.float64).reshape(4, 4)
    cam_to_world = np.linalg.inv(V)
    perspective = abs(P[3, 2] + 1.0) < 1e-6 and abs(P[3, 3]) < 1e-6
    if perspective:
        near, far = P[2, 3] / (P[2, 2] - 1.0), P[2, 3] / (P[2, 2] + 1.0)
        shift_x, shift_y = 0.5 * P[0, 2], 0.5 * P[1, 2] * P[0, 0] / P[1, 1]
    else:
        near, far = (P[2, 3] + 1.0) / P[2, 2], (P[2, 3] - 1.0) / P[2, 2]
        shift_x, shift_y = -0.5 * P[0, 3], -0.5 * P[1, 3] * P[0, 0] / P[1, 1]
        back = max(0.0, -near) + 1e-3 * max(far - near, 1e-6)     # eye in front of the near plane
        if near <= 0.0:
            axis = cam_to_world[:3, 2] / max(np.linalg.norm(cam_to_world[:3, 2]), 1e-300)   # view +Z (backwards)
            cam_to_world = cam_to_world.copy()
            cam_to_world[:3, 3] += back * axis
            near, far = near + back, far + back
    if not np.isfinite(far) or far <= near:
        far = near * 1e9
    return scene_model.Camera(
        type="PERSP" if perspective else "ORTHO",
        transform=MotionTransform.static(cam_to_world),
        lens=float(_VIEW_SENSOR * P[0, 0] / 2.0) if perspective else 50.0,
        sensor_width=_VIEW_SENSOR,
        sensor_height=_VIEW_SENSOR * height / max(width, 1),
        sensor_fit="HORIZONTAL",
        ortho_scale=float(2.0 / P[0, 0]) if not perspective else 6.0,
        shift_x=float(shift_x),
        shift_y=float(shift_y),
        clip_start=float(max(near, 1e-6)),
        clip_end=float(far),
    )
