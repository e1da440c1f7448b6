"""What accuracy costs in time: how long each estimator needs to match the accumulation buffer.

For a metric (RMSE, relative MSE or FLIP) the **target** is the error of
ACCUMULATION with N = ``target_steps`` instants (16 by default; the largest N
run at or below it if that run was skipped).  Each photon estimator's runs
form an error-vs-time curve (a PROGRESSIVE or SPPM run is a curve by itself: its
image measured after passes 1, 2, 4, ...): their Pareto front (by wall time, each run kept
only if it beats every cheaper run).  The time it needs to reach the target is
where that front first crosses it, interpolated linearly in log(time) -
log(error) between the two runs either side.  Cases:

* its cheapest run is already at or below the target: time = that run's time,
  marked ``bound = 'at most'``;
* it never reaches the target within the sweep: time None, ``bound = 'not reached'``.

speed-up = accumulation time / estimator time (> 1: the estimator is faster).
"""
from __future__ import annotations

import math

__all__ = ["pareto_front", "time_to_reach", "cost_of_accuracy", "curve_points", "METRICS", "TIME_DEPENDENT"]

METRICS = ("rmse", "relmse", "flip")
TIME_DEPENDENT = ("TEMPORAL", "KD4D", "PROGRESSIVE")
_ORDER = ("STANDARD", "TEMPORAL", "KD4D", "PROGRESSIVE", "SPPM")


def curve_points(runs, method: str, metric: str) -> list:
    """(wall_s, error) points of ``method``'s finished runs; a PROGRESSIVE / SPPM run gives its curve."""
    pts = []
    for r in runs:
        if r.method != method or r.status != "done":
            continue
        if getattr(r, "curve", None):
            pts.extend((c["wall_s"], c.get(metric)) for c in r.curve)
        else:
            pts.append((r.wall_s, r.errors.get(metric)))
    return pts


def pareto_front(points):
    """The runs worth their time: sorted by time, each kept only if its error is below every cheaper run's."""
    front = []
    for t, e, *rest in sorted(points, key=lambda p: (p[0], p[1])):
        if not front or e < front[-1][1]:
            front.append((t, e, *rest))
    return front


def time_to_reach(points, target: float) -> tuple[float | None, str]:
    """(seconds, bound) for a curve [(wall_s, error), ...] to reach ``target`` error.

    bound: 'interpolated' | 'at most' | 'not reached'.
    """
    pts = pareto_front([(t, e) for t, e in points if t is not None and e is not None and t > 0])
    for i, (t, e) in enumerate(pts):
        if e <= target:
            if i == 0:
                return t, "at most"
            t0, e0 = pts[i - 1]
            if e <= 0 or e0 <= 0 or target <= 0 or e0 == e:
                return t, "interpolated"
            # Linear in log-log between the last run above and the first at or below the target
            w = (math.log(e0) - math.log(target)) / (math.log(e0) - math.log(e))
            return math.exp(math.log(t0) + w * (math.log(t) - math.log(t0))), "interpolated"
    return None, "not reached"


def _target_run(runs, target_steps: int):
    """The ACCUMULATION run with N = target_steps, else the largest done N below it, else None."""
    acc = [r for r in runs if r.method == "ACCUMULATION" and r.status == "done"]
    exact = [r for r in acc if r.accumulation_steps == target_steps]
    if exact:
        return exact[0]
    below = sorted((r for r in acc if r.accumulation_steps < target_steps), key=lambda r: r.accumulation_steps)
    return below[-1] if below else None


def cost_of_accuracy(runs, *, target_steps: int = 16, metrics=METRICS) -> dict:
    """Time for each photon estimator to reach ACCUMULATION-N's error, and the speed-up.

    Returns a JSON-ready dict::

        {'target': {'label', 'accumulation_steps', 'wall_s', 'rmse', ...} or None,
         'note': str,
         'metrics': {metric: {estimator: {'time_s', 'bound', 'speedup'}}},
         'best_time_dependent': {metric: {'estimator', 'time_s', 'speedup'} or None}}
    """
    target = _target_run(runs, target_steps)
    out = {"target": None, "note": "", "metrics": {}, "best_time_dependent": {}}
    if target is None:
        out["note"] = f"no ACCUMULATION run with N <= {target_steps} finished: nothing to compare against"
        return out
    out["target"] = {"label": target.label, "accumulation_steps": target.accumulation_steps,
                     "wall_s": target.wall_s, **{m: target.errors.get(m) for m in metrics}}
    if target.accumulation_steps != target_steps:
        out["note"] = (f"ACCUMULATION N={target_steps} was not run; the target is {target.label}")
    estimators = sorted({r.method for r in runs if r.method != "ACCUMULATION"}, key=_ORDER.index)
    for m in metrics:
        goal = target.errors.get(m)
        per = {}
        for est in estimators:
            pts = curve_points(runs, est, m)
            if goal is None:
                per[est] = {"time_s": None, "bound": "no target", "speedup": None}
                continue
            t, bound = time_to_reach(pts, goal)
            speedup = (target.wall_s / t) if (t and target.wall_s) else None
            per[est] = {"time_s": t, "bound": bound, "speedup": speedup}
        out["metrics"][m] = per
        reached = [(v["time_s"], est) for est, v in per.items() if est in TIME_DEPENDENT and v["time_s"]]
        if reached:
            t, est = min(reached)
            out["best_time_dependent"][m] = {"estimator": est, "time_s": t, "speedup": per[est]["speedup"],
                                             "bound": per[est]["bound"]}
        else:
            out["best_time_dependent"][m] = None
    return out
