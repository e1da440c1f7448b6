"""pytest configuration: heavy tests are opt-in.

``@pytest.mark.slow`` tests are skipped unless the environment sets
``STPM_SLOW=1``.  The tests directory is put on ``sys.path`` so test files can
``import scenes`` (the shared tiny-scene builders).  Bakes of unsupported shader inputs
(addon/export/bake.py) go to a temporary folder for the session (``STPM_BAKE_CACHE``), never to
the user's cache or next to the repository's .blend files.
"""
from __future__ import annotations

import os
import sys

import tempfile

import pytest

sys.path.insert(0, os.path.dirname(__file__))


_BAKE_CACHE: list = []


def pytest_configure(config):
    if not os.environ.get("STPM_BAKE_CACHE"):
        _BAKE_CACHE.append(tempfile.mkdtemp(prefix="stpm_test_bake_cache_"))
        os.environ["STPM_BAKE_CACHE"] = _BAKE_CACHE[0]


def pytest_unconfigure(config):
    import shutil
    for d in _BAKE_CACHE:
        shutil.rmtree(d, ignore_errors=True)


def pytest_collection_modifyitems(config, items):
    if os.environ.get("STPM_SLOW", "") == "1":
        return
    skip = pytest.mark.skip(reason="slow: set STPM_SLOW=1 to run")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
