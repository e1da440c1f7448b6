"""The ``stpm`` command line (console script ``stpm = stpm_core.cli:main``).

    stpm render SCENE [--frame F|A-B] [--output OUT.exr] [--method photon|accumulation]
                [--estimator standard|temporal|kd4d] [--accumulation-steps N]
                [--samples S] [--photons-global N] [--photons-caustic N] [--k K]
                [--temporal-alpha A] [--time-scale S] [--seed S] [--resolution WxH]
                [--stats STATS.json] [--quiet]
    stpm plan SCENE [--frame F] [--json]
    stpm compare SCENE [--frame F] [--output REPORT_DIR] [--reference REF.exr] [--time-budget S]
                 [the settings options of render]

SCENE is a core scene file (``.stpm`` / ``.npz``, see docs/scene-format.md) or
a ``.blend`` (loaded through ``addon.batch.load_blend``, which needs bpy).
Options not given come from the file's settings (a core file's optional
settings; a .blend's ``scene.stpm``), else the :class:`RenderSettings` defaults.

Exit status: 0 success; 1 a user error (one ``stpm: error: ...`` line on
stderr); 2 bad command-line syntax; 3 an internal error (a bug: please
report); 130 cancelled with Ctrl-C.  See docs/cli.md.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import sys
import time
from dataclasses import fields
from pathlib import Path

from .errors import RenderCancelled, SceneError, SettingsError, StpmError

__all__ = ["main", "parse_frames", "load_any_scene"]

EXIT_OK, EXIT_ERROR, EXIT_USAGE, EXIT_INTERNAL, EXIT_CANCELLED = 0, 1, 2, 3, 130


class UsageError(StpmError):
    """Bad command-line syntax (exit status 2)."""


class _Parser(argparse.ArgumentParser):
    """argparse that reports a syntax error as one line instead of usage + message + exit."""

    def error(self, message):
        raise UsageError(message)


# ----------------------------------------------------------------------------
# Argument parsing helpers
# ----------------------------------------------------------------------------
_FRAMES = re.compile(r"^\s*(-?\d+)\s*(?:(?:-|\.\.)\s*(-?\d+))?\s*$")


def parse_frames(text: str) -> list[int]:
    """``"5"`` -> [5]; ``"1-4"`` or ``"1..4"`` -> [1, 2, 3, 4] (negative frames allowed: ``"-2..2"``)."""
    m = _FRAMES.match(text or "")
    if not m:
        raise UsageError(f"--frame must be F or A-B with integer frames, got {text!r}")
    a = int(m.group(1))
    b = int(m.group(2)) if m.group(2) is not None else a
    if b < a:
        raise UsageError(f"--frame range {text!r} ends before it starts")
    if b - a >= 100_000:
        raise UsageError(f"--frame range {text!r} is longer than 100000 frames")
    return list(range(a, b + 1))


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


def _build_parser() -> _Parser:
    p = _Parser(prog="stpm", description="STPM: time-dependent photon mapping renderer.")
    sub = p.add_subparsers(dest="command", metavar="{render,plan,compare}", parser_class=_Parser)

    r = sub.add_parser("render", help="render a scene to a multilayer EXR and a PNG preview")
    r.add_argument("scene", help="scene file: .stpm / .npz (core) or .blend")
    r.add_argument("--frame", help="frame F or range A-B (default: the file's frame)")
    r.add_argument("--output", "-o", help="output .exr (default: next to the scene, same stem); "
                   "'#' characters are replaced by the zero-padded frame number")
    _add_setting_options(r)
    r.add_argument("--stats", metavar="STATS.json", help="write timings, counts and settings as JSON")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress bar")

    pl = sub.add_parser("plan", help="print which effects the scene calls for, and why")
    pl.add_argument("scene")
    pl.add_argument("--frame", help="frame F (default: the file's frame)")
    pl.add_argument("--json", action="store_true", help="print the plan as JSON")

    # `compare` has many options of its own: its parser lives with it (stpm_core.compare.command).
    c = sub.add_parser("compare", add_help=False,
                       help="compare the estimators and the accumulation buffer (REPORT_DIR/report.html + "
                            "report.json); see stpm compare --help")
    c.add_argument("rest", nargs=argparse.REMAINDER)
    return p


def _add_setting_options(parser, skip: tuple[str, ...] = ()) -> None:
    """The RenderSettings options shared by ``render`` and ``compare`` (names fixed by interface.md).

    ``skip``: option destinations the caller defines differently (``compare`` sweeps
    accumulation steps and has its own --samples / --resolution).
    """
    add = parser.add_argument

    def opt(*names, **kw):
        if kw.get("dest", names[0].lstrip("-")) not in skip:
            add(*names, **kw)
    opt("--method", dest="method", type=_lower_choice("photon", "accumulation"), metavar="{photon,accumulation}")
    opt("--estimator", dest="estimator", type=_lower_choice("standard", "temporal", "kd4d"),
                        metavar="{standard,temporal,kd4d}")
    opt("--accumulation-steps", type=int, dest="accumulation_steps", metavar="N")
    opt("--samples", type=int, dest="samples", metavar="S")
    opt("--photons-global", type=int, dest="photons_global", metavar="N")
    opt("--photons-caustic", type=int, dest="photons_caustic", metavar="N")
    opt("--k", type=int, dest="k_nearest", metavar="K")
    opt("--temporal-alpha", type=float, dest="temporal_alpha", metavar="A")
    opt("--time-scale", type=float, dest="time_scale", metavar="S")
    opt("--seed", type=int, dest="seed", metavar="S")
    opt("--resolution", type=_resolution, dest="resolution", metavar="WxH")


# Command-line option -> RenderSettings field (only the ones the user gave override).
_SETTING_OPTIONS = ("method", "estimator", "accumulation_steps", "samples", "photons_global",
                    "photons_caustic", "k_nearest", "temporal_alpha", "time_scale", "seed")
_OPTION_FLAGS = {"k_nearest": "--k"}


# ----------------------------------------------------------------------------
# Scenes: core files and .blend
# ----------------------------------------------------------------------------
def _scene_kind(path: Path) -> str:
    """'core' or 'blend' from the suffix, else from the file's first bytes."""
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


def _settings_from_dict(d: dict | None, source: str):
    """RenderSettings from a settings dict (unknown keys are the add-on's UI-only ones: ignored)."""
    from .settings import RenderSettings
    if d is None:
        return RenderSettings()
    known = {f.name for f in fields(RenderSettings)}
    try:
        return RenderSettings.from_dict({k: v for k, v in dict(d).items() if k in known})
    except SettingsError as e:
        raise SettingsError(f"{source} settings: {e}") from None


class _stdout_to_stderr:
    """Point file descriptor 1 at stderr for a while (bpy writes its log straight to fd 1)."""

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


def load_any_scene(path, frame: int | None):
    """(Scene, RenderSettings, export seconds) from a core scene file or a .blend.

    A core file holds one frame: asking for another is an error.  A .blend is
    loaded through ``addon.batch.load_blend(path, frame)`` (bpy, imported lazily).
    """
    path = Path(path)
    if not path.exists():
        raise StpmError(f"scene file not found: {path}")
    if path.is_dir():
        raise StpmError(f"scene path is a directory, not a file: {path}")
    t0 = time.perf_counter()
    kind = _scene_kind(path)
    if kind == "core":
        from .scenefile import load_scene_with_settings
        scene, settings = load_scene_with_settings(path)
        if frame is not None and float(frame) != float(scene.frame):
            raise StpmError(f"{path.name} holds frame {scene.frame:g} only (a core scene file is one frame); "
                            f"cannot render frame {frame}")
        if settings is None:
            settings = _settings_from_dict(None, path.name)
    else:
        try:
            from addon import batch  # bpy lives only in addon/
        except ImportError as e:
            raise StpmError(f"cannot load {path.name}: .blend files need Blender's bpy module and "
                            f"addon.batch ({e}); install the 'test' extra or export a .stpm scene") from None
        with _stdout_to_stderr():  # Blender's own log lines must not pollute stdout (plan --json)
            scene, d = batch.load_blend(str(path), frame)
        settings = _settings_from_dict(d, path.name)
    return scene, settings, time.perf_counter() - t0


def _default_output(scene_path: Path, frame: int | None, many: bool) -> str:
    stem = scene_path.with_suffix("")
    return f"{stem}_####.exr" if many or (frame is not None and scene_path.suffix.lower() == ".blend") \
        else f"{stem}.exr"


def _frame_path(template: str, frame: int | None, many: bool) -> Path:
    """Replace a run of '#' by the zero-padded frame; a range without '#' gets ``_NNNN`` before the suffix."""
    if frame is not None and "#" in template:
        return Path(re.sub(r"#+", lambda m: f"{frame:0{len(m.group(0))}d}", template))
    p = Path(template)
    if many and frame is not None:
        return p.with_name(f"{p.stem}_{frame:04d}{p.suffix}")
    return p


def _checked_overrides(args, skip: tuple[str, ...] = ()) -> dict:
    """The settings options the user gave, checked before any (possibly slow, .blend) loading."""
    from .settings import RenderSettings
    overrides = {k: getattr(args, k) for k in _SETTING_OPTIONS
                 if k not in skip and getattr(args, k, None) is not None}
    try:
        RenderSettings().replace(**overrides)
    except SettingsError as e:
        raise SettingsError(_option_message(str(e), overrides)) from None
    return overrides


def _option_message(message: str, overrides: dict) -> str:
    """A SettingsError about an option the user typed, named as typed (``--samples must ...``)."""
    for key in overrides:
        if message.startswith(key + " "):
            flag = _OPTION_FLAGS.get(key, "--" + key.replace("_", "-"))
            return flag + message[len(key):]
    return message


def _check_writable_dir(path: Path, what: str) -> None:
    parent = path.resolve().parent
    if not parent.is_dir():
        raise StpmError(f"cannot write {what} {path}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK):
        raise StpmError(f"cannot write {what} {path}: directory {parent} is not writable")


# ----------------------------------------------------------------------------
# Ctrl-C: first press cancels the render cleanly, a second one aborts
# ----------------------------------------------------------------------------
class _CancelFlag:
    def __init__(self):
        self.set = False
        self._old = None

    def __call__(self) -> bool:
        return self.set

    def _handler(self, signum, frame):
        if self.set:
            raise KeyboardInterrupt
        self.set = True
        print("\nstpm: cancelling (Ctrl-C again to abort)", file=sys.stderr, flush=True)

    def __enter__(self):
        try:
            self._old = signal.signal(signal.SIGINT, self._handler)
        except ValueError:  # not the main thread (embedded use): no handler
            self._old = None
        return self

    def __exit__(self, *exc):
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
        return False


# ----------------------------------------------------------------------------
# Subcommands
# ----------------------------------------------------------------------------
def _cmd_render(args) -> int:
    t_start = time.perf_counter()
    scene_path = Path(args.scene)
    frames = parse_frames(args.frame) if args.frame is not None else [None]
    many = len(frames) > 1
    template = args.output or _default_output(scene_path, frames[0], many)
    if not template.lower().endswith(".exr"):
        raise UsageError(f"--output must end in .exr, got {template!r}")

    overrides = _checked_overrides(args)
    # A frame range keeps the baked static geometry from frame to frame while it does not change
    from .raycast import set_persistent_static
    set_persistent_static(many)
    try:
        return _render_frames(args, frames, many, template, overrides, scene_path, t_start)
    finally:
        set_persistent_static(False)


def _render_frames(args, frames, many, template, overrides, scene_path, t_start) -> int:
    """The frame loop of :func:`_cmd_render`: load, render and write each frame."""
    from .imageio import write_exr, write_png
    from .progress import ProgressBar
    from .render import render

    for frame in frames:
        t_frame = time.perf_counter() if many else t_start
        # Fail fast on an unwritable output folder, before any loading or rendering
        _check_writable_dir(_frame_path(template, frame, many), "output")
        if args.stats:
            _check_writable_dir(_frame_path(args.stats, frame, many), "stats")

        # -- Scene and settings: file values, then command-line overrides -------------
        scene, settings, export_s = load_any_scene(scene_path, frame)
        f_out = frame if frame is not None else (int(scene.frame) if float(scene.frame).is_integer() else None)
        out_exr = _frame_path(template, f_out, many)
        out_png = out_exr.with_suffix(".png")
        stats_path = _frame_path(args.stats, f_out, many) if args.stats else None
        try:
            settings = settings.replace(**overrides)
        except SettingsError as e:
            raise SettingsError(_option_message(str(e), overrides)) from None
        if args.resolution is not None:
            scene.resolution = args.resolution
        for w in scene.metadata.get("warnings", []) if isinstance(scene.metadata, dict) else []:
            print(f"stpm: warning: {w}", file=sys.stderr)

        # -- Render, with a progress bar and Ctrl-C cancelling ---------------------------
        bar = ProgressBar(quiet=args.quiet)
        label = f"frame {frame}: " if frame is not None else ""
        with _CancelFlag() as cancel:
            try:
                result = render(scene, settings, progress=lambda f, m: bar(f, label + m), cancel=cancel)
            finally:
                bar.close()

        # -- Outputs: EXR, PNG preview, stats ---------------------------------------------
        t_write = time.perf_counter()
        plan = getattr(result, "plan", None) or {}
        stats = dict(result.stats)
        stats["export_s"] = float(export_s) + float(stats.get("export_s", 0.0) or 0.0)
        meta = {"stpm:settings": settings.to_dict(), "stpm:plan": plan,
                "stpm:scene": str(scene_path), "stpm:frame": str(scene.frame if frame is None else frame)}
        write_exr(out_exr, result, {**meta, "stpm:stats": stats})
        write_png(out_png, result.passes["Combined"][:, :, :3])
        stats.update({
            "render_wall_s": float(result.stats.get("wall_s", 0.0)),
            "write_s": time.perf_counter() - t_write,
            "wall_s": time.perf_counter() - t_frame,
            "scene": str(scene_path), "frame": scene.frame if frame is None else frame,
            "output_exr": str(out_exr), "output_png": str(out_png),
            "settings": settings.to_dict(), "plan": plan,
            "warnings": list(getattr(result, "warnings", []) or []),
        })
        for w in stats["warnings"]:
            print(f"stpm: warning: {w}", file=sys.stderr)
        print(f"wrote {out_exr}")
        print(f"wrote {out_png}")
        if stats_path is not None:
            from .imageio import _json_default
            stats_path.write_text(json.dumps(stats, indent=2, default=_json_default) + "\n")
            print(f"wrote {stats_path}")
        if not args.quiet:
            print(f"{label}{stats['wall_s']:.2f} s (render {stats.get('render_s', 0.0):.2f} s, "
                  f"photons {stats.get('photon_trace_s', 0.0) + stats.get('photon_map_build_s', 0.0):.2f} s)",
                  file=sys.stderr)
    return EXIT_OK


def _cmd_plan(args) -> int:
    from .plan import format_plan, make_plan
    frames = parse_frames(args.frame) if args.frame is not None else [None]
    if len(frames) > 1:
        raise UsageError("stpm plan takes one frame, not a range")
    scene, settings, _ = load_any_scene(args.scene, frames[0])
    plan = make_plan(scene, settings)
    if args.json:
        print(json.dumps(plan, indent=2))
    else:
        print(format_plan(plan))
    return EXIT_OK


def _cmd_compare(args) -> int:
    """``stpm compare``: hand the arguments to stpm_core.compare.command (report.html + report.json)."""
    from .compare.command import main as compare_main
    return compare_main(args.rest)


# ----------------------------------------------------------------------------
# Entry point
# ----------------------------------------------------------------------------
def _os_error_line(e: OSError) -> str:
    what = e.strerror or str(e)
    return f"{what}: {e.filename}" if getattr(e, "filename", None) else what


def main(argv: list[str] | None = None) -> int:
    """Run the CLI; returns (and, as a console script, exits with) the status code."""
    argv = list(sys.argv[1:] if argv is None else argv)
    try:
        parser = _build_parser()
        if argv[:1] == ["compare"]:
            # Everything after `compare` belongs to its own parser (argparse's REMAINDER
            # would not take a leading option such as --help).
            return _cmd_compare(argparse.Namespace(rest=argv[1:]))
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return EXIT_USAGE
        command = {"render": _cmd_render, "plan": _cmd_plan, "compare": _cmd_compare}[args.command]
        return command(args)
    except UsageError as e:
        command = argv[0] if argv and argv[0] in ("render", "plan", "compare") else ""
        print(f"stpm: error: {e} (see stpm {command} --help)".replace("  ", " "), file=sys.stderr)
        return EXIT_USAGE
    except RenderCancelled:
        print("stpm: render cancelled", file=sys.stderr)
        return EXIT_CANCELLED
    except KeyboardInterrupt:
        print("stpm: aborted", file=sys.stderr)
        return EXIT_CANCELLED
    except (StpmError, SceneError) as e:
        print(f"stpm: error: {str(e).splitlines()[0] if str(e) else type(e).__name__}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as e:
        print(f"stpm: error: {_os_error_line(e)}", file=sys.stderr)
        return EXIT_ERROR
    except SystemExit as e:  # --help inside argparse
        return int(e.code or 0) if isinstance(e.code, int) else EXIT_OK
    except Exception as e:  # a bug in STPM: one line, unless STPM_DEBUG asks for the traceback
        if os.environ.get("STPM_DEBUG"):
            raise
        line = str(e).splitlines()[0] if str(e) else ""
        print(f"stpm: internal error: {type(e).__name__}: {line} (please report this bug; "
              "STPM_DEBUG=1 shows the traceback)", file=sys.stderr)
        return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
