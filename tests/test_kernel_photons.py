"""The compiled photon-path kernel against the numpy photon tracer it replaced (tests/oracles).

The same emitted photons and random stream go through
``photons.trace.trace_photon_paths`` (``kernels.photon_paths.photon_bounce``)
and ``oracles.photons_numpy.trace_photon_paths``: caustic paths through glass
and mirrors onto a moving receiver, global paths over diffuse, coated and rough
metal surfaces.  The records must agree to float32 rounding, and the random
streams must end in the same state.
"""
from __future__ import annotations

import numpy as np
import pytest

from kernel_scenes import kernel_scenes
from oracles.photons_numpy import trace_photon_paths as trace_numpy
from stpm_core.bsdf import MaterialTable
from stpm_core.lights import LightSet
from stpm_core.photons.trace import specular_targets, trace_photon_paths
from stpm_core.raycast import make_caster
from stpm_core.raycast.geometry import instance_offsets


def _scene():
    return {name: scene for name, scene, _ in kernel_scenes()}["photons_temporal"]


def _same_records(a: np.ndarray, b: np.ndarray) -> None:
    assert a.shape == b.shape
    for f in ("position", "power", "time"):
        x, y = a[f].astype(np.float64), b[f].astype(np.float64)
        assert np.allclose(x, y, rtol=1e-6, atol=1e-6 * max(float(np.abs(y).max()), 1e-30)), f
    assert np.abs(a["wi_oct"].astype(int) - b["wi_oct"].astype(int)).max() <= 1
    assert np.abs(a["ng_oct"].astype(int) - b["ng_oct"].astype(int)).max() <= 1     # (stored normals: both)
    assert (a["ng_oct"] != -32768).all()


@pytest.mark.parametrize("mode,budget", [("caustic", None), ("global", None), ("global", 2), ("caustic", 0)])
def test_photon_kernel_matches_the_numpy_tracer(mode, budget):
    """budget: the diffuse_bounces budget (None: none; 2: global photons stored after at most one
    counted diffuse bounce; 0: nothing stored)."""
    scene = _scene()
    caster, lights, table = make_caster(scene), LightSet(scene), MaterialTable(scene.materials)
    n = 20_000
    t = np.random.default_rng(1).random(n)
    if mode == "caustic":
        ii, c, r = next(tg for tg in specular_targets(scene, table) if scene.instances[tg[0]].name == "glass")
        o, d, Phi = lights.emit_toward(0, n, t, np.random.default_rng(2), c, r)
        kw = dict(mode="caustic", target_instance=ii)
    else:
        o, d, Phi = lights.emit(0, n, t, np.random.default_rng(2))
        kw = dict(mode="global", min_nondelta=1)
    args = dict(max_depth=8, inst_offset=instance_offsets(scene), origin=np.zeros(3), diffuse_bounces=budget, **kw)
    rng_k, rng_n = np.random.default_rng(3), np.random.default_rng(3)
    got = trace_photon_paths(caster, table, o, d, Phi, t, rng_k, **args)
    want = trace_numpy(caster, table, o, d, Phi, t, rng_n, **args)
    if budget == 0:
        assert len(want) == 0 and len(got) == 0
    else:
        assert len(want) > 500                    # the scene really stores photons of this kind
        _same_records(got, want)
    assert rng_k.random() == rng_n.random()       # the same numbers were drawn
