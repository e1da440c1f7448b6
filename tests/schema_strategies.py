"""Hypothesis strategies derived from the typed schema (stpm_core/schema.py).

Every strategy is built from a :class:`~stpm_core.schema.Spec` row alone -- its kind, bounds,
``gap`` / ``hi_open`` and choices -- never from a field's name, so a field added to
``RenderSettings`` or to ``schema.METADATA`` is drawn (valid and invalid) without new test code.

* :func:`valid` / :func:`invalid`: values one row accepts / refuses (JSON-serialisable: they can
  be written into a scene file's header);
* :func:`settings_dicts`: whole settings dicts, every field valid (rules *between* fields are
  left to the test: any SettingsError of such a dict is one of those);
* :func:`metadata_dicts`: metadata with every typed key valid, plus free-form keys.
"""
from __future__ import annotations

import math

from hypothesis import strategies as st

from stpm_core.schema import FRAME_LIMIT, METADATA, Spec
from stpm_core.settings import RenderSettings

_NOT_NUMBERS = st.one_of(st.none(), st.text(max_size=6), st.lists(st.integers(0, 3), max_size=2),
                         st.sampled_from(["1", "0.5", "nan", "true", ""]))
_HUGE = st.sampled_from([10**400, -10**400])               # JSON integers no float can hold


def valid(spec: Spec) -> st.SearchStrategy:
    """Values ``spec`` accepts, as they can appear in a JSON header or a Python call."""
    k = spec.kind
    if k == "int":
        return st.integers(spec.lo, spec.hi)
    if k == "float":
        lo, hi = float(spec.lo), float(spec.hi)
        low = spec.gap if spec.gap is not None else lo
        nums = st.floats(low, hi, exclude_max=spec.hi_open, allow_nan=False, allow_infinity=False)
        a, b = math.ceil(low), min(math.floor(hi), 10**6)       # integers are numbers too
        if spec.hi_open and b >= hi:
            b -= 1
        parts = [nums] + ([st.integers(a, b)] if a <= b else [])
        if spec.gap is not None:
            parts.append(st.just(spec.lo))
        return st.one_of(*parts)
    if k == "bool":
        return st.one_of(st.booleans(), st.sampled_from([0, 1]))
    if k == "enum":
        return st.sampled_from(spec.values + tuple(v.lower() for v in spec.values))
    if k == "str":
        return st.text(max_size=20)
    if k == "strs":
        return st.lists(st.text(max_size=12), max_size=4)
    if k == "bools":
        return st.lists(st.booleans(), max_size=6)
    if k == "frames":
        return st.tuples(st.integers(-FRAME_LIMIT, FRAME_LIMIT), st.integers(-FRAME_LIMIT, FRAME_LIMIT)) \
            .map(lambda ab: sorted(ab))
    raise ValueError(f"no strategy for kind {k!r}")


def invalid(spec: Spec) -> st.SearchStrategy:
    """Values ``spec`` refuses: wrong types, out of range, NaN / inf, in a gap, ambiguous booleans."""
    k = spec.kind
    if k == "int":
        return st.one_of(st.integers(max_value=spec.lo - 1), st.integers(min_value=spec.hi + 1), _HUGE,
                         st.floats(allow_nan=True), st.booleans(), _NOT_NUMBERS)
    if k == "float":
        lo, hi = float(spec.lo), float(spec.hi)
        parts = [st.floats(max_value=lo, exclude_max=True), st.sampled_from([math.nan, math.inf, -math.inf]),
                 st.floats(min_value=hi, exclude_min=not spec.hi_open), _HUGE, st.booleans(), _NOT_NUMBERS]
        if spec.gap is not None:
            parts.append(st.floats(lo, spec.gap, exclude_min=True, exclude_max=True))
        return st.one_of(*parts)
    if k == "bool":
        return st.one_of(st.integers().filter(lambda v: v not in (0, 1)), st.floats(), _NOT_NUMBERS,
                         st.sampled_from(["false", "False", "0", "no"]))
    if k == "enum":
        return st.one_of(st.text(max_size=12).filter(lambda t: t.upper() not in spec.values),
                         st.integers(), st.booleans(), st.none(), st.just([spec.values[0]]))
    if k == "str":
        return st.one_of(st.integers(), st.booleans(), st.none(), st.lists(st.text(max_size=3), max_size=2))
    if k in ("strs", "bools"):
        wrong_item = st.one_of(st.integers(2), st.none(), st.sampled_from(["false", 1.5])) if k == "bools" \
            else st.one_of(st.integers(), st.none(), st.booleans())
        return st.one_of(st.text(min_size=1, max_size=8), st.integers(), st.none(),
                         st.lists(wrong_item, min_size=1, max_size=3))
    if k == "frames":
        frame = st.integers(-FRAME_LIMIT, FRAME_LIMIT)
        return st.one_of(st.tuples(frame, frame).filter(lambda ab: ab[0] > ab[1]).map(list),
                         st.lists(frame, max_size=4).filter(lambda v: len(v) != 2),
                         st.tuples(st.integers(min_value=FRAME_LIMIT + 1), frame).map(list),
                         st.just([True, 3]), st.just([1.0, 2.0]), st.integers(), st.none(), st.text(max_size=4))
    raise ValueError(f"no strategy for kind {k!r}")


def settings_dicts() -> st.SearchStrategy:
    """A value for every RenderSettings field, each valid on its own."""
    return st.fixed_dictionaries({s.name: valid(s) for s in RenderSettings.SPECS})


def metadata_dicts() -> st.SearchStrategy:
    """Metadata: any subset of the typed keys with valid values, plus free-form JSON keys."""
    typed = st.fixed_dictionaries({}, optional={s.name: valid(s) for s in METADATA})
    free = st.dictionaries(st.text(min_size=1, max_size=6).filter(lambda t: t not in {s.name for s in METADATA}),
                           st.one_of(st.integers(-5, 5), st.text(max_size=5), st.booleans(), st.none()), max_size=2)
    return st.tuples(typed, free).map(lambda tf: {**tf[1], **tf[0]})
