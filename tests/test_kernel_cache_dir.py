"""Where the compiled kernels are cached (numba_probe.choose_cache_dir), and that a second process
loads them instead of compiling, also from a read-only install folder.

The cheap checks: the rules with a stubbed file system, then two real processes each for the
extension's folder (``STPM_KERNEL_CACHE``) and for a read-only copy of ``stpm_core`` used outside
Blender (the platform's user cache), compiling one small kernel module (``kernels.closure``).  The
whole extension, installed into Blender and rendering twice from a read-only install folder, is
``tests/test_addon_zip.py::test_installed_extension_compiles_once_into_its_user_folder``.
"""
from __future__ import annotations

import json
import os
import shutil
import stat
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import stpm_core.numba_probe as probe
from stpm_core._version import __version__

pytest.importorskip("numba")

ROOT = Path(__file__).resolve().parent.parent


def test_the_version_is_the_same_everywhere():
    assert __version__ == tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert __version__ == tomllib.loads((ROOT / "addon" / "blender_manifest.toml").read_text())["version"]


def test_the_cache_key_names_the_version_and_this_cpu():
    from llvmlite import binding
    key = probe.cache_key()
    assert key.startswith(__version__ + "-") and binding.get_host_cpu_name() in key
    assert "/" not in key and "\\" not in key


def test_the_rules_in_order(tmp_path, monkeypatch):
    readonly: set = set()
    monkeypatch.setattr(probe, "_writable", lambda p: not any(Path(p).is_relative_to(r) for r in readonly))
    monkeypatch.setattr(probe, "_user_cache_root", lambda: tmp_path / "user")
    pkg, ext = tmp_path / "pkg", tmp_path / "ext"
    key = probe.cache_key()
    # 1. the user's NUMBA_CACHE_DIR wins over everything
    assert probe.choose_cache_dir({"NUMBA_CACHE_DIR": "/x", probe.CACHE_ENV: str(ext)}, pkg) == (None, "NUMBA_CACHE_DIR")
    # 2. the extension's user folder, one sub-folder per version and CPU
    assert probe.choose_cache_dir({probe.CACHE_ENV: str(ext)}, pkg) == (ext / key, "extension")
    # 3. a writable package (a source checkout): numba's own __pycache__ beside each module
    assert probe.choose_cache_dir({}, pkg) == (None, "in-tree")
    # 4. a read-only package outside Blender: the platform's user cache
    readonly.add(pkg)
    assert probe.choose_cache_dir({}, pkg) == (tmp_path / "user" / "kernels" / key, "user-cache")
    # an unwritable extension folder falls through to the next rule
    readonly.add(ext)
    assert probe.choose_cache_dir({probe.CACHE_ENV: str(ext)}, pkg) == (tmp_path / "user" / "kernels" / key,
                                                                         "user-cache")
    readonly.add(tmp_path / "user")           # nowhere to write: numba's default (it compiles every time)
    assert probe.choose_cache_dir({}, pkg) == (None, "in-tree")


# A child: import the core, compile (or load) the closure kernels, report
_CHILD = r"""
import json, sys
sys.path.insert(0, sys.argv[1])
import numpy as np
from stpm_core import numba_probe
from stpm_core.kernels.closure import pack_materials
from stpm_core.scene import Material
import stpm_core
pack_materials([Material(base_color=np.array([0.5, 0.4, 0.3]), roughness=0.2)])
print("RESULT" + json.dumps({"cache": numba_probe.CACHE, "compiled": numba_probe.compile_counts()[0],
                             "core": stpm_core.__file__}))
"""


def _as_unprivileged_writer() -> list:
    """A command prefix under which mode bits hold: root ignores them unless it drops
    CAP_DAC_OVERRIDE (setpriv), as a read-only install folder is for an ordinary user."""
    if os.name != "posix" or os.geteuid() != 0:
        return []
    if shutil.which("setpriv") is None:
        pytest.skip("running as root without setpriv: a read-only folder cannot be made to hold")
    return ["setpriv", "--bounding-set=-dac_override,-dac_read_search", "--"]


def _child(path_entry: Path, env: dict, prefix=()) -> dict:
    env = {k: v for k, v in env.items() if k not in ("NUMBA_CACHE_DIR", "PYTHONPATH")}
    out = subprocess.run([*prefix, sys.executable, "-c", _CHILD, str(path_entry)], env=env, capture_output=True,
                         text=True, timeout=300)
    line = next((l for l in out.stdout.splitlines() if l.startswith("RESULT")), None)
    assert line is not None, out.stdout[-2000:] + out.stderr[-3000:]
    return json.loads(line[len("RESULT"):])


def _read_only_copy(tmp_path: Path) -> Path:
    """A copy of stpm_core (no caches) whose folders and files nobody may write."""
    dst = tmp_path / "site"
    shutil.copytree(ROOT / "stpm_core", dst / "stpm_core",
                    ignore=shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc", "*.pyc"))
    for d, dirs, files in os.walk(dst):
        for name in files:
            os.chmod(os.path.join(d, name), stat.S_IRUSR | stat.S_IRGRP | stat.S_IROTH)
        os.chmod(d, stat.S_IRUSR | stat.S_IXUSR | stat.S_IRGRP | stat.S_IXGRP | stat.S_IROTH | stat.S_IXOTH)
    return dst


def _writable_again(path: Path) -> None:
    for d, _dirs, files in os.walk(path):
        os.chmod(d, 0o755)
        for name in files:
            os.chmod(os.path.join(d, name), 0o644)


def test_the_extension_folder_holds_the_kernels_and_a_second_process_loads_them(tmp_path):
    site = _read_only_copy(tmp_path)
    env = dict(os.environ, **{probe.CACHE_ENV: str(tmp_path / "ext")})
    try:
        first = _child(site, env, _as_unprivileged_writer())
        second = _child(site, env, _as_unprivileged_writer())
    finally:
        _writable_again(site)
    assert Path(first["core"]).is_relative_to(site)
    folder = tmp_path / "ext" / probe.cache_key()
    assert first["cache"] == {"dir": str(folder), "source": "extension"}
    assert first["compiled"] > 0 and second["compiled"] == 0
    assert list(folder.rglob("closure.finish_closure-*.nbi")) and not list(site.rglob("*.nbi"))


def test_a_read_only_install_outside_blender_caches_in_the_users_cache_folder(tmp_path):
    site = _read_only_copy(tmp_path)
    env = {k: v for k, v in os.environ.items() if k != probe.CACHE_ENV}
    env["XDG_CACHE_HOME"] = str(tmp_path / "xdg")          # the platform's user cache folder (Linux)
    env["HOME"] = str(tmp_path / "home")                    # (macOS: ~/Library/Caches)
    env["LOCALAPPDATA"] = str(tmp_path / "appdata")         # (Windows)
    try:
        first = _child(site, env, _as_unprivileged_writer())
        second = _child(site, env, _as_unprivileged_writer())
    finally:
        _writable_again(site)
    assert first["cache"]["source"] == "user-cache"
    folder = Path(first["cache"]["dir"])
    assert folder.is_relative_to(tmp_path) and folder.name == probe.cache_key()
    assert first["compiled"] > 0 and second["compiled"] == 0
    assert not list(site.rglob("*.nbi"))
