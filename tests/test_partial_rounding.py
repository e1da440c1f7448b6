"""`stpm merge` of partials whose scenes differ only by float rounding (artist review).

Blender's evaluated meshes are not bit-reproducible between processes: a Bevel modifier's UVs
differ in the last bit or two from run to run (review/make_bevel_min.py: three exports of one
frame, three scene hashes), so two farm machines rendering pass chunks of one .blend frame wrote
partials that `stpm merge` refused as "partials of different scenes".  The partial header now
carries a scene fingerprint (per array a digest and float sums); merge accepts float arrays that
agree to rounding and still refuses a real edit.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from scenes import make_scene, persp_camera, plane_mesh, point_light
from stpm_core.errors import StpmError
from stpm_core.scene import Material
from stpm_core.partial import merge, scene_fingerprint, scene_hash, write_partial
from stpm_core.progressive import PassSums


def _scene(uv):
    mesh = dataclasses.replace(plane_mesh(2.0), uv_layers={"UVMap": uv}, uv_render="UVMap")
    return make_scene([mesh], [Material.diffuse((0.5, 0.5, 0.5))],
                      persp_camera((0, -3, 2), (0, 0, 0)), [point_light((0, 0, 2), 50.0)], resolution=(8, 6))


def _uv(n_faces, seed=0):
    return np.random.default_rng(seed).random((n_faces, 3, 2)).astype(np.float32)


def _sums(first, count, rng, H=6, W=8):
    s = PassSums(first)
    for i in range(first, first + count):
        s.add(i, {"Combined": rng.random((H, W, 4)).astype(np.float32)})
    return s


def _partials(tmp_path, scene_a, scene_b):
    rng = np.random.default_rng(1)
    kw = dict(seed=0, settings_digest="b" * 64)
    a = write_partial(tmp_path / "a.exr", _sums(1, 4, rng), scene_digest=scene_hash(scene_a),
                      scene_print=scene_fingerprint(scene_a), **kw)
    b = write_partial(tmp_path / "b.exr", _sums(5, 4, rng), scene_digest=scene_hash(scene_b),
                      scene_print=scene_fingerprint(scene_b), **kw)
    return a, b


def test_partials_of_a_scene_differing_in_the_last_bits_of_its_uvs_merge(tmp_path):
    n = len(plane_mesh(2.0).triangles)
    uv = _uv(n)
    uv2 = uv.copy()
    uv2[::3, 1, 0] = np.nextafter(uv2[::3, 1, 0], np.float32(2))      # one ulp, as Bevel's UVs do
    a, b = _scene(uv), _scene(uv2)
    assert scene_hash(a) != scene_hash(b)
    pa, pb = _partials(tmp_path, a, b)
    total, head = merge([pa, pb])
    assert (total.first, total.end) == (1, 9)
    assert head["scene_rounding"] == [str(pb)]


@pytest.mark.parametrize("edit", ["moved", "swapped", "vertex"])
def test_partials_of_an_edited_scene_are_still_refused(tmp_path, edit):
    n = len(plane_mesh(2.0).triangles)
    uv = _uv(n)
    a = _scene(uv)
    if edit == "moved":                        # one UV corner moved by 1e-3
        uv2 = uv.copy(); uv2[0, 0, 0] += 1e-3
        b = _scene(uv2)
    elif edit == "swapped":                    # two corners exchanged: every plain sum stays
        uv2 = uv.copy(); uv2[0, 0], uv2[1, 0] = uv[1, 0].copy(), uv[0, 0].copy()
        b = _scene(uv2)
    else:                                      # a vertex moved by 1 mm
        b = _scene(uv)
        v = b.meshes[0].vertices.copy(); v[0, 0] += 1e-3
        b.meshes[0] = dataclasses.replace(b.meshes[0], vertices=v)
    pa, pb = _partials(tmp_path, a, b)
    with pytest.raises(StpmError, match="different scenes"):
        merge([pa, pb])


def test_a_malformed_fingerprint_is_one_error_line(tmp_path):
    a = _scene(_uv(len(plane_mesh(2.0).triangles)))
    rng = np.random.default_rng(1)
    bad = {"header": "0" * 64, "arrays": {"x": ["ab", "f", [1.0, float("nan"), 0.0, 1.0]]}}
    p = write_partial(tmp_path / "a.exr", _sums(1, 4, rng), seed=0, scene_digest=scene_hash(a),
                      settings_digest="b" * 64, scene_print=bad)
    with pytest.raises(StpmError, match="scene_fingerprint"):
        merge([p])
