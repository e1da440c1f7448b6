"""Does one instant converge to the exact image at that instant?  ACC N=1 (t = 0.5) vs analytic n_t=1."""
from common import *
res = (96, 64)
ex1 = analytic_moving_caustic(res, n_t=1)
sc = moving_caustic_scene(res)
for b, k in [(1, 30), (4, 30), (16, 30), (64, 30), (64, 10), (256, 30)]:
    rgb, w, _ = run(sc, method="ACCUMULATION", accumulation_steps=1, photons_caustic=20000 * b, samples=64, k_nearest=k)
    e = rgb - ex1
    print(f"b={b} k={k} wall {w:.2f} rmse {rmse(rgb, ex1):.5f} relmse {relmse(rgb, ex1):.5f} mean_rel {e.mean()/ex1.mean():+.4f}", flush=True)
