"""``report.html``: one self-contained page (images as base64 PNG, plots as inline SVG).

Sections, each a ``<section id=...>``:

* ``scene``      -- scene and settings the sweep used, and the reference;
* ``images``     -- the reference and each method's best run, side by side;
* ``error-maps`` -- per best run: FLIP error (magma) and signed luminance error
  (blue = too dark, red = too bright);
* ``plot``       -- error against render time, log-log, one curve per method;
* ``table``      -- the seed's table: method, consistent?, time, RMSE, relMSE, FLIP;
* ``cost``       -- what accuracy costs in time: time to reach ACCUMULATION-16's error;
* ``runs``       -- every run with its phases, and what was skipped.

Images are sRGB-encoded 8-bit PNGs written by :func:`png_bytes` (zlib, no
external encoder), all with the same exposure (``metrics.display_scale``).
"""
from __future__ import annotations

import base64
import struct
import zlib
from html import escape

import numpy as np

from ..imageio import linear_to_srgb
from .costs import METRICS
from .metrics import diverging_colors, signed_relative_error
from .plots import METHOD_COLORS, error_vs_time_svg

__all__ = ["png_bytes", "png_data_uri", "render_html", "METRIC_NAMES"]

_LUMA = np.array([0.2126, 0.7152, 0.0722])   # Rec. 709 luminance weights

METRIC_NAMES = {"rmse": "RMSE", "relmse": "relMSE", "flip": "FLIP"}
_MIN_DISPLAY_WIDTH = 240     # small renders are shown enlarged (pixelated), never below this


# ----------------------------------------------------------------------------
# PNG encoding
# ----------------------------------------------------------------------------
def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_bytes(rgb8: np.ndarray) -> bytes:
    """PNG file bytes of an (H, W, 3) uint8 image (8-bit RGB, filter 0 on every row, sRGB chunk)."""
    rgb8 = np.ascontiguousarray(rgb8, dtype=np.uint8)
    H, W = rgb8.shape[:2]
    raw = np.concatenate([np.zeros((H, 1), np.uint8), rgb8.reshape(H, W * 3)], axis=1).tobytes()
    return (b"\x89PNG\r\n\x1a\n"
            + _chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 2, 0, 0, 0))
            + _chunk(b"sRGB", b"\x00")
            + _chunk(b"IDAT", zlib.compress(raw, 9))
            + _chunk(b"IEND", b""))


def png_data_uri(rgb: np.ndarray, *, linear: bool = True, scale: float = 1.0) -> str:
    """``data:image/png;base64,...`` of (H, W, 3) RGB: linear radiance (x scale, sRGB-encoded) or display [0, 1]."""
    v = linear_to_srgb(np.asarray(rgb, np.float64) * scale) if linear else np.clip(np.nan_to_num(rgb), 0.0, 1.0)
    return "data:image/png;base64," + base64.b64encode(png_bytes(np.round(v * 255.0).astype(np.uint8))).decode("ascii")


# ----------------------------------------------------------------------------
# Formatting helpers
# ----------------------------------------------------------------------------
def _num(v, fmt="{:.4g}", none="&mdash;") -> str:
    return none if v is None else fmt.format(v)


def _secs(v) -> str:
    return "&mdash;" if v is None else (f"{v:.2f} s" if v < 100 else f"{v:.0f} s")


def _img(uri: str, W: int, H: int, alt: str) -> str:
    w = max(W, _MIN_DISPLAY_WIDTH)
    return (f'<img src="{uri}" alt="{escape(alt)}" width="{w}" height="{int(round(H * w / W))}" '
            f'style="image-rendering: pixelated">')


def _figure(inner: str, caption: str) -> str:
    return f"<figure>{inner}<figcaption>{caption}</figcaption></figure>"


_CSS = """
body { font-family: sans-serif; margin: 2em; color: #222; max-width: 1400px; }
h1 { font-size: 1.5em; } h2 { font-size: 1.2em; border-bottom: 1px solid #ccc; padding-bottom: .2em; margin-top: 2em; }
table { border-collapse: collapse; margin: .5em 0; } td, th { border: 1px solid #ccc; padding: .25em .6em; text-align: right; }
th { background: #f3f3f3; } td:first-child, th:first-child { text-align: left; }
.row { display: flex; flex-wrap: wrap; gap: 1em; align-items: flex-start; }
figure { margin: 0; } figcaption { font-size: .85em; text-align: center; max-width: 320px; margin: .3em auto; }
.note { color: #555; font-size: .9em; } .skipped { color: #999; } .swatch { display: inline-block; width: 1em; height: .6em; }
code { background: #f5f5f5; padding: 0 .2em; }
"""


# ----------------------------------------------------------------------------
# Sections
# ----------------------------------------------------------------------------
def _recipe(rs: dict) -> str:
    """One line describing a computed reference's settings."""
    acc = rs.get("method") == "ACCUMULATION"
    per = " per instant" if acc else ""
    head = (f'accumulation buffer, {rs.get("accumulation_steps")} instants, ' if acc else
            f'{escape(str(rs.get("estimator")))} estimator (temporal_alpha {rs.get("temporal_alpha")}), ')
    return (head + f'{rs.get("photons_caustic")} caustic + {rs.get("photons_global")} global photons{per}, '
            f'{rs.get("samples")} samples/pixel{per}, k = {rs.get("k_nearest")}')


def _section_scene(rep: dict) -> str:
    sc, st, ref, sw = rep["scene"], rep["settings"], rep["reference"], rep["sweep"]
    rows = [("scene", escape(str(sc.get("name")))), ("resolution", f'{sc["resolution"][0]} x {sc["resolution"][1]}'),
            ("frame", _num(sc.get("frame"), "{:g}")),
            ("shutter", f'{sc["shutter"]["open"]:g} .. {sc["shutter"]["close"]:g} frames'
                        + (" (curve)" if sc["shutter"].get("curve") else "")),
            ("something moves", "yes" if sc.get("has_motion") else "no"),
            ("effects plan", escape(", ".join(k for k in ("motion_blur", "caustics", "indirect", "time_dependent")
                                              if sc.get("plan", {}).get(k)) or "none"))]
    kexp = float(sw.get("k_exponent") or 0.0)
    rows.append(("photon budgets", ", ".join(f"x{b[0]:g}" + ("" if len(b) < 2 or b[1] == 1 else f" s{b[1]:g}")
                                             + ("" if len(b) < 3 or b[2] == 1 else f" k x{b[2]:g}")
                                             for b in sw["photon_budgets"])
                                   + ("" if kexp == 0 else f"; k x b^{kexp:g}")))
    rows.append(("accumulation N", ", ".join(str(n) for n in sw["accumulation_steps"])))
    rows.append(("time budget", "none" if sw["time_budget_s"] is None else f'{sw["time_budget_s"]:g} s'))
    keys = ("samples", "photons_caustic", "photons_global", "k_nearest", "temporal_alpha", "time_scale",
            "seed", "kernel", "effects")
    srows = [(k, escape(str(st.get(k)))) for k in keys]
    body = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in rows)
    sbody = "".join(f"<tr><th>{k}</th><td>{v}</td></tr>" for k, v in srows)
    rs = ref.get("settings") or {}
    if ref["source"] == "supplied":
        ref_line = (f'supplied ({escape(str(ref.get("kind")))})'
                    + (f': <code>{escape(str(ref["path"]))}</code>' if ref.get("path") else ""))
    else:
        ref_line = f'{escape(ref["source"])} ({escape(ref["kind"])}): ' + _recipe(rs) + \
            (f'; rendered in {_secs(ref.get("wall_s"))}' if ref.get("wall_s") is not None else "")
    return (f'<section id="scene"><h2>Scene and settings</h2>'
            f'<div class="row"><table>{body}</table><table>{sbody}</table></div>'
            f'<p><b>Reference</b>: {ref_line}.<br><span class="note">Why it is right: {escape(ref["why"])}</span></p>'
            f'<p class="note">Errors are measured on the linear RGB of the Combined pass. RMSE is in pixel units '
            f'(shutter-averaged radiance); relMSE = mean (x - r)&sup2; / (r&sup2; + {rep["metrics"]["relmse_eps"]:g}); '
            f'FLIP is the mean HDR-FLIP error (0 = identical, 1 = as different as can be). '
            f'Images are shown with exposure x{rep["display"]["exposure"]:.3g}, sRGB.</p></section>')


def _best_runs(rep: dict, runs_by_label: dict) -> list:
    """[(method, run)] of each method's best (lowest RMSE) finished run, in method order."""
    out = []
    for method, label in rep["best"].items():
        if label is not None and label in runs_by_label:
            out.append((method, runs_by_label[label]))
    return out


def _section_images(rep: dict, ref_rgb, best, exposure: float) -> str:
    H, W = ref_rgb.shape[:2]
    figs = [_figure(_img(png_data_uri(ref_rgb, scale=exposure), W, H, "reference"), "<b>reference</b>")]
    for method, run in best:
        cap = (f'<b>{escape(run.label)}</b><br>{_secs(run.wall_s)}, RMSE {_num(run.errors["rmse"])}, '
               f'FLIP {_num(run.errors["flip"], "{:.3f}")}')
        figs.append(_figure(_img(png_data_uri(run.rgb, scale=exposure), W, H, run.label), cap))
    return ('<section id="images"><h2>Images side by side</h2>'
            '<p class="note">The reference and, for each method, its run with the lowest RMSE.</p>'
            f'<div class="row">{"".join(figs)}</div></section>')


def _section_error_maps(ref_rgb, best) -> str:
    H, W = ref_rgb.shape[:2]
    flips, signed = [], []
    for method, run in best:
        if run.flip_map is not None:
            flips.append(_figure(_img(png_data_uri(run.flip_map, linear=False), W, H, f"FLIP map {run.label}"),
                                 f'FLIP: {escape(run.label)} (mean {_num(run.errors["flip"], "{:.3f}")})'))
        d = signed_relative_error(run.rgb.astype(np.float64), ref_rgb)
        overall = float(np.mean(run.rgb @ _LUMA) / max(float(np.mean(ref_rgb @ _LUMA)), 1e-12) - 1.0)
        signed.append(_figure(_img(png_data_uri(diverging_colors(d, 0.5), linear=False), W, H,
                                   f"signed error {run.label}"),
                              f'{escape(run.label)}: overall {100 * overall:+.1f} %'))
    legend = ('<p class="note">Signed luminance error (test - reference) / max(reference, 5 % of its mean); '
              'the caption gives the overall brightness error (mean luminance against the reference\'s): '
              '<span class="swatch" style="background:#2159d9"></span> -50 % or darker, white = right, '
              '<span class="swatch" style="background:#d92121"></span> +50 % or brighter. '
              'FLIP maps use the magma scale: black = no visible difference, yellow = large.</p>')
    return ('<section id="error-maps"><h2>Error maps</h2>' + legend
            + (f'<h3>FLIP</h3><div class="row">{"".join(flips)}</div>' if flips else
               '<p class="note">FLIP could not be computed (black reference).</p>')
            + f'<h3>Signed relative error</h3><div class="row">{"".join(signed)}</div></section>')


def _section_plot(rep: dict) -> str:
    svgs = []
    target = rep["cost"].get("target")
    for m in METRICS:
        series = {}
        for r in rep["runs"]:
            if r["status"] == "done" and r.get("curve"):
                series.setdefault(r["method"], []).extend(
                    (c["wall_s"], c[m], f'{r["label"]}: pass {c["pass"]}') for c in r["curve"] if c.get(m) is not None)
            elif r["status"] == "done" and r[m] is not None:
                series.setdefault(r["method"], []).append((r["wall_s"], r[m], r["label"]))
        order = [k for k in ("ACCUMULATION", "STANDARD", "TEMPORAL", "KD4D", "PROGRESSIVE", "SPPM") if k in series]
        tgt = (target[m], target["label"]) if target and target.get(m) is not None else None
        svgs.append(f'<figure>{error_vs_time_svg({k: series[k] for k in order}, ylabel=METRIC_NAMES[m], target=tgt, width=560, height=360)}'
                    f'<figcaption>{METRIC_NAMES[m]} against render time</figcaption></figure>')
    return ('<section id="plot"><h2>Error against render time</h2>'
            '<p class="note">Log-log; one curve per method (photon estimators: photon budget grows along the '
            'curve; ACCUMULATION: N grows; PROGRESSIVE and SPPM: one render measured after passes 1, 2, 4, ...). '
            'Lower-left is better. The dashed line is the target: '
            f'{escape(target["label"]) if target else "none"}.</p>'
            f'<div class="row">{"".join(svgs)}</div></section>')


def _section_table(rep: dict) -> str:
    names = {"ACCUMULATION": "Accumulation buffer", "STANDARD": "Standard radiance estimate",
             "TEMPORAL": "Time-dependent estimate (TEMPORAL)", "KD4D": "Time-dependent estimate (KD4D)",
             "PROGRESSIVE": "Progressive, shrinking space-time kernel", "SPPM": "SPPM, one instant per pass (pbrt-v4)"}
    rows = []
    for method, label in rep["best"].items():
        r = next((x for x in rep["runs"] if x["label"] == label), None)
        c = rep["consistent"][method]
        color = METHOD_COLORS.get(method, "#000")
        if r is None:
            rows.append(f'<tr><td><span class="swatch" style="background:{color}"></span> {names[method]}</td>'
                        f'<td>{"Yes" if c["consistent"] else "No"}</td><td colspan="5" class="skipped">no finished run</td></tr>')
            continue
        rows.append(f'<tr><td><span class="swatch" style="background:{color}"></span> {names[method]}</td>'
                    f'<td title="{escape(c["why"])}">{"Yes" if c["consistent"] else "No"}</td>'
                    f'<td>{escape(r["label"])}</td><td>{_secs(r["wall_s"])}</td><td>{_num(r["rmse"])}</td>'
                    f'<td>{_num(r["relmse"])}</td><td>{_num(r["flip"], "{:.4f}")}</td></tr>')
    return ('<section id="table"><h2>Methods: consistent?, time, error</h2>'
            '<p class="note">As in the seed\'s table; each method\'s best (lowest RMSE) run. '
            'Hover "Yes"/"No" for why.</p>'
            '<table><tr><th>Method</th><th>Consistent?</th><th>Run</th><th>Render time</th><th>RMSE</th>'
            f'<th>relMSE</th><th>FLIP</th></tr>{"".join(rows)}</table></section>')


def _section_cost(rep: dict) -> str:
    cost = rep["cost"]
    tgt = cost.get("target")
    if tgt is None:
        return ('<section id="cost"><h2>What accuracy costs in time</h2>'
                f'<p>{escape(cost.get("note") or "no accumulation run to compare against")}.</p></section>')
    lines = []
    for m, per in cost["metrics"].items():
        for est, v in per.items():
            if v["time_s"] is None:
                cell_t, cell_s = escape(v["bound"]), "&mdash;"
            else:
                cell_t = ("&le; " if v["bound"] == "at most" else "") + _secs(v["time_s"])
                cell_s = ("&ge; " if v["bound"] == "at most" else "") + _num(v["speedup"], "{:.2f}x")
            lines.append(f'<tr><td>{METRIC_NAMES[m]}</td><td>{escape(est)}</td><td>{_num(tgt.get(m))}</td>'
                         f'<td>{cell_t}</td><td>{cell_s}</td></tr>')
    head = []
    for m in METRICS:
        b = cost["best_time_dependent"].get(m)
        if b:
            head.append(f'<li>{METRIC_NAMES[m]}: <b>{escape(b["estimator"])}</b> reaches {escape(tgt["label"])}\'s '
                        f'error ({_num(tgt.get(m))}) in {("&le; " if b["bound"] == "at most" else "")}{_secs(b["time_s"])} '
                        f'against {_secs(tgt["wall_s"])}: <b>{_num(b["speedup"], "{:.2f}x")}</b> faster.</li>')
        else:
            head.append(f'<li>{METRIC_NAMES[m]}: no time-dependent estimator reached {escape(tgt["label"])}\'s error '
                        f'({_num(tgt.get(m))}) within the sweep.</li>')
    note = f'<p class="note">{escape(cost["note"])}</p>' if cost.get("note") else ""
    for name, cx in (rep.get("cross_references") or {}).items():
        agree = cx["main_reference_error"]
        items = []
        for m in METRICS:
            b = cx["cost"]["best_time_dependent"].get(m)
            t = cx["cost"].get("target") or {}
            items.append(f'{METRIC_NAMES[m]}: ' + (
                f'{escape(b["estimator"])} {("&le; " if b["bound"] == "at most" else "")}{_secs(b["time_s"])}, '
                f'{_num(b["speedup"], "{:.2f}x")}' if b else f'not reached (target {_num(t.get(m))})'))
        rs = cx["reference"].get("settings") or {}
        note += (f'<p><b>Cross-check against a second reference, {escape(name)}</b> '
                 f'({escape(str(cx["reference"].get("kind")))}{(": " + _recipe(rs)) if rs else ""}). '
                 f'The main reference is off it by RMSE {_num(agree["rmse"])}, relMSE {_num(agree["relmse"])}, '
                 f'FLIP {_num(agree["flip"], "{:.4f}")}. Measured against it, the best time-dependent '
                 f'estimator reaches the target in: {"; ".join(items)}.</p>')
    return ('<section id="cost"><h2>What accuracy costs in time</h2>'
            f'<p>Target: <b>{escape(tgt["label"])}</b>, {_secs(tgt["wall_s"])}.</p><ul>{"".join(head)}</ul>{note}'
            '<p class="note">Time to reach the target: where the estimator\'s error-vs-time curve first crosses '
            'it, interpolated in log-log between its runs; "&le;" when its cheapest run already beats it. '
            'Speed-up = accumulation time / estimator time.</p>'
            '<table><tr><th>Metric</th><th>Estimator</th><th>Target error</th><th>Time to reach</th>'
            f'<th>Speed-up</th></tr>{"".join(lines)}</table></section>')


def _section_runs(rep: dict) -> str:
    rows = []
    for r in rep["runs"]:
        cls = "" if r["status"] == "done" else ' class="skipped"'
        ph = r.get("phases") or {}
        photons = f'{r["photons_caustic"]} / {r["photons_global"]}'
        samples = r["samples"] * (r["accumulation_steps"] or 1)
        rows.append(f'<tr{cls}><td>{escape(r["label"])}</td><td>{escape(r["status"])}'
                    f'{(": " + escape(r["note"])) if r.get("note") else ""}</td><td>{photons}</td><td>{samples}</td>'
                    f'<td>{_secs(r["wall_s"])}</td><td>{_secs(ph.get("photon_trace_s"))}</td>'
                    f'<td>{_secs(ph.get("photon_lookup_s"))}</td><td>{_secs(ph.get("render_s"))}</td>'
                    f'<td>{_num(r["rmse"])}</td><td>{_num(r["relmse"])}</td><td>{_num(r["flip"], "{:.4f}")}</td></tr>')
    sw = rep["sweep"]
    skipped = sw["skipped"]
    if not skipped:
        note = "<p>Every planned run finished.</p>"
    elif sw.get("cancelled"):
        note = f'<p><b>Skipped</b> ({len(skipped)}): the sweep was cancelled before {escape(", ".join(skipped))}.</p>'
    else:
        note = (f'<p><b>Skipped</b> ({len(skipped)}): the time budget of {sw["time_budget_s"]:g} s was spent '
                f'before {escape(", ".join(skipped))} could start.</p>')
    return ('<section id="runs"><h2>All runs</h2>' + note
            + f'<p class="note">Sweep time {_secs(sw["sweep_wall_s"])} (reference not included). '
              'Photons: emitted per still, caustic / global. Samples / pixel: in total (ACCUMULATION: N x per still). '
              'Photon look-ups: seconds inside look-ups summed over the worker threads (they run inside ray tracing, '
              'so they can exceed its wall time).</p>'
            '<table><tr><th>Run</th><th>Status</th><th>Photons</th><th>Samples / pixel</th><th>Wall time</th><th>Photon tracing</th>'
            '<th>Photon look-ups</th><th>Ray tracing</th><th>RMSE</th><th>relMSE</th><th>FLIP</th></tr>'
            f'{"".join(rows)}</table></section>')


# ----------------------------------------------------------------------------
# The page
# ----------------------------------------------------------------------------
def render_html(rep: dict, ref_rgb: np.ndarray, runs: list) -> str:
    """The whole report page.

    rep : the report dict (what ``report.json`` holds).
    ref_rgb : (H, W, 3) linear reference.  runs : the sweep's Run objects (images).
    """
    exposure = float(rep["display"]["exposure"])
    best = _best_runs(rep, {r.label: r for r in runs if r.status == "done"})
    title = f'STPM compare: {rep["scene"].get("name")}'
    return ("<!DOCTYPE html>\n"
            f'<html lang="en"><head><meta charset="utf-8"><title>{escape(title)}</title>'
            f'<style>{_CSS}</style></head><body>'
            f'<h1>{escape(title)}</h1>'
            f'<p class="note">What accuracy costs in time: the time-stamped photon map (STANDARD, TEMPORAL, KD4D '
            f'estimates) against the accumulation buffer. Generated by stpm compare on {escape(rep["generated_utc"])}.</p>'
            + _section_scene(rep) + _section_images(rep, ref_rgb, best, exposure) + _section_error_maps(ref_rgb, best)
            + _section_plot(rep) + _section_table(rep) + _section_cost(rep) + _section_runs(rep)
            + "</body></html>\n")
