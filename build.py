#!/usr/bin/env python3
"""STPM developer entry point.

    python3 build.py demo     create/update .venv, render the demo scene, print output paths
    python3 build.py test     create/update .venv, run the whole test suite
    python3 build.py bench    create/update .venv, run the benchmarks (figures, not pass/fail)
    python3 build.py addon [--all-platforms]   build the Blender extension zip into dist/

Only the standard library is used here: this file must work on a fresh machine
with nothing but Python 3.11 installed.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent
VENV = ROOT / ".venv"
STAMP = VENV / ".stpm-installed"


def _venv_python() -> Path:
    sub = "Scripts/python.exe" if os.name == "nt" else "bin/python"
    return VENV / sub


def _find_python311() -> str:
    """A Python 3.11 interpreter: bpy 5.0.1 (Blender 4.2 to 5.0's Python) needs it."""
    if sys.version_info[:2] == (3, 11):
        return sys.executable
    for name in ("python3.11", "python3"):
        exe = shutil.which(name)
        if exe:
            out = subprocess.run([exe, "-c", "import sys;print(sys.version_info[:2]==(3,11))"],
                                 capture_output=True, text=True)
            if out.stdout.strip() == "True":
                return exe
    sys.exit("build.py: STPM needs Python 3.11 (the version Blender 4.2-5.0 embeds); none found on PATH")


def ensure_env() -> Path:
    """Create .venv and install the pinned dependencies; skip when pyproject.toml is unchanged."""
    digest = hashlib.sha256((ROOT / "pyproject.toml").read_bytes()).hexdigest()
    py = _venv_python()
    if py.exists() and STAMP.exists() and STAMP.read_text().strip() == digest:
        return py
    if not py.exists():
        print("build.py: creating .venv", flush=True)
        subprocess.check_call([_find_python311(), "-m", "venv", str(VENV)])
    print("build.py: installing dependencies into .venv (bpy is ~370 MB the first time)", flush=True)
    subprocess.check_call([str(py), "-m", "pip", "install", "-q", "--upgrade", "pip"])
    subprocess.check_call([str(py), "-m", "pip", "install", "-q", "-e", ".[test]"], cwd=ROOT)
    STAMP.write_text(digest)
    return py


def _run(py: Path, *args: str) -> int:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    return subprocess.call([str(py), *args], cwd=ROOT, env=env)


def main(argv: list[str]) -> int:
    if not argv or argv[0] in ("-h", "--help"):
        print(__doc__)
        return 0 if argv else 2
    cmd, rest = argv[0], argv[1:]
    if cmd not in ("demo", "test", "bench", "addon"):
        print(f"build.py: unknown command {cmd!r} (expected demo, test, bench or addon)", file=sys.stderr)
        return 2
    py = ensure_env()
    if cmd == "test":
        return _run(py, "-m", "pytest", "-q", "-ra", *rest)
    if cmd == "demo":
        return _run(py, "-m", "stpm_core.demo", *rest)
    if cmd == "bench":
        return _run(py, "-m", "benchmarks", *rest)
    return _run(py, "-m", "addon.build_zip", *rest)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
