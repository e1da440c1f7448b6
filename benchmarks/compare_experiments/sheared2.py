"""Idealised test of a motion-sheared space-time kernel (not in the project).

Floor band 0.45 < |y| < 0.8 of the benchmark scene: there the irradiance is the mirror caustic alone,
moving at v = 1.5 m/shutter along x (box, its shadow and the shade's shadow are elsewhere).
Per query point x: shutter-averaged irradiance
  exact   : quadrature over 512 instants
  ACC-16  : mean over 16 stills at t_i = (i + 1/2)/16, each a 2D k-NN estimate (k = 30) on its own
            N_s photons traced at t_i (what ACCUMULATION-16 does per pixel, camera noise aside)
  KD4D    : mean over T stratified times of the 4D k-NN estimate on one map of 16 N_s photons
            (ball in (x, y, s t), s = 2.26, clipped to the shutter)
  SHEAR   : the same with the ball in (x - v t, y, s' t): co-moving with the caustic (v known here)
RMSE over query points against exact, relative to the mean.
"""
import sys
from common import *
from scipy.spatial import cKDTree
from stpm_core.raycast import make_caster
from stpm_core.lights import LightSet
from stpm_core.bsdf import MaterialTable
from stpm_core.photons.trace import trace_caustic_map
from stpm_core.photons.record import photon_origin

scene = moving_caustic_scene((96, 64))
caster, lights, table = make_caster(scene), LightSet(scene), MaterialTable(scene.materials)
origin = photon_origin(scene)
I = 100 / (4 * np.pi)

def E_exact(x, y, t):
    c = -0.25 + 0.5 * t
    h = 3.0
    ap = (np.abs(x / h - c) < 0.3) & (np.abs(y / h) < 0.3)
    return np.where(ap, I * h / (x * x + y * y + h * h) ** 1.5, 0.0)

def floor_photons(N, seed, t=None):
    st = RenderSettings(**{**BASE, "photons_caustic": int(N), "seed": seed})
    rec, _ = trace_caustic_map(scene, st, caster, lights, table, time_override=t)
    p = rec["position"].astype(np.float64) + origin
    keep = (np.abs(p[:, 2]) < 1e-3) & (np.abs(p[:, 1]) > 0.34)
    tt = rec["time"].astype(np.float64)
    return p[keep, 0], p[keep, 1], tt[keep], rec["power"][keep, 0].astype(np.float64)

def knn_2d(px, py, pw, qx, qy, k):
    tree = cKDTree(np.c_[px, py])
    d, i = tree.query(np.c_[qx, qy], k=k)
    r = d[:, -1]
    return pw[i[:, :-1]].sum(1) / (np.pi * r * r)

def slab_vol(R, t, s):
    a = np.clip(t - R / s, 0, 1); b = np.clip(t + R / s, 0, 1)
    return np.pi * (R * R * (b - a) - s * s * ((b - t) ** 3 - (a - t) ** 3) / 3)

def knn_3d(cx, py, pt, pw, qx, qy, qt, k, s):
    tree = cKDTree(np.c_[cx, py, s * pt])
    d, i = tree.query(np.c_[qx, qy, s * qt], k=k)
    R = d[:, -1]
    return pw[i[:, :-1]].sum(1) / slab_vol(R, qt, s)

M = 3000
rng = np.random.default_rng(7)
qx = rng.uniform(-1.2, 1.2, M); qy = rng.choice([-1, 1], M) * rng.uniform(0.45, 0.8, M)
tq = (np.arange(512) + 0.5) / 512
ex = np.mean([E_exact(qx, qy, t) for t in tq], axis=0)
Ns = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
T = 16
v = 1.5
CFG = [("KD4D x16 k30", 2.26, 0, 30, 16), ("KD4D x32 k30", 2.26, 0, 30, 32), ("KD4D x64 k40", 2.26, 0, 40, 64),
       ("SHEAR x16 s0.25 k100", 0.25, v, 100, 16), ("SHEAR x16 s0.1 k200", 0.1, v, 200, 16),
       ("SHEAR x16 s0.25 k200", 0.25, v, 200, 16),
       ("SHEAR x8 s0.25 k60", 0.25, v, 60, 8), ("SHEAR x4 s0.25 k30", 0.25, v, 30, 4),
       ("SHEAR x4 s0.1 k60", 0.1, v, 60, 4), ("SHEAR x8 s0.1 k100", 0.1, v, 100, 8)]
for seed in (1, 2):
    # ACC-16
    acc = np.zeros(M)
    for i in range(16):
        px, py, _, pw = floor_photons(Ns, 1000 * seed + i, t=(i + 0.5) / 16)
        acc += knn_2d(px, py, pw, qx, qy, 30) / 16
    res = {"ACC16 k30": acc}
    ts = (np.arange(T)[None, :] + rng.random((M, T))) / T
    for name, s, shear, k, b in CFG:
        px, py, pt, pw = floor_photons(b * Ns, seed)
        est = np.zeros(M)
        for j in range(T):
            t = ts[:, j]
            est += knn_3d(px - shear * pt, py, pt, pw, qx - shear * t, qy, t, k, s) / T
        res[name] = est
    for name, s, shear, k in []:
        px, py, pt, pw = floor_photons(16 * Ns, seed)
    for name, s, shear, k in [("KD4D s2.26 k30", 2.26, 0, 30), ("KD4D s2.26 k15", 2.26, 0, 15),
                              ("KD4D s1.13 k15", 1.13, 0, 15),
                              ("SHEAR s2.26 k30", 2.26, v, 30), ("SHEAR s0.5 k30", 0.5, v, 30),
                              ("SHEAR s0.25 k30", 0.25, v, 30), ("SHEAR s0.5 k60", 0.5, v, 60),
                              ("SHEAR s0.25 k100", 0.25, v, 100)]:
        est = np.zeros(M)
        for j in range(T):
            t = ts[:, j]
            est += knn_3d(px - shear * pt, py, pt, pw, qx - shear * t, qy, t, k, s) / T
        res[name] = est
    for name, e in res.items():
        err = e - ex
        print(f"Ns={Ns} seed {seed} {name:18s} rmse/mean {np.sqrt(np.mean(err ** 2)) / ex.mean():.4f} "
              f"bias(mean) {err.mean() / ex.mean():+.4f}", flush=True)
