"""The scene-file loader under fuzzing: no uncaught exception, hang or crash (issue 18).

300 mutations of a valid scene file in the default run, 10 000 with ``STPM_SLOW=1``.  Each is
loaded in a child forked from one preloaded server process (tests/loader_fuzz.py: the imports
are paid once), under a memory limit (``RLIMIT_AS``) and a 10 s alarm, and used as ``stpm
render`` uses a loaded scene before rendering.  Every mutation must either load or give the
documented one-line ``SceneError`` naming the file; failing files are kept for reproduction
(``python -P tests/loader_fuzz.py`` reruns a seed).

Mutation kinds (tests/loader_fuzz.py, ``KINDS``, one ninth each): bytes of the compressed file,
truncation, bytes inside an inflated member, a member's .npy header (shape, dtype), member
operations (delete, rename, duplicate, replace, add, store uncompressed), header JSON values
(anywhere, from a pool of hostile values), header JSON text, a settings / metadata field of the
schema with a foreign value, the zip directory's sizes and methods.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from stpm_core.motion import MotionTransform
from stpm_core.scenefile import save_scene
from stpm_core.settings import RenderSettings
from stpm_core.scene import World
from test_scenefile import rich_scene

ROOT = Path(__file__).resolve().parent.parent
HARNESS = Path(__file__).resolve().parent / "loader_fuzz.py"


@pytest.fixture(scope="module")
def valid_file(tmp_path_factory) -> Path:
    """Every feature of the format: meshes (rigid, deforming, UVs, tangents, colours), node graphs,
    textures, every light type, motion, a shutter curve, an environment world, settings and the
    typed metadata keys."""
    scene = rich_scene()
    rng = np.random.default_rng(3)
    scene.world = World(color=np.array([0.2, 0.3, 0.4]), strength=1.5,
                        image=rng.random((4, 8, 3)).astype(np.float32),
                        mapping=MotionTransform.static(np.eye(4)), interpolation="CLOSEST",
                        camera_image=rng.random((2, 4, 3)).astype(np.float32))
    scene.metadata.update(warnings=["approximated \x1b[1m", "second"], frame_range=[1, 24], film_transparent=True,
                          light_visible_camera=[True, False, True, False], exporter="test", motion_steps=3)
    settings = RenderSettings(method="PROGRESSIVE", passes=4, time_limit=2.5, samples=3, effects="MANUAL",
                              caustics=False, kernel="CONE", seed=11)
    return save_scene(scene, tmp_path_factory.mktemp("fuzz") / "valid.stpm", settings=settings)


def _fuzz(valid: Path, workdir: Path, seed: int, count: int, jobs: int = 2, timeout: float = 600) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1",
               MKL_NUM_THREADS="1", NUMBA_NUM_THREADS="1")
    env.pop("STPM_DEBUG", None)
    r = subprocess.run([sys.executable, "-P", str(HARNESS), str(valid), str(workdir), str(seed), str(count),
                        str(jobs)], env=env, cwd=workdir, capture_output=True, text=True, timeout=timeout)
    assert r.returncode == 0, r.stderr[-3000:]
    summary = json.loads(r.stdout.strip().splitlines()[-1])
    print(f"\nloader fuzz seed {seed}: {count} mutations in {summary['seconds']:.1f} s: {summary['counts']}")
    for kind, c in sorted(summary["by_kind"].items()):
        print(f"  {kind:13s} {c}")
    return summary


def _no_findings(summary: dict) -> None:
    bad = {k: v for k, v in summary["counts"].items() if k not in ("ok", "error")}
    detail = "\n".join(f"  m{f['i']} [{f['kind']}] {f['what']}: {f['outcome']}: {f['detail']}\n"
                       f"    {f.get('file')}\n{f.get('traceback', '')}" for f in summary["failures"][:5])
    assert not bad, f"{bad}\n{detail}"
    assert sum(summary["counts"].values()) == summary["count"]


def test_300_mutations_load_or_give_one_line(valid_file, tmp_path):
    summary = _fuzz(valid_file, tmp_path, seed=18, count=300)
    _no_findings(summary)
    assert summary["counts"].get("ok", 0) > 0 and summary["counts"].get("error", 0) > 100
    assert summary["seconds"] <= 30, summary["seconds"]


@pytest.mark.slow
def test_10k_mutations_load_or_give_one_line(valid_file, tmp_path):
    summary = _fuzz(valid_file, tmp_path, seed=1018, count=10_000, timeout=3600)
    _no_findings(summary)
