"""What textures and shader nodes cost: the same scene with flat colours and with node materials.

Scene: the tracer benchmark's ~107k-triangle scene (``bench_render.render_scene``; 320 x 240 at 16
spp, a point light and a grey world) once with its flat diffuse material and once with a node
material on every surface: a 1024 x 1024 8-bit sRGB image texture read through Object
coordinates and a Mapping node (Linear interpolation), multiplied by a Checker (Mix Color), into
a Principled BSDF's Base Color, plus a ColorRamp on its Roughness.  Photon tracing: the same two
materials, 200k global photons from the point light.

Reported (one run, interleaved rounds, minimum CPU seconds of the tracing thread):

* ``tracer_shading_flat_s`` / ``tracer_shading_nodes_s``: CPU s outside ray casting, and
  ``tracer_nodes_over_flat`` = whole-tracer CPU s with nodes / without (target <= 1.3);
* ``photon_trace_nodes_over_flat``: the same ratio for photon tracing (target <= 1.3);
* ``texture_bytes_per_texel``: stored bytes per texel of the 8-bit RGB image (3: its own size);
* ``cold_compile_flat_s`` / ``cold_compile_nodes_s``: a fresh process rendering a tiny version of
  each scene with an empty numba cache (the interpreter's share is the difference; the issue's
  target: the node scene's cold compile at most 20 % above the flat scene's of 2026-11-30), wall
  seconds; ``..._cpu_s`` the process's CPU seconds (what another job on the machine changes less),
  ``..._kernels`` the STPM functions it compiled (``numba_probe.compile_counts``).
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

from stpm_core.nodes import Link, Node, ShaderGraph
from stpm_core.scene import Material
from stpm_core.textures import Texture

from .bench_render import TimingCaster, _trace, render_scene

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
N_TEX = 1024


def node_material(tex_index: int = 0) -> Material:
    """The benchmark's node material (see the module docstring)."""
    g = ShaderGraph(nodes={
        "Coord": Node("ShaderNodeTexCoord", outputs={"Generated": "VECTOR", "Normal": "VECTOR", "UV": "VECTOR",
                                                    "Object": "VECTOR", "Reflection": "VECTOR"}),
        "Mapping": Node("ShaderNodeMapping", props={"vector_type": "POINT"},
                        inputs={"Vector": Link("Coord", "Object"), "Scale": (0.3, 0.3, 0.3),
                                "Rotation": (0.0, 0.0, 0.4), "Location": (0.0, 0.0, 0.0)},
                        outputs={"Vector": "VECTOR"}),
        "Image": Node("ShaderNodeTexImage", props={"image": tex_index, "interpolation": "Linear",
                                                   "extension": "REPEAT", "projection": "FLAT"},
                      inputs={"Vector": Link("Mapping", "Vector")}, outputs={"Color": "RGBA", "Alpha": "VALUE"}),
        "Checker": Node("ShaderNodeTexChecker", inputs={"Vector": Link("Coord", "Object"), "Scale": 2.0,
                                                        "Color1": (1.0, 1.0, 1.0), "Color2": (0.5, 0.5, 0.5)},
                        outputs={"Color": "RGBA", "Fac": "VALUE"}),
        "Mix": Node("ShaderNodeMix", props={"data_type": "RGBA", "blend_type": "MULTIPLY", "clamp_factor": True},
                    inputs={"Factor_Float": 1.0, "A_Color": Link("Image", "Color"), "B_Color": Link("Checker", "Color")},
                    outputs={"Result_Color": "RGBA"}),
        "Ramp": Node("ShaderNodeValToRGB", props={"elements": [(0.0, (0.2, 0.2, 0.2, 1.0)), (1.0, (0.9, 0.9, 0.9, 1.0))],
                                                  "interpolation": "LINEAR"},
                     inputs={"Fac": Link("Checker", "Fac")}, outputs={"Color": "RGBA", "Alpha": "VALUE"}),
        "BSDF": Node("ShaderNodeBsdfPrincipled", inputs={"Base Color": Link("Mix", "Result_Color"),
                                                        "Roughness": Link("Ramp", "Color"), "Specular IOR Level": 0.0},
                     outputs={"BSDF": "SHADER"}),
    }, surface=Link("BSDF", "BSDF"))
    return Material(base_color=np.full(3, 0.5), roughness=0.5, graph=g, name="textured")


def texture(n: int = N_TEX) -> Texture:
    rng = np.random.default_rng(1)
    return Texture(rng.integers(0, 256, (n, n, 3), dtype=np.uint8), colorspace="sRGB", name="noise")


def textured_scene(moving: bool = False):
    sc = render_scene(moving)
    sc.textures = [texture()]
    sc.materials = [node_material(0)]
    return sc


def _tracer_cpu(sc, caster):
    timed = TimingCaster(caster)
    t0 = time.thread_time()
    _trace(sc, timed, threads=1)
    return time.thread_time() - t0, timed.seconds


def _photon_cpu(sc, caster, n: int = 200_000):
    from stpm_core.bsdf import MaterialTable
    from stpm_core.lights import LightSet
    from stpm_core.photons.trace import trace_global_map
    from stpm_core.settings import RenderSettings
    st = RenderSettings(samples=1, photons_global=n, photons_caustic=0, seed=0, threads=1)
    t0 = time.thread_time()
    recs, _ = trace_global_map(sc, st, caster, LightSet(sc), MaterialTable(sc.materials))
    return time.thread_time() - t0


_CHILD = r"""
import json, sys, time
sys.path.insert(0, sys.argv[1])
t0 = time.perf_counter()
from benchmarks.bench_textures import textured_scene
from benchmarks.bench_render import render_scene
from stpm_core.render import render
from stpm_core.settings import RenderSettings
from stpm_core.numba_probe import compile_counts
sc = textured_scene() if sys.argv[2] == "nodes" else render_scene(False)
sc.resolution = (32, 24)
render(sc, RenderSettings(samples=1, photons_global=1000, photons_caustic=0, seed=0))
print(json.dumps({"s": time.perf_counter() - t0, "cpu_s": time.process_time(), "kernels": compile_counts()[0]}))
"""


def cold_compile(kind: str) -> dict:
    """A fresh process rendering the flat or node scene with an empty numba cache: {'s': wall
    seconds, 'cpu_s': its CPU seconds, 'kernels': STPM functions compiled}."""
    with tempfile.TemporaryDirectory(prefix="stpm-numba-cache-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        r = subprocess.run([sys.executable, "-c", _CHILD, ROOT, kind], env=env, capture_output=True, text=True,
                           check=True)
        return json.loads(r.stdout.strip().splitlines()[-1])


def run(rounds: int = 4) -> dict:
    from stpm_core.raycast import make_caster
    from stpm_core.raycast.build import embree_available
    out: dict = {"resolution": "320x240", "spp": 16, "texture": f"{N_TEX}x{N_TEX} uint8 RGB"}
    if not embree_available():
        out["skipped"] = "embreex not importable"
        return out
    flat, nodes = render_scene(False), textured_scene(False)
    cf, cn = make_caster(flat, "embree"), make_caster(nodes, "embree")
    _trace(flat, cf, 1)
    _trace(nodes, cn, 1)                       # compile / load, not timed
    _photon_cpu(flat, cf, 10_000)
    _photon_cpu(nodes, cn, 10_000)
    t = {"flat": [], "nodes": [], "flat_cast": [], "nodes_cast": [], "pf": [], "pn": []}
    for _ in range(rounds):
        a, ac = _tracer_cpu(flat, cf)
        b, bc = _tracer_cpu(nodes, cn)
        t["flat"].append(a)
        t["flat_cast"].append(ac)
        t["nodes"].append(b)
        t["nodes_cast"].append(bc)
        t["pf"].append(_photon_cpu(flat, cf))
        t["pn"].append(_photon_cpu(nodes, cn))
    i, j = int(np.argmin(t["flat"])), int(np.argmin(t["nodes"]))
    out["tracer_cpu_flat_s"] = t["flat"][i]
    out["tracer_cpu_nodes_s"] = t["nodes"][j]
    out["tracer_shading_flat_s"] = t["flat"][i] - t["flat_cast"][i]
    out["tracer_shading_nodes_s"] = t["nodes"][j] - t["nodes_cast"][j]
    out["tracer_nodes_over_flat"] = t["nodes"][j] / t["flat"][i]
    out["tracer_nodes_over_flat_per_round"] = [round(b / a, 3) for a, b in zip(t["flat"], t["nodes"])]
    out["photon_trace_flat_s"] = min(t["pf"])
    out["photon_trace_nodes_s"] = min(t["pn"])
    out["photon_trace_nodes_over_flat"] = min(t["pn"]) / min(t["pf"])
    tex = nodes.textures[0]
    out["texture_bytes_per_texel"] = tex.nbytes / (tex.pixels.shape[0] * tex.pixels.shape[1])
    for kind in ("flat", "nodes"):
        c = cold_compile(kind)
        out[f"cold_compile_{kind}_s"], out[f"cold_compile_{kind}_cpu_s"] = c["s"], c["cpu_s"]
        out[f"cold_compile_{kind}_kernels"] = c["kernels"]
    out["cold_compile_nodes_over_flat"] = out["cold_compile_nodes_s"] / out["cold_compile_flat_s"]
    out["cold_compile_nodes_over_flat_cpu"] = out["cold_compile_nodes_cpu_s"] / out["cold_compile_flat_cpu_s"]
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:40s} {v}")
