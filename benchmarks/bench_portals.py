"""Light portals: how many world photons reach a room lit through one window, and the noise.

The room of tests/portal_scenes.py (a closed 2 m box, one 0.8 x 0.8 m window, white walls of
albedo 0.7) under a constant white world and under a small sky image with a sun, with and without
the window's portal:

* ``*_enter_frac``: the fraction of emitted world photons whose line enters the room through the
  window (``LightSet.emit``, no tracing);
* ``*_stored_per_emitted``: photons stored in the global map (all of them in the room: outside
  there is nothing for a bounce to reach) per world photon emitted, from a render's stats;
* ``*_indirect_rel_sd`` / ``*_direct_rel_sd``: the per-pixel standard deviation over seeds of the
  Indirect / Direct pass divided by its mean (median over pixels): the noise at equal photon and
  sample counts;
* ``*_mean_ratio``: Combined with the portal over without (1 within the noise).

``python -m benchmarks portals`` (about a minute on 2 cores after the kernels are compiled).
"""
from __future__ import annotations

import os
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, ".."))
sys.path.insert(0, os.path.join(HERE, "..", "tests"))

from stpm_core.lights import LightSet  # noqa: E402
from stpm_core.render import render  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402

from portal_scenes import WINDOW, room_scene  # noqa: E402

N_EMIT = 400_000
PHOTONS = 100_000
SEEDS = (0, 1, 2, 3)


def _sky(h: int = 32, w: int = 64) -> np.ndarray:
    v = (np.arange(h) + 0.5) / h
    img = np.empty((h, w, 3), np.float32)
    img[...] = np.where(v[:, None, None] > 0.5, np.array([0.6, 0.8, 1.2]), np.array([0.1, 0.08, 0.05]))
    img[24:26, 6:8] = 40.0
    return img


def _enter_fraction(sc) -> float:
    ls = LightSet(sc)
    li = [l.type for l in ls.lights].index("WORLD")
    o, d, _ = ls.emit(li, N_EMIT, np.full(1, 0.5), np.random.default_rng(0))
    s = (1.0 - o[:, 0]) / np.where(d[:, 0] == 0, np.inf, d[:, 0])
    x = o + s[:, None] * d
    y0, y1, z0, z1 = WINDOW
    hit = (d[:, 0] < 0) & (x[:, 1] >= y0) & (x[:, 1] <= y1) & (x[:, 2] >= z0) & (x[:, 2] <= z1)
    return float(hit.mean())


def _renders(sc):
    comb, ind, dire, stats = [], [], [], None
    for s in SEEDS:
        r = render(sc, RenderSettings(samples=8, photons_caustic=0, photons_global=PHOTONS, k_nearest=50,
                                      seed=s, effects="MANUAL", caustics=False, indirect=True))
        comb.append(r.passes["Combined"][..., :3].mean(-1))
        ind.append(r.passes["Indirect"][..., :3].mean(-1))
        dire.append(r.passes["Direct"][..., :3].mean(-1))
        stats = r.stats
    return np.array(comb), np.array(ind), np.array(dire), stats


def _rel_sd(stack) -> float:
    m = stack.mean(0)
    sel = m > 0.05 * np.percentile(m, 90)
    return float(np.median(stack.std(0, ddof=1)[sel] / m[sel]))


def run() -> dict:
    out = {}
    for name, image in (("const", None), ("sky", _sky())):
        res = {}
        for portal in (False, True):
            tag = f"{name}_{'portal' if portal else 'plain'}"
            sc = room_scene(portal=portal, image=image, resolution=(64, 48))
            out[f"{tag}_enter_frac"] = _enter_fraction(sc)
            t0 = time.perf_counter()
            comb, ind, dire, st = _renders(sc)
            out[f"{tag}_render_s"] = (time.perf_counter() - t0) / len(SEEDS)
            ps = st["photon_stats"]
            out[f"{tag}_stored_per_emitted"] = st["photons_global"] / max(ps["photons_emitted_global"], 1)
            out[f"{tag}_indirect_rel_sd"] = _rel_sd(ind)
            out[f"{tag}_direct_rel_sd"] = _rel_sd(dire)
            res[portal] = comb
        out[f"{name}_mean_ratio"] = float(res[True].mean() / res[False].mean())
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:32s} {v:.4g}")
