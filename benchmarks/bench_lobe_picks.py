"""Lobe picks against Cycles: per-pixel variance STPM / Cycles where a smooth dielectric picks
reflection or refraction (issue 14; docs/rendering.md, "The lobe's pick").

Scenes (64 x 48, 64 samples, 4 seeds of each renderer):

* ``water``: ``tests/sun_glint_scenes.py``'s sun glint in water (Principled, transmission 1, IOR
  1.33, roughness 0; the reflection picked with probability F), Cycles with one glossy and one
  transmission bounce, STPM ``max_depth = 1``;
* ``glass_sphere``: a smooth Glass BSDF sphere (IOR 1.45, radius 0.8) in front of an emissive
  checker wall, grey world; 6 glossy / transmission bounces, STPM ``max_depth = 6``.

Results per scene: the block Z-test's largest |z| and mean ratio (``tests/cycles_ref.block_ztest``),
the per-pixel variance over seeds STPM / Cycles summed over lit pixels and its median there
(``cycles_ref.lit_variance_ratio``), and for the sphere the summed ratio inside its central 8 px.
Cycles' images are cached in ``bench_out/cache/lobe_picks/``; PNGs of seed 0 are written there.

    PYTHONPATH=. .venv/bin/python -m benchmarks lobe_picks
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
SPP, SEEDS = 64, (0, 1, 2, 3)


def _emissive_checker(name: str):
    import bpy
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    for n in [n for n in t.nodes if n.type != "OUTPUT_MATERIAL"]:
        t.nodes.remove(n)
    out = next(n for n in t.nodes if n.type == "OUTPUT_MATERIAL")
    em, ck = t.nodes.new("ShaderNodeEmission"), t.nodes.new("ShaderNodeTexChecker")
    ck.inputs["Scale"].default_value = 8.0
    ck.inputs["Color1"].default_value = (1.0, 0.9, 0.7, 1)
    ck.inputs["Color2"].default_value = (0.1, 0.2, 0.5, 1)
    t.links.new(ck.outputs["Color"], em.inputs["Color"])
    t.links.new(em.outputs["Emission"], out.inputs["Surface"])
    return mat


def _glass(name: str, ior: float = 1.45):
    import bpy
    mat = bpy.data.materials.new(name)
    t = mat.node_tree
    for n in [n for n in t.nodes if n.type != "OUTPUT_MATERIAL"]:
        t.nodes.remove(n)
    out = next(n for n in t.nodes if n.type == "OUTPUT_MATERIAL")
    g = t.nodes.new("ShaderNodeBsdfGlass")
    g.inputs["Roughness"].default_value = 0.0
    g.inputs["IOR"].default_value = ior
    t.links.new(g.outputs["BSDF"], out.inputs["Surface"])
    return mat


def glass_sphere():
    """A smooth glass sphere (radius 0.8) 3 m before an emissive checker wall, grey world."""
    import bpy
    from test_addon_scenes import add_camera, add_mesh, fresh, set_world
    scene = fresh()
    scene.render.resolution_x, scene.render.resolution_y = 64, 48
    set_world((0.2, 0.2, 0.2), 1.0)
    add_mesh("plane", "Wall", location=(0, 3, 1), material=_emissive_checker("Wall"), size=6.0,
             rotation=(math.pi / 2, 0, 0))
    add_mesh("sphere", "Ball", location=(0, 0, 1), material=_glass("Glass"), radius=0.8, segments=48,
             ring_count=24)
    bpy.ops.object.shade_smooth()
    add_camera(location=(0, -5, 1), rotation=(math.pi / 2, 0, 0), lens=50)
    return scene


def run() -> dict:
    sys.path.insert(0, str(ROOT / "tests"))
    import bpy  # noqa: F401
    import sun_glint_scenes as sgs
    from cycles_ref import block_ztest, lit_variance_ratio, render_cycles_paths, render_stpm
    from stpm_core.imageio import write_png
    out = ROOT / "bench_out" / "cache" / "lobe_picks"
    out.mkdir(parents=True, exist_ok=True)
    res = {}
    for name, build, depth in (("water", lambda: sgs.build("water"), 1), ("glass_sphere", glass_sphere, 6)):
        build()
        scene = bpy.context.scene
        cache = out / f"cycles_{name}_{SPP}_{len(SEEDS)}.npy"
        if cache.exists():
            cyc = np.load(cache)
        else:
            cyc = render_cycles_paths(scene, out, samples=SPP, seeds=SEEDS, diffuse_bounces=0, glossy_bounces=depth,
                                      transmission_bounces=depth, caustics=True)
            np.save(cache, cyc)
        stpm, _ = render_stpm(scene, samples=SPP, seeds=SEEDS, max_depth=depth)
        r = block_ztest(stpm, cyc)
        s, c = stpm.mean(axis=-1), cyc.mean(axis=-1)
        cm = c.mean(axis=0)
        lit = cm > 0.05 * np.percentile(cm, 90)
        vs, vc = s.var(axis=0, ddof=1), c.var(axis=0, ddof=1)
        med, _ = lit_variance_ratio(stpm, cyc)
        res[f"{name}_z_max"] = float(r.z_abs_max)
        res[f"{name}_mean_ratio"] = r.mean_ratio
        res[f"{name}_var_summed"] = float(vs[lit].sum() / max(float(vc[lit].sum()), 1e-300))
        res[f"{name}_var_median"] = med
        if name == "glass_sphere":
            H, W = vs.shape
            yy, xx = np.mgrid[:H, :W]
            core = np.hypot(xx - (W - 1) / 2, yy - (H - 1) / 2) < 8
            res["glass_sphere_core_var_summed"] = float(vs[core].sum() / max(float(vc[core].sum()), 1e-300))
        write_png(str(out / f"{name}_cycles.png"), cyc[0])
        write_png(str(out / f"{name}_stpm.png"), stpm[0])
    return res
