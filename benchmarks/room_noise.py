"""Where STPM's error on the textured room sits: bias against variance, per surface and per pass.

The room's counterpart of :mod:`benchmarks.product_noise` (its ``decompose`` and ``print_table``,
without a caustic region): STPM's FINAL preset on ``blend_scenes/textured_room.blend`` rendered
with several seeds (``bench_room.stpm_final``), each seed's passes saved as
``stpm_passes_seed<N>.npz`` in a folder, then against the cached Cycles 1024-spp reference of
``python -m benchmarks room`` (render that first), per surface (the benchmark's eroded object
masks) and per pass (Emit, Direct, Indirect, Caustic):

* the decomposition of ``product_noise`` (mean over the reference's, the shares of variance and of
  squared bias);
* per surface and pass, each seed's region mean / the reference's region mean (Combined), their
  mean and its standard error over the seeds (``sem``): a pass whose mean moves between two
  folders by several ``sem`` moved for a reason, not by the draw;
* with a second folder (``--against``): the per-pass differences of those means, folder - against,
  with the standard error of the difference.

    python -m benchmarks.room_noise render FOLDER --seeds 0,1,2 [--set key=value ...]
    python -m benchmarks.room_noise report FOLDER [--against OTHER_FOLDER]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from benchmarks import bench_room as room
from benchmarks import product_noise as pn

PASSES = pn.PASSES + ("Combined",)


def render(folder: Path, seeds: list[int], overrides: dict | None = None) -> None:
    """Render the room's FINAL preset with each seed (``overrides`` after the preset) into folder:
    ``stpm_passes_seed<N>.npz``, ``timing_seed<N>.json``, ``objects.json``."""
    folder.mkdir(parents=True, exist_ok=True)
    for i, seed in enumerate(seeds):
        img, passes, tim = room.stpm_final(seed=seed, warm=(i == 0), overrides=overrides)
        np.savez_compressed(folder / f"stpm_passes_seed{seed}.npz", **passes)
        tim = {k: v for k, v in tim.items() if k != "warnings"}
        tim["overrides"], tim["when_utc"] = overrides or {}, time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
        (folder / f"timing_seed{seed}.json").write_text(json.dumps(tim, default=str))
        print(f"room_noise: seed {seed} render {tim['render_s']:.1f} s, mean {img.mean():.5f}", flush=True)
    (folder / "objects.json").write_text(json.dumps(room.object_names()))


def load(folder: Path) -> tuple[list[dict], list[int], np.ndarray, np.ndarray, list[str]]:
    """(per-seed passes, seeds, Cycles 1024 RGB (H, W, 3), object index (H, W), names)."""
    paths = sorted(folder.glob("stpm_passes_seed*.npz"), key=lambda p: int(p.stem.split("seed")[1]))
    if not paths:
        raise SystemExit(f"room_noise: no stpm_passes_seed*.npz in {folder} (run 'render' first)")
    runs = [dict(np.load(p)) for p in paths]
    ref, index, _, cached = room.reference()
    if not cached:
        print("room_noise: the Cycles reference was not cached: rendered it now", flush=True)
    names = json.loads((folder / "objects.json").read_text())
    return runs, [int(p.stem.split("seed")[1]) for p in paths], np.asarray(ref, np.float64), index, names


def region_means(runs, ref, index, names) -> dict:
    """{region: {pass: (n,) each seed's region-mean luminance / the reference's region mean}}."""
    R = ref @ room.LUMA
    out = {}
    regs = room.regions(index, names, ref)
    regs["all"] = np.ones(R.shape, bool)
    for name, m in regs.items():
        rm = max(float(R[m].mean()), 1e-12)
        out[name] = {k: np.array([float((np.asarray(r[k][..., :3], np.float64) @ room.LUMA)[m].mean()) / rm
                                  if k in r else 0.0 for r in runs]) for k in PASSES}
        out[name]["px"] = int(m.sum())
    return out


def _sem(x: np.ndarray) -> float:
    return float(x.std(ddof=1) / np.sqrt(x.size)) if x.size > 1 else float("nan")


def report(folder: Path, against: Path | None = None) -> dict:
    runs, seeds, ref, index, names = load(folder)
    out, _ = pn.decompose(runs, ref, index, names, None)
    print(f"room_noise: {folder} (seeds {seeds})")
    pn.print_table(out)
    rm = region_means(runs, ref, index, names)
    other = None
    if against is not None:
        runs_b, seeds_b, _, _, _ = load(against)
        other = region_means(runs_b, ref, index, names)
        print(f"\nper-pass region means / the reference's region mean: {folder.name} - {against.name} "
              f"(seeds {seeds} vs {seeds_b}); +- the standard error of the difference")
    else:
        print("\nper-pass region means / the reference's region mean, mean over seeds +- standard error")
    print(f"{'region':<16}{'px':>6} | " + "".join(f"{k:>17}" for k in PASSES))
    for name, r in sorted(rm.items(), key=lambda kv: -kv[1]["px"]):
        cells = []
        for k in PASSES:
            a = r[k]
            if other is None:
                cells.append(f"{a.mean():>9.4f}+-{_sem(a):.4f}")
            else:
                b = other[name][k]
                se = float(np.hypot(_sem(a), _sem(b)))
                cells.append(f"{a.mean() - b.mean():>+9.4f}+-{se:.4f}")
        print(f"{name:<16}{r['px']:>6} | " + "".join(f"{c:>17}" for c in cells))
    result = {"decomposition": out, "region_means": {n: {k: (v.tolist() if isinstance(v, np.ndarray) else v)
                                                          for k, v in r.items()} for n, r in rm.items()},
              "seeds": seeds}
    (folder / "room_noise.json").write_text(json.dumps(result, indent=1))
    return result


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.room_noise", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    r = sub.add_parser("render", help="render the room's FINAL preset with several seeds into FOLDER")
    r.add_argument("folder", type=Path)
    r.add_argument("--seeds", default="0,1,2", help="comma-separated seeds (default 0,1,2)")
    r.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="a render setting after the preset (JSON value, e.g. k_nearest=50); repeatable")
    p = sub.add_parser("report", help="decompose FOLDER's renders against the Cycles reference")
    p.add_argument("folder", type=Path)
    p.add_argument("--against", type=Path, default=None, help="a second folder: per-pass differences")
    a = ap.parse_args(argv)
    if a.cmd == "render":
        over = {}
        for kv in a.set:
            if "=" not in kv:
                ap.error(f"--set wants KEY=VALUE, got {kv!r}")
            k, v = kv.split("=", 1)
            try:
                over[k] = json.loads(v)
            except json.JSONDecodeError:
                over[k] = v
        try:
            seeds = [int(s) for s in a.seeds.split(",") if s.strip()]
        except ValueError:
            ap.error(f"--seeds wants comma-separated integers, got {a.seeds!r}")
        render(a.folder, seeds, over)
    else:
        report(a.folder, a.against)


if __name__ == "__main__":
    main()
