"""The error-vs-time plot of the report: a log-log chart drawn as inline SVG (no plotting library).

``error_vs_time_svg(series, ...)`` takes one curve per method, each a list of
(wall seconds, error, label) points, and returns an ``<svg>`` element string:
log10 axes with decade ticks (and 2, 5 ticks when the range is short), one
polyline with markers per method, a legend, and optionally a dashed
horizontal line at a target error (ACCUMULATION N=16's).  Points with a
missing or non-positive coordinate are left out (log axes).
"""
from __future__ import annotations

import math
from html import escape

from .costs import pareto_front

__all__ = ["error_vs_time_svg", "METHOD_COLORS", "log_ticks"]

METHOD_COLORS = {"ACCUMULATION": "#333333", "STANDARD": "#d62728", "TEMPORAL": "#1f77b4", "KD4D": "#2ca02c",
                 "PROGRESSIVE": "#9467bd", "SPPM": "#ff7f0e"}
_FALLBACK_COLORS = ("#9467bd", "#8c564b", "#e377c2", "#7f7f7f")


def log_ticks(lo: float, hi: float) -> list[float]:
    """Tick values in [lo, hi] (lo > 0): decades, plus 2 and 5 x decades when the span is under 3 decades."""
    a, b = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    mult = (1, 2, 5) if b - a <= 3 else (1,)
    ticks = [m * 10.0 ** e for e in range(a, b + 1) for m in mult]
    return [t for t in ticks if lo * (1 - 1e-9) <= t <= hi * (1 + 1e-9)]


def _fmt(v: float) -> str:
    return f"{v:.3g}" if (1e-3 <= abs(v) < 1e4) else f"{v:.0e}"


def _range(values) -> tuple[float, float]:
    """Padded log range [lo, hi] covering ``values`` (all > 0)."""
    lo, hi = min(values), max(values)
    if hi / lo < 10.0:                      # at least one decade, centred
        c = math.sqrt(lo * hi)
        lo, hi = c / math.sqrt(10.0), c * math.sqrt(10.0)
    pad = (hi / lo) ** 0.05
    return lo / pad, hi * pad


def error_vs_time_svg(series: dict, *, ylabel: str = "RMSE", xlabel: str = "render time (s)",
                      target: tuple[float, str] | None = None, width: int = 640, height: int = 400,
                      title: str | None = None) -> str:
    """Log-log error-vs-time chart.

    series : method name -> [(seconds, error, point label), ...] (any order; sorted by time).
    target : (error, label) for a dashed horizontal line, or None.
    Returns an ``<svg>`` string (UTF-8 text, no external references).
    """
    # -- Keep the points a log axis can show --------------------------------------------
    curves = {}
    for name, pts in series.items():
        good = sorted((float(t), float(e), str(lbl)) for t, e, lbl in pts
                      if t is not None and e is not None and t > 0 and e > 0
                      and math.isfinite(t) and math.isfinite(e))
        if good:
            curves[name] = good
    xs = [p[0] for c in curves.values() for p in c]
    ys = [p[1] for c in curves.values() for p in c]
    if target is not None and target[0] is not None and target[0] > 0:
        ys.append(float(target[0]))
    L, R, T, B = 72, 150, 30 if title else 14, 48        # margins: left, right (legend), top, bottom
    pw, ph = width - L - R, height - T - B
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12" role="img" '
           f'aria-label="{escape(ylabel)} against {escape(xlabel)}, log-log">',
           f'<rect x="0" y="0" width="{width}" height="{height}" fill="white"/>']
    if title:
        out.append(f'<text x="{L + pw / 2}" y="18" text-anchor="middle" font-size="14">{escape(title)}</text>')
    if not xs:
        out.append(f'<text x="{width / 2}" y="{height / 2}" text-anchor="middle">no finished runs to plot</text>')
        out.append("</svg>")
        return "\n".join(out)

    # -- Axes: log10 mapping -------------------------------------------------------------
    x0, x1 = _range(xs)
    y0, y1 = _range(ys)

    def X(t):
        return L + pw * (math.log10(t) - math.log10(x0)) / (math.log10(x1) - math.log10(x0))

    def Y(e):
        return T + ph * (1.0 - (math.log10(e) - math.log10(y0)) / (math.log10(y1) - math.log10(y0)))

    out.append(f'<rect x="{L}" y="{T}" width="{pw}" height="{ph}" fill="none" stroke="#999"/>')
    for t in log_ticks(x0, x1):
        x = X(t)
        major = abs(math.log10(t) - round(math.log10(t))) < 1e-9
        out.append(f'<line x1="{x:.1f}" y1="{T}" x2="{x:.1f}" y2="{T + ph}" stroke="{"#ddd" if major else "#eee"}"/>')
        out.append(f'<text x="{x:.1f}" y="{T + ph + 16}" text-anchor="middle">{_fmt(t)}</text>')
    for e in log_ticks(y0, y1):
        y = Y(e)
        major = abs(math.log10(e) - round(math.log10(e))) < 1e-9
        out.append(f'<line x1="{L}" y1="{y:.1f}" x2="{L + pw}" y2="{y:.1f}" stroke="{"#ddd" if major else "#eee"}"/>')
        out.append(f'<text x="{L - 6}" y="{y + 4:.1f}" text-anchor="end">{_fmt(e)}</text>')
    out.append(f'<text x="{L + pw / 2}" y="{height - 10}" text-anchor="middle">{escape(xlabel)} (log)</text>')
    out.append(f'<text x="16" y="{T + ph / 2}" text-anchor="middle" '
               f'transform="rotate(-90 16 {T + ph / 2})">{escape(ylabel)} (log)</text>')

    # -- Target line ------------------------------------------------------------------------
    if target is not None and target[0] is not None and target[0] > 0:
        y = Y(float(target[0]))
        out.append(f'<line x1="{L}" y1="{y:.1f}" x2="{L + pw}" y2="{y:.1f}" stroke="#333" '
                   f'stroke-dasharray="5,4"/>')
        out.append(f'<text x="{L + pw - 4}" y="{y - 5:.1f}" text-anchor="end" fill="#333">{escape(target[1])}</text>')

    # -- Curves and legend -------------------------------------------------------------------
    for i, (name, pts) in enumerate(curves.items()):
        color = METHOD_COLORS.get(name, _FALLBACK_COLORS[i % len(_FALLBACK_COLORS)])
        path = " ".join(f"{X(t):.1f},{Y(e):.1f}" for t, e, _ in pareto_front(pts))
        out.append(f'<g class="curve" data-method="{escape(name)}">')
        out.append(f'<polyline points="{path}" fill="none" stroke="{color}" stroke-width="2"/>')
        for t, e, lbl in pts:
            out.append(f'<circle cx="{X(t):.1f}" cy="{Y(e):.1f}" r="4" fill="{color}">'
                       f'<title>{escape(lbl)}: {t:.3g} s, {escape(ylabel)} {e:.4g}</title></circle>')
        out.append("</g>")
        ly = T + 10 + 20 * i
        out.append(f'<line x1="{L + pw + 12}" y1="{ly}" x2="{L + pw + 36}" y2="{ly}" stroke="{color}" stroke-width="2"/>')
        out.append(f'<circle cx="{L + pw + 24}" cy="{ly}" r="4" fill="{color}"/>')
        out.append(f'<text x="{L + pw + 42}" y="{ly + 4}">{escape(name)}</text>')
    out.append("</svg>")
    return "\n".join(out)
