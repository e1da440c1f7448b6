"""The typed schema of the render settings and the scene metadata: one table, every reader.

Each setting is one :class:`Spec` row -- name, kind, default, range or choices, doc -- and every
place that reads or shows settings derives from those rows instead of repeating them:

* :class:`stpm_core.settings.RenderSettings` declares its fields with :func:`setting`, so the
  dataclass field *is* the row (``RenderSettings.SPECS``); ``validate()`` runs :meth:`Spec.check`;
* the scene-file loader (:mod:`stpm_core.scenefile`) reads a file's ``settings`` through
  ``RenderSettings.from_dict`` and its ``metadata`` through :data:`METADATA` (:func:`check_metadata`);
* the command line (:func:`stpm_core.command_common.add_setting_options`) makes one option per row
  with a ``flag``, its help text and range from the row;
* the Blender add-on (``addon/properties.py``) makes one ``scene.stpm`` property per row (its
  ``label``, default, min / max, enum items and description);
* the tests draw valid and invalid values of every row (``tests/schema_strategies.py``), so a
  field added later is covered without new test code.

A row's rule, in the order :meth:`Spec.check` applies it:

=========  ===================================================================================
kind       accepted values (JSON / Python)
=========  ===================================================================================
``int``    an integer (numpy integers taken; bool, float, str refused) in ``[lo, hi]``
``float``  a number (int or float; bool, str, None refused), finite, in ``[lo, hi]``; with
           ``hi_open`` ``hi`` itself is refused, with ``gap`` the values in ``(lo, gap)`` are
           (``rule`` then says what is allowed: ``0 (automatic) or >= 1``)
``bool``   ``true`` / ``false``; the integers 0 and 1 are unambiguous and taken
           (a string such as ``"false"`` is refused: read as a truth value it means the opposite)
``enum``   one of ``choices`` (a string; upper-cased first: ``"photon"`` is ``PHOTON``)
``str``    a string
``strs``   a list of strings
``bools``  a list of booleans
``frames`` two integer frames ``[start, end]`` in Blender's limits, start <= end
=========  ===================================================================================

Every refusal is a :class:`~stpm_core.errors.SettingsError` with one line naming the field
(``samples must be an integer in [1, 65536], got 0``); callers add the file or option name.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from .errors import SceneError, SettingsError

__all__ = ["Spec", "setting", "METADATA", "check_metadata", "FRAME_LIMIT", "range_text"]

# Blender's frame limits (MINAFRAME / MAXFRAME): frame numbers a .blend can hold
FRAME_LIMIT = 1_048_574


@dataclass(frozen=True)
class Spec:
    """One typed field: what it accepts, its default and what it means.

    Attributes
    ----------
    name : the field's name (RenderSettings attribute, ``scene.stpm`` property, metadata key).
    kind : 'int' | 'float' | 'bool' | 'enum' | 'str' | 'strs' | 'bools' | 'frames' (module docstring).
    default : the value when the field is absent.
    doc : one sentence: what it controls, with its units.
    lo, hi : inclusive bounds of 'int' and 'float' fields.
    hi_open : 'float': ``hi`` itself is refused (``shrink_alpha`` in (0, 1)).
    gap : 'float': values in ``(lo, gap)`` are refused (``temporal_alpha``: 0 or >= 1).
    rule : the allowed values in words, said when ``hi_open`` or ``gap`` refuses one.
    choices : 'enum': ``((value, label, description), ...)``; labels and descriptions are the
        add-on's menu entries.
    label : the add-on's property name ("Samples").
    flag : the command-line option (``--samples``), or None when the command line has none;
        ``metavar`` its value's name in the help (``--samples S``).
    help : the option's help when it differs from ``doc`` (the range is appended).
    ui : extra keywords of the add-on's property (``soft_max``, ``subtype``).
    """

    name: str
    kind: str
    default: object
    doc: str
    lo: float | None = None
    hi: float | None = None
    hi_open: bool = False
    gap: float | None = None
    rule: str = ""
    choices: tuple = ()
    label: str = ""
    flag: str | None = None
    metavar: str = "X"
    help: str | None = None
    ui: dict = field(default_factory=dict)

    @property
    def values(self) -> tuple:
        """'enum': the allowed values (``('PHOTON', 'ACCUMULATION', ...)``)."""
        return tuple(c[0] for c in self.choices)

    # ------------------------------------------------------------------ checking
    def check(self, v, where: str | None = None):
        """``v`` checked against this row -> the canonical value (int, float, bool, upper-case
        enum, list); :class:`SettingsError` with one line naming ``where`` (default: the name)."""
        name = where or self.name
        kind = self.kind
        if kind == "enum":
            if isinstance(v, str):
                v = v.upper()
            if not isinstance(v, str) or v not in self.values:
                raise SettingsError(f"{name} must be one of {', '.join(self.values)}, got {v!r:.60}")
            return v
        if kind == "bool":
            # true / false only; 0 and 1 (and numpy booleans) are unambiguous and taken
            if isinstance(v, (bool, np.bool_)) or (isinstance(v, (int, np.integer)) and v in (0, 1)):
                return bool(v)
            raise SettingsError(f"{name} must be true or false, got {v!r:.60}")
        if kind == "int":
            if isinstance(v, np.integer) and not isinstance(v, np.bool_):
                v = int(v)                                   # a numpy integer (bpy, numpy): exact
            if isinstance(v, bool) or not isinstance(v, int) or not (self.lo <= v <= self.hi):
                raise SettingsError(f"{name} must be an integer in [{self.lo}, {self.hi}], got {v!r:.60}")
            return v
        if kind == "float":
            return self._check_float(v, name)
        if kind == "str":
            if not isinstance(v, str):
                raise SettingsError(f"{name} must be a string, got {v!r:.60}")
            return v
        if kind in ("strs", "bools"):
            item = str if kind == "strs" else bool
            if not isinstance(v, list) or not all(isinstance(x, item) for x in v):
                what = "strings" if kind == "strs" else "booleans (true / false)"
                raise SettingsError(f"{name} must be a list of {what}, got {v!r:.60}")
            return list(v)
        if kind == "frames":
            ok = (isinstance(v, list) and len(v) == 2
                  and all(not isinstance(x, bool) and isinstance(x, int) and -FRAME_LIMIT <= x <= FRAME_LIMIT
                          for x in v) and v[0] <= v[1])
            if not ok:
                raise SettingsError(f"{name} must be two integer frames [start, end] in "
                                    f"[{-FRAME_LIMIT}, {FRAME_LIMIT}] with start <= end, got {v!r:.60}")
            return list(v)
        raise ValueError(f"unknown kind {kind!r} of field {self.name!r}")

    def _check_float(self, v, name: str) -> float:
        lo, hi = self.lo, self.hi
        # Numbers only: a string ("0.5"), a boolean or None is refused, not coerced
        if isinstance(v, (bool, np.bool_)) or not isinstance(v, (int, float, np.integer, np.floating)):
            raise SettingsError(f"{name} must be a number, got {v!r:.60}")
        try:
            v = float(v)
        except OverflowError:                                # an integer too large for a float
            raise SettingsError(f"{name} must be in [{lo}, {hi}], got {v!r:.40}") from None
        if not math.isfinite(v):
            raise SettingsError(f"{name} must be a finite number in [{lo}, {hi}], got {v}")
        if not (lo <= v <= hi):
            raise SettingsError(f"{name} must be in [{lo}, {hi}], got {v}")
        if (self.hi_open and v >= hi) or (self.gap is not None and lo < v < self.gap):
            raise SettingsError(f"{name} must be {self.rule}, got {v}")
        return v

    # ------------------------------------------------------------------ describing
    def describe(self) -> str:
        """The allowed values in words, for help texts and docs (``integer in [1, 65536]``)."""
        if self.kind == "int":
            return f"integer in [{_num(self.lo)}, {_num(self.hi)}]"
        if self.kind == "float":
            if self.gap is not None:
                return f"{_num(self.lo)} or a number in [{_num(self.gap)}, {_num(self.hi)}]"
            return f"a number in [{_num(self.lo)}, {_num(self.hi)}{')' if self.hi_open else ']'}"
        if self.kind == "enum":
            return "one of " + ", ".join(v.lower() for v in self.values)
        if self.kind == "bool":
            return "true or false"
        return {"str": "a string", "strs": "a list of strings", "bools": "a list of booleans",
                "frames": "[start, end] frames"}[self.kind]


def _num(x) -> str:
    """A bound as people write it: 65536, 2^31, 2^63 - 1, 1e6, 0.5."""
    if isinstance(x, int) and not isinstance(x, bool):
        for n in range(20, 64):
            if x == 1 << n:
                return f"2^{n}"
            if x == (1 << n) - 1:
                return f"2^{n} - 1"
        return str(x)
    x = float(x)
    if x.is_integer() and abs(x) >= 1e5:
        e = int(round(math.log10(abs(x))))
        if float(f"1e{e}") == abs(x):
            return ("-" if x < 0 else "") + f"1e{e}"
    return f"{x:g}"


def range_text(spec: Spec) -> str:
    """:meth:`Spec.describe` as a function (for ``map``)."""
    return spec.describe()


def setting(default, kind: str, doc: str, **kw):
    """A dataclass field that is also a schema row: ``samples: int = setting(16, 'int', '...', lo=1, ...)``.

    The row (a :class:`Spec` without its name) rides in the field's metadata; the class collects
    them into ``SPECS`` (:func:`specs_of`).
    """
    row = Spec(name="", kind=kind, default=default, doc=doc, **kw)
    return field(default=default, metadata={"spec": row})


def specs_of(cls) -> tuple:
    """The named :class:`Spec` rows of a dataclass declared with :func:`setting`, in field order."""
    return tuple(dataclasses.replace(f.metadata["spec"], name=f.name)
                 for f in dataclasses.fields(cls) if "spec" in f.metadata)


# ----------------------------------------------------------------------------
# Scene metadata: free-form JSON, but the keys STPM reads are typed
# ----------------------------------------------------------------------------
METADATA: tuple = (
    Spec("warnings", "strs", [], "what the export approximated; the CLI and the add-on print each "
                                 "(control and bidi characters escaped)"),
    Spec("source", "str", "", "where the scene came from (the .blend's path, a script)"),
    Spec("name", "str", "", "a display name (stpm compare's report)"),
    Spec("description", "str", "", "free text"),
    Spec("exporter", "str", "", "what wrote the scene ('stpm-blender')"),
    Spec("blender_scene", "str", "", "the Blender scene exported"),
    Spec("motion_steps", "int", 1, "times across the shutter the export sampled", lo=1, hi=1 << 20),
    Spec("frame_range", "frames", None, "the .blend's [frame_start, frame_end] (stpm render warns "
                                        "about frames outside it)"),
    Spec("film_transparent", "bool", False, "Blender's Film > Transparent: the world is not seen "
                                            "by camera rays (alpha 0)"),
    Spec("light_visible_camera", "bools", [], "per light (scene order): seen by camera rays "
                                              "(Blender's Ray Visibility > Camera)"),
    Spec("light_visible_diffuse", "bools", [], "per light (scene order): lights diffuse lobes "
                                               "(Blender's Ray Visibility > Diffuse; unset: on)"),
    Spec("light_visible_glossy", "bools", [], "per light (scene order): lights glossy (reflection) lobes "
                                              "(Blender's Ray Visibility > Glossy; unset: on)"),
    Spec("light_visible_transmission", "bools", [], "per light (scene order): lights refraction lobes "
                                                    "(Blender's Ray Visibility > Transmission; unset: on)"),
    Spec("working_space", "enum", "REC709", "the scene's working colour space (Blender 5's "
                                            "bpy.data.colorspace.working_space): every colour is an RGB "
                                            "triple in it, image textures are converted into it",
         choices=(("REC709", "Linear Rec.709", "Blender's default"), ("REC2020", "Linear Rec.2020", ""),
                  ("ACESCG", "ACEScg", "ACES AP1 primaries"))),
)


def check_metadata(metadata) -> dict:
    """A scene's ``metadata``: a JSON object whose keys in :data:`METADATA` have their types.

    Other keys are free-form JSON and kept.  Raises :class:`SceneError` naming
    ``metadata.<key>`` (one line); returns the dict.
    """
    if not isinstance(metadata, dict):
        raise SceneError(f"metadata must be a JSON object, got {type(metadata).__name__}")
    for spec in METADATA:
        if spec.name in metadata:
            try:
                spec.check(metadata[spec.name], f"metadata.{spec.name}")
            except SettingsError as e:
                raise SceneError(str(e)) from None
    return metadata
