"""Browser tests' wait predicates never read through an element that may not be drawn yet.

Playwright's `wait_for_function` fails at once when its predicate throws, so
`document.querySelector('#runs-body tr').cells` fails while the row is still on its way (CI failed
so once, at e00db65). Only an element of the static page (an id in web/index.html) is read
without `?.`. And a page opened under the dashboard's content security policy (no `bypass_csp`)
is waited on with functions: Playwright polls an expression with eval, which the policy refuses
once the first check is false."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
BROWSER_TESTS = [ROOT / "tests" / "web", ROOT / "tests" / "ui"]
# querySelector('…') or ("…") followed by a plain property read, not `?.`
READ = re.compile(r"""querySelector\((?P<q>['"])(?P<selector>.*?)(?P=q)\)\.(?!\.)""")
FUNCTION = re.compile(r"^\s*(async\s+)?(function\b|(\([^)]*\)|\w+)\s*=>)")
STATIC = {f"#{i}" for i in re.findall(r'\bid="([^"]+)"', (ROOT / "web" / "index.html").read_text())}


def calls(path: Path, name: str) -> list[ast.Call]:
    return [
        n
        for n in ast.walk(ast.parse(path.read_text()))
        if isinstance(n, ast.Call) and getattr(n.func, "attr", None) == name
    ]


def under_csp(path: Path) -> bool:
    """Whether the file opens a context, or a page of its own context, without bypass_csp=True."""
    own = [c for c in calls(path, "new_page") if "browser" in ast.unparse(c.func)]  # not context.new_page()
    opened = own + calls(path, "new_context")
    return any(not any(k.arg == "bypass_csp" for k in call.keywords) for call in opened)


def predicate_texts(path: Path) -> list[tuple[int, str]]:
    """(line, text) of each string given to a `wait_for_function` call, f-strings' literal parts joined."""
    found = []
    for node in calls(path, "wait_for_function"):
        if node.args:
            arg = node.args[0]
            parts = [n.value for n in ast.walk(arg) if isinstance(n, ast.Constant) and isinstance(n.value, str)]
            found.append((node.lineno, "…".join(parts)))
    return found


def unguarded(text: str) -> list[str]:
    return [m["selector"] for m in READ.finditer(text) if m["selector"] not in STATIC]


def test_the_rule_finds_what_failed_and_passes_its_fix() -> None:
    failed = "document.querySelector('#runs-body tr[data-run-id=\"1\"]').cells[5].textContent === '0'"
    assert unguarded(failed) == ['#runs-body tr[data-run-id="1"]']
    assert unguarded(failed.replace("').cells", "')?.cells")) == []
    assert unguarded("document.querySelector('#map').dataset.epoch") == []  # in the static page
    assert unguarded("document.querySelector('#discard-message').textContent") == ["#discard-message"]  # drawn


def test_no_wait_predicate_reads_through_an_element_that_may_be_missing() -> None:
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {selector}"
        for folder in BROWSER_TESTS
        for path in sorted(folder.rglob("*.py"))
        for line, text in predicate_texts(path)
        for selector in unguarded(text)
    ]
    assert not offenders, "read these with ?. (the element may not be drawn yet):\n" + "\n".join(offenders)


def test_pages_under_the_content_security_policy_are_waited_on_with_functions() -> None:
    assert FUNCTION.match("() => a") and FUNCTION.match("(old) => { return 1; }") and not FUNCTION.match("a === 1")
    offenders = [
        f"{path.relative_to(ROOT)}:{line}: {text[:60]}"
        for path in sorted((ROOT / "tests" / "web").rglob("*.py"))
        if under_csp(path)
        for line, text in predicate_texts(path)
        if not FUNCTION.match(text)
    ]
    assert not offenders, 'a page without bypass_csp: give these as functions ("() => …"):\n' + "\n".join(offenders)
