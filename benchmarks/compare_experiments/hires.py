"""Speed-up at 192x128: ACC-16 at S = 4, 16 vs KD4D (k tuned), one seed, exact reference."""
from common import *
res = (192, 128)
ex = exact(res)
sc = moving_caustic_scene(res)
run(sc, estimator="KD4D", photons_caustic=1000, samples=1)   # warm-up
cfgs = [("ACC16_S4", dict(method="ACCUMULATION", accumulation_steps=16, samples=4)),
        ("ACC16_S1", dict(method="ACCUMULATION", accumulation_steps=16, samples=1)),
        ("KD_x16_T16_k15", dict(estimator="KD4D", photons_caustic=320000, samples=16, k_nearest=15)),
        ("KD_x32_T16_k17", dict(estimator="KD4D", photons_caustic=640000, samples=16, k_nearest=17)),
        ("KD_x32_T32_k17", dict(estimator="KD4D", photons_caustic=640000, samples=32, k_nearest=17)),
        ("KD_x16_T16_k30", dict(estimator="KD4D", photons_caustic=320000, samples=16, k_nearest=30)),
        ("ACC16_S16", dict(method="ACCUMULATION", accumulation_steps=16, samples=16))]
for tag, kw in cfgs:
    rgb, w, st = run(sc, **kw)
    print(f"{tag:18s} wall {w:6.2f} rmse {rmse(rgb, ex):.5f} relmse {relmse(rgb, ex):.5f} lookup {st['photon_lookup_s']:.2f} trace {st['photon_trace_s']:.2f} render {st['render_s']:.2f}", flush=True)
