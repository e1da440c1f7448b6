"""The sweep of ``stpm compare``: which runs, in which order, their time and error.

Runs (:func:`plan_runs`):

* each photon estimator (STANDARD, TEMPORAL, KD4D) at each budget (b, s, f):
  ``photons_caustic`` and ``photons_global`` = b x the file's, samples per
  pixel = s x the file's, ``k_nearest`` = round(f x k x b^e) with k the
  file's and e = ``k_exponent`` (:func:`budget_k`; s = f = 1 when a budget
  does not give them, e = 0 by default), everything else (seed, time scale)
  the file's.  More samples matter because ACCUMULATION with N instants takes
  N x the file's camera samples per pixel; k may grow with the photons
  because a consistent estimate needs k -> infinity as well as k / N -> 0;
* ACCUMULATION with N instants for each N: N complete stills with the file's
  settings (its k too, whatever the budgets say), averaged (``stpm_core.render``);
* with ``progressive_passes`` P > 0, two progressive curves: method PROGRESSIVE
  (the file's estimator form, TEMPORAL unless KD4D; P passes of the file's photons
  and samples) and the SPPM baseline (``sppm.render_sppm``: one shutter instant
  per pass, 1 sample per pixel, P x the file's samples passes, so both take
  the same camera samples).  Each is one render whose image is measured after
  passes 1, 2, 4, ... and P: its ``curve`` of (wall time, error) points, the time
  spent measuring taken out.

Runs go cheapest first (estimated cost in stills: a photon run at budget
(b, s) is about (b + s) / 2 stills, ACCUMULATION N about N), so a time budget that
runs out leaves every method with its cheap points and skips the dear ones.
Once the sweep's elapsed time reaches the budget no further run starts; the
rest are marked ``skipped``.

Each run records ``wall_s`` (from ``result.stats``), the per-phase seconds
and RMSE / relative MSE / FLIP of its Combined RGB against the reference.
"""
from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field

import numpy as np

from ..errors import RenderCancelled, StpmError
from .metrics import combined_rgb, image_errors

__all__ = ["Run", "plan_runs", "parse_budget", "budget_k", "budget_label", "run_sweep", "warm_up", "is_consistent",
           "PHOTON_ESTIMATORS", "METHOD_ORDER", "CURVE_METHODS",
           "DEFAULT_PHOTON_BUDGETS", "DEFAULT_ACCUMULATION_STEPS", "DEFAULT_PROGRESSIVE_PASSES", "checkpoints"]

PHOTON_ESTIMATORS = ("STANDARD", "TEMPORAL", "KD4D")
METHOD_ORDER = ("ACCUMULATION", "STANDARD", "TEMPORAL", "KD4D", "PROGRESSIVE", "SPPM")
CURVE_METHODS = ("PROGRESSIVE", "SPPM")        # one render each, measured pass by pass
DEFAULT_PROGRESSIVE_PASSES = 32
DEFAULT_PHOTON_BUDGETS = ((1, 1), (4, 1), (16, 1), (4, 4), (16, 4))   # (photons x, samples x[, k x])
DEFAULT_ACCUMULATION_STEPS = (1, 2, 4, 8, 16, 32)
_PHASES = ("photon_trace_s", "photon_map_build_s", "photon_lookup_s", "render_s")


@dataclass
class Run:
    """One render of the sweep.

    Attributes
    ----------
    label : 'TEMPORAL x4', 'KD4D x16 s4' (16 x photons, 4 x samples), 'KD4D x16 s4 k15' (k = 15, not
        the file's), 'ACCUMULATION N=16', 'PROGRESSIVE TEMPORAL 32 passes', 'SPPM 128 passes', ...
    method : 'STANDARD' | 'TEMPORAL' | 'KD4D' | 'ACCUMULATION' | 'PROGRESSIVE' | 'SPPM' (the curve it
        belongs to).
    settings : the RenderSettings it renders with.
    photon_factor : photons as a multiple of the file's (1 for ACCUMULATION: per still).
    sample_factor : samples per pixel as a multiple of the file's (1 for ACCUMULATION: per still).
    k_factor : the budget's f in k = round(f x k_file x b^k_exponent) (1 for ACCUMULATION).
    accumulation_steps : N for ACCUMULATION, else None.
    cost : estimated cost in stills (orders the sweep).
    status : 'pending' | 'done' | 'skipped' | 'failed'; note: why (skipped / failed).
    wall_s, phases : seconds from the render's stats.
    errors : {'rmse', 'relmse', 'flip'} against the reference (None where not computed).
    rgb : (H, W, 3) float32 Combined RGB (done runs), flip_map : (H, W, 3) magma map or None.
    curve : PROGRESSIVE / SPPM: [{'pass', 'wall_s', 'rmse', 'relmse', 'flip'}] after passes 1, 2, 4, ...
    """

    label: str
    method: str
    settings: object
    photon_factor: float = 1.0
    sample_factor: float = 1.0
    k_factor: float = 1.0
    accumulation_steps: int | None = None
    cost: float = 1.0
    status: str = "pending"
    note: str = ""
    wall_s: float | None = None
    phases: dict = field(default_factory=dict)
    photons: dict = field(default_factory=dict)
    errors: dict = field(default_factory=lambda: {"rmse": None, "relmse": None, "flip": None})
    rgb: np.ndarray | None = None
    flip_map: np.ndarray | None = None
    curve: list = field(default_factory=list)

    def to_json(self) -> dict:
        """JSON-ready record (no images)."""
        s = self.settings
        return {
            "label": self.label, "method": self.method,
            "estimator": "STANDARD" if self.method == "ACCUMULATION" else self.method,
            "photon_factor": self.photon_factor, "sample_factor": self.sample_factor, "k_factor": self.k_factor,
            "accumulation_steps": self.accumulation_steps,
            "photons_caustic": int(s.photons_caustic), "photons_global": int(s.photons_global),
            "samples": int(s.samples), "k_nearest": int(s.k_nearest),
            "status": self.status, "note": self.note or None,
            "wall_s": self.wall_s, "phases": dict(self.phases) if self.status == "done" else None,
            "photons_stored": dict(self.photons) if self.status == "done" else None,
            "rmse": self.errors.get("rmse"), "relmse": self.errors.get("relmse"), "flip": self.errors.get("flip"),
            "passes": int(s.passes) if self.method in CURVE_METHODS else None,
            "curve": list(self.curve) if self.method in CURVE_METHODS else None,
        }


# ----------------------------------------------------------------------------
# Consistency (the seed's "consistent?" column)
# ----------------------------------------------------------------------------
def is_consistent(method: str, settings, scene) -> tuple[bool, str]:
    """(consistent?, why) for a method on this scene: does its error vanish as its budget grows?"""
    if method == "STANDARD":
        if not scene.has_motion:
            return True, "nothing moves: time plays no role"
        return False, "time ignored: photons on a moving surface at other times are lost"
    if method == "TEMPORAL":
        if float(settings.temporal_alpha) == 0.0:
            return True, "automatic window shrinks as photons grow"
        return False, f"fixed alpha = {settings.temporal_alpha:g}: the time window does not shrink"
    if method == "KD4D":
        return True, "4D ball shrinks as photons grow"
    if method == "ACCUMULATION":
        return True, "as N and the photons per still grow"
    if method == "PROGRESSIVE":
        return True, "its space-time kernel shrinks pass by pass"
    if method == "SPPM":
        return True, "as passes grow (one instant per pass: few passes strobe)"
    raise StpmError(f"unknown method {method!r}")


# ----------------------------------------------------------------------------
# Plan
# ----------------------------------------------------------------------------
def budget_label(b: float, s: float = 1.0, k: int | None = None) -> str:
    """'x16', 'x16 s4', 'x16 s4 k15': photons x b, samples x s (when not 1), k (when given)."""
    return f"x{b:g}" + ("" if s == 1 else f" s{s:g}") + ("" if k is None else f" k{int(k)}")


def parse_budget(item) -> tuple[float, float, float]:
    """(photon factor b, sample factor s, k factor f) from 4, (4, 2), (4, 2, 0.5), '4:2' or '4:2:0.5'.

    s and f default to 1.  All three must be positive and finite.
    """
    try:
        if isinstance(item, str):
            parts = item.split(":")
            if not 1 <= len(parts) <= 3:
                raise ValueError
            vals = [float(v) for v in parts]
        elif isinstance(item, (tuple, list)):
            if not 1 <= len(item) <= 3:
                raise ValueError
            vals = [float(v) for v in item]
        else:
            vals = [float(item)]
    except (TypeError, ValueError, IndexError):
        raise StpmError(f"a budget is PHOTONS, PHOTONS:SAMPLES or PHOTONS:SAMPLES:K (multiples of the "
                        f"file's), got {item!r}") from None
    b, s, f = (vals + [1.0, 1.0])[:3]
    if not all(v > 0 and math.isfinite(v) for v in (b, s, f)):
        raise StpmError(f"budget multiples must be positive, got {item!r}")
    return b, s, f


K_MAX = 100_000        # RenderSettings.k_nearest's upper limit


def budget_k(k_file: int, photon_factor: float, k_factor: float = 1.0, k_exponent: float = 0.0) -> int:
    """k of a photon run: max(1, round(k_factor x k_file x photon_factor ** k_exponent)).

    k_exponent = e: with N = b x the file's photons a look-up's relative variance goes as 1 / k ~ b^-e
    and its radius as (k / N)^(1/d) ~ b^((e - 1) / d) (d = 2 for STANDARD's disc, 3 for KD4D's
    ball in space x time), so e = 0 (the file's k throughout) shrinks only the radius, 0 < e < 1
    shrinks both (consistent).  Which e pays depends on whether bias or variance dominates:
    docs/compare.md, "k with the budget".
    """
    if not (k_exponent >= 0 and math.isfinite(k_exponent)):
        raise StpmError(f"k exponent must be >= 0, got {k_exponent!r}")
    try:
        k = float(k_factor) * int(k_file) * float(photon_factor) ** float(k_exponent)
    except OverflowError:
        k = math.inf
    if not k <= K_MAX:
        raise StpmError(f"k of the budget x{float(photon_factor):g} with k exponent {float(k_exponent):g} would be "
                        f"{k:.3g}, beyond k's limit {K_MAX}: lower --k-exponent or the budget")
    return max(1, int(round(k)))


def plan_runs(settings, *, photon_budgets=DEFAULT_PHOTON_BUDGETS,
              accumulation_steps=DEFAULT_ACCUMULATION_STEPS, estimators=PHOTON_ESTIMATORS,
              k_exponent: float = 0.0, progressive_passes: int = 0) -> list[Run]:
    """The sweep's runs, cheapest first (ties: ACCUMULATION, then STANDARD, TEMPORAL, KD4D).

    photon_budgets : items b (photons x b), (b, s) / 'b:s' (and samples x s) or (b, s, f) / 'b:s:f'
        (and k = f x the file's k x b^k_exponent, :func:`budget_k`).
    k_exponent : how k grows with the photon factor b in the photon runs (0: the file's k throughout).
        ACCUMULATION always uses the file's settings, k included.
    progressive_passes : P > 0 adds the PROGRESSIVE and SPPM curves (module docstring); 0: neither.
    """
    budgets = sorted({parse_budget(b) for b in photon_budgets})
    steps = sorted({int(n) for n in accumulation_steps})
    if any(n < 1 for n in steps):
        raise StpmError("accumulation steps must be >= 1")
    for e in estimators:
        if e not in PHOTON_ESTIMATORS:
            raise StpmError(f"unknown estimator {e!r} (choose from {', '.join(PHOTON_ESTIMATORS)})")
    runs, seen = [], set()
    # -- Photon estimators at each budget -------------------------------------------
    for b, s, f in budgets:
        k = budget_k(settings.k_nearest, b, f, k_exponent)
        samples = max(1, int(round(settings.samples * s)))
        for est in estimators:
            label = f"{est} {budget_label(b, s, None if k == settings.k_nearest else k)}"
            if label in seen:          # two budgets that round to the same run
                continue
            seen.add(label)
            st = settings.replace(method="PHOTON", estimator=est,
                                  photons_caustic=int(round(settings.photons_caustic * b)),
                                  photons_global=int(round(settings.photons_global * b)),
                                  samples=samples, k_nearest=k)
            runs.append(Run(label=label, method=est, settings=st,
                            photon_factor=b, sample_factor=s, k_factor=f, cost=0.5 * (b + s)))
    # -- Accumulation buffer with N stills ----------------------------------------------
    for n in steps:
        st = settings.replace(method="ACCUMULATION", accumulation_steps=n)
        runs.append(Run(label=f"ACCUMULATION N={n}", method="ACCUMULATION", settings=st,
                        accumulation_steps=n, cost=float(n)))
    # -- Progressive curves: PROGRESSIVE and the SPPM baseline ----------------------------------
    P = int(progressive_passes)
    if P < 0:
        raise StpmError("progressive passes must be >= 0")
    if P:
        form = settings.estimator if settings.estimator in ("TEMPORAL", "KD4D") else "TEMPORAL"
        stops = dict(pass_offset=0, time_limit=0.0, noise_threshold=0.0)
        st = settings.replace(method="PROGRESSIVE", estimator=form, passes=P, final_gather_samples=0, **stops)
        runs.append(Run(label=f"PROGRESSIVE {form} {P} passes", method="PROGRESSIVE", settings=st, cost=float(P)))
        n_sppm = P * int(settings.samples)
        st = settings.replace(method="PHOTON", estimator="STANDARD", passes=n_sppm, **stops)
        runs.append(Run(label=f"SPPM {n_sppm} passes", method="SPPM", settings=st, cost=0.5 * n_sppm))
    order = {m: i for i, m in enumerate(METHOD_ORDER)}
    runs.sort(key=lambda r: (r.cost, order[r.method]))
    return runs


def checkpoints(passes: int) -> set:
    """Passes after which a curve run is measured: 1, 2, 4, ... and the last."""
    out, i = {int(passes)}, 1
    while i < passes:
        out.add(i)
        i *= 2
    return out


# ----------------------------------------------------------------------------
# Sweep
# ----------------------------------------------------------------------------
WARM_UP_RESOLUTION = (16, 16)
WARM_UP_PHOTONS = 2000


def warm_up(scene, runs: list[Run]) -> float:
    """Render each distinct (method, estimator) of ``runs`` once, tiny, untimed; returns the seconds spent.

    The first render in a process loads (or compiles) the numba kernels of its code path: measured
    0.4-0.7 s with a warm on-disk cache and 2-3 s after a source change, against 0.16 s for a
    whole 96 x 64 still, all charged to whichever run happens to go first.  A 16 x 16 render with
    at most 2000 photons and 1 sample per pixel per code path takes that cost out of the timings.
    """
    import dataclasses

    from ..render import render
    from .sppm import render_sppm

    t0 = _time.perf_counter()
    small = dataclasses.replace(scene, resolution=WARM_UP_RESOLUTION)
    seen = set()
    for run in runs:
        st = run.settings
        key = (run.method, st.method, st.estimator)
        if key in seen:
            continue
        seen.add(key)
        st = st.replace(samples=1, accumulation_steps=1, passes=2,
                        photons_caustic=min(int(st.photons_caustic), WARM_UP_PHOTONS),
                        photons_global=min(int(st.photons_global), WARM_UP_PHOTONS))
        try:
            (render_sppm if run.method == "SPPM" else render)(small, st)
        except StpmError:
            pass                      # the timed run will fail again and say why
    return _time.perf_counter() - t0


def run_sweep(scene, runs: list[Run], reference_rgb: np.ndarray, *, time_budget: float | None = None,
              progress=None, cancel=None, with_flip: bool = True, warm: bool = True) -> dict:
    """Render every run (until the time budget is spent) and measure it against the reference.

    warm : first render every code path once, tiny and untimed (:func:`warm_up`), so that no run's
    wall time includes loading the compiled kernels.  Not counted against ``time_budget``.

    reference_rgb : (H, W, 3) linear RGB.  progress(fraction, message) spans
    the whole sweep, weighted by each run's estimated cost.
    cancel() -> bool stops the sweep (the running render within about a second); the
    unfinished runs are marked skipped ('cancelled') so a partial report can still be written.
    Returns {'sweep_wall_s', 'warm_up_s', 'time_budget_s', 'skipped': [labels], 'budget_exhausted': bool,
    'cancelled': bool}.
    """
    from ..render import render

    skip_all = time_budget is not None and time_budget <= 0
    warm_s = warm_up(scene, [r for r in runs if r.status == "pending"]) if warm and runs and not skip_all else 0.0
    total_cost = sum(r.cost for r in runs) or 1.0
    done_cost = 0.0
    t_start = _time.perf_counter()
    exhausted = cancelled = False
    for i, run in enumerate(runs):
        # -- Time budget: start no run once it is spent.  A positive budget always lets
        #    the first run start (a report with no run says nothing); 0 skips them all --
        elapsed = _time.perf_counter() - t_start
        if time_budget is not None and elapsed >= time_budget and (i > 0 or time_budget <= 0):
            exhausted = True
            run.status, run.note = "skipped", f"time budget of {time_budget:g} s spent"
            continue
        if cancelled or (cancel is not None and cancel()):
            cancelled = True
            run.status, run.note = "skipped", "cancelled"
            continue

        # -- Render ----------------------------------------------------------------
        def sub(f, msg, _a=done_cost, _c=run.cost, _label=run.label, _i=i):
            if progress is not None:
                progress((_a + _c * float(f)) / total_cost, f"[{_i + 1}/{len(runs)}] {_label}: {msg}")

        try:
            if run.method in CURVE_METHODS:
                result = _render_curve(scene, run, reference_rgb, sub, cancel, with_flip)
            else:
                result = render(scene, run.settings, progress=sub, cancel=cancel)
        except RenderCancelled:
            cancelled = True
            run.status, run.note = "skipped", "cancelled"
            continue
        except StpmError as e:
            run.status, run.note = "failed", str(e).splitlines()[0] if str(e) else type(e).__name__
            done_cost += run.cost
            continue
        stats = result.stats
        run.wall_s = float(stats.get("wall_s", 0.0))
        run.phases = {k: float(stats.get(k, 0.0) or 0.0) for k in _PHASES}
        run.photons = {"caustic": int(stats.get("photons_caustic", 0) or 0),
                       "global": int(stats.get("photons_global", 0) or 0)}
        run.rgb = combined_rgb(result.passes).astype(np.float32)

        # -- Error against the reference ----------------------------------------------
        errs = image_errors(run.rgb.astype(np.float64), reference_rgb, with_flip=with_flip)
        run.flip_map = errs.pop("_flip_map")
        run.errors = errs
        run.status = "done"
        done_cost += run.cost
        if progress is not None:
            progress(done_cost / total_cost, f"[{i + 1}/{len(runs)}] {run.label}: done in {run.wall_s:.1f} s")
    return {"sweep_wall_s": _time.perf_counter() - t_start, "warm_up_s": warm_s,
            "time_budget_s": None if time_budget is None else float(time_budget),
            "skipped": [r.label for r in runs if r.status == "skipped"],
            "budget_exhausted": exhausted, "cancelled": cancelled}


def _render_curve(scene, run: Run, reference_rgb, progress, cancel, with_flip: bool):
    """Render a PROGRESSIVE or SPPM run, measuring its image after each checkpoint pass into ``run.curve``.

    The seconds spent measuring are subtracted from the wall times that follow, so the curve's times
    are the render's own.  Returns the RenderResult (its stats' wall_s corrected the same way).
    """
    from ..render import render
    from .sppm import render_sppm

    marks = checkpoints(run.settings.passes)
    spent = [0.0]
    run.curve = []

    def on_pass(passes, info):
        if info["pass"] not in marks:
            return
        t0 = _time.perf_counter()
        errs = image_errors(combined_rgb(passes), reference_rgb, with_flip=with_flip)
        run.curve.append({"pass": int(info["pass"]), "wall_s": float(info["elapsed_s"]) - spent[0],
                          **{m: errs[m] for m in ("rmse", "relmse", "flip")}})
        spent[0] += _time.perf_counter() - t0

    fn = render_sppm if run.method == "SPPM" else render
    result = fn(scene, run.settings, progress=progress, cancel=cancel, on_pass=on_pass)
    result.stats["wall_s"] = float(result.stats.get("wall_s", 0.0)) - spent[0]
    return result
