"""Scene-file loader fuzzing in forked children of one preloaded server process.

Used by tests/test_loader_fuzz.py.  ``python -P tests/loader_fuzz.py VALID.stpm WORKDIR SEED COUNT JOBS``
starts a server that imports the loader (numpy, stpm_core, the node compiler) and loads the
valid file once, then forks one child per mutation -- so a mutation costs a fork and a load,
not an interpreter start -- at most JOBS at a time.  Each child:

* limits its address space (``RLIMIT_AS``: the server's size + :data:`MEMORY_HEADROOM`) and
  arms a :data:`ALARM_S` alarm;
* builds mutation ``i`` of the valid file (:func:`mutate`, deterministic in SEED and i) and
  writes it to WORKDIR;
* loads it as ``stpm render`` / ``stpm plan`` would, and does what the command does next with
  a loaded scene before rendering (:func:`use_as_the_cli_does`);
* reports one JSON line: ``"ok"`` (it loaded), ``"error"`` (a documented one-line
  ``SceneError`` naming the file, at most ``scenefile.MAX_ERROR_LINE`` characters), or
  ``"uncaught"`` / ``"bad-error"`` with the detail.

The server adds ``"crash"`` (the child died of a signal), ``"hang"`` (SIGALRM) and ``"lost"``
(it exited without a report), keeps every failing file under WORKDIR/failures/, and prints a
summary JSON line: counts per outcome, per mutation kind, and the failures.
"""
from __future__ import annotations

import io
import json
import os
import random
import resource
import signal
import sys
import time
import traceback
import zipfile

ALARM_S = 10                      # a child still running after this long is a hang
MEMORY_HEADROOM = 1 << 30         # address space a child may add to the server's (bytes)

KINDS = ("bytes", "truncate", "member_bytes", "npy_header", "member_ops", "json_value", "json_text",
         "schema", "zip_meta")

# JSON values put anywhere in the header
_JSON_POOL = [None, True, False, 0, 1, -1, 2, 7, 2**31, 2**63, -2**63, 10**400, -10**400, 0.5, -0.0, 1e308, -1e308,
              1e-320, float("nan"), float("inf"), -float("inf"), "", "x", "POINT", "PHOTON", "false", "\x1b]0;t\x07",
              "\u202e", "a" * 5000, [], [1], [1, 2, 3], [0.0, 0.0, 0.0], ["a"], [[1, 2], [3]], {}, {"a": 1},
              {"link": ["BSDF", "BSDF"]}, [True, False], [-1048574, 1048574], [5, 1]]


# ----------------------------------------------------------------------------
# Mutations
# ----------------------------------------------------------------------------
def _members(data: bytes) -> list[tuple[zipfile.ZipInfo, bytes]]:
    with zipfile.ZipFile(io.BytesIO(data)) as z:
        return [(info, z.read(info)) for info in z.infolist()]


def _zip(members, compress=True) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED) as z:
        for name, blob in members:
            z.writestr(name, blob)
    return buf.getvalue()


def _npy(a) -> bytes:
    import numpy as np
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asarray(a), allow_pickle=False)
    return buf.getvalue()


def _json_paths(obj, prefix=()):
    yield prefix
    if isinstance(obj, dict):
        for k, v in obj.items():
            yield from _json_paths(v, prefix + (k,))
    elif isinstance(obj, list):
        for i, v in enumerate(obj):
            yield from _json_paths(v, prefix + (i,))


def _header_of(members) -> tuple[int, dict]:
    import numpy as np
    for j, (info, blob) in enumerate(members):
        if info.filename == "header.npy":
            a = np.load(io.BytesIO(blob), allow_pickle=False)
            return j, json.loads(a.tobytes().decode())
    raise KeyError("header")


def _with_header(members, j, header_bytes: bytes) -> list:
    import numpy as np
    out = [(i.filename, b) for i, b in members]
    out[j] = ("header.npy", _npy(np.frombuffer(header_bytes, np.uint8)))
    return out


def mutate(valid: bytes, seed: int, i: int) -> tuple[str, bytes, str]:
    """Mutation ``i``: (kind, file bytes, what was done)."""
    import numpy as np
    r = random.Random(seed * 1_000_003 + i)
    kind = KINDS[i % len(KINDS)]
    members = _members(valid)
    names = [info.filename for info, _ in members]
    if kind == "bytes":                                   # overwrite bytes of the compressed file
        b = bytearray(valid)
        edits = [(r.randrange(len(b)), r.randrange(256)) for _ in range(r.choice([1, 2, 4, 16]))]
        for pos, val in edits:
            b[pos] = val
        return kind, bytes(b), f"bytes {edits[:4]}"
    if kind == "truncate":
        n = r.randrange(len(valid))
        return kind, valid[:n], f"truncated to {n} of {len(valid)} bytes"
    if kind == "member_bytes":                            # overwrite bytes inside one inflated member
        j = r.randrange(len(members))
        blob = bytearray(members[j][1])
        edits = [(r.randrange(len(blob)), r.randrange(256)) for _ in range(r.choice([1, 2, 8]))] if blob else []
        for pos, val in edits:
            blob[pos] = val
        out = [(info.filename, b) for info, b in members]
        out[j] = (names[j], bytes(blob))
        return kind, _zip(out), f"{names[j]}: bytes {edits[:4]}"
    if kind == "npy_header":                              # rewrite one member's declared shape / dtype
        j = r.randrange(len(members))
        blob = members[j][1]
        shape = tuple(r.choice([0, 1, 2, 3, 4, 7, 2**31, 2**40, 10**12]) for _ in range(r.randrange(0, 4)))
        descr = r.choice(["<f4", "<f8", "<i4", "<i8", "|u1", "<u2", "<f2", "|b1", ">f4", "<c8", "|O", "<U4",
                          "|V8", "<M8[s]"])
        head = {"descr": descr, "fortran_order": r.random() < 0.2, "shape": shape}
        buf = io.BytesIO()
        try:
            np.lib.format.write_array_header_1_0(buf, head)
        except ValueError:
            buf = io.BytesIO(b"\x93NUMPY\x01\x00" + b"\x10\x00" + b"{'descr': 'x'}  \n")
        payload = blob[len(blob) - r.randrange(0, len(blob) + 1):] if r.random() < 0.5 else blob[128:]
        out = [(info.filename, b) for info, b in members]
        out[j] = (names[j], buf.getvalue() + payload)
        return kind, _zip(out), f"{names[j]}: npy header {head}"
    if kind == "member_ops":                              # delete / rename / duplicate / replace a member
        out = [(info.filename, b) for info, b in members]
        j = r.randrange(len(out))
        op = r.choice(["delete", "rename", "duplicate", "replace", "extra", "stored"])
        if op == "delete":
            del out[j]
        elif op == "rename":
            out[j] = (r.choice(names) if r.random() < 0.5 else out[j][0] + "x", out[j][1])
        elif op == "duplicate":
            out.append((out[j][0], out[r.randrange(len(out))][1]))
        elif op == "replace":
            shape = tuple(r.randrange(0, 5) for _ in range(r.randrange(0, 4)))
            dtype = r.choice([np.float32, np.float64, np.int32, np.int64, np.uint8, np.int8, np.bool_, np.float16])
            val = r.choice([0, 1, -1, 7, 1e30, np.nan, np.inf, 0.5, 255, 2**31 - 1])
            with np.errstate(invalid="ignore", over="ignore"):
                out[j] = (out[j][0], _npy(np.full(shape, val).astype(dtype)))
        elif op == "extra":
            out.append((f"extra{r.randrange(9)}.npy", _npy(np.zeros(3))))
        return kind, _zip(out, compress=op != "stored"), f"{op} {names[j]}"
    if kind in ("json_value", "schema", "json_text"):
        j, header = _header_of(members)
        if kind == "json_text":                           # edit the JSON text itself
            text = bytearray(json.dumps(header).encode())
            edits = [(r.randrange(len(text)), r.choice(b'{}[]",:0123456789.eE-+ntfa\\\x00\xff\xc3'))
                     for _ in range(r.choice([1, 2, 3]))]
            for pos, val in edits:
                text[pos] = val
            return kind, _zip(_with_header(members, j, bytes(text))), f"header text {edits}"
        if kind == "schema":                              # a settings or metadata field with a foreign value
            from stpm_core.schema import METADATA
            from stpm_core.settings import RenderSettings
            value = r.choice(_JSON_POOL)
            if r.random() < 0.5:
                spec = r.choice(RenderSettings.SPECS)
                if not isinstance(header.get("settings"), dict):
                    header["settings"] = {}
                header["settings"][spec.name] = value
                what = f"settings.{spec.name}"
            else:
                spec = r.choice(METADATA)
                header["metadata"][spec.name] = value
                what = f"metadata.{spec.name}"
            return kind, _zip(_with_header(members, j, json.dumps(header).encode())), f"{what} = {value!r:.60}"
        paths = [p for p in _json_paths(header) if p]
        done = []
        for _ in range(r.choice([1, 1, 2, 3])):
            path = r.choice(paths)
            parent = header
            try:
                for k in path[:-1]:
                    parent = parent[k]
                if r.random() < 0.25 and isinstance(parent, dict):
                    del parent[path[-1]]
                    done.append(f"del {path}")
                else:
                    v = r.choice(_JSON_POOL)
                    parent[path[-1]] = v
                    done.append(f"{path} = {v!r:.40}")
            except (KeyError, IndexError, TypeError):
                continue
        return kind, _zip(_with_header(members, j, json.dumps(header).encode())), "; ".join(done)
    if kind == "zip_meta":                                # a member's sizes / method in the zip directory
        b = bytearray(valid)
        cd = bytes(b).rfind(b"PK\x01\x02") if r.random() < 0.5 else bytes(b).find(b"PK\x03\x04", r.randrange(len(b)))
        if cd < 0:
            cd = 0
        field = r.choice([(10, 2), (20, 4), (24, 4), (28, 2), (30, 2), (42, 4), (8, 2), (18, 4), (22, 4)])
        pos = cd + field[0]
        val = r.choice([0, 1, 0xFFFFFFFF, 0x7FFFFFFF, 12, 99, r.randrange(1 << 32)])
        b[pos:pos + field[1]] = (val & ((1 << (8 * field[1])) - 1)).to_bytes(field[1], "little")
        return kind, bytes(b), f"zip field at {pos} (+{field[0]}) = {val}"
    raise ValueError(kind)


# ----------------------------------------------------------------------------
# A child: load the mutation as the CLI would
# ----------------------------------------------------------------------------
def use_as_the_cli_does(scene, settings, name: str) -> None:
    """What ``stpm render`` / ``stpm plan`` do with a loaded scene before rendering."""
    from stpm_core.blend_loader import blend_frame_range
    from stpm_core.command_common import check_memory, safe_text, settings_from_dict
    from stpm_core.nodes import compile_graph
    from stpm_core.scene import scene_warnings, validate_scene
    if settings is None:
        settings = settings_from_dict(None, name)
    validate_scene(scene)
    for m in scene.materials:
        if m.graph is not None:
            compile_graph(m.graph, len(scene.textures), [])
    blend_frame_range(scene)
    for w in scene.metadata.get("warnings", []):
        safe_text(w)
    scene_warnings(scene)
    check_memory(scene.resolution, settings.method, settings)
    settings.replace(samples=settings.samples)
    float(scene.frame).is_integer()


def _child(valid: bytes, seed: int, i: int, workdir: str, limit: int, report_fd: int) -> None:
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    signal.alarm(ALARM_S)
    out = os.fdopen(report_fd, "w")
    kind, what = "?", ""
    try:
        from stpm_core.errors import SceneError, StpmError
        from stpm_core.scenefile import MAX_ERROR_LINE, load_scene_with_settings
        kind, data, what = mutate(valid, seed, i)
        path = os.path.join(workdir, f"m{i}.stpm")
        with open(path, "wb") as f:
            f.write(data)
        try:
            scene, settings = load_scene_with_settings(path)
            use_as_the_cli_does(scene, settings, os.path.basename(path))
            result = {"outcome": "ok"}
        except SceneError as e:
            msg = str(e)
            good = "\n" not in msg and msg.startswith(f"m{i}.stpm: ") and len(msg) <= MAX_ERROR_LINE
            result = {"outcome": "error" if good else "bad-error", "detail": msg[:300]}
        except StpmError as e:        # the CLI's other one-line errors (memory check, settings)
            msg = str(e)
            result = {"outcome": "error" if "\n" not in msg else "bad-error", "detail": msg[:300]}
        except BaseException as e:    # noqa: BLE001 -- anything else is a finding
            result = {"outcome": "uncaught", "detail": f"{type(e).__name__}: {str(e)[:200]}",
                      "traceback": traceback.format_exc()[-1500:]}
        if result["outcome"] in ("ok", "error"):
            os.unlink(path)
    except BaseException as e:        # noqa: BLE001 -- the harness itself failed
        result = {"outcome": "harness", "detail": f"{type(e).__name__}: {e}", "traceback": traceback.format_exc()}
    result.update(i=i, kind=kind, what=what[:300])
    out.write(json.dumps(result) + "\n")
    out.flush()
    os._exit(0)


# ----------------------------------------------------------------------------
# The server
# ----------------------------------------------------------------------------
def _vm_size() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmSize:"):
                return int(line.split()[1]) * 1024
    return 4 << 30


def serve(valid_path: str, workdir: str, seed: int, count: int, jobs: int) -> dict:
    """Run ``count`` mutations, at most ``jobs`` children at a time; returns the summary."""
    # Preload everything a child uses, and load the valid file once (warm caches, lazy imports)
    from stpm_core.scenefile import load_scene_with_settings
    import stpm_core.command_common  # noqa: F401
    import stpm_core.blend_loader  # noqa: F401
    valid = open(valid_path, "rb").read()
    scene, settings = load_scene_with_settings(valid_path)
    use_as_the_cli_does(scene, settings, "valid.stpm")
    mutate(valid, seed, 0)
    limit = _vm_size() + MEMORY_HEADROOM
    os.makedirs(os.path.join(workdir, "failures"), exist_ok=True)

    counts: dict = {}
    by_kind: dict = {}
    failures = []
    running: dict[int, tuple[int, int, float]] = {}      # pid -> (i, read fd, start)
    reports: dict[int, bytes] = {}
    t0 = time.perf_counter()
    nxt = 0

    def finish(pid: int, status: int) -> None:
        i, fd, _ = running.pop(pid)
        data = reports.pop(fd, b"")
        while True:
            chunk = os.read(fd, 1 << 16)
            if not chunk:
                break
            data += chunk
        os.close(fd)
        if os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            res = {"outcome": "hang" if sig == signal.SIGALRM else "crash", "i": i,
                   "detail": signal.Signals(sig).name}
        else:
            try:
                res = json.loads(data.decode().strip().splitlines()[-1])
            except (ValueError, IndexError):
                res = {"outcome": "lost", "i": i, "detail": f"exit {os.WEXITSTATUS(status)}: {data[-300:]!r}"}
        if "kind" not in res:
            kind, _, what = mutate(valid, seed, i)
            res.update(kind=kind, what=what[:300])
        counts[res["outcome"]] = counts.get(res["outcome"], 0) + 1
        k = by_kind.setdefault(res["kind"], {})
        k[res["outcome"]] = k.get(res["outcome"], 0) + 1
        if res["outcome"] not in ("ok", "error"):
            _, data_bytes, _ = mutate(valid, seed, i)
            keep = os.path.join(workdir, "failures", f"seed{seed}_m{i}.stpm")
            with open(keep, "wb") as f:
                f.write(data_bytes)
            res["file"] = keep
            failures.append(res)
        stray = os.path.join(workdir, f"m{i}.stpm")
        if os.path.exists(stray):
            os.unlink(stray)

    while nxt < count or running:
        while nxt < count and len(running) < jobs:
            r, w = os.pipe()
            pid = os.fork()
            if pid == 0:
                os.close(r)
                try:
                    _child(valid, seed, nxt, workdir, limit, w)
                finally:
                    os._exit(70)
            os.close(w)
            running[pid] = (nxt, r, time.perf_counter())
            nxt += 1
        pid, status = os.wait()
        if pid in running:
            finish(pid, status)
    return {"count": count, "seed": seed, "jobs": jobs, "seconds": time.perf_counter() - t0,
            "counts": counts, "by_kind": by_kind, "failures": failures[:50],
            "memory_limit_mib": limit >> 20, "alarm_s": ALARM_S}


if __name__ == "__main__":
    valid_path, workdir, seed, count, jobs = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4]), \
        int(sys.argv[5])
    print(json.dumps(serve(valid_path, workdir, seed, count, jobs)), flush=True)
