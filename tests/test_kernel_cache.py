"""Editing one kernel file makes every cached kernel stale (numba_probe.invalidate_stale_caches).

numba checks a cached kernel against its own file only; a kernel that calls or
inlines a function from another file would keep running the old code.  Shown
on a two-file toy package compiled with ``cache=True`` into a private
``NUMBA_CACHE_DIR``: without the check the caller keeps the old callee, with it
the caller follows the edit.
"""
from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

from stpm_core.numba_probe import KERNEL_SOURCES, invalidate_stale_caches

pytest.importorskip("numba")

CALLEE = "from numba import njit\n\n@njit(cache=True, inline='always')\ndef f(x):\n    return x * {k}\n"
CALLER = textwrap.dedent("""\
    from numba import njit
    from toy.callee import f

    @njit(cache=True)
    def g(x):
        return f(x) + 1.0
    """)
RUN = "import sys; sys.path.insert(0, sys.argv[1]); from toy.caller import g; print(g(2.0))"


def _package(tmp_path, k):
    pkg = tmp_path / "toy"
    pkg.mkdir(exist_ok=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "callee.py").write_text(CALLEE.format(k=k))
    (pkg / "caller.py").write_text(CALLER)
    return pkg


def _g(tmp_path) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", RUN, str(tmp_path)], env=env, capture_output=True, text=True,
                         check=True)
    return float(out.stdout.strip())


def test_an_edit_of_a_called_file_reaches_the_cached_caller(tmp_path):
    pkg = _package(tmp_path, 3.0)
    assert invalidate_stale_caches(pkg, ("*.py",))          # first sight: stamp written
    assert not invalidate_stale_caches(pkg, ("*.py",))      # unchanged: nothing to do
    assert _g(tmp_path) == 7.0                              # compiled and cached
    (pkg / "callee.py").write_text(CALLEE.format(k=5.0))
    # numba alone would still load g with the old f: the caller's file did not change
    os.utime(pkg / "callee.py", None)
    assert _g(tmp_path) == 7.0
    assert invalidate_stale_caches(pkg, ("*.py",))          # the sources changed: every kernel stale
    assert _g(tmp_path) == 11.0


def test_the_product_checks_every_file_with_cached_kernels():
    """Every stpm_core module that compiles with cache=True is covered by KERNEL_SOURCES."""
    from pathlib import Path
    import stpm_core
    root = Path(stpm_core.__file__).parent
    covered = {p for pat in KERNEL_SOURCES for p in root.glob(pat)}
    cached = {p for p in root.rglob("*.py") if "cache=True" in p.read_text()}
    assert cached <= covered, sorted(str(p.relative_to(root)) for p in cached - covered)
