"""STPM's version: the same string as ``pyproject.toml`` and ``addon/blender_manifest.toml``
(tests/test_kernel_cache_dir.py checks all three).  Keys the compiled-kernel cache folder."""
__version__ = "0.1.0"
