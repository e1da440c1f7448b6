"""pytest configuration: heavy tests are opt-in.

``@pytest.mark.slow`` tests are skipped unless the environment sets
``STPM_SLOW=1``.  The tests directory is put on ``sys.path`` so test files can
``import scenes`` (the shared tiny-scene builders).
"""
from __future__ import annotations

import os
import sys

import pytest

sys.path.insert(0, os.path.dirname(__file__))


def pytest_collection_modifyitems(config, items):
    if os.environ.get("STPM_SLOW", "") == "1":
        return
    skip = pytest.mark.skip(reason="slow: set STPM_SLOW=1 to run")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)
