"""The rendered viewport and the material preview, timed on ``blend_scenes/demo.blend``.

Everything runs in this process through bpy (``python -m benchmarks viewport``, or
``python benchmarks/bench_viewport.py``), as background Blender can: the viewport's
:class:`addon.viewport.ViewportSession` is driven the way ``view_update`` / ``view_draw`` drive it
(a view looking through the scene camera at 640 x 360, Blender's own projection of it), and the
preview through ``bpy.ops.ed.lib_id_generate_preview`` (Blender's preview scene, rendered by the
engine with ``is_preview``).  Kernels are warm: a first start, not counted, loads them.

Reported:

* ``first_image_s``: from ``sync`` (Rendered mode turned on; the export included) to the first
  image (the reduced first pass, at most ``FIRST_PASS_PIXELS`` pixels), median of ``REPEATS`` starts;
* ``first_full_pass_s``: to the first pass at the view's resolution;
* ``passes_per_s``: full-resolution passes per second over ``PASS_WINDOW_S`` seconds after it;
* ``navigate_first_image_s``: a moved view (no export) to its first image;
* ``edit_first_image_s``: a material colour change (export of materials only) to its first image;
* ``preview_s``: a material preview (128 x 128, :data:`addon.preview.PREVIEW_SETTINGS`), from the
  operator to the end of the engine's render, median of ``REPEATS``.

The viewport's settings are the file's own (``viewport_settings``: 1 sample per pixel and F12's
photons per camera sample per pass).
"""
from __future__ import annotations

import statistics
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEMO = ROOT / "blend_scenes" / "demo.blend"
SIZE = (640, 360)
REPEATS = 3
PASS_WINDOW_S = 8.0


def _camera_view(bpy, scene, width, height, dz: float = 0.0):
    from addon.viewport import ViewParams
    cam = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    proj = cam.evaluated_get(depsgraph).calc_matrix_camera(depsgraph, x=width, y=height)
    view = cam.matrix_world.inverted()
    view[2][3] -= dz                      # the eye moved dz back along its view axis
    return ViewParams.from_matrices(width, height, view, proj)


def _first_image(session, timeout: float = 120.0) -> float:
    session.wait(lambda s: s.first_image_s is not None, timeout)
    return float(session.first_image_s)


def measure_viewport(size=SIZE) -> dict:
    import bpy

    import addon
    from addon.viewport import FIRST_PASS_PIXELS, ViewportSession, first_pass_size
    addon.register()
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    W, H = size
    out = {"scene": DEMO.name, "view": f"{W}x{H}", "first_pass": "x".join(map(str, first_pass_size(W, H))),
           "first_pass_pixels_max": FIRST_PASS_PIXELS}
    # Warm-up: the process's first render loads the compiled kernels
    warm = ViewportSession()
    warm.sync(bpy.context.evaluated_depsgraph_get(), view=_camera_view(bpy, scene, W, H))
    warm.wait(lambda s: s.passes_done >= 1, 300)
    warm.stop()

    firsts, fulls = [], []
    for _ in range(REPEATS):
        session = ViewportSession()
        t0 = time.perf_counter()
        session.sync(bpy.context.evaluated_depsgraph_get(), view=_camera_view(bpy, scene, W, H))
        session.wait(lambda s: s.first_image_s is not None, 120)
        firsts.append(time.perf_counter() - t0)
        session.wait(lambda s: s.passes_done >= 1, 120)
        fulls.append(time.perf_counter() - t0)
        if len(firsts) < REPEATS:
            session.stop()
    # Passes per second at full resolution, then a navigation and an edit
    n0, t0 = session.passes_done, time.perf_counter()
    time.sleep(PASS_WINDOW_S)
    passes_per_s = (session.passes_done - n0) / (time.perf_counter() - t0)
    nav = []
    for k in range(REPEATS):
        session.set_view(_camera_view(bpy, scene, W, H, dz=0.1 * (k + 1)))
        nav.append(_first_image(session))
    edits, exported, converted = [], [], []
    node = bpy.data.materials["Floor"].node_tree.nodes["Diffuse BSDF"]

    def view_update(_scene, depsgraph):                 # what Blender's view_update hands over
        if depsgraph.mode == "VIEWPORT":
            session.sync(depsgraph)
    bpy.app.handlers.depsgraph_update_post.append(view_update)
    try:
        for k in range(REPEATS):
            e0, m0 = session.cache.exports, session.cache.mesh_conversions
            t0 = time.perf_counter()
            node.inputs["Color"].default_value = (0.8, 0.2 + 0.1 * k, 0.2, 1.0)
            bpy.context.view_layer.update()
            session.wait(lambda s: s.first_image_s is not None, 120)
            edits.append(time.perf_counter() - t0)
            exported.append(session.cache.exports - e0)
            converted.append(session.cache.mesh_conversions - m0)
    finally:
        bpy.app.handlers.depsgraph_update_post.remove(view_update)
        session.stop()
    out.update({
        "first_image_s": statistics.median(firsts),
        "first_full_pass_s": statistics.median(fulls),
        "passes_per_s": passes_per_s,
        "navigate_first_image_s": statistics.median(nav),
        "edit_first_image_s": statistics.median(edits),
        "edit_exports": max(exported),
        "edit_meshes_converted": max(converted),
    })
    return out


def measure_preview() -> dict:
    import bpy

    import addon
    from addon import preview
    addon.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    bpy.context.scene.render.engine = "STPM"
    done, seconds = threading.Event(), []
    real = preview.render_preview

    def timed(engine, depsgraph):
        t0 = time.perf_counter()
        try:
            real(engine, depsgraph)
        finally:
            seconds.append(time.perf_counter() - t0)
            done.set()

    preview.render_preview = timed
    try:
        totals = []
        for k in range(REPEATS + 1):                       # the first one warms the node kernels
            mat = bpy.data.materials.new(f"Bench{k}")
            mat.node_tree.nodes["Principled BSDF"].inputs["Base Color"].default_value = (0.8, 0.1, 0.1, 1.0)
            done.clear()
            t0 = time.perf_counter()
            with bpy.context.temp_override(id=mat):
                bpy.ops.ed.lib_id_generate_preview()
            done.wait(300)
            totals.append(time.perf_counter() - t0)
    finally:
        preview.render_preview = real
    return {"preview_size": "128x128", "preview_s": statistics.median(seconds[1:]),
            "preview_operator_s": statistics.median(totals[1:]), "preview_passes": preview.PREVIEW_SETTINGS["passes"]}


def run() -> dict:
    try:
        import bpy  # noqa: F401
    except ImportError:
        return {"skipped": "bpy not importable: pip install bpy==5.0.1 (build.py installs it)"}
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    out = measure_viewport()
    out.update(measure_preview())
    return out


if __name__ == "__main__":
    for key, value in run().items():
        print(f"{key:28s} {value}")
