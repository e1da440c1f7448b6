"""Where STPM's error on the product shot sits: bias against variance, per surface and per pass.

Reads what ``python -m benchmarks product`` wrote with ``STPM_BENCH_SEEDS=1,2`` (or more seeds):
``stpm_passes.npz`` (the file's seed) and ``stpm_passes_seed<N>.npz`` (the others, whole frames),
``index.npy``, ``objects.json``, ``caustic_mask.npy``, and the Cycles 1024-spp reference from the
cache.  Per surface (the benchmark's eroded object masks, the caustic region apart) and per pass
(Emit, Direct, Indirect, Caustic), over the n seeds' images X_s (linear luminance, per pixel):

* ``mean`` = mean_s X_s over the region / the reference's mean over it;
* ``var`` = sum over pixels of the seeds' unbiased variance s^2 (one render's noise energy);
* ``bias2`` = sum over pixels of (mean_s X_s - R)^2 - s^2 / n (the squared bias, the one-render
  noise taken out; it still holds the reference's own 1024-spp noise);
* shares of the image's total (outside the caustic region), so "where the error is" reads directly.

Writes ``mean_vs_cycles.png`` (the seeds' mean | Cycles 1024) and ``std_stpm.png`` (per-pixel
standard deviation, x4) into the same folder.

    python -m benchmarks.product_noise [bench_out/product]
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from benchmarks import bench_product as bp
from benchmarks import bench_room as room

LUMA = room.LUMA
PASSES = ("Emit", "Direct", "Indirect", "Caustic")


def load(folder: Path) -> tuple[list[dict], np.ndarray, np.ndarray, list[str], np.ndarray]:
    """(per-seed passes, Cycles 1024 RGB (H, W, 3), object index (H, W), names, caustic mask (H, W))."""
    runs = [dict(np.load(folder / "stpm_passes.npz"))]
    for p in sorted(folder.glob("stpm_passes_seed*.npz")):
        runs.append(dict(np.load(p)))
    ref, _, _, _ = bp.reference()
    index = np.load(folder / "index.npy")
    names = json.loads((folder / "objects.json").read_text())
    return runs, np.asarray(ref, np.float64), index, names, np.load(folder / "caustic_mask.npy")


def decompose(runs, ref, index, names, caustic=None) -> dict:
    """{region: {pass: {mean, var, bias2}}} (see the module docstring) and the per-pixel images;
    caustic (H, W) bool or None (no caustic region: ``benchmarks.room_noise``)."""
    n = len(runs)
    lum = lambda a: np.asarray(a[..., :3], np.float64) @ LUMA
    X = {k: np.stack([lum(r[k]) if k in r else np.zeros(ref.shape[:2]) for r in runs]) for k in PASSES}
    X["Combined"] = np.stack([lum(r["Combined"]) for r in runs])
    R = ref @ LUMA
    regs = room.regions(index, names, ref)
    if caustic is None:
        caustic = np.zeros(R.shape, bool)
    else:
        regs["caustic region"] = caustic
    regs = {k: (v & ~caustic if k != "caustic region" else v) for k, v in regs.items()}
    regs["all outside"] = ~caustic
    out = {"seeds": n}
    for name, m in regs.items():
        row = {"px": int(m.sum()), "ref_mean": float(R[m].mean())}
        for k, x in X.items():
            mu, s2 = x.mean(0), x.var(0, ddof=1)
            row[k] = {"mean": float(mu[m].mean() / max(R[m].mean(), 1e-12)), "var": float(s2[m].sum()),
                      "abs_mean": float(mu[m].mean())}
            if k == "Combined":
                row[k]["bias2"] = float(((mu - R) ** 2 - s2 / n)[m].sum())
        out[name] = row
    return out, X


def print_table(out: dict) -> None:
    """The decomposition as a table: per region the mean over the reference's, the shares of the
    image's one-render variance and squared bias, and each pass's mean luminance and variance share."""
    tot = out["all outside"]["Combined"]
    print(f"{out['seeds']} seeds; outside the caustic: var {tot['var']:.2f}, bias^2 {tot['bias2']:.2f} "
          f"(sums over pixels of luminance^2)")
    print(f"{'region':<16}{'px':>6}{'refY':>8}{'mean':>7}{'var%':>7}{'bias2%':>8} | "
          + "".join(f"{k + ' Y':>11}{'var%':>6}" for k in PASSES))
    for name, r in sorted(out.items(), key=lambda kv: -kv[1]["px"] if isinstance(kv[1], dict) else 0):
        if not isinstance(r, dict):
            continue
        c = r["Combined"]
        s = (f"{name:<16}{r['px']:>6}{r['ref_mean']:>8.4f}{c['mean']:>7.3f}{100 * c['var'] / tot['var']:>7.1f}"
             f"{100 * c['bias2'] / tot['var']:>8.1f} | ")
        s += "".join(f"{r[k]['abs_mean']:>11.4f}{100 * r[k]['var'] / tot['var']:>6.1f}" for k in PASSES)
        print(s)


def main(folder: Path) -> None:
    runs, ref, index, names, caustic = load(folder)
    out, X = decompose(runs, ref, index, names, caustic)
    print_table(out)
    (folder / "noise_decomposition.json").write_text(json.dumps(out, indent=1))
    from stpm_core.imageio import write_png
    mean_rgb = np.mean([np.asarray(r["Combined"][..., :3], np.float64) for r in runs], 0)
    H = ref.shape[0]
    write_png(folder / "mean_vs_cycles.png",
              np.concatenate([mean_rgb, np.ones((H, 4, 3)), ref], 1).astype(np.float32))
    sd = np.sqrt(X["Combined"].var(0, ddof=1))
    write_png(folder / "std_stpm.png", np.repeat(4 * sd[..., None], 3, -1).astype(np.float32))


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else bp.OUT)
