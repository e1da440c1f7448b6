"""Blender camera -> :class:`stpm_core.scene.Camera` (motion added by the caller)."""
from __future__ import annotations

from .._core import scene_model
from .motion import transform_from_samples, without_scale


def render_resolution(render) -> tuple[int, int]:
    """Output size in pixels (width, height), with ``resolution_percentage`` applied.

    Integer arithmetic exactly as Blender's ``(size * xsch) / 100``: 29 % of 100 is 29, not
    ``int(100 * 0.29) = 28``.
    """
    pct = int(render.resolution_percentage)
    return max(1, int(render.resolution_x) * pct // 100), max(1, int(render.resolution_y) * pct // 100)


def export_camera(cam_obj, times, matrices, warnings: list) -> "scene_model.Camera":
    """Camera data + sampled camera-to-world matrices (K, 4, 4) -> Camera.

    Scale is removed from the matrices (Blender cameras ignore it too).
    """
    cam = cam_obj.data
    ctype = cam.type
    if ctype not in ("PERSP", "ORTHO"):
        warnings.append(f"camera {cam_obj.name!r}: {ctype} projection is not supported, rendered as perspective")
        ctype = "PERSP"
    if getattr(getattr(cam, "dof", None), "use_dof", False):
        warnings.append(f"camera {cam_obj.name!r}: depth of field is not supported, rendered as a pinhole")
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
    )
