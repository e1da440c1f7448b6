"""The ``stpm`` command line (console script ``stpm = stpm_core.cli:main``).

    stpm render SCENE [--frame F|A-B] [--output OUT.exr] [--method photon|accumulation]
                [--estimator standard|temporal|kd4d] [--accumulation-steps N]
                [--samples S] [--photons-global N] [--photons-caustic N] [--k K]
                [--temporal-alpha A] [--time-scale S] [--seed S] [--resolution WxH]
                [--stats STATS.json] [--quiet] [--no-bake]
                [--method progressive [--passes N] [--time-limit S] [--noise-threshold T]
                 [--shrink-alpha A] [--pass-offset A]]
    stpm merge PART.exr... [--output OUT.exr] [--stats STATS.json] [--quiet]
    stpm plan SCENE [--frame F] [--json]
    stpm compare SCENE [--frame F] [--output REPORT_DIR] [--reference REF.exr] [--time-budget S]
                 [the settings options of render]

SCENE is a core scene file (``.stpm`` / ``.npz``, see docs/scene-format.md) or
a ``.blend`` (loaded through :mod:`stpm_core.blend_loader`, which needs bpy).
Options not given come from the file's settings (a core file's optional
settings; a .blend's ``scene.stpm``), else the :class:`RenderSettings` defaults.

Exit status: 0 success; 1 a user error (one ``stpm: error: ...`` line on
stderr); 2 bad command-line syntax; 3 an internal error (a bug: please
report); 130 cancelled with Ctrl-C (143 with SIGTERM).  See docs/cli.md.

What ``stpm compare`` (:mod:`stpm_core.compare.command`) shares with these
commands lives in :mod:`stpm_core.command_common`.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import re
import sys
import tempfile
import time
from pathlib import Path

from .colorspaces import working_space_of
from .command_common import (EXIT_CANCELLED, EXIT_ERROR, EXIT_INTERNAL, EXIT_OK, EXIT_USAGE, FRAME_MAX,
                             FRAME_MIN, CancelFlag, CommandParser, UsageError, add_setting_options,
                             check_cancel, check_memory, checked_overrides, load_any_scene, open_blend_reader,
                             option_message, safe_text, scene_kind)
from .errors import RenderCancelled, SceneError, SettingsError, StpmError
from .strata import is_round_end, round_end_after, round_ends_near

__all__ = ["main", "parse_frames", "load_any_scene"]

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
    for f in (a, b):
        if not FRAME_MIN <= f <= FRAME_MAX:
            raise UsageError(f"--frame {f} is outside Blender's frame limits [{FRAME_MIN}, {FRAME_MAX}]")
    if b < a:
        raise UsageError(f"--frame range {text!r} ends before it starts")
    if b - a >= 100_000:
        raise UsageError(f"--frame range {text!r} is longer than 100000 frames")
    return list(range(a, b + 1))


def _build_parser() -> CommandParser:
    p = CommandParser(prog="stpm", description="STPM: time-dependent photon mapping renderer.")
    p.add_argument("--version", action="version", version=f"stpm {_version()}")
    sub = p.add_subparsers(dest="command", metavar="{render,merge,plan,compare}", parser_class=CommandParser)

    r = sub.add_parser("render", help="render a scene to a multilayer EXR and a PNG preview")
    r.add_argument("scene", help="scene file: .stpm / .npz (core) or .blend")
    r.add_argument("--frame", help=f"frame F or range A-B (A..B), integers in [{FRAME_MIN}, {FRAME_MAX}]; "
                   "a range needs a .blend (default: the file's frame)")
    r.add_argument("--output", "-o", metavar="OUT.exr",
                   help="output .exr (default: next to the scene, same stem); "
                   "'#' characters are replaced by the zero-padded frame number")
    add_setting_options(r)
    r.add_argument("--stats", metavar="STATS.json", help="write timings, counts and settings as JSON")
    r.add_argument("--quiet", "-q", action="store_true", help="no progress bar, timing line or Blender log")
    r.add_argument("--no-bake", dest="no_bake", action="store_true",
                   help="a .blend: do not bake the shader inputs the node interpreter cannot evaluate "
                        "(cached bakes are still used; the others use their defaults, named)")

    mg = sub.add_parser("merge", help="join partial results of a progressive render (--pass-offset) into one image")
    mg.add_argument("parts", nargs="+", metavar="PART.exr", help="partial results (stpm render --pass-offset ...)")
    mg.add_argument("--output", "-o", metavar="OUT.exr", required=True, help="the merged multilayer EXR (a PNG "
                    "preview is written beside it)")
    mg.add_argument("--stats", metavar="STATS.json", help="write the merged passes' noise and ranges as JSON")
    mg.add_argument("--quiet", "-q", action="store_true", help="print only the files written")

    pl = sub.add_parser("plan", help="print which effects the scene calls for, and why")
    pl.add_argument("scene")
    pl.add_argument("--frame", help=f"frame F, an integer in [{FRAME_MIN}, {FRAME_MAX}] (default: the file's frame)")
    pl.add_argument("--json", action="store_true", help="print the plan as JSON")

    # `compare` has many options of its own: its parser lives with it (stpm_core.compare.command).
    c = sub.add_parser("compare", add_help=False,
                       help="compare the estimators and the accumulation buffer (REPORT_DIR/report.html + "
                            "report.json); see stpm compare --help")
    c.add_argument("rest", nargs=argparse.REMAINDER)
    return p


def _version() -> str:
    """The installed package's version (pyproject.toml), or 'unknown' when run from a bare checkout."""
    try:
        from importlib.metadata import version
        return version("stpm")
    except Exception:  # noqa: BLE001 -- not installed: no metadata
        return "unknown"


# ----------------------------------------------------------------------------
# Output paths
# ----------------------------------------------------------------------------
def _default_exr(scene_path: Path, frame: int | None, numbered: bool) -> Path:
    """The default output: next to the scene, same stem, ``_NNNN`` when numbered.

    Built directly rather than through a '#' template, so a '#' in the scene's
    own name (``shot #1.stpm``) stays as it is.
    """
    stem = scene_path.with_suffix("")
    return Path(f"{stem}_{frame:04d}.exr") if numbered and frame is not None else Path(f"{stem}.exr")


def _frame_path(template: str, frame: int | None, many: bool) -> Path:
    """Replace a run of '#' by the zero-padded frame; a range without '#' gets ``_NNNN`` before the suffix."""
    if frame is not None and "#" in template:
        return Path(re.sub(r"#+", lambda m: f"{frame:0{len(m.group(0))}d}", template))
    p = Path(template)
    if many and frame is not None:
        return p.with_name(f"{p.stem}_{frame:04d}{p.suffix}")
    return p


def _check_output_path(path: Path, what: str, probed: set | None = None) -> None:
    """Refuse, before any rendering, an output that cannot be written: one line naming the problem.

    ``path`` must not be a directory, and its folder must exist and take a new
    file (probed by creating and removing a hidden file: this also catches
    read-only file systems, which ``os.access`` misses for root).  The folder is
    looked up on disk as given (``p/missing/../x.exr`` needs ``p/missing``, as the
    kernel does), never normalised by its text.  ``probed``: folders already
    probed (a frame range writes many files to one folder).
    """
    if path.is_dir():
        raise StpmError(f"cannot write {what} {path}: it is a directory")
    given = path.absolute().parent           # not normalised: '..' after a missing folder stays
    if not os.path.isdir(given):
        state = "is not a directory" if os.path.lexists(given) else "does not exist"
        missing = _first_missing(given)
        where = f" ({missing} {'is not a directory' if os.path.lexists(missing) else 'does not exist'})" \
            if missing is not None and missing != given else ""
        raise StpmError(f"cannot write {what} {path}: directory {given} {state}{where}")
    parent = Path(os.path.realpath(given))
    if probed is not None and parent in probed:
        return
    try:
        fd, probe = tempfile.mkstemp(prefix=".stpm-probe-", dir=parent)
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise StpmError(f"cannot write {what} {path}: directory {parent} is not writable "
                        f"({e.strerror or e})") from None
    if probed is not None:
        probed.add(parent)


def _first_missing(folder: Path) -> Path | None:
    """The first component of ``folder`` (absolute) that is not a directory on disk, or None."""
    cur = Path(folder.anchor)
    for part in folder.parts[1:]:
        cur = cur / part
        if not os.path.isdir(cur):
            return cur
    return None


def real_target(path: Path) -> Path:
    """``path`` with its folder resolved on disk (symlinks and '..' as the kernel follows them);
    the file name is kept, so a symlinked output is replaced as before.  Temporary files are
    created next to this, in the folder the file really lands in.  A folder missing on disk
    raises OSError (``os.path.realpath`` would otherwise drop ``missing/..`` by its text)."""
    return Path(os.path.realpath(Path(path).absolute().parent, strict=True)) / Path(path).name


def _same_file(a: Path, b: Path) -> bool:
    """Do two paths name the same file (resolved real paths; an existing file also by inode)?"""
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return os.path.realpath(a) == os.path.realpath(b)


def _check_outputs(out_exr: Path, out_png: Path, stats: Path | None, scene_path: Path,
                   probed: set | None = None) -> None:
    """Every output of one frame writable, and no two of them (or the scene) the same file."""
    _check_output_path(out_exr, "output", probed)
    _check_output_path(out_png, "PNG preview", probed)
    if stats is not None:
        _check_output_path(stats, "stats file", probed)
    for p, what in ((out_exr, "output EXR"), (out_png, "PNG preview")):
        if _same_file(p, scene_path):
            raise StpmError(f"the {what} {p} is the scene file itself: choose another --output")
    if stats is not None:
        for p, what in ((out_exr, "output EXR"), (out_png, "PNG preview"), (scene_path, "scene file")):
            if _same_file(stats, p):
                raise StpmError(f"--stats {stats} is the same file as the {what}: choose another name")


# ----------------------------------------------------------------------------
# Subcommands
# ----------------------------------------------------------------------------
def _cmd_render(args) -> int:
    t_start = time.perf_counter()
    scene_path = Path(args.scene)
    frames = parse_frames(args.frame) if args.frame is not None else [None]
    many = len(frames) > 1
    if args.output is not None and not args.output.lower().endswith(".exr"):
        raise UsageError(f"--output must end in .exr, got {args.output!r}")
    if args.output is not None:
        def exr_for(f):
            return _frame_path(args.output, f, many)
    else:  # a .blend frame or a range -> shot_0001.exr (docs/cli.md)
        numbered = many or (frames[0] is not None and scene_path.suffix.lower() == ".blend")

        def exr_for(f):
            return _default_exr(scene_path, f, numbered)

    overrides = checked_overrides(args)
    if not scene_path.exists():  # the first thing to say (before any complaint about outputs)
        raise StpmError(f"scene file not found: {scene_path}")
    # A core scene file holds one frame: a range is refused before anything renders
    if many and scene_path.is_file() and scene_kind(scene_path) == "core":
        scene, _, _ = load_any_scene(scene_path, None)
        raise StpmError(f"{scene_path.name} holds frame {scene.frame:g} only (a core scene file is one frame); "
                        f"cannot render the range {args.frame.strip()}: render a .blend for several frames")
    # Fail fast on outputs that cannot be written, before any loading or rendering
    probed: set = set()
    for frame in frames:
        out_exr = exr_for(frame)
        _check_outputs(out_exr, out_exr.with_suffix(".png"),
                       _frame_path(args.stats, frame, many) if args.stats else None, scene_path, probed)
    # A frame range keeps the baked static geometry from frame to frame while it does not change
    from .raycast import set_persistent_static
    set_persistent_static(many)
    # A .blend is read by one child process for the whole range: opened once (blend_loader)
    reader = open_blend_reader(scene_path, quiet=args.quiet, bake=not getattr(args, "no_bake", False)) \
        if scene_path.is_file() and scene_kind(scene_path) == "blend" else None
    try:
        return _render_frames(args, frames, many, exr_for, overrides, scene_path, t_start, reader)
    finally:
        if reader is not None:
            reader.close()
        set_persistent_static(False)


def _warn_progressive_options(args, overrides: dict, settings) -> None:
    """Warnings for progressive options that do nothing, or do what the user may not expect."""
    given = [f for f, k in (("--passes", "passes"), ("--time-limit", "time_limit"),
                            ("--noise-threshold", "noise_threshold"), ("--shrink-alpha", "shrink_alpha"))
             if k in overrides]
    if settings.method != "PROGRESSIVE" and given:
        _warn(f"{' / '.join(given)} {'has' if len(given) == 1 else 'have'} no effect with --method "
              f"{settings.method.lower()}: they set progressive rendering (--method progressive)")
    # `--time-limit 60` alone stops at the file's pass limit (16 by default) long before 60 s: the
    # render stops at the first stop reached (artist review: 16 passes in 16.8 s at --time-limit 20)
    stops = [f for f, k in (("--time-limit", "time_limit"), ("--noise-threshold", "noise_threshold"))
             if k in overrides and overrides[k]]
    if settings.method == "PROGRESSIVE" and stops and "passes" not in overrides and settings.passes > 0:
        _warn(f"{' / '.join(stops)} without --passes: the render also stops at the file's pass limit "
              f"({settings.passes} passes), whichever comes first; give --passes 0 to render until "
              f"{'it' if len(stops) == 1 else 'they'} alone stop{'s' if len(stops) == 1 else ''} the render")
    per_pass = ("samples", "photons_caustic", "photons_global")
    if settings.method == "PROGRESSIVE" and str(overrides.get("method", "")).upper() == "PROGRESSIVE" \
            and not any(k in overrides for k in per_pass) \
            and (settings.samples > 4 or settings.photons_caustic + settings.photons_global > 400_000):
        _warn(f"every progressive pass traces the file's {settings.samples} samples per pixel and "
              f"{settings.photons_caustic + settings.photons_global:,} photons: many small passes converge "
              "faster (the Final Progressive preset: --samples 1 --photons-caustic 200000 --photons-global 100000 "
              "--k-nearest 20)")


def _warn(line: str) -> None:
    print(f"stpm: warning: {safe_text(line)}", file=sys.stderr, flush=True)


def _warn_frames_outside(scene, frames) -> None:
    """A warning line when frames of the range lie outside the .blend's frame_start..frame_end."""
    from .blend_loader import blend_frame_range
    rng = blend_frame_range(scene)
    if rng is None or frames == [None]:
        return
    outside = [f for f in frames if not rng[0] <= f <= rng[1]]
    if outside:
        which = f"frame {outside[0]}" if len(outside) == 1 else f"{len(outside)} frames ({outside[0]}..{outside[-1]})"
        _warn(f"{which} outside the file's frame range {rng[0]}..{rng[1]} (rendered anyway, as Blender does)")


def _render_frames(args, frames, many, exr_for, overrides, scene_path, t_start, reader=None) -> int:
    """The frame loop of :func:`_cmd_render`: load, render and write each frame.

    ``reader``: a .blend's :class:`~stpm_core.blend_loader.BlendReader` (one child process
    exporting every frame), None for a core file.

    The outputs of a frame (EXR, PNG, stats) are written to temporary files and
    renamed into place together once all are written, so a failure, a kill or a
    Ctrl-C leaves either all of them or none under the final names.
    """
    from .imageio import write_exr, write_json, write_png
    from .progress import ProgressBar
    from .render import render

    cancel = CancelFlag.active
    probed: set = set()
    said: set = set()        # warning lines printed: a frame range prints each once, not once per frame

    def warn_once(line: str) -> None:
        if line not in said:
            said.add(line)
            _warn(line)
    for index, frame in enumerate(frames):
        t_frame = time.perf_counter() if many else t_start
        check_cancel(cancel)

        # -- Scene and settings: file values, then command-line overrides -------------
        scene, settings, export_s = load_any_scene(scene_path, frame, quiet=args.quiet,
                                                   bake=not getattr(args, "no_bake", False), reader=reader)
        if reader is not None and index == len(frames) - 1:
            reader.close()    # the last frame is read: Blender's memory is freed before it renders
        check_cancel(cancel)  # a Ctrl-C while Blender loaded: stop before rendering
        f_out = frame if frame is not None else (int(scene.frame) if float(scene.frame).is_integer() else None)
        out_exr = exr_for(f_out)
        out_png = out_exr.with_suffix(".png")
        stats_path = _frame_path(args.stats, f_out, many) if args.stats else None
        _check_outputs(out_exr, out_png, stats_path, scene_path, probed)
        try:
            settings = settings.replace(**overrides)
        except SettingsError as e:
            raise SettingsError(option_message(str(e), overrides)) from None
        if args.resolution is not None:
            scene.resolution = args.resolution
        partial = getattr(args, "pass_offset", None) is not None    # --pass-offset: write a partial result
        if partial and settings.method != "PROGRESSIVE":
            raise StpmError(f"--pass-offset renders part of a progressive render: it needs --method progressive "
                            f"(the settings say {settings.method.lower()})")
        if partial and settings.passes > 0 and not is_round_end(settings.pass_offset + settings.passes):
            n, a = settings.pass_offset + settings.passes, settings.pass_offset
            counts = ", ".join(str(m - a) for m in round_ends_near(n) if m > a)
            raise StpmError(f"--pass-offset {a} --passes {settings.passes} ends at pass {n}, inside a round of "
                            f"time strata, and a partial result holds whole rounds: with --pass-offset {a} use "
                            f"--passes {counts} (docs/cli.md, \"Splitting one frame between machines\")")
        if index == 0:
            _warn_progressive_options(args, overrides, settings)
            if partial and settings.denoise:
                _warn("denoise is not applied to a partial result (--pass-offset): the merged EXR holds the "
                      "noisy passes; denoise it in Blender's compositor (docs/blender.md, \"Denoising\")")
        check_memory(scene.resolution, settings.method, settings)
        if index == 0:
            if scene_path.suffix.lower() == ".blend" or scene_kind(scene_path) == "blend":
                _warn_frames_outside(scene, frames)
            if settings.method == "ACCUMULATION" and args.estimator not in (None, "STANDARD"):
                _warn(f"--estimator {args.estimator.lower()} has no effect with --method accumulation: "
                      "each still is read with STANDARD")
        meta_warnings = scene.metadata.get("warnings", []) if isinstance(scene.metadata, dict) else []
        for w in meta_warnings if isinstance(meta_warnings, list) else []:
            warn_once(str(w))

        # -- Render, with a progress bar and Ctrl-C cancelling ---------------------------
        bar = ProgressBar(quiet=args.quiet)
        label = f"frame {frame}: " if frame is not None else ""

        def on_pass(_passes, info):
            noise = info.get("noise_p95")
            bar.note(f"{label}pass {info['pass']}: {info['elapsed_s']:.1f} s"
                     + (f", noise {noise:.4f}" if noise is not None and noise < 1e30 else ""))
        # A Render Region: only its pixels are traced, a partial's too (with denoise the whole frame is
        # traced so the denoiser sees real neighbours at the region's edges; a partial is not denoised)
        window = None if settings.denoise and not partial else scene_region(scene.metadata, scene.resolution)
        try:
            result = render(scene, settings, progress=lambda f, m: bar(f, label + m), cancel=cancel,
                            on_pass=on_pass if settings.method == "PROGRESSIVE" else None,
                            scheduled_rounds=partial, window=window)
        finally:
            bar.close()
        if settings.denoise and not partial:     # Blender's Denoise node where bpy runs (docs/blender.md)
            from .blend_loader import denoise_result
            result.warnings.extend(denoise_result(result, scene_path, cancel=cancel))

        # -- Outputs: temporary files, renamed into place together -------------------------
        t_write = time.perf_counter()
        plan = getattr(result, "plan", None) or {}
        stats = dict(result.stats)
        stats["export_s"] = float(export_s) + float(stats.get("export_s", 0.0) or 0.0)
        working = working_space_of(scene.metadata)       # the passes' colour space (Blender 5)
        meta = {"stpm:settings": settings.to_dict(), "stpm:plan": plan,
                "stpm:scene": str(scene_path), "stpm:frame": str(scene.frame if frame is None else frame)}
        if partial and result.sums is not None and result.sums.count == 0:
            a = settings.pass_offset
            why = str(stats.get("progressive", {}).get("stopped_by", "?")).replace("_", " ")
            raise StpmError(f"the render stopped ({why}) before its "
                            f"first round of time strata (passes {a + 1}..{round_end_after(a + 1)}) was done, and a "
                            "partial result holds whole rounds: nothing written; give it more --time-limit, or "
                            "--passes instead")

        def exr(tmp):
            if partial:
                from .partial import scene_fingerprint, scene_hash, settings_hash, write_partial
                write_partial(tmp, result.sums, seed=settings.seed, scene_digest=scene_hash(scene),
                              scene_print=scene_fingerprint(scene), crop=region_crop(scene.metadata),
                              settings_digest=settings_hash(settings), metadata={**meta, "stpm:stats": stats},
                              atomic=False, working=working)
            else:
                write_exr(tmp, result, {**meta, "stpm:stats": stats}, atomic=False, working=working)

        def stats_json(tmp):
            write_json(tmp, stats, atomic=False)

        stats.update({
            "render_wall_s": float(result.stats.get("wall_s", 0.0)),
            "scene": str(scene_path), "frame": scene.frame if frame is None else frame,
            "output_exr": str(out_exr), "output_png": str(out_png),
            "settings": settings.to_dict(), "plan": plan,
            "warnings": list(getattr(result, "warnings", []) or []),
        })
        if not partial:
            region = apply_render_region(result.passes, scene.metadata, stats)
            if region is not None and not args.quiet:
                print(f"{label}render region: {region}", file=sys.stderr)
        elif window is not None and not args.quiet:
            # (the partial's sums hold the whole frame, 0 outside the region; stpm merge crops)
            text = region_passes(None, window, False, (scene.resolution[1], scene.resolution[0]))
            print(f"{label}render region: {text} traced (stpm merge applies it)", file=sys.stderr)
        png_warnings: list = []
        outputs = [(out_exr, exr), (out_png, lambda tmp: write_view_png(tmp, result.passes["Combined"][:, :, :3],
                                                                          scene.metadata, working, png_warnings))]
        if stats_path is not None:
            def timed_stats(tmp):
                stats.update({"write_s": time.perf_counter() - t_write, "wall_s": time.perf_counter() - t_frame})
                stats_json(tmp)
            outputs.append((stats_path, timed_stats))
        _write_together(outputs, cancel)
        if stats_path is None:
            stats.update({"write_s": time.perf_counter() - t_write, "wall_s": time.perf_counter() - t_frame})
        for w in stats["warnings"] + png_warnings:
            warn_once(w)
        if stats.get("progressive") and not args.quiet:
            from .progressive import summary
            print(f"{label}progressive: {summary(stats['progressive'])}", file=sys.stderr)
        if stats.get("adaptive") and not args.quiet:
            a = stats["adaptive"]
            print(f"{label}adaptive sampling: {a['samples_mean']:.1f} samples per pixel on average "
                  f"({a['samples_min']}-{a['samples_max']}, threshold {a['threshold']:g})", file=sys.stderr)
        print(f"wrote {safe_text(out_exr)}" + (" (partial result: join with stpm merge)" if partial else ""))
        print(f"wrote {safe_text(out_png)}")
        if stats_path is not None:
            print(f"wrote {safe_text(stats_path)}")
        sys.stdout.flush()
        if not args.quiet:
            print(f"{label}{stats['wall_s']:.2f} s (render {stats.get('render_s', 0.0):.2f} s, "
                  f"photons {stats.get('photon_trace_s', 0.0) + stats.get('photon_map_build_s', 0.0):.2f} s)",
                  file=sys.stderr)
    return EXIT_OK


def scene_region(metadata, resolution) -> tuple | None:
    """The Render Region of a .blend's export (``metadata.render_region``: [min_x, max_x, min_y,
    max_y] fractions, y from the bottom) in pixels of ``resolution`` (W, H): (x0, y0, x1, y1) with
    rows counted from the *top* (row 0 = top, as the passes), or None when there is none or it
    covers the frame.  Blender's arithmetic: ``(int)(fraction * size)`` in float32, as
    ``addon.engine.border_region``.  A malformed value (a hand-edited scene file) is an error."""
    if not isinstance(metadata, dict) or metadata.get("render_region") is None:
        return None
    box = metadata["render_region"]
    if (not isinstance(box, (list, tuple)) or len(box) != 4
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in box)):
        raise StpmError(f"metadata.render_region must be [min_x, max_x, min_y, max_y] (4 finite numbers), "
                        f"got {safe_text(repr(box)[:80])}")
    import numpy as np
    W, H = int(resolution[0]), int(resolution[1])
    f32 = np.float32

    def edge(frac, size):
        return int(f32(min(max(float(frac), 0.0), 1.0)) * f32(size))
    x0, x1 = edge(box[0], W), edge(box[1], W)
    y0, y1 = edge(box[2], H), edge(box[3], H)
    if x1 <= x0 or y1 <= y0 or (x0, y0, x1, y1) == (0, 0, W, H):
        return None
    return x0, H - y1, x1, H - y0


def apply_render_region(passes: dict, metadata, stats: dict) -> str | None:
    """Make the passes what Blender writes for a Render Region (``blender -b -f``): with Crop to
    Render Region the region alone, else the whole frame with everything outside the region
    blank (0, alpha 0; Depth Blender's background 1e10).  In place; returns a description for the
    log (also ``stats["render_region"]``), None without a region."""
    import numpy as np
    from .film import DEPTH_BACKGROUND
    any_pass = next(iter(passes.values()))
    H, W = any_pass.shape[:2]
    px = scene_region(metadata, (W, H))
    if px is None:
        return None
    x0, r0, x1, r1 = px
    crop = region_crop(metadata)
    stats["render_region"] = {"x0": x0, "x1": x1, "row0": r0, "row1": r1, "crop": crop}
    return region_passes(passes, px, crop)


def region_crop(metadata) -> bool:
    """The scene's *Crop to Render Region* (``metadata.render_region_crop``)."""
    return isinstance(metadata, dict) and bool(metadata.get("render_region_crop", False))


def region_passes(passes: dict | None, px, crop: bool, shape=None) -> str:
    """Blender's output of a Render Region px = (x0, y0, x1, y1) (rows from the top): with ``crop``
    the region alone, else the whole frame blank outside it (0, alpha 0; Depth Blender's background
    1e10); in place (``passes`` None: only the description).  Returns the description for the log;
    ``shape`` (H, W) when there are no passes."""
    import numpy as np
    from .film import DEPTH_BACKGROUND
    H, W = shape if passes is None else next(iter(passes.values())).shape[:2]
    x0, r0, x1, r1 = px
    for name in list(passes or ()):
        a = np.asarray(passes[name])
        if crop:
            passes[name] = np.ascontiguousarray(a[r0:r1, x0:x1])
        else:
            out = np.full_like(a, DEPTH_BACKGROUND if name == "Depth" else 0.0)
            out[r0:r1, x0:x1] = a[r0:r1, x0:x1]
            passes[name] = out
    return (f"columns {x0}..{x1 - 1}, rows {r0}..{r1 - 1} of {W}x{H}"
            + ("" if passes is None else ", cropped" if crop else ", the rest blank"))


def blender_ocio_config() -> Path | None:
    """The OCIO config of the bpy module beside this Python (``bpy/<version>/datafiles/
    colormanagement/config.ocio``: the one the .blend reader's Blender uses), or None."""
    import importlib.util
    try:
        spec = importlib.util.find_spec("bpy")
    except (ImportError, ValueError):
        return None
    for root in (getattr(spec, "submodule_search_locations", None) or []) if spec is not None else []:
        found = sorted(Path(root).glob("*/datafiles/colormanagement/config.ocio"))
        if found:
            return found[-1]
    return None


def write_view_png(path, rgb, metadata, working: str, warnings: list) -> None:
    """The PNG of ``stpm render``: linear ``rgb`` (H, W, 3) through the .blend's colour management
    as Blender writes a PNG (``metadata.view_settings``: display device, view transform such as
    AgX or Filmic, exposure, gamma; Blender's own OCIO config (:func:`blender_ocio_config`), through
    OpenImageIO's ``ociodisplay``), else (a core scene file, no config) the sRGB curve of the clipped values
    (:func:`~stpm_core.imageio.write_png`).  A look or curves the preview cannot apply, or a
    config OpenImageIO cannot read, add a line to ``warnings`` and fall back where needed."""
    import numpy as np

    from .imageio import _oiio_write, write_png
    view = metadata.get("view_settings") if isinstance(metadata, dict) else None
    config = blender_ocio_config() if isinstance(view, dict) else None
    if config is None:
        write_png(path, rgb, atomic=False, working=working)
        return
    import OpenImageIO as oiio
    try:
        exposure, gamma = float(view.get("exposure", 0.0)), float(view.get("gamma", 1.0))
        display, vt = str(view.get("display_device", "sRGB")), str(view.get("view_transform", "Standard"))
        src = str(view.get("working_space", "Linear Rec.709"))
        if not (math.isfinite(exposure) and math.isfinite(gamma) and gamma > 0):
            raise ValueError(f"exposure {exposure} / gamma {gamma}")
        if str(view.get("look", "None")).upper() != "NONE":
            warnings.append(f"PNG preview: the look {safe_text(str(view['look']))!r} is not applied (the EXR is "
                            "linear and unaffected)")
        if view.get("use_curve_mapping"):
            warnings.append("PNG preview: Color Management curves are not applied (the EXR is linear and unaffected)")
        lin = np.ascontiguousarray(np.nan_to_num(np.asarray(rgb, np.float32)[:, :, :3], nan=0.0, posinf=0.0)
                                   * np.float32(2.0 ** exposure))
        H, W = lin.shape[:2]
        buf = oiio.ImageBuf(oiio.ImageSpec(W, H, 3, oiio.FLOAT))
        buf.set_pixels(oiio.ROI(0, W, 0, H), lin)
        out = oiio.ImageBufAlgo.ociodisplay(buf, display, vt, src, "", False, "", "", str(config))
        if out.has_error:
            raise ValueError(out.geterror().splitlines()[0] if out.geterror() else "ociodisplay failed")
        v = np.clip(out.get_pixels(oiio.FLOAT).reshape(H, W, 3), 0.0, 1.0)
        if gamma != 1.0:
            v = v ** (1.0 / gamma)
    except Exception as e:  # noqa: BLE001 -- a preview never fails a render: fall back to sRGB
        warnings.append(f"PNG preview: the file's view transform could not be applied ({safe_text(str(e))[:120]}): "
                        "written with the sRGB curve (the EXR is linear and unaffected)")
        write_png(path, rgb, atomic=False, working=working)
        return
    spec = oiio.ImageSpec(W, H, 3, oiio.UINT8)
    spec.attribute("oiio:ColorSpace", display)
    _oiio_write(Path(path), spec, np.ascontiguousarray(np.round(v * 255.0).astype(np.uint8)), f"PNG {path}")


def _write_together(outputs, cancel) -> None:
    """Write each (path, write(tmp)) of ``outputs`` to a temporary file beside the path's real target
    (folders resolved on disk), in order, then rename them all into place: a failure, a kill or a
    Ctrl-C before the renames leaves none of them under their final names."""
    from .imageio import atomic_output, commit_temp, discard_temp
    staged: list[tuple[Path, Path]] = []
    try:
        for path, write in outputs:
            real = real_target(path)
            with atomic_output(real, commit=False) as tmp:
                write(tmp)
            staged.append((tmp, real))
        check_cancel(cancel)  # a Ctrl-C while writing: none of the outputs
        while staged:
            commit_temp(*staged[0])
            staged.pop(0)
    finally:
        for tmp, _ in staged:
            discard_temp(tmp)


def _cmd_merge(args) -> int:
    """``stpm merge``: partial results of one progressive render -> the image one process would have made."""
    from .imageio import write_exr, write_json, write_png
    from .partial import merge
    from .progressive import flip_visible_fraction, noise_estimate, summary
    if not args.output.lower().endswith(".exr"):
        raise UsageError(f"--output must end in .exr, got {args.output!r}")
    out_exr = Path(args.output)
    out_png = out_exr.with_suffix(".png")
    stats_path = Path(args.stats) if args.stats else None
    for p in args.parts:
        if not Path(p).exists():
            raise StpmError(f"partial result not found: {p}")
    for p, what in ((out_exr, "output"), (out_png, "PNG preview")) + (((stats_path, "stats file"),) if stats_path else ()):
        _check_output_path(p, what)
        for part in args.parts:
            if _same_file(p, Path(part)):
                raise StpmError(f"the {what} {p} is the partial result {part} itself: choose another --output")
    check_cancel(CancelFlag.active)
    sums, head = merge(args.parts)
    if head.get("scene_rounding"):
        _warn(f"{', '.join(head['scene_rounding'])}: the scene was exported with float values differing in the "
              "last bits from the first partial's (Blender's modifiers, e.g. Bevel UVs, are not bit-reproducible): "
              "merged; the image is not bit-equal to one process's")
    if sums.first != 1:
        _warn(f"the partial results hold passes {sums.first}..{sums.end - 1}: passes 1..{sums.first - 1} are "
              "missing (the image is right but noisier than one of passes 1..)")
    noise = noise_estimate(sums)
    info = {"passes": sums.count, "pass_first": sums.first, "pass_end": sums.end, "stopped_by": "merge",
            "noise_p95": noise["noise_p95"] if noise["noise_p95"] < 1e300 else None,
            "noise_mean": noise["noise_mean"] if noise["noise_mean"] < 1e300 else None,
            "noise_flip_visible": flip_visible_fraction(sums), "parts": [str(p) for p in args.parts],
            "seed": head["seed"], "scene_hash": head["scene_hash"], "settings_hash": head["settings_hash"]}
    passes = sums.image()
    if head.get("region") is not None:
        # the partials traced a Render Region: the merged image as stpm render writes it (cropped or blank)
        region = region_passes(passes, head["region"], head["region_crop"])
        info["render_region"] = region
        if not args.quiet:
            print(f"render region: {region}", file=sys.stderr)
    working = head["working_space"]
    meta = {**head.get("provenance", {}), "stpm:progressive": info}
    outputs = [(out_exr, lambda tmp: write_exr(tmp, passes, meta, atomic=False, working=working)),
               (out_png, lambda tmp: write_png(tmp, passes["Combined"][:, :, :3], atomic=False, working=working))]
    if stats_path is not None:
        outputs.append((stats_path, lambda tmp: write_json(tmp, {"progressive": info}, atomic=False)))
    _write_together(outputs, CancelFlag.active)
    if not args.quiet:
        n_parts = len(args.parts)
        print(f"merged {n_parts} partial result{'' if n_parts == 1 else 's'}: "
              f"{summary({**info, 'kernel_radius_scale': None})}",
              file=sys.stderr)
    print(f"wrote {safe_text(out_exr)}")
    print(f"wrote {safe_text(out_png)}")
    if stats_path is not None:
        print(f"wrote {safe_text(stats_path)}")
    return EXIT_OK


def _cmd_plan(args) -> int:
    from .plan import format_plan, make_plan
    frames = parse_frames(args.frame) if args.frame is not None else [None]
    if len(frames) > 1:
        raise UsageError("stpm plan takes one frame, not a range")
    scene, settings, _ = load_any_scene(args.scene, frames[0])
    check_cancel(CancelFlag.active)
    plan = make_plan(scene, settings)
    check_cancel(CancelFlag.active)         # a signal during the plan's probe: no plan printed, 130 / 143
    if args.json:
        print(json.dumps(plan, indent=2))
    else:
        print(safe_text(format_plan(plan), keep_newlines=True))
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
    """Run the CLI; returns (and, as a console script, exits with) the status code.

    SIGINT / SIGTERM are handled from the start (:class:`CancelFlag`), so a
    Ctrl-C at any moment, loading included, ends with one line and status 130.
    """
    own_process = argv is None  # the console script: the process ends when this returns
    argv = list(sys.argv[1:] if argv is None else argv)
    with CancelFlag(keep_after_cancel=own_process) as cancel:
        status = _main(argv, cancel)
    if own_process and cancel.set:
        _end_cancelled_process(status)
    return status


def _end_cancelled_process(status: int) -> None:
    """End a cancelled ``stpm`` process now, with ``status``.

    Python's own shutdown puts the default signal actions back before it tears
    the modules down, so a second Ctrl-C in that window would kill the process by
    the signal (status -2) without a word.  The exit handlers (reader processes
    and temporary folders) run here, with STPM's handler still installed, then
    the process ends.
    """
    import atexit
    try:
        atexit._run_exitfuncs()
    finally:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError, RuntimeError):
                pass
        os._exit(status)


def _main(argv: list[str], cancel: CancelFlag) -> int:
    command = argv[0] if argv and argv[0] in ("render", "merge", "plan", "compare") else ""
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
        return {"render": _cmd_render, "merge": _cmd_merge, "plan": _cmd_plan,
                "compare": _cmd_compare}[args.command](args)
    except UsageError as e:
        print(safe_text(f"stpm: error: {e} (see stpm {command} --help)".replace("  ", " ")), file=sys.stderr)
        return EXIT_USAGE
    except RenderCancelled:
        print("stpm: render cancelled" if command in ("render", "compare") else "stpm: cancelled",
              file=sys.stderr)
        return cancel.exit_status()
    except KeyboardInterrupt:  # a SIGINT with no handler (not the main thread)
        print("stpm: aborted", file=sys.stderr)
        return EXIT_CANCELLED
    except (StpmError, SceneError) as e:
        print(f"stpm: error: {safe_text(str(e).splitlines()[0] if str(e) else type(e).__name__)}", file=sys.stderr)
        return EXIT_ERROR
    except OSError as e:
        print(f"stpm: error: {safe_text(_os_error_line(e))}", file=sys.stderr)
        return EXIT_ERROR
    except SystemExit as e:  # --help / --version inside argparse
        return int(e.code or 0) if isinstance(e.code, int) else EXIT_OK
    except Exception as e:  # a bug in STPM: one line, unless STPM_DEBUG asks for the traceback
        if os.environ.get("STPM_DEBUG"):
            raise
        line = str(e).splitlines()[0] if str(e) else ""
        print(f"stpm: internal error: {type(e).__name__}: {safe_text(line)} (please report this bug; "
              "STPM_DEBUG=1 shows the traceback)", file=sys.stderr)
        return EXIT_INTERNAL


if __name__ == "__main__":
    sys.exit(main())
