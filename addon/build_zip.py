"""Build the STPM Blender extension zip (``python3 build.py addon [--all-platforms]``).

Layout of ``dist/stpm-<version>-<platform>.zip`` (manifest at the root, as
Blender's "Install from Disk" expects)::

    blender_manifest.toml   # + platforms = [...] and wheels = [...]
    __init__.py, engine.py, ... , export/   # the add-on
    stpm_core/                              # the core, imported as a sub-package
    wheels/*.whl                            # scipy, OpenImageIO, numba, ... embreex (where it exists)

numpy is left out: Blender ships it (1.26 in Blender 4.2 to 5.0).  Wheels are
fetched with ``pip download`` for CPython 3.11 and the target platform tags.
embreex (Embree 4) exists for Linux x86_64 and Windows x64 only; elsewhere
``stpm_core.raycast`` uses its numba backend (see docs/raycast.md).

Options:  --all-platforms   linux-x64, macos-arm64, macos-x64, windows-x64
          --platform NAME   one of those (default: this machine)
          --no-wheels       skip pip downloads (the zip then needs the
                            dependencies already importable in Blender)
          --out DIR         output directory (default dist/)
"""
from __future__ import annotations

import argparse
import platform
import re
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ADDON = ROOT / "addon"
CORE = ROOT / "stpm_core"
WHEEL_CACHE = ROOT / "dist" / "wheel-cache"

# Blender platform name -> pip --platform tags (newest first is not required)
PLATFORM_TAGS: dict[str, list[str]] = {
    "linux-x64": ["manylinux2014_x86_64", "manylinux_2_17_x86_64", "manylinux_2_28_x86_64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64", "macosx_14_0_arm64"],
    "macos-x64": ["macosx_10_9_x86_64", "macosx_10_14_x86_64", "macosx_10_15_x86_64", "macosx_14_0_x86_64"],
    "windows-x64": ["win_amd64"],
}


def _pinned_dependencies() -> dict[str, str]:
    """name -> 'name==version' for the core's dependencies in pyproject.toml (one source of truth)."""
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    pins = {}
    for dep in deps:
        req = dep.split(";")[0].strip()
        pins[re.split(r"[=<>!~ ]", req, maxsplit=1)[0].lower()] = req
    return pins


_PINS = _pinned_dependencies()
# numba's compiler backend: a dependency of numba pip would resolve; wheels are fetched --no-deps.
LLVMLITE = "llvmlite==0.44.0"
# Bundled Python dependencies (numpy excluded: Blender has it; embreex only where it has wheels).
WHEELS_ALL = [req for name, req in _PINS.items() if name not in ("numpy", "embreex")] + [LLVMLITE]
WHEELS_EMBREE = {"linux-x64": _PINS["embreex"], "windows-x64": _PINS["embreex"]}
# Wheels some platforms lack (flip-evaluator: none for macOS x86_64); bundled where they exist.
OPTIONAL_WHEELS = (_PINS["flip-evaluator"],)
# Files of addon/ that are developer tools, not part of the extension
EXCLUDE = {"build_zip.py", "blender_manifest.toml"}

REQUIRED_KEYS = ("schema_version", "id", "version", "name", "tagline", "maintainer", "type",
                 "blender_version_min", "license")


class ManifestError(ValueError):
    """The manifest would be refused by Blender."""


def this_platform() -> str:
    """Blender's name for the machine we run on."""
    machine = platform.machine().lower()
    arm = machine in ("arm64", "aarch64")
    if sys.platform.startswith("linux"):
        return "linux-arm64" if arm else "linux-x64"
    if sys.platform == "darwin":
        return "macos-arm64" if arm else "macos-x64"
    if sys.platform == "win32":
        return "windows-arm64" if arm else "windows-x64"
    raise SystemExit(f"build_zip: unknown platform {sys.platform}/{machine}")


def validate_manifest(text: str, *, zip_names: set[str] | None = None) -> dict:
    """Parse a manifest and check what Blender checks; returns the parsed dict.

    Raises ManifestError naming the first problem.
    """
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ManifestError(f"manifest is not valid TOML: {exc}") from None
    for key in REQUIRED_KEYS:
        if key not in data:
            raise ManifestError(f"manifest lacks required key {key!r}")
    if data["schema_version"] != "1.0.0":
        raise ManifestError(f"schema_version must be '1.0.0', got {data['schema_version']!r}")
    if not re.fullmatch(r"[A-Za-z][A-Za-z0-9_]*", data["id"]):
        raise ManifestError(f"id {data['id']!r} must be a Python identifier")
    if data["type"] not in ("add-on", "theme"):
        raise ManifestError(f"type must be 'add-on' or 'theme', got {data['type']!r}")
    for key in ("version", "blender_version_min"):
        if not re.fullmatch(r"\d+\.\d+\.\d+", str(data[key])):
            raise ManifestError(f"{key} must look like 1.2.3, got {data[key]!r}")
    tagline = data["tagline"]
    if len(tagline) > 64 or tagline[-1:] in ".!?,;:":
        raise ManifestError("tagline must be <= 64 characters without trailing punctuation")
    if not isinstance(data["license"], list) or not all(str(x).startswith("SPDX:") for x in data["license"]):
        raise ManifestError("license must be a list of 'SPDX:...' strings")
    perms = data.get("permissions", {})
    for key, why in perms.items():
        if key not in ("files", "network", "clipboard", "camera", "microphone"):
            raise ManifestError(f"unknown permission {key!r}")
        if not why or why[-1:] == ".":
            raise ManifestError(f"permission {key!r} needs a reason without a trailing period")
    for name in data.get("platforms", []):
        if name not in ("windows-x64", "windows-arm64", "macos-x64", "macos-arm64", "linux-x64", "linux-arm64"):
            raise ManifestError(f"unknown platform {name!r}")
    for whl in data.get("wheels", []):
        if not whl.startswith("./wheels/") or not whl.endswith(".whl"):
            raise ManifestError(f"wheel path {whl!r} must be ./wheels/<name>.whl")
        if zip_names is not None and whl[2:] not in zip_names:
            raise ManifestError(f"wheel {whl!r} is listed but not in the zip")
    return data


def manifest_for(platform_name: str, wheels: list[str]) -> str:
    """The source manifest with ``platforms`` and ``wheels`` added as top-level keys."""
    text = (ADDON / "blender_manifest.toml").read_text()
    extra = f'platforms = ["{platform_name}"]\n'
    if wheels:
        extra += "wheels = [\n" + "".join(f'  "./wheels/{w}",\n' for w in wheels) + "]\n"
    # Top-level keys must come before the first [table] header
    m = re.search(r"^\[", text, flags=re.M)
    cut = m.start() if m else len(text)
    return text[:cut] + extra + "\n" + text[cut:]


def download_wheels(platform_name: str) -> list[Path]:
    """pip-download the dependency wheels for one platform (cached in dist/wheel-cache/)."""
    dest = WHEEL_CACHE / platform_name
    dest.mkdir(parents=True, exist_ok=True)
    reqs = list(WHEELS_ALL)
    if platform_name in WHEELS_EMBREE:
        reqs.append(WHEELS_EMBREE[platform_name])
    cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--only-binary=:all:",
           "--python-version", "3.11", "--implementation", "cp", "--abi", "cp311", "--abi", "abi3",
           "--abi", "none", "-d", str(dest)]
    for tag in PLATFORM_TAGS[platform_name]:
        cmd += ["--platform", tag]
    subprocess.check_call(cmd + [r for r in reqs if r not in OPTIONAL_WHEELS])
    for req in OPTIONAL_WHEELS:  # no wheel for some platforms: the feature degrades, the build goes on
        if req in reqs and subprocess.call(cmd + [req], stderr=subprocess.DEVNULL) != 0:
            print(f"build.py addon: no {req} wheel for {platform_name}; "
                  f"stpm compare reports no FLIP there", file=sys.stderr)
    wanted = {re.split(r"[=<>]", r)[0].lower().replace("-", "_") for r in reqs}
    found = [p for p in sorted(dest.glob("*.whl")) if p.name.split("-")[0].lower() in wanted]
    return found


def _add_tree(zf: zipfile.ZipFile, src: Path, arc_root: str) -> None:
    """Add a Python package directory, without caches and developer tools."""
    for path in sorted(src.rglob("*")):
        if path.is_dir() or "__pycache__" in path.parts or path.suffix in (".pyc", ".pyo"):
            continue
        if path.name in EXCLUDE and path.parent == ADDON:
            continue
        zf.write(path, f"{arc_root}{path.relative_to(src).as_posix()}")


def build(platform_name: str, *, wheels: bool = True, out_dir: Path | None = None) -> Path:
    """Build one platform's zip and return its path."""
    if platform_name not in PLATFORM_TAGS:
        raise SystemExit(f"build_zip: no wheel tags for platform {platform_name!r} "
                         f"(supported: {', '.join(PLATFORM_TAGS)})")
    version = tomllib.loads((ADDON / "blender_manifest.toml").read_text())["version"]
    out_dir = Path(out_dir or ROOT / "dist")
    out_dir.mkdir(parents=True, exist_ok=True)
    wheel_files = download_wheels(platform_name) if wheels else []
    manifest = manifest_for(platform_name, [w.name for w in wheel_files])
    target = out_dir / f"stpm-{version}-{platform_name}.zip"
    with zipfile.ZipFile(target, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        _add_tree(zf, ADDON, "")
        zf.writestr("blender_manifest.toml", manifest)  # replaces nothing: source copy skipped below
        _add_tree(zf, CORE, "stpm_core/")
        for whl in wheel_files:
            zf.write(whl, f"wheels/{whl.name}", compress_type=zipfile.ZIP_STORED)
    # Re-check what was written
    with zipfile.ZipFile(target) as zf:
        names = set(zf.namelist())
        if sum(n == "blender_manifest.toml" for n in zf.namelist()) != 1:
            raise ManifestError("zip must hold exactly one blender_manifest.toml")
        validate_manifest(zf.read("blender_manifest.toml").decode(), zip_names=names)
    return target


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="build.py addon", description=__doc__.split("\n\n")[0])
    ap.add_argument("--all-platforms", action="store_true")
    ap.add_argument("--platform", default=None)
    ap.add_argument("--no-wheels", action="store_true")
    ap.add_argument("--out", default=None)
    args = ap.parse_args(argv)
    targets = list(PLATFORM_TAGS) if args.all_platforms else [args.platform or this_platform()]
    for name in targets:
        path = build(name, wheels=not args.no_wheels, out_dir=args.out)
        note = "" if name in WHEELS_EMBREE or args.no_wheels else "  (no embreex wheel: numba ray casting)"
        print(f"{path}{note}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
