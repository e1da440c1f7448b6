""""Compare with accumulation buffer": the `stpm compare` report from inside Blender.

The operator exports the current frame on the main thread (Blender data is
only safe there), then runs :func:`stpm_core.compare.run_compare` on a worker
thread, so the interface stays responsive.  A timer shows progress in the
status bar; Esc cancels (the report written so far is kept).  The report goes
next to the .blend as ``<blend stem>_compare/report.html`` and the operator says
where.
"""
from __future__ import annotations

import os
import threading

import bpy

from . import _core


def report_dir(blend_path: str) -> str:
    """Where the report of ``blend_path`` goes: ``<dir>/<stem>_compare``."""
    root, _ext = os.path.splitext(bpy.path.abspath(blend_path))
    return root + "_compare"


class _Job:
    """State shared between the worker thread and the modal operator."""

    def __init__(self):
        self.fraction = 0.0
        self.message = "starting"
        self.cancel = False
        self.done = False
        self.error: str | None = None
        self.report: dict | None = None


def _run(job: _Job, scene, settings, out_dir: str, scene_name: str, time_budget: float | None) -> None:
    """Worker thread: the compare sweep (no bpy in here)."""
    from importlib import import_module
    run_compare = import_module(f"{_core.core.__name__}.compare").run_compare

    def progress(fraction, message):
        job.fraction, job.message = float(fraction), str(message)

    try:
        job.report = run_compare(scene, settings, out_dir, time_budget=time_budget, progress=progress,
                                 cancel=lambda: job.cancel, scene_name=scene_name)
    except _core.StpmError as e:  # cancelled (partial report written) or bad input
        job.error = str(e).splitlines()[0] if str(e) else type(e).__name__
    except Exception as e:  # a bug: say so in one line, keep Blender alive
        job.error = f"compare failed ({type(e).__name__}: {e}); please report"
    finally:
        job.done = True


class STPM_OT_compare(bpy.types.Operator):
    """Render this frame with STANDARD, TEMPORAL and KD4D and with the accumulation
    buffer, and write a report of error against time next to the .blend"""

    bl_idname = "stpm.compare"
    bl_label = "Compare with Accumulation Buffer"
    bl_options = {"REGISTER"}

    time_budget: bpy.props.FloatProperty(
        name="Time Budget", default=0.0, min=0.0, unit="TIME_ABSOLUTE",
        description="Stop starting new runs after this many seconds (0 = run the whole sweep)")

    _timer = None
    _job: _Job | None = None
    _thread: threading.Thread | None = None

    @classmethod
    def poll(cls, context):
        return context.scene is not None and context.scene.render.engine == "STPM"

    def execute(self, context):
        if not bpy.data.filepath:
            self.report({"ERROR"}, "Save the .blend first: the report is written next to it")
            return {"CANCELLED"}
        from .batch import export_current
        from .properties import settings_from_scene
        try:
            settings = settings_from_scene(context.scene)
            scene, _ = export_current(context.scene)
        except _core.StpmError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        out_dir = report_dir(bpy.data.filepath)
        self._job = job = _Job()
        budget = self.time_budget if self.time_budget > 0 else None
        self._thread = threading.Thread(
            target=_run, args=(job, scene, settings, out_dir, os.path.basename(bpy.data.filepath), budget),
            daemon=True)
        self._thread.start()
        wm = context.window_manager
        if bpy.app.background or context.window is None:  # no event loop (farm, tests): wait here
            self._thread.join()
            return self._finish(context)
        self._timer = wm.event_timer_add(0.25, window=context.window)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC":
            job.cancel = True
        if event.type == "TIMER":
            context.workspace.status_text_set(f"STPM compare: {job.fraction * 100:.0f}%  {job.message}  (Esc cancels)")
            if job.done:
                context.window_manager.event_timer_remove(self._timer)
                context.workspace.status_text_set(None)
                return self._finish(context)
        return {"PASS_THROUGH"}

    def _finish(self, context):
        job = self._job
        html = os.path.join(report_dir(bpy.data.filepath), "report.html")
        if job.error:
            where = f"; partial report: {html}" if os.path.exists(html) else ""
            self.report({"WARNING"}, f"{job.error}{where}")
            return {"CANCELLED"}
        files = (job.report or {}).get("files", {})
        self.report({"INFO"}, f"Compare report written: {files.get('html', html)}")
        return {"FINISHED"}


classes = (STPM_OT_compare,)


# Blender's helper: register in order, unregister in reverse
register, unregister = bpy.utils.register_classes_factory(classes)
