"""``stpm compare``: what accuracy costs in time, against the accumulation buffer.

Modules:

* :mod:`.reference`   -- the reference image: supplied, or computed (TEMPORAL, many photons) and cached;
* :mod:`.sweep`       -- the runs (STANDARD / TEMPORAL / KD4D x photon budgets, ACCUMULATION x N,
  the PROGRESSIVE and SPPM curves), their wall time and error;
* :mod:`.sppm`        -- the SPPM baseline: one shutter instant per pass, pbrt-v4's radius update;
* :mod:`.metrics`     -- RMSE, relative MSE, FLIP and the error-map images;
* :mod:`.costs`       -- time for each estimator to reach ACCUMULATION-16's error, speed-up;
* :mod:`.plots`       -- the log-log error-vs-time chart as inline SVG;
* :mod:`.report_html` -- the self-contained report page;
* :mod:`.run`         -- :func:`run_compare`, tying them together;
* :mod:`.command`     -- :func:`main`, the ``stpm compare`` command line.

See docs/compare.md.
"""
from .command import main
from .costs import cost_of_accuracy, time_to_reach
from .metrics import image_errors
from .reference import Reference, get_reference, reference_settings
from .run import run_compare
from .sweep import Run, plan_runs, run_sweep

main_compare = main      # alias: stpm_core.cli calls compare.main(argv)

__all__ = ["main", "main_compare", "run_compare", "get_reference", "reference_settings", "Reference",
           "plan_runs", "run_sweep", "Run", "image_errors", "cost_of_accuracy", "time_to_reach"]
