"""The boundaries of DESIGN.md and docs/architecture.md, checked on the source: every import statement of a
package (lazy ones inside functions included, TYPE_CHECKING ones excluded) against what that
package must never import. `make lint` runs this file."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]

# package → top-level modules it must not import
FORBIDDEN: dict[str, set[str]] = {
    "backend": {"torch", "mujoco", "trainer", "labeling_ui", "teacher"},
    "labeling_ui": {"torch", "trainer", "backend", "sqlalchemy"},
    "trainer": {"backend", "sqlalchemy", "labeling_ui"},
    "teacher": {"torch", "mujoco", "trainer", "backend", "labeling_ui", "sqlalchemy"},
    "collie": {"torch", "tqdm", "trainer", "backend", "labeling_ui", "sqlalchemy", "fastapi"},
}


def _type_checking_only(node: ast.If) -> bool:
    test = node.test
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def imports(path: Path) -> list[tuple[int, str]]:
    """(line, top-level module) of every import in the file that runs (not under TYPE_CHECKING)."""
    found: list[tuple[int, str]] = []

    def visit(node: ast.AST) -> None:
        if isinstance(node, ast.If) and _type_checking_only(node):
            for child in node.orelse:
                visit(child)
            return
        if isinstance(node, ast.Import):
            found.extend((node.lineno, alias.name.split(".")[0]) for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module.split(".")[0]))
        for child in ast.iter_child_nodes(node):
            visit(child)

    visit(ast.parse(path.read_text(), str(path)))
    return found


def violations(package: str) -> list[str]:
    bad = []
    for path in sorted((ROOT / package).rglob("*.py")):
        for line, module in imports(path):
            if module in FORBIDDEN[package]:
                bad.append(f"{path.relative_to(ROOT)}:{line} imports {module}")
    return bad


@pytest.mark.parametrize("package", sorted(FORBIDDEN))
def test_package_keeps_its_boundaries(package: str) -> None:
    assert violations(package) == []


def test_only_the_backend_touches_the_database() -> None:
    """Every package of the repository but the backend, whether or not FORBIDDEN lists it."""
    packages = sorted(p.parent.name for p in ROOT.glob("*/__init__.py") if p.parent.name not in ("backend", "tests"))
    assert {"collie", "trainer", "labeling_ui", "teacher"} <= set(packages)
    touching = [
        f"{path.relative_to(ROOT)}:{line}"
        for package in packages
        for path in sorted((ROOT / package).rglob("*.py"))
        for line, module in imports(path)
        if module == "sqlalchemy"
    ]
    assert touching == []


def test_the_checker_sees_lazy_imports_and_skips_type_checking(tmp_path: Path) -> None:
    source = tmp_path / "m.py"
    source.write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import torch\n"
        "def f():\n    import trainer.loop\n    from backend import db\n"
    )
    assert [m for _, m in imports(source)] == ["typing", "trainer", "backend"]


def test_every_type_ignore_says_why() -> None:
    """`# type: ignore[code]  # reason`: a silenced checker error names its code and its reason."""
    pattern = re.compile(r"type: ignore(?!\[[\w, -]+\]\s+#\s*\S)")
    bare = [
        f"{path.relative_to(ROOT)}:{n}"
        for package in FORBIDDEN
        for path in sorted((ROOT / package).rglob("*.py"))
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if pattern.search(line)
    ]
    assert bare == []
