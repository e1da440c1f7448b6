"""The "Compare with Accumulation Buffer" operator inside Blender (bpy module).

Runs the operator on a tiny saved .blend in background mode (where it waits for
its worker thread) and checks the report lands next to the file with numbers.
"""
from __future__ import annotations

import json

import pytest

bpy = pytest.importorskip("bpy")

import addon  # noqa: E402
from addon.compare_op import report_dir  # noqa: E402
from test_addon_render import DEMO, _tiny  # noqa: E402

addon.register()


def _open_demo_saved_as(path):
    bpy.ops.wm.open_mainfile(filepath=str(DEMO))
    scene = bpy.context.scene
    _tiny(scene, samples=1, photons=1500)
    scene.render.resolution_x, scene.render.resolution_y = 16, 12
    bpy.ops.wm.save_as_mainfile(filepath=str(path))
    return scene


def test_compare_operator_writes_the_report_next_to_the_blend(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    blend = tmp_path / "shot.blend"
    _open_demo_saved_as(blend)
    # a budget spent by the first run keeps the test small: one run done, the rest skipped
    result = bpy.ops.stpm.compare(time_budget=1e-6)
    assert result == {"FINISHED"}
    out = tmp_path / "shot_compare"
    assert report_dir(str(blend)) == str(out)
    data = json.loads((out / "report.json").read_text())
    done = [r for r in data["runs"] if r["status"] == "done"]
    assert len(done) == 1 and done[0]["rmse"] is not None and done[0]["rmse"] >= 0
    assert "<html" in (out / "report.html").read_text().lower()


def test_compare_operator_refuses_an_unsaved_file():
    bpy.ops.wm.read_homefile(use_empty=True)
    bpy.context.scene.render.engine = "STPM"
    with pytest.raises(RuntimeError, match="Save the .blend first"):
        bpy.ops.stpm.compare()
