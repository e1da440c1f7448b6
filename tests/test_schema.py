"""The typed schema (stpm_core/schema.py) drives the loader, the command line and the add-on.

Values are drawn from the schema's own rows (tests/schema_strategies.py), so a field added to
``RenderSettings`` or to ``schema.METADATA`` is covered here without new test code:

* valid settings round-trip: settings -> scene file -> load gives the same settings, canonical types;
* an invalid value of any field gives one line naming the field: from ``RenderSettings``, from a
  scene file (``f.stpm: settings: samples must be ...``) and from the command line (exit 1 or 2,
  the option named);
* metadata: the typed keys round-trip, a wrong type is refused on save and on load (one line);
* the add-on's ``scene.stpm`` properties mirror the rows (defaults, bounds, enum items).
"""
from __future__ import annotations

import contextlib
import io
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings as hsettings, strategies as st

from schema_strategies import invalid, metadata_dicts, settings_dicts, valid
from stpm_core import cli
from stpm_core.demo import demo_scene
from stpm_core.errors import SceneError, SettingsError
from stpm_core.schema import METADATA
from stpm_core.scenefile import load_scene_with_settings, save_scene, scene_to_arrays
from stpm_core.settings import RenderSettings

SPECS = RenderSettings.SPECS
FLAGGED = [s for s in SPECS if s.flag is not None]
EXAMPLES = hsettings(max_examples=40, deadline=None, suppress_health_check=list(HealthCheck))


@pytest.fixture(scope="module")
def work(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("schema")


@pytest.fixture(scope="module")
def scene():
    return demo_scene(resolution=(8, 6))


def _write_raw(path: Path, header: dict, arrays: dict) -> Path:
    """A scene file with a header the saver would refuse (the loader must refuse it too)."""
    def npy(a):
        buf = io.BytesIO()
        np.lib.format.write_array(buf, a)
        return buf.getvalue()
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("header.npy", npy(np.frombuffer(json.dumps(header).encode(), np.uint8)))
        for k, a in arrays.items():
            z.writestr(k + ".npy", npy(a))
    return path


def _settings_or_reject(d: dict) -> RenderSettings:
    """Every field of ``d`` is valid on its own; a SettingsError is a rule between fields: drawn again."""
    try:
        return RenderSettings.from_dict(d)
    except SettingsError:
        assume(False)


# ----------------------------------------------------------------------------
# Settings
# ----------------------------------------------------------------------------
@EXAMPLES
@given(d=settings_dicts())
def test_valid_settings_round_trip_through_the_scene_file(work, scene, d):
    s = _settings_or_reject(d)
    for spec in SPECS:                       # canonical types: int, float, bool, upper-case enum
        v = getattr(s, spec.name)
        want = {"int": int, "float": float, "bool": bool, "enum": str}[spec.kind]
        assert type(v) is want, (spec.name, v)
        assert v == (d[spec.name].upper() if spec.kind == "enum" else d[spec.name])
    assert RenderSettings.from_dict(s.to_dict()) == s
    path = save_scene(scene, work / "round.stpm", settings=s)
    _, loaded = load_scene_with_settings(path)
    assert loaded == s
    assert all(type(getattr(loaded, n.name)) is type(getattr(s, n.name)) for n in SPECS)


@EXAMPLES
@given(d=settings_dicts(), data=st.data())
def test_an_invalid_setting_is_one_line_naming_it(work, scene, d, data):
    s = _settings_or_reject(d)
    spec = data.draw(st.sampled_from(SPECS))
    bad = data.draw(invalid(spec))
    with pytest.raises(SettingsError) as e:
        RenderSettings.from_dict({**d, spec.name: bad})
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"{spec.name} "), msg
    # ... and from a scene file, with the file's name
    header, arrays = scene_to_arrays(scene, s)
    header["settings"][spec.name] = bad
    path = _write_raw(work / "bad.stpm", header, arrays)
    with pytest.raises(SceneError) as e:
        load_scene_with_settings(path)
    assert str(e.value) == f"bad.stpm: settings: {msg}"


def _cli(argv: list[str]) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        status = cli.main(argv)
    return status, err.getvalue()


def _valid_text(spec, text: str) -> bool:
    from stpm_core.command_common import _option_type
    try:
        spec.check(_option_type(spec)(text))
    except Exception:  # noqa: BLE001 -- any refusal
        return False
    return True


@EXAMPLES
@given(data=st.data())
def test_command_line_options_follow_the_schema(work, data):
    """Each schema row with a flag is an option: a valid value is taken as the schema canonicalises it,
    an invalid one is refused before loading with one line naming the option (exit 2 syntax, 1 range)."""
    spec = data.draw(st.sampled_from(FLAGGED))
    args = cli._build_parser().parse_args(["render", "x.stpm", f"{spec.flag}={data.draw(valid(spec))}"])
    assert cli.checked_overrides(args)[spec.name] == spec.check(getattr(args, spec.name))
    bad = data.draw(invalid(spec))
    text = str(bad).lower() if isinstance(bad, str) and spec.kind == "enum" else str(bad)
    assume(not _valid_text(spec, text))          # "1" is a bad JSON integer but a good option
    status, err = _cli(["render", str(work / "missing.stpm"), f"{spec.flag}={text}", "-q"])
    lines = err.strip().splitlines()
    assert status in (1, 2) and len(lines) == 1, err
    assert lines[0].startswith("stpm: error: ") and spec.flag in lines[0], lines[0]
    assert "not found" not in lines[0]            # refused before the scene is looked for


def test_every_flag_is_an_option_with_its_range_in_the_help(capsys):
    assert cli.main(["render", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    for spec in FLAGGED:
        choices = "{" + ",".join(v.lower() for v in spec.values) + "}"
        assert f"{spec.flag} {choices if spec.kind == 'enum' else spec.metavar}" in text, spec.name
        assert spec.kind == "enum" or spec.describe() in text, spec.name


# ----------------------------------------------------------------------------
# Metadata
# ----------------------------------------------------------------------------
@EXAMPLES
@given(meta=metadata_dicts())
def test_metadata_round_trips(work, scene, meta):
    import dataclasses
    path = save_scene(dataclasses.replace(scene, metadata=meta), work / "meta.stpm")
    loaded, _ = load_scene_with_settings(path)
    assert loaded.metadata == json.loads(json.dumps(meta))


@EXAMPLES
@given(data=st.data())
def test_invalid_metadata_is_never_written_and_never_loaded(work, scene, data):
    import dataclasses
    spec = data.draw(st.sampled_from(METADATA))
    bad = data.draw(invalid(spec))
    with pytest.raises(SceneError) as e:
        save_scene(dataclasses.replace(scene, metadata={spec.name: bad}), work / "never.stpm")
    msg = str(e.value)
    assert "\n" not in msg and msg.startswith(f"metadata.{spec.name} "), msg
    header, arrays = scene_to_arrays(scene)
    header["metadata"] = {spec.name: bad}
    with pytest.raises(SceneError) as e:
        load_scene_with_settings(_write_raw(work / "badmeta.stpm", header, arrays))
    assert str(e.value) == f"badmeta.stpm: {msg}"


def test_a_nan_in_a_typed_metadata_key_is_named(work, scene):
    """NaN is not JSON: still the key is named, not just 'not JSON-serialisable' (found by the test above)."""
    import dataclasses
    with pytest.raises(SceneError, match=r"^metadata\.film_transparent must be true or false, got nan$"):
        save_scene(dataclasses.replace(scene, metadata={"film_transparent": float("nan")}), work / "nan.stpm")
    with pytest.raises(SceneError, match="JSON-serialisable"):
        save_scene(dataclasses.replace(scene, metadata={"free": float("inf")}), work / "inf.stpm")


# ----------------------------------------------------------------------------
# The add-on
# ----------------------------------------------------------------------------
@pytest.mark.bpy
def test_addon_properties_mirror_the_schema():
    bpy = pytest.importorskip("bpy")
    import addon
    addon.register()
    rna = bpy.types.Scene.bl_rna.properties["stpm"].fixed_type.properties
    for spec in SPECS:
        p = rna[spec.name]
        assert p.name == spec.label and p.description.lower() == spec.doc.lower(), spec.name
        if spec.kind == "enum":
            assert [i.identifier for i in p.enum_items] == list(spec.values) and p.default == spec.default
        elif spec.kind == "bool":
            assert p.default == spec.default
        elif spec.kind == "int":
            assert p.type == "INT" and p.default == spec.default
            assert (p.hard_min, p.hard_max) == (spec.lo, min(spec.hi, 2**31 - 1)), spec.name
        else:
            assert p.type == "FLOAT" and p.default == pytest.approx(spec.default)
            assert p.hard_min == spec.lo and p.hard_max == pytest.approx(spec.hi, rel=1e-6), spec.name
            if spec.hi_open:
                assert p.hard_max < spec.hi
