"""Whether the compiled (numba) paths may be used in this process: one rule for every module.

``STPM_NO_NUMBA=1`` (any value but empty or 0) switches them off; otherwise
they are on when ``import numba`` works.  The result is ``AVAILABLE`` (and
``IMPORT_ERROR``, why not), and ``njit``: numba's decorator, or a placeholder
that leaves functions uncompiled when numba is off, so that the kernel modules
still import.

* Shading: every module of :mod:`stpm_core.kernels` with kernels (closure,
  bsdf, lights, emission, sampling, paths, photon_paths) imports ``njit`` from
  here, and :func:`stpm_core.kernels.require` turns ``AVAILABLE`` False (or a
  numba that cannot compile) into the one-line
  :class:`stpm_core.kernels.KernelsUnavailable`: a render stops, there is no
  numpy fallback for shading.
* Photon look-ups: :mod:`stpm_core.photons.kdtree` keeps its own
  ``AVAILABLE`` flag from :func:`probe`, because it can also be switched off
  later on its own (a compile failure); without numba (or with
  ``STPM_NO_NUMBA``) ``PhotonMap`` uses scipy's cKDTree.
* Ray casting (:mod:`stpm_core.raycast`) checks ``import numba`` itself when
  choosing between its embree / numba / numpy backends (``STPM_NO_NUMBA``
  does not switch those off).
"""
from __future__ import annotations

import os

__all__ = ["probe", "njit", "AVAILABLE", "IMPORT_ERROR", "invalidate_stale_caches", "KERNEL_SOURCES"]


def probe() -> tuple[bool, str]:
    """(available, reason when not): numba importable and not disabled by STPM_NO_NUMBA."""
    if os.environ.get("STPM_NO_NUMBA", "") not in ("", "0"):
        return False, "disabled by STPM_NO_NUMBA"
    try:
        import numba  # noqa: F401
    except Exception as exc:  # noqa: BLE001 -- any import failure: KernelsUnavailable for shading, scipy for the kd-tree
        return False, f"{type(exc).__name__}: {exc}"
    return True, ""


AVAILABLE, IMPORT_ERROR = probe()

if AVAILABLE:
    from numba import njit  # noqa: F401  (the compiled kernels' decorator)
else:                                          # pragma: no cover - depends on the platform
    def njit(*args, **kwargs):                 # noqa: D103 -- placeholder so kernel modules import
        if len(args) == 1 and callable(args[0]) and not kwargs:
            return args[0]

        def wrap(f):
            return f
        return wrap


# Files whose numba kernels are cached on disk (cache=True), relative to stpm_core/
KERNEL_SOURCES = ("kernels/*.py", "raycast/embree_kernels.py", "raycast/numba_backend.py", "raycast/bvh_build.py",
                  "photons/kdtree.py", "numba_probe.py", "nodes/ops.py")
_STAMP = "stpm-kernel-sources.sha256"


def invalidate_stale_caches(root=None, patterns=KERNEL_SOURCES) -> bool:
    """Make numba recompile every cached kernel when any kernel source changed; True if it did.

    numba's on-disk cache of a kernel is checked against its own file's mtime and size only, not
    against the files of the functions it calls or inlines (numba's "Notes on Caching", issue
    1833), so an edit of ``kernels/bsdf.py`` would leave ``kernels/paths.py``'s cached kernels
    running the old BSDF.  Here one SHA-256 over all of ``KERNEL_SOURCES`` is compared with the
    one recorded in ``stpm_core/__pycache__/stpm-kernel-sources.sha256``; when they differ,
    every kernel source's mtime is set to now (numba then treats each cached kernel as stale,
    wherever ``NUMBA_CACHE_DIR`` puts it) and the new digest is recorded.  Runs once, when
    ``stpm_core`` is imported, before any kernel module is.  A read-only install (whose files
    change only by reinstalling, which rewrites them) is left alone.  root / patterns: another
    package and its kernel files (tests).
    """
    import hashlib
    from pathlib import Path

    root = Path(__file__).resolve().parent if root is None else Path(root)
    files = sorted({p for pattern in patterns for p in root.glob(pattern)})
    h = hashlib.sha256()
    try:
        for p in files:
            h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
        stamp = root / "__pycache__" / _STAMP
        digest = h.hexdigest()
        if stamp.exists() and stamp.read_text().strip() == digest:
            return False
        for p in files:
            os.utime(p, None)
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{_STAMP}.{os.getpid()}.tmp")
        tmp.write_text(digest)
        os.replace(tmp, stamp)
        return True
    except OSError:
        return False
