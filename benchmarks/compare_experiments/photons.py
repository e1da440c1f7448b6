"""Speed-up vs the file's photon count (S = 4, k = 30): ACC-16 vs KD4D with k = 10 (N / 20k)^(1/4)."""
from common import *
res = (96, 64); ex = exact(res); sc = moving_caustic_scene(res)
run(sc, estimator="KD4D", photons_caustic=1000, samples=1); run(sc, method="ACCUMULATION", accumulation_steps=1, photons_caustic=1000, samples=1)
for base in (5_000, 80_000):
    rgb, w, _ = run(sc, method="ACCUMULATION", accumulation_steps=16, photons_caustic=base)
    print(f"base {base} ACC16 S4 wall {w:.2f} rmse {rmse(rgb, ex):.5f} relmse {relmse(rgb, ex):.5f}", flush=True)
    for b, T in ((8, 16), (16, 16), (32, 16), (32, 32), (64, 16)):
        N = base * b
        if N > 3_000_000: continue
        k = max(1, round(10 * (N / 20_000) ** 0.25))
        rgb, w, _ = run(sc, estimator="KD4D", photons_caustic=N, samples=T, k_nearest=k)
        print(f"base {base} KD4D x{b} T{T} k{k} wall {w:.2f} rmse {rmse(rgb, ex):.5f} relmse {relmse(rgb, ex):.5f}", flush=True)
