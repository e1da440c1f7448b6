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

``measure_installed`` (issue 17, needs bpy): the first F12 render in a fresh Blender process
after installing the extension zip (built without wheels; Blender's own operator into a
throw-away user folder), cold (the kernels compile into the extension's user folder) and warm
(a second fresh process: they load).  The demo scene at 160 x 120, 4 samples, 20k + 20k photons;
reported: the process's seconds from start to the finished render, the render's ``wall_s``,
``kernels_compiled`` and ``kernel_compile_s`` (the engine's own report).
``python benchmarks/bench_compile.py --installed`` runs it alone.  Measured 2026-12-06 on the
2-core machine: cold 57.8 s from process start (render 57.0 s, of which 55.5 s compiling 132
functions), warm 2.4 s (render 1.3 s, nothing compiled).
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


_INSTALL = r"""
import sys, bpy
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
"""

_F12 = r"""
import json, sys, time
t0 = time.perf_counter()
import bpy
bpy.ops.preferences.addon_enable(module="bl_ext.user_default.stpm")
bpy.ops.wm.open_mainfile(filepath=sys.argv[1])
scene = bpy.context.scene
scene.stpm.samples, scene.stpm.photons_global, scene.stpm.photons_caustic = 4, 20000, 20000
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 160, 120, 100
bpy.ops.render.render()
stats = sys.modules["bl_ext.user_default.stpm.engine"].LAST_RENDER["stats"]
print("RESULT" + json.dumps({"process_s": time.perf_counter() - t0, "render_wall_s": stats["wall_s"],
                             "kernels_compiled": stats["kernels_compiled"],
                             "kernel_compile_s": stats["kernel_compile_s"]}))
"""


def measure_installed(tree: Path = ROOT) -> dict:
    """{'installed_cold_*', 'installed_warm_*'}: the first F12 render of a fresh Blender process after
    installing the extension zip of ``tree`` (cold: kernels compile; warm: a second fresh process)."""
    sys.path.insert(0, str(tree))
    from addon import build_zip
    out = {}
    with tempfile.TemporaryDirectory(prefix="stpm-installed-") as tmp:
        zip_path = build_zip.build(build_zip.this_platform(), wheels=False, out_dir=Path(tmp) / "dist")
        env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR", "STPM_KERNEL_CACHE")}
        env["BLENDER_USER_RESOURCES"] = str(Path(tmp) / "user")
        subprocess.run([sys.executable, "-c", _INSTALL, str(zip_path)], cwd=tmp, env=env, capture_output=True,
                       text=True, check=True)
        for label in ("cold", "warm"):
            r = subprocess.run([sys.executable, "-c", _F12, str(tree / "blend_scenes" / "demo.blend")], cwd=tmp,
                               env=env, capture_output=True, text=True, check=True)
            line = next(l for l in r.stdout.splitlines() if l.startswith("RESULT"))
            for key, value in json.loads(line[len("RESULT"):]).items():
                out[f"installed_{label}_{key}"] = value
    return out


def run() -> dict:
    import importlib.util
    out = measure()
    if importlib.util.find_spec("bpy") is None:          # the installed-extension figures need Blender
        return out
    return {**out, **measure_installed()}


if __name__ == "__main__":
    if "--installed" in sys.argv:
        print(json.dumps(measure_installed(), indent=2))
    else:
        print(json.dumps(measure(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT), indent=2))
