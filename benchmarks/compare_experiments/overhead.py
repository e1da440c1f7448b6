from common import *
import time
for res in [(96, 64), (192, 128)]:
    sc = moving_caustic_scene(res)
    run(sc, method="PHOTON", estimator="KD4D")  # warm-up (numba)
    for kw in [dict(method="PHOTON", estimator="KD4D", photons_caustic=100, samples=1),
               dict(method="PHOTON", estimator="KD4D"),
               dict(method="PHOTON", estimator="STANDARD"),
               dict(method="ACCUMULATION", accumulation_steps=1),
               dict(method="ACCUMULATION", accumulation_steps=1, samples=16),
               dict(method="ACCUMULATION", accumulation_steps=4),
               dict(method="ACCUMULATION", accumulation_steps=16, photons_caustic=100, samples=1),
               dict(method="PHOTON", estimator="KD4D", photons_caustic=320_000, samples=16)]:
        ws = []
        for _ in range(2):
            rgb, w, s = run(sc, **kw); ws.append(w)
        print(res, kw, f"wall {min(ws):.3f}", {k: round(s[k], 3) for k in ("plan_s", "photon_trace_s", "photon_map_build_s", "photon_lookup_s", "render_s")}, flush=True)
