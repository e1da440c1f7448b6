"""Guided emission (issue 16, item 1; setting ``photon_guiding``): photons stored on camera-visible
surfaces, image agreement and noise, guided against unguided.

Scenes (``tests/guide_scenes.py``, ``tests/test_compare.py``):

* ``room``: a closed 4 x 4 x 3 m room lit by a sun through a 2 x 1.6 m window in one wall, a 40 m
  ground outside (most of the sun's photons land there), the camera inside, 96 x 72;
* ``room_point``: the same room (2 x 1.6 m window, 8 m ground) lit by a point lamp outside, 96 x 72;
* ``moving_receiver``: a point light under a mirror, a box sliding through the caustic
  (``moving_receiver_scene``), 48 x 32.

Each scene is rendered with ``photon_guiding`` off and on, interleaved (off, on, off, on, ...)
over seeds ``STPM_GUIDING_SEEDS`` (default 6), method PHOTON (the default) and PROGRESSIVE.
Reported per scene and method:

* ``*_visible_fraction``: photons stored on camera-visible surfaces (``photon_stats``'s
  ``photons_stored_visible_global_fraction``, what ``--stats`` writes) over photons emitted;
  ``visible_gain``: guided over unguided (issue 16's target: >= 50 % in the room, >= 5x);
* ``*_s``: mean wall seconds per render (``guide_pilot_s`` the pilot's share);
* ``mean_ratio``: guided over unguided image mean (all seeds); ``block_z_max``: the largest |z|
  of 8 x 8 block means (``tests/cycles_ref.block_ztest``, 1 % floor); ``indirect_mean_ratio`` the
  same for the Indirect pass;
* ``var_ratio`` (``indirect_var_ratio``): guided over unguided per-pixel variance across seeds of
  Combined (Indirect), at equal photon count; ``*_equal_time`` those ratios times the time ratio
  (below 1: guiding wins at equal time);
* ``*_rmse``: root mean square error of single renders against a reference (unguided, method
  PHOTON, ``REF_FACTOR`` x the photons, seeds 100 and 101 averaged), relative to the reference's
  mean; ``mse_ratio`` guided over unguided, ``mse_ratio_equal_time`` times the time ratio.  This
  counts the density estimate's blur (unguided images with few photons in view are smooth and
  wrong), which the variance across seeds does not; ``*_ref_mean_ratio`` image means over the
  reference's.  The product with the time ratio is only a bound (the blur does not fall as 1 / N):
  ``mse_ratio_rendered_equal_time`` is the guided renders redone with the photons divided by the
  time ratio (``equal_time_photons_global``; ``equal_time_guided_s`` their mean seconds, to set
  against ``unguided_s``), their MSE over the unguided one.

Where the power stored in view comes from (``room_split_*``, :func:`where_in_view`): the sun
room's global photons, unguided and guided, sorted by where each first lands: through the window
(its first hit inside the room), on the ground outside, on the room's outside (walls, roof).  Per
class: its share of the emitted photons, its records stored on camera-visible surfaces per photon,
its share of their power and of their summed squared power.  ``room_split_in_view_bound``: the
most any guide with the guided share g = ``GUIDED_SHARE`` can store in view,
g r_window + (1 - g) f_unguided (r_window the window photons' in-view records per photon, every
guided photon through the window; f_unguided the unguided fraction in view).

Pictures: ``bench_out/guiding/<scene>_<method>.png`` (left unguided, right guided; one row per
seed and the mean last, exposure x4), the images in ``<scene>_<method>.npz``.

    python -m benchmarks guiding       # about 5-10 min on 2 cores
"""
from __future__ import annotations

import os
os.environ.setdefault("STPM_VISIBLE_STATS", "1")
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SEEDS = range(int(os.environ.get("STPM_GUIDING_SEEDS", 6)))
REF_FACTOR = 16
SPLIT_PHOTONS = int(os.environ.get("STPM_GUIDING_SPLIT_PHOTONS", 2_000_000))   # where_in_view's unguided photons


def _scenes():
    sys.path.insert(0, str(ROOT / "tests"))
    from guide_scenes import window_room
    from test_compare import moving_receiver_scene
    return {"room": window_room((96, 72), ground=40.0),
            "room_point": window_room((96, 72), light="POINT"),
            "moving_receiver": moving_receiver_scene((48, 32))}


def _settings(name: str, method: str):
    from stpm_core.settings import RenderSettings
    if name == "moving_receiver":
        st = RenderSettings(samples=4, photons_global=100_000, photons_caustic=20_000, k_nearest=30)
    else:
        st = RenderSettings(samples=4, photons_global=200_000, photons_caustic=0, k_nearest=30)
    if method == "PROGRESSIVE":
        st = st.replace(method="PROGRESSIVE", passes=2, samples=2,
                        photons_global=st.photons_global // 2, photons_caustic=st.photons_caustic // 2)
    return st


def where_in_view(scene, n: int, *, guided: bool, seed: int = 11) -> dict:
    """The sun room's global photons sorted by where they first land (module docstring): per class
    (``window``, ``ground``, ``exterior``) the share of the n emitted photons, in-view records per
    photon, the share of the in-view power and of its summed squares."""
    from guide_scenes import ROOM_INSIDE
    from stpm_core.bsdf import MaterialTable
    from stpm_core.lights import LightSet
    from stpm_core.photons import guide as _guide
    from stpm_core.photons.record import photon_origin
    from stpm_core.photons.trace import _times, trace_photon_paths
    from stpm_core.raycast import make_caster
    from stpm_core.raycast.geometry import instance_offsets
    from stpm_core.sampling import rng_for
    from stpm_core.settings import RenderSettings
    from stpm_core.shading import shading_data
    caster, lights, table = make_caster(scene), LightSet(scene), MaterialTable(scene.materials)
    st, origin, inst_offset = RenderSettings(), photon_origin(scene), instance_offsets(scene)
    shading = shading_data(scene, table.closures)
    cells, guides, _, _ = _guide.guides_for(scene, caster, lights, table, shading=shading, inst_offset=inst_offset,
                                            origin=origin, time_override=None, guiding=True)
    ground = [i for i, inst in enumerate(scene.instances) if inst.name == "ground"]
    lo, hi = np.array(ROOM_INSIDE[0]) - 1e-3, np.array(ROOM_INSIDE[1]) + 1e-3     # (its faces: the inside walls)
    names = ("window", "ground", "exterior")
    tot = {k: np.zeros(4) for k in names}               # photons, in-view records, power, power^2
    batch = 1 << 18
    for b0 in range(0, n, batch):
        m = min(batch, n - b0)
        rng = rng_for(seed, 0x5B17, b0 // batch)
        t = _times(scene, m, rng, None)
        o, d, Phi, s_lit = lights.emit(0, m, t, rng, with_s_lit=True, guide=guides[0] if guided else None)
        h = caster.intersect(o, d, t)
        on_ground = h.hit & np.isin(h.instance, ground)
        X = np.asarray(h.position, np.float64)
        inside = h.hit & ~on_ground & np.all((X > lo) & (X < hi), axis=1)
        recs, pid = trace_photon_paths(caster, table, o, d, Phi * (m / n), t, rng, origin=origin, mode="global",
                                       s_lit=s_lit, max_depth=st.max_depth, inst_offset=inst_offset,
                                       shading=shading, diffuse_bounces=st.diffuse_bounces, path_ids=np.arange(m))
        on = cells.contains(recs["position"].astype(np.float64) + origin)
        P, ids = recs["power"][on].astype(np.float64).mean(axis=1), pid[on]
        for k, sel in zip(names, (inside, on_ground, ~inside & ~on_ground)):
            r = sel[ids]
            tot[k] += (np.count_nonzero(sel), np.count_nonzero(r), P[r].sum(), (P[r] ** 2).sum())
    P1, P2 = sum(v[2] for v in tot.values()), sum(v[3] for v in tot.values())
    out = {"in_view_fraction": sum(v[1] for v in tot.values()) / n}
    for k, (nph, nrec, p1, p2) in tot.items():
        out[f"{k}_photon_share"] = nph / n
        out[f"{k}_in_view_per_photon"] = nrec / max(nph, 1.0)
        out[f"{k}_power_share"] = p1 / max(P1, 1e-300)
        out[f"{k}_power_sq_share"] = p2 / max(P2, 1e-300)
    return out


def run() -> dict:
    from stpm_core.render import render
    from stpm_core.photons import guide as _guide
    if os.environ.get("STPM_GUIDING_TEMPER"):               # a sweep: the guide's density exponent
        _guide.TEMPER = float(os.environ["STPM_GUIDING_TEMPER"])
    scenes = _scenes()
    from cycles_ref import block_ztest
    from stpm_core.compare.report_html import png_bytes
    outdir = ROOT / "bench_out" / "guiding"
    outdir.mkdir(parents=True, exist_ok=True)
    render(scenes["moving_receiver"], _settings("moving_receiver", "PHOTON").replace(
        photons_global=1000, photons_caustic=100, photon_guiding=True))          # warm-up (kernels)
    out = {}
    # Where the sun room's in-view power comes from, and the most a guide can store in view
    split = {"unguided": where_in_view(scenes["room"], SPLIT_PHOTONS, guided=False),
             "guided": where_in_view(scenes["room"], SPLIT_PHOTONS // 4, guided=True)}
    for k, v in split.items():
        out.update({f"room_split_{k}_{a}": b for a, b in v.items()})
        print(f"room_split_{k}", {a: round(b, 6) for a, b in v.items()}, flush=True)
    g = _guide.GUIDED_SHARE
    out["room_split_in_view_bound"] = (g * split["unguided"]["window_in_view_per_photon"]
                                       + (1.0 - g) * split["unguided"]["in_view_fraction"])
    print("room_split_in_view_bound", round(out["room_split_in_view_bound"], 4), flush=True)
    for name, scene in scenes.items():
        st_ref = _settings(name, "PHOTON")
        st_ref = st_ref.replace(photons_global=REF_FACTOR * st_ref.photons_global,
                                photons_caustic=REF_FACTOR * st_ref.photons_caustic, samples=16)
        ref = np.mean([render(scene, st_ref.replace(seed=s)).passes["Combined"][..., :3].astype(np.float64)
                       for s in (100, 101)], axis=0)
        for method in ("PHOTON", "PROGRESSIVE"):
            st = _settings(name, method)
            ims = {False: [], True: []}
            ind = {False: [], True: []}
            frac = {False: [], True: []}
            sec = {False: [], True: []}
            pilot = []
            for seed in SEEDS:
                for g in (False, True):                  # interleaved: load changes hit both alike
                    t0 = time.perf_counter()
                    r = render(scene, st.replace(seed=seed, photon_guiding=g))
                    sec[g].append(time.perf_counter() - t0)
                    ps = r.stats["photon_stats"]
                    frac[g].append(ps.get("photons_stored_visible_global_fraction", 0.0))
                    if g:
                        pilot.append(ps.get("guide_pilot_s", 0.0))
                    ims[g].append(r.passes["Combined"][..., :3].astype(np.float64))
                    ind[g].append(r.passes["Indirect"][..., :3].astype(np.float64))
            a, b = np.array(ims[False]), np.array(ims[True])
            ia, ib = np.array(ind[False]), np.array(ind[True])
            key = f"{name}_{method.lower()}"
            res = {"unguided_visible_fraction": float(np.mean(frac[False])),
                   "guided_visible_fraction": float(np.mean(frac[True])),
                   "unguided_s": float(np.mean(sec[False])), "guided_s": float(np.mean(sec[True])),
                   "guide_pilot_s": float(np.mean(pilot))}
            res["visible_gain"] = res["guided_visible_fraction"] / max(res["unguided_visible_fraction"], 1e-12)
            z = block_ztest(b, a, block=8, floor=0.01)
            res["mean_ratio"] = float(z.mean_ratio)
            res["block_z_max"] = float(np.max(np.abs(z.z)))
            res["indirect_mean_ratio"] = float(ib.mean() / max(ia.mean(), 1e-30))
            res["indirect_block_z_max"] = float(np.max(np.abs(block_ztest(ib, ia, block=8, floor=0.01).z)))
            tr = res["guided_s"] / res["unguided_s"]
            res["var_ratio"] = float(b.var(0, ddof=1).mean() / max(a.var(0, ddof=1).mean(), 1e-30))
            res["indirect_var_ratio"] = float(ib.var(0, ddof=1).mean() / max(ia.var(0, ddof=1).mean(), 1e-30))
            res["var_ratio_equal_time"] = res["var_ratio"] * tr
            mse = {k: float(np.mean((x - ref[None]) ** 2)) for k, x in (("unguided", a), ("guided", b))}
            for k in mse:
                res[f"{k}_rmse"] = float(np.sqrt(mse[k]) / max(ref.mean(), 1e-30))
            res["mse_ratio"] = mse["guided"] / max(mse["unguided"], 1e-30)
            res["mse_ratio_equal_time"] = res["mse_ratio"] * tr
            # Equal time, rendered: guided with the photons scaled by the time ratio just measured
            # (unguided MSE is mostly the k-nearest blur, which does not fall as 1 / N: the product
            # above is only a bound)
            # (two steps: photons / time ratio, then the line time = a + b N through both guided
            # runs solved for the unguided seconds)
            def guided_at(n):
                st_n = st.replace(photons_global=max(int(n), 1000), photon_guiding=True)
                ims_n, s_n = [], []
                for seed in SEEDS:
                    t0 = time.perf_counter()
                    ims_n.append(render(scene, st_n.replace(seed=seed)).passes["Combined"][..., :3].astype(np.float64))
                    s_n.append(time.perf_counter() - t0)
                return st_n, ims_n, float(np.mean(s_n))
            N = st.photons_global
            st_eq, eq, eq_t = guided_at(N / max(tr, 1.0))
            if st_eq.photons_global < N and eq_t > 1.1 * res["unguided_s"]:
                per_photon = (res["guided_s"] - eq_t) / (N - st_eq.photons_global)
                fixed = res["guided_s"] - per_photon * N
                if per_photon > 0.0 and res["unguided_s"] > fixed:
                    st_eq, eq, eq_t = guided_at((res["unguided_s"] - fixed) / per_photon)
            eq_s = [eq_t]
            res["equal_time_photons_global"] = int(st_eq.photons_global)
            res["equal_time_guided_s"] = float(np.mean(eq_s))
            res["mse_ratio_rendered_equal_time"] = float(np.mean((np.array(eq) - ref[None]) ** 2)) / max(mse["unguided"], 1e-30)
            res["unguided_ref_mean_ratio"] = float(a.mean() / max(ref.mean(), 1e-30))
            res["guided_ref_mean_ratio"] = float(b.mean() / max(ref.mean(), 1e-30))
            np.savez_compressed(outdir / f"{key}.npz", unguided=a, guided=b, reference=ref)
            res["indirect_var_ratio_equal_time"] = res["indirect_var_ratio"] * tr
            for k, v in res.items():
                out[f"{key}_{k}"] = v
            tm = lambda x: (np.clip(4.0 * x, 0.0, 1.0) ** (1 / 2.2) * 255).astype(np.uint8)   # noqa: E731
            rows = [np.concatenate([tm(a[i]), tm(b[i])], 1) for i in range(a.shape[0])]
            rows.append(np.concatenate([tm(a.mean(0)), tm(b.mean(0))], 1))
            (outdir / f"{key}.png").write_bytes(png_bytes(np.concatenate(rows, 0)))
            print(key, {k: round(v, 4) for k, v in res.items()}, flush=True)
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(k, v)
