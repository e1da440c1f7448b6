"""Partial results of progressive renders under fuzzing: `stpm merge` reads them as untrusted input.

A valid partial (``stpm render --pass-offset``) is mutated 200 ways -- bytes of the EXR overwritten,
the file truncated, the ``stpm:partial`` header's fields given hostile values or removed, its JSON
text garbled, sum layers dropped or filled with NaN -- and each mutation is merged with a valid
partial of the passes before it.  Every outcome must be a merge or one ``StpmError`` line; the
mutations run in a child process, so a crash of the EXR reader would fail this test rather than the
test run (issue 18: partial results go through the same checks as scene files).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from stpm_core.progressive import PassSums

ROOT = Path(__file__).resolve().parent.parent

_POOL = [None, True, -1, 0, 1, 2, 3, 2**31, 2**63, 10**400, 0.5, float("nan"), "", "x", "0" * 64, "g" * 64, [],
         [1], [4, 3], [0, 3], [4, -3], ["Combined"], ["Nope"], {}, "stpm-partial", "\x1b[2J"]

_CHILD = r"""
import json, sys
from stpm_core.errors import StpmError
from stpm_core.partial import merge
first, paths = sys.argv[1], sys.argv[2:]
for p in paths:
    try:
        merge([first, p])
        out = "ok"
        detail = ""
    except StpmError as e:
        out = "error" if "\n" not in str(e) else "bad-error"
        detail = str(e)[:200]
    except BaseException as e:  # noqa: BLE001
        out, detail = "uncaught", f"{type(e).__name__}: {e}"[:300]
    print(json.dumps({"file": p, "outcome": out, "detail": detail}), flush=True)
"""


def _sums(first, count, rng, H=6, W=8):
    s = PassSums(first)
    for i in range(first, first + count):
        img = {n: rng.random((H, W, c)).astype(np.float32) for n, c in (("Combined", 4), ("Depth", 1),
                                                                         ("Normal", 3), ("Caustic", 3))}
        s.add(i, img)
    return s


def test_merge_survives_200_mutated_partials(tmp_path):
    from stpm_core.imageio import read_exr, write_exr
    from stpm_core.partial import write_partial
    rng = np.random.default_rng(0)
    kw = dict(seed=3, scene_digest="a" * 64, settings_digest="b" * 64)
    first = write_partial(tmp_path / "first.exr", _sums(1, 3, rng), **kw)
    good = write_partial(tmp_path / "good.exr", _sums(4, 2, rng), **kw)
    data = good.read_bytes()
    parsed = read_exr(good)
    head = json.loads(parsed["_metadata"]["stpm:partial"])
    layers = {k: v for k, v in parsed.items() if not k.startswith("_")}
    meta = {k: v for k, v in parsed["_metadata"].items() if k.startswith("stpm:")}
    r = np.random.default_rng(18)
    paths = []
    for i in range(200):
        p = tmp_path / f"m{i}.exr"
        kind = i % 5
        if kind == 0:                                        # bytes overwritten
            b = bytearray(data)
            for _ in range(int(r.integers(1, 16))):
                b[int(r.integers(len(b)))] = int(r.integers(256))
            p.write_bytes(bytes(b))
        elif kind == 1:                                      # truncated
            p.write_bytes(data[: int(r.integers(len(data)))])
        elif kind == 2:                                      # a header field with a hostile value, or gone
            h = dict(head)
            key = list(h)[int(r.integers(len(h)))]
            if r.random() < 0.2:
                del h[key]
            else:
                h[key] = _POOL[int(r.integers(len(_POOL)))]
            write_exr(p, layers, {**meta, "stpm:partial": json.dumps(h)})
        elif kind == 3:                                      # the header's JSON text garbled
            text = bytearray(meta["stpm:partial"].encode())
            for _ in range(int(r.integers(1, 4))):
                text[int(r.integers(len(text)))] = int(r.choice(list(b'{}[]",:0123456789.eE-ntfa\\')))
            write_exr(p, layers, {**meta, "stpm:partial": text.decode("latin-1")})
        else:                                                # a sum layer dropped, or non-finite
            names = [k for k in layers if k.startswith("STPMSum")]
            name = names[int(r.integers(len(names)))]
            lay = dict(layers)
            if r.random() < 0.5:
                del lay[name]
            else:
                lay[name] = np.full_like(lay[name], np.nan if r.random() < 0.5 else np.inf)
            write_exr(p, lay, meta)
        paths.append(str(p))
    out = subprocess.run([sys.executable, "-c", _CHILD, str(first), *paths], cwd=tmp_path, capture_output=True,
                         text=True, timeout=600, env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    results = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    assert out.returncode == 0 and len(results) == 200, (out.returncode, out.stderr[-2000:], len(results))
    bad = [x for x in results if x["outcome"] not in ("ok", "error")]
    assert not bad, bad[:5]
    counts = {k: sum(x["outcome"] == k for x in results) for k in ("ok", "error")}
    assert counts["error"] > 100, counts                      # most mutations are refused, each in one line
