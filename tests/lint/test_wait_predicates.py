"""Browser tests' wait predicates never read through an element that may not be drawn yet.

Playwright's `wait_for_function` fails at once when its predicate throws, so
`document.querySelector('#runs-body tr').cells` fails while the row is still on its way (CI failed
so once, at e00db65). Only an element of the dashboard's static page (an id in web/index.html) is
read without `?.`. And a page opened under the dashboard's content security policy (without
`bypass_csp=True`) is waited on with functions: Playwright polls an expression with eval, which the
policy refuses once the first check is false."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
TESTS = ROOT / "tests"
BROWSER_TESTS = [TESTS / "web", TESTS / "ui", TESTS / "service"]
UNKNOWN = "…"  # a part of a predicate this check cannot read (a value computed at run time)
# querySelector('…'), ("…") or (`…`), or getElementById('…'), followed by a plain property read, not `?.`
READ = re.compile(r"""(?P<by>querySelector|getElementById)\((?P<q>['"`])(?P<selector>.*?)(?P=q)\)\.(?!\.)""")
FUNCTION = re.compile(r"^\s*(async\s+)?(function\b|(\([^)]*\)|\w+)\s*=>)")
DASHBOARD_IDS = {f"#{i}" for i in re.findall(r'\bid="([^"]+)"', (ROOT / "web" / "index.html").read_text())}


def calls(tree: ast.AST, name: str) -> list[ast.Call]:
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call) and getattr(n.func, "attr", None) == name]


def under_csp(tree: ast.AST) -> bool:
    """Whether the file opens a context, or a page of its own context, without bypass_csp=True."""
    own = [c for c in calls(tree, "new_page") if "browser" in ast.unparse(c.func)]  # not context.new_page()
    bypassed = ast.Constant(True)
    return any(
        not any(k.arg == "bypass_csp" and ast.dump(k.value) == ast.dump(bypassed) for k in call.keywords)
        for call in own + calls(tree, "new_context")
    )


def text_of(node: ast.AST, before: int, names: dict[str, list[tuple[int, ast.AST]]]) -> str:
    """The text of a string expression in source order: literal parts as written, a name by its
    last assignment in the file before line `before`, anything else UNKNOWN."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(text_of(v, before, names) for v in node.values)
    if isinstance(node, ast.FormattedValue):
        return text_of(node.value, before, names) if isinstance(node.value, ast.Name) else UNKNOWN
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.Add):
        return text_of(node.left, before, names) + text_of(node.right, before, names)
    if isinstance(node, ast.Name):
        earlier = [value for line, value in names.get(node.id, []) if line < before]
        return text_of(earlier[-1], before, names) if earlier else UNKNOWN
    return UNKNOWN


def predicate_texts(tree: ast.AST) -> list[tuple[int, str]]:
    """(line, text) of each predicate given to a `wait_for_function` call."""
    names: dict[str, list[tuple[int, ast.AST]]] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.Assign) and len(node.targets) == 1 and isinstance(node.targets[0], ast.Name):
            names.setdefault(node.targets[0].id, []).append((node.lineno, node.value))
    for assigned in names.values():
        assigned.sort(key=lambda pair: pair[0])
    found = []
    for call in calls(tree, "wait_for_function"):
        given = call.args[:1] or [k.value for k in call.keywords if k.arg == "expression"]
        found += [(call.lineno, text_of(arg, call.lineno, names)) for arg in given]
    return found


def unguarded(text: str, static: set[str]) -> list[str]:
    selectors = [("#" if m["by"] == "getElementById" else "") + m["selector"] for m in READ.finditer(text)]
    return [s for s in selectors if s not in static]


def browser_test_files() -> list[tuple[Path, ast.AST]]:
    return [(path, ast.parse(path.read_text())) for folder in BROWSER_TESTS for path in sorted(folder.rglob("*.py"))]


def test_the_rules_find_what_failed_and_pass_their_fixes() -> None:
    failed = "document.querySelector('#runs-body tr[data-run-id=\"1\"]').cells[5].textContent === '0'"
    assert unguarded(failed, DASHBOARD_IDS) == ['#runs-body tr[data-run-id="1"]']
    assert unguarded(failed.replace("').cells", "')?.cells"), DASHBOARD_IDS) == []
    assert unguarded("document.querySelector('#map').dataset.epoch", DASHBOARD_IDS) == []  # in the static page
    assert unguarded("document.getElementById('discard-message').textContent", DASHBOARD_IDS) == ["#discard-message"]
    source = 'row = "#runs-body tr"\nmark = f"document.querySelector(`{row}`)"\npage.wait_for_function(mark + ".x")\n'
    assert [text for _, text in predicate_texts(ast.parse(source))] == ["document.querySelector(`#runs-body tr`).x"]
    opened = "browser.new_page(bypass_csp=False)\nbrowser.new_context(bypass_csp=True)\ncontext.new_page()\n"
    assert under_csp(ast.parse(opened)) and not under_csp(ast.parse(opened.replace("False", "True")))
    assert FUNCTION.match("() => a") and FUNCTION.match("(old) => { return 1; }") and not FUNCTION.match("a === 1")


def test_no_wait_predicate_reads_through_an_element_that_may_be_missing() -> None:
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {selector}"
        for path, tree in browser_test_files()
        for line, text in predicate_texts(tree)
        for selector in unguarded(text, DASHBOARD_IDS if path.parent.name == "web" else set())
    ]
    assert not offenders, "read these with ?. (the element may not be drawn yet):\n" + "\n".join(offenders)


def test_pages_under_the_content_security_policy_are_waited_on_with_functions() -> None:
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {text[:60]}"
        for path, tree in browser_test_files()
        if under_csp(tree)
        for line, text in predicate_texts(tree)
        if text != UNKNOWN and not FUNCTION.match(text)
    ]
    assert not offenders, 'a page without bypass_csp=True: give these as functions ("() => …"):\n' + "\n".join(
        offenders
    )
