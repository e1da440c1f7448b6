"""blend_scenes/: every scene has its generator and README line, exports, and calls for the effects it shows.

Each .blend is opened with bpy (addon.batch.load_blend, as ``stpm plan`` does)
and its effects plan is checked against what the scene was built to show.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "blend_scenes"

# scene -> (motion_blur, caustics, indirect, time_dependent): what it was built to show
EXPECTED = {
    "demo": (True, True, False, True),
    "moving_receiver": (True, True, True, True),
    "metal_ring": (True, True, False, True),
    "cornell_moving_cube": (True, False, True, True),
    "camera_pan_caustic": (True, True, False, False),
    "deforming_caustic": (True, True, True, True),
    "fast_spinner": (True, True, False, True),
    "static_scene": (False, True, True, False),
    "textured_room": (True, False, True, False),      # its sky-only caustic is faint: no map (docs/effects.md)
    "hdri_product": (True, True, True, True),
    "sunlit_pool": (True, True, True, True),
}
KEYS = ("motion_blur", "caustics", "indirect", "time_dependent")


def test_every_scene_has_a_generator_and_a_readme_line():
    readme = (SCENES / "README.md").read_text()
    blends = {p.stem for p in SCENES.glob("*.blend")}
    assert blends == set(EXPECTED)
    for name in EXPECTED:
        assert (SCENES / f"make_{name}.py").is_file(), name
        assert readme.count(f"`{name}.blend`") == 1, name
        assert (SCENES / f"{name}.blend").stat().st_size < 1_000_000      # small files


@pytest.fixture(scope="module")
def loaded():
    pytest.importorskip("bpy")
    from addon import batch
    return {name: batch.load_blend(str(SCENES / f"{name}.blend"), 1) for name in EXPECTED}


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_scene_calls_for_what_it_shows(loaded, name):
    from stpm_core.plan import make_plan
    from stpm_core.settings import RenderSettings
    scene, settings = loaded[name]
    plan = make_plan(scene, RenderSettings.from_dict(settings))
    assert tuple(plan[k] for k in KEYS) == EXPECTED[name], plan["reasons"]
    assert scene.shutter.length == pytest.approx(0.5)


def test_motion_is_exported_as_built(loaded):
    # moving receiver: the box slides 0.8 m along +X during the shutter
    scene, _ = loaded["moving_receiver"]
    box = next(i for i in scene.instances if i.name == "Box")
    x0, x1 = box.transform.at(0.0)[0, 3], box.transform.at(1.0)[0, 3]
    assert x1 - x0 == pytest.approx(0.8, rel=1e-3)
    # camera pan: only the camera moves
    scene, _ = loaded["camera_pan_caustic"]
    assert not scene.camera.transform.is_static and all(i.transform.is_static for i in scene.instances)
    # deforming floor: vertex positions per motion step, and they differ
    scene, _ = loaded["deforming_caustic"]
    mesh = next(scene.meshes[i.mesh] for i in scene.instances if i.name == "RipplingFloor")
    assert mesh.is_deforming and np.ptp(np.asarray(mesh.vertices)[:, :, 2], axis=0).max() > 0.01


def test_textured_room_exports_its_textures_uvs_and_normal_map(loaded):
    """The artist-built room keeps its images (from files next to the .blend), UV maps, tangents
    for the normal map and node graphs: nothing is reduced to a mean colour."""
    scene, _ = loaded["textured_room"]
    names = sorted(t.name for t in scene.textures)
    assert names == ["planks.png", "planks_normal.png", "tiles16.png"], names
    kinds = {t.name: (t.pixels.dtype, t.colorspace) for t in scene.textures}
    assert kinds["planks.png"] == (np.uint8, "sRGB") and kinds["planks_normal.png"][1] in ("Non-Color", "Linear")
    assert kinds["tiles16.png"][0] in (np.uint16, np.float32)     # more than 8 bits kept (Blender: linear floats)
    graphs = {m.name: m.graph for m in scene.materials}
    assert all(graphs[n] is not None for n in ("Planks", "Wallpaper", "Tiles"))
    floor = next(scene.meshes[i.mesh] for i in scene.instances if i.name == "Floor")
    assert floor.uv_layers and floor.tangents
    assert not any("mean colour" in w for w in scene.metadata.get("warnings", []))


def test_fast_spinner_turns_a_full_turn_without_aliasing(loaded):
    """One revolution per shutter: the blades are back at t=1, half a turn round at t=0.5."""
    scene, _ = loaded["fast_spinner"]
    rotor = next(i for i in scene.instances if i.name == "Rotor")
    assert rotor.transform.times.shape[0] >= 9                     # enough steps: < 180 degrees apart
    R = rotor.transform.at(np.array([0.0, 0.25, 0.5, 1.0]))[:, :3, :3]
    x = R[:, :, 0]                                                 # blade axis in world space
    np.testing.assert_allclose(x[3], x[0], atol=1e-6)
    np.testing.assert_allclose(x[2], -x[0], atol=1e-6)
    assert abs(float(x[1] @ x[0])) < 1e-6                          # a quarter turn at t = 0.25


# ----------------------------------------------------------------------------
# The plan in Blender: operator, panel data, render report and EXR metadata
# ----------------------------------------------------------------------------
def test_plan_operator_stores_the_plan_on_the_scene():
    bpy = pytest.importorskip("bpy")
    import json
    import addon
    from addon import ui
    addon.register()
    bpy.ops.wm.open_mainfile(filepath=str(SCENES / "camera_pan_caustic.blend"))
    scene = bpy.context.scene
    assert ui.scene_plan(scene) is None
    assert bpy.ops.stpm.compute_plan() == {"FINISHED"}
    plan = ui.scene_plan(scene)
    assert (plan["motion_blur"], plan["caustics"], plan["time_dependent"]) == (True, True, False)
    assert plan["estimator"] == "STANDARD" and json.loads(scene["stpm_plan"]) == plan
    assert scene.frame_current == 1 and scene.frame_subframe == 0.0      # the frame is restored


def test_render_reports_the_plan_and_writes_it_into_the_exr(tmp_path):
    bpy = pytest.importorskip("bpy")
    oiio = pytest.importorskip("OpenImageIO")
    import json
    import addon
    from addon import batch, ui
    from addon.engine import LAST_RENDER
    addon.register()
    bpy.ops.wm.open_mainfile(filepath=str(SCENES / "static_scene.blend"))
    scene = bpy.context.scene
    st = scene.stpm
    st.samples, st.photons_global, st.photons_caustic, st.k_nearest = 1, 2000, 2000, 10
    scene.render.resolution_x, scene.render.resolution_y = 24, 18
    scene.render.filepath = str(tmp_path / "static.exr")
    scene.render.use_file_extension = False
    batch._set_format(scene.render.image_settings, "EXR")
    LAST_RENDER.clear()
    bpy.ops.render.render(write_still=True)
    plan = LAST_RENDER["plan"]
    assert (plan["motion_blur"], plan["caustics"], plan["indirect"]) == (False, True, True)
    assert ui.scene_plan(scene) == plan                         # the panel shows the last render's plan
    inp = oiio.ImageInput.open(str(tmp_path / "static.exr"))
    meta = {a.name: a.value for a in inp.spec().extra_attribs}
    inp.close()
    key = next(k for k in meta if k.endswith("STPM Plan"))
    assert json.loads(meta[key]) == plan


class _Layout:
    """Stand-in for bpy's UILayout: records labels, accepts everything else."""

    def __init__(self, labels):
        self.labels = labels

    def label(self, text="", icon="NONE"):
        self.labels.append((text, icon))

    def __getattr__(self, name):
        return lambda *a, **k: self

    def __setattr__(self, name, value):
        object.__setattr__(self, name, value)


def test_effects_panel_lists_the_plan_and_its_reasons():
    bpy = pytest.importorskip("bpy")
    import types
    import addon
    from addon import ui
    addon.register()
    bpy.ops.wm.open_mainfile(filepath=str(SCENES / "cornell_moving_cube.blend"))
    scene = bpy.context.scene
    labels = []
    panel = type("Drawn", (ui._STPMPanel,), {})()          # the panels' shared helpers, no bpy panel
    panel.layout = _Layout(labels)
    ui.STPM_RENDER_PT_effects.draw(panel, types.SimpleNamespace(scene=scene))
    assert labels == [("No plan yet: compute it or render", "INFO")]
    bpy.ops.stpm.compute_plan()
    labels.clear()
    ui.STPM_RENDER_PT_effects.draw(panel, types.SimpleNamespace(scene=scene))
    assert ("Caustics", "X") in labels and ("Indirect", "CHECKMARK") in labels
    assert ("Motion Blur", "CHECKMARK") in labels and ("Estimator: TEMPORAL", "NONE") in labels
    assert any(text.startswith("caustics: off (no specular object") for text, _ in labels)
