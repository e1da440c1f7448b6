"""Import layering of stpm_core, read from the source (ast), never by importing it.

* stpm_core never imports bpy (it runs without Blender);
* stpm_core reaches the add-on (``addon``, where bpy lives) only through the one
  seam stpm_core/blend_loader.py, and that one imports none of it: it runs ``addon.batch.serve``
  in a child process;
* the two command lines share stpm_core/command_common.py instead of each
  other's internals: stpm_core/compare/* does not import stpm_core.cli, and
  stpm_core/cli.py imports no private (underscore) name from stpm_core.compare.

Every import statement counts, the lazy ones inside functions too, and so do
``importlib.import_module("...")`` / ``__import__("...")`` with a literal name.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
CORE = ROOT / "stpm_core"
SEAM = CORE / "blend_loader.py"


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _imports(path: Path, root: Path = ROOT) -> list[tuple[str, str | None, int]]:
    """(absolute module, imported name or None, line) for every import in ``path``.

    ``import a.b`` -> ("a.b", None); ``from a import b`` -> ("a", "b");
    relative imports are resolved against the file's package.
    """
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    module = _module_name(path, root)
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(alias.name, None, node.lineno) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[:len(package) - (node.level - 1)] if node.level > 1 else package
                assert len(base) == len(package) - (node.level - 1), f"{path}:{node.lineno}: import above the top"
                target = ".".join(base + ([node.module] if node.module else []))
            else:
                target = node.module
            found += [(target, alias.name, node.lineno) for alias in node.names]
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str)
              and ((isinstance(node.func, ast.Name) and node.func.id in ("__import__", "import_module"))
                   or (isinstance(node.func, ast.Attribute) and node.func.attr == "import_module"))):
            found.append((node.args[0].value, None, node.lineno))
    return found


def _reaches(target: str, name: str | None, package: str) -> bool:
    """Does importing (target, name) load ``package`` or a module inside it?"""
    full = f"{target}.{name}" if name is not None else target
    return any(m == package or m.startswith(package + ".") for m in (target, full))


CORE_FILES = sorted(p for p in CORE.rglob("*.py") if "__pycache__" not in p.parts)


def test_the_walk_sees_the_core_and_its_imports():
    names = {p.relative_to(CORE).as_posix() for p in CORE_FILES}
    assert {"cli.py", "blend_loader.py", "command_common.py", "compare/command.py"} <= names
    # the parser is not vacuous: the seam's imports and cli's shared helpers are seen
    assert any(t == "stpm_core.errors" for t, _, _ in _imports(SEAM))
    assert any(t == "stpm_core.command_common" for t, _, _ in _imports(CORE / "cli.py"))
    assert any(t == "stpm_core.command_common" for t, _, _ in _imports(CORE / "compare" / "command.py"))


@pytest.mark.parametrize("path", CORE_FILES, ids=lambda p: p.relative_to(CORE).as_posix())
def test_no_core_module_imports_bpy(path):
    bad = [f"line {line}: {t}{'.' + n if n else ''}" for t, n, line in _imports(path) if _reaches(t, n, "bpy")]
    assert not bad, f"stpm_core/{path.relative_to(CORE).as_posix()} imports bpy: {bad}"


@pytest.mark.parametrize("path", [p for p in CORE_FILES if p != SEAM], ids=lambda p: p.relative_to(CORE).as_posix())
def test_only_the_blend_loader_imports_the_addon(path):
    bad = [f"line {line}: {t}{'.' + n if n else ''}" for t, n, line in _imports(path) if _reaches(t, n, "addon")]
    assert not bad, (f"stpm_core/{path.relative_to(CORE).as_posix()} imports the add-on {bad}: "
                     "go through stpm_core.blend_loader")


def test_the_seam_reaches_the_addon_only_in_a_child_process():
    """blend_loader imports nothing of the add-on (bpy never loads into stpm's own process, so a
    crash of Blender's reader cannot end it): it starts ``addon.batch.serve`` in a child."""
    assert not [line for t, n, line in _imports(SEAM) if _reaches(t, n, "addon")]
    strings = [node.value for node in ast.walk(ast.parse(SEAM.read_text(encoding="utf-8")))
               if isinstance(node, ast.Constant) and isinstance(node.value, str)]   # f-string parts too
    assert any("from addon.batch import serve" in text for text in strings)


@pytest.mark.parametrize("path", sorted((CORE / "compare").rglob("*.py")), ids=lambda p: p.name)
def test_compare_does_not_import_the_cli(path):
    bad = list(dict.fromkeys(f"line {line}" for t, n, line in _imports(path) if _reaches(t, n, "stpm_core.cli")))
    assert not bad, (f"stpm_core/compare/{path.name} imports stpm_core.cli ({', '.join(bad)}): "
                     "shared helpers live in stpm_core.command_common")


def test_cli_imports_no_private_name_of_compare():
    bad = []
    for target, name, line in _imports(CORE / "cli.py"):
        if not _reaches(target, name, "stpm_core.compare"):
            continue
        full = f"{target}.{name}" if name is not None else target
        private = [part for part in full.split(".") if part.startswith("_") and not part.startswith("__")]
        if private:
            bad.append(f"line {line}: {full}")
    assert not bad, f"stpm_core/cli.py imports private names of stpm_core.compare: {bad}"


def test_the_checks_catch_what_they_forbid(tmp_path):
    """The checks themselves: each forbidden import in a throw-away file is seen."""
    fake = tmp_path / "stpm_core" / "compare" / "fake.py"
    fake.parent.mkdir(parents=True)
    fake.write_text("import bpy.types\n"
                    "def f():\n"
                    "    from addon.batch import load_blend\n"
                    "    from .. import cli\n"
                    "    from ..cli import main\n"
                    "    from .command import _OWN_OPTIONS\n"
                    "    importlib.import_module('addon')\n")
    found = _imports(fake, root=tmp_path)
    assert [line for t, n, line in found if _reaches(t, n, "bpy")] == [1]
    assert [line for t, n, line in found if _reaches(t, n, "addon")] == [3, 7]
    assert [line for t, n, line in found if _reaches(t, n, "stpm_core.cli")] == [4, 5]
    assert ("stpm_core.compare.command", "_OWN_OPTIONS", 6) in found
