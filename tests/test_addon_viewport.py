"""The rendered viewport and material previews, driven through bpy with the real depsgraph.

Background Blender cannot instantiate RenderEngine subclasses or draw, so ``view_update`` /
``view_draw`` themselves are not run here (docs/blender.md says what only a GUI shows); they only
delegate to :class:`addon.viewport.ViewportSession`, which is driven here exactly as they drive
it: ``sync(depsgraph)`` from a ``depsgraph_update_post`` handler (the evaluated depsgraph with
its real ``updates``), ``set_view`` with a view built from the scene camera's own matrices.
Previews run for real: ``bpy.ops.ed.lib_id_generate_preview`` renders Blender's preview scene
with the engine (``is_preview``) on a job thread, also in background mode.
"""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from test_addon_scenes import ROOT, add_camera, add_light, add_mesh, fresh, node_material  # noqa: E402

import addon  # noqa: E402
from addon import preview  # noqa: E402
from addon.engine import LAST_RENDER  # noqa: E402
from addon.export import camera as camera_export  # noqa: E402
from addon.viewport import ViewParams, ViewportSession, first_pass_size, viewport_settings  # noqa: E402
from stpm_core.camera import generate_rays  # noqa: E402
from stpm_core.settings import RenderSettings  # noqa: E402

DEMO = ROOT / "blend_scenes" / "demo.blend"
addon.register()  # before any .blend is opened, so files keep engine 'STPM'


def camera_view(scene, width: int, height: int) -> ViewParams:
    """The view a 3D view looking through the scene camera has (Blender's own projection)."""
    cam = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.evaluated_get(depsgraph).calc_matrix_camera(depsgraph, x=width, y=height)
    return ViewParams.from_matrices(width, height, cam.matrix_world.inverted(), proj)


def exported_camera(scene):
    """The scene camera as F12 exports it."""
    cam = scene.camera
    return camera_export.export_camera(cam, np.array([0.5]), np.array(cam.matrix_world)[None], [])


def non_core_threads() -> set:
    """Python threads alive, apart from the core's process-wide photon look-up pool
    (``stpm-lookup_*``, stpm_core/photons/kdtree.py: idle between renders, shared by every render
    of the process) and Blender's own threads that ran Python (render and preview jobs: Python
    keeps a dummy entry for each)."""
    return {t for t in threading.enumerate()
            if not t.name.startswith("stpm-lookup") and not isinstance(t, threading._DummyThread)}


@pytest.fixture
def on_updates():
    """Register fn(depsgraph) as a depsgraph_update_post handler for the test, called for the
    view layer's (viewport) depsgraph only, as Blender calls view_update (an F12 render's own
    depsgraph reports its updates to the same handlers)."""
    added = []

    def add(fn):
        def handler(_scene, depsgraph):
            if depsgraph.mode == "VIEWPORT":
                fn(depsgraph)
        bpy.app.handlers.depsgraph_update_post.append(handler)
        added.append(handler)
    yield add
    for h in added:
        bpy.app.handlers.depsgraph_update_post.remove(h)


# ----------------------------------------------------------------------------- the view's camera
@pytest.mark.parametrize("kind, fit", [("PERSP", "AUTO"), ("PERSP", "VERTICAL"), ("ORTHO", "AUTO")])
def test_the_view_camera_casts_the_rays_of_the_scene_camera(kind, fit):
    # A view looking through the scene camera (Blender's projection of it: calc_matrix_camera)
    # must give the rays F12's exported camera gives, shift, sensor fit and aspect included
    scene = fresh()
    add_camera(type=kind, lens=35.0, shift_x=0.1, shift_y=-0.05, ortho_scale=4.0, clip_start=0.2, sensor_fit=fit)
    W, H = 64, 40
    view = camera_view(scene, W, H)
    mine, f12 = view.camera(), exported_camera(scene)
    assert mine.type == kind
    px = np.array([0.5, 10.25, 63.5, 32.0, 0.0])
    py = np.array([0.5, 39.5, 20.0, 3.75, 40.0])
    t = np.full(px.shape, 0.5)
    o1, d1 = generate_rays(mine, (W, H), px, py, t)
    o2, d2 = generate_rays(f12, (W, H), px, py, t)
    assert np.allclose(d1, d2, atol=1e-5)
    if kind == "PERSP":
        assert np.allclose(o1, o2, atol=1e-5)
    else:          # the same lines (origins may sit elsewhere along them)
        diff = o1 - o2
        along = np.sum(diff * d2, axis=1, keepdims=True) * d2
        assert np.allclose(diff - along, 0.0, atol=1e-5)


def test_a_view_through_the_camera_has_its_depth_of_field():
    """Looking through the scene camera, the rendered view has F12's lens (Cycles' viewport shows
    depth of field there); any other view, or a camera without it, is a pinhole."""
    from types import SimpleNamespace
    from addon.viewport import camera_view_lens
    scene = fresh()
    add_camera(type="PERSP", lens=50.0)
    dof = scene.camera.data.dof
    dof.use_dof, dof.focus_distance, dof.aperture_fstop, dof.aperture_blades = True, 3.0, 2.0, 6
    through, free = SimpleNamespace(view_perspective="CAMERA"), SimpleNamespace(view_perspective="PERSP")
    lens = camera_view_lens(scene, through)
    view = camera_view(scene, 48, 32)
    cam = ViewParams.from_matrices(48, 32, np.reshape(view.view_matrix, (4, 4)), np.reshape(view.window_matrix, (4, 4)),
                                   lens=lens).camera()
    f12 = exported_camera(scene)
    for name in ("aperture_radius", "focus_distance", "aperture_blades", "aperture_rotation", "aperture_ratio"):
        assert getattr(cam, name) == pytest.approx(getattr(f12, name)), name
    assert cam.aperture_radius == pytest.approx(0.05 / 4.0)       # 50 mm / (2 x f/2)
    assert camera_view_lens(scene, free) == ()
    dof.use_dof = False
    assert camera_view_lens(scene, through) == ()
    assert view.camera().aperture_radius == 0.0


def test_an_ortho_view_whose_near_plane_is_behind_the_eye_moves_the_eye_back():
    # Blender's ortho views clip symmetrically around the eye: near < 0 is not a camera the
    # core accepts, so the eye moves back along the view axis and the rays stay the same lines
    near, far, half = -50.0, 50.0, 2.0
    P = np.array([[1 / half, 0, 0, 0], [0, 1 / half, 0, 0],
                  [0, 0, -2 / (far - near), -(far + near) / (far - near)], [0, 0, 0, 1]])
    cam = camera_export.view_camera(np.eye(4), P, 100, 100)
    assert cam.type == "ORTHO" and cam.clip_start > 0 and cam.ortho_scale == pytest.approx(4.0)
    assert cam.transform.matrices[0][2, 3] > -near          # moved back along +Z (behind the old eye)
    assert cam.clip_end - cam.clip_start == pytest.approx(far - near)


# ----------------------------------------------------------------------------- settings
def test_viewport_settings_spend_f12s_photons_per_camera_sample():
    base = RenderSettings(samples=16, photons_global=200_000, photons_caustic=100_000)
    v = viewport_settings(base, passes=0, time_limit=5.0)
    assert (v.method, v.samples, v.photons_global, v.photons_caustic) == ("PROGRESSIVE", 1, 12_500, 6_250)
    assert v.passes >= 1 << 20 and v.time_limit == 5.0 and v.noise_threshold == 0 and not v.denoise
    assert viewport_settings(base.replace(photons_caustic=0), passes=3, time_limit=0).photons_caustic == 0
    assert viewport_settings(base, passes=3, time_limit=0).passes == 3
    assert first_pass_size(640, 360) == (160, 90)
    assert first_pass_size(1920, 1080) == (160, 90)
    assert first_pass_size(100, 60) == (100, 60)          # already small: rendered as it is
    w, h = first_pass_size(1000, 333, 5000)
    assert w * h <= 5000 and w / h == pytest.approx(1000 / 333, rel=0.05)


def test_viewport_passes_and_time_limit_are_panel_settings():
    scene = fresh()
    assert scene.stpm.preview_passes == 1024 and scene.stpm.preview_time_limit == 0.0
    scene.stpm.preview_passes, scene.stpm.preview_time_limit = 5, 2.5
    session = ViewportSession()
    s = session._read_settings(scene)
    assert (s.passes, s.time_limit) == (5, 2.5)


# ----------------------------------------------------------------------------- the session
def test_viewport_renders_pass_by_pass_restarts_on_edits_and_moves_without_reexport(on_updates):
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    st = scene.stpm
    st.samples, st.photons_global, st.photons_caustic, st.k_nearest = 1, 4000, 4000, 10
    st.preview_passes = 0                                  # unlimited: the test stops it
    threads_before = non_core_threads()
    W, H = 96, 54
    session = ViewportSession(first_pass_pixels=600)       # the first pass at 32 x 18
    on_updates(lambda depsgraph: session.sync(depsgraph))
    try:
        # Rendered mode turned on: everything exported once, a reduced pass, then full passes
        session.sync(bpy.context.evaluated_depsgraph_get(), view=camera_view(scene, W, H))
        assert session.cache.exports == 1 and session.cache.mesh_conversions == 2     # floor, sphere
        assert session.wait(lambda s: s.images >= 1)
        first, _ = session.image()
        assert first.shape == (18, 32, 4)
        assert session.wait(lambda s: s.passes_done >= 2)
        img, version = session.image()
        assert img.shape == (H, W, 4) and np.isfinite(img).all() and img[..., :3].mean() > 0.01
        assert session.status.startswith("Pass ")
        floor_before = img[2:10, :, :3].mean(axis=(0, 1))          # the floor fills the bottom rows

        # An edit (the floor turns red): a restart, materials again, no mesh converted
        starts, meshes = session.starts, session.cache.mesh_conversions
        tree = bpy.data.materials["Floor"].node_tree
        tree.nodes["Diffuse BSDF"].inputs["Color"].default_value = (0.8, 0.02, 0.02, 1.0)
        bpy.context.view_layer.update()
        assert session.starts == starts + 1 and session.cache.exports == 2
        assert session.cache.mesh_conversions == meshes
        assert session.wait(lambda s: s.passes_done >= 1 and s.image()[1] > version)
        red = session.image()[0][2:10, :, :3].mean(axis=(0, 1))
        assert red[0] > 5 * red[1] and floor_before[1] > 0.5 * floor_before[0]

        # The scene camera moves: nothing is exported; the view through it restarts the render
        exports = session.cache.exports
        scene.camera.location.z += 0.3
        bpy.context.view_layer.update()
        assert session.cache.exports == exports and session.cache.mesh_conversions == meshes
        starts = session.starts
        assert session.set_view(camera_view(scene, W, H))
        assert session.starts == starts + 1 and session.cache.exports == exports
        assert not session.set_view(camera_view(scene, W, H))          # the same view: no restart
        assert session.wait(lambda s: s.passes_done >= 1)

        # An object moves: exported again, but its mesh is not converted again
        bpy.data.objects["GlassSphere"].location.y += 0.2
        bpy.context.view_layer.update()
        assert session.cache.exports == exports + 1 and session.cache.mesh_conversions == meshes
        # Its shape changes: only that mesh is converted again
        sphere = bpy.data.objects["GlassSphere"].data
        sphere.vertices[0].co.z += 0.05
        sphere.update()
        bpy.context.view_layer.update()
        assert session.cache.mesh_conversions == meshes + 1

        # F12 while the viewport renders: each keeps its own result
        st.samples = 1
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 24, 16, 100
        LAST_RENDER.clear()
        starts = session.starts
        bpy.ops.render.render()
        assert LAST_RENDER["stats"]["resolution"] == [24, 16] and session.starts == starts
        shown = session.images
        assert session.wait(lambda s: s.images > shown and s.image()[0].shape == (H, W, 4))
    finally:
        assert session.stop()
    # No thread of the session is left: its worker and the renders' tile pools are gone
    assert session.wait(lambda s: non_core_threads() <= threads_before, timeout=5)
    assert not any(t.name == "STPM viewport" for t in threading.enumerate())


def test_stop_during_a_pass_ends_the_thread_and_two_sessions_share_nothing():
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    scene.stpm.photons_global = scene.stpm.photons_caustic = 4000
    threads_before = non_core_threads()
    a, b = ViewportSession(), ViewportSession()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    a.sync(depsgraph, view=camera_view(scene, 64, 48))
    b.sync(depsgraph, view=camera_view(scene, 40, 30))
    try:
        assert a.wait(lambda s: s.passes_done >= 1) and b.wait(lambda s: s.passes_done >= 1)
        assert a.image()[0].shape == (48, 64, 4) and b.image()[0].shape == (30, 40, 4)
        assert a.running
        t0 = time.perf_counter()
        assert a.stop()                      # in the middle of a pass
        stop_s = time.perf_counter() - t0
        shown = b.images
        assert b.wait(lambda s: s.images > shown)         # the other view goes on
        assert not a.running and a.stopped
        starts = a.starts
        a.set_view(camera_view(scene, 32, 24))           # a stopped session does not start again
        assert a.starts == starts and a._thread is None
    finally:
        b.stop()
    assert stop_s < 10
    assert a.wait(lambda s: non_core_threads() <= threads_before, timeout=5)


def test_a_bad_setting_is_one_status_line_and_fixing_it_restarts():
    scene = fresh()
    add_mesh("plane", size=4.0)
    add_camera()
    add_light(energy=200.0)
    scene.stpm.temporal_alpha = 0.5                    # 0 or >= 1 only
    session = ViewportSession()
    try:
        assert not session.sync(bpy.context.evaluated_depsgraph_get(), view=camera_view(scene, 32, 24))
        assert session.status.startswith("STPM: temporal_alpha must be") and "\n" not in session.status
        assert session.starts == 0 and session._thread is None
        scene.stpm.temporal_alpha = 0.0
        assert session.set_settings(scene)
        assert session.wait(lambda s: s.passes_done >= 1)
    finally:
        assert session.stop()


def test_a_scene_without_camera_or_lights_still_renders_in_the_viewport():
    # The viewport brings its own camera; a scene without lights is black, not an error
    scene = fresh()
    add_mesh("cube")
    session = ViewportSession()
    view = ViewParams.from_matrices(32, 24, [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -6], [0, 0, 0, 1]],
                                    [[1.5, 0, 0, 0], [0, 2.0, 0, 0], [0, 0, -1.002, -0.2002], [0, 0, -1, 0]])
    try:
        session.sync(bpy.context.evaluated_depsgraph_get(), view=view)
        assert scene.camera is None
        assert session.wait(lambda s: s.passes_done >= 1)
        assert session.image()[0].shape == (24, 32, 4)
    finally:
        assert session.stop()


# ----------------------------------------------------------------------------- the engine's glue
class _StandInEngine:
    """What addon.viewport.view_update / view_draw use of a RenderEngine (background Blender
    cannot make a real one): update_stats, tag_redraw, is_preview and an instance __dict__."""

    is_preview = False

    def __init__(self):
        self.stats = []

    def update_stats(self, stats, info):
        self.stats.append(info)

    def tag_redraw(self):
        pass


def test_view_update_and_view_draw_delegate_to_one_session_per_engine(monkeypatch):
    from types import SimpleNamespace

    from addon import viewport
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    scene.stpm.photons_global = scene.stpm.photons_caustic = 4000
    drawn = []
    monkeypatch.setattr(viewport.ViewportDisplay, "draw",
                        lambda self, engine, sc, session, w, h: drawn.append((w, h, session.image()[1])))

    def context(view: ViewParams):
        return SimpleNamespace(scene=scene, region=SimpleNamespace(width=view.width, height=view.height),
                               region_data=SimpleNamespace(view_matrix=np.reshape(view.view_matrix, (4, 4)),
                                                           window_matrix=np.reshape(view.window_matrix, (4, 4))))
    a, b = _StandInEngine(), _StandInEngine()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    try:
        viewport.view_update(a, context(camera_view(scene, 48, 32)), depsgraph)
        viewport.view_update(b, context(camera_view(scene, 40, 30)), depsgraph)
        sa, sb = a.stpm_viewport, b.stpm_viewport
        assert sa is not sb and sa.starts == 1 and sb.starts == 1
        assert sa.wait(lambda s: s.passes_done >= 1)
        viewport.view_draw(a, context(camera_view(scene, 48, 32)), depsgraph)      # same view: no restart
        assert sa.starts == 1 and drawn[-1][:2] == (48, 32) and a.stats[-1].startswith(("Pass", "Done"))
        moved = camera_view(scene, 48, 32)
        moved = ViewParams(48, 32, moved.view_matrix[:3] + (moved.view_matrix[3] + 0.2,) + moved.view_matrix[4:],
                           moved.window_matrix)
        viewport.view_draw(a, context(moved), depsgraph)                           # navigation
        assert sa.starts == 2 and sa.cache.exports == 1
        # A broken view (a singular view matrix) is one status line, not an exception
        broken = ViewParams(48, 32, (0.0,) * 16, moved.window_matrix)
        viewport.view_draw(a, context(broken), depsgraph)
        assert a.stats[-1].startswith("STPM: viewport failed (LinAlgError")
    finally:
        viewport.stop_engine_session(a)
        viewport.stop_engine_session(b)
    assert sa.stopped and sb.stopped and sa._thread is None and sb._thread is None


# ----------------------------------------------------------------------------- previews
def _preview_of(material, done: threading.Event, timeout: float = 300.0) -> np.ndarray:
    """Blender's preview of ``material`` rendered by the engine: (H, W, 4) float, row 0 = bottom."""
    done.clear()
    with bpy.context.temp_override(id=material):
        assert bpy.ops.ed.lib_id_generate_preview() == {"FINISHED"}
    assert done.wait(timeout), "the preview render did not finish"
    p = material.preview
    t_end = time.perf_counter() + 10
    while time.perf_counter() < t_end:       # Blender copies the result into the preview after the render
        if p.image_size[0] and max(p.image_pixels_float[:]) > 0:
            break
        time.sleep(0.02)
    w, h = p.image_size
    return np.array(p.image_pixels_float[:], dtype=np.float32).reshape(h, w, 4)


def test_material_and_world_previews_render_their_colour(monkeypatch):
    fresh()
    bpy.context.scene.render.engine = "STPM"
    done = threading.Event()
    seen = []
    real = preview.render_preview

    def watched(engine, depsgraph):
        t0 = time.perf_counter()
        try:
            real(engine, depsgraph)
        finally:
            seen.append((bool(engine.is_preview), time.perf_counter() - t0))
            done.set()

    monkeypatch.setattr(preview, "render_preview", watched)
    LAST_RENDER.clear()
    red, _ = node_material("Red", "ShaderNodeBsdfDiffuse", Color=(0.8, 0.03, 0.03, 1.0))
    blue, _ = node_material("Blue", "ShaderNodeBsdfDiffuse", Color=(0.03, 0.03, 0.8, 1.0))
    r, b = _preview_of(red, done), _preview_of(blue, done)
    assert all(flag for flag, _s in seen) and len(seen) >= 2
    # The sphere fills the middle of the preview
    mid = (slice(r.shape[0] * 3 // 8, r.shape[0] * 5 // 8), slice(r.shape[1] * 3 // 8, r.shape[1] * 5 // 8))
    rm, bm = r[mid][..., :3].mean(axis=(0, 1)), b[mid][..., :3].mean(axis=(0, 1))
    assert rm[0] > 1.5 * rm[2] and rm[0] > 1.5 * rm[1], rm
    assert bm[2] > 1.5 * bm[0] and bm[2] > 1.5 * bm[1], bm
    # A world preview: the world's own colour fills it
    world = bpy.data.worlds.new("Green")
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.05, 0.6, 0.05, 1.0)
    g = _preview_of(world, done)[..., :3].mean(axis=(0, 1))
    assert g[1] > 1.3 * g[0] and g[1] > 1.3 * g[2], g
    assert LAST_RENDER == {}                       # previews leave F12's record alone
