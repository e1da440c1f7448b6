"""Image output: multilayer OpenEXR with Blender's channel names, and an sRGB PNG preview.

Channel names follow Blender's multilayer EXR: ``<view layer>.<pass>.<channel>``,
e.g. ``ViewLayer.Combined.R``, ``ViewLayer.Depth.Z``, ``ViewLayer.Normal.X``.
The passes and their channel letters come from the one table
:data:`stpm_core.film.PASSES` (re-exported by :mod:`stpm_core.render`), so the
film, this writer and the Blender add-on cannot disagree.

Images are row 0 = top (the contract in docs/internal-api.md), which is also
the EXR / PNG scanline order: no flip here.
"""
from __future__ import annotations

import json
import os
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .errors import StpmError

__all__ = ["write_exr", "read_exr", "write_png", "read_png", "linear_to_srgb",
           "channel_names", "VIEW_LAYER", "write_json", "atomic_output", "temp_path", "remove_pending_temps"]

VIEW_LAYER = "ViewLayer"


# ----------------------------------------------------------------------------
# Atomic outputs: write a hidden temporary file in the same folder, rename it into place
# ----------------------------------------------------------------------------
_PENDING: set[str] = set()   # temporary files being written (removed by remove_pending_temps on a hard abort)


def temp_path(path) -> Path:
    """The temporary name :func:`atomic_output` writes ``path`` under: hidden, same folder, same suffix.

    Same folder, so the final ``os.replace`` is a rename on one file system (atomic);
    same suffix, so OpenImageIO picks the same format from the name.
    """
    path = Path(path)
    return path.with_name(f".{path.stem}.stpm-tmp-{os.getpid()}{path.suffix}")


def _unlink_quietly(path) -> None:
    try:
        os.unlink(path)
    except OSError:
        pass


@contextmanager
def atomic_output(path, *, commit: bool = True):
    """Yield a temporary path to write ``path``'s content to; rename it over ``path`` at the end.

    Any exception (or KeyboardInterrupt) inside the block removes the temporary
    file, so a failed or interrupted write never leaves a partial file under the
    final name, nor a stray temporary one.  ``commit=False`` leaves the
    temporary file for the caller to rename (several outputs committed together)
    or remove; it stays registered for :func:`remove_pending_temps` until then.
    """
    path = Path(path)
    tmp = temp_path(path)
    _PENDING.add(str(tmp))
    try:
        yield tmp
        if commit:
            os.replace(tmp, path)
    except BaseException:
        _unlink_quietly(tmp)
        _PENDING.discard(str(tmp))
        raise
    if commit:
        _PENDING.discard(str(tmp))


def commit_temp(tmp, path) -> None:
    """Rename a temporary file left by ``atomic_output(..., commit=False)`` into place."""
    os.replace(tmp, path)
    _PENDING.discard(str(tmp))


def discard_temp(tmp) -> None:
    """Remove a temporary file left by ``atomic_output(..., commit=False)``."""
    _unlink_quietly(tmp)
    _PENDING.discard(str(tmp))


def remove_pending_temps() -> None:
    """Remove every temporary output file still being written (a hard abort calls this before exiting)."""
    for name in list(_PENDING):
        discard_temp(name)


def _oiio_write(path: Path, spec, pixels: np.ndarray, what: str) -> None:
    """Write ``pixels`` with ``spec`` to ``path`` through OpenImageIO (StpmError on failure)."""
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        raise StpmError(f"cannot write {what}: {oiio.geterror() or 'open failed'}")
    try:
        ok = out.write_image(pixels)
        err = out.geterror()
    finally:
        out.close()
    if not ok:
        raise StpmError(f"cannot write {what}: {err}")


def _passes_table():
    """The (name, channels, channel_ids) table of every pass STPM writes (``film.ALL_PASSES``: the
    passes of ``render.PASSES``, then the denoising passes)."""
    from .film import ALL_PASSES
    return ALL_PASSES


def channel_names(passes: dict, view_layer: str = VIEW_LAYER) -> list[tuple[str, str, int]]:
    """(pass name, full channel name, channel index) for every channel written, in table order.

    Passes in ``passes`` but not in the table (extra passes) follow, with
    channel letters RGBA / XYZ picked by their channel count.
    """
    out = []
    known = set()
    for name, count, ids in _passes_table():
        known.add(name)
        if name in passes:
            for c in range(count):
                out.append((name, f"{view_layer}.{name}.{ids[c]}", c))
    for name in sorted(set(passes) - known):
        count = np.asarray(passes[name]).reshape(*np.shape(passes[name])[:2], -1).shape[2]
        ids = "Z" if count == 1 else ("RGB" if count == 3 else "RGBA"[:count] if count <= 4 else None)
        for c in range(count):
            out.append((name, f"{view_layer}.{name}.{ids[c] if ids else c}", c))
    return out


# The Color Interop Forum's ids of the working spaces (Blender writes one as ``colorInteropID``)
INTEROP_IDS = {"REC709": "lin_rec709_scene", "REC2020": "lin_rec2020_scene", "ACESCG": "lin_ap1_scene"}


def write_exr(path, result, metadata: dict | None = None, *, half: bool = False,
              view_layer: str = VIEW_LAYER, atomic: bool = True, working: str = "REC709") -> Path:
    """Write a multilayer OpenEXR (ZIP compression) with Blender's channel names.

    ``atomic``: write a temporary file next to ``path`` and rename it into place
    (:func:`atomic_output`), so ``path`` is never a partial file.

    Parameters
    ----------
    path : output file name.
    result : a ``RenderResult`` (``.passes``, optional ``.stats``) or a dict
        pass name -> (H, W, C) float array (row 0 = top).
    metadata : extra string attributes (values that are not strings are written
        as JSON).  ``result.stats`` is added as ``stpm:stats`` (JSON).
    half : write 16-bit half floats instead of 32-bit floats (Depth stays 32-bit).
    working : the scene's working colour space (``stpm_core.colorspaces``): the passes are in it;
        another than Linear Rec.709 is named in the ``colorInteropID`` attribute, as Blender does.
    """
    import OpenImageIO as oiio

    passes = result if isinstance(result, dict) else result.passes
    if not passes:
        raise StpmError("write_exr: no passes to write")
    shapes = {n: np.asarray(a).shape for n, a in passes.items()}
    H, W = next(iter(shapes.values()))[:2]

    # Gather every channel, in table order, into one (H, W, C) float32 block
    cols, names = [], []
    for name, full, c in channel_names(passes, view_layer):
        a = np.asarray(passes[name], dtype=np.float32)
        if a.ndim == 2:
            a = a[:, :, None]
        if a.shape[:2] != (H, W):
            raise StpmError(f"write_exr: pass {name} has shape {a.shape}, expected ({H}, {W}, C)")
        cols.append(a[:, :, c])
        names.append(full)
    pixels = np.ascontiguousarray(np.stack(cols, axis=-1))

    # Header: channels, compression, metadata
    fmt = oiio.HALF if half else oiio.FLOAT
    spec = oiio.ImageSpec(int(W), int(H), len(names), fmt)
    spec.channelnames = tuple(names)
    if half:
        # Depth stays 32-bit float as in Blender's half EXRs (1e10 background overflows half)
        spec.channelformats = tuple(oiio.TypeDesc(oiio.FLOAT) if n.endswith(".Depth.Z") else oiio.TypeDesc(oiio.HALF)
                                    for n in names)
    spec.attribute("compression", "zip")
    if working != "REC709":
        spec.attribute("colorInteropID", INTEROP_IDS[working])
    # Tell readers the alpha channel of Combined is alpha (Blender does the same).
    if f"{view_layer}.Combined.A" in names:
        spec.alpha_channel = names.index(f"{view_layer}.Combined.A")
    meta = dict(metadata or {})
    stats = getattr(result, "stats", None)
    if stats and "stpm:stats" not in meta:
        meta["stpm:stats"] = stats
    for key, value in meta.items():
        text = value if isinstance(value, str) else json.dumps(value, default=_json_default)
        spec.attribute(key if ":" in key else f"stpm:{key}", text)

    path = Path(path)
    if not atomic:
        _oiio_write(path, spec, pixels, f"EXR {path}")
        return path
    with atomic_output(path) as tmp:
        _oiio_write(tmp, spec, pixels, f"EXR {path}")
    return path


def _json_default(o):
    """JSON for numpy scalars and arrays inside stats / settings."""
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, np.generic):
        return o.item()
    return str(o)


@contextmanager
def _native_stderr_captured():
    """Hold what native code writes to file descriptor 2 (OpenEXR's own error printer writes there,
    past Python's sys.stderr) in a temporary file; yields a list that receives the text at the end.
    An unreadable file then gives one line of ours, not the library's lines besides."""
    import sys
    import tempfile
    got: list = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):      # no real descriptor 2 (embedded): nothing to hold
        yield got
        return
    with tempfile.TemporaryFile() as hold:
        os.dup2(hold.fileno(), 2)
        try:
            yield got
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            hold.seek(0)
            got.append(hold.read(4096).decode("utf-8", "replace"))


def read_exr(path, view_layer: str = VIEW_LAYER) -> dict:
    """Read a multilayer EXR written by :func:`write_exr` (or Blender).

    Returns a dict pass name -> (H, W, C) float32, plus ``"_channels"``: the
    channel names in file order and ``"_metadata"``: string attributes.
    A file that cannot be read raises StpmError (one line); the OpenEXR library's
    own messages are not printed.
    """
    import OpenImageIO as oiio

    with _native_stderr_captured():
        inp = oiio.ImageInput.open(str(path))
        if inp is None:
            raise StpmError(f"cannot read EXR {path}: {oiio.geterror()}".splitlines()[0])
        try:
            spec = inp.spec()
            pixels = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
            err = inp.geterror() if pixels is None else ""
            try:
                names = list(spec.channelnames)
            except (UnicodeDecodeError, ValueError) as e:
                raise StpmError(f"cannot read EXR {path}: corrupt channel names ({type(e).__name__})") from None
            meta = {}
            for a in spec.extra_attribs:
                try:
                    meta[a.name] = a.value
                except (UnicodeDecodeError, ValueError, TypeError):    # a damaged attribute: not readable
                    continue
        finally:
            inp.close()
    shape = (spec.height, spec.width, spec.nchannels)
    pixels = None if pixels is None else np.asarray(pixels, dtype=np.float32)
    if pixels is None or pixels.size != shape[0] * shape[1] * shape[2]:
        why = (err or oiio.geterror() or "no pixels").strip().splitlines()
        raise StpmError(f"cannot read EXR {path}: truncated or corrupt ({why[0] if why else 'no pixels'})")
    pixels = pixels.reshape(shape)
    groups: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        parts = n.split(".")
        key = parts[1] if len(parts) == 3 and parts[0] == view_layer else ".".join(parts[:-1]) or n
        groups.setdefault(key, []).append(i)
    out = {k: pixels[:, :, idx].copy() for k, idx in groups.items()}
    out["_channels"] = names
    out["_metadata"] = meta
    return out


def linear_to_srgb(x: np.ndarray) -> np.ndarray:
    """The sRGB transfer curve (IEC 61966-2-1) on linear values clipped to [0, 1].

    ``12.92 x`` for ``x <= 0.0031308``, else ``1.055 x^(1/2.4) - 0.055``.
    NaN and -inf map to 0, +inf to 1 (a bad pixel never spreads or crashes).
    """
    x = np.nan_to_num(np.asarray(x, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)


def write_png(path, rgb: np.ndarray, *, atomic: bool = True, working: str = "REC709") -> Path:
    """Write an 8-bit sRGB preview of linear RGB(A) ``rgb`` (H, W, 3|4), row 0 = top.

    ``atomic``: through a temporary file renamed into place, as :func:`write_exr`.

    Colour channels (in the working space ``working``, converted to Rec.709 first) are clipped to
    [0, 1] and sRGB-encoded; alpha (if given) is dropped: the preview is opaque, as the world
    colour is rendered.
    """
    import OpenImageIO as oiio

    from .colorspaces import WORKING_SPACES, conversion
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] < 3:
        raise StpmError(f"write_png: expected (H, W, 3) RGB, got {rgb.shape}")
    M = conversion(WORKING_SPACES[working], "REC709")
    lin = rgb[:, :, :3] if M is None else np.asarray(rgb[:, :, :3], np.float64) @ M.T
    v = np.round(linear_to_srgb(lin) * 255.0).astype(np.uint8)
    H, W = v.shape[:2]
    spec = oiio.ImageSpec(W, H, 3, oiio.UINT8)
    spec.attribute("oiio:ColorSpace", "sRGB")
    path = Path(path)
    if not atomic:
        _oiio_write(path, spec, np.ascontiguousarray(v), f"PNG {path}")
        return path
    with atomic_output(path) as tmp:
        _oiio_write(tmp, spec, np.ascontiguousarray(v), f"PNG {path}")
    return path


def write_json(path, data, *, atomic: bool = True) -> Path:
    """Write ``data`` as indented JSON (numpy values made plain), atomically as :func:`write_exr`."""
    path = Path(path)
    text = json.dumps(data, indent=2, default=_json_default) + "\n"
    if not atomic:
        path.write_text(text)
        return path
    with atomic_output(path) as tmp:
        tmp.write_text(text)
    return path


def read_png(path) -> np.ndarray:
    """Read an 8-bit image -> (H, W, C) uint8 (for tests)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise StpmError(f"cannot read {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        px = inp.read_image(0, 0, 0, spec.nchannels, oiio.UINT8)
    finally:
        inp.close()
    return np.asarray(px, dtype=np.uint8).reshape(spec.height, spec.width, spec.nchannels)
