"""STPM benchmarks: ``python -m benchmarks [name ...]`` runs ``bench_*.py`` modules.

Each module exposes ``run() -> dict`` of named measurements; results are printed
as a table and written to ``bench_out/results.json``.
"""
