"""The compiled (numba) kernels: the one implementation of shading.

* :mod:`.closure` -- the material closure row every BSDF kernel reads;
* :mod:`.bsdf` -- BSDF evaluation, pdf and sampling per hit;
* :mod:`.lights` -- next-event light sampling and light shapes seen along rays;
* :mod:`.emission` -- photon emission per light;
* :mod:`.sampling` -- scalar helpers the other kernels call (chiefly :mod:`.lights` and
  :mod:`.emission`): vectors, warps, frames, light shapes (area shape, mesh-light points, spot mask);
* :mod:`.light_params` -- lights as data: one parameter row per light, its poses and a mesh
  light's triangles, packed once per LightSet (plain numpy, no kernels);
* :mod:`.paths` -- camera-path bookkeeping, next-event estimation, specular steps, film sums;
* :mod:`.photon_paths` -- one bounce of photon paths: deposit, BSDF sampling, Russian roulette.
* :mod:`.static_views` -- which camera-path segments see the same point at every instant (static
  views, whose photon queries read the shutter's average).

Ray casting (embree, or the numba BVH of :mod:`stpm_core.raycast`) happens
between kernel calls, one wavefront bounce at a time.

Every module here with kernels (all but :mod:`.light_params`) takes ``njit`` from
:mod:`stpm_core.numba_probe`; :func:`require` (called by
``render.render``, ``integrator.trace_image`` and ``photons.trace.trace_photon_paths``) turns
"numba unavailable" into one :class:`KernelsUnavailable` line: there is no numpy fallback.  The
numpy code these kernels replaced is the test oracles in ``tests/oracles/``.  numba's on-disk cache
of a kernel is invalidated only by edits of the kernel's own file, not of what it calls from
other modules: ``numba_probe.invalidate_stale_caches`` (run when ``stpm_core`` is imported) touches
every kernel source when any of them changed (docs/architecture.md, "Compiled kernels").

Compiling or loading: :func:`kernels_cached` looks in numba's cache index whether the camera-path
kernels are there for this CPU and these sources; :func:`first_use_progress` tells the user on a
process's first render whether the kernels load or compile; :func:`compile_stats` is what a
render reports (``kernels_compiled``: STPM functions numba compiled during it, 0 when everything
came from the cache).
"""
from __future__ import annotations

import numpy as np

from ..errors import StpmError
from ..numba_probe import AVAILABLE, CACHE, IMPORT_ERROR, compile_counts

__all__ = ["KernelsUnavailable", "require", "compile_error", "is_numba_error", "kernel_array", "kernels_cached",
           "first_use_progress", "compile_stats"]


class KernelsUnavailable(StpmError):
    """numba cannot be imported or cannot compile the kernels on this machine (one line: why)."""


_CHECKED = False


def require() -> None:
    """Raise :class:`KernelsUnavailable` unless the compiled kernels can run in this process.

    Checks once per process that numba imports (and is not switched off by
    ``STPM_NO_NUMBA``) and that it compiles a trivial function; STPM has no
    slow numpy path to fall back on.
    """
    global _CHECKED
    if _CHECKED:
        return
    if not AVAILABLE:
        raise KernelsUnavailable(f"the compiled kernels need numba, which is unavailable here ({IMPORT_ERROR})")
    try:
        from numba import njit

        @njit(cache=False)
        def _probe(x):
            return x + 1.0

        _probe(1.0)
    except Exception as exc:  # noqa: BLE001 -- any failure of numba / LLVM here is the cause to name
        raise KernelsUnavailable(f"numba cannot compile on this machine: {compile_error(exc)}") from exc
    _CHECKED = True


def compile_error(exc: BaseException) -> str:
    """One line naming why a kernel failed to compile or load: the exception type and its first line."""
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


def is_numba_error(exc: BaseException) -> bool:
    """Was exc raised by numba or llvmlite (a kernel that failed to compile or to load)?"""
    return type(exc).__module__.split(".")[0] in ("numba", "llvmlite")


def kernel_array(a, dtype=np.float64) -> np.ndarray:
    """a as a C-contiguous, writable array of dtype (a copy only when it is not one already).

    numba compiles one version of a kernel per argument type, and a read-only array (a
    ``np.broadcast_to`` view, which ``np.ascontiguousarray`` returns unchanged when its shape is
    already contiguous) is a different type from a writable one: every array handed to a kernel
    goes through here, so no scene or call form compiles a kernel twice
    (tests/test_kernel_signatures.py).
    """
    return np.require(a, dtype, ("C", "W"))


def kernels_cached():
    """True when the camera-path kernels are compiled in this process or in numba's on-disk cache for
    this CPU and these sources, False when the next render compiles them, None when unknown.

    Reads the index numba keeps per function (``<module>.<function>-<line>.py311.nbi``: its numba
    version, the source file's stamp and one entry per signature and CPU) for
    ``paths.classify_hits``, which every render uses; the cache is written all at once by a first
    render, so one function stands for the others (a scene that needs a kernel no earlier render
    needed still compiles that one: ``compile_stats`` reports it).
    """
    if not AVAILABLE:
        return None
    try:
        from . import paths
        dispatcher = paths.classify_hits
        if dispatcher.overloads:
            return True
        index = dispatcher._cache._cache_file._load_index()      # {} when missing, stale or another numba
        magic = dispatcher.targetctx.codegen().magic_tuple()     # (target triple, CPU name, CPU features)
        return any(key[1] == magic for key in index)
    except Exception:  # noqa: BLE001 -- numba internals differ: say nothing rather than something wrong
        return None


_FIRST_RENDER = [True]      # this process has not rendered yet


def first_use_progress(progress):
    """progress, after telling the user (on this process's first render) whether the kernels load
    from the cache or compile; while they compile, every message of that render says so."""
    if not _FIRST_RENDER[0] or progress is None:
        return progress
    _FIRST_RENDER[0] = False
    cached = kernels_cached()
    if cached:
        progress(0.0, "loading compiled kernels")
        return progress
    if cached is None:
        progress(0.0, "loading compiled kernels (or compiling them: about a minute on a first render)")
        return progress
    progress(0.0, "compiling kernels: the first render after installing or updating STPM (about a minute, "
                  "more with node materials; cached afterwards)")
    return lambda f, message: progress(f, f"{message} (compiling kernels on first use)" if message else message)


def compile_stats(before=(0, 0.0)) -> dict:
    """The render's report on compiled kernels since ``before`` (a :func:`compile_counts` value):
    ``kernels_compiled`` (STPM functions numba compiled, callees included; 0 = all loaded from the
    cache or already in memory), ``kernel_compile_s`` (seconds compiling) and ``kernel_cache`` (the
    cache folder, '' = numba's default ``__pycache__`` beside each module) and
    ``kernel_cache_source`` (why there: ``numba_probe.choose_cache_dir``)."""
    n, seconds = compile_counts()
    return {"kernels_compiled": int(n - before[0]), "kernel_compile_s": float(seconds - before[1]),
            "kernel_cache": CACHE.get("dir", ""), "kernel_cache_source": CACHE.get("source", "")}
