"""The Blender extension zip: manifest validation, build, install into bpy, render."""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from addon import build_zip  # noqa: E402  (no bpy needed)


def test_source_manifest_is_valid():
    data = build_zip.validate_manifest((ROOT / "addon" / "blender_manifest.toml").read_text())
    assert data["id"] == "stpm" and data["type"] == "add-on" and data["blender_version_min"] == "4.2.0"
    assert "files" in data["permissions"]


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace('id = "stpm"', 'id = "st-pm"'), "identifier"),
    (lambda t: t.replace('type = "add-on"\n', ""), "type"),
    (lambda t: t.replace('blender_version_min = "4.2.0"', 'blender_version_min = "4.2"'), "blender_version_min"),
    (lambda t: t.replace('schema_version = "1.0.0"', 'schema_version = "2"'), "schema_version"),
    (lambda t: t + "\nwheels = [", "TOML"),
])
def test_broken_manifests_are_refused(edit, message):
    text = edit((ROOT / "addon" / "blender_manifest.toml").read_text())
    with pytest.raises(build_zip.ManifestError, match=message):
        build_zip.validate_manifest(text)


def test_platform_manifest_lists_wheels_as_top_level_keys():
    text = build_zip.manifest_for("windows-x64", ["scipy-1.16.3-cp311-cp311-win_amd64.whl"])
    data = build_zip.validate_manifest(text)
    assert data["platforms"] == ["windows-x64"]
    assert data["wheels"] == ["./wheels/scipy-1.16.3-cp311-cp311-win_amd64.whl"]
    with pytest.raises(build_zip.ManifestError, match="not in the zip"):
        build_zip.validate_manifest(text, zip_names={"blender_manifest.toml"})


# Installs the zip with Blender's own operator into a throw-away user directory,
# then renders the demo with the installed engine (its bundled stpm_core).
_INSTALL_AND_RENDER = r"""
import json, sys
import bpy
zip_path, blend, exr = sys.argv[1:4]
ret = bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
mod = sys.modules["bl_ext.user_default.stpm"]
bpy.ops.wm.open_mainfile(filepath=blend)
scene = bpy.context.scene
scene.stpm.samples, scene.stpm.photons_global, scene.stpm.photons_caustic = 1, 500, 500
scene.render.resolution_x, scene.render.resolution_y = 16, 12
scene.render.filepath, scene.render.use_file_extension = exr, False
bpy.ops.render.render(write_still=True)
core = sys.modules["bl_ext.user_default.stpm._core"].core
print("RESULT" + json.dumps({"install": sorted(ret), "engine": scene.render.engine,
                             "core": core.__file__, "addon": mod.__file__}))
"""


# Installs the zip with Blender's operator (nothing rendered): the first fresh process
_INSTALL = r"""
import json, sys
import bpy
ret = bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo="user_default", enable_on_install=True)
print("RESULT" + json.dumps({"install": sorted(ret)}))
"""

# A later fresh process: enable the installed extension, render the demo, report the engine's stats
_RENDER_INSTALLED = r"""
import json, sys
import bpy
blend, exr = sys.argv[1:3]
bpy.ops.preferences.addon_enable(module="bl_ext.user_default.stpm")
core = sys.modules["bl_ext.user_default.stpm._core"]
bpy.ops.wm.open_mainfile(filepath=blend)
scene = bpy.context.scene
scene.stpm.samples, scene.stpm.photons_global, scene.stpm.photons_caustic = 1, 500, 500
scene.render.resolution_x, scene.render.resolution_y = 16, 12
scene.render.filepath, scene.render.use_file_extension = exr, False
cached_before = core.sub("kernels").kernels_cached()     # what the status bar is told before the render
bpy.ops.render.render(write_still=True)
stats = sys.modules["bl_ext.user_default.stpm.engine"].LAST_RENDER["stats"]
print("RESULT" + json.dumps({"engine": scene.render.engine, "core": core.core.__file__,
                             "cached_before": cached_before,
                             **{k: stats[k] for k in ("kernels_compiled", "kernel_compile_s", "kernel_cache",
                                                     "kernel_cache_source")}}))
"""


def _blender_child(script: str, args: list, tmp_path: Path, read_only_install: bool = False) -> dict:
    """Run script in a fresh bpy process with the throw-away user folder tmp_path / 'user' (no checkout
    on sys.path); read_only_install: mode bits hold even for root (it drops CAP_DAC_OVERRIDE)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "NUMBA_CACHE_DIR", "STPM_KERNEL_CACHE")}
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "user")
    prefix = []
    if read_only_install and os.name == "posix" and os.geteuid() == 0:
        if shutil.which("setpriv") is None:
            pytest.skip("running as root without setpriv: a read-only folder cannot be made to hold")
        prefix = ["setpriv", "--bounding-set=-dac_override,-dac_read_search", "--"]
    proc = subprocess.run([*prefix, sys.executable, "-c", script, *map(str, args)], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=1200)
    line = next((l for l in proc.stdout.splitlines() if l.startswith("RESULT")), None)
    assert line is not None, proc.stdout[-2000:] + proc.stderr[-3000:]
    return json.loads(line[len("RESULT"):])


def _set_read_only(folder: Path, read_only: bool) -> None:
    for d, _dirs, files in os.walk(folder):
        os.chmod(d, 0o555 if read_only else 0o755)
        for name in files:
            os.chmod(os.path.join(d, name), 0o444 if read_only else 0o644)


def test_built_zip_installs_into_blender_and_compiles_its_kernels_once(tmp_path):
    """Issue 17: install, make the install folder read-only, render in a fresh process (the kernels
    compile into the extension's user folder), render in another fresh process: nothing compiles,
    as the engine's own report says (``kernels_compiled``), and the status bar was told so."""
    pytest.importorskip("bpy")
    zip_path = build_zip.build(build_zip.this_platform(), wheels=False, out_dir=tmp_path / "dist")
    with zipfile.ZipFile(zip_path) as zf:
        names = set(zf.namelist())
    assert {"blender_manifest.toml", "__init__.py", "engine.py", "export/mesh.py",
            "stpm_core/__init__.py", "stpm_core/render.py"} <= names
    assert "build_zip.py" not in names and not any("__pycache__" in n for n in names)
    assert _blender_child(_INSTALL, [zip_path], tmp_path)["install"] == ["FINISHED"]
    installed = tmp_path / "user" / "extensions" / "user_default" / "stpm"
    user_folder = tmp_path / "user" / "extensions" / ".user" / "user_default" / "stpm" / "kernel-cache"
    blend = ROOT / "blend_scenes" / "demo.blend"
    _set_read_only(installed, True)
    try:
        first = _blender_child(_RENDER_INSTALLED, [blend, tmp_path / "first.exr"], tmp_path, read_only_install=True)
        second = _blender_child(_RENDER_INSTALLED, [blend, tmp_path / "second.exr"], tmp_path, read_only_install=True)
    finally:
        _set_read_only(installed, False)
    assert first["engine"] == "STPM" and Path(first["core"]).is_relative_to(installed)   # the bundled core
    assert (tmp_path / "first.exr").stat().st_size > 0 and (tmp_path / "second.exr").stat().st_size > 0
    # the first render compiled, into the extension's user folder (one sub-folder per version and CPU)
    assert first["cached_before"] is False and first["kernels_compiled"] > 50
    assert first["kernel_cache_source"] == "extension" and Path(first["kernel_cache"]).parent == user_folder
    assert any(Path(first["kernel_cache"]).rglob("paths.classify_hits-*.nbi"))
    assert not any(installed.rglob("*.nbi"))
    # the second fresh process loaded every kernel
    assert second["cached_before"] is True and second["kernels_compiled"] == 0
    assert second["kernel_cache"] == first["kernel_cache"]
    print(f"first render {first['kernel_compile_s']:.1f} s compiling, second {second['kernel_compile_s']:.1f} s")


def _install_and_render(zip_path: Path, tmp_path: Path) -> None:
    """Install with Blender's operator in a fresh process and render the demo (16 x 12)."""
    # A fresh Blender process with its own user directory (no checkout on sys.path)
    tmp_path.mkdir(parents=True, exist_ok=True)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["BLENDER_USER_RESOURCES"] = str(tmp_path / "user")
    exr = tmp_path / "out.exr"
    proc = subprocess.run([sys.executable, "-c", _INSTALL_AND_RENDER, str(zip_path),
                           str(ROOT / "blend_scenes" / "demo.blend"), str(exr)],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    line = next((l for l in proc.stdout.splitlines() if l.startswith("RESULT")), None)
    assert line is not None, proc.stdout[-2000:] + proc.stderr[-2000:]
    info = json.loads(line[len("RESULT"):])
    assert info["install"] == ["FINISHED"] and info["engine"] == "STPM"
    installed = tmp_path / "user" / "extensions" / "user_default" / "stpm"
    assert Path(info["core"]).is_relative_to(installed)  # the bundled core, not the checkout's
    assert exr.is_file() and exr.stat().st_size > 0


@pytest.mark.slow
def test_all_platform_zips_bundle_the_wheels_that_exist(tmp_path):
    # Downloads scipy, OpenImageIO, numba, flip-evaluator and embreex wheels for four platforms (hundreds of MB)
    for name in build_zip.PLATFORM_TAGS:
        zip_path = build_zip.build(name, wheels=True, out_dir=tmp_path)
        with zipfile.ZipFile(zip_path) as zf:
            data = build_zip.validate_manifest(zf.read("blender_manifest.toml").decode(), zip_names=set(zf.namelist()))
        wheels = " ".join(data["wheels"]).lower()
        assert "scipy-" in wheels and "openimageio-" in wheels and "numpy" not in wheels
        assert ("embreex-" in wheels) == (name in ("linux-x64", "windows-x64")), name
        # the ray-casting backend where embreex is missing, and its compiler
        assert "numba-" in wheels and "llvmlite-" in wheels, name
        assert ("flip_evaluator-" in wheels) == (name != "macos-x64"), name  # no macOS x86_64 wheel exists
        if name == build_zip.this_platform() and importlib.util.find_spec("bpy"):
            _install_and_render(zip_path, tmp_path / name)  # Blender installs the wheels itself
