"""The one seam between ``stpm_core`` and the Blender add-on: reading a ``.blend``.

Why it exists: ``stpm_core`` never imports ``bpy`` (it runs without Blender:
the ``stpm`` command, tests, benchmarks), and the add-on's exporter
(``addon/export/``, driven by ``addon.batch``) is the only reader of ``.blend``
files -- the core has no second one.  A core module that needs a ``.blend``
comes through here, and this is the only module of ``stpm_core`` that reaches
``addon`` (checked by tests/test_layering.py).

The .blend is read in a child process
------------------------------------
Blender's own reader can crash on a corrupt file (a segmentation fault inside
``bpy.ops.wm.open_mainfile``, no Python exception to catch).  So the file is
never opened in the calling process: :class:`BlendReader` starts one child,
``python -P -c "from addon.batch import serve; serve(FD)"`` (:func:`addon.batch.serve`),
which opens the .blend once and, per frame asked for, exports it with the add-on
and writes it to a core scene file (:mod:`stpm_core.scenefile`, uncompressed) in a
private temporary folder; the parent loads that file -- with the loader's checks --
and deletes it.  One reader, one open of the .blend, whatever the number of frames.

* A crash or kill of the child is one :class:`~stpm_core.errors.StpmError` line naming
  the file: ``cannot open bad.blend: Blender's .blend reader crashed (SIGSEGV): the file
  is corrupt or truncated``.
* Blender's console output (the child's stdout and stderr) is captured in that folder and
  passed on per request: to stderr when the request succeeded (``quiet`` drops the "Read
  blend:" line), dropped when it failed (the ``stpm: error:`` line says it once;
  ``STPM_DEBUG`` keeps it), with control and bidi characters escaped.
* ``cancel()`` (the CLI's :class:`~stpm_core.command_common.CancelFlag`) is polled while
  waiting: a Ctrl-C or SIGTERM kills the child's process group (its own session, so a
  terminal's Ctrl-C never reaches Blender directly) and raises
  :class:`~stpm_core.errors.RenderCancelled`.  :func:`kill_children` does the same for
  an abort (the second signal) and at exit.

Measured cost on top of exporting in-process (docs/cli.md, "A .blend is read in a child
process"): the child's start (a Python process and the core's imports it shares with the
parent) once per command, and per frame a write and a read of the scene file.

:func:`blend_frame_range` imports nothing: it reads the ``frame_range`` the exporter
records in the scene's metadata.

:func:`denoise_result` runs Blender's Denoise node (the add-on's STPM Denoise group; the
compositor runs in the bpy module) on a render made with ``denoise``, in a reader process too
(:meth:`BlendReader.denoise`: no .blend opened, the passes handed over in a file).
"""
from __future__ import annotations

import atexit
import importlib.util
import json
import os
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from .errors import RenderCancelled, SceneError, SettingsError, StpmError

__all__ = ["BlendSupportMissing", "BlendReader", "BlenderExportBug", "load_blend", "blend_frame_range",
           "kill_children", "denoise_result"]


class BlendSupportMissing(StpmError):
    """.blend input is not available here: Blender's bpy module or ``addon.batch`` cannot be imported."""


class BlenderExportBug(Exception):
    """The .blend reader process met an unexpected exception (a bug in the exporter, not in the file).

    Not an :class:`StpmError`: the command reports it as an internal error ("please report").
    """


# The user errors the reader process may answer with, by class name (others: StpmError)
_ERRORS = {cls.__name__: cls for cls in (StpmError, SceneError, SettingsError, BlendSupportMissing)}

# Live reader processes: pid -> their temporary folder (killed and removed by kill_children)
_LIVE: dict[int, str] = {}


def kill_children() -> None:
    """Kill every live reader process (its whole process group: a Cycles bake it started too) and
    remove its temporary folder.  Safe in a signal handler before ``os._exit`` and at exit."""
    for pid, folder in list(_LIVE.items()):
        try:
            os.killpg(pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError, OSError):
            pass
        shutil.rmtree(folder, ignore_errors=True)
        _LIVE.pop(pid, None)


atexit.register(kill_children)


def _child_env() -> dict:
    """The environment of the reader process: ours, with the folder holding ``addon`` on PYTHONPATH."""
    if importlib.util.find_spec("bpy") is None:
        raise ImportError("no module named 'bpy'")
    spec = importlib.util.find_spec("addon")
    if spec is None or not spec.submodule_search_locations:
        raise ImportError("no package named 'addon'")
    root = str(Path(list(spec.submodule_search_locations)[0]).resolve().parent)
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([root] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    env.pop("PYTHONSTARTUP", None)
    return env


class BlendReader:
    """One child process reading one .blend: opened once, frames exported on request.

    A context manager.  ``scene(frame)`` -> (Scene, the file's ``scene.stpm`` settings dict).

    Parameters
    ----------
    path : the .blend (as the user gave it: error lines name it so).
    bake : first bake, per frame, the shader inputs the node interpreter cannot evaluate and
        that have no cached bake (one Cycles child of the reader; ``addon/export/bake.py``).
    quiet : drop Blender's "Read blend:" line from the output passed on.
    cancel : ``cancel() -> bool`` polled every 50 ms while waiting (None: never).
    """

    def __init__(self, path, *, bake: bool = False, quiet: bool = False, cancel=None):
        self.path = Path(path)
        self.bake, self.quiet, self.cancel = bool(bake), bool(quiet), cancel
        self.frame_range: list | None = None
        self.timings: dict = {}          # seconds of the last request: start, export, save, load, wall
        self._proc: subprocess.Popen | None = None
        self._dir: str | None = None
        self._reply_fd: int | None = None
        self._buf = b""
        self._log_pos = 0
        self._last_log = ""             # Blender's output of the last request (for a death's line)
        self._count = 0

    # ------------------------------------------------------------------ public
    def __enter__(self) -> "BlendReader":
        return self

    def __exit__(self, *exc) -> bool:
        self.close()
        return False

    def scene(self, frame: int | float | None = None) -> tuple:
        """(Scene, settings dict) of ``frame`` (None: the file's current frame)."""
        from .scenefile import load_scene_with_settings
        t0 = time.perf_counter()
        start_s = 0.0
        if self._proc is None:
            self._start()
            start_s = time.perf_counter() - t0
        self._count += 1
        out = os.path.join(self._dir, f"frame_{self._count}.stpm")
        answer = self._request({"frame": frame, "bake": self.bake, "out": out}, frame)
        t1 = time.perf_counter()
        try:
            scene, _ = load_scene_with_settings(out)
        except SceneError as e:   # the reader writes only what loads: a disagreement between the two
            rest = str(e).split(": ", 1)[-1]
            raise SceneError(f"{self.path.name} (frame {frame if frame is not None else 'current'}, "
                             f"exported): {rest}") from None
        finally:
            try:
                os.unlink(out)
            except OSError:
                pass
        self.timings = {"start_s": start_s, "export_s": float(answer.get("export_s", 0.0)),
                        "save_s": float(answer.get("save_s", 0.0)), "load_s": time.perf_counter() - t1,
                        "wall_s": time.perf_counter() - t0}
        return scene, answer.get("settings")

    def denoise(self, passes: dict):
        """Blender's Denoise node on a render's passes, in the child (``addon.denoise.denoise_passes``:
        the STPM Denoise group in a compositor of its own): the denoised RGBA (H, W, 4) float32.
        Needs no .blend open: a reader made for this alone starts without opening its file."""
        import numpy as np
        if self._proc is None:
            self._start(open_file=False)
        self._count += 1
        src = os.path.join(self._dir, f"denoise_{self._count}.npz")
        out = os.path.join(self._dir, f"denoised_{self._count}.npy")
        np.savez(src, **{name: np.asarray(passes[name], np.float32)
                         for name in ("Combined", "Noisy Image", "Denoising Albedo", "Denoising Normal")
                         if name in passes})
        try:
            # (Blender's own lines about it -- "Saved: '/tmp/stpm_denoise_...'", the compositor's
            # timing -- name temporary files gone by now: not passed on, unless STPM_DEBUG)
            answer = self._request({"denoise": src, "out": out}, None, chatter=False)
            image = np.load(out)
        finally:
            for f in (src, out):
                try:
                    os.unlink(f)
                except OSError:
                    pass
        self.timings = {"denoise_s": float(answer.get("denoise_s", 0.0))}
        return image

    def close(self) -> None:
        """End the reader process (end of input: it exits at once) and remove its folder."""
        proc, self._proc = self._proc, None
        if proc is not None:
            try:
                proc.stdin.close()
            except OSError:
                pass
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                _kill_group(proc)
            _LIVE.pop(proc.pid, None)
        if self._reply_fd is not None:
            os.close(self._reply_fd)
            self._reply_fd = None
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    # ------------------------------------------------------------------ the child
    def _start(self, open_file: bool = True) -> None:
        try:
            env = _child_env()
        except ImportError as e:
            raise BlendSupportMissing(f"cannot load {self.path.name}: .blend files need Blender's bpy module "
                                      f"and addon.batch ({e}); install the 'test' extra or export a .stpm "
                                      "scene") from None
        self._dir = tempfile.mkdtemp(prefix="stpm-blend-")
        read_fd, write_fd = os.pipe()
        try:
            with open(os.path.join(self._dir, "blender.log"), "wb") as log:
                # -P: the current folder is not on sys.path (a random.py there must not shadow the stdlib)
                self._proc = subprocess.Popen(
                    [sys.executable, "-P", "-c", f"from addon.batch import serve; serve({write_fd})"],
                    stdin=subprocess.PIPE, stdout=log, stderr=subprocess.STDOUT, pass_fds=(write_fd,),
                    env=env, start_new_session=True)     # its own process group: signals go through us
        except OSError:
            os.close(read_fd)
            raise
        finally:
            os.close(write_fd)
        self._reply_fd = read_fd
        _LIVE[self._proc.pid] = self._dir
        if open_file:
            answer = self._request({"open": str(self.path)}, None)
            self.frame_range = answer.get("frame_range")

    def _request(self, request: dict, frame, chatter: bool = True) -> dict:
        """Send one request, wait for its answer (polling ``cancel``), pass Blender's output on when it
        succeeded (``chatter`` False: not even then, unless STPM_DEBUG)."""
        try:
            self._proc.stdin.write((json.dumps(request) + "\n").encode())
            self._proc.stdin.flush()
        except (BrokenPipeError, OSError):
            pass                                   # the child is gone: its exit status says why
        while b"\n" not in self._buf:
            if self.cancel is not None and self.cancel():
                _kill_group(self._proc)
                self.close()
                raise RenderCancelled("cancelled")
            ready, _, _ = select.select([self._reply_fd], [], [], 0.05)
            if not ready:
                continue
            chunk = os.read(self._reply_fd, 1 << 16)
            if not chunk:
                status = self._proc.wait()
                self._pass_log(ok=False)
                self.close()
                raise self._death(status, request, frame)
            self._buf += chunk
        line, self._buf = self._buf.split(b"\n", 1)
        answer = json.loads(line)
        self._pass_log(ok=bool(answer.get("ok")) and chatter)
        if answer.get("ok"):
            return answer
        message = str(answer.get("error", "")).replace(": Error: ", ": ")   # Blender's "Error: " said once
        if "bug" in answer:
            if os.environ.get("STPM_DEBUG"):
                sys.stderr.write(str(answer.get("traceback", "")))
            raise BlenderExportBug(f"{answer['bug']}: {message} (in the .blend reader process)")
        raise _ERRORS.get(answer.get("kind"), StpmError)(message)

    def _death(self, status: int, request: dict, frame) -> StpmError:
        """The one line for a reader process that ended without answering."""
        name = self.path
        if status < 0:
            try:
                sig = signal.Signals(-status).name
            except ValueError:
                sig = f"signal {-status}"
            if "open" in request:
                what = "was killed (SIGKILL: out of memory?)" if sig == "SIGKILL" else f"crashed ({sig})"
                return StpmError(f"cannot open {name}: Blender's .blend reader {what}: the file is corrupt "
                                 "or truncated")
            if "denoise" in request:
                return StpmError(f"{name}: Blender crashed ({sig}) in its Denoise node (a bug)")
            which = f"frame {frame}" if frame is not None else "the current frame"
            return StpmError(f"{name}: Blender crashed ({sig}) exporting {which} (a corrupt file, or a bug)")
        tail = [ln for ln in self._last_log.splitlines() if ln.strip()][-1:] or ["no message"]
        return StpmError(f"cannot open {name}: the .blend reader process stopped (exit {status}): {tail[0]}")

    def _pass_log(self, ok: bool) -> None:
        """Blender's output since the last request: to stderr when it succeeded, else dropped."""
        from .command_common import safe_text
        try:
            with open(os.path.join(self._dir, "blender.log"), "rb") as f:
                f.seek(self._log_pos)
                data = f.read()
        except OSError:
            return
        self._log_pos += len(data)
        text = data.decode("utf-8", errors="replace")
        self._last_log = text
        if not ok and not os.environ.get("STPM_DEBUG"):
            return
        keep = [safe_text(line) for line in text.splitlines()
                if line.strip() and not (self.quiet and "Read blend:" in line)]
        if keep:
            sys.stderr.write("\n".join(keep) + "\n")
            sys.stderr.flush()


def _kill_group(proc: subprocess.Popen) -> None:
    """SIGKILL the reader's process group (it and any Cycles bake it started) and reap it."""
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError, OSError):
        pass
    try:
        proc.wait(timeout=10)
    except subprocess.TimeoutExpired:
        pass


def load_blend(path, frame: int | float | None = None, bake: bool = False, *, quiet: bool = False,
               cancel=None) -> tuple:
    """(Scene, settings dict) of frame ``frame`` (None: the file's current frame) of the .blend ``path``.

    One :class:`BlendReader` for one frame.  ``bake``: first bake the shader inputs the node
    interpreter cannot evaluate and that have no cached bake (one Cycles child process;
    ``addon/export/bake.py``), as ``stpm render`` does.

    Raises :class:`BlendSupportMissing` (one line, naming the file and the fix) when bpy or the
    add-on cannot be found, and StpmError (one line) when the file cannot be read -- also when
    Blender's reader crashes on it -- with Blender's "Error: " said once (``cannot open x.blend:
    File format is not supported ...``).
    """
    with BlendReader(path, bake=bake, quiet=quiet, cancel=cancel) as reader:
        return reader.scene(frame)


def blend_frame_range(scene) -> tuple[int, int] | None:
    """(frame_start, frame_end) of the .blend ``scene`` was exported from, or None if unknown.

    From ``scene.metadata['frame_range']`` (the reader records it; the scene-file loader has
    checked its type), else from the bpy module already loaded by an in-process export (the
    add-on; never imported here).
    """
    meta = scene.metadata if isinstance(scene.metadata, dict) else {}
    rng = meta.get("frame_range")
    if rng is not None:
        try:
            return int(rng[0]), int(rng[1])
        except (TypeError, ValueError, IndexError):
            return None
    bpy = sys.modules.get("bpy")
    try:
        bscene = bpy.data.scenes[meta["blender_scene"]] if "blender_scene" in meta else bpy.context.scene
        return int(bscene.frame_start), int(bscene.frame_end)
    except Exception:  # noqa: BLE001 -- no bpy or no such scene: no range to check
        return None


_DENOISERS: dict = {}          # a reader process kept for denoising, one per command (closed at exit)


def _close_denoisers() -> None:
    for reader in list(_DENOISERS.values()):
        reader.close()
    _DENOISERS.clear()


atexit.register(_close_denoisers)


def denoise_result(result, path, *, cancel=None) -> list[str]:
    """Denoise a render made with ``RenderSettings.denoise`` in place: its Combined becomes the image
    of Blender's Denoise node (the add-on's STPM Denoise group, guided by Denoising Albedo and
    Normal), Noisy Image keeps the raw one; ``stats['denoise_s']`` the seconds it took.

    Blender runs in a child process (:meth:`BlendReader.denoise`; bpy never loads into this one),
    kept for the next frame of the command.  ``path``: the scene file, for error lines.  Returns
    warning lines: where bpy cannot be found, Combined stays raw (the guide passes are written all
    the same, for a compositor elsewhere).
    """
    passes = result.passes
    if "Denoising Albedo" not in passes or "Denoising Normal" not in passes:
        return ["denoise: the render has no denoising passes; Combined is not denoised"]
    t0 = time.perf_counter()
    reader = _DENOISERS.get("reader")
    if reader is None:
        reader = _DENOISERS["reader"] = BlendReader(path, quiet=True, cancel=cancel)
    try:
        denoised = reader.denoise(passes)
    except BlendSupportMissing as e:
        _DENOISERS.pop("reader", None)
        return [f"denoise: {str(e).split(': ', 1)[-1]}; Combined is not denoised (Denoising Albedo, Denoising "
                "Normal and Noisy Image are in the EXR for a compositor)"]
    except (StpmError, BlenderExportBug):
        _DENOISERS.pop("reader", None)
        raise
    passes.setdefault("Noisy Image", passes["Combined"])
    passes["Combined"] = denoised
    result.stats["denoise_s"] = time.perf_counter() - t0
    return []
