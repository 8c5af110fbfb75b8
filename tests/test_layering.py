"""The package's layers import only downwards: the runtime (top of ``jassy/``) imports no
engine and no application, the engines (``jassy/engines``) no application, and physics no
ugen, no patch, no engine and no application. Imports inside functions count too: a lazy
import is still a dependency."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
APPLICATIONS = ("jassy.apps", "jassy.batch", "jassy.study")
ENGINES = ("jassy.engines",)
#: The package's front re-exports the offline renderer; ``python -m jassy`` runs the CLI.
FRONT = {"jassy/__init__.py", "jassy/__main__.py"}
#: Run by hand to write the shipped model files into patches/.
PHYSICS_WRITERS = {"physics/modal/shipped.py"}


def imported_modules(path: Path) -> set[str]:
    """Every module a file imports, at any depth of its code."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


def offences(files, forbidden) -> list[str]:
    bad = []
    for path in files:
        rel = path.relative_to(ROOT).as_posix()
        for module in sorted(imported_modules(path)):
            if any(module == f or module.startswith(f + ".") for f in forbidden):
                bad.append(f"{rel} imports {module}")
    return bad


def test_imports_collects_function_level_imports(tmp_path):
    source = tmp_path / "m.py"
    source.write_text("import os\n\ndef f():\n    from jassy.apps import cli\n    return cli\n")
    assert "jassy.apps.cli" in imported_modules(source)
    assert "os" in imported_modules(source)


@pytest.mark.parametrize(
    ("layer", "files", "forbidden"),
    [
        (
            "runtime",
            [p for p in (ROOT / "jassy").glob("*.py") if p.relative_to(ROOT).as_posix() not in FRONT],
            APPLICATIONS + ENGINES,
        ),
        ("engines", sorted((ROOT / "jassy" / "engines").rglob("*.py")), APPLICATIONS),
        (
            "physics",
            [
                p
                for p in (ROOT / "physics").rglob("*.py")
                if p.relative_to(ROOT).as_posix() not in PHYSICS_WRITERS
            ],
            ("ugens", "patches") + ENGINES + APPLICATIONS,
        ),
    ],
)
def test_layer_imports_only_downwards(layer, files, forbidden):
    assert files, f"no files found for the {layer} layer"
    bad = offences(files, forbidden)
    assert not bad, f"the {layer} layer imports upwards:\n" + "\n".join(bad)
