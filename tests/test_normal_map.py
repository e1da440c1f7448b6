"""Normal Map node: analytic answers on a lit plane (the shading normal the node makes).

A 2 m plane at z = 0 (UVs over [0, 1]^2, tangent +X, bitangent sign +1) under a sun from straight
above (irradiance S on the plane), seen by an orthographic camera from above: a diffuse surface
with shading normal n reflects L = rho / pi * S * max(n . z, 0).  A constant normal-map colour
c encodes the tangent-space normal 2 c - 1, so tilting it by angle a about the bitangent gives
n . z = cos a.  The plane is also turned about Z by a rotating instance: a tangent-space map
follows the object, so the answer does not change.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from stpm_core.motion import MotionTransform
from stpm_core.nodes import Link, Node, ShaderGraph
from stpm_core.render import render
from stpm_core.scene import Camera, Instance, Light, Material, Mesh, Scene, World
from stpm_core.settings import RenderSettings

S = 3.0              # sun strength, W/m^2
RHO = 0.8


def _plane(angle_z: float = 0.0, spin: bool = False):
    V = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    F = np.array([[0, 1, 2], [0, 2, 3]], np.int32)
    uv = (V[F][:, :, :2] * 0.5 + 0.5).astype(np.float32)
    tan = np.zeros((2, 3, 4), np.float32)
    tan[:, :, 0] = 1.0
    tan[:, :, 3] = 1.0
    mesh = Mesh(vertices=V, triangles=F, material_ids=np.zeros(2, np.int32), uv_layers={"UVMap": uv},
                uv_render="UVMap", tangents={"UVMap": tan})

    def rz(a):
        M = np.eye(4)
        M[:2, :2] = [[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]]
        return M
    tr = MotionTransform(np.array([0.0, 1.0]), np.stack([rz(angle_z), rz(angle_z + 1.0)])) if spin \
        else MotionTransform.static(rz(angle_z))
    return mesh, Instance(0, tr)


def _graph(color, space="TANGENT", strength=1.0):
    return ShaderGraph(nodes={
        "Map": Node("ShaderNodeNormalMap", props={"space": space, "uv_map": ""},
                    inputs={"Color": tuple(color), "Strength": strength}, outputs={"Normal": "VECTOR"}),
        "BSDF": Node("ShaderNodeBsdfDiffuse", inputs={"Color": (RHO, RHO, RHO), "Normal": Link("Map", "Normal")},
                     outputs={"BSDF": "SHADER"}),
    }, surface=Link("BSDF", "BSDF"))


def _render(graph, angle_z=0.0, spin=False):
    mesh, inst = _plane(angle_z, spin)
    cam = np.eye(4)
    cam[2, 3] = 5.0
    sc = Scene(meshes=[mesh], instances=[inst], materials=[Material(graph=graph)],
               camera=Camera(type="ORTHO", ortho_scale=1.0, transform=MotionTransform.static(cam)),
               lights=[Light(type="SUN", power=S, transform=MotionTransform.static(np.eye(4)))],
               world=World(color=np.zeros(3), strength=0.0), resolution=(8, 8))
    if spin:
        from stpm_core.shutter import Shutter
        sc.shutter = Shutter(1.0, 1.5)
    res = render(sc, RenderSettings(samples=4, photons_global=0, photons_caustic=0))
    assert not res.warnings, res.warnings
    return res.passes["Combined"][..., :3], res.passes["Normal"]


def _tilted(a: float, axis: str = "x") -> tuple:
    n = (math.sin(a), 0.0, math.cos(a)) if axis == "x" else (0.0, math.sin(a), math.cos(a))
    return tuple(0.5 * v + 0.5 for v in n)


@pytest.mark.parametrize("a", [0.0, 0.4, 1.0])
def test_tangent_space_tilt_gives_cosine(a):
    img, normal = _render(_graph(_tilted(a)))
    np.testing.assert_allclose(img, RHO / math.pi * S * math.cos(a), rtol=1e-6)
    # the Normal pass shows the mapped normal: tilted toward +X (the tangent)
    np.testing.assert_allclose(normal[..., 0], math.sin(a), atol=1e-6)


@pytest.mark.parametrize("spin", [False, True])
def test_tangent_space_follows_the_object(spin):
    # Turned 90 degrees about Z (or spinning during the shutter) the tilt is still cos(a) to the sun
    a = 0.7
    img, normal = _render(_graph(_tilted(a, "y")), angle_z=math.pi / 2, spin=spin)
    np.testing.assert_allclose(img, RHO / math.pi * S * math.cos(a), rtol=1e-6)
    if not spin:
        # bitangent +Y turned to -X in world space
        np.testing.assert_allclose(normal[..., 0], -math.sin(a), atol=1e-6)


@pytest.mark.parametrize("s", [0.5, 3.0])
def test_strength_scales_the_tangent_space_normal(s):
    """Cycles applies a tangent-space map's Strength to the decoded colour c = (sin a, 0, cos a):
    (s c_x, s c_y, 1 + (c_z - 1) sat(s)), then normalises (no displacement: svm_node_normal_map)."""
    a = 1.0
    img, _ = _render(_graph(_tilted(a), strength=s))
    m = np.array([s * math.sin(a), 0.0, 1.0 + (math.cos(a) - 1.0) * min(s, 1.0)])
    np.testing.assert_allclose(img, RHO / math.pi * S * m[2] / np.linalg.norm(m), rtol=1e-6)


def test_strength_blends_object_space_normals_from_the_surface_normal():
    a, s = 0.5, 1.5                      # the blended normal stays above the surface
    n = (math.sin(a), 0.0, math.cos(a))
    img, _ = _render(_graph(tuple(0.5 * v + 0.5 for v in n), space="WORLD", strength=s))
    # normalize(z + s (n - z))
    m = np.array([s * math.sin(a), 0.0, 1.0 + s * (math.cos(a) - 1.0)])
    np.testing.assert_allclose(img, RHO / math.pi * S * m[2] / np.linalg.norm(m), rtol=1e-6)


@pytest.mark.parametrize("space", ["OBJECT", "WORLD"])
def test_object_and_world_space(space):
    # Object space follows the instance's rotation (90 degrees about Z), world space does not
    a = 0.6
    n = (math.sin(a), 0.0, math.cos(a))
    img, normal = _render(_graph(tuple(0.5 * v + 0.5 for v in n), space=space), angle_z=math.pi / 2)
    np.testing.assert_allclose(img, RHO / math.pi * S * math.cos(a), rtol=1e-6)
    expect = (0.0, math.sin(a)) if space == "OBJECT" else (math.sin(a), 0.0)
    np.testing.assert_allclose(normal[..., 0], expect[0], atol=1e-6)
    np.testing.assert_allclose(normal[..., 1], expect[1], atol=1e-6)


def test_without_tangents_the_surface_normal_is_used():
    mesh, inst = _plane()
    mesh.tangents = {}                      # e.g. a mesh without that UV map
    cam = np.eye(4)
    cam[2, 3] = 5.0
    sc = Scene(meshes=[mesh], instances=[inst], materials=[Material(graph=_graph(_tilted(1.0)))],
               camera=Camera(type="ORTHO", ortho_scale=1.0, transform=MotionTransform.static(cam)),
               lights=[Light(type="SUN", power=S, transform=MotionTransform.static(np.eye(4)))],
               world=World(color=np.zeros(3), strength=0.0), resolution=(4, 4))
    img = render(sc, RenderSettings(samples=1, photons_global=0, photons_caustic=0)).passes["Combined"][..., :3]
    np.testing.assert_allclose(img, RHO / math.pi * S, rtol=1e-6)


def _bump_graph(k: float, distance: float = 1.0, strength: float = 1.0, invert: bool = False):
    """Height = k * Object x (a ramp rising toward +X) into a Bump node into a diffuse Normal."""
    return ShaderGraph(nodes={
        "Coord": Node("ShaderNodeTexCoord", outputs={"Generated": "VECTOR", "Normal": "VECTOR", "UV": "VECTOR",
                                                    "Object": "VECTOR", "Reflection": "VECTOR"}),
        "Sep": Node("ShaderNodeSeparateXYZ", inputs={"Vector": Link("Coord", "Object")},
                    outputs={"X": "VALUE", "Y": "VALUE", "Z": "VALUE"}),
        "Mul": Node("ShaderNodeMath", props={"operation": "MULTIPLY"}, inputs={"Value": Link("Sep", "X"),
                                                                               "Value_001": k},
                    outputs={"Value": "VALUE"}),
        "Bump": Node("ShaderNodeBump", props={"invert": invert},
                     inputs={"Height": Link("Mul", "Value"), "Strength": strength, "Distance": distance},
                     outputs={"Normal": "VECTOR"}),
        "BSDF": Node("ShaderNodeBsdfDiffuse", inputs={"Color": (RHO, RHO, RHO), "Normal": Link("Bump", "Normal")},
                     outputs={"BSDF": "SHADER"}),
    }, surface=Link("BSDF", "BSDF"))


@pytest.mark.parametrize("k, distance, invert", [(0.5, 1.0, False), (2.0, 0.3, False), (1.0, 1.0, True)])
def test_bump_of_a_linear_ramp_tilts_the_normal_by_its_slope(k, distance, invert):
    # N' = normalize(N - d grad h) = normalize((-d k, 0, 1)) (invert: d -> -d); the plane turned
    # 90 degrees about Z moves the ramp's slope to world +Y but keeps the cosine to the sun
    slope = -distance * k * (-1.0 if invert else 1.0)
    for angle, axis in ((0.0, 0), (math.pi / 2, 1)):
        img, normal = _render(_bump_graph(k, distance, invert=invert), angle_z=angle)
        np.testing.assert_allclose(img, RHO / math.pi * S / math.sqrt(1.0 + slope ** 2), rtol=1e-5)
        np.testing.assert_allclose(normal[..., axis], slope / math.sqrt(1.0 + slope ** 2), atol=1e-5)


def test_bump_strength_zero_keeps_the_surface_normal():
    img, _ = _render(_bump_graph(2.0, strength=0.0))
    np.testing.assert_allclose(img, RHO / math.pi * S, rtol=1e-6)
