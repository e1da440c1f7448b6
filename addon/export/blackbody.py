"""Blender's blackbody colour (the Blackbody shader node, a light's Temperature) for light node trees.

Cycles' Blackbody node gives, for a temperature T in kelvin, the same colour as a light's own
*Temperature* (``Light.temperature_color``; measured: equal to 4 decimals in Cycles renders at
1000, 2500, 4000 and 9000 K): a linear Rec.709 colour of luminance 1, constant below 800 K and
above 12000 K.  :data:`TABLE` holds that colour, read from Blender 5.0.1 through its Python API
by :func:`table_from_blender`, at 65 temperatures equally spaced in mired (1e6 / T) from 800 K to
12000 K; :func:`blackbody` interpolates linearly in mired.  Against Blender at the midpoints the
largest error is 0.11 % of the colour's largest channel (near 5400 K).
``tests/test_addon_review2.py`` compares the table with the running Blender.
"""
from __future__ import annotations

import numpy as np

T_MIN, T_MAX = 800.0, 12000.0
SAMPLES = 65

# Linear Rec.709 blackbody colours at mired 1e6 / T_MIN ... 1e6 / T_MAX (equal steps)
TABLE = np.array([
    (5.41386, 0, 0),
    (5.36007, 0, 0),
    (5.30555, 0, 0),
    (5.25027, 0, 0),
    (5.19419, 0, 0),
    (5.13728, 0, 0),
    (5.07949, 0, 0),
    (5.02078, 0, 0),
    (4.96111, 0, 0),
    (4.90043, 0, 0),
    (4.83868, 0, 0),
    (4.77581, 0, 0),
    (4.71286, 0.00581926, 0),
    (4.64807, 0.0251272, 0),
    (4.58257, 0.0446377, 0),
    (4.51632, 0.0643621, 0),
    (4.44927, 0.0843126, 0),
    (4.38138, 0.104502, 0),
    (4.3126, 0.124946, 0),
    (4.24288, 0.145658, 0),
    (4.17215, 0.166655, 0),
    (4.10036, 0.187956, 0),
    (4.02849, 0.209248, 0),
    (3.955, 0.231015, 0),
    (3.88095, 0.252922, 0),
    (3.80629, 0.274978, 0),
    (3.73099, 0.297194, 0),
    (3.655, 0.319581, 0),
    (3.57826, 0.342151, 0),
    (3.50073, 0.364919, 0),
    (3.42233, 0.3879, 0),
    (3.34404, 0.410779, 0),
    (3.26431, 0.434046, 0),
    (3.18429, 0.457325, 0),
    (3.10396, 0.480615, 0),
    (3.0233, 0.503918, 0),
    (2.94226, 0.527236, 0),
    (2.86082, 0.550569, 0),
    (2.77894, 0.573918, 0),
    (2.69656, 0.597287, 0),
    (2.61506, 0.620367, 0.00363611),
    (2.53196, 0.643555, 0.0181972),
    (2.449, 0.666533, 0.0344777),
    (2.36622, 0.689276, 0.0526998),
    (2.28363, 0.711756, 0.0731152),
    (2.20125, 0.733938, 0.0960078),
    (2.11912, 0.755784, 0.121696),
    (2.03726, 0.777246, 0.150531),
    (1.95573, 0.798269, 0.182893),
    (1.87456, 0.818785, 0.219181),
    (1.79382, 0.838713, 0.259782),
    (1.71358, 0.857951, 0.305024),
    (1.63393, 0.876376, 0.355081),
    (1.55596, 0.894167, 0.411645),
    (1.47915, 0.910365, 0.474526),
    (1.40336, 0.925792, 0.544044),
    (1.32884, 0.940264, 0.621081),
    (1.25592, 0.953534, 0.706544),
    (1.18504, 0.96526, 0.80124),
    (1.11687, 0.974958, 0.905541),
    (1.05072, 0.983308, 1.01969),
    (0.989594, 0.988551, 1.14271),
    (0.930876, 0.99261, 1.27628),
    (0.875862, 0.994849, 1.41807),
    (0.826295, 0.994508, 1.56631)
], dtype=np.float64)


def blackbody(temperature: float, working: str = "REC709") -> np.ndarray:
    """(3,) the blackbody colour of ``temperature`` kelvin as Blender gives it, in the working space
    ``working`` (a ``stpm_core.colorspaces.WORKING_SPACES`` id)."""
    t = float(temperature)
    t = T_MAX if not np.isfinite(t) else min(max(t, T_MIN), T_MAX)
    m0, m1 = 1e6 / T_MIN, 1e6 / T_MAX
    u = (m0 - 1e6 / t) / (m0 - m1) * (SAMPLES - 1)
    i = min(int(u), SAMPLES - 2)
    f = u - i
    rgb = (1.0 - f) * TABLE[i] + f * TABLE[i + 1]
    if working != "REC709":
        from .._core import sub
        M = sub("colorspaces").conversion("Linear Rec.709", working)
        rgb = rgb if M is None else M @ rgb
    return rgb


def table_from_blender() -> np.ndarray:
    """(SAMPLES, 3) :data:`TABLE` as the running Blender computes it (needs bpy; makes and removes
    a light datablock: not for a render thread)."""
    import bpy
    lamp = bpy.data.lights.new("stpm_blackbody_probe", "POINT")
    try:
        lamp.use_temperature = True
        out = []
        for m in np.linspace(1e6 / T_MIN, 1e6 / T_MAX, SAMPLES):
            lamp.temperature = float(1e6 / m)
            out.append(lamp.temperature_color[:])
        return np.array(out, dtype=np.float64)
    finally:
        bpy.data.lights.remove(lamp)
