"""benchmarks.bench_error_budget's split of the error into bias^2 and variance, on synthetic images (numpy only)."""
import numpy as np

from benchmarks import bench_error_budget as eb  # noqa: E402


def test_budget_recovers_a_known_bias_and_noise():
    """Renders = exact + a fixed bias image (RMS 0.03) + noise of std 0.02: the split finds both, and
    bias^2 + variance is the MSE."""
    rng = np.random.default_rng(5)
    ref = rng.random((64, 96, 3))
    bias = 0.03 * np.where(rng.random((64, 96, 3)) < 0.5, -1.0, 1.0)
    renders = [ref + bias + rng.normal(0.0, 0.02, ref.shape) for _ in range(4)]
    b = eb.budget(renders, ref)
    assert abs(b["bias"] - 0.03) < 0.0015
    assert abs(b["std"] - 0.02) < 0.0005
    assert abs(b["bias"] ** 2 + b["std"] ** 2 - b["rmse"] ** 2) < 0.02 * b["rmse"] ** 2
    assert abs(b["bias2_share"] - 0.09 / 0.13) < 0.03


def test_budget_of_unbiased_noise_has_no_bias():
    """Pure noise: the seeds' own noise is taken out of their mean's squared error (without that term the
    bias would read std / sqrt(n) = 0.01)."""
    rng = np.random.default_rng(6)
    ref = rng.random((64, 96, 3))
    b = eb.budget([ref + rng.normal(0.0, 0.02, ref.shape) for _ in range(4)], ref)
    assert b["bias"] < 0.002
    assert b["bias2_share"] < 0.01
