"""benchmarks.bench_room's Cycles reference settings (bpy opens the scene files; nothing renders)."""
import pytest

bpy = pytest.importorskip("bpy")
from benchmarks import bench_product as bp  # noqa: E402
from benchmarks import bench_room as room  # noqa: E402


def test_the_rooms_reference_filters_no_glossy_and_clamps_nothing():
    """The room's file keeps Cycles' default Filter Glossy 1 (a glossy lobe seen after a diffuse
    bounce is rounded: the floor's coat lighting the right wall read 8 % dark); the reference
    renders with 0, as docs/blender.md ("Comparing with Cycles yourself") asks."""
    scene = room._open()
    assert scene.cycles.blur_glossy > 0 and scene.cycles.sample_clamp_indirect > 0   # the file's own
    room.reference_settings(scene)
    assert scene.render.engine == "CYCLES"
    assert scene.cycles.blur_glossy == 0.0
    assert scene.cycles.sample_clamp_indirect == 0.0 and scene.cycles.sample_clamp_direct == 0.0
    assert scene.cycles.diffuse_bounces == room.CYCLES["diffuse_bounces"]


def test_only_the_rooms_cache_key_takes_the_file_fix():
    """The product's reference (its file saved with Filter Glossy 0) keeps its cached key; the
    room's changes with the fix."""
    with bp._this_scene():
        product_key = room._cache_key()
        saved = dict(room.FILE_FIXES)
        try:
            room.FILE_FIXES.clear()
            assert room._cache_key() == product_key
        finally:
            room.FILE_FIXES.update(saved)
    room_key = room._cache_key()
    try:
        room.FILE_FIXES.clear()
        assert room._cache_key() != room_key
    finally:
        room.FILE_FIXES.update(saved)


def test_the_equal_time_cycles_render_does_not_share_the_references_seed(monkeypatch, tmp_path):
    """With the reference's seed Cycles' N-sample image shares part of the 1024-sample reference's
    random sequence and its error against it reads low (product shot, 315 spp: FLIP outside the
    caustic 0.0353 with seed 0, 0.0373 with seed 1); the equal-time render takes another seed."""
    calls = []

    def fake_cycles(scene, spp, path, *, index_pass=False, seed=None):
        calls.append((spp, seed))
        return __import__("numpy").zeros((2, 2, 3)), 10.0 * spp / 100.0

    monkeypatch.setattr(room, "_cycles", fake_cycles)
    monkeypatch.setattr(room, "_open", lambda: None)
    monkeypatch.setattr(room, "OUT", tmp_path)
    rgb, spp, seconds = room.cycles_equal_time(20.0, 102.4)
    timed = calls[1:]                                       # the first is the untimed 1-sample warm-up
    assert timed and spp == 200 and seconds == 20.0
    assert all(seed is not None and seed != room.CYCLES["seed"] for _, seed in timed)
    assert room.EQUAL_TIME_SEED != room.CYCLES["seed"]
