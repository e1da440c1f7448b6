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

Where the compiled kernels are cached (every kernel is ``cache=True``): decided here, once, when
numba is imported, before any kernel module defines its dispatchers (numba picks a function's
cache folder when it is decorated).  :func:`choose_cache_dir` has the rules; :data:`CACHE` says
what was chosen.  An installed Blender extension sets ``STPM_KERNEL_CACHE`` to its user folder
(``addon/_core.py``), so the cache survives a read-only install folder and reinstalls keep their
own.  :func:`compile_counts` counts the kernels numba actually compiled in this process (numba's
``numba:compile`` event fires only on a cache miss): a render reports it (``kernels_compiled``).
"""
from __future__ import annotations

import os
import tempfile
import threading
import time
from pathlib import Path

from ._version import __version__

__all__ = ["probe", "njit", "AVAILABLE", "IMPORT_ERROR", "invalidate_stale_caches", "KERNEL_SOURCES",
           "CACHE_ENV", "CACHE", "choose_cache_dir", "cache_key", "compile_counts", "variant_dir", "sources_digest"]


def probe() -> tuple[bool, str]:
    """(available, reason when not): numba importable and not disabled by STPM_NO_NUMBA."""
    if os.environ.get("STPM_NO_NUMBA", "") not in ("", "0"):
        return False, "disabled by STPM_NO_NUMBA"
    try:
        import numba  # noqa: F401
    except Exception as exc:  # noqa: BLE001 -- any import failure: KernelsUnavailable for shading, scipy for the kd-tree
        return False, f"{type(exc).__name__}: {exc}"
    return True, ""


# The compiled kernels' cache folder: set by the Blender extension to its user folder
# (bpy.utils.extension_path_user); the compiled kernels go into a sub-folder named by cache_key()
CACHE_ENV = "STPM_KERNEL_CACHE"
_HERE = Path(__file__).resolve().parent


def cache_key() -> str:
    """The cache sub-folder of this STPM version on this CPU, e.g. ``0.1.0-skylake-avx512``.

    numba's own cache index already keys each entry by the CPU (name and features), the numba
    version and the source file's stamp; a folder per version and CPU keeps a shared home folder
    (a farm) or two installed versions from overwriting each other's index files.
    """
    try:
        from llvmlite import binding
        cpu = binding.get_host_cpu_name() or "cpu"
    except Exception:  # noqa: BLE001 -- any llvmlite failure: one folder for all CPUs (numba's keys still hold)
        cpu = "cpu"
    safe = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in cpu)
    return f"{__version__}-{safe}"


def _writable(folder: Path) -> bool:
    """Can numba write cache files into folder (created if missing)?  numba's own test."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=folder).close()
        return True
    except OSError:
        return False


def _user_cache_root() -> Path:
    """The platform's per-user cache folder for STPM (``~/.cache/stpm`` on Linux,
    ``~/Library/Caches/stpm`` on macOS, ``%LOCALAPPDATA%\\stpm\\Cache`` on Windows)."""
    from numba.misc.appdirs import AppDirs  # numba's vendored appdirs: what numba uses for its own
    return Path(AppDirs(appname="stpm", appauthor=False).user_cache_dir)


def choose_cache_dir(environ=None, package: Path = _HERE) -> tuple:
    """(folder or None, source): where numba should cache the kernels, by these rules in order.

    1. ``NUMBA_CACHE_DIR`` set by the user: numba's own setting wins (None, 'NUMBA_CACHE_DIR').
    2. ``STPM_KERNEL_CACHE`` (the Blender extension sets its user folder): ``<it>/<cache_key()>``
       ('extension').
    3. ``stpm_core``'s own ``__pycache__`` folders writable (a source checkout, a user install):
       numba's default, each module's ``__pycache__`` (None, 'in-tree').
    4. Otherwise (a read-only install used outside Blender): the platform's user cache folder,
       ``<it>/kernels/<cache_key()>`` ('user-cache').

    A chosen folder that cannot be written falls through to the next rule.
    """
    env = os.environ if environ is None else environ
    if env.get("NUMBA_CACHE_DIR"):
        return None, "NUMBA_CACHE_DIR"
    root = env.get(CACHE_ENV, "")
    if root:
        folder = Path(root) / cache_key()
        if _writable(folder):
            return folder, "extension"
    if _writable(Path(package) / "kernels" / "__pycache__"):
        return None, "in-tree"
    try:
        folder = _user_cache_root() / "kernels" / cache_key()
    except Exception:  # noqa: BLE001 -- no numba: nothing to cache
        return None, "in-tree"
    if _writable(folder):
        return folder, "user-cache"
    return None, "in-tree"                     # nowhere writable: numba compiles every process


def _configure_cache() -> dict:
    """Point numba's cache at :func:`choose_cache_dir`'s folder (numba.config and the environment,
    so that numba's config reload and child processes keep it); the chosen {'dir', 'source'}."""
    folder, source = choose_cache_dir()
    if folder is not None:
        import numba
        os.environ["NUMBA_CACHE_DIR"] = str(folder)
        numba.config.CACHE_DIR = str(folder)
    elif source == "NUMBA_CACHE_DIR":
        folder = Path(os.environ["NUMBA_CACHE_DIR"])
    return {"dir": str(folder) if folder is not None else "", "source": source}


class _CompileCounter:
    """Counts numba's compilations of STPM functions (``numba:compile`` events: numba fires them only
    when a function is compiled, not when it is loaded from the cache) and their seconds."""

    def __init__(self, package: str):
        self.package = package
        self.count = 0
        self.seconds = 0.0
        self._depth = 0                     # nested compiles (callees) hold numba's global compiler lock
        self._t0 = 0.0
        self._lock = threading.Lock()

    def _ours(self, event) -> bool:
        disp = (event.data or {}).get("dispatcher") if isinstance(event.data, dict) else None
        module = getattr(getattr(disp, "py_func", None), "__module__", "") or ""
        return module == self.package or module.startswith(self.package + ".")

    def on_start(self, event):
        with self._lock:
            if self._depth == 0:
                self._t0 = time.perf_counter()
            self._depth += 1
            if self._ours(event):
                self.count += 1

    def on_end(self, event):
        with self._lock:
            self._depth = max(self._depth - 1, 0)
            if self._depth == 0:
                self.seconds += time.perf_counter() - self._t0



AVAILABLE, IMPORT_ERROR = probe()
CACHE: dict = {"dir": "", "source": "none"}
_COUNTER = _CompileCounter(__name__.rpartition(".")[0])
if AVAILABLE:
    try:
        CACHE = _configure_cache()
        from numba.core import event as _event

        class _Listener(_CompileCounter, _event.Listener):
            """numba's Listener interface around the counter."""

        _COUNTER = _Listener(__name__.rpartition(".")[0])
        _event.register("numba:compile", _COUNTER)
    except Exception as _exc:  # noqa: BLE001 -- a numba without these: numba's default cache, no counts
        CACHE = {"dir": "", "source": f"numba default ({type(_exc).__name__})"}


def compile_counts() -> tuple:
    """(functions compiled, seconds compiling) in this process so far: STPM's numba functions
    compiled (not loaded from the cache), callees included; seconds of the outermost compiles."""
    return _COUNTER.count, _COUNTER.seconds

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
                  "raycast/contact.py", "photons/kdtree.py", "photons/hashgrid.py", "numba_probe.py", "nodes/ops.py")
_STAMP = "stpm-kernel-sources.sha256"


def _digest(root: Path, patterns) -> str:
    """SHA-256 over the files of ``patterns`` under root (their paths and bytes, in path order)."""
    import hashlib

    files = sorted({p for pattern in patterns for p in root.glob(pattern)})
    h = hashlib.sha256()
    for p in files:
        h.update(p.relative_to(root).as_posix().encode() + b"\0" + p.read_bytes() + b"\0")
    return h.hexdigest()


_SOURCES_DIGEST: list = []


def sources_digest() -> str:
    """The SHA-256 of this install's kernel sources (``KERNEL_SOURCES``), computed once per process:
    generated kernel files (``kernels.svm_variants``) carry it in their names, since numba checks a
    cached kernel against its own file only."""
    if not _SOURCES_DIGEST:
        _SOURCES_DIGEST.append(_digest(_HERE, KERNEL_SOURCES))
    return _SOURCES_DIGEST[0]


def variant_dir():
    """The folder for generated kernel modules (``kernels.svm_variants``), created if missing, or None
    when it cannot be written: ``svm_variants`` in the chosen cache folder (:data:`CACHE`), or in
    ``stpm_core/kernels/__pycache__`` when numba caches in-tree.  numba caches a generated module's
    kernels as any other's (next to it, or under ``NUMBA_CACHE_DIR``)."""
    base = Path(CACHE["dir"]) if CACHE.get("dir") else _HERE / "kernels" / "__pycache__"
    folder = base / "svm_variants"
    return folder if _writable(folder) else None


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
    root = Path(__file__).resolve().parent if root is None else Path(root)
    files = sorted({p for pattern in patterns for p in root.glob(pattern)})
    try:
        digest = _digest(root, patterns)
        stamp = root / "__pycache__" / _STAMP
        if stamp.exists() and stamp.read_text().strip() == digest:
            return False
        # the new digest is written first: where it cannot be (a read-only install, even one whose
        # owner could still touch the files' times) nothing is touched, or every process would
        # make every cached kernel stale again
        stamp.parent.mkdir(exist_ok=True)
        tmp = stamp.with_name(f"{_STAMP}.{os.getpid()}.tmp")
        tmp.write_text(digest)
    except OSError:
        return False
    try:
        for p in files:
            os.utime(p, None)
        os.replace(tmp, stamp)
        return True
    except OSError:
        try:
            tmp.unlink()
        except OSError:
            pass
        return False
