"""Run the STPM benchmarks: ``python -m benchmarks [name ...]``.

Discovers ``benchmarks/bench_*.py``, calls each module's ``run() -> dict``
(optionally only the modules whose name contains one of the arguments, e.g.
``python -m benchmarks rays``), prints one table per module and writes all
results with machine information to ``bench_out/results.json`` (merged with
the results of benchmarks not run this time).

``bench_room`` (issue 13's room: STPM's FINAL preset against Cycles at 1024 spp) needs bpy and
flip-evaluator (both installed by ``build.py``); its first run renders the Cycles reference
(about 10 min on 2 cores) and caches it in ``bench_out/cache/room/``, later runs take about
4 min.  ``python -m benchmarks room`` runs it alone.

``bench_product`` (issue 14's HDRI product shot, ``blend_scenes/hdri_product.blend``: STPM's FINAL preset
against Cycles at 1024 spp, inside and outside the glass caustics) needs the same; its first run renders two
Cycles references (about 7 min on 2 cores) into ``bench_out/cache/product/``, later runs take about 5 min.
``python -m benchmarks product`` runs it alone.

``bench_pool`` (issue 16's sunlit pool, ``blend_scenes/sunlit_pool.blend``: STPM PROGRESSIVE's time to the
caustic quality of Cycles' shadow caustics (MNEE) at 128 samples, both against a converged Cycles path trace)
renders its reference once (32768 spp at 96 x 72: about 11-45 min on 2 cores, by load) into
``bench_out/cache/pool/``; later runs take about 3 min.  ``python -m benchmarks pool`` runs it alone.
"""
from __future__ import annotations

import importlib
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path


def discover() -> list[str]:
    """Module names ``bench_*`` in this package, sorted."""
    here = Path(__file__).resolve().parent
    return sorted(p.stem for p in here.glob("bench_*.py"))


def format_value(v) -> str:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    if isinstance(v, int):
        return f"{v:d}"
    return f"{v:.4g}"


def print_table(name: str, results: dict, seconds: float) -> None:
    width = max([len(k) for k in results] + [10])
    print(f"\n== {name} ({seconds:.1f} s)")
    for k, v in results.items():
        print(f"  {k:<{width}}  {format_value(v)}")


def main(argv: list[str]) -> int:
    wanted = [a for a in argv if not a.startswith("-")]
    names = [n for n in discover() if not wanted or any(w in n for w in wanted)]
    if not names:
        print(f"no benchmark matches {wanted}; available: {', '.join(discover())}", file=sys.stderr)
        return 2
    report = {
        "machine": {"platform": platform.platform(), "python": platform.python_version(),
                    "cpus": os.cpu_count(), "when_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())},
        "benchmarks": {},
    }
    failed = 0
    for name in names:
        t0 = time.perf_counter()
        try:
            results = importlib.import_module(f"benchmarks.{name}").run()
        except Exception:
            failed += 1
            traceback.print_exc()
            results = {"error": traceback.format_exc(limit=1).strip().splitlines()[-1]}
        seconds = time.perf_counter() - t0
        print_table(name, results, seconds)
        report["benchmarks"][name] = {"seconds": seconds, "results": results}
    # Merge with earlier results so running one benchmark keeps the others
    out = Path("bench_out")
    out.mkdir(exist_ok=True)
    path = out / "results.json"
    try:
        old = json.loads(path.read_text())
        old.get("benchmarks", {}).update(report["benchmarks"])
        report["benchmarks"] = old.get("benchmarks", report["benchmarks"])
    except (OSError, ValueError):
        pass
    path.write_text(json.dumps(report, indent=2, default=float))
    print(f"\nwrote {out / 'results.json'}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
