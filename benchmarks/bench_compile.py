"""Cold compile and warm first render of the compiled kernels.

Each measurement is a fresh Python process that imports STPM and renders one
small scene of ``tests/kernel_scenes.py`` (``photons_temporal``: a point light
and a sun, diffuse, coated, rough-metal, mirror and glass surfaces, a moving
box, caustic and global photon maps, 4 samples at 24 x 18): first with an
empty numba cache (``NUMBA_CACHE_DIR`` pointed at a new folder: every kernel
compiles), then again with that cache warm (every kernel loads from disk).
Reported: the process's wall time to a finished render, and the render's own
``wall_s``.  ``python benchmarks/bench_compile.py TREE`` measures another
checkout (e.g. the commit before a change) the same way.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = "photons_temporal"

_CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
from kernel_scenes import kernel_scenes
from stpm_core.render import render
name, scene, settings = next(s for s in kernel_scenes() if s[0] == sys.argv[1])
res = render(scene, settings)
print(json.dumps({"process_s": time.perf_counter() - t0, "render_wall_s": res.stats["wall_s"]}))
"""


def measure(tree: Path = ROOT, scene: str = SCENE) -> dict:
    """{'cold_*', 'warm_*'} seconds for the checkout at ``tree`` (its stpm_core and tests/ on the path)."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="stpm-numba-cache-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache,
                   PYTHONPATH=os.pathsep.join([str(tree), str(tree / "tests")]))
        for label in ("cold", "warm"):
            t0 = time.perf_counter()
            r = subprocess.run([sys.executable, "-c", _CHILD, scene], cwd=tree, env=env, capture_output=True,
                               text=True, check=True)
            line = r.stdout.strip().splitlines()[-1]
            d = json.loads(line)
            out[f"{label}_process_s"] = time.perf_counter() - t0
            out[f"{label}_render_wall_s"] = d["render_wall_s"]
    return out


def run() -> dict:
    return measure()


if __name__ == "__main__":
    print(json.dumps(measure(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT), indent=2))
