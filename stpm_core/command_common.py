"""What the command-line programs share: ``stpm render|plan`` (:mod:`stpm_core.cli`),
``stpm compare`` (:mod:`stpm_core.compare.command`) and the demo (:mod:`stpm_core.demo`).

Each command imports from here and none imports another's internals, so
``cli`` and ``compare.command`` depend on this module, never on each other's
private names (checked by tests/test_layering.py).  Nothing here parses a
whole command line or renders; heavy modules are imported only when called,
so ``stpm --help`` stays quick.

* exit statuses (``EXIT_*``), Blender's frame limits (:data:`FRAME_MIN`,
  :data:`FRAME_MAX`), :class:`UsageError` and :class:`CommandParser` (syntax
  errors as one line, exit status 2);
* the render-settings options both commands take (:func:`add_setting_options`)
  and their check before loading (:func:`checked_overrides`, :func:`option_message`);
* scenes: :func:`load_any_scene` (core file or .blend, through
  :mod:`stpm_core.blend_loader`), :func:`open_blend_reader`, :func:`scene_kind`, :func:`settings_from_dict`,
  :class:`stdout_to_stderr`;
* memory: :func:`check_memory` (:func:`image_memory`, :func:`available_memory`);
* Ctrl-C / SIGTERM: :class:`CancelFlag` and :func:`check_cancel`.
"""
from __future__ import annotations

import argparse
import math
import os
import re
import signal
import sys
import time
import unicodedata
from dataclasses import fields
from pathlib import Path

from .errors import RenderCancelled, SettingsError, StpmError

__all__ = ["EXIT_OK", "EXIT_ERROR", "EXIT_USAGE", "EXIT_INTERNAL", "EXIT_CANCELLED", "FRAME_MIN", "FRAME_MAX",
           "UsageError", "CommandParser", "add_setting_options", "checked_overrides", "option_message",
           "scene_kind", "settings_from_dict", "stdout_to_stderr", "load_any_scene", "open_blend_reader",
           "BYTES_PER_PIXEL", "available_memory", "image_memory", "check_memory", "CancelFlag", "check_cancel",
           "finite_float", "safe_text", "BYTES_PER_PHOTON_ESTIMATE", "photon_memory"]

# Exit statuses of every command (docs/cli.md): 0 success; 1 a user error; 2 bad
# command-line syntax; 3 an internal error (a bug); 130 cancelled (128 + the signal).
EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_INTERNAL, EXIT_CANCELLED = 0, 1, 2, 3, 130

# Blender's frame limits (MINAFRAME, MAXFRAME): --frame beyond them is refused.
FRAME_MIN, FRAME_MAX = -1_048_574, 1_048_574


class UsageError(StpmError):
    """Bad command-line syntax (exit status 2)."""


def safe_text(text, keep_newlines: bool = False) -> str:
    r"""``text`` with control, format (bidi overrides, zero-width) and line-separator characters escaped.

    For untrusted text the commands print (warnings and names from a scene file, paths): a
    file can then neither move the cursor, retitle or clear the terminal, nor reorder what
    a line shows.  ``\x1b`` prints as ``\x1b``, U+202E as ``\u202e``; ``keep_newlines``
    leaves ``\n`` for multi-line output.
    """
    out = []
    for ch in str(text):
        if ch == "\n" and keep_newlines:
            out.append(ch)
        elif unicodedata.category(ch) in ("Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"):
            o = ord(ch)
            out.append(f"\\x{o:02x}" if o < 0x100 else f"\\u{o:04x}" if o < 0x10000 else f"\\U{o:08x}")
        else:
            out.append(ch)
    return "".join(out)


def finite_float(text: str) -> float:
    """argparse type: a float that is neither NaN nor infinite (``--time-budget nan`` is exit status 2)."""
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from None
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"must be a finite number, got {text!r}")
    return v


finite_float.__name__ = "number"


class CommandParser(argparse.ArgumentParser):
    """argparse that reports a syntax error as one line (:class:`UsageError`) instead of usage + message + exit."""

    def error(self, message):
        raise UsageError(message)


# ----------------------------------------------------------------------------
# The render-settings options of `stpm render` and `stpm compare`
# ----------------------------------------------------------------------------
def _resolution(text: str) -> tuple[int, int]:
    m = re.match(r"^\s*(\d+)\s*[xX]\s*(\d+)\s*$", text)
    if not m or not (1 <= int(m.group(1)) <= 65536 and 1 <= int(m.group(2)) <= 65536):
        raise argparse.ArgumentTypeError(f"must be WxH with integers in [1, 65536], got {text!r}")
    return int(m.group(1)), int(m.group(2))


def _lower_choice(*allowed):
    def conv(text: str) -> str:
        if text.lower() not in allowed:
            raise argparse.ArgumentTypeError(f"must be one of {', '.join(allowed)}, got {text!r}")
        return text.upper()
    conv.__name__ = "choice"
    return conv


def _on_off(text: str) -> bool:
    """A boolean option's value: on / off (also true / false, yes / no, 1 / 0)."""
    t = text.strip().lower()
    if t in ("on", "true", "yes", "1"):
        return True
    if t in ("off", "false", "no", "0"):
        return False
    raise argparse.ArgumentTypeError(f"must be on or off, got {text!r}")


def _option_type(spec):
    """argparse type of a settings option: the kind's syntax (the range is checked by the schema, exit 1)."""
    if spec.kind == "enum":
        return _lower_choice(*(v.lower() for v in spec.values))
    if spec.kind == "int":
        return int
    if spec.kind == "float":
        return finite_float
    if spec.kind == "bool":
        return _on_off
    raise ValueError(f"setting {spec.name!r} of kind {spec.kind!r} has no command-line form")


def add_setting_options(parser, skip: tuple[str, ...] = ()) -> None:
    """Add the RenderSettings options shared by ``render`` and ``compare`` (names fixed by interface.md).

    One option per schema row with a ``flag`` (:data:`stpm_core.settings.RenderSettings.SPECS`):
    its type from the row's kind, its help from the row's help / doc and range.  ``skip``: option
    destinations the caller defines differently (``compare`` sweeps accumulation steps and has
    its own --samples / --resolution).
    """
    from .settings import RenderSettings
    for spec in RenderSettings.SPECS:
        if spec.flag is None or spec.name in skip:
            continue
        kw = {"type": _option_type(spec), "dest": spec.name, "help": spec.help or spec.doc}
        if spec.kind == "enum":
            kw["metavar"] = "{" + ",".join(v.lower() for v in spec.values) + "}"
        else:
            kw["metavar"] = spec.metavar
            kw["help"] += f", {spec.describe()}"
        parser.add_argument(spec.flag, **kw)
    if "resolution" not in skip:
        parser.add_argument("--resolution", type=_resolution, dest="resolution", metavar="WxH",
                            help="image size, W and H integers in [1, 65536] (default: the scene's)")


def _setting_options(skip: tuple[str, ...] = ()) -> tuple:
    """RenderSettings fields that are command-line options (schema rows with a ``flag``)."""
    from .settings import RenderSettings
    return tuple(s.name for s in RenderSettings.SPECS if s.flag is not None and s.name not in skip)


def checked_overrides(args, skip: tuple[str, ...] = ()) -> dict:
    """The settings options the user gave (``args`` from :func:`add_setting_options`), as RenderSettings
    field -> value, checked before any (possibly slow, .blend) loading: SettingsError naming the option."""
    from .settings import RenderSettings
    overrides = {k: getattr(args, k) for k in _setting_options(skip) if getattr(args, k, None) is not None}
    try:
        RenderSettings().replace(**overrides)
    except SettingsError as e:
        raise SettingsError(option_message(str(e), overrides)) from None
    return overrides


def option_message(message: str, overrides: dict) -> str:
    """A SettingsError about an option the user typed, named as typed (``--samples must ...``)."""
    from .settings import RenderSettings
    flags = {s.name: s.flag for s in RenderSettings.SPECS if s.flag is not None}
    for key in overrides:
        if message.startswith(key + " ") and key in flags:
            return flags[key] + message[len(key):]
    return message


# ----------------------------------------------------------------------------
# Scenes: core files and .blend
# ----------------------------------------------------------------------------
def scene_kind(path: Path) -> str:
    """'core' or 'blend' from the suffix, else from the file's first bytes (StpmError if neither)."""
    from .scenefile import SCENE_SUFFIXES
    suffix = path.suffix.lower()
    if suffix in SCENE_SUFFIXES:
        return "core"
    if suffix == ".blend":
        return "blend"
    with open(path, "rb") as f:
        magic = f.read(7)
    if magic[:4] == b"PK\x03\x04":
        return "core"
    if magic == b"BLENDER" or magic[:2] in (b"\x1f\x8b", b"\x28\xb5"):  # plain, gzip, zstd .blend
        return "blend"
    raise StpmError(f"{path.name}: unknown scene file type (expected .stpm, .npz or .blend)")


def settings_from_dict(d: dict | None, source: str):
    """RenderSettings from a settings dict (a .blend's ``scene.stpm``; None: the defaults).

    Unknown keys are the add-on's UI-only ones: ignored.  A bad value raises
    SettingsError prefixed with ``source`` (the file's name).
    """
    from .settings import RenderSettings
    if d is None:
        return RenderSettings()
    known = {f.name for f in fields(RenderSettings)}
    try:
        return RenderSettings.from_dict({k: v for k, v in dict(d).items() if k in known})
    except SettingsError as e:
        raise SettingsError(f"{source} settings: {e}") from None


class stdout_to_stderr:
    """Context manager: point file descriptor 1 at stderr for a while (bpy writes its log straight to fd 1)."""

    def __enter__(self):
        sys.stdout.flush()
        try:
            self._saved = os.dup(1)
            os.dup2(2, 1)
        except OSError:  # no real descriptors (embedded): leave stdout alone
            self._saved = None
        return self

    def __exit__(self, *exc):
        if self._saved is not None:
            sys.stdout.flush()
            os.dup2(self._saved, 1)
            os.close(self._saved)
        return False


def load_any_scene(path, frame: int | None, *, quiet: bool = False, bake: bool = False, reader=None):
    """(Scene, RenderSettings, export seconds) from a core scene file or a .blend.

    A core file holds one frame: asking for another is an error.  A .blend is read in a child
    process (:class:`stpm_core.blend_loader.BlendReader`: a crash of Blender's reader is one
    line; Blender's log goes to stderr, ``quiet`` drops its "Read blend:" line; a Ctrl-C kills
    the child).  ``reader``: an open BlendReader of ``path`` to reuse (a frame range reads the
    file once); else one is opened for this frame.  ``bake``: a .blend's unsupported shader
    inputs are baked first where no bake is cached (``stpm render``; core files: ignored).
    """
    path = Path(path)
    if not path.exists():
        raise StpmError(f"scene file not found: {path}")
    if path.is_dir():
        raise StpmError(f"scene path is a directory, not a file: {path}")
    t0 = time.perf_counter()
    kind = scene_kind(path)
    if kind == "core":
        from .scenefile import load_scene_with_settings
        scene, settings = load_scene_with_settings(path)
        if frame is not None and float(frame) != float(scene.frame):
            raise StpmError(f"{path.name} holds frame {scene.frame:g} only (a core scene file is one frame); "
                            f"cannot render frame {frame}")
        if settings is None:
            settings = settings_from_dict(None, path.name)
    else:
        if reader is not None:
            scene, d = reader.scene(frame)
        else:
            from .blend_loader import load_blend
            scene, d = load_blend(path, frame, bake, quiet=quiet, cancel=CancelFlag.active)
        settings = settings_from_dict(d, path.name)
    return scene, settings, time.perf_counter() - t0


def open_blend_reader(path, *, quiet: bool = False, bake: bool = False):
    """A :class:`stpm_core.blend_loader.BlendReader` of ``path`` polling the command's
    :class:`CancelFlag` (a context manager: use it for every frame of a range)."""
    from .blend_loader import BlendReader
    return BlendReader(path, bake=bake, quiet=quiet, cancel=CancelFlag.active)


# ----------------------------------------------------------------------------
# Memory: refuse an image that cannot fit, before rendering
# ----------------------------------------------------------------------------
# Peak bytes per pixel of one frame, measured (peak RSS of `stpm render` at 2000x1500 minus at
# 100x100, 1 sample): 239 (PHOTON: the film's float32 sums, resolve()'s temporaries, the passes,
# the EXR / PNG writers' copies) and 481 (ACCUMULATION: also a float64 sum and one still's passes).
# Rounded up; photon maps and per-tile buffers come on top (docs/cli.md, "Memory").
BYTES_PER_PIXEL = {"PHOTON": 256, "ACCUMULATION": 512,
                   # 800 measured the same way (8 passes at 1600x1200): float64 sums of the 30 pass
                   # channels twice (whole rounds, the pending round's), the odd / even halves, this
                   # pass's float32 image and the one shown
                   "PROGRESSIVE": 1024}


def available_memory() -> int | None:
    """Bytes of memory available now: /proc/meminfo MemAvailable, else physical memory; None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (OSError, ValueError, AttributeError):
        return None


def image_memory(resolution, method: str = "PHOTON") -> int:
    """Estimated peak bytes of the image buffers of one frame at ``resolution`` (W, H)."""
    w, h = int(resolution[0]), int(resolution[1])
    return w * h * BYTES_PER_PIXEL.get(str(method).upper(), BYTES_PER_PIXEL["ACCUMULATION"])


# Peak bytes per photon of the photon maps, counting one stored photon per emitted one: the 32-byte
# record, the map's decoded working arrays (float64 positions and times, a packed float32 row: 64
# bytes), the kd-tree's indices and the tracer's batch copies.  Rounded up (docs/cli.md, "Memory").
BYTES_PER_PHOTON_ESTIMATE = 128


def photon_memory(settings) -> int:
    """Estimated peak bytes of the photon maps of one render: the photons asked for x
    :data:`BYTES_PER_PHOTON_ESTIMATE` (a global photon can be stored at several bounces: more)."""
    n = int(getattr(settings, "photons_global", 0) or 0) + int(getattr(settings, "photons_caustic", 0) or 0)
    return n * BYTES_PER_PHOTON_ESTIMATE


def check_memory(resolution, method: str, settings=None) -> None:
    """Refuse (StpmError), before rendering, an image whose buffers cannot fit in the memory available;
    with ``settings``, also photon counts whose maps (with the image) cannot fit."""
    need = image_memory(resolution, method)
    avail = available_memory()
    if avail is not None and need > avail:
        w, h = int(resolution[0]), int(resolution[1])
        raise StpmError(f"{w}x{h} needs about {need / 2**30:.1f} GiB of memory for the image buffers, "
                        f"more than the {avail / 2**30:.1f} GiB available: lower --resolution")
    if settings is not None and avail is not None:
        photons = photon_memory(settings)
        if need + photons > avail:
            raise StpmError(f"photons_global {settings.photons_global} + photons_caustic {settings.photons_caustic} "
                            f"need about {photons / 2**30:.1f} GiB of memory for the photon maps "
                            f"({BYTES_PER_PHOTON_ESTIMATE} bytes per photon), more than the "
                            f"{max(avail - need, 0) / 2**30:.1f} GiB available beside the image: lower "
                            "--photons-global / --photons-caustic")


# ----------------------------------------------------------------------------
# Ctrl-C / SIGTERM: the first one cancels cleanly, a second one aborts at once
# ----------------------------------------------------------------------------
class CancelFlag:
    """SIGINT and SIGTERM handling, and the ``cancel() -> bool`` the renderer polls.

    A context manager.  The first signal only sets the flag (so it is safe at any
    moment, even inside ``import bpy`` or a .blend load, where a KeyboardInterrupt
    can crash Blender): the command stops at its next check (the renderer polls it
    per tile and per photon batch; the commands before rendering and before
    committing outputs: :func:`check_cancel`) and exits 130 (143 for SIGTERM).  A
    second signal aborts at once: it removes the temporary output files being
    written and ends the process with ``os._exit``.

    ``stpm_core.cli.main`` installs one for the whole command (``CancelFlag.active``);
    a nested ``with CancelFlag()`` (``stpm compare``) returns that one.  ``err_fd``:
    where the messages go (a descriptor; None = sys.stderr).  ``keep_after_cancel``:
    after a cancel, leave the handler installed on exit (for a process that ends
    right after; a second signal then still aborts with one line).
    """

    active: "CancelFlag | None" = None

    def __init__(self, keep_after_cancel: bool = False):
        self.signum: int | None = None
        self.keep_after_cancel = keep_after_cancel
        self.err_fd: int | None = None
        self._old: dict = {}
        self._outer = None

    @property
    def set(self) -> bool:
        return self.signum is not None

    def __call__(self) -> bool:
        return self.signum is not None

    def exit_status(self) -> int:
        """128 + the signal that cancelled (130 for SIGINT, 143 for SIGTERM)."""
        return 128 + int(self.signum) if self.signum is not None else EXIT_CANCELLED

    def _say(self, text: str) -> None:
        try:
            if self.err_fd is not None:
                os.write(self.err_fd, text.encode())
            else:
                sys.stderr.write(text)
                sys.stderr.flush()
        except (OSError, ValueError, RuntimeError):
            pass

    def _handler(self, signum, frame):
        if self.signum is not None:
            from .imageio import remove_pending_temps
            remove_pending_temps()
            loader = sys.modules.get(__package__ + ".blend_loader")
            if loader is not None:               # a .blend reader process: killed, its folder removed
                loader.kill_children()
            lead = "\n" if getattr(sys.stderr, "isatty", lambda: False)() else ""
            self._say(f"{lead}stpm: aborted\n")
            try:
                sys.stdout.flush()
            except (OSError, ValueError, RuntimeError):
                pass
            os._exit(128 + int(signum))
        self.signum = signum
        lead = "\n" if getattr(sys.stderr, "isatty", lambda: False)() else ""
        what = "Ctrl-C" if signum == signal.SIGINT else signal.Signals(signum).name
        self._say(f"{lead}stpm: cancelling ({what} again to abort)\n")

    def __enter__(self):
        outer = CancelFlag.active
        if outer is not None:
            self._outer = outer
            return outer
        try:
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handler)
        except ValueError:  # not the main thread (embedded use): no handler
            for sig, old in self._old.items():
                signal.signal(sig, old)
            self._old = {}
            return self
        CancelFlag.active = self
        return self

    def __exit__(self, *exc):
        if self._outer is not None:
            return False
        if self.signum is not None and self.keep_after_cancel and CancelFlag.active is self:
            # Cancelled, and the process is about to exit 128 + signum: the handler stays, so
            # a second signal in that window still aborts with one line and 130 / 143 rather
            # than killing the process by the signal's default action.
            CancelFlag.active = None
            return False
        for sig, old in self._old.items():
            signal.signal(sig, old if old is not None else signal.SIG_DFL)
        self._old = {}
        if CancelFlag.active is self:
            CancelFlag.active = None
        return False


def check_cancel(cancel) -> None:
    """Raise RenderCancelled if ``cancel()`` (a :class:`CancelFlag`, or None) says a Ctrl-C came.

    For the steps between those the renderer polls itself (after loading, before
    committing outputs).
    """
    if cancel is not None and cancel():
        raise RenderCancelled("cancelled")
