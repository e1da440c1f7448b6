"""Render presets: named bundles of ``scene.stpm`` values.

``Preview`` renders in seconds (noisy, blurry caustics); ``Final`` is the
setting for frames that leave the studio.  Applied by ``stpm.apply_preset``.
"""
from __future__ import annotations

PRESETS: dict[str, dict] = {
    "PREVIEW": {
        "method": "PHOTON", "estimator": "TEMPORAL", "samples": 4, "photons_global": 20_000,
        "photons_caustic": 50_000, "k_nearest": 30, "temporal_alpha": 0.0, "time_scale": 0.0,
        "max_depth": 4, "motion_steps": 3,
    },
    "FINAL": {
        "method": "PHOTON", "estimator": "TEMPORAL", "samples": 64, "photons_global": 1_000_000,
        "photons_caustic": 2_000_000, "k_nearest": 100, "temporal_alpha": 0.0, "time_scale": 0.0,
        "max_depth": 8, "motion_steps": 5,
    },
}

PRESET_ITEMS = (
    ("PREVIEW", "Preview", "Fast and noisy: look development"),
    ("FINAL", "Final", "Many photons and samples: final frames"),
)


def apply_preset(props, name: str) -> None:
    """Set every value of preset ``name`` on a ``scene.stpm`` property group."""
    for key, value in PRESETS[name].items():
        setattr(props, key, value)
