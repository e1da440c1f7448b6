"""benchmarks.bench_product's caustic-region helpers on synthetic images (numpy only, no bpy)."""
import numpy as np
import pytest

pytest.importorskip("scipy")
from benchmarks import bench_product as bp  # noqa: E402


def test_caustic_parts_split_the_region_and_its_excess():
    # two parts in a 16 x 24 crop at rows 8.., columns 16..; STPM is 1.5x the converged light on the
    # first part (all of it in Emit + Direct) and exact on the second
    H, W, box = 32, 48, (8, 24, 16, 40)
    mask = np.zeros((H, W), bool)
    mask[10:14, 18:24] = True                      # 24 px
    mask[18:22, 30:38] = True                      # 32 px
    conv = np.full((16, 24, 3), 0.2)
    passes = {name: np.zeros((H, W, 4 if name == "Combined" else 3), np.float32)
              for name in ("Combined", "Emit", "Direct", "Caustic", "Indirect")}
    passes["Combined"][..., :3] = 0.2
    passes["Caustic"][...] = 0.05
    passes["Direct"][...] = 0.15
    passes["Combined"][10:14, 18:24, :3] = 0.3
    passes["Direct"][10:14, 18:24] = 0.25
    nocaustic = np.full((H, W, 3), 0.1)
    parts = bp.caustic_parts(passes, conv, nocaustic, mask, box)
    assert [p["px"] for p in parts] == [32, 24]                       # largest first
    big, small = parts
    assert small["rows"] == [10, 13] and small["columns"] == [18, 23]   # full-image coordinates
    assert small["ratio"] == pytest.approx(1.5) and big["ratio"] == pytest.approx(1.0)
    assert small["emit_direct"] == pytest.approx(0.25) and small["caustic"] == pytest.approx(0.05)
    assert small["share"] == pytest.approx(1.0, rel=1e-5) and big["share"] == pytest.approx(0.0, abs=1e-5)
    assert small["nocaustic"] == pytest.approx(0.1)
