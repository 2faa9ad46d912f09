"""docs/architecture.md stays true: every file it names exists, and every symbol in a table row
is defined in that row's file (a class, function, method or assignment)."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOC = ROOT / "docs" / "architecture.md"
SOURCES = ("collie", "backend", "trainer", "labeling_ui", "teacher")


def defined(path: Path) -> set[str]:
    """Names a Python file defines at any depth: classes, functions, methods, assigned names."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign | ast.AnnAssign):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names.update(t.id for t in targets if isinstance(t, ast.Name))
    return names


def everything_defined() -> set[str]:
    return set().union(*(defined(p) for package in SOURCES for p in (ROOT / package).rglob("*.py")))


def test_every_named_file_exists() -> None:
    files = [*re.findall(r"`([\w/.]+\.(?:py|js|md))`", DOC.read_text()), "backend/web"]
    assert [f for f in files if not (ROOT / f).exists()] == []


def test_every_command_is_a_collie_subcommand() -> None:
    from collie.cli import SUBCOMMANDS

    commands = re.findall(r"`collie ([\w-]+)`", DOC.read_text())
    assert commands and [c for c in commands if c not in SUBCOMMANDS] == []


def test_every_symbol_is_defined_where_the_table_says() -> None:
    rows = re.findall(r"^\| \d+ \| `([\w/.]+\.py)` \| `([\w.]+)` \|", DOC.read_text(), re.M)
    assert len(rows) >= 15
    missing = [f"{file}: {symbol}" for file, symbol in rows if not set(symbol.split(".")) <= defined(ROOT / file)]
    assert missing == []


def test_every_other_backticked_name_is_defined_somewhere() -> None:
    text = DOC.read_text()
    names = set(re.findall(r"`([A-Z]\w+|[a-z]+_\w+)`", text))
    assert sorted(names - everything_defined()) == []


def test_a_label_crosses_at_most_twelve_files() -> None:
    section = DOC.read_text().split("## One label")[1].split("## One segment")[0]
    assert 1 <= len(set(re.findall(r"^\| \d+ \| `([\w/.]+\.py)`", section, re.M))) <= 12
