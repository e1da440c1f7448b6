"""Method PROGRESSIVE: passes whose space-time kernel shrinks, averaged; stop at passes, time or noise.

    result = render(scene, settings.replace(method="PROGRESSIVE", passes=64))

Pass i (1-based over the whole render) traces ``photons_caustic`` +
``photons_global`` photons and ``samples`` camera samples per pixel, each
photon path and camera sample at its own shutter time, from random streams
of (seed, i) alone; its photon look-ups use fixed-size kernels shrunk by the
schedule of :mod:`stpm_core.photons.progressive` from the pilot's initial
size.  The image is the mean of the passes.  So:

* passes are independent: ``--pass-offset A --passes B`` renders passes
  A + 1 .. A + B anywhere, and :class:`PassSums` of disjoint ranges add up
  (``stpm merge``);
* memory is one pass's photons (plus the pilot's, about a third of one pass);
* each pass renders a time stratum of the shutter, and the image holds whole
  rounds of strata (:mod:`stpm_core.strata`: 1, 2, 3, 4, 8, ..., 256 passes,
  then every 128), so every part of the shutter weighs alike;
* the noise is estimated from the even and the odd passes (two independent,
  identically distributed half images), see :func:`noise_estimate`.

Stops (the first that holds, after at least one pass): ``passes`` passes
rendered, ``time_limit`` seconds elapsed (a round is only started when the
last pass's time says it can end in time; else a smaller round that can, or
none), the 95th
percentile of the block noise below ``noise_threshold`` (from two passes on).
A cancel (Blender's Esc) after at least one pass keeps the passes so far.
Passes of a round cut short by a stop are left out of the image (``left_out``
in the stats), and said so.
"""
from __future__ import annotations

import copy
import math
import time as _time
from concurrent.futures import ThreadPoolExecutor
from types import SimpleNamespace

import numpy as np

from .errors import RenderCancelled, StpmError
from .integrator import static_view_setup, trace_image
from .parallel import worker_count
from .photons import build_photon_maps
from .photons.progressive import ProgressiveMaps, auto_shrink_alpha, build_pilot
from .photons.timescale import auto_time_scale
from .sampling import rng_for
from .strata import Rounds, is_round_end, pass_stratum, round_end_after, round_ends_near

__all__ = ["PassSums", "noise_estimate", "flip_visible_fraction", "render_passes", "summary", "progressive_warnings",
           "pass_seed",
           "pass_stratum", "STREAM_PASS", "NOISE_BLOCK", "NOISE_PERCENTILE"]

STREAM_PASS = 0x9A55          # random stream of the passes' seeds
NOISE_BLOCK = 8               # noise is averaged over NOISE_BLOCK x NOISE_BLOCK pixel blocks
NOISE_PERCENTILE = 95.0       # ... and its 95th percentile over the blocks is compared with the threshold
FLIP_VISIBLE = 0.05           # an LDR-FLIP error above this between the halves counts as a visible difference
_LUMA = np.array([0.2126, 0.7152, 0.0722])
PIPELINE_PHOTONS = 1 << 16    # passes of at most this many photons trace the next pass's photons during their image
TIME_SLACK = 0.1              # a round begun under a time limit is finished if it overruns the limit by at most this


def pass_seed(seed: int, i: int) -> int:
    """The seed of pass i (1-based): a pure function of (seed, i), the same on every machine."""
    return int(rng_for(seed, STREAM_PASS, i).integers(0, 2**62))


class PassSums:
    """Float64 sums of pass images over a range of passes (1-based pass indices).

    The image holds whole rounds of time strata only (:mod:`stpm_core.strata`): passes
    [first, end), where end - 1 is a round end.  Passes after it, of a round not
    finished yet, wait in a pending sum until the round ends (then they join) or the
    render stops (then they are left out: they would weight part of the shutter twice).

    Attributes
    ----------
    sums : pass name -> (H, W, C) float64, the sum of that pass over passes [first, end).
    even, odd : (H, W, 3) float64 sums of Combined RGB over the even / odd passes of [first, end).
    n_even, n_odd : how many passes each holds; first, end : the range the image holds.
    next : the next pass to add (passes [end, next) are pending).
    stratified : False for passes that all render the whole shutter (every count is a round end).
    window : (x0, y0, x1, y1) pixels, rows from the top, or None: the pixels the passes traced (a
        Render Region; the others are 0 in every sum), over which the noise is estimated.
    """

    def __init__(self, first: int, *, stratified: bool = True, window=None):
        self.first = int(first)
        self.window = None if window is None else tuple(int(v) for v in window)
        self.end = int(first)
        self.next = int(first)
        self.stratified = bool(stratified)
        self.sums: dict = {}
        self.even = None
        self.odd = None
        self.n_even = 0
        self.n_odd = 0
        self._pending = None          # the pending passes: sums, halves and their counts

    @property
    def count(self) -> int:
        """Passes in the image."""
        return self.end - self.first

    @property
    def pending(self) -> int:
        """Passes rendered after the last round end (not in the image)."""
        return self.next - self.end

    def add(self, i: int, passes: dict, round_end: bool | None = None) -> None:
        """Add pass i's images (name -> (H, W, C) float32); passes must come in order.  ``round_end``:
        whether pass i ends a round (None: as the schedule says, :func:`stpm_core.strata.is_round_end`)."""
        if i != self.next:
            raise ValueError(f"pass {i} added after pass {self.next - 1} (passes are summed in order)")
        if self._pending is None:
            self._pending = {"sums": {}, "even": None, "odd": None, "n_even": 0, "n_odd": 0}
        p = self._pending
        for name, img in passes.items():
            a = np.asarray(img, dtype=np.float64)
            if name in p["sums"]:
                p["sums"][name] += a
            else:
                p["sums"][name] = a.copy()
        rgb = np.asarray(passes["Combined"], dtype=np.float64)[:, :, :3]
        half = "even" if i % 2 == 0 else "odd"
        p[half] = rgb.copy() if p[half] is None else p[half] + rgb
        p["n_" + half] += 1
        self.next += 1
        if not self.stratified or (is_round_end(i) if round_end is None else round_end):
            self._fold()

    def _fold(self) -> None:
        """The pending passes complete a round: they join the image."""
        p = self._pending
        for name, v in p["sums"].items():
            if name in self.sums:
                self.sums[name] += v
            else:
                self.sums[name] = v
        self.even, self.odd = _add(self.even, p["even"]), _add(self.odd, p["odd"])
        self.n_even += p["n_even"]
        self.n_odd += p["n_odd"]
        self.end = self.next
        self._pending = None

    def merged(self, other: "PassSums") -> "PassSums":
        """The sums over both ranges (``other`` must start where this one ends; pending passes are left out)."""
        if other.first != self.end:
            raise ValueError(f"passes {other.first}..{other.end - 1} do not follow {self.first}..{self.end - 1}")
        if other.window != self.window:
            raise ValueError(f"passes of the Render Region {other.window} do not add to passes of {self.window}")
        out = PassSums(self.first, stratified=self.stratified, window=self.window)
        out.end = out.next = other.end
        out.sums = {k: self.sums[k] + other.sums[k] for k in self.sums}
        out.even = _add(self.even, other.even)
        out.odd = _add(self.odd, other.odd)
        out.n_even, out.n_odd = self.n_even + other.n_even, self.n_odd + other.n_odd
        return out

    def image(self) -> dict:
        """The mean of the passes in the image: name -> (H, W, C) float32.

        Before the first round ends (a range that begins after pass 4 and stops early)
        there is no time-balanced image: the mean of the pending passes is returned."""
        if self.count == 0 and self._pending is not None:
            return self.preview()
        n = max(self.count, 1)
        return {k: (v / n).astype(np.float32) for k, v in self.sums.items()}

    def preview(self) -> dict:
        """The mean of every pass rendered, pending ones included: what a progressive display
        shows after each pass (faint bands along motion trails until the round ends)."""
        p = self._pending
        if p is None:
            return self.image()
        n = self.next - self.first
        return {k: ((self.sums[k] + v if k in self.sums else v) / n).astype(np.float32)
                for k, v in p["sums"].items()}

    def halves(self):
        """(mean of the even passes, mean of the odd passes) of Combined RGB in the image (of the
        window's pixels alone with a window), or None before both exist.  Pass pairs (2q - 1, 2q)
        render the same stratum, so the halves of whole rounds are identically distributed."""
        if not self.n_even or not self.n_odd:
            return None
        A, B = self.even / self.n_even, self.odd / self.n_odd
        if self.window is not None:
            x0, y0, x1, y1 = self.window
            A, B = A[y0:y1, x0:x1], B[y0:y1, x0:x1]
        return A, B


def _add(a, b):
    if a is None:
        return None if b is None else b.copy()
    return a.copy() if b is None else a + b


def noise_estimate(sums: PassSums, block: int = NOISE_BLOCK) -> dict:
    """Estimated relative error of the mean image, from the two half images.

    With A, B the means of the n_e even and n_o odd passes (independent) and F their
    pass-weighted mean, Var F = (A - B)^2 n_e n_o / (n_e + n_o)^2 per pixel (an unbiased
    one-sample estimate: E (A - B)^2 = sigma^2 (1/n_e + 1/n_o) for a per-pass variance sigma^2).
    On luminance Y: the relative error e^2 = Var F / (Y_F + eps)^2 (eps = 1e-3 of the image's mean
    Y, so black pixels do not dominate), averaged over ``block`` x ``block`` blocks, square-rooted.

    Returns {'noise_p95': 95th percentile of the block errors, 'noise_mean': their mean,
    'blocks': (Hb, Wb) array}; inf before both halves exist.
    """
    h = sums.halves()
    if h is None:
        return {"noise_p95": math.inf, "noise_mean": math.inf, "blocks": None}
    A, B = (x @ _LUMA for x in h)
    ne, no = sums.n_even, sums.n_odd
    F = (ne * A + no * B) / (ne + no)
    var = (A - B) ** 2 * (ne * no) / (ne + no) ** 2
    eps = 1e-3 * max(float(np.mean(np.abs(F))), 1e-12)
    e2 = var / (np.abs(F) + eps) ** 2
    H, W = e2.shape
    Hb, Wb = -(-H // block), -(-W // block)
    pad = np.full((Hb * block, Wb * block), np.nan)
    pad[:H, :W] = e2
    blocks = np.sqrt(np.nanmean(pad.reshape(Hb, block, Wb, block), axis=(1, 3)))
    return {"noise_p95": float(np.percentile(blocks, NOISE_PERCENTILE)), "noise_mean": float(np.mean(blocks)),
            "blocks": blocks}


def flip_visible_fraction(sums: PassSums) -> float | None:
    """Fraction of pixels whose LDR-FLIP error between the two half images exceeds FLIP_VISIBLE
    (the seed's perceptual reading: noise a viewer would see), after the Standard view transform
    (clip to [0, 1], sRGB).  None when FLIP is unavailable or before both halves exist."""
    h = sums.halves()
    if h is None:
        return None
    try:
        import flip_evaluator as flip
    except ImportError:
        return None

    def srgb(x):
        x = np.clip(x, 0.0, 1.0)
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055).astype(np.float32)

    err, _mean, _ = flip.evaluate(np.ascontiguousarray(srgb(h[0])), np.ascontiguousarray(srgb(h[1])), "LDR",
                                  applyMagma=False)
    return float(np.mean(np.asarray(err) > FLIP_VISIBLE))


def render_passes(scene, settings, psettings, caster, lights, table, *, progress=None, cancel=None,
                  on_pass=None, scheduled_rounds: bool = False, window=None):
    """The pass loop of method PROGRESSIVE.

    settings : the user's RenderSettings; psettings : after the effects plan (photon counts,
    estimator).  on_pass(sums, info) is called after each pass (info: pass, passes, elapsed_s,
    noise_p95).  ``scheduled_rounds``: keep to the schedule of rounds even when a time limit cuts one
    short (a partial result must hold scheduled rounds), instead of taking smaller rounds that fit.
    ``window``: (x0, y0, x1, y1) pixels, rows from the top, or None: a Render Region; each pass traces
    the camera samples of those pixels alone (``integrator.trace_image``; the photons light the whole
    scene anyway) and the noise is estimated over them.
    Returns (sums, info dict for the stats, TraceStats list, photon stats list).
    """
    t0 = _time.perf_counter()
    first = int(settings.pass_offset) + 1
    last = first + int(settings.passes) - 1 if settings.passes > 0 else None
    alpha = float(settings.shrink_alpha) or auto_shrink_alpha(psettings.estimator)
    s = float(settings.time_scale) if settings.time_scale > 0 else auto_time_scale(scene)
    with_photons = psettings.photons_caustic > 0 or psettings.photons_global > 0

    def say(f, msg):
        if progress is not None:
            progress(min(max(f, 0.0), 1.0), msg)

    # -- The pilot: the initial kernel size, from photons of its own ----------------------------
    pilot = None
    if with_photons:
        say(0.0, "tracing pilot photons")
        pilot = build_pilot(scene, psettings, caster, lights, time_scale=s, cancel=cancel)
    if window is not None:
        W, H = int(scene.resolution[0]), int(scene.resolution[1])
        x0, y0, x1, y1 = (int(v) for v in window)
        window = (max(x0, 0), max(y0, 0), min(x1, W), min(y1, H))
        if window[2] <= window[0] or window[3] <= window[1]:
            raise StpmError(f"the window {tuple(int(v) for v in (x0, y0, x1, y1))} holds no pixel of {W}x{H}")
        window = None if window == (0, 0, W, H) else window
    sums = PassSums(first, window=window)
    rounds = Rounds()
    # the passes' settings but for the seed (a copy with the pass's seed per pass: a replace would
    # validate every field again, 0.5 ms a pass; pass_seed is a valid seed, 0 <= seed < 2^62)
    pbase = psettings.replace(time_scale=s)

    # static views (integrator.static_view_setup) read the pass's 3D tree too: built with the others
    static_views = with_photons and static_view_setup(
        scene, SimpleNamespace(reads_standard=True, estimator=psettings.estimator)) is not None

    def with_seed(j):
        pset_j = copy.copy(pbase)
        pset_j.seed = pass_seed(settings.seed, j)
        return pset_j

    def pass_maps(j, u, prog, pset_j=None):
        """Pass j's photon maps (stratum u = (lo, hi) of shutter mass) as the pass reads them, its
        kd-trees built: a pure function of (seed, j, u)."""
        stratum_j = u if tuple(u) != (0.0, 1.0) else None
        # (no k-nearest trees: the pass's fixed regions build the one they read, ProgressiveMaps)
        pset_j = with_seed(j) if pset_j is None else pset_j
        raw = build_photon_maps(scene, pset_j, caster, lights,
                                time_override=stratum_j, progress=prog, cancel=cancel, build_trees=False)
        t_lo, t_hi = scene.shutter.sample(np.array([u[0], u[1]]))
        pm = ProgressiveMaps(raw, pilot, pass_index=j, alpha=alpha, kernel=psettings.kernel,
                             stratum=(t_lo, t_hi, u[1] - u[0]))
        pm.prepare(static=static_views)
        return pm

    # Passes of few photons trace the next pass's photons while the image is traced (two passes' photons
    # in memory, at most 2 x PIPELINE_PHOTONS); not with threads = 1
    pipeline = with_photons and worker_count(settings) > 1 and \
        psettings.photons_caustic + psettings.photons_global <= PIPELINE_PHOTONS
    pool: list = []

    def ahead_pool():
        if not pool:
            pool.append(ThreadPoolExecutor(max_workers=1, thread_name_prefix="stpm-pass-photons"))
        return pool[0]

    ahead = None                  # (pass index, future of its ProgressiveMaps) traced ahead

    def drop_ahead():
        """The render stops: wait for a pass traced ahead that it does not take, drop it, end the thread."""
        if ahead is not None:
            ahead[1].cancel()
            try:
                ahead[1].result()
            except BaseException:      # noqa: BLE001  (its error, or a cancel, concerns no pass of the image)
                pass
        for ex in pool:
            ex.shutdown(wait=True)
    noise_end = None              # sums.end when the noise was last estimated (the halves change at round ends only)
    trace_stats, map_stats, pass_s, wall_at = [], [], [], []
    noise = {"noise_p95": math.inf, "noise_mean": math.inf}
    stop = "passes"
    i = first
    try:
        while True:
            # -- Progress: the fraction of the stop that comes first -----------------------------------
            elapsed = _time.perf_counter() - t0
            done = i - first
            frac = [done / settings.passes] if settings.passes > 0 else []
            if settings.time_limit > 0:
                frac.append(elapsed / settings.time_limit)
            if settings.noise_threshold > 0 and math.isfinite(noise["noise_p95"]) and noise["noise_p95"] > 0:
                frac.append(min(1.0, (settings.noise_threshold / noise["noise_p95"]) ** 2))
            f_lo = max(frac) if frac else 0.0

            def span(f, msg, lo=f_lo, i=i):
                hi = lo + (1 - lo) / max(1, (last - i + 1) if last is not None else 4)
                say(lo + (hi - lo) * f, f"pass {i}: {msg}")

            # -- One pass: its photons, read with this pass's kernel, and its camera samples ------------
            t_pass = _time.perf_counter()
            pset = with_seed(i)
            u_lo, u_hi = rounds.stratum(i)
            stratum = (u_lo, u_hi) if (u_lo, u_hi) != (0.0, 1.0) else None
            try:
                maps = None
                if with_photons:
                    if ahead is not None and ahead[0] == i:
                        maps = ahead[1].result()              # traced while the pass before traced its image
                    else:
                        maps = pass_maps(i, (u_lo, u_hi), lambda f, m: span(0.3 * f, m), pset)
                    ahead = None
                    # -- Pass i + 1's photons, traced on a second thread while this pass traces its image:
                    #    only when its stratum is already fixed (pass i does not end a round, whose end may
                    #    choose the next round's strata) and it is a pass the render takes
                    if pipeline and not rounds.is_end(i) and (last is None or i < last):
                        ahead = (i + 1, ahead_pool().submit(pass_maps, i + 1, rounds.stratum(i + 1), None))
                img, ts = trace_image(scene, pset, caster, lights, maps, table=table, stream=i, time_override=stratum,
                                      window=window, progress=lambda f, m: span(f, m), cancel=cancel,
                                      progress_span=(0.3 if maps is not None else 0.0, 1.0))
            except RenderCancelled:
                if sums.next == sums.first:
                    raise
                stop = "cancelled"
                break
            sums.add(i, img, round_end=rounds.is_end(i))
            trace_stats.append(ts)
            if maps is not None:
                map_stats.append(maps.stats)
            pass_s.append(_time.perf_counter() - t_pass)
            if sums.end != noise_end:
                # (the image, and so its halves, changes only when a round of passes joins it)
                noise, noise_end = noise_estimate(sums), sums.end
            elapsed = _time.perf_counter() - t0
            wall_at.append(elapsed)
            if on_pass is not None:
                on_pass(sums, {"pass": i, "passes": i - first + 1, "elapsed_s": elapsed, "noise_p95": noise["noise_p95"]})
            # -- Stop? ------------------------------------------------------------------------------
            if last is not None and i >= last:
                stop = "passes"
                break
            if settings.noise_threshold > 0 and noise["noise_p95"] <= settings.noise_threshold:
                stop = "noise_threshold"
                break
            # The next round: the schedule's, or (unless the schedule must be kept) a smaller one that
            # ends by the pass limit, within the time limit (else its passes would be left out), and not
            # long after the noise so far says the threshold is reached (it is read at round ends)
            fit = None
            if settings.time_limit > 0:
                # the wall time a pass takes (its overheads too): the last one's, or the last four's mean
                walls = np.diff(([0.0] if len(wall_at) <= 9 else []) + wall_at[-9:])      # the last 8 passes'
                p_est = max(float(walls[-1]), float(walls[-4:].mean()), 1e-9)
                fit = int(max(settings.time_limit - elapsed, 0.0) / p_est)
                # a round begun is finished unless that would overrun the limit by more than TIME_SLACK,
                # its remaining passes at the median of the last 8 (one pass slowed by a hiccup -- a
                # garbage collection, a busy scheduler -- does not abandon a round; passes that all
                # slow down do, after a few)
                p_round = max(float(np.median(walls)), 1e-9)
                if not rounds.is_end(i) and elapsed + (rounds.end_of(i) - i) * p_round > \
                        (1.0 + TIME_SLACK) * settings.time_limit:
                    stop = "time_limit"
                    break
            if rounds.is_end(i):
                # (a round takes at most half the time left: it still ends in time if the passes slow
                # down twofold, as on a machine that gets busy; the last rounds are smaller)
                half = None if fit is None else max(1, fit // 2)
                want = half if last is None else (last - i if half is None else min(half, last - i))
                if settings.noise_threshold > 0 and math.isfinite(noise["noise_p95"]) and not scheduled_rounds:
                    # noise ~ 1 / sqrt(passes) at best: the passes still needed, at least
                    more = sums.count * ((noise["noise_p95"] / settings.noise_threshold) ** 2 - 1.0)
                    want = max(1, int(math.ceil(more))) if want is None else min(want, max(1, int(math.ceil(more))))
                if scheduled_rounds:
                    n = round_end_after(i + 1) - i
                else:
                    n = rounds.begin(i + 1, max(want, 1) if want is not None else None)
                if fit is not None and (n == 0 or n > fit):
                    stop = "time_limit"
                    break
            if cancel is not None and cancel():
                stop = "cancelled"
                break
            i += 1
    finally:
        drop_ahead()          # (also when the loop raises: no pass traced ahead outlives the render)
    left_out = [sums.end, sums.next - 1, rounds.end_of(sums.next - 1)] if sums.pending and sums.count else None
    info = {
        "passes": sums.count,
        "passes_rendered": sums.next - sums.first,
        "left_out": left_out,
        "pass_first": sums.first,
        "pass_end": sums.end,
        "stopped_by": stop,
        "scheduled_rounds": rounds.scheduled,
        "shrink_alpha": alpha,
        "kernel_dims": 2 if psettings.estimator == "STANDARD" else 3,
        "kernel_radius_scale": (map_stats[-1]["kernel_radius_scale"] if map_stats else 1.0),
        "noise_p95": noise["noise_p95"],
        "noise_mean": noise["noise_mean"],
        "noise_flip_visible": flip_visible_fraction(sums),
        "pass_seconds": pass_s,
        "pilot_s": pilot.seconds if pilot is not None else 0.0,
        "time_scale": s,
    }
    if map_stats:
        for kind in ("caustic", "global"):
            info[f"{kind}_median_radius"] = map_stats[-1].get(f"{kind}_median_radius", 0.0)
            info[f"{kind}_photons_per_estimate"] = map_stats[-1].get(f"{kind}_photons_per_estimate", 0.0)
    for k in list(info):
        if isinstance(info[k], float) and not math.isfinite(info[k]):
            info[k] = None
    return sums, info, trace_stats, map_stats


def progressive_warnings(info: dict) -> list[str]:
    """The render report's warnings about a progressive render's stop (cancel, passes left out)."""
    out = []
    if info.get("stopped_by") == "cancelled":
        done, held = info.get("passes_rendered", info.get("passes", 0)), info.get("passes", 0)
        first = info.get("pass_first", 1)
        what = f"passes {first}-{first + held - 1}" if held > 1 else (f"pass {first}" if held else "its passes")
        out.append(f"cancelled after {done} pass{'' if done == 1 else 'es'}: the image holds {what}")
    left = info.get("left_out")
    if left:
        lo, hi, end = left
        ends = ", ".join(str(n) for n in round_ends_near(hi, 2) if n > 0)
        out.append(f"passes {lo}-{hi} are left out of the image: the round of time strata they began (it ends at "
                   f"pass {end}) did not finish, and a part of a round weights part of the shutter twice; pass "
                   f"counts {ends}, ... use every pass")
    elif info.get("passes") == 0 and info.get("passes_rendered"):
        out.append(f"no round of time strata finished (passes {info.get('pass_first')}-"
                   f"{info.get('pass_first') + info.get('passes_rendered') - 1}): the image is their mean and "
                   "weights parts of the shutter unevenly")
    return out


def summary(info: dict) -> str:
    """One line for the render report and the CLI: passes, why it stopped, noise, kernel size."""
    noise = info.get("noise_p95")
    flip = info.get("noise_flip_visible")
    n = int(info.get("passes", 0) or 0)
    first, end = info.get("pass_first", 1), info.get("pass_end", 1)
    held = f"{n} pass{'' if n == 1 else 'es'} ({first}..{end - 1})" if n else "no whole round of passes"
    why = str(info.get("stopped_by", "?"))
    parts = [held if why == "merge" else
             f"{held}, stopped by {'a cancel' if why == 'cancelled' else why.replace('_', ' ')}"]
    if noise is not None:
        parts.append(f"noise {noise:.4f} (95th percentile of 8x8 blocks)")
    if flip is not None:
        parts.append(f"{100 * flip:.1f} % of pixels differ visibly between the odd and even passes")
    if info.get("kernel_radius_scale") is not None:
        parts.append(f"kernel radius x{info['kernel_radius_scale']:.3f} of pass 1's")
    return "; ".join(parts)
