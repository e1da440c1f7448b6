"""The effects plan (stpm_core.plan): each rule on a scene built to switch it, and the renderer following it."""
from __future__ import annotations

import json

import numpy as np
import pytest

from scenes import (box_mesh, make_scene, moving, ortho_camera_down, persp_camera, plane_mesh, point_light,
                    sphere_mesh, translate)
from stpm_core.motion import MotionTransform
from stpm_core.plan import (EFFECT_KEYS, PROBE_RETURN_MIN, apply_plan, format_plan, make_plan, plan_summary,
                             self_reflecting)
from stpm_core.scene import Light, Material, Mesh
from stpm_core.settings import RenderSettings
from stpm_core.shutter import Shutter

OPEN = Shutter(0.75, 1.25)
DIFFUSE, GLASS, MIRROR, ROUGH_METAL = 0, 1, 2, 3
MATERIALS = [Material.diffuse((0.8, 0.8, 0.8), name="white"), Material.glass(1.5), Material.mirror(),
             Material.mirror(roughness=0.4, name="brushed")]


def _scene(objects, *, lights=None, shutter=OPEN, camera=None):
    return make_scene(objects, MATERIALS, camera or persp_camera((0, -6, 3), (0, 0, 0.5)),
                      [point_light((0, 0, 3), 300.0)] if lights is None else lights, shutter=shutter)


def _glass_over_floor(sphere_motion=None, **kw):
    sphere = sphere_mesh(0.5, 12, 24, material=GLASS, name="ball")
    return _scene([plane_mesh(6.0, name="floor"),
                   (sphere, sphere_motion if sphere_motion is not None else translate(0, 0, 1))], **kw)


def _inward_box(size=2.0, material=DIFFUSE, name="room") -> Mesh:
    m = box_mesh((-size / 2,) * 3, (size / 2,) * 3, material=material, name=name)
    m.triangles = m.triangles[:, ::-1].copy()
    return m


# ----------------------------------------------------------------------------
# Motion blur and time dependence
# ----------------------------------------------------------------------------
def test_moving_glass_over_floor_calls_for_motion_caustics_and_time():
    plan = make_plan(_glass_over_floor(moving((-0.5, 0, 1), (0.5, 0, 1))))
    assert plan["motion_blur"] and plan["caustics"] and plan["time_dependent"]
    assert not plan["indirect"]                      # one convex diffuse floor: nothing to interreflect
    d = plan["details"]
    assert d["moving_objects"] == ["ball"] and d["specular_objects"] == ["ball"]
    assert d["lights_reaching_specular"] == {"light": ["ball"]}
    assert d["probe"]["caustic_photons_stored"] > 0
    assert plan["estimator"] == "TEMPORAL"
    assert {r.split(":")[0] for r in plan["reasons"]} >= set(EFFECT_KEYS)


def test_static_scene_is_not_time_dependent_and_uses_standard():
    plan = make_plan(_glass_over_floor(), RenderSettings(estimator="KD4D"))
    assert not plan["motion_blur"] and not plan["time_dependent"]
    assert plan["caustics"] and plan["estimator"] == "STANDARD"


def test_zero_length_shutter_ignores_motion():
    plan = make_plan(_glass_over_floor(moving((-0.5, 0, 1), (0.5, 0, 1)), shutter=Shutter(1.0, 1.0)))
    assert not plan["motion_blur"] and not plan["time_dependent"]
    assert "zero length" in plan["reasons"][0]


def test_camera_pan_is_motion_blur_but_not_time_dependent():
    cam = persp_camera((0, -6, 3), (0, 0, 0.5))
    M0 = cam.transform.at(0.5)
    cam.transform = MotionTransform(np.array([0.0, 1.0]), np.stack([translate(-1, 0, 0) @ M0, translate(1, 0, 0) @ M0]))
    plan = make_plan(_glass_over_floor(camera=cam))
    assert plan["motion_blur"] and plan["details"]["camera_moves"]
    assert plan["caustics"] and not plan["time_dependent"] and plan["estimator"] == "STANDARD"
    assert "only the camera moves" in plan["reasons"][-1]


def test_moving_light_is_motion_but_a_moving_dark_light_is_not():
    lit = Light(type="POINT", power=300.0, transform=moving((-1, 0, 3), (1, 0, 3)), name="lamp")
    plan = make_plan(_glass_over_floor(lights=[lit]))
    assert plan["motion_blur"] and plan["time_dependent"] and plan["details"]["moving_lights"] == ["lamp"]
    dark = Light(type="POINT", power=0.0, transform=moving((-1, 0, 3), (1, 0, 3)), name="off")
    plan = make_plan(_glass_over_floor(lights=[point_light((0, 0, 3), 300.0), dark]))
    assert not plan["motion_blur"] and plan["details"]["dark_lights"] == ["off"]


def test_deforming_mesh_is_motion():
    floor = plane_mesh(6.0, name="floor")
    v = np.asarray(floor.vertices)
    wave = Mesh(vertices=np.stack([v, v + [0, 0, 0.3]]).astype(np.float32), triangles=floor.triangles,
                material_ids=floor.material_ids, vertex_times=np.array([0.0, 1.0]), name="wave")
    plan = make_plan(_scene([wave, (sphere_mesh(0.5, 8, 16, material=GLASS, name="ball"), translate(0, 0, 1.5))]))
    assert plan["motion_blur"] and plan["time_dependent"] and plan["details"]["deforming_objects"] == ["wave"]


# ----------------------------------------------------------------------------
# Caustics
# ----------------------------------------------------------------------------
def test_no_specular_no_caustics():
    plan = make_plan(_scene([plane_mesh(6.0, name="floor"), (box_mesh(material=DIFFUSE), translate(0, 0, 0.5))]))
    assert not plan["caustics"] and "no specular object" in plan["reasons"][1]
    assert plan["indirect"]                          # floor + box light each other


def test_rough_metal_casts_glossy_caustics():
    """Caustic photons go on through glossy lobes (L (S|G)+ D, docs/rendering.md "Path partition"):
    a rough metal sphere over a floor is a caustic source."""
    plan = make_plan(_scene([plane_mesh(6.0), (sphere_mesh(0.5, 8, 16, material=ROUGH_METAL, name="ball"),
                                               translate(0, 0, 1))]))
    assert plan["caustics"] and plan["details"]["specular_objects"] == ["ball"]


def test_mirror_caustic_and_zero_power_light():
    objs = [plane_mesh(6.0), (sphere_mesh(0.5, 8, 16, material=MIRROR, name="chrome"), translate(0, 0, 1))]
    assert make_plan(_scene(objs))["caustics"]
    plan = make_plan(_scene(objs, lights=[point_light((0, 0, 3), 0.0)]))
    assert not any(plan[k] for k in EFFECT_KEYS)
    assert "no light with power > 0" in plan["reasons"][1]


def test_spot_aimed_away_from_the_glass_gives_no_caustics():
    away = Light(type="SPOT", power=500.0, spot_size=0.3, name="spot",
                 transform=MotionTransform.static(translate(4, 0, 3)))   # looks down -Z at (4, 0, 0)
    plan = make_plan(_glass_over_floor(lights=[away]))
    assert not plan["caustics"] and "no light reaches" in plan["reasons"][1]
    toward = Light(type="SPOT", power=500.0, spot_size=0.3, name="spot",
                   transform=MotionTransform.static(translate(0, 0, 3)))
    assert make_plan(_glass_over_floor(lights=[toward]))["caustics"]


def test_probe_sees_a_light_shut_inside_a_closed_box():
    """Geometry alone says the light reaches the glass; the probe finds the box in the way."""
    box = box_mesh((-0.3, -0.3, 2.7), (0.3, 0.3, 3.3), material=DIFFUSE, name="crate")
    scene = _scene([plane_mesh(6.0, name="floor"), (sphere_mesh(0.5, 8, 16, material=GLASS, name="ball"),
                                                    translate(0, 0, 1)), box])
    assert make_plan(scene, probe=False)["caustics"]
    plan = make_plan(scene)
    assert not plan["caustics"] and plan["details"]["lights_reaching_specular"] == {}
    assert plan["details"]["lit_diffuse_objects"] == []            # lit only inside the closed crate
    assert not plan["indirect"]                      # only the (convex) inside of the crate is lit


# ----------------------------------------------------------------------------
# Indirect light
# ----------------------------------------------------------------------------
def test_self_reflecting_meshes():
    assert not self_reflecting(plane_mesh(2.0))
    assert not self_reflecting(box_mesh())
    assert not self_reflecting(sphere_mesh(1.0, 8, 16))
    assert self_reflecting(_inward_box())
    open_box = box_mesh()
    open_box.triangles, open_box.material_ids = open_box.triangles[2:], open_box.material_ids[2:]  # no floor
    assert self_reflecting(open_box)


def test_one_room_mesh_is_enough_for_indirect():
    plan = make_plan(_scene([_inward_box(4.0)], lights=[point_light((0, 0, 1.5), 100.0)],
                            camera=persp_camera((0, -1.5, 0), (0, 0, 0))))
    assert plan["indirect"] and plan["details"]["self_reflecting_objects"] == ["room"]
    assert not plan["caustics"]


def test_a_floor_under_a_glass_plane_gets_its_returned_light():
    """One convex diffuse floor under a glass (water) plane: the plane's underside reflects a large
    share of the floor's light back onto it (total internal reflection: L D S+ D), so indirect light
    is on; a glass ball over the same floor returns almost nothing and stays off.  An artist review
    measured a floor under water 31 % dark on AUTO before this rule."""
    plan = make_plan(_scene([plane_mesh(6.0, name="floor"), plane_mesh(8.0, z=1.0, material=GLASS, name="water")]))
    frac = plan["details"]["probe"]["returned_power_fraction"]
    assert plan["indirect"] and frac >= PROBE_RETURN_MIN, (frac, plan["reasons"])
    assert any("L D S+ D" in r for r in plan["reasons"])
    ball = make_plan(_glass_over_floor())
    assert not ball["indirect"] and ball["details"]["probe"]["returned_power_fraction"] < 0.1 * PROBE_RETURN_MIN


# ----------------------------------------------------------------------------
# MANUAL override, output format, what the renderer acts on
# ----------------------------------------------------------------------------
def test_manual_overrides_caustics_and_indirect():
    scene = _glass_over_floor(moving((-0.5, 0, 1), (0.5, 0, 1)))
    plan = make_plan(scene, RenderSettings(effects="MANUAL", caustics=False, indirect=True))
    assert not plan["caustics"] and plan["indirect"] and plan["time_dependent"]
    assert plan["effects"] == "MANUAL" and "automatic choice: caustics on, indirect off" in plan["reasons"][-2]
    plan = make_plan(scene, RenderSettings(effects="MANUAL", caustics=False, indirect=False))
    assert not plan["time_dependent"] and plan["estimator"] == "STANDARD"


def test_apply_plan_zeroes_what_is_ruled_out():
    s = RenderSettings(photons_caustic=1000, photons_global=2000, estimator="KD4D")
    off = {"motion_blur": False, "caustics": False, "indirect": False, "time_dependent": False}
    r = apply_plan(s, off)
    assert (r.photons_caustic, r.photons_global, r.estimator) == (0, 0, "STANDARD")
    assert (s.photons_caustic, s.estimator) == (1000, "KD4D")       # the input is untouched
    on = {"motion_blur": True, "caustics": True, "indirect": True, "time_dependent": True}
    assert apply_plan(s, on).to_dict() == s.to_dict()
    assert apply_plan(s.replace(method="ACCUMULATION"), off).estimator == "KD4D"


def test_plan_is_json_and_printable():
    plan = make_plan(_glass_over_floor(moving((-0.5, 0, 1), (0.5, 0, 1))))
    assert json.loads(json.dumps(plan)) == plan
    text = format_plan(plan)
    assert "caustics        yes" in text and "why:" in text and "lights_reaching_specular" in text
    assert plan_summary(plan) == "motion blur, caustics, time dependent (estimator TEMPORAL)"


def test_plan_is_deterministic():
    scene = _glass_over_floor(moving((-0.5, 0, 1), (0.5, 0, 1)))
    assert make_plan(scene) == make_plan(scene)


# ----------------------------------------------------------------------------
# The renderer follows the plan (asserted through RenderResult.stats)
# ----------------------------------------------------------------------------
def _tiny(scene, **kw):
    from stpm_core.render import render
    scene.resolution = (12, 9)
    s = dict(samples=2, photons_caustic=3000, photons_global=3000, k_nearest=10, seed=3)
    s.update(kw)
    return render(scene, RenderSettings(**s))


def _diffuse_pair(shutter):
    return make_scene([plane_mesh(6.0, name="floor"), (box_mesh(material=DIFFUSE, name="crate"), translate(0, 0, 0.5))],
                      MATERIALS, ortho_camera_down(5.0, 4.0), [point_light((0.5, 0.5, 3), 200.0)], shutter=shutter)


def test_no_specular_surface_builds_no_caustic_map():
    res = _tiny(_diffuse_pair(OPEN))
    assert res.plan["caustics"] is False
    assert res.stats["photons_caustic"] == 0
    assert res.stats["photon_stats"].get("photons_emitted_caustic", 0) == 0   # none traced, not just none stored
    assert res.stats["photons_global"] > 0                                      # the global map is built
    assert float(np.abs(res.passes["Caustic"]).max()) == 0.0


def test_static_scene_costs_the_same_with_motion_blur_on_and_off():
    on, off = _tiny(_diffuse_pair(OPEN)), _tiny(_diffuse_pair(Shutter(1.0, 1.0)))
    for key in ("rays_cast", "camera_rays", "bounce_rays", "shadow_rays", "photon_lookups",
                "photons_caustic", "photons_global"):
        assert on.stats[key] == off.stats[key], key
    assert on.stats["photon_stats"]["photons_emitted"] == off.stats["photon_stats"]["photons_emitted"]
    assert not on.plan["motion_blur"] and not on.plan["time_dependent"]
    # nothing in the scene moves: the caster has no moving part, and the image is the same
    assert on.stats["photon_stats"]["estimator"] == "STANDARD"
    for name in ("Combined", "Direct", "Indirect"):
        np.testing.assert_allclose(on.passes[name], off.passes[name], rtol=1e-5, atol=1e-6)


def test_probe_turns_caustics_off_when_no_specular_path_reaches_a_diffuse_surface():
    """A mirror plate facing a light above sends all of it back up: nothing focuses on the floor."""
    plate = plane_mesh(1.0, z=1.0, material=MIRROR, name="plate")
    plan = make_plan(_scene([plane_mesh(6.0, name="floor"), plate]))
    assert plan["details"]["lights_reaching_specular"] == {"light": ["plate"]}
    assert not plan["caustics"] and "none of" in plan["reasons"][1]
    assert plan["details"]["probe"]["photons_aimed"] == 512 + 4096


def test_stpm_render_records_the_plan_in_stats_and_exr(tmp_path):
    """`stpm render` (in-process) writes the plan it followed into --stats and the EXR header."""
    from stpm_core.cli import main
    from stpm_core.imageio import read_exr
    from stpm_core.scenefile import save_scene
    scene = _diffuse_pair(OPEN)
    scene.resolution = (8, 6)
    path = save_scene(scene, tmp_path / "pair.stpm") or tmp_path / "pair.stpm"
    out, stats = tmp_path / "pair.exr", tmp_path / "pair.json"
    assert main(["render", str(path), "--output", str(out), "--stats", str(stats), "--samples", "1",
                 "--photons-global", "2000", "--photons-caustic", "2000", "--quiet"]) == 0
    st = json.loads(stats.read_text())
    expected = make_plan(scene, RenderSettings(samples=1, photons_global=2000, photons_caustic=2000))
    assert st["plan"] == expected
    assert st["photons_caustic"] == 0 and st["estimator"] == expected["estimator"] == "STANDARD"
    assert json.loads(read_exr(out)["_metadata"]["stpm:plan"]) == expected


def test_an_emissive_mesh_is_a_light_of_the_plan():
    """A lamp shade with an Emission shader (a mesh light) lights a glass ball over a floor: the
    plan must see it as a light (the artist review 3's living room, lit by an emissive shade only
    above a wine glass, had caustics off: "no light reaches the specular objects")."""
    mats = MATERIALS + [Material.emitter((20.0, 15.0, 10.0), name="shade")]
    shade = plane_mesh(0.6, z=0.0, flip=True, material=len(MATERIALS), name="shade")
    scene = make_scene([plane_mesh(6.0, name="floor"),
                        (sphere_mesh(0.5, 12, 24, material=GLASS, name="ball"), translate(0, 0, 1)),
                        (shade, translate(0, 0, 2.5))],
                       mats, persp_camera((0, -6, 3), (0, 0, 0.5)), [], shutter=OPEN)
    plan = make_plan(scene)
    d = plan["details"]
    assert d["lights"] == ["shade (emission)"]
    assert plan["caustics"] and d["lights_reaching_specular"] == {"shade (emission)": ["ball"]}
    assert d["probe"]["caustic_photons_stored"] > 0


def test_a_room_lit_by_an_emissive_panel_only_gets_indirect_light():
    mats = MATERIALS + [Material.emitter((5.0, 5.0, 5.0), name="panel")]
    panel = plane_mesh(0.5, z=0.0, flip=True, material=len(MATERIALS), name="panel")
    scene = make_scene([_inward_box(4.0), (panel, translate(0, 0, 1.9))], mats,
                       persp_camera((0, -1.5, 0.5), (0, 0, 0)), [], shutter=OPEN)
    plan = make_plan(scene)
    assert plan["indirect"] and plan["details"]["lit_diffuse_objects"] == ["room"]


# ----------------------------------------------------------------------------
# A caustic too faint to map (plan.CAUSTIC_CONTRAST_MIN, CAUSTIC_POWER_MIN)
# ----------------------------------------------------------------------------
def _spot_floor_and_dim_ball(ball_light_w: float, radius: float = 0.5):
    """The textured room in small: a strong spot lights the floor away from a glass ball, and a second
    point light of ``ball_light_w`` W (a sphere of ``radius``) is the only one that reaches the ball (the
    room's sky through the window; its sun misses the ball)."""
    spot = Light(type="SPOT", color=np.ones(3), power=300.0, spot_size=np.radians(30.0), spot_blend=0.0,
                 transform=MotionTransform.static(translate(-1.5, 0, 3)), radius=0.0, use_soft_falloff=False)
    ball = sphere_mesh(0.5, 12, 24, material=GLASS, name="ball")
    return make_scene([plane_mesh(6.0, name="floor"), (ball, translate(1.5, 0, 1.0))], MATERIALS,
                      ortho_camera_down(5.0, 5.0), [spot, point_light((1.5, 0, 2.5), ball_light_w, radius=radius)],
                      shutter=Shutter(1.0, 1.0))


def test_caustic_contrast_of_a_uniform_disc():
    """N photons spread evenly over a disc of area A with total power P (per channel) read an irradiance of
    about P / A: against D W (summed over RGB) landing on S m^2 of lit surface the contrast is
    (P / A) / (D / 3 / S), read high (the brightest of 400 noisy k = 8 estimates: 3.7x here), never low."""
    from stpm_core.photons.record import PHOTON_DTYPE
    from stpm_core.plan import caustic_contrast
    rng = np.random.default_rng(0)
    n, R, P = 400, 0.2, 2.0
    r, phi = R * np.sqrt(rng.random(n)), 2 * np.pi * rng.random(n)
    recs = np.zeros(n, PHOTON_DTYPE)
    recs["position"] = np.stack([r * np.cos(phi), r * np.sin(phi), np.zeros(n)], 1)
    recs["power"] = P / n
    expected = (P / (np.pi * R * R)) / (300.0 / 3.0 / 30.0)
    got = caustic_contrast([recs[:150], recs[150:]], 300.0, 30.0)
    assert expected <= got <= 5.0 * expected, (got, expected)
    assert caustic_contrast([recs[:1]], 300.0, 30.0) == float("inf")      # cannot tell: keep the caustic
    assert caustic_contrast([], 300.0, 30.0) == float("inf")


def test_a_faint_caustic_gets_no_map_and_carried_almost_no_light():
    """The dim soft light's caustic is under both thresholds: the plan drops the caustic map and says
    why; a render that keeps it (MANUAL) shows the Caustic pass holds < 0.1 % of the image.  The same
    dim light as a true point focuses to a spot 40 % as bright as the floor's mean direct light while
    carrying 0.005 % of the power: kept (the power fraction alone would drop it).  With the ball's light
    as strong as the spot the caustic is kept and holds more than 0.1 % of the image."""
    from stpm_core.plan import CAUSTIC_CONTRAST_MIN, CAUSTIC_POWER_MIN
    focused = make_plan(_spot_floor_and_dim_ball(0.01, radius=0.0))
    pr = focused["details"]["probe"]
    assert focused["caustics"] and pr["caustic_power_fraction"] < CAUSTIC_POWER_MIN, focused["reasons"]
    assert pr["caustic_contrast"] > 10 * CAUSTIC_CONTRAST_MIN
    faint = _spot_floor_and_dim_ball(0.001)
    plan = make_plan(faint)
    pr = plan["details"]["probe"]
    assert plan["details"]["lights_reaching_specular"] == {"light": ["ball"]}     # the dim one reaches it
    assert pr["caustic_photons_stored"] > 0
    assert pr["caustic_contrast"] < CAUSTIC_CONTRAST_MIN and pr["caustic_power_fraction"] < CAUSTIC_POWER_MIN
    assert not plan["caustics"] and any("the caustic is faint" in r for r in plan["reasons"]), plan["reasons"]
    kept = _tiny(faint, effects="MANUAL", caustics=True, indirect=False, photons_caustic=20000)
    assert kept.stats["photons_caustic"] > 0
    share = float(kept.passes["Caustic"][..., :3].sum() / kept.passes["Combined"][..., :3].sum())
    assert share < 1e-3, share
    dropped = _tiny(faint, photons_caustic=20000)
    assert dropped.stats["photon_stats"].get("photons_emitted_caustic", 0) == 0

    bright = _spot_floor_and_dim_ball(300.0)
    plan = make_plan(bright)
    assert plan["caustics"], plan["reasons"]
    assert plan["details"]["probe"]["caustic_contrast"] > 10 * CAUSTIC_CONTRAST_MIN
    res = _tiny(bright, effects="MANUAL", caustics=True, indirect=False, photons_caustic=20000)
    share = float(res.passes["Caustic"][..., :3].sum() / res.passes["Combined"][..., :3].sum())
    assert share > 1e-3, share


# ----------------------------------------------------------------------------
# What the plan costs: the probe's shading may come from a compiled superset's interpreter
# ----------------------------------------------------------------------------
def _node_glass_over_floor():
    """A ball whose Mix Shader picks Glass or Diffuse by a Checker, over a Checker-coloured floor:
    the probe's caustic photons exist only through the node interpreter's Glass branch."""
    from stpm_core.nodes.graph import Link, ShaderGraph
    from test_kernel_svm import N
    floor = ShaderGraph(nodes={
        "Checker": N("ShaderNodeTexChecker", {"Scale": 4.0, "Color1": (0.9, 0.9, 0.9), "Color2": (0.3, 0.5, 0.2)}),
        "Diffuse": N("ShaderNodeBsdfDiffuse", {"Color": Link("Checker", "Color")})}, surface=Link("Diffuse", "BSDF"))
    ball = ShaderGraph(nodes={
        "Checker": N("ShaderNodeTexChecker", {"Scale": 3.0}),
        "Glass": N("ShaderNodeBsdfGlass", {"Color": (0.9, 0.8, 0.6), "Roughness": 0.0, "IOR": 1.5}),
        "Diffuse": N("ShaderNodeBsdfDiffuse", {"Color": (0.5, 0.5, 0.5)}),
        "Mix": N("ShaderNodeMixShader", {"Fac": Link("Checker", "Fac"), "Shader": Link("Diffuse", "BSDF"),
                                         "Shader_001": Link("Glass", "BSDF")})}, surface=Link("Mix", "Shader"))
    mats = [Material(graph=floor, name="checker floor"), Material(graph=ball, name="mixed glass")]
    return make_scene([plane_mesh(6.0, name="floor", material=0),
                       (sphere_mesh(0.5, 12, 24, material=1, name="ball"), translate(0, 0, 1))],
                      mats, persp_camera((0, -6, 3), (0, 0, 0.5)), [point_light((0, 0, 3), 300.0)], shutter=OPEN)


def test_the_plan_is_the_same_whichever_compiled_interpreter_shades_its_probe(monkeypatch):
    """The probe shades its photons with the node interpreter compiled for the scene's node kinds or,
    to compile nothing (``svm_variants.covering``), a compiled one of more kinds -- the full
    interpreter is the largest: the same plan, probe numbers included.  One missing a kind the scene
    uses (the Glass branch folded away) would change it: the test can tell."""
    from stpm_core.kernels import svm_variants
    from stpm_core.shading import shading_data
    scene = _node_glass_over_floor()
    ops = shading_data(scene).ops
    assert {"BSDF_GLASS", "MIX_SHADER", "TEX_CHECKER"} <= ops

    def plan_with(cover):
        monkeypatch.setattr(svm_variants, "_LOADED", {})
        monkeypatch.setattr(svm_variants, "_VARIANTS_LOADED", set())
        monkeypatch.setattr(svm_variants, "covering", cover)
        return make_plan(scene)

    own = plan_with(lambda o, *a, **k: frozenset(o))
    assert own["caustics"] and own["details"]["probe"]["caustic_photons_stored"] > 0
    monkeypatch.setenv("STPM_SVM_VARIANTS", "0")                      # the full interpreter
    assert plan_with(lambda o, *a, **k: frozenset(o)) == own
    monkeypatch.delenv("STPM_SVM_VARIANTS")
    wrong = plan_with(lambda o, *a, **k: frozenset(o) - {"BSDF_GLASS"})
    assert wrong != own and wrong["details"]["probe"]["caustic_photons_stored"] == 0
