"""Photon look-ups replayed: the kd-tree's own cost per query, apart from the render around it.

Records every call into :class:`stpm_core.photons.kdtree.FlatTree` (``lookup``: the k-nearest
estimates, reported as ``lookup_m150`` for FINAL's m = 150 candidates and ``lookup_m24`` for
PROGRESSIVE's pilot region; ``knn_radius``: the pilot's search cap; ``range_sum``:
a pass's regions) during two renders of the demo at 160 x 120 with ``threads = 1`` -- FINAL's maps
(``bench_lookups.FINAL``: TEMPORAL, k = 100, 4 spp) and 4 passes of FINAL_PROGRESSIVE's pass
(``bench_lookups.PROGRESSIVE``) -- then replays the calls on the recorded trees, ROUNDS times,
and reports the minimum CPU microseconds per query of each kind (one thread, ``time.thread_time``).

Before / after a change to ``kdtree.py``: set ``STPM_REPLAY_REF`` to another version of that
file (e.g. ``git show main:stpm_core/photons/kdtree.py > /tmp/kdtree_ref.py``); it is loaded as a
separate module (compiled without the on-disk cache), its trees are built from the same photons,
both are replayed interleaved per round, and ``ref_us_per_query_*``, ``new_over_ref_*`` and the
number of differing output values (``differing_values``: radii, windows, counts, sums) are added.

    python -m benchmarks lookup_replay          # about 2 minutes on 2 cores
"""
from __future__ import annotations

import importlib.util
import os
import time

import numpy as np

__all__ = ["run"]

ROUNDS = 5
KINDS = ("lookup", "knn_radius", "range_sum")


def _record(render_args) -> list:
    """[(kind, tree, args)] of every FlatTree call made while rendering (arrays copied)."""
    from stpm_core.photons import kdtree
    from stpm_core.render import render
    calls = []
    orig = {n: getattr(kdtree.FlatTree, n) for n in KINDS}

    def wrap(name):
        def g(self, *a, **k):
            calls.append((name, self, tuple(np.array(x) if isinstance(x, np.ndarray) else x for x in a)))
            return orig[name](self, *a, **k)
        return g

    for n in KINDS:
        setattr(kdtree.FlatTree, n, wrap(n))
    try:
        for scene, settings in render_args:
            render(scene, settings)
    finally:
        for n in KINDS:
            setattr(kdtree.FlatTree, n, orig[n])
    return calls


def _rebuilt(mod, tree):
    """The same tree built by module ``mod`` (from the tree's photons in input order)."""
    inv = np.argsort(tree.perm)
    xyzt = tree.xyzt[:, inv]
    return mod.FlatTree(np.ascontiguousarray(xyzt[:3].T), np.ascontiguousarray(xyzt[3]),
                        np.ascontiguousarray(tree.pts[inv]), dims=tree.dims, s=tree.s)


def _label(name, a) -> str:
    """The kind of a call: ``lookup_m150`` (FINAL's estimates), ``lookup_m24`` (the pilot's regions), ..."""
    return f"lookup_m{a[3]}" if name == "lookup" else name


def _replay(calls, trees) -> tuple[dict, list]:
    sec = {}
    outs = []
    for name, tree, a in calls:
        t0 = time.thread_time()
        out = getattr(trees[id(tree)], name)(*a)
        sec[_label(name, a)] = sec.get(_label(name, a), 0.0) + time.thread_time() - t0
        outs.append(out if isinstance(out, tuple) else (out,))
    return sec, outs


def run(rounds: int = ROUNDS) -> dict:
    from stpm_core.demo import demo_scene
    from stpm_core.photons import kdtree
    from stpm_core.settings import RenderSettings
    from .bench_lookups import FINAL, PROGRESSIVE, RESOLUTION
    small = demo_scene((32, 24))
    _record([(small, RenderSettings(**{**FINAL, "photons_caustic": 20_000, "photons_global": 10_000})),
             (small, RenderSettings(**{**PROGRESSIVE, "passes": 2, "photons_caustic": 5000, "photons_global": 2000}))])
    scene = demo_scene(RESOLUTION)
    calls = _record([(scene, RenderSettings(**FINAL)), (scene, RenderSettings(**{**PROGRESSIVE, "passes": 4}))])
    engines = {"new": {id(t): t for _, t, _ in calls}}
    ref_path = os.environ.get("STPM_REPLAY_REF")
    if ref_path:
        src = open(ref_path).read().replace("from ..numba_probe import probe",
                                            "def probe():\n    return True, None").replace("cache=True", "cache=False")
        spec = importlib.util.spec_from_loader("stpm_kdtree_ref", loader=None)
        ref = importlib.util.module_from_spec(spec)
        exec(compile(src, ref_path, "exec"), ref.__dict__)
        engines["ref"] = {id(t): _rebuilt(ref, t) for _, t, _ in calls}
    queries = {}
    for name, _, a in calls:
        queries[_label(name, a)] = queries.get(_label(name, a), 0) + len(a[1] if name == "lookup" else a[0])
    best = {e: {n: np.inf for n in queries} for e in engines}
    outs = {}
    for e in engines:
        _replay(calls, engines[e])                          # warm-up (compiles the reference)
    for _ in range(rounds):
        for e, trees in engines.items():
            sec, outs[e] = _replay(calls, trees)
            for n in queries:
                best[e][n] = min(best[e][n], sec[n])
    out: dict = {"rounds": rounds, "leaf_size": kdtree.LEAF_SIZE}
    for n in sorted(queries):
        out[f"queries_{n}"] = queries[n]
        for e in engines:
            out[f"{e}_us_per_query_{n}"] = 1e6 * best[e][n] / max(queries[n], 1)
        if "ref" in engines:
            out[f"new_over_ref_{n}"] = best["new"][n] / best["ref"][n]
    if "ref" in engines:
        out["differing_values"] = int(sum((np.asarray(x) != np.asarray(y)).sum()
                                          for a, b in zip(outs["new"], outs["ref"]) for x, y in zip(a, b)))
    return out


if __name__ == "__main__":
    for k, v in run().items():
        print(f"{k:36s} {v}")
