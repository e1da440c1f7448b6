"""Error floor of *any* per-instant estimator at S samples per pixel (not in the project).

Every time-dependent estimator here (TEMPORAL, KD4D, a sheared ball) gives each camera sample an
estimate of the irradiance at its own point and time.  With a perfect estimate -- the exact
radiance L(x, y, t) of the benchmark scene (tests/test_compare.py: moving_caustic_radiance, what
analytic_moving_caustic integrates, evaluated per sample) -- the only error left is camera
sampling: the film's filter-importance-sampled positions and stratified times
(the numpy oracle of the tracer's camera samples, tests/oracles/integrator_numpy.camera_samples).  This
script renders that oracle at several S and compares its RMSE with ACCUMULATION N=16's (0.0169,
bias-dominated): a photon estimator at S samples per pixel can never be better than the oracle.

    .venv/bin/python benchmarks/compare_experiments/oracle.py
"""
from common import *  # noqa: F401,F403

from oracles.integrator_numpy import camera_samples  # tests/ on sys.path (common)
from test_compare import moving_caustic_radiance as radiance  # tests/ on sys.path (common)


def oracle_image(scene, S, seed, time_override=None, res=(96, 64)):
    """(H, W) mean of the exact radiance over S camera samples per pixel (FIS positions, stratified times)."""
    W, H = res
    iy, ix = np.divmod(np.arange(W * H), W)
    px, py, t = camera_samples(ix, iy, S, scene.shutter, np.random.default_rng(seed), time_override,
                               filter_width=1.5)
    pix = 2.4 / W
    L = radiance(-1.2 + px * pix, 0.8 - py * pix, t)            # t: normalised shutter times
    return L.reshape(W * H, S).mean(axis=1).reshape(H, W)


if __name__ == "__main__":
    scene, ref = moving_caustic_scene((96, 64)), exact((96, 64))[..., 0]
    print("per-instant oracle (exact irradiance per camera sample):")
    for S in (1, 2, 4, 8, 16, 32, 64):
        e = [rmse(oracle_image(scene, S, seed), ref) for seed in (1, 2, 3)]
        print(f"  S = {S:3d} samples/pixel: RMSE {np.mean(e):.4f} (seeds {min(e):.4f}-{max(e):.4f})", flush=True)
    print("accumulation's camera side (16 exact stills at (i + 1/2)/16, S samples each):")
    for S in (1, 4):
        img = np.mean([oracle_image(scene, S, 100 + i, time_override=(i + 0.5) / 16) for i in range(16)], axis=0)
        print(f"  S = {S}: RMSE {rmse(img, ref):.4f}")
