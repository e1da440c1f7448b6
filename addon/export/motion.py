"""Motion across the shutter: when to sample, and how samples become transforms.

Blender's shutter (``render.motion_blur_shutter`` frames long) sits around the
current frame ``f`` according to ``render.motion_blur_position``::

    START  : [f,       f + s]
    CENTER : [f - s/2, f + s/2]
    END    : [f - s,   f]

Normalised shutter time ``u`` in [0, 1] maps to ``open + u * s``.  Moving
things are sampled at ``K`` equally spaced ``u`` (``frame_set(frame,
subframe)`` for each), their matrices become a
:class:`stpm_core.motion.MotionTransform` (static when nothing changes).
"""
from __future__ import annotations

import math

import numpy as np

from .._core import MotionTransform, Shutter

CURVE_SAMPLES = 33   # points at which the shutter curve is sampled into Shutter.curve
MAX_STEPS = 65       # cap on motion steps (memory: one matrix / vertex set per step)


def shutter_interval(frame: float, shutter: float, position: str) -> tuple[float, float]:
    """Shutter open and close in frames for Blender's shutter ``position``."""
    if position == "START":
        return frame, frame + shutter
    if position == "END":
        return frame - shutter, frame
    return frame - 0.5 * shutter, frame + 0.5 * shutter


def shutter_curve(render, n: int = CURVE_SAMPLES) -> np.ndarray | None:
    """``render.motion_blur_shutter_curve`` sampled at n points of [0, 1] (n,), or None when flat."""
    cm = render.motion_blur_shutter_curve
    try:
        cm.initialize()
        curve = cm.curves[0]
        w = np.array([cm.evaluate(curve, float(x)) for x in np.linspace(0.0, 1.0, n)], dtype=np.float64)
    except (AttributeError, IndexError, RuntimeError):
        return None
    w = np.maximum(w, 0.0)
    if w.sum() <= 0 or np.allclose(w, w[0], rtol=1e-6, atol=1e-9):
        return None  # a box shutter
    return w


def shutter_from_render(render, frame: float) -> Shutter:
    """The :class:`Shutter` of a frame; a zero-length one when motion blur is off."""
    if not render.use_motion_blur or render.motion_blur_shutter <= 0:
        return Shutter(open=frame, close=frame)
    t_open, t_close = shutter_interval(frame, float(render.motion_blur_shutter), render.motion_blur_position)
    return Shutter(open=t_open, close=t_close, curve=shutter_curve(render))


def step_times(steps: int) -> np.ndarray:
    """K equally spaced normalised shutter times (K,) in [0, 1]."""
    return np.linspace(0.0, 1.0, int(np.clip(steps, 2, MAX_STEPS)))


def split_frame(frame: float) -> tuple[int, float]:
    """A fractional frame -> (integer frame, subframe in [0, 1)) for ``frame_set``."""
    f = math.floor(frame + 1e-9)
    return int(f), float(max(frame - f, 0.0))


def object_motion_settings(obj) -> tuple[bool, bool, int]:
    """Per-object toggles where Blender has them: (use_motion_blur, use_deform_motion, steps).

    These live in ``object.cycles`` (only present while Cycles is registered);
    without them every object moves with the scene's steps.
    """
    cyc = getattr(obj, "cycles", None)
    if cyc is None:
        return True, True, 0
    use = bool(getattr(cyc, "use_motion_blur", True))
    deform = bool(getattr(cyc, "use_deform_motion", True))
    ms = int(getattr(cyc, "motion_steps", 1))
    return use, deform, (2 ** max(ms, 1)) + 1  # Cycles' steps: 2^(motion_steps) intervals


def transform_from_samples(times: np.ndarray, matrices: list) -> MotionTransform:
    """K sampled 4x4 matrices -> MotionTransform (collapses to static when they are equal)."""
    M = np.asarray(matrices, dtype=np.float64).reshape(-1, 4, 4)
    if M.shape[0] == 1:
        return MotionTransform.static(M[0])
    return MotionTransform(times=np.asarray(times, dtype=np.float64), matrices=M)


def without_scale(M: np.ndarray) -> np.ndarray:
    """A 4x4 matrix (..., 4, 4) with unit-length axis columns (cameras ignore scale)."""
    M = np.array(M, dtype=np.float64, copy=True)
    n = np.linalg.norm(M[..., :3, :3], axis=-2, keepdims=True)
    M[..., :3, :3] /= np.where(n > 0, n, 1.0)
    return M
