"""Shared helpers for the compare experiments (not part of the project)."""
import os, sys, time
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, ROOT); sys.path.insert(0, os.path.join(ROOT, "tests"))
WORK = os.path.join(ROOT, "bench_out", "compare_experiments"); os.makedirs(WORK, exist_ok=True)
import numpy as np
from stpm_core.settings import RenderSettings
from stpm_core.render import render
from stpm_core.compare.metrics import combined_rgb
from test_compare import analytic_moving_caustic, moving_caustic_scene

BASE = dict(samples=4, photons_caustic=20_000, photons_global=0, k_nearest=30, seed=1,
            effects="MANUAL", caustics=True, indirect=False)
_exact = {}

def exact(res):
    if res not in _exact:
        path = os.path.join(WORK, f"exact_{res[0]}x{res[1]}.npy")
        if os.path.exists(path):
            _exact[res] = np.load(path)
        else:
            _exact[res] = analytic_moving_caustic(res); np.save(path, _exact[res])
    return _exact[res]

def run(scene, **kw):
    st = RenderSettings(**{**BASE, **kw})
    t = time.perf_counter()
    r = render(scene, st)
    w = time.perf_counter() - t
    return combined_rgb(r.passes).astype(np.float64), w, r.stats

def rmse(x, r): return float(np.sqrt(np.mean((x - r) ** 2)))
def relmse(x, r): return float(np.mean((x - r) ** 2 / (r * r + 0.01)))
