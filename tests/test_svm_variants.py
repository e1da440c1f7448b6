"""The interpreter compiled for the opcodes a scene uses (stpm_core.kernels.svm_variants).

A variant re-compiles svm's dispatching functions with the unused opcodes' branches folded away.
It must shade exactly as the full interpreter on the same programs (bit for bit: it is the same
source, with branches that these programs never take removed), be chosen deterministically from
the programs' opcodes, and must not compile what only the removed branches call (else it saves
no compile time).  The test_kernel_svm tests run the full interpreter (no ``ops``) against the
numpy oracle; these compare the two interpreters.
"""
from __future__ import annotations

import numpy as np

from stpm_core.kernels import svm, svm_variants
from stpm_core.kernels.closure import N_CLOSURE
from stpm_core.nodes.graph import Link, Node, ShaderGraph
from stpm_core.raycast import Hits
from stpm_core.scene import Material
from stpm_core.shading import hit_geometry, shading_data
from stpm_core.textures import Texture
from test_kernel_svm import N, make_hits, make_scene

# The node kinds of benchmarks/bench_textures.node_material (Texture Coordinate -> Mapping -> Image
# Texture, a Checker, Mix Color, a ColorRamp on Roughness) and a second material mixing a Diffuse
# and a Glossy BSDF by the Checker's Fac
# (the Image Texture's Linear look-up of an 8-bit image, Mix Color's Multiply: parts of an opcode)
BENCH_OPS = {"TEXCOORD", "TEXCOORD_OBJECT", "MAPPING", "TEX_IMAGE", "IMAGE_LINEAR8", "TEX_CHECKER", "MIX_COLOR",
             "BLEND_MULTIPLY", "RAMP", "CONVERT", "BSDF_PRINCIPLED"}


def _textured() -> ShaderGraph:
    return ShaderGraph(nodes={
        "Coord": N("ShaderNodeTexCoord"),
        "Mapping": N("ShaderNodeMapping", {"Vector": Link("Coord", "Object"), "Scale": (3.0, 2.0, 1.0),
                                           "Rotation": (0.0, 0.0, 0.4), "Location": (0.1, 0.0, 0.0)},
                     {"vector_type": "POINT"}),
        "Image": N("ShaderNodeTexImage", {"Vector": Link("Mapping", "Vector")},
                   {"image": 0, "interpolation": "Linear", "extension": "REPEAT", "projection": "FLAT"}),
        "Checker": N("ShaderNodeTexChecker", {"Vector": Link("Coord", "Object"), "Scale": 2.0,
                                              "Color1": (1.0, 1.0, 1.0), "Color2": (0.5, 0.5, 0.5)}),
        "Mix": N("ShaderNodeMix", {"Factor_Float": 1.0, "A_Color": Link("Image", "Color"),
                                   "B_Color": Link("Checker", "Color")},
                 {"data_type": "RGBA", "blend_type": "MULTIPLY", "clamp_factor": True}),
        "Ramp": N("ShaderNodeValToRGB", {"Fac": Link("Checker", "Fac")},
                  {"elements": [(0.0, (0.2, 0.2, 0.2, 1.0)), (1.0, (0.9, 0.9, 0.9, 1.0))], "interpolation": "LINEAR"}),
        "BSDF": N("ShaderNodeBsdfPrincipled", {"Base Color": Link("Mix", "Result_Color"),
                                               "Roughness": Link("Ramp", "Color"), "Specular IOR Level": 0.0}),
    }, surface=Link("BSDF", "BSDF"))


def _mixed() -> ShaderGraph:
    return ShaderGraph(nodes={
        "Coord": N("ShaderNodeTexCoord"),
        "Checker": N("ShaderNodeTexChecker", {"Vector": Link("Coord", "Object"), "Scale": 3.0}),
        "Diffuse": N("ShaderNodeBsdfDiffuse", {"Color": Link("Checker", "Color")}),
        "Glossy": N("ShaderNodeBsdfGlossy", {"Color": (0.9, 0.8, 0.7), "Roughness": 0.3}),
        "Mix": N("ShaderNodeMixShader", {"Fac": Link("Checker", "Fac"), "Shader": Link("Diffuse", "BSDF"),
                                         "Shader_001": Link("Glossy", "BSDF")}),
    }, surface=Link("Mix", "Shader"))


def _cutout() -> ShaderGraph:
    """A Principled BSDF coloured by the UV coordinates, its Alpha a Checker's Fac (a cut-out)."""
    return ShaderGraph(nodes={
        "Coord": N("ShaderNodeTexCoord"),
        "Checker": N("ShaderNodeTexChecker", {"Vector": Link("Coord", "UV"), "Scale": 4.0}),
        "BSDF": N("ShaderNodeBsdfPrincipled", {"Base Color": Link("Coord", "UV"), "Alpha": Link("Checker", "Fac")}),
    }, surface=Link("BSDF", "BSDF"))


def _scene():
    rng = np.random.default_rng(3)
    tex = Texture(rng.integers(0, 256, (16, 8, 3), dtype=np.uint8), colorspace="sRGB", name="noise")
    flat = Material(base_color=np.array([0.3, 0.6, 0.2]), roughness=0.4, name="flat")
    return make_scene([_textured(), flat, _mixed(), _cutout()], [tex])


def _shade(scene, ops, rows: bool):
    """Closure rows (and the shading normals after) of 600 hits on the scene's materials and misses,
    by the interpreter for ``ops`` (None: the full one)."""
    sd = shading_data(scene)
    rng = np.random.default_rng(7)
    hits = make_hits(600, rng)
    mat = rng.integers(-1, len(scene.materials), 600).astype(np.int32)
    h = Hits(t=np.ones(600), instance=np.zeros(600, np.int32), prim=np.zeros(600, np.int32), u=hits["bu"],
             v=hits["bv"], position=hits["P"], ng=hits["NG"], ns=hits["NS"], material=mat)
    G = hit_geometry(h, hits["D"])
    # (the entry svm.shade_closures / shade_closure_rows call: ops' own variant, not a compiled
    # superset's that svm_variants.covering may pick)
    entry = svm._shade if ops is None else svm_variants.interpreter(ops, reuse=False)
    if rows:
        C = np.full((600 + sd.closures.shape[0], N_CLOSURE), np.nan)
        crow = np.zeros(600, np.int64)
        entry(mat, sd.closures, sd.prog, sd.n_slots, G, sd.A, sd.X, 5, svm._NO_U, C, crow, True)
        return C[crow], G[2].copy()
    C = np.full((600, N_CLOSURE), np.nan)
    entry(mat, sd.closures, sd.prog, sd.n_slots, G, sd.A, sd.X, 5, svm._NO_U, C, svm._NO_ROWS, False)
    return C, G[2].copy()


def test_program_ops_walks_every_instruction():
    sd = shading_data(make_scene([_textured()], [Texture(np.zeros((4, 4, 3), np.uint8), name="t")]))
    assert sd.ops == BENCH_OPS
    # a float image's Linear look-up is not the 8-bit one
    sd = shading_data(make_scene([_textured()], [Texture(np.zeros((4, 4, 3), np.float32), name="t")]))
    assert sd.ops == BENCH_OPS - {"IMAGE_LINEAR8"} | {"IMAGE_LINEAR"}
    sd = shading_data(_scene())
    assert sd.ops == BENCH_OPS | {"BSDF_DIFFUSE", "BSDF_GLOSSY", "MIX_SHADER", "TEXCOORD_UV", "ALPHA"}
    # a scene without node programs has none
    assert shading_data(make_scene([Material(name="flat")])).ops == frozenset()


def test_a_variant_shades_bit_identically_to_the_full_interpreter():
    scene = _scene()
    sd = shading_data(scene)
    entry = svm_variants.interpreter(sd.ops, reuse=False)     # (this set's own, not a compiled superset's)
    assert entry is not svm._shade, "no variant was made (no writable kernel cache folder?)"
    for rows in (False, True):
        full, ns_full = _shade(scene, None, rows)
        var, ns_var = _shade(scene, sd.ops, rows)
        assert np.isfinite(full).all()
        assert np.array_equal(full.view(np.int64), var.view(np.int64)), f"rows={rows}: closures differ"
        assert np.array_equal(ns_full, ns_var)
    # the removed branches' callees were not compiled: no colour, procedural or geometry-node
    # function of the variant's own (they are the variant module's dispatchers, compiled only
    # for it); the ones its opcodes need were, unless the entry came from the on-disk cache
    # (then none of them is compiled: the entry's cached code holds them)
    mod = __import__(entry.py_func.__module__, fromlist=["_shade"])
    assert mod._USE_TEX_NOISE is False and mod._USE_TEX_IMAGE is True
    assert not mod._procedural_node.signatures and not mod._color_node.signatures
    if not sum(entry.stats.cache_hits.values()):
        assert mod._texture_node.signatures and mod._value_node.signatures and mod._geometry_node.signatures
        assert mod.tex_image_rows.signatures and mod.mix_color.signatures


def _generated() -> ShaderGraph:
    """A Glass BSDF coloured by a Checker on Generated coordinates (Texture Coordinate's Generated
    without its Object output; the Glass tints)."""
    return ShaderGraph(nodes={
        "Coord": N("ShaderNodeTexCoord"),
        "Checker": N("ShaderNodeTexChecker", {"Vector": Link("Coord", "Generated"), "Scale": 3.0}),
        "Glass": N("ShaderNodeBsdfGlass", {"Color": Link("Checker", "Color"), "Roughness": 0.2, "IOR": 1.45}),
    }, surface=Link("Glass", "BSDF"))


def _closest_float() -> ShaderGraph:
    """A Principled BSDF coloured by a float image read with Closest at the UV coordinates (the
    Image Texture's general look-ups, without the 8-bit Linear loop)."""
    return ShaderGraph(nodes={
        "Image": N("ShaderNodeTexImage", {}, {"image": 0, "interpolation": "Closest", "extension": "REPEAT",
                                              "projection": "FLAT"}),
        "BSDF": N("ShaderNodeBsdfPrincipled", {"Base Color": Link("Image", "Color"), "Metallic": 0.3}),
    }, surface=Link("BSDF", "BSDF"))


def test_the_parts_a_variant_leaves_out_shade_bit_identically():
    """Texture Coordinate's Generated without Object, a Glass BSDF without the Principled or Glossy
    columns' tests, Closest look-ups without the 8-bit Linear loop: the same closures."""
    rng = np.random.default_rng(5)
    tex = Texture(rng.uniform(0.0, 1.0, (8, 4, 4)).astype(np.float32), name="float")
    scene = make_scene([_generated(), _closest_float()], [tex])
    sd = shading_data(scene)
    assert {"TEXCOORD_GENERATED", "BSDF_GLASS", "IMAGE_CLOSEST"} <= sd.ops
    assert not sd.ops & {"TEXCOORD_OBJECT", "BSDF_GLOSSY", "IMAGE_LINEAR8", "IMAGE_LINEAR", "SET_NORMAL"}
    entry = svm_variants.interpreter(sd.ops, reuse=False)
    assert entry is not svm._shade
    for rows in (False, True):
        full, ns_full = _shade(scene, None, rows)
        var, ns_var = _shade(scene, sd.ops, rows)
        assert np.isfinite(full).all()
        assert np.array_equal(full.view(np.int64), var.view(np.int64)), f"rows={rows}: closures differ"
        assert np.array_equal(ns_full, ns_var)


def test_the_variant_is_chosen_by_the_opcode_set():
    ops = frozenset(BENCH_OPS)
    assert svm_variants.variant_source(ops) == svm_variants.variant_source(sorted(ops, reverse=True))
    assert svm_variants.interpreter(ops) is svm_variants.interpreter(set(BENCH_OPS))
    assert svm_variants.variant_source(ops) != svm_variants.variant_source(ops - {"BLEND_MULTIPLY"})
    # a scene with every opcode and part of one, and no information about the programs: the full
    # interpreter
    assert svm_variants.interpreter(svm_variants.FEATURES | {"END"}) is svm._shade
    assert svm_variants.interpreter(None) is svm._shade


_CHILD = r"""
import json, sys
sys.path.insert(0, sys.argv[1]); sys.path.insert(0, sys.argv[2])
import numpy as np
from stpm_core import numba_probe
from stpm_core.kernels import svm
from stpm_core.shading import shading_data
from stpm_core.nodes.graph import Link, ShaderGraph
from test_kernel_svm import N, make_scene
from test_svm_variants import _shade
g = ShaderGraph(nodes={"Checker": N("ShaderNodeTexChecker", {"Scale": 3.0}),
                       "Diffuse": N("ShaderNodeBsdfDiffuse", {"Color": Link("Checker", "Color")})},
                surface=Link("Diffuse", "BSDF"))
scene = make_scene([g])
C, _ = _shade(scene, shading_data(scene).ops, False)
print(json.dumps({"compiled": numba_probe.compile_counts()[0], "sum": float(np.nansum(C)),
                  "ops": sorted(shading_data(scene).ops), "dir": str(numba_probe.variant_dir())}))
"""


def test_a_second_process_loads_the_variant_from_the_cache(tmp_path):
    """The variant file and its compiled kernels land in the kernel cache folder; a second process
    (a warm start) compiles nothing and shades the same; a new kernel-source digest names a new file."""
    import json
    import os
    import subprocess
    import sys
    from pathlib import Path

    from stpm_core import numba_probe
    root, tests = Path(__file__).resolve().parent.parent, Path(__file__).resolve().parent
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "cache"))

    def child():
        out = subprocess.run([sys.executable, "-c", _CHILD, str(root), str(tests)], env=env, capture_output=True,
                             text=True, check=True)
        return json.loads(out.stdout.strip().splitlines()[-1])

    first, second = child(), child()
    assert first["ops"] == ["BSDF_DIFFUSE", "TEXCOORD", "TEXCOORD_GENERATED", "TEX_CHECKER"]
    assert Path(first["dir"]) == tmp_path / "cache" / "svm_variants"
    files = list(Path(first["dir"]).glob("svm_*.py"))
    assert len(files) == 1
    assert first["compiled"] > 0 and second["compiled"] == 0 and first["sum"] == second["sum"]
    # the file's name follows the kernel sources' digest (numba checks a cached kernel against its
    # own file only: an edited callee must not be served from an old compile)
    assert files[0].name == svm_variants.variant_name(first["ops"]) + ".py"
    old = numba_probe._SOURCES_DIGEST[:]
    try:
        numba_probe._SOURCES_DIGEST[:] = ["0" * 64]
        assert files[0].name != svm_variants.variant_name(first["ops"]) + ".py"
    finally:
        numba_probe._SOURCES_DIGEST[:] = old


def test_stale_variants_are_removed_conservatively(tmp_path):
    """Variant modules of other kernel sources (and numba's compiled files of them) go once they
    have been left alone for STALE_AGE_S; this install's, recent ones and other names stay."""
    import os
    import time

    folder, cache, mirror = tmp_path / "svm_variants", tmp_path / "svm_variants" / "__pycache__", tmp_path / "mirror"
    cache.mkdir(parents=True)
    mirror.mkdir()
    current = svm_variants.variant_source({"BSDF_DIFFUSE"})
    digest = svm_variants.numba_probe.sources_digest()
    other = current.replace(digest, "f" * 64)
    assert other != current
    legacy = "\n".join(line for line in current.splitlines() if not line.startswith("# kernel sources: "))
    now = time.time()
    old = now - svm_variants.STALE_AGE_S - 60

    def put(path, text="", mtime=old):
        path.write_text(text)
        os.utime(path, (mtime, mtime))
        return path

    h = iter(f"{i:020x}" for i in range(1, 100))
    keep, gone = [], []
    a = next(h)                                      # this install's, old: kept with its kernels
    keep += [put(folder / f"svm_{a}.py", current), put(cache / f"svm_{a}._shade-10.py311.nbi")]
    b = next(h)                                      # another digest, old: removed with its kernels
    gone += [put(folder / f"svm_{b}.py", other), put(cache / f"svm_{b}._shade-10.py311.nbi"),
             put(cache / f"svm_{b}._shade-10.py311.1.nbc"), put(mirror / f"svm_{b}._closures-9.py311.nbi"),
             put(cache / f"svm_{b}.cpython-311.pyc")]
    c = next(h)                                      # written before the digest line: another digest's
    gone += [put(folder / f"svm_{c}.py", legacy)]
    d = next(h)                                      # another digest, but a kernel of it saved lately
    keep += [put(folder / f"svm_{d}.py", other), put(cache / f"svm_{d}._shade-10.py311.nbi", mtime=now)]
    e = next(h)                                      # another digest, written lately
    keep += [put(folder / f"svm_{e}.py", other, mtime=now)]
    gone += [put(folder / f"svm_{next(h)}.4242.tmp", other)]     # an interrupted write
    keep += [put(folder / "notes.py", other), put(folder / "svm_short.py", other),
             put(cache / "svm_short._shade-1.py311.nbi"), put(mirror / "other.f-1.py311.nbi")]

    removed = svm_variants.remove_stale(folder, cache_dirs=[cache, mirror], now=now)
    assert sorted(removed) == sorted(gone)
    assert all(p.exists() for p in keep) and not any(p.exists() for p in gone)
    # nothing left to remove: a second sweep (another process) removes nothing and does not fail
    assert svm_variants.remove_stale(folder, cache_dirs=[cache, mirror], now=now) == []
    # the default cache folders: numba's __pycache__ next to the modules
    assert svm_variants._cache_dirs(folder)[0] == cache


def test_a_compiled_superset_variant_is_reused_and_only_a_superset(tmp_path, monkeypatch):
    """``covering``: a variant already compiled (numba's index of its ``_shade`` in the cache folder)
    whose features hold every one of a scene's serves it (no new compile; the smallest such one);
    a set's own compiled variant wins; a variant missing a feature, one never compiled, or one of
    other kernel sources is never picked (it would shade the scene's programs wrongly or compile)."""
    folder, cache = tmp_path / "svm_variants", tmp_path / "svm_variants" / "__pycache__"
    cache.mkdir(parents=True)
    ops = frozenset(BENCH_OPS)
    monkeypatch.setattr(svm_variants, "_VARIANTS_LOADED", set())   # (none loaded in this process)

    def put(feats, compiled=True, digest_ok=True):
        name = svm_variants.variant_name(feats)
        text = svm_variants.variant_source(feats)
        if not digest_ok:
            text = text.replace(svm_variants._DIGEST_TAG, svm_variants._DIGEST_TAG + "0")
        (folder / f"{name}.py").write_text(text)
        if compiled:
            (cache / f"{name}._shade-702.py311.nbi").write_text("")
        return frozenset(feats)

    def cover(o):
        return svm_variants.covering(o, folder=folder, cache_dirs=[cache])

    assert cover(ops) == ops                                        # nothing compiled: its own
    put(ops - {"RAMP"} | {"TEX_NOISE"})                             # lacks RAMP: never
    put(ops | {"TEX_WAVE"}, compiled=False)                         # not compiled: never
    put(ops | {"TEX_GRADIENT"}, digest_ok=False)                    # other kernel sources: never
    assert cover(ops) == ops
    big = put(ops | {"TEX_NOISE", "BUMP", "TEX_WAVE", "BSDF_GLASS"})
    small = put(ops | {"TEX_NOISE", "BUMP"})
    assert cover(ops) == small                                      # the smallest compiled superset
    assert cover(ops | {"BSDF_GLASS"}) == big
    assert cover(ops | {"TEX_MAGIC"}) == ops | {"TEX_MAGIC"}        # no superset: its own
    put(ops)                                                        # its own compiled: its own
    assert cover(ops) == ops
    # in this process: a loaded superset serves without looking at the folder
    svm_variants._VARIANTS_LOADED.add(big)
    assert svm_variants.covering(ops | {"BSDF_GLASS"}, folder=tmp_path / "none") == big
    # interpreter(): a set served by a superset's variant is not itself a loaded variant (a subset of
    # it must not be sent to a variant that was never compiled)
    monkeypatch.setattr(svm_variants, "_LOADED", {})
    monkeypatch.setattr(svm_variants, "_load", lambda f: ("entry", f))
    monkeypatch.setattr(svm_variants.numba_probe, "variant_dir", lambda: tmp_path / "none")
    assert svm_variants.interpreter(ops) == ("entry", big)
    assert svm_variants._VARIANTS_LOADED == {big}
    assert svm_variants.covering(ops - {"RAMP"}, folder=tmp_path / "none") == big
