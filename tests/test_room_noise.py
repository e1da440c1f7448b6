"""benchmarks.room_noise's per-surface, per-pass means on synthetic images (numpy only, no bpy)."""
import numpy as np
import pytest

from benchmarks import product_noise as pn
from benchmarks import room_noise as rn


def _runs(H=40, W=40):
    """Two seeds of a frame whose left half is object 1 ('Wall') and right half object 2 ('Box'):
    the wall's Indirect is 1.1x the reference there in seed 0 and 1.3x in seed 1; Direct exact."""
    ref = np.full((H, W, 3), 0.2)
    index = np.zeros((H, W), int)
    index[:, :W // 2], index[:, W // 2:] = 1, 2
    runs = []
    for f in (1.1, 1.3):
        direct = np.full((H, W, 3), 0.1)
        indirect = np.full((H, W, 3), 0.1)
        indirect[:, :W // 2] *= f
        z = np.zeros((H, W, 3))
        runs.append({"Direct": direct, "Indirect": indirect, "Caustic": z, "Emit": z,
                     "Combined": np.concatenate([direct + indirect, np.ones((H, W, 1))], -1)})
    return runs, ref, index, ["Wall", "Box"]


def test_region_means_per_pass_and_their_spread():
    runs, ref, index, names = _runs()
    rm = rn.region_means(runs, ref, index, names)
    wall, box = rm["Wall"], rm["Box"]
    assert wall["Direct"] == pytest.approx([0.5, 0.5])
    assert wall["Indirect"] == pytest.approx([0.55, 0.65])
    assert wall["Combined"] == pytest.approx([1.05, 1.15])
    assert box["Combined"] == pytest.approx([1.0, 1.0])
    assert rn._sem(wall["Indirect"]) == pytest.approx(0.05)      # std 0.0707 / sqrt(2)
    assert rm["all"]["px"] == 1600 and wall["px"] < 800             # eroded masks


def test_the_products_decomposition_runs_without_a_caustic_region():
    runs, ref, index, names = _runs()
    out, _ = pn.decompose(runs, ref, index, names, None)
    assert "caustic region" not in out and out["all outside"]["px"] == 1600
    assert out["Box"]["Combined"]["bias2"] == pytest.approx(0.0, abs=1e-12)
    assert out["Wall"]["Combined"]["mean"] == pytest.approx(1.1)
