"""``stpm compare SCENE`` on the command line (``stpm_core.cli`` hands it the arguments after ``compare``).

    stpm compare SCENE [--frame F] [--output REPORT_DIR] [--reference REF.exr]
                 [--time-budget SECONDS] [--photon-budgets 1,4,16,4:4,16:4] [--k-exponent E]
                 [--accumulation-steps 1,2,4,8,16,32] [--estimators standard,temporal,kd4d]
                 [--resolution WxH] [--samples S] [--reference-method accumulation|temporal|kd4d]
                 [--reference-steps N] [--reference-photons F] [--reference-samples F]
                 [--cache-dir DIR] [--no-cache] [--quiet]

Writes REPORT_DIR/report.html and REPORT_DIR/report.json (default REPORT_DIR:
``<scene stem>_compare`` next to the scene) and prints where, with the headline
speed-up, on stdout.  A progress bar goes to stderr.

What it shares with ``stpm render`` (the settings options, scene loading, the
memory check, Ctrl-C handling, :class:`UsageError`) comes from
:mod:`stpm_core.command_common`; this module does not import ``stpm_core.cli``.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from ..command_common import (EXIT_OK, FRAME_MAX, FRAME_MIN, CancelFlag, CommandParser, UsageError,
                              add_setting_options, check_cancel, check_memory, checked_overrides, finite_float,
                              load_any_scene, safe_text)
from ..errors import StpmError
from .reference import REFERENCE_FACTORS, REFERENCE_METHOD, REFERENCE_METHODS, REFERENCE_STEPS
from .run import run_compare
from .sweep import (DEFAULT_ACCUMULATION_STEPS, DEFAULT_PHOTON_BUDGETS, DEFAULT_PROGRESSIVE_PASSES, PHOTON_ESTIMATORS,
                    parse_budget)

__all__ = ["main", "build_parser", "K_EXPONENT_MAX"]

# --k-exponent's range: k = f x k_file x B^E; E = 1 already keeps the look-up radius fixed as
# photons grow (docs/compare.md, "k with the budget"), so E above 2 only makes k explode.
K_EXPONENT_MAX = 2.0


def _number_list(kind):
    def conv(text: str):
        try:
            vals = [kind(v) for v in text.replace(" ", "").split(",") if v]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of numbers, got {text!r}") from None
        if not vals or any(v <= 0 for v in vals):
            raise argparse.ArgumentTypeError(f"expected positive numbers, got {text!r}")
        return vals
    return conv


def _budgets(text: str):
    try:
        return [parse_budget(v) for v in text.replace(" ", "").split(",") if v] or parse_budget("")
    except StpmError as e:
        raise argparse.ArgumentTypeError(str(e)) from None


def _estimators(text: str):
    vals = [v.upper() for v in text.replace(" ", "").split(",") if v]
    bad = [v for v in vals if v not in PHOTON_ESTIMATORS]
    if not vals or bad:
        raise argparse.ArgumentTypeError(f"estimators are standard, temporal, kd4d; got {text!r}")
    return vals


def _resolution(text: str):
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WxH, e.g. 320x240, got {text!r}") from None
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"resolution must be positive, got {text!r}")
    return w, h


def build_parser() -> argparse.ArgumentParser:
    p = CommandParser(prog="stpm compare",
                description="Compare STANDARD, TEMPORAL and KD4D photon estimates with the accumulation "
                            "buffer: wall time and error against a reference; writes report.html and "
                            "report.json.")
    p.add_argument("scene", help="scene file: .stpm / .npz (core) or .blend")
    p.add_argument("--frame", type=int, help="frame (default: the file's)")
    p.add_argument("--output", "-o", metavar="REPORT_DIR",
                   help="report directory (default: <scene stem>_compare next to the scene)")
    p.add_argument("--reference", metavar="REF.exr",
                   help="reference image (its Combined pass); default: computed and cached")
    p.add_argument("--time-budget", type=finite_float, dest="time_budget", metavar="SECONDS",
                   help="stop starting runs once the sweep has taken this long (the report notes what was skipped); "
                        "not counted: the reference computed first (unless --reference or cached) and the run "
                        "in flight when it runs out")
    p.add_argument("--photon-budgets", type=_budgets, dest="photon_budgets", metavar="B[:S[:K]],...",
                   default=list(DEFAULT_PHOTON_BUDGETS),
                   help="budgets of the photon-estimator runs: photons x B (and samples x S, k x K) of the file's "
                        f"(default {','.join(f'{b:g}:{s:g}' if s != 1 else f'{b:g}' for b, s in DEFAULT_PHOTON_BUDGETS)})")
    p.add_argument("--k-exponent", type=finite_float, dest="k_exponent", default=0.0, metavar="E",
                   help="photon runs use k x B^E (B = their photon multiple; default 0: the file's k)")
    p.add_argument("--accumulation-steps", type=_number_list(int), dest="accumulation_steps", metavar="N,N,...",
                   default=list(DEFAULT_ACCUMULATION_STEPS),
                   help=f"accumulation-buffer instants (default {','.join(map(str, DEFAULT_ACCUMULATION_STEPS))})")
    p.add_argument("--estimators", type=_estimators, default=list(PHOTON_ESTIMATORS),
                   metavar="standard,temporal,kd4d", help="photon estimators to sweep (default all three)")
    p.add_argument("--progressive-passes", type=int, dest="progressive_passes", default=DEFAULT_PROGRESSIVE_PASSES,
                   metavar="P", help="add the progressive method's curve (P passes, measured pass by pass) and the "
                   f"SPPM baseline (one shutter instant per pass); 0: neither (default {DEFAULT_PROGRESSIVE_PASSES})")
    p.add_argument("--resolution", type=_resolution, metavar="WxH", help="override the scene's resolution")
    p.add_argument("--samples", type=int, metavar="S", help="override the file's samples per pixel")
    p.add_argument("--reference-method", type=str.upper, dest="reference_method", default=REFERENCE_METHOD,
                   choices=REFERENCE_METHODS, metavar="{accumulation,temporal,kd4d}",
                   help="computed reference's recipe (default accumulation: 64 instants x 4x photons)")
    p.add_argument("--reference-steps", type=int, dest="reference_steps", metavar="N", default=REFERENCE_STEPS,
                   help=f"instants of an accumulation reference (default {REFERENCE_STEPS})")
    p.add_argument("--reference-photons", type=finite_float, dest="reference_photons", metavar="F",
                   help="computed reference: photons x F (per instant for accumulation; default "
                        + ", ".join(f"{m.lower()} {f[0]:g}" for m, f in REFERENCE_FACTORS.items()) + ")")
    p.add_argument("--reference-samples", type=finite_float, dest="reference_samples", metavar="F",
                   help="computed reference: samples x F (per instant for accumulation; default "
                        + ", ".join(f"{m.lower()} {f[1]:g}" for m, f in REFERENCE_FACTORS.items()) + ")")
    p.add_argument("--cache-dir", dest="cache_dir", metavar="DIR",
                   help="where computed references are cached (default ~/.cache/stpm/references)")
    p.add_argument("--no-cache", action="store_true", dest="no_cache", help="always recompute the reference")
    p.add_argument("--quiet", "-q", action="store_true", help="no progress bar")
    # The render settings every run starts from (same names as `stpm render`).
    add_setting_options(p, skip=_OWN_OPTIONS)
    return p


# Options this parser defines itself (the sweep's list of N, and scene overrides).
_OWN_OPTIONS = ("accumulation_steps", "samples", "resolution")


def _headline(report: dict) -> list[str]:
    lines = []
    cost = report["cost"]
    tgt = cost.get("target")
    for m, name in (("rmse", "RMSE"), ("flip", "FLIP")):
        b = cost["best_time_dependent"].get(m) if tgt else None
        if b:
            le = "<= " if b["bound"] == "at most" else ""
            lines.append(f"{name}: {b['estimator']} reaches {tgt['label']}'s error in {le}{b['time_s']:.2f} s "
                         f"vs {tgt['wall_s']:.2f} s: {b['speedup']:.2f}x")
        elif tgt:
            lines.append(f"{name}: no time-dependent estimator reached {tgt['label']}'s error within the sweep")
    if report["sweep"]["skipped"]:
        lines.append(f"skipped (time budget): {', '.join(report['sweep']['skipped'])}")
    return lines


def _check_reference(path: str) -> None:
    """Refuse a --reference that is not an OpenEXR file (by its magic number), in one line.

    The reference must hold linear radiance (its Combined pass); an 8-bit sRGB
    PNG / JPEG preview would compare a tone-mapped image with linear renders.
    """
    p = Path(path)
    if not p.is_file():
        raise StpmError(f"reference image not found: {path}")
    with open(p, "rb") as f:
        magic = f.read(4)
    if magic != EXR_MAGIC:
        kind = next((name for m, name in _OTHER_IMAGES if magic.startswith(m)), None)
        what = f"a {kind} image" if kind else "not an OpenEXR file"
        raise StpmError(f"--reference {path} is {what}: give a linear OpenEXR with a Combined pass "
                        "(e.g. the .exr of stpm render)")
    # Read it all now, before any loading or rendering: a truncated or corrupt EXR is one line
    from .reference import load_reference_exr
    load_reference_exr(p)


EXR_MAGIC = b"\x76\x2f\x31\x01"
_OTHER_IMAGES = ((b"\x89PNG", "PNG"), (b"\xff\xd8", "JPEG"), (b"II*\x00", "TIFF"), (b"MM\x00*", "TIFF"),
                 (b"#?", "Radiance HDR"))


def main(argv: list[str] | None = None) -> int:
    """Run ``stpm compare``; returns the exit status (errors are raised as StpmError for the CLI to print)."""
    from ..progress import ProgressBar

    args = build_parser().parse_args(list(sys.argv[1:] if argv is None else argv))
    if not 0 <= args.k_exponent <= K_EXPONENT_MAX:
        raise StpmError(f"--k-exponent must be in [0, {K_EXPONENT_MAX:g}], got {args.k_exponent:g}")
    if args.time_budget is not None and args.time_budget < 0:
        raise StpmError("--time-budget must be >= 0 seconds")
    if any(v is not None and v < 1 for v in (args.reference_photons, args.reference_samples, args.reference_steps)):
        raise StpmError("--reference-photons, --reference-samples and --reference-steps must be >= 1")
    if args.frame is not None and not FRAME_MIN <= args.frame <= FRAME_MAX:
        raise UsageError(f"--frame {args.frame} is outside Blender's frame limits [{FRAME_MIN}, {FRAME_MAX}]")
    if args.samples is not None and args.samples < 1:
        raise StpmError("--samples must be >= 1")
    overrides = checked_overrides(args, skip=_OWN_OPTIONS)
    scene_path = Path(args.scene)
    if args.reference is not None and scene_path.exists():
        _check_reference(args.reference)

    with CancelFlag() as cancel:   # main's, installed before loading (a Ctrl-C while Blender loads)
        scene, settings, _export_s = load_any_scene(scene_path, args.frame, quiet=args.quiet)
        check_cancel(cancel)
        settings = settings.replace(**overrides)
        if args.resolution is not None:
            scene = dataclasses.replace(scene, resolution=tuple(args.resolution))
        if args.samples is not None:
            settings = settings.replace(samples=args.samples)
        out_dir = Path(args.output) if args.output else scene_path.with_name(scene_path.stem + "_compare")
        if out_dir.exists() and not out_dir.is_dir():
            raise StpmError(f"report folder {out_dir} is a file, not a directory: choose another --output")
        check_memory(scene.resolution, "ACCUMULATION", settings)   # the sweep renders accumulation too

        bar = ProgressBar(quiet=args.quiet)
        try:
            report = run_compare(scene, settings, out_dir, reference=args.reference, time_budget=args.time_budget,
                                 photon_budgets=args.photon_budgets, accumulation_steps=args.accumulation_steps,
                                 estimators=args.estimators, k_exponent=args.k_exponent,
                                 progressive_passes=args.progressive_passes, progress=bar,
                                 cancel=cancel, cache_dir=args.cache_dir,
                                 use_cache=not args.no_cache, reference_method=args.reference_method,
                                 reference_photon_factor=args.reference_photons,
                                 reference_sample_factor=args.reference_samples,
                                 reference_steps=args.reference_steps,
                                 scene_name=scene_path.name, scene_path=scene_path)
        finally:
            bar.close()
    print(f"report: {safe_text(report['files']['html'])}")
    print(f"numbers: {safe_text(report['files']['json'])}")
    for line in _headline(report):
        print(safe_text(line))
    return EXIT_OK
