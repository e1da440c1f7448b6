"""Stratum-box time windows: one still-like estimate per camera time stratum (not in the project).

Idea tested (2026-11-25): a pixel's S camera samples have stratified times, sample j in stratum
[j/S, (j+1)/S).  If sample j estimated the irradiance *averaged over its stratum* (k nearest in
space among the photons stamped in that stratum, E = sum Phi / (pi r_k^2 / S)), the S samples
of a pixel would average to the shutter average of E with no time-sampling noise: on a static
receiver under a moving caustic the per-instant estimators (TEMPORAL, KD4D) need 16 samples
per pixel where accumulation's 16 stills x 4 samples get by.  Moving receivers need their
photons in the receiver's own frame: here (box-local) the photons and queries on the sliding
box top (z > 0.2) are moved by -b(t) = -(0.8 - 1.6 t) along x and kept apart from the floor's.

The estimate replaces ``PhotonMap.estimate`` for estimator TEMPORAL (scipy trees, so its wall
times are not comparable); errors are against the exact image (tests/test_compare.py).

    .venv/bin/python benchmarks/compare_experiments/slicebox.py

Result (docs/compare.md, "Stratum-box windows"): 0.0237 RMSE at 320k photons, 4 samples/pixel
(KD4D 0.0288, TEMPORAL 0.0263 at the same settings, ACCUMULATION-16 0.0169): the time noise goes,
but floor points the sliding box both hides and shadows within a stratum read the stratum's mean
irradiance while seen only when lit (a covariance bias, dark, over the box's path).
"""
import time

from common import *  # noqa: F401,F403  (ROOT on sys.path, run, exact, rmse, relmse, moving_caustic_scene)
from scipy.spatial import cKDTree

from stpm_core.photons import estimators as E

CFG = {"B": 4, "local": True, "k": 30}
_ORIGINAL = E.PhotonMap.estimate


def box_local(pos, t):
    """Positions (n, 3) on the sliding box top (z > 0.2) in the box's frame, shifted off the floor."""
    q = pos.copy()
    on = pos[:, 2] > 0.2
    q[on, 0] -= 0.8 - 1.6 * t[on]
    q[on, 2] += 5.0
    return q


def stratum_box(self, p, ns, t, *, estimator="TEMPORAL", k=50, kernel="BOX", temporal_alpha=0.0):
    """E (n, 3) W/m^2: k nearest in space among the photons of the query's time stratum, over pi r_k^2 / B."""
    if estimator != "TEMPORAL":
        return _ORIGINAL(self, p, ns, t, estimator=estimator, k=k, kernel=kernel, temporal_alpha=temporal_alpha)
    t0 = time.perf_counter()
    p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    n = p.shape[0]
    t = np.broadcast_to(np.asarray(t, float), (n,))
    B, k = CFG["B"], CFG["k"]
    key = ("stratum-box", B, CFG["local"])
    if key not in self._slices:
        wpos = self.position + self.origin
        pos = box_local(wpos, self.time) if CFG["local"] else wpos
        sj = np.minimum((self.time * B).astype(int), B - 1)
        self._slices[key] = [(rows, cKDTree(pos[rows])) for rows in (np.nonzero(sj == j)[0] for j in range(B))]
    qp = box_local(p, t) if CFG["local"] else p
    qj = np.minimum((t * B).astype(int), B - 1)
    ns = np.asarray(ns, np.float32).reshape(-1, 3)
    out = np.zeros((n, 3))
    for j, (rows, tree) in enumerate(self._slices[key]):
        q = np.nonzero(qj == j)[0]
        if len(q) == 0 or len(rows) < k:
            continue
        d, idx = tree.query(qp[q], k)
        r = d[:, -1]
        out[q] = self._weighted_sum(rows[idx[:, :-1]], ns[q], None) / (np.pi * r[:, None] ** 2 / B)
    self.stats["lookup_s"] += time.perf_counter() - t0
    return out


if __name__ == "__main__":
    E.PhotonMap.estimate = stratum_box
    scene, ref = moving_caustic_scene((96, 64)), exact((96, 64))
    print("B  box-local  k  photons  samples  RMSE  relMSE  mean brightness")
    for B, local, k, photons, S in [(4, True, 30, 320_000, 4), (4, True, 60, 320_000, 4), (4, True, 120, 320_000, 4),
                                    (4, False, 30, 320_000, 4), (4, False, 120, 320_000, 4),
                                    (4, True, 30, 80_000, 4), (8, True, 30, 320_000, 8), (8, True, 60, 320_000, 8),
                                    (16, True, 30, 320_000, 16)]:
        CFG.update(B=B, local=local, k=k)
        img, _, _ = run(scene, estimator="TEMPORAL", photons_caustic=photons, samples=S)
        print(f"{B:2d} {str(local):5s} {k:4d} {photons:8d} {S:3d}  {rmse(img, ref):.4f}  {relmse(img, ref):.4f}  "
              f"{img.mean() / ref.mean() - 1:+.3f}", flush=True)
