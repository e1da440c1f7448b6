"""The rendered viewport: a plain class that ``view_update`` / ``view_draw`` delegate to.

    session = ViewportSession()
    session.sync(depsgraph)                    # view_update: export what changed, restart
    session.set_view(ViewParams.from_context(context))   # view_draw: a moved view restarts
    image, version = session.image()           # the newest image, (H, W, 4) float32, row 0 = bottom
    session.stop()                             # no thread left

One session per 3D view in Rendered mode (one RenderEngine instance each); sessions share no
state, with each other or with F12 and material previews (no module-level variables are written).

**Export** happens on Blender's main thread only (:meth:`ViewportSession.sync`), through
:func:`addon.export.export_scene` with an :class:`addon.export.ExportCache`: the first sync
converts everything, later ones read ``depsgraph.updates`` and convert again only the meshes of
objects whose geometry changed, the materials when a material / node tree / image changed, the
world when it changed (transforms, lights and flags are read every time, they are cheap).  A
camera object's move exports nothing (the viewport's own view is the camera), nor does a
selection change.  The viewport renders the current frame without motion blur (moving Blender's
frame for the shutter's steps is F12's business).

**Rendering** runs on one worker thread per session, which touches no bpy: it gets a core scene
(the view's camera put in, :func:`addon.export.camera.view_camera`), and settings.  Each start
renders a first pass at a reduced resolution (at most :data:`FIRST_PASS_PIXELS` pixels) and then
progressive passes at the view's resolution (``stpm_core.render.render``, method PROGRESSIVE,
each pass's image published by ``on_pass``) until ``preview_passes`` passes or
``preview_time_limit`` seconds.  A restart (an edit, a moved view, a resized region, changed
settings) bumps a generation number: the running render's ``cancel()`` sees it within a tile and
the thread takes the newest job.

**Viewport settings** (:func:`viewport_settings`): the scene's render settings with method
PROGRESSIVE, one camera sample per pixel per pass, and per pass the photons F12 spends per camera
sample (``photons_* / samples``), so the viewport converges towards the look of F12.
"""
from __future__ import annotations

import math
import threading
import time
import traceback
from dataclasses import dataclass, replace

import numpy as np

from . import _core
from .export import ExportCache, export_scene
from .export.cache import forget_for_updates
from .export.camera import thin_lens, view_camera

__all__ = ["ViewParams", "ViewportSession", "ViewportDisplay", "viewport_settings", "first_pass_size",
           "FIRST_PASS_PIXELS", "view_update", "view_draw"]

# The first pass of every start renders at most this many pixels (then the view's resolution)
FIRST_PASS_PIXELS = 160 * 96
# ``preview_passes`` = 0 (unlimited) becomes this pass count (the schema's largest)
_UNLIMITED_PASSES = 1 << 24


@dataclass(frozen=True)
class ViewParams:
    """What the worker needs of a 3D view, copied on Blender's main thread.

    width, height : the region's size in pixels; view_matrix : world -> view (16 floats, row
    major); window_matrix : the projection (16 floats, row major); lens : the depth of field
    of a view through the scene camera, ((Camera field, value), ...) (:func:`camera_view_lens`;
    empty: a pinhole).
    """

    width: int
    height: int
    view_matrix: tuple
    window_matrix: tuple
    lens: tuple = ()

    @classmethod
    def from_context(cls, context) -> "ViewParams":
        """The view of ``context.region`` / ``context.region_data`` (main thread: reads bpy)."""
        region, rv3d = context.region, context.region_data
        return cls.from_matrices(region.width, region.height, rv3d.view_matrix, rv3d.window_matrix,
                                 lens=camera_view_lens(context.scene, rv3d))

    @classmethod
    def from_matrices(cls, width, height, view_matrix, window_matrix, lens: tuple = ()) -> "ViewParams":
        """From any 4 x 4 matrices (mathutils or numpy)."""
        def flat(m):
            return tuple(float(x) for row in m for x in row)
        return cls(max(1, int(width)), max(1, int(height)), flat(view_matrix), flat(window_matrix), tuple(lens))

    def camera(self):
        """The core camera of this view (:func:`addon.export.camera.view_camera`), with the scene
        camera's depth of field when the view looks through it (``lens``)."""
        cam = view_camera(np.reshape(self.view_matrix, (4, 4)), np.reshape(self.window_matrix, (4, 4)),
                          self.width, self.height)
        for name, value in self.lens:
            setattr(cam, name, value)
        return cam


def camera_view_lens(scene, rv3d) -> tuple:
    """((Camera field, value), ...): the scene camera's depth of field (``export.camera.thin_lens``,
    as F12 exports it) when the 3D view looks through that camera (``view_perspective`` 'CAMERA'),
    as Cycles' viewport shows it; () for any other view or a camera without depth of field."""
    cam = getattr(scene, "camera", None)
    if cam is None or getattr(rv3d, "view_perspective", "") != "CAMERA" or getattr(cam, "type", "") != "CAMERA":
        return ()
    return tuple(sorted(thin_lens(cam, cam.data.type).items()))


def viewport_settings(base, passes: int, time_limit: float):
    """The viewport's RenderSettings from the scene's ``base``: PROGRESSIVE, 1 camera sample per
    pixel per pass, per pass ``photons_* / samples`` photons (F12's photons per camera sample),
    stopping after ``passes`` passes (0 = no limit) or ``time_limit`` seconds (0 = none); no noise
    threshold, pass offset or denoising passes; no final gathering (PROGRESSIVE has none: the
    viewport shows the global map read directly)."""
    def per_sample(n: int) -> int:
        return 0 if n <= 0 else max(1, int(round(n / max(1, base.samples))))
    return base.replace(method="PROGRESSIVE", samples=1, photons_global=per_sample(base.photons_global),
                        photons_caustic=per_sample(base.photons_caustic),
                        passes=int(passes) if passes > 0 else _UNLIMITED_PASSES, time_limit=float(time_limit),
                        noise_threshold=0.0, pass_offset=0, denoise=False, final_gather_samples=0)


def first_pass_size(width: int, height: int, pixels: int = FIRST_PASS_PIXELS) -> tuple[int, int]:
    """The first pass's (width, height): the view's size divided by the smallest integer that
    leaves at most ``pixels`` pixels (the view's own size when it already does)."""
    d = max(1, math.ceil(math.sqrt(width * height / float(pixels))))
    while d > 1 and (width // d) * (height // d) > pixels:
        d += 1
    return max(1, width // d), max(1, height // d)


@dataclass
class _Job:
    """One start of the renderer: a scene with the view's camera, its settings, its generation."""

    generation: int
    scene: object
    settings: object


class ViewportSession:
    """Export, worker thread, image buffer and restarts of one rendered 3D view.

    Main thread (reads bpy): :meth:`sync`, :meth:`set_view`, :meth:`set_settings`.  Any thread:
    :meth:`image`, :attr:`status`, :meth:`take_redraw`, :meth:`stop`, :attr:`passes_done`.

    Counters (for tests and the benchmark): ``cache.exports`` (scene walks),
    ``cache.mesh_conversions`` (meshes converted), ``starts`` (render starts), ``images``
    (images published).
    """

    def __init__(self, *, first_pass_pixels: int = FIRST_PASS_PIXELS):
        self.cache = ExportCache()
        self.first_pass_pixels = int(first_pass_pixels)
        self.starts = 0
        self.images = 0
        self._scene = None              # the core scene of the last export (its camera is replaced)
        self._settings = None           # viewport RenderSettings
        self._signature = None          # what of the Blender scene needs a restart but no mesh export
        self._view = None               # ViewParams
        self._lock = threading.Lock()
        self._wake = threading.Condition(self._lock)
        self._generation = 0
        self._job = None                # the newest _Job not yet taken by the worker
        self._thread = None
        self._busy = False              # the worker is rendering a job
        self._stopping = False
        self._image = None              # (H, W, 4) float32, row 0 = bottom (GPU order)
        self._version = 0
        self._redraw = False
        self._status = ""
        self._passes_done = 0
        self._t_start = 0.0
        self.first_image_s = None       # seconds from the last start to its first image

    # ------------------------------------------------------------------ main thread (bpy)
    def sync(self, depsgraph, view: ViewParams | None = None) -> bool:
        """``view_update``: export what the depsgraph's updates changed, restart when needed.

        The first call exports everything; ``view`` (the region's, when known) is taken in the
        same restart.  Returns True when the render was restarted.  Errors in the scene (no
        lights is fine; a setting out of range, say) become the status line, never an exception.
        """
        scene = depsgraph.scene
        view_changed = view is not None and view != self._view
        if view_changed:
            self._view = view
        signature = _scene_signature(scene)
        first = self._scene is None
        needs_export = first
        if not first:
            what = forget_for_updates(self.cache, depsgraph.updates)
            before = self._signature or {}
            if signature["world"] != before.get("world"):
                self.cache.forget_world()          # another world assigned: a Scene update, not a World one
            if signature["working_space"] != before.get("working_space"):
                self.cache.forget_materials()      # colours converted to another working space
                self.cache.forget_world()
            needs_export = bool(what["objects"] or what["materials"] or what["world"] or what["other"]) \
                or signature != self._signature
        self._signature = signature
        if needs_export:
            try:
                stpm_scene, _warnings = export_scene(depsgraph, _no_frame_set, motion_steps=2,
                                                     motion_blur=False, camera=False, cache=self.cache)
            except _core.StpmError as exc:
                self._fail(f"STPM: {exc}")
                return False
            self._scene = stpm_scene
        try:
            settings = self._read_settings(scene)
        except _core.StpmError as exc:         # the scene is kept: fixing the setting restarts
            self._settings = None
            self._fail(f"STPM: {exc}")
            return False
        changed = needs_export or view_changed or settings != self._settings
        self._settings = settings
        if changed:
            self._restart()
        return changed

    def set_settings(self, scene) -> bool:
        """Re-read the scene's STPM settings (a panel edit Blender reported as no update); restart
        without export when they changed.  Returns True when restarted."""
        try:
            settings = self._read_settings(scene)
        except _core.StpmError as exc:
            if self._settings is not None:          # said once, not at every redraw
                self._settings = None
                self._fail(f"STPM: {exc}")
            return False
        if settings == self._settings:
            return False
        self._settings = settings
        self._restart()
        return True

    def set_view(self, view: ViewParams) -> bool:
        """``view_draw``: a new view (navigation, a resized region) restarts without export.
        Returns True when restarted."""
        if view == self._view:
            return False
        self._view = view
        self._restart()
        return True

    @staticmethod
    def _read_settings(scene):
        from .properties import settings_from_scene
        scene = getattr(scene, "original", None) or scene   # an edit in the panel is on the original first
        props = scene.stpm
        return viewport_settings(settings_from_scene(scene), int(props.preview_passes),
                                 float(props.preview_time_limit))

    # ------------------------------------------------------------------ restarts
    def _restart(self) -> None:
        """Hand the worker a new job (the running render stops within a tile)."""
        if self._scene is None or self._view is None or self._settings is None:
            return
        W, H = self._view.width, self._view.height
        scene = replace(self._scene, camera=self._view.camera(), resolution=(W, H))
        with self._lock:
            if self._stopping:
                return
            self._generation += 1
            self._job = _Job(self._generation, scene, self._settings)
            self._status = "Starting"
            self._passes_done = 0
            self._t_start = time.perf_counter()
            self.first_image_s = None
            self.starts += 1
            if self._thread is None:
                self._thread = threading.Thread(target=self._worker, name="STPM viewport", daemon=True)
                self._thread.start()
            self._wake.notify_all()

    def _fail(self, text: str) -> None:
        with self._lock:
            self._generation += 1          # whatever runs belongs to a scene that no longer renders
            self._job = None
            self._status = text
            self._redraw = True

    # ------------------------------------------------------------------ worker thread (no bpy)
    def _worker(self) -> None:
        while True:
            with self._lock:
                while self._job is None and not self._stopping:
                    self._wake.wait()
                if self._stopping:
                    return
                job, self._job = self._job, None
                self._busy = True
            try:
                self._render(job)
            except _core.RenderCancelled:
                pass
            except _core.StpmError as exc:
                self._say(job, f"STPM: {exc}")
            except Exception as exc:  # noqa: BLE001 -- a bug: the console gets the traceback, the view one line
                traceback.print_exc()
                first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
                self._say(job, f"STPM: viewport render failed ({type(exc).__name__}{': ' + first if first else ''})")
            finally:
                with self._lock:
                    self._busy = False

    def _current(self, job) -> bool:
        return job.generation == self._generation and not self._stopping

    def _render(self, job: _Job) -> None:
        """A reduced first pass, then progressive passes at the view's size (both publish)."""
        render = _core.render_function()

        def cancel():
            return not self._current(job)

        def progress(_fraction, message):
            # Until the first image: what the core is doing (loading or compiling kernels, photons)
            if message and self.first_image_s is None:
                self._say(job, str(message)[:1].upper() + str(message)[1:])

        W, H = job.scene.resolution
        small = first_pass_size(W, H, self.first_pass_pixels)
        if small != (W, H):
            self._say(job, "Rendering first pass")
            render(replace(job.scene, resolution=small), job.settings.replace(passes=1, time_limit=0.0),
                   cancel=cancel, progress=progress, on_pass=lambda passes, info: self._publish(job, passes, None))
        if not self._current(job):
            return
        limit = job.settings.passes if job.settings.passes < _UNLIMITED_PASSES else None
        result = render(job.scene, job.settings, cancel=cancel, progress=progress,
                        on_pass=lambda passes, info: self._publish(job, passes, info, limit))
        prog = (result.stats or {}).get("progressive") or {}
        if self._current(job):
            elapsed = time.perf_counter() - self._t_start
            why = str(prog.get("stopped_by", "passes")).replace("_", " ")
            self._say(job, f"Done: {prog.get('passes', self._passes_done)} passes in {elapsed:.1f} s "
                           f"(stopped by {why})")

    def _publish(self, job: _Job, passes: dict, info, limit=None) -> None:
        """An image of ``job`` (core passes, row 0 = top) -> the buffer (RGBA, row 0 = bottom)."""
        combined = np.asarray(passes["Combined"], dtype=np.float32)
        rgba = np.ones(combined.shape[:2] + (4,), dtype=np.float32)
        rgba[..., :combined.shape[2]] = combined[..., :4]
        rgba = np.ascontiguousarray(rgba[::-1])
        with self._lock:
            if job.generation != self._generation:
                return
            self._image = rgba
            self._version += 1
            self.images += 1
            self._redraw = True
            elapsed = time.perf_counter() - self._t_start
            if self.first_image_s is None:
                self.first_image_s = elapsed
            if info is None:
                self._status = "Reduced first pass; rendering pass 1"
            else:
                self._passes_done = int(info["passes"])
                self._status = f"Pass {self._passes_done}" + (f"/{limit}" if limit else "") + f", {elapsed:.1f} s"

    def _say(self, job: _Job, text: str) -> None:
        with self._lock:
            if job.generation == self._generation:
                self._status = text
                self._redraw = True

    # ------------------------------------------------------------------ any thread
    def image(self):
        """(newest image (H, W, 4) float32 row 0 = bottom, its version) or (None, 0)."""
        with self._lock:
            return self._image, self._version

    def take_redraw(self) -> bool:
        """Has anything new (an image, a status) arrived since the last call?"""
        with self._lock:
            news, self._redraw = self._redraw, False
            return news

    @property
    def status(self) -> str:
        with self._lock:
            return self._status

    @property
    def passes_done(self) -> int:
        """Full-resolution passes published since the last start."""
        with self._lock:
            return self._passes_done

    @property
    def running(self) -> bool:
        """Is a render started and not finished (or a job waiting)?"""
        with self._lock:
            return self._job is not None or self._busy

    @property
    def stopped(self) -> bool:
        return self._stopping

    def wait(self, predicate, timeout: float = 300.0, poll: float = 0.01) -> bool:
        """Wait until ``predicate(self)`` holds (tests, the benchmark); False on timeout (the default
        leaves room for a first render that compiles the kernels)."""
        t_end = time.perf_counter() + timeout
        while time.perf_counter() < t_end:
            if predicate(self):
                return True
            time.sleep(poll)
        return bool(predicate(self))

    def stop(self, timeout: float = 30.0) -> bool:
        """Stop the render and end the worker thread (idempotent).  Returns True when no thread
        is left (the running pass stops within a tile: about a second at most)."""
        with self._lock:
            self._stopping = True
            self._generation += 1
            self._job = None
            thread = self._thread
            self._wake.notify_all()
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
            if thread.is_alive():
                return False
        with self._lock:
            self._thread = None
        return True


def _no_frame_set(frame: int, subframe: float) -> None:
    """The viewport never moves Blender's frame (export_scene with motion_blur=False never calls it)."""
    raise RuntimeError("the rendered viewport does not step through the shutter")


def _scene_signature(scene) -> dict:
    """What of the Blender scene, besides its objects, the viewport's export reads: a change
    (seen as a Scene update, e.g. another world assigned, Film > Transparent) re-exports; the
    file's working colour space (Blender 5), which the materials' and world's colours are
    converted to, also makes them stale."""
    from .export.nodes import working_space
    return {"world": scene.world.name_full if scene.world is not None else None,
            "film_transparent": bool(scene.render.film_transparent),
            "frame": (int(scene.frame_current), float(scene.frame_subframe)),
            "working_space": working_space()}


# ---------------------------------------------------------------------------------------------
# What RenderEngine.view_update / view_draw call (Blender's main thread)
# ---------------------------------------------------------------------------------------------
def view_update(engine, context, depsgraph) -> None:
    """``RenderEngine.view_update``: the engine's session syncs with the depsgraph (and takes the
    region's view when the context has one)."""
    _call(engine, context, lambda session, view: session.sync(depsgraph, view=view), need_view=False)


def view_draw(engine, context, depsgraph) -> None:
    """``RenderEngine.view_draw``: a new view or new settings restart; the newest image is drawn
    through the display-space shader and the status goes to the viewport's text."""
    def draw(session, view):
        session.set_view(view)
        session.set_settings(context.scene)
        engine.stpm_display.draw(engine, depsgraph.scene, session, view.width, view.height)
        engine.update_stats("", session.status)
    _call(engine, context, draw)


def _call(engine, context, fn, need_view: bool = True) -> None:
    """fn(session, view) with ``engine``'s :class:`ViewportSession` (made on first use, with its
    :class:`ViewportDisplay` and redraw timer; kept on the engine instance, one per 3D view) and
    the region's view (None without one, unless ``need_view``).  An unexpected exception becomes
    one status line in the view (its traceback printed to the console once)."""
    try:
        session = engine.__dict__.get("stpm_viewport")
        if session is None:
            session = engine.stpm_viewport = ViewportSession()
            engine.stpm_display = ViewportDisplay()
            start_redraw_timer(engine, session)
        has_view = getattr(context, "region_data", None) is not None and getattr(context, "region", None) is not None
        if has_view or not need_view:
            fn(session, ViewParams.from_context(context) if has_view else None)
    except Exception as exc:  # noqa: BLE001 -- never a traceback in the UI
        line = f"STPM: viewport failed ({type(exc).__name__}: {str(exc).strip()[:120]})"
        if engine.__dict__.get("stpm_viewport_error") != line:      # once per error, not per redraw
            traceback.print_exc()
            engine.stpm_viewport_error = line
        engine.update_stats("", line)


def stop_engine_session(engine, timeout: float = 5.0) -> None:
    """Stop ``engine``'s session, if it has one (``RenderEngine.__del__``)."""
    session = engine.__dict__.get("stpm_viewport")
    if session is not None:
        session.stop(timeout=timeout)


def start_redraw_timer(engine, session: ViewportSession, interval: float = 0.05) -> None:
    """Ask Blender to redraw ``engine``'s view whenever the session has news, from a timer on
    Blender's main thread (the worker thread calls no bpy).  The timer holds the engine weakly
    and ends with the session, or when Blender has freed the engine (its RNA raises
    ReferenceError; the session is stopped then)."""
    import weakref

    import bpy
    try:
        ref = weakref.ref(engine)
    except TypeError:                   # no weak references to this type: hold it
        ref = (lambda e=engine: e)

    def tick():
        eng = ref()
        if eng is None or session.stopped:
            return None
        try:
            if session.take_redraw():
                eng.tag_redraw()
            else:
                eng.is_preview          # a freed engine's RNA raises ReferenceError
        except ReferenceError:
            session.stop(timeout=0.0)
            return None
        return interval

    bpy.app.timers.register(tick, first_interval=interval)


class ViewportDisplay:
    """The newest image as a GPU texture, drawn through the engine's display-space shader.

    Lives on the RenderEngine (one per view) and is used in ``view_draw`` only (Blender's main
    thread with its GPU context); ``gpu`` is imported there, so background Blender never needs it.
    """

    def __init__(self):
        self.texture = None
        self.version = -1

    def draw(self, engine, scene, session: ViewportSession, width: int, height: int) -> bool:
        """Draw the session's newest image over the region (scaled when it is a reduced pass).
        Returns False when there is no image yet."""
        import gpu
        from gpu_extras.presets import draw_texture_2d

        image, version = session.image()
        if image is None:
            return False
        if version != self.version or self.texture is None:
            h, w = image.shape[:2]
            data = gpu.types.Buffer("FLOAT", w * h * 4, image.reshape(-1))
            self.texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=data)
            self.version = version
        # Scene linear -> display: the engine's display-space shader (the view transform and look of F12)
        gpu.state.blend_set("ALPHA_PREMULT")
        engine.bind_display_space_shader(scene)
        draw_texture_2d(self.texture, (0, 0), width, height)
        engine.unbind_display_space_shader()
        gpu.state.blend_set("NONE")
        return True

    def free(self) -> None:
        self.texture = None
