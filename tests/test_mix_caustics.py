"""Caustic lobes hidden in a Mix Shader: the effects plan and the caustic tracer's aiming read
each lobe some hit can pick (``nodes.shader_lobes``), not the blended representative constants.

The constants below are what the exporter writes for each graph (addon/export/materials.py:
a Mix Shader blends its branches' parameters by the Fac socket's own value, linked or not), so
the old rule (constants only) misses the smooth coat and the textured-Fac glass.
"""
from __future__ import annotations

import numpy as np

from scenes import make_scene, ortho_camera_down, plane_mesh, point_light, sphere_mesh, translate
from stpm_core.nodes.graph import Link, Node, ShaderGraph, shader_lobes
from stpm_core.plan import make_plan
from stpm_core.scene import Material
from stpm_core.settings import RenderSettings

BSDF = {"BSDF": "SHADER"}


def _mix(fac, a: Node, b: Node, **extra) -> ShaderGraph:
    """Mix Shader(Fac, Shader = a, Shader_001 = b); ``extra`` nodes (a texture feeding Fac)."""
    nodes = {"A": a, "B": b, "Mix": Node("ShaderNodeMixShader", inputs={"Fac": fac, "Shader": Link("A", "BSDF"),
                                                                         "Shader_001": Link("B", "BSDF")},
                                         outputs={"Shader": "SHADER"}), **extra}
    return ShaderGraph(nodes=nodes, surface=Link("Mix", "Shader"))


def _diffuse(color=(0.8, 0.8, 0.8)) -> Node:
    return Node("ShaderNodeBsdfDiffuse", inputs={"Color": tuple(color)}, outputs=BSDF)


def _glass() -> Node:
    return Node("ShaderNodeBsdfGlass", inputs={"Color": (1.0, 1.0, 1.0), "Roughness": 0.0, "IOR": 1.5}, outputs=BSDF)


def _smooth_dielectric() -> Node:
    return Node("ShaderNodeBsdfPrincipled", inputs={"Base Color": (0.8, 0.8, 0.8), "Roughness": 0.0,
                                                   "Specular IOR Level": 0.5}, outputs=BSDF)


def _checker_fac(value: float = 0.5) -> dict:
    """A Checker whose two colours are equal: a linked Fac of ``value`` everywhere."""
    c = (value, value, value)
    return {"Checker": Node("ShaderNodeTexChecker", inputs={"Color1": c, "Color2": c, "Scale": 5.0},
                            outputs={"Color": "RGBA"})}


def coat_mix() -> Material:
    """Diffuse mixed (Fac 0.5) with a smooth dielectric Principled: constants as exported
    (roughness 0.5 * 1 + 0.5 * 0, specular 0.5 * 1): no smooth lobe in the blend."""
    return Material(base_color=np.full(3, 0.8), roughness=0.5, specular=0.5, name="coat mix",
                    graph=_mix(0.5, _diffuse(), _smooth_dielectric()))


def textured_glass_mix(diffuse=(0.8, 0.8, 0.8)) -> Material:
    """Diffuse mixed with a Glass BSDF by a textured Fac whose socket value is 0: exported as the
    Diffuse alone."""
    g = _mix(Link("Checker", "Color"), _diffuse(diffuse), _glass(), **_checker_fac(0.5))
    return Material(base_color=np.asarray(diffuse, float), roughness=1.0, name="textured glass mix", graph=g)


def _ball_scene(ball: Material, *, resolution=(20, 20)):
    """A ball (material 1) of radius 0.5 at height 1 lit from the side: the camera looks down on the
    floor where its caustic lands, past the ball (which it does not see)."""
    floor = Material.diffuse((0.8, 0.8, 0.8), name="floor")
    sphere = sphere_mesh(0.5, 16, 32, material=1, name="ball")
    return make_scene([plane_mesh(6.0, name="floor"), (sphere, translate(0, 0, 1.0))], [floor, ball],
                      ortho_camera_down(5.0, 1.4, center=(1.2, 0.0)), [point_light((-2.0, 0, 3), 300.0)],
                      resolution=resolution)


def test_shader_lobes_follow_every_branch_with_weight():
    assert shader_lobes(coat_mix().graph) == (True, True)
    assert shader_lobes(textured_glass_mix().graph) == (True, True)
    # a constant Fac of 0 / 1 drops the other branch: the rule can say no
    assert shader_lobes(_mix(0.0, _diffuse(), _glass())) == (False, True)
    assert shader_lobes(_mix(1.0, _diffuse(), _glass())) == (True, False)
    rough = Node("ShaderNodeBsdfPrincipled", inputs={"Roughness": 0.4}, outputs=BSDF)
    assert shader_lobes(_mix(0.5, _diffuse(), rough)) == (False, True)   # a rough coat is a diffuse bounce
    black = Node("ShaderNodeBsdfGlossy", inputs={"Color": (0.0, 0.0, 0.0)}, outputs=BSDF)
    assert shader_lobes(_mix(0.5, _diffuse(), black)) == (False, True)


def test_plan_sees_a_smooth_coat_and_a_textured_glass_inside_a_mix():
    for ball in (coat_mix(), textured_glass_mix()):
        plan = make_plan(_ball_scene(ball))
        assert plan["caustics"], (ball.name, plan["reasons"])
        assert plan["details"]["specular_objects"] == ["ball"]
        assert plan["details"]["probe"]["caustic_photons_stored"] > 0
    off = Material(base_color=np.full(3, 0.8), roughness=1.0, graph=_mix(0.0, _diffuse(), _glass()))
    assert not make_plan(_ball_scene(off))["caustics"]


def _caustic(ball: Material, seed: int) -> np.ndarray:
    from stpm_core.render import render
    res = render(_ball_scene(ball), RenderSettings(samples=2, photons_caustic=40000, photons_global=0,
                                                   k_nearest=30, seed=seed, max_depth=8))
    assert res.plan["caustics"]
    return np.asarray(res.passes["Caustic"], float)[..., :3]


def test_caustic_through_a_textured_mix_of_black_diffuse_and_glass():
    """Mix(black Diffuse, Glass) at Fac 0.5 (textured) is, closure for closure, a Glass BSDF of
    colour 0.5 (its colour scales reflection and refraction alike): the same caustic under the
    ball, which the old rule (constants: a black Diffuse) did not trace at all."""
    half = Material(base_color=np.full(3, 0.5), transmission=1.0, roughness=0.0, ior=1.5,
                    reflection_tint=np.full(3, 0.5), name="glass 0.5")
    mix = textured_glass_mix(diffuse=(0.0, 0.0, 0.0))
    seeds = (1, 2, 3)
    a = np.array([_caustic(mix, s).sum() for s in seeds])
    b = np.array([_caustic(half, s).sum() for s in seeds])
    assert b.mean() > 0
    ratio = a.mean() / b.mean()
    spread = np.sqrt(a.var(ddof=1) / a.mean() ** 2 / len(seeds) + b.var(ddof=1) / b.mean() ** 2 / len(seeds))
    assert abs(ratio - 1.0) < max(4.0 * spread, 0.03), (ratio, spread, a, b)
