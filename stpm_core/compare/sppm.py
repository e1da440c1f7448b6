"""Baseline for ``stpm compare``: SPPM with one shutter instant per pass, as pbrt-v4 renders motion blur.

pbrt-v4's stochastic progressive photon mapping (``SPPMIntegrator``, motion blur since its PR #441)
gives each pass ONE shutter instant for its camera rays and its photons (a radical inverse of the
pass index), one camera sample per pixel, and a radius per pixel updated from the photons that
pixel's visible point found:

    N_{i+1} = N_i + gamma M_i,   R_{i+1} = R_i sqrt(N_{i+1} / (N_i + M_i)),   gamma = 2/3

(M_i: photons within R_i in pass i).  Its estimate, tau / (N_emitted pi R^2) with the flux tau
rescaled by R_{i+1}^2 / R_i^2 every pass, equals the mean over passes of each pass's own disc
estimate Phi_i / (pi R_i^2); that mean is what the passes here add up (``PassSums``), so the
image and its noise estimate come out as STPM's progressive method's do.  Each pass is a still:
correct, but few passes strobe, and a pass's photons say nothing about other instants.

The initial radius of a pixel (pbrt: a user setting) is the pilot's at that pixel's first visible
point (:class:`stpm_core.photons.progressive.Pilot`, STANDARD: about ``k_nearest`` of a pass's
photons), the same start the progressive method gets.
"""
from __future__ import annotations

import math
import time as _time

import numpy as np

from ..errors import RenderCancelled
from ..photons.estimators import CONE_K
from ..photons.maps import KINDS

__all__ = ["GAMMA", "SPPMMaps", "radical_inverse", "render_sppm"]

GAMMA = 2.0 / 3.0              # pbrt-v4's SPPM radius update
STREAM_SPPM = 0x5399


def radical_inverse(i: int, base: int = 2) -> float:
    """Van der Corput radical inverse of i >= 0 in ``base``: 0, 1/2, 1/4, 3/4, 1/8, ..."""
    inv, f, x = 1.0 / base, 1.0 / base, 0.0
    while i > 0:
        x += (i % base) * f
        i //= base
        f *= inv
    return x


class SPPMMaps:
    """One pass's photon maps read with each pixel's own radius; the integrator passes ``pixels``.

    state : {kind: {'R': (H W,) float64 radius (nan: not yet set), 'N': (H W,) float64}} shared by
    the passes of one render (updated here, pbrt's rule).
    """

    per_pixel = True

    def __init__(self, maps, pilot, state: dict):
        self.maps = maps
        self.pilot = pilot
        self.state = state
        self.lookups = 0

    def has(self, kind: str) -> bool:
        return self.maps.has(kind)

    def estimate(self, kind, p, ns, t, *, pixels, ng=None):
        """Irradiance E (n, 3) W/m^2 at p (n, 3): photons within the pixel's radius / (pi R^2); then the
        radius update of every pixel queried.  ng (the geometric normals) is ignored: pbrt's SPPM
        sums the whole ball, no tangent slab (this is its baseline)."""
        m = self.maps.maps[kind]
        p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
        n = p.shape[0]
        E = np.zeros((n, 3))
        if n == 0 or m.n == 0:
            return E
        ns = np.ascontiguousarray(np.asarray(ns, dtype=np.float32).reshape(-1, 3))
        st = self.state[kind]
        R = st["R"][pixels]
        new = np.isnan(R)
        if new.any():
            q = np.zeros((int(new.sum()), 4))
            q[:, :3] = p[new] - self.pilot.maps.maps[kind].origin
            r0, _ = self.pilot.initial_size(kind, q, ns[new])
            R[new] = np.where(np.isfinite(r0), r0, 0.0)
            st["R"][pixels[new]] = R[new]
        q = np.zeros((n, 4))
        q[:, :3] = p - m.origin
        Phi, cnt = m.flat_tree(3).range_sum(q, ns, R, None, False, CONE_K, m.workers)
        ok = R > 0
        E[ok] = Phi[ok] / (np.pi * R[ok, None] ** 2)
        # pbrt's update, per pixel, from the photons its visible point found
        M = np.bincount(pixels, weights=cnt, minlength=st["N"].size)
        hit = np.bincount(pixels, minlength=st["N"].size) > 0
        N_old = st["N"]
        N_new = N_old + GAMMA * M
        grow = hit & (N_old + M > 0)
        st["R"][grow] *= np.sqrt(N_new[grow] / (N_old[grow] + M[grow]))
        st["N"] = np.where(hit, N_new, N_old)
        self.lookups += n
        return E

    @property
    def stats(self) -> dict:
        st = dict(self.maps.stats)
        for kind in KINDS:
            R = self.state[kind]["R"]
            st[f"{kind}_median_radius"] = float(np.nanmedian(R)) if np.isfinite(R).any() else 0.0
        return st


def render_sppm(scene, settings, *, progress=None, cancel=None, on_pass=None):
    """Render ``settings.passes`` SPPM passes (one instant each, 1 sample per pixel); a RenderResult.

    settings : RenderSettings (photon counts per pass, k_nearest for the initial radius, seed);
    method and estimator are ignored (one instant: STANDARD).  on_pass(passes, info) as for PROGRESSIVE.
    """
    from ..bsdf import MaterialTable
    from ..integrator import trace_image
    from ..lights import LightSet
    from ..photons import build_photon_maps
    from ..photons.progressive import build_pilot
    from ..plan import apply_plan, make_plan
    from ..progressive import PassSums, noise_estimate, pass_seed
    from ..raycast import make_caster
    from ..render import RenderResult
    from ..sampling import rng_for
    from ..scene import validate_scene

    t0 = _time.perf_counter()
    validate_scene(scene)
    settings = settings.replace(method="PHOTON", estimator="STANDARD", samples=1)
    caster, lights, table = make_caster(scene), LightSet(scene), MaterialTable(scene.materials)
    psettings = apply_plan(settings, make_plan(scene, settings, caster=caster, lights=lights))
    W, H = int(scene.resolution[0]), int(scene.resolution[1])
    seed = int(rng_for(settings.seed, STREAM_SPPM).integers(0, 2**62))
    pilot = build_pilot(scene, psettings.replace(seed=seed), caster, lights, time_scale=1.0, cancel=cancel)
    state = {kind: {"R": np.full(W * H, np.nan), "N": np.zeros(W * H)} for kind in KINDS}
    sums = PassSums(1, stratified=False)          # every pass renders the whole shutter
    passes = max(1, int(settings.passes))
    photon_s = render_s = 0.0
    stopped = "passes"
    for i in range(1, passes + 1):
        u = radical_inverse(i - 1)
        t_i = float(scene.shutter.sample(np.array([u]))[0])
        pset = psettings.replace(seed=pass_seed(settings.seed, i) ^ STREAM_SPPM)
        try:
            t1 = _time.perf_counter()
            maps = None
            if pset.photons_caustic > 0 or pset.photons_global > 0:
                maps = SPPMMaps(build_photon_maps(scene, pset, caster, lights, time_override=t_i, cancel=cancel),
                                pilot, state)
            photon_s += _time.perf_counter() - t1
            img, ts = trace_image(scene, pset, caster, lights, maps, table=table, time_override=t_i, stream=i,
                                  cancel=cancel)
            render_s += ts.seconds
        except RenderCancelled:
            if sums.count == 0:
                raise
            stopped = "cancelled"
            break
        sums.add(i, img)
        if progress is not None:
            progress(i / passes, f"SPPM pass {i}/{passes}")
        if on_pass is not None:
            on_pass(sums.image(), {"pass": i, "passes": sums.count, "elapsed_s": _time.perf_counter() - t0,
                                   "noise_p95": None})
    noise = noise_estimate(sums)
    stats = {"wall_s": _time.perf_counter() - t0, "photon_s": photon_s, "render_s": render_s,
             "method": "SPPM", "estimator": "STANDARD", "samples": 1, "seed": int(settings.seed),
             "resolution": [W, H], "photons_caustic": int(psettings.photons_caustic) * sums.count,
             "photons_global": int(psettings.photons_global) * sums.count,
             "progressive": {"passes": sums.count, "pass_first": 1, "pass_end": sums.end, "stopped_by": stopped,
                             "gamma": GAMMA, "pilot_s": pilot.seconds,
                             "noise_p95": noise["noise_p95"] if math.isfinite(noise["noise_p95"]) else None}}
    return RenderResult(passes=sums.image(), stats=stats, warnings=[], sums=sums)
