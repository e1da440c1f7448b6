"""Procedural texture nodes through the interpreter: the compiled program gives what the node's
formula gives (``kernels.procedural``, itself checked against Cycles 5.0 in
tests/test_procedural_textures.py) at each hit's coordinates, for every output.

One triangle, hits at chosen barycentrics; each output is read through an Emission shader
(strength +1, so the closure's clamping keeps values >= 0: we compare max(value, 0))."""
from __future__ import annotations

import numpy as np
import pytest

from stpm_core.kernels import procedural as P
from stpm_core.kernels.closure import C_EMIT, N_CLOSURE
from stpm_core.kernels.svm import shade_closures
from stpm_core.nodes import Link, Node, ShaderGraph
from stpm_core.scene import Instance, Material, Mesh, Scene
from stpm_core.shading import hit_geometry, shading_data

V = np.array([[-1.3, -0.7, 0.2], [2.1, -0.4, 0.9], [0.3, 1.8, -0.5]], np.float32)


class _Hits:
    pass


def _evaluate(node: Node, output: str, kind: str, n: int = 64, seed: int = 0):
    """(object-space points (n, 3), emitted values (n, 3)) of ``node``'s output on the triangle."""
    nodes = {"Coord": Node("ShaderNodeTexCoord", outputs={"Object": "VECTOR", "Normal": "VECTOR"}), "Tex": node}
    node.inputs.setdefault("Vector", Link("Coord", "Object"))
    nodes["Emit"] = Node("ShaderNodeEmission", inputs={"Color": Link("Tex", output), "Strength": 1.0})
    if kind == "VALUE":
        nodes["Comb"] = Node("ShaderNodeCombineXYZ", inputs={"X": Link("Tex", output), "Y": Link("Tex", output),
                                                             "Z": Link("Tex", output)}, outputs={"Vector": "VECTOR"})
        nodes["Emit"].inputs["Color"] = Link("Comb", "Vector")
    g = ShaderGraph(nodes=nodes, surface=Link("Emit", "Emission"))
    mesh = Mesh(vertices=V, triangles=np.array([[0, 1, 2]], np.int32), material_ids=np.zeros(1, np.int32))
    sc = Scene(meshes=[mesh], instances=[Instance(0)], materials=[Material(graph=g)])
    sd = shading_data(sc)
    assert not sd.unsupported, sd.unsupported
    rng = np.random.default_rng(seed)
    bu = rng.uniform(0, 0.6, n)
    bv = rng.uniform(0, 0.4, n)
    h = _Hits()
    h.position = ((1 - bu - bv)[:, None] * V[0] + bu[:, None] * V[1] + bv[:, None] * V[2]).astype(np.float64)
    h.ng = np.tile([0.0, 0.0, 1.0], (n, 1))
    h.ns = h.ng.copy()
    h.instance = np.zeros(n, np.int32)
    h.prim = np.zeros(n, np.int32)
    h.u, h.v = bu, bv
    C = np.zeros((n, N_CLOSURE))
    shade_closures(np.zeros(n, np.int32), sd.closures, sd.prog, sd.n_slots, hit_geometry(h, -h.ng), sd.A, sd.X, 0, C)
    p_obj = (1 - bu - bv)[:, None] * V[0].astype(np.float64) + bu[:, None] * V[1] + bv[:, None] * V[2]
    return p_obj, C[:, C_EMIT:C_EMIT + 3]


def _check(got, want):
    np.testing.assert_allclose(got, np.maximum(np.asarray(want, float), 0.0), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("dims, noise_type", [("3D", "FBM"), ("4D", "RIDGED_MULTIFRACTAL"), ("2D", "HETERO_TERRAIN")])
def test_noise(dims, noise_type):
    node = Node("ShaderNodeTexNoise", props={"noise_dimensions": dims, "noise_type": noise_type, "normalize": True},
                inputs={"W": 0.3, "Scale": 3.0, "Detail": 3.0, "Roughness": 0.6, "Distortion": 0.4},
                outputs={"Fac": "VALUE", "Color": "RGBA"})
    p, fac = _evaluate(node, "Fac", "VALUE")
    p2, col = _evaluate(Node(node.type, props=dict(node.props), inputs={k: v for k, v in node.inputs.items()
                                                                        if k != "Vector"}, outputs=node.outputs),
                        "Color", "RGBA")
    d = P.DIMENSIONS[dims]
    want = np.array([P.noise_texture(x, y, z, 0.3, d, 3.0, 3.0, 0.6, 2.0, 0.4, True, P.NOISE_TYPES[noise_type],
                                     0.0, 1.0, True) for x, y, z in p])
    _check(fac, np.repeat(want[:, :1], 3, axis=1))
    _check(col, want[:, 1:])


@pytest.mark.parametrize("feature, metric", [("F1", "EUCLIDEAN"), ("SMOOTH_F1", "MANHATTAN"), ("F2", "MINKOWSKI")])
def test_voronoi(feature, metric):
    props = {"voronoi_dimensions": "3D", "feature": feature, "distance": metric, "normalize": False}
    ins = {"Scale": 4.0, "Randomness": 0.8, "Exponent": 1.5, "Smoothness": 0.5}
    p, dist = _evaluate(Node("ShaderNodeTexVoronoi", props=props, inputs=dict(ins)), "Distance", "VALUE")
    _, col = _evaluate(Node("ShaderNodeTexVoronoi", props=props, inputs=dict(ins)), "Color", "RGBA")
    _, pos = _evaluate(Node("ShaderNodeTexVoronoi", props=props, inputs=dict(ins)), "Position", "VECTOR")
    want = np.array([P.voronoi_texture(x, y, z, 0.0, 3, 4.0, 0.0, 0.5, 2.0, 0.5, 1.5, 0.8,
                                       P.VORONOI_FEATURES[feature], P.VORONOI_METRICS[metric], False)
                     for x, y, z in p])
    _check(dist, np.repeat(want[:, :1], 3, axis=1))
    _check(col, want[:, 1:4])
    _check(pos, want[:, 4:7])


def test_wave_brick_magic_white_noise():
    p, wave = _evaluate(Node("ShaderNodeTexWave", props={"wave_type": "RINGS", "rings_direction": "SPHERICAL",
                                                          "wave_profile": "SAW"},
                             inputs={"Scale": 2.0, "Distortion": 1.5, "Detail": 3.0}), "Fac", "VALUE")
    _check(wave, np.array([[P.wave_texture(x, y, z, 1, 0, 3, 1, 2.0, 1.5, 3.0, 1.0, 0.5, 0.0)[0]] * 3
                           for x, y, z in p]))
    c1, c2, m = (0.9, 0.2, 0.1), (0.1, 0.5, 0.9), (0.3, 0.3, 0.3)
    p, brick = _evaluate(Node("ShaderNodeTexBrick", props={"offset": 0.4, "offset_frequency": 2, "squash": 1.2,
                                                            "squash_frequency": 3},
                              inputs={"Color1": c1, "Color2": c2, "Mortar": m, "Scale": 3.0, "Bias": 0.2}),
                         "Color", "RGBA")
    want = []
    for x, y, z in p:
        f, tint = P.brick_texture(x, y, z, 3.0, 0.02, 0.1, 0.2, 0.5, 0.25, 0.4, 2, 1.2, 3)
        want.append(P.brick_color(f, tint, *c1, *c2, *m))
    _check(brick, want)
    p, magic = _evaluate(Node("ShaderNodeTexMagic", props={"turbulence_depth": 4},
                              inputs={"Scale": 2.0, "Distortion": 1.3}), "Color", "RGBA")
    _check(magic, [P.magic_texture(x, y, z, 4, 2.0, 1.3)[1:] for x, y, z in p])
    p, white = _evaluate(Node("ShaderNodeTexWhiteNoise", props={"noise_dimensions": "3D"}), "Color", "RGBA")
    _check(white, [P.white_noise_texture(x, y, z, 0.0, 3)[1:] for x, y, z in p])


def test_texture_coordinate_normal_is_the_object_space_normal():
    p, got = _evaluate(Node("ShaderNodeMapping", props={"vector_type": "VECTOR"},
                            inputs={"Vector": Link("Coord", "Normal"), "Scale": (1.0, 1.0, 1.0)}), "Vector", "VECTOR")
    n = np.cross(V[1] - V[0], V[2] - V[0]).astype(np.float64)
    _check(got, np.tile(n / np.linalg.norm(n), (p.shape[0], 1)))
