"""The shader-node interpreter compiled for the opcodes (and parts of them) one scene's programs use.

:mod:`.svm`'s interpreter (``svm._shade`` and the functions that dispatch on an opcode) handles
every node kind: a cold start compiles all of them (about a hundred numba functions, most of a
node scene's compile time) even when a scene's materials use three node kinds.  Every dispatching
test there reads ``_USE_<op> and op == _<op>``, with each ``_USE_<op>`` a module constant, True in
:mod:`.svm`.  A *variant* for a set of opcodes is a generated module that takes :mod:`.svm`'s
globals, sets ``_USE_<op> = False`` for the opcodes outside the set, and holds the source text of
:data:`DISPATCHERS` as :mod:`.svm` has it (read with ``inspect.getsource``: the node formulas are
written once, in :mod:`.svm`; the variant only re-compiles the dispatch around them).  numba folds
the constant flags and drops the dead branches before typing (its ``dead_branch_prune``), so a
function only a dropped branch calls is never compiled.  The leaf functions (``_mapping``,
``mix_color``, ``texture.tex_image_rows`` ...) are :mod:`.svm`'s own dispatchers, compiled and
cached once for every variant.

A variant of more features shades a scene's programs bit for bit as the scene's own: when one is
already compiled (:func:`covering`: in this process, or numba's index of its ``_shade`` in the cache
folder), the scene runs it instead of compiling its own (the fifth review's kitchen after
``hdri_product``: 1.5-1.7 s for its first plan against 6.6-7.9 s at load 2.5).

The generated file goes to the kernel cache folder (:func:`stpm_core.numba_probe.variant_dir`), so
numba's on-disk cache works for it as for any kernel file.  Its name is a hash of the kernel
sources (``numba_probe.sources_digest``: a callee's edit must not reuse a stale compile) and of
its text (which names the opcodes): the same opcodes give the same file in every process
(deterministic), an edit of any kernel source a new one.  A scene using every opcode, a process
with no folder to write to, or ``STPM_SVM_VARIANTS=0`` in the environment (one compile of the
whole interpreter for every scene: a test run with a cold cache over many node combinations)
runs :mod:`.svm`'s own ``_shade``.

The variant's dispatchers other than its entry ``_shade`` are compiled without numba's CPython and
C wrappers (they are called from compiled code only; unboxing the hit and scene tuples in a
wrapper cost about as much to compile as a dispatcher's body).  Variant files of other kernel
sources accumulate as kernels are edited: :func:`remove_stale` (run once per process, when the
first variant loads) removes those left alone for :data:`STALE_AGE_S`, with their compiled kernels.
"""
from __future__ import annotations

import hashlib
import importlib.util
import inspect
import os
import re
import sys
import threading
import time
from pathlib import Path

import numpy as np

from .. import numba_probe
from ..nodes.ops import BLEND_MODES, LAYOUT, OP
from . import svm, texture

__all__ = ["DISPATCHERS", "FEATURES", "program_ops", "variant_source", "variant_name", "interpreter", "covering",
           "remove_stale", "STALE_AGE_S"]

# The functions that test _USE_<feature> flags, and every function calling one of them up to the
# compiled entry svm._shade (each is compiled again in a variant; callees before callers)
DISPATCHERS = ((texture, "tex_image_rows"), (svm, "mix_color"), (svm, "_color_node"), (svm, "_value_node"),
               (svm, "_geometry_node"), (svm, "_texture_node"), (svm, "_procedural_node"), (svm, "_closure"),
               (svm, "_closures"), (svm, "_shade"))

# What a variant can leave out: every opcode (but END), each Mix Color blend mode (BLEND_<mode>),
# a closure's Normal input (SET_NORMAL), a Principled BSDF's Alpha other than a constant 1 (ALPHA),
# the Image Texture's look-ups (IMAGE_CLOSEST, IMAGE_LINEAR, IMAGE_LINEAR8: Linear on an 8-bit
# image without a working-space matrix, IMAGE_CUBIC, IMAGE_UDIM), Texture Coordinate's outputs
# (TEXCOORD_UV, TEXCOORD_GENERATED, TEXCOORD_OBJECT, TEXCOORD_NORMAL, TEXCOORD_REFLECTION)
FEATURES = frozenset(set(OP) - {"END"} | {f"BLEND_{b}" for b in BLEND_MODES} | {"SET_NORMAL", "ALPHA"}
                     | {"IMAGE_CLOSEST", "IMAGE_LINEAR", "IMAGE_LINEAR8", "IMAGE_CUBIC", "IMAGE_UDIM"}
                     | {"TEXCOORD_UV", "TEXCOORD_GENERATED", "TEXCOORD_OBJECT", "TEXCOORD_NORMAL", "TEXCOORD_REFLECTION"})
VARIANTS_ENV = "STPM_SVM_VARIANTS"     # "0": always the full interpreter
_DIGEST_TAG = "# kernel sources: "     # a variant file's line: the kernel sources' digest it was made from
STALE_AGE_S = 86400.0                  # remove_stale: files of another digest untouched for a day
_NAME = re.compile(r"svm_([0-9a-f]{20})(\.py|\.\d+\.tmp)")
_COMPILED = re.compile(r"svm_([0-9a-f]{20})\..+\.(nbi|nbc|pyc)")
_BLEND_NAMES = {v: k for k, v in BLEND_MODES.items()}
_NORMAL_OPERAND = {name: LAYOUT[name].index("*normal") + 1 for name in ("BSDF_PRINCIPLED", "BSDF_DIFFUSE",
                                                                        "BSDF_GLOSSY", "BSDF_GLASS")}


def program_ops(words: np.ndarray, hdr: np.ndarray | None = None) -> frozenset:
    """The :data:`FEATURES` one program's words (W,) float64 use (layout: :mod:`stpm_core.nodes.ops`),
    value section and closure section, walked instruction by instruction.  hdr: the texture pack's
    header (``TexturePack.arrays()[0]``), to tell 8-bit Linear look-ups (IMAGE_LINEAR8) from the
    others; None: a Linear look-up counts as both."""
    words = np.asarray(words, np.float64)
    size = {OP[name]: 1 + len(ops) for name, ops in LAYOUT.items()}
    names = {v: k for k, v in OP.items()}
    out = set()
    n_const = int(words[1])
    pc = 3 + n_const
    while pc < words.shape[0]:
        name = names[int(words[pc])]
        out.add(name)
        step = size[OP[name]]
        if name == "RAMP":
            step += 4 * int(words[pc + 3])
        elif name == "CURVES":
            step += 3 * int(words[pc + 3])
        elif name == "TEX_IMAGE":
            tiles, interp, tid = int(words[pc + 8]), int(words[pc + 2]), int(words[pc + 1])
            step += 2 * tiles
            if tiles > 0:
                out.add("IMAGE_UDIM")
                out.update(("IMAGE_CLOSEST", "IMAGE_LINEAR", "IMAGE_CUBIC"))    # (tex_lookup: all three)
            elif interp == 0:
                out.add("IMAGE_CLOSEST")
            elif interp == 1:
                plain = hdr is not None and 0 <= tid < hdr.shape[0] and texture._plain8.py_func(hdr, tid)
                out.add("IMAGE_LINEAR8" if plain else "IMAGE_LINEAR")
                if hdr is None:
                    out.add("IMAGE_LINEAR8")
            else:
                out.add("IMAGE_CUBIC")
        elif name == "MIX_COLOR":
            out.add(f"BLEND_{_BLEND_NAMES.get(int(words[pc + 1]), 'MIX')}")
        elif name == "TEXCOORD":
            gen, nrm, uv, obj, refl = (words[pc + 1 + LAYOUT["TEXCOORD"].index(k)] >= 0
                                       for k in ("*generated", "*normal", "*uv", "*object", "*reflection"))
            out.update(f for f, used in (("TEXCOORD_GENERATED", gen), ("TEXCOORD_OBJECT", obj), ("TEXCOORD_NORMAL", nrm),
                                         ("TEXCOORD_UV", uv), ("TEXCOORD_REFLECTION", refl)) if used)
        if "#offset" in LAYOUT[name] and words[pc + 1 + LAYOUT[name].index("#offset")] != 0:
            out.add("BUMP")                        # (a displaced read: svm gates displacement on BUMP)
        if name in _NORMAL_OPERAND and words[pc + _NORMAL_OPERAND[name]] >= 0:
            out.add("SET_NORMAL")
        if name == "BSDF_PRINCIPLED":
            a = int(words[pc + 1 + LAYOUT["BSDF_PRINCIPLED"].index("alpha")])   # a constant >= 1: always opaque
            if not (0 <= a < n_const and words[3 + a] >= 1.0):
                out.add("ALPHA")
        pc += step
    return frozenset(out)


def variant_source(ops) -> str:
    """The text of the variant module for the opcode names ``ops`` (see the module docstring)."""
    ops = frozenset(ops)
    unknown = ops - FEATURES - {"END"}
    if unknown:
        raise ValueError(f"unknown opcodes {sorted(unknown)}")
    homes = list(dict.fromkeys(mod for mod, _ in DISPATCHERS))          # texture, svm
    _check_names(homes)
    lines = [f'"""Generated by {__name__} from {", ".join(m.__name__ for m in homes)}: the shader',
             f'interpreter for {", ".join(sorted(ops)) or "(nothing)"} only.',
             'Do not edit: regenerated when missing."""',
             f"{_DIGEST_TAG}{numba_probe.sources_digest()}",
             "import importlib"]
    for mod in homes:                  # later modules' names win (svm's over texture's)
        lines += [f"globals().update({{k: v for k, v in vars(importlib.import_module({mod.__name__!r})).items()",
                  "                  if not k.startswith('__')})"]
    lines.append("")
    lines += [f"_USE_{name} = {name in ops}" for name in sorted(FEATURES)]
    # every dispatcher but the entry is called from compiled code only: no CPython wrapper, and no
    # C wrapper for any (numba compiles both for every function by default; unboxing the hit and
    # scene tuples, 30-odd arrays, costs as much to compile as a small function's body)
    lines += ["", "_JIT_ENTRY = JIT", "JIT = dict(JIT, no_cpython_wrapper=True, no_cfunc_wrapper=True)"]
    for mod, name in DISPATCHERS:
        if (mod, name) == DISPATCHERS[-1]:
            lines += ["", "", "JIT = dict(_JIT_ENTRY, no_cfunc_wrapper=True)      # (the entry: called from Python)"]
        lines += ["", "", inspect.getsource(getattr(mod, name).py_func).rstrip()]
    return "\n".join(lines) + "\n"


def _check_names(homes) -> None:
    """Every global name a copied function reads must mean in the variant what it means in the
    function's own module (the variant module holds all the homes' names, later ones winning)."""
    merged: dict = {}
    for mod in homes:
        merged.update(vars(mod))
    own = {name for _, name in DISPATCHERS}

    def names(code):
        out = set(code.co_names)
        for c in code.co_consts:
            if hasattr(c, "co_names"):
                out |= names(c)
        return out

    for mod, name in DISPATCHERS:
        for g in names(getattr(mod, name).py_func.__code__):
            if g in own or g.startswith("_USE_") or g not in vars(mod):
                continue
            if merged.get(g) is not vars(mod)[g]:
                raise RuntimeError(f"{mod.__name__}.{name} reads {g}, which another module's name hides in a variant")


_LOCK = threading.Lock()
_LOADED: dict = {}          # frozenset of feature names -> the compiled entry (a numba dispatcher)
_VARIANTS_LOADED: set = set()   # the feature sets of the variant modules loaded (and run) in this process


def interpreter(ops, reuse: bool = True):
    """The compiled ``_shade`` for programs using only the :data:`FEATURES` named in ``ops``
    (``ShadingData.ops``; None: any): :mod:`.svm`'s own when ops holds every feature or no variant
    file can be written, else the variant module's (generated and imported once per process): the
    variant of ``ops`` itself, or (``reuse``) of the smallest superset already compiled
    (:func:`covering`)."""
    if ops is None or os.environ.get(VARIANTS_ENV, "") == "0":
        return svm._shade
    ops = frozenset(ops) - {"END"}
    if FEATURES <= ops:
        return svm._shade
    if not reuse:
        with _LOCK:
            return _load(ops)
    with _LOCK:
        entry = _LOADED.get(ops)
        if entry is None:
            # a variant of more features already compiled (in this process, or in the cache folder)
            # shades these programs bit for bit as this set's own would: no compile
            cover = covering(ops)
            entry = _LOADED[ops] = _load(cover)
            if entry is not svm._shade:
                _VARIANTS_LOADED.add(cover)
        return entry


def _features_of(path: Path, digest: str):
    """The feature set a variant module file was generated for (its ``_USE_<feature> = True``
    lines), or None when it is not one of this install's kernel sources (``digest``) or its name is
    not its text's (:func:`variant_name`'s hash: a hand-edited, truncated or foreign file)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError):
        return None
    if f"\n{_DIGEST_TAG}{digest}\n" not in text:
        return None
    if "svm_" + hashlib.sha256((digest + "\0" + text).encode()).hexdigest()[:20] != path.stem:
        return None
    return frozenset(m.group(1) for m in re.finditer(r"^_USE_(\w+) = True$", text, re.M)) & FEATURES


def covering(ops, folder=None, cache_dirs=None) -> frozenset:
    """The feature set whose variant :func:`interpreter` loads for ``ops``: ``ops`` itself when its
    variant is compiled (in this process or in the cache folder) or when no compiled variant holds
    every feature of ``ops``; else the smallest such compiled variant's (ties: the first in sorted
    feature names).

    A variant of a superset shades ``ops``' programs bit for bit as ``ops``' own variant (the
    opcodes it keeps besides are never dispatched to: :mod:`.svm`'s full interpreter is the
    largest superset, ``tests/test_svm_variants.py``), so the choice changes no pixel and no plan,
    and a scene whose node kinds a scene rendered earlier already covers (the fifth review's kitchen
    after ``hdri_product``, ``sunlit_pool`` after ``textured_room``) compiles nothing: a new
    variant costs 5-12 s at load 4, 12-37 s at load 7-10 (docs/effects.md, "What the plan costs").  "Compiled in the
    cache folder": numba's index of the variant's ``_shade`` is there (:func:`_cache_dirs`)."""
    ops = frozenset(ops) - {"END"}
    loaded = [f for f in _VARIANTS_LOADED if ops <= f]
    if ops in loaded:
        return ops
    folder = numba_probe.variant_dir() if folder is None else folder
    if folder is None or not Path(folder).is_dir():
        return min(loaded, key=lambda f: (len(f), sorted(f))) if loaded else ops
    folder = Path(folder)
    compiled = set()
    for d in (_cache_dirs(folder) if cache_dirs is None else cache_dirs):
        d = Path(d)
        if d.is_dir():
            compiled.update(p.name.split(".", 1)[0] for p in d.glob("svm_*._shade-*.nbi"))
    try:
        if variant_name(ops) in compiled:
            return ops
    except (OSError, ValueError):
        return ops
    digest = numba_probe.sources_digest()
    found = list(loaded)
    for stem in sorted(compiled):
        path = folder / f"{stem}.py"
        if _NAME.fullmatch(path.name) and path.is_file():
            feats = _features_of(path, digest)
            if feats is not None and ops <= feats:
                found.append(feats)
    if not found:
        return ops
    return min(found, key=lambda f: (len(f), sorted(f)))


def variant_name(ops) -> str:
    """The variant module's file name (without .py) for ``ops``: ``svm_`` and 20 hex digits of the
    SHA-256 of the kernel sources' digest and the module's text."""
    text = variant_source(frozenset(ops) - {"END"})
    return "svm_" + hashlib.sha256((numba_probe.sources_digest() + "\0" + text).encode()).hexdigest()[:20]


def _load(ops):
    """Write (when missing) and import the variant module of ``ops``; svm._shade when that fails."""
    folder = numba_probe.variant_dir()
    if folder is None or not numba_probe.AVAILABLE:
        return svm._shade
    try:
        text = variant_source(ops)             # (OSError: no source files, e.g. a frozen install)
        name = variant_name(ops)
        h = name[len("svm_"):]
        path = Path(folder) / f"{name}.py"
        if not path.exists() or path.read_text() != text:
            # written once under a temporary name: another process never imports half a file, and a
            # file that is already there keeps its time stamp (numba's cache index checks it)
            tmp = path.with_name(f"{name}.{os.getpid()}.tmp")
            tmp.write_text(text)
            os.replace(tmp, path)
        _remove_stale_once(folder)
        modname = f"{svm.__package__}._svm_variant_{h}"
        mod = sys.modules.get(modname)
        if mod is None:
            spec = importlib.util.spec_from_file_location(modname, path)
            mod = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(mod)
            sys.modules[modname] = mod
        return mod._shade
    except (OSError, ImportError, SyntaxError):     # nowhere to write, a broken file: the full interpreter
        return svm._shade


_SWEPT: list = []


def _remove_stale_once(folder) -> None:
    """:func:`remove_stale` on the variant folder, once per process (when the first variant loads)."""
    if _SWEPT:
        return
    _SWEPT.append(True)
    try:
        remove_stale(folder)
    except OSError:                    # (a file another process is sweeping: the next process tries again)
        pass


def _cache_dirs(folder: Path) -> list:
    """Where numba keeps the compiled kernels of the modules in folder: its ``__pycache__``, and the
    folder's mirror under ``NUMBA_CACHE_DIR`` when that is set (numba's own locator's rule)."""
    out = [folder / "__pycache__"]
    try:
        from numba.core import caching, config
        if config.CACHE_DIR:
            sub = caching._CacheLocator.get_suitable_cache_subpath(str(folder / "x.py"))
            out.append(Path(config.CACHE_DIR) / sub)
    except Exception:  # noqa: BLE001 -- a numba without that locator: the __pycache__ folder only
        pass
    return out


def remove_stale(folder, digest: str | None = None, min_age: float = STALE_AGE_S, cache_dirs=None,
                 now: float | None = None) -> list:
    """Remove the variant modules in ``folder`` generated from other kernel sources than ``digest``
    (default: this install's, ``numba_probe.sources_digest()``) and numba's compiled kernels of
    them; returns the removed paths.  Every kernel edit writes new variant files (their names
    carry the sources' digest), so without this the kernel cache folder only grows.

    Conservative: only names this module writes (``svm_<20 hex>.py``, the ``.<pid>.tmp`` of an
    interrupted write, and in ``cache_dirs`` (default :func:`_cache_dirs`) numba's
    ``svm_<20 hex>.*.nbi`` / ``.nbc`` of such a module, and Python's ``.pyc`` of it); never a module whose digest line names
    ``digest``; and only when neither the module nor any of its compiled files changed in the last
    ``min_age`` seconds (a process running older kernel sources from the same folder may be
    writing or loading them now; one that loaded them earlier holds its code in memory).  A module
    without a digest line (written before there was one) counts as another digest's."""
    folder = Path(folder)
    digest = numba_probe.sources_digest() if digest is None else digest
    now = time.time() if now is None else now
    compiled: dict = {}                # module hash -> its compiled kernels' files
    for d in (_cache_dirs(folder) if cache_dirs is None else cache_dirs):
        d = Path(d)
        if d.is_dir():
            for p in d.iterdir():
                m = _COMPILED.fullmatch(p.name)
                if m:
                    compiled.setdefault(m.group(1), []).append(p)
    removed = []
    for p in sorted(folder.iterdir()) if folder.is_dir() else []:
        m = _NAME.fullmatch(p.name)
        if m is None or not p.is_file():
            continue
        files = [p]
        if m.group(2) == ".py":
            with open(p, encoding="utf-8", errors="replace") as f:
                head = [f.readline() for _ in range(6)]
            if f"{_DIGEST_TAG}{digest}\n" in head:
                continue               # this install's: never
            files += compiled.get(m.group(1), [])
        if any(now - f.stat().st_mtime < min_age for f in files):
            continue                   # touched lately: may be in use
        for f in files:
            try:
                f.unlink()
                removed.append(f)
            except FileNotFoundError:  # (another process swept it first)
                pass
    return removed
