"""Render presets: named bundles of ``scene.stpm`` values.

``Preview`` renders in seconds (noisy, blurry caustics); ``Final`` is the
setting for frames that leave the studio.  The progressive variants render
passes until a time limit (``Preview Progressive``: the image sharpens for
as long as you watch) or a noise threshold (``Final Progressive``); their
photon counts and samples are per pass: many small passes (1 sample per pixel, k = 20) measured
best (docs/compare.md, "Progressive and SPPM").  Every preset allows 8 bounces: a glass of liquid is six
interfaces deep, and the Preview presets' former 4 rendered it black (tests/test_preset_depth.py; no
measurable cost on the demo: diffuse paths end at the photon maps).  Applied by ``stpm.apply_preset``.
"""
from __future__ import annotations

PRESETS: dict[str, dict] = {
    "PREVIEW": {
        "method": "PHOTON", "estimator": "TEMPORAL", "samples": 4, "photons_global": 20_000,
        "photons_caustic": 50_000, "k_nearest": 30, "temporal_alpha": 0.0, "time_scale": 0.0,
        "max_depth": 8, "motion_steps": 3,
    },
    "FINAL": {
        "method": "PHOTON", "estimator": "TEMPORAL", "samples": 256, "photons_global": 1_000_000,
        "photons_caustic": 2_000_000, "k_nearest": 100, "temporal_alpha": 0.0, "time_scale": 0.0,
        "use_adaptive_sampling": True, "adaptive_threshold": 0.05, "adaptive_min_samples": 32,
        "max_depth": 8, "motion_steps": 5, "rough_splits": 2,
    },
    "PREVIEW_PROGRESSIVE": {
        "method": "PROGRESSIVE", "estimator": "TEMPORAL", "samples": 1, "photons_global": 20_000,
        "photons_caustic": 50_000, "k_nearest": 20, "temporal_alpha": 0.0, "time_scale": 0.0,
        "passes": 0, "time_limit": 20.0, "noise_threshold": 0.0, "shrink_alpha": 0.0, "pass_offset": 0,
        "max_depth": 8, "motion_steps": 3,
    },
    "FINAL_PROGRESSIVE": {
        "method": "PROGRESSIVE", "estimator": "TEMPORAL", "samples": 1, "photons_global": 100_000,
        "photons_caustic": 200_000, "k_nearest": 20, "temporal_alpha": 0.0, "time_scale": 0.0,
        "passes": 1024, "time_limit": 0.0, "noise_threshold": 0.1, "shrink_alpha": 0.0, "pass_offset": 0,
        "max_depth": 8, "motion_steps": 5,
    },
}

PRESET_ITEMS = (
    ("PREVIEW", "Preview", "Fast and noisy: look development"),
    ("FINAL", "Final", "Many photons; 32 to 256 samples per pixel, more where the noise is (adaptive): final frames"),
    ("PREVIEW_PROGRESSIVE", "Preview Progressive",
     "Passes that sharpen for 20 seconds (a shrinking space-time kernel); stop it any time with Esc"),
    ("FINAL_PROGRESSIVE", "Final Progressive",
     "Passes until the estimated noise is under 10 % (at most 1024 passes): converges instead of stopping at "
     "a kernel's blur"),
)


def apply_preset(props, name: str) -> None:
    """Set every value of preset ``name`` on a ``scene.stpm`` property group."""
    for key, value in PRESETS[name].items():
        setattr(props, key, value)
