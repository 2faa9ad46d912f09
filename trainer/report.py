"""`collie report RUN_ROOT…`: run folders → the paper's tables (mean ± std over seeds, markdown and
CSV) and Fig. 2-style skill figures, in OUT (default RUN_ROOT/report):

    report.md       safe coverage (Table 1), safe ratio (Table 2), composite and weighted composite
                    coverage, wall time per run, zero-shot (Table 3) and hierarchical (Table 4)
                    downstream returns when downstream.json exists; methods in the paper's order
    metrics.csv     one row per (env, task, method, variant, setting, metric): mean, std, n, seeds
    runs.csv        one row per run folder with its final metrics; `bin_rule` names the rule of its
                    coverage columns (a run without that rule's figures: its headline's rule, †)
    figures/skills_<env>_<task>.png   one panel per method: its lowest seed's final evaluation
                    skills over the task's shaded regions

The diagnostic "safe ratio outside the start's 2×2 bins" (2-D bodies, from eval_latest.npz;
`trainer.metrics.off_start_safe_ratio`) leaves out the four bins a robot standing at the start
visits, three of which the corner rule judges at a corner outside a wedge whose apex is the start;
"share of the skills ending within one unit of their start" counts the skills that stand.

A run folder is any folder with summary.json; runs not "finished" are listed and left out, and so
are folders whose files cannot be read or whose env or task this version does not know, each with
why (`checked_run`, which `collie archive` applies too), and folders where a run began
(config.json) without a summary.json yet: one still training or killed early. A report that counts
no run exits 1. A task file's run is also told apart by its rule (`trainer.same_run.RULE`). ± is
the sample standard deviation over seeds (as the paper's tables); a single seed shows its value
alone, and a cell of fewer seeds than the report's most says how many ("53.00 (n=1)", or "39.00 (1
of 2 seeds)" where a run lacks the figure; metrics.csv counts the same seeds). A cell never
averages runs whose configurations differ (beyond `trainer.same_run.NOT_THE_RUN`: folder, threads,
device…): each configuration has its own row, named the same in every column by where it departs
from its preset's defaults ("COLLIE (distance=l2)"; `name_settings`), and report.md lists those
rows. A run found twice (an archive beside its run root, a `collie rescore` copy) counts once: the
copy holding the most (`once_each`).

Downstream cells that average results over different numbers of trajectories (episodes), or hold
a result computed before its run was resumed and trained on (downstream.json's epoch below the
run's), are kept and marked "[n]", with a footnote saying which counts or which epoch.

Coverage cells use the reference's corner bin rule (the `corner_*` figures every run logs), as the
paper's tables do, and where the paper published a cell (`trainer/paper_results.py`: Ant,
HalfCheetah, Quadruped, Humanoid) its number stands in a "(paper)" column beside ours;
`--bin-rule visited` shows the visited-rule figures instead. A run without figures by the chosen
rule (one that predates the corner figures) shows its headline value, marked †.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from collie.tasks import Task
from collie.whole_files import make_folder
from trainer.config import first_version
from trainer.methods import METHODS, matters
from trainer.metrics import BIN_RULES, off_start_safe_ratio, standing_share
from trainer.paper_results import paper_cell
from trainer.run_files import (
    RunFolderError,
    read_arrays,
    read_json_object,
    run_folders,
    unsummarised_run_folders,
    writing_into,
)
from trainer.same_run import PLACED, RULE, comparable, preset_defaults, with_rule
from trainer.task_choice import judged_by

METRICS: tuple[tuple[str, str, int], ...] = (
    ("safe_coverage", "Safe state coverage (Table 1)", 2),
    ("safe_ratio", "Safe state ratio (Table 2)", 3),
    ("composite_coverage", "Composite safe coverage (+1 good, +1 neutral, −1 bad)", 2),
    ("weighted_composite_coverage", "Weighted composite safe coverage (+2 good, +1 neutral, −1 bad)", 2),
    ("median_final_distance", "Median final distance of the skills from the start", 2),
    ("final_x_spread", "Spread of the skills' final x (max − min)", 2),
    ("wall_s", "Wall time per run (s)", 0),
    (
        "off_start_safe_ratio",
        "Safe ratio outside the start's 2×2 bins (a diagnostic, corner rule; not a paper metric)",
        3,
    ),
    ("standing_share", "Share of the skills ending within one unit of their start (a diagnostic)", 2),
)
CORNER_METRICS = ("safe_coverage", "safe_ratio", "composite_coverage", "weighted_composite_coverage")
HEADLINE_MARK = "†"  # a cell with a run that logged no figures by the report's bin rule (its headline shown)
METHOD_ORDER = ("oracle", "diayn", "lsd", "metra", "ddg", "dodont", "collie")
DISPLAY = {
    "oracle": "Oracle",
    "diayn": "DIAYN",
    "lsd": "LSD",
    "metra": "METRA",
    "ddg": "DDG*",
    "dodont": "DoDont*",
    "collie": "COLLIE",
}


@dataclass
class RunResult:
    path: Path
    env: str
    task: str
    method: str
    seed: int
    status: str
    metrics: dict[str, Any]
    variant: str = ""
    downstream: dict[str, Any] = field(default_factory=dict)
    config: dict[str, Any] = field(default_factory=dict)
    setting: str = ""  # where its configuration departs from its preset ("distance=l2"; name_settings)
    bin_rule: str = "corner"  # the rule of the coverage figures shown (collie report --bin-rule)

    @property
    def label(self) -> str:
        name = DISPLAY.get(self.method, self.method)
        extra = ", ".join(part for part in (self.variant, self.setting) if part)
        return f"{name} ({extra})" if extra else name

    @property
    def settings(self) -> dict[str, Any]:
        """Its configuration but for where and how it ran, what its row and column say, and the keys
        its method does not read (trainer.methods.matters: `--total-queries` to METRA)."""
        known = self.method in METHODS
        return {
            k: v
            for k, v in comparable(self.config).items()
            if k not in PLACED and (not known or matters(k, self.method))
        }

    @property
    def column(self) -> str:
        return f"{self.env} {self.task}"

    def order(self) -> tuple[int, str, str]:
        rank = METHOD_ORDER.index(self.method) if self.method in METHOD_ORDER else len(METHOD_ORDER)
        return rank, self.variant, self.setting


# the figures the report reads from a run's side files as numbers: a damaged one leaves the run out
SUMMARY_NUMBERS = (
    *(m for m, _, _ in METRICS),
    *(f"{rule}_{m}" for rule in BIN_RULES for m in CORNER_METRICS),
)
DOWNSTREAM_NUMBERS = {"zero_shot": ("mean", "best"), "hierarchical": ("mean", "random_skills_mean")}


def _is_number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _checked_side_files(folder: Path, summary: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    """The run's variant (sweep_run.json) and downstream results (downstream.json), once every
    figure the report reads from them and from `summary` is of its type; RunFolderError naming the
    file and the field if not (a hand-edited or foreign file would stop the whole report)."""
    for key in SUMMARY_NUMBERS:
        if summary.get(key) is not None and not _is_number(summary[key]):
            raise RunFolderError(f"{folder / 'summary.json'}: its {key} {summary[key]!r:.40} is not a number")
    sweep, down = folder / "sweep_run.json", folder / "downstream.json"
    variant = read_json_object(sweep).get("variant", "") if sweep.exists() else ""
    if not isinstance(variant, str):
        raise RunFolderError(f"{sweep}: its variant {variant!r:.40} is not a string")
    downstream = read_json_object(down) if down.exists() else {}
    for kind, keys in DOWNSTREAM_NUMBERS.items():
        if kind not in downstream:
            continue
        result = downstream[kind]
        if not isinstance(result, dict):
            raise RunFolderError(f"{down}: its {kind} is not a JSON object")
        bad = [k for k in keys if not _is_number(result.get(k))]
        if bad:
            raise RunFolderError(f"{down}: its {kind} has no number {' or '.join(bad)}")
    return variant, downstream


def load_run(folder: Path) -> RunResult:
    """The run in `folder`; RunFolderError naming the file and why if one of its files is broken."""
    summary = read_json_object(folder / "summary.json")
    config_path = folder / "summary.json" if summary.get("config") else folder / "config.json"
    if not summary.get("config") and not config_path.exists():
        raise RunFolderError(f"{folder / 'summary.json'}: no config in it, and no config.json beside it")
    cfg = summary.get("config") or read_json_object(config_path)
    if not isinstance(cfg, dict):
        raise RunFolderError(f"{config_path}: its config is not a JSON object")
    missing = [k for k in ("env", "task", "method", "seed") if not isinstance(cfg.get(k), (str, int))]
    if missing:
        raise RunFolderError(f"{config_path}: its config has no {', '.join(missing)}")
    try:
        seed = int(cfg["seed"])
    except ValueError:
        raise RunFolderError(f"{config_path}: its config's seed {cfg['seed']!r} is not a whole number") from None
    variant, downstream = _checked_side_files(folder, summary)
    cfg = with_rule(folder, cfg)  # a task file's rule: two files of one name are two tasks
    return RunResult(
        folder,
        str(cfg["env"]),
        str(cfg["task"]),
        str(cfg["method"]),
        seed,
        summary.get("status", "?"),
        summary,
        variant,
        downstream,
        cfg,
    )


def run_task(run: RunResult) -> Task | None:
    """The rule the run was judged by: its own saved rule (task files; None for an instruction
    alone), else the built-in task."""
    return judged_by(run.path, run.env, run.task, run.seed)


def add_diagnostics(run: RunResult) -> None:
    """Put the diagnostics into `run.metrics` from the saved final evaluation: the share of skills
    that stand, and for a 2-D body the safe ratio outside the start's bins."""
    from trainer.envs import env_class  # MuJoCo: only for reports that have such runs

    saved = run.path / "eval_latest.npz"
    if not saved.exists():
        return
    xy = list(read_arrays(saved, ("xy",))["xy"])  # a damaged file: RunFolderError naming it
    try:
        dims, task = env_class(run.env).position_dims, run_task(run)
    except RunFolderError:
        raise
    except ValueError as exc:  # an env or task this version does not know, a damaged task.json
        said = str(exc)
        raise RunFolderError(said if said.startswith(str(run.path)) else f"{run.path}: {said}") from None
    run.metrics["standing_share"] = standing_share([t[:, :dims] for t in xy])
    if task is not None and dims == 2:
        run.metrics["off_start_safe_ratio"] = off_start_safe_ratio(xy, task)


def checked_run(folder: Path) -> RunResult:
    """The run in `folder` with its final evaluation read, as the report counts a finished run;
    RunFolderError naming the file and why for one it leaves out (`collie archive` refuses those)."""
    run = load_run(folder)
    add_diagnostics(run)
    return run


def find_runs(roots: list[Path]) -> tuple[list[RunResult], list[tuple[Path, str]]]:
    """Every run folder (one with summary.json) under `roots`, in a stable order, and the folders
    that could not be read, each with why (one broken folder must not hide the others)."""
    folders = sorted({f for root in roots for f in run_folders(Path(root))})  # none in a hidden folder
    runs, broken = [], []
    for f in folders:
        try:
            runs.append(load_run(f))
        except RunFolderError as exc:
            broken.append((f, str(exc)))
    return runs, broken


def format_cell(values: list[float], digits: int, most: int = 0) -> str:
    """'mean ± std' (sample std over seeds); a lone value as itself; nothing as '–'. A cell says how
    many seeds it holds where some of its runs lack the figure ("39.00 (1 of 2 seeds)") or it holds
    fewer than `most` (the report's most per cell: "53.00 (n=1)"), lest it read as the whole cell's
    or an exact figure."""
    v = np.asarray(finite(values), dtype=float)
    if len(v) == 0:
        return "–"
    text = f"{v[0]:.{digits}f}" if len(v) == 1 else f"{v.mean():.{digits}f} ± {v.std(ddof=1):.{digits}f}"
    if len(v) < len(values):
        return f"{text} ({len(v)} of {len(values)} seeds)"
    return f"{text} (n={len(v)})" if len(v) < most else text


def finite(values: list[float]) -> list[float]:
    return [x for x in values if x is not None and math.isfinite(x)]


def _table(rows: list[str], columns: list[str], cell: dict[tuple[str, str], str], corner: str = "method") -> str:
    lines = [f"| {corner} | " + " | ".join(columns) + " |", "|---|" + "---:|" * len(columns)]
    lines += [f"| {r} | " + " | ".join(cell.get((r, c), "–") for c in columns) + " |" for r in rows]
    return "\n".join(lines)


def _rows_and_columns(runs: list[RunResult]) -> tuple[list[str], list[str]]:
    rows = [r.label for r in sorted(runs, key=RunResult.order)]
    columns = sorted({r.column for r in runs})
    return list(dict.fromkeys(rows)), columns


def _group(runs: list[RunResult]) -> dict[tuple[str, str], list[RunResult]]:
    groups: dict[tuple[str, str], list[RunResult]] = {}
    for r in runs:
        groups.setdefault((r.label, r.column), []).append(r)
    return groups


def metric_value(r: RunResult, metric: str) -> float:
    """The run's final `metric`: coverage metrics by the report's bin rule (corner, as the paper,
    unless --bin-rule visited), else, for a run without that rule's figures, its headline."""
    if has_rule_figure(r, metric):
        return r.metrics[f"{r.bin_rule}_{metric}"]
    return r.metrics.get(metric, math.nan)


def has_rule_figure(r: RunResult, metric: str) -> bool:
    return metric in CORNER_METRICS and f"{r.bin_rule}_{metric}" in r.metrics


def figures_rule(r: RunResult) -> str:
    """runs.csv's `bin_rule`: the rule of the run's coverage figures there, the report's; for a run
    without that rule's figures (one from before `bin_rule`), the rule its headline followed (what
    it ran with: trainer.config.FIRST_VERSION), marked † as report.md marks its cells."""
    if all(has_rule_figure(r, m) for m in CORNER_METRICS):
        return r.bin_rule
    return f"{(first_version(r.config) | r.config).get('bin_rule')}{HEADLINE_MARK}"


def metric_table(runs: list[RunResult], metric: str, digits: int, most: int = 0) -> str:
    """Methods × tasks, each cell mean ± std of the run's final `metric` over seeds, with the paper's
    published cell in a "(paper)" column beside every task it reports."""
    rows, columns = _rows_and_columns(runs)
    cells: dict[tuple[str, str], str] = {}
    paper_columns: set[str] = set()
    for (label, col), g in _group(runs).items():
        cell = format_cell([metric_value(r, metric) for r in g], digits, most)
        headline = metric in CORNER_METRICS and not all(has_rule_figure(r, metric) for r in g)
        cells[(label, col)] = cell + (HEADLINE_MARK if headline and cell != "–" else "")
        paper = paper_cell(metric, g[0].env, g[0].task, g[0].method) if not g[0].variant else None
        if paper is not None:
            cells[(label, f"{col} (paper)")] = f"{paper[0]:.{digits}f} ± {paper[1]:.{digits}f}"
            paper_columns.add(col)
    shown = [c for col in columns for c in ((col, f"{col} (paper)") if col in paper_columns else (col,))]
    return _table(rows, shown, cells)


# what a downstream result counts over: results over different counts are not one protocol
# (zero-shot's best of more trajectories is higher), so a cell mixing them says so
DOWNSTREAM_COUNT = {"zero_shot": "trajectories", "hierarchical": "episodes"}


def trained_epochs(r: RunResult) -> int | None:
    """The epochs the run trained (summary.json's epochs_done, else its last evaluation's epoch)."""
    held = [r.metrics[k] for k in ("epochs_done", "epoch") if _is_number(r.metrics.get(k))]
    return int(max(held)) if held else None


def downstream_notes(g: list[RunResult], kind: str) -> list[str]:
    """Why a downstream cell of runs `g` is not one plain figure: it mixes counts of trajectories
    (episodes), or a run's result predates training it resumed (downstream.json's epoch < its own)."""
    notes = []
    counts = {r.downstream[kind].get(DOWNSTREAM_COUNT[kind]) for r in g}
    if len(counts) > 1:
        said = [f"{c:g}" for c in sorted(c for c in counts if _is_number(c))]
        said += ["unrecorded"] if any(not _is_number(c) for c in counts) else []
        notes.append(f"averages results over {' and '.join(said)} {DOWNSTREAM_COUNT[kind]} per run")
    for r in g:
        epoch, trained = r.downstream[kind].get("epoch"), trained_epochs(r)
        if _is_number(epoch) and trained is not None and epoch < trained:
            notes.append(f"seed {r.seed}'s result is from epoch {epoch} of {trained} (computed before it trained on)")
    return notes


class Footnotes:
    """Numbered footnotes of one table: a cell's mark "[n]" per note, one number per distinct note."""

    def __init__(self) -> None:
        self.numbers: dict[str, int] = {}

    def mark(self, notes: list[str]) -> str:
        return "".join(f" [{self.numbers.setdefault(n, len(self.numbers) + 1)}]" for n in notes)

    def text(self) -> str:
        return "".join(f"\n\n[{i}] {note}." for note, i in self.numbers.items())


def counts_note(runs: list[RunResult], kind: str) -> str:
    """The count results of `kind` were computed over, where every run's is recorded and the same."""
    counts = {r.downstream[kind].get(DOWNSTREAM_COUNT[kind]) for r in runs}
    one = next(iter(counts)) if len(counts) == 1 else None
    return f"\n\n{DOWNSTREAM_COUNT[kind].capitalize()} per run: {one}." if _is_number(one) else ""


def downstream_tables(runs: list[RunResult], most: int = 0) -> list[tuple[str, str]]:
    """(title, markdown) for the zero-shot (avg and best per task) and hierarchical returns; a cell
    mixing trajectory counts, or holding a result older than its run, is marked and footnoted."""
    out = []
    zs = [r for r in runs if "zero_shot" in r.downstream]
    if zs:
        rows, columns = _rows_and_columns(zs)
        cells: dict[tuple[str, str], str] = {}
        published: set[str] = set()
        notes = Footnotes()
        for (label, col), g in _group(zs).items():
            mark = notes.mark(downstream_notes(g, "zero_shot"))
            for kind, key in (("avg", "mean"), ("best", "best")):
                cell = format_cell([r.downstream["zero_shot"][key] for r in g], 2, most)
                cells[(label, f"{col} ({kind})")] = cell + mark
                paper = paper_cell(f"zero_shot_{key}", g[0].env, g[0].task, g[0].method) if not g[0].variant else None
                if paper is not None:
                    cells[(label, f"{col} ({kind}, paper)")] = f"{paper[0]:.2f} ± {paper[1]:.2f}"
                    published.add(col)
        cols = [
            c
            for kind in ("avg", "best")
            for col in columns
            for c in ((f"{col} ({kind})", f"{col} ({kind}, paper)") if col in published else (f"{col} ({kind})",))
        ]
        table = _table(rows, cols, cells) + counts_note(zs, "zero_shot") + notes.text()
        out.append(("Zero-shot motion return (Table 3)", table))
    hi = [r for r in runs if "hierarchical" in r.downstream]
    if hi:
        rows, columns = _rows_and_columns(hi)
        cells = {}
        published = set()
        notes = Footnotes()
        for (label, col), g in _group(hi).items():
            mark = notes.mark(downstream_notes(g, "hierarchical"))
            cells[(label, col)] = format_cell([r.downstream["hierarchical"]["mean"] for r in g], 2, most) + mark
            paper = paper_cell("hierarchical_mean", g[0].env, g[0].task, g[0].method) if not g[0].variant else None
            if paper is not None:
                cells[(label, f"{col} (paper)")] = f"{paper[0]:.2f} ± {paper[1]:.2f}"
                published.add(col)
            random_skills = [r.downstream["hierarchical"]["random_skills_mean"] for r in g]
            cells[(label, f"{col} (random skills)")] = format_cell(random_skills, 2, most) + mark
        cols = [
            c
            for col in columns
            for c in ((col, f"{col} (paper)") if col in published else (col,)) + (f"{col} (random skills)",)
        ]
        table = _table(rows, cols, cells) + counts_note(hi, "hierarchical") + notes.text()
        out.append(("Hierarchical Goal return, PPO over frozen skills (Table 4)", table))
    return out


def long_rows(runs: list[RunResult]) -> list[dict[str, Any]]:
    """metrics.csv: one row per (env, task, method, variant, setting, metric), over the seeds that
    have the figure (`n`, `seeds`), as report.md's cells."""
    rows = []
    for (_, _), g in sorted(_group(runs).items(), key=lambda kv: (kv[1][0].column, kv[1][0].order())):
        r0 = g[0]
        values: dict[str, list[float]] = {m: [metric_value(r, m) for r in g] for m, _, _ in METRICS}
        for kind, key in (("zero_shot", "mean"), ("zero_shot", "best"), ("hierarchical", "mean")):
            if all(kind in r.downstream for r in g):
                values[f"{kind}_{key}"] = [r.downstream[kind][key] for r in g]
        for metric, v in values.items():
            held = [(r.seed, x) for r, x in zip(g, v, strict=True) if finite([x])]
            a = np.asarray([x for _, x in held], dtype=float)
            rows.append(
                {
                    "env": r0.env,
                    "task": r0.task,
                    "method": r0.method,
                    "variant": r0.variant,
                    "setting": r0.setting,
                    "label": r0.label,
                    "metric": metric,
                    "mean": float(a.mean()) if len(a) else math.nan,
                    "std": float(a.std(ddof=1)) if len(a) > 1 else math.nan,
                    "n": len(a),
                    "seeds": " ".join(str(seed) for seed, _ in held),
                }
            )
    return rows


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:
    with open(path, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]) if rows else ["empty"])
        writer.writeheader()
        writer.writerows(rows)


def markdown(
    runs: list[RunResult],
    skipped: Sequence[tuple[Path, str]],
    figures: list[Path],
    out: Path,
    broken: Sequence[tuple[Path, str]] = (),
) -> str:
    seeds = sorted({len(g) for g in _group(runs).values()})
    most = max(seeds, default=0)
    tables = [
        f"## {title}\n\n{metric_table(runs, metric, digits, most)}"
        for metric, title, digits in METRICS
        if any(metric in r.metrics for r in runs)
    ]
    tables += [f"## {title}\n\n{table}" for title, table in downstream_tables(runs, most)]
    paper = (
        ' "(paper)" columns: the paper\'s published tables at its own budget.' if "(paper)" in "".join(tables) else ""
    )
    parts = [
        f"# collie report\n\n{len(runs)} finished runs; seeds per cell: {', '.join(map(str, seeds)) or '–'}. "
        "Cells: mean ± sample std over seeds of each run's final evaluation"
        + (f" (a cell of fewer than {most} says how many)" if len(seeds) > 1 else "")
        + "; "
        + rule_note(runs)
        + paper
    ]
    note = settings_note(runs)
    if note:
        parts.append(note)
    if skipped:
        parts.append("Left out (not finished): " + ", ".join(f"`{path}` ({status})" for path, status in skipped))
    if broken:
        parts.append("Left out (unreadable or twice): " + ", ".join(f"`{path}` ({why})" for path, why in broken))
    parts += tables
    if figures:
        parts.append(
            "## Skills (final evaluation, lowest seed)\n\n"
            + "\n".join(f"![{p.stem}]({p.relative_to(out)})" for p in figures)
        )
    return "\n\n".join(parts) + "\n"


def _setting_key(run: RunResult) -> str:
    return json.dumps(run.settings, sort_keys=True, default=str)


def held_data(r: RunResult) -> list[str]:
    """What a run folder holds beside its final figures that another copy of the run may lack (a
    `collie rescore` copy has no wall time and no zero-shot result)."""
    held = [f"{kind.replace('_', '-')} result" for kind in DOWNSTREAM_NUMBERS if kind in r.downstream]
    return held + (["wall time"] if _is_number(r.metrics.get("wall_s")) else [])


def once_each(runs: list[RunResult]) -> tuple[list[RunResult], list[tuple[Path, str]]]:
    """The runs with one per (env, task, method, variant, seed, configuration) — the copy holding the
    most (held_data), the first in path order among equals — and the others, each with why: a run
    found twice (a run root and its archive given together, say) is one seed, not two. Another
    configuration is another run (name_settings)."""
    copies: dict[tuple[str, str, str, str, int, str], list[RunResult]] = {}
    for r in runs:
        copies.setdefault((r.env, r.task, r.method, r.variant, r.seed, _setting_key(r)), []).append(r)
    kept: list[RunResult] = []
    left: list[tuple[Path, str]] = []
    for same in copies.values():
        best = max(same, key=lambda r: len(held_data(r)))  # the first of equals
        kept.append(best)
        for r in same:
            if r is not best:
                lacks = [d for d in held_data(best) if d not in held_data(r)]
                why = f": it has the {' and '.join(lacks)} this copy lacks" if lacks else ""
                left.append((r.path, f"the same run as `{best.path}`, which is the one counted{why}"))
    return kept, left


def _shown(value: Any) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def departures(r: RunResult) -> dict[str, Any]:
    """The run's settings where they differ from what its preset gives its env (all of them for a
    preset or env this version does not know)."""
    defaults = preset_defaults(r.config)
    base = comparable(defaults) if defaults else {}
    return {k: v for k, v in r.settings.items() if k not in base or base[k] != v}


def name_settings(runs: list[RunResult]) -> None:
    """Give each run a `setting` naming where its configuration departs from its preset's defaults,
    the same in every column ("epochs=20"), so that no cell averages runs of different
    configurations. Named: the keys a run's config sets away from its preset, and the keys whose
    values differ within a cell (an option an older run predates: `first_version`); the preset
    itself when the report holds several. A run at its preset's defaults keeps the plain row."""
    cells: dict[tuple[str, str, str, str], list[dict[str, Any]]] = {}
    for r in runs:
        cells.setdefault((r.method, r.variant, r.env, r.task), []).append(r.settings)
    split = {k for cell in cells.values() for s in cell for k in s if any(o.get(k) != s.get(k) for o in cell)}
    departed = [departures(r) for r in runs]
    chosen = {k for r, d in zip(runs, departed, strict=True) for k in d if k in r.config and k != RULE}
    keys = sorted((split | chosen) - {"preset"})
    several = len({r.settings.get("preset") for r in runs}) > 1
    for r, d in zip(runs, departed, strict=True):
        named = (["preset"] if several else []) + [k for k in keys if k in d]
        r.setting = ", ".join(f"{k}={_shown(r.settings.get(k))}" for k in named)


def settings_note(runs: list[RunResult]) -> str:
    """A line naming the rows whose configurations depart from their preset, or the one preset of
    all runs (empty for none)."""
    named = list(dict.fromkeys(r.label for r in sorted(runs, key=RunResult.order) if r.setting))
    presets = sorted({str(r.settings.get("preset")) for r in runs})
    if not named:
        return f"All runs: preset {presets[0]}." if len(presets) == 1 else ""
    preset = f"preset {presets[0]}" if len(presets) == 1 else "the preset each names"
    rules = any(RULE in r.settings and f"{RULE}=" in r.setting for r in runs)
    return (
        "Runs whose configurations differ are never averaged: a row's name gives the settings where its "
        f"runs depart from the defaults of {preset}, the same in every column: "
        + ", ".join(named)
        + "."
        + (
            f" ({RULE}=…: a digest of the rule a task file gave the run, its task.json: task files of one"
            " task name that judge differently.)"
            if rules
            else ""
        )
    )


def rule_note(runs: list[RunResult]) -> str:
    rule = runs[0].bin_rule if runs else "corner"
    said = "the reference's corner bin rule (as the paper)" if rule == "corner" else "the visited bin rule (--bin-rule)"
    return f"coverage by {said}; {HEADLINE_MARK}: a run without {rule}-rule figures, shown by its headline rule."


def write_report(roots: list[Path], out: Path, figures: bool = True, bin_rule: str = "corner") -> dict[str, Path]:
    """Find the runs under `roots`, write report.md, metrics.csv, runs.csv and figures into `out`;
    coverage by `bin_rule` (corner as the paper's tables, or visited: each run's logged headline)."""
    found, unreadable = find_runs(roots)
    every = [r for r in found if out not in r.path.parents]
    broken = [(path, why) for path, why in unreadable if out not in path.parents]
    runs = [r for r in every if r.status == "finished"]
    skipped = [(r.path, r.status) for r in every if r.status != "finished"]
    begun = sorted({f for root in roots for f in unsummarised_run_folders(Path(root)) if out not in f.parents})
    skipped += [(f, "no summary.json: still training, or killed before it wrote one") for f in begun]
    runs, duplicates = once_each(runs)
    broken += duplicates
    name_settings(runs)
    for r in runs:
        r.bin_rule = bin_rule
    for r in list(runs):
        try:
            add_diagnostics(r)
        except RunFolderError as exc:  # its final evaluation is unreadable: left out, with why
            runs.remove(r)
            broken.append((r.path, str(exc)))
    make_folder(out)
    paths: list[Path] = []
    if figures and runs:
        from trainer.report_figures import skill_figures

        paths = skill_figures(runs, out / "figures")
    _write_csv(out / "metrics.csv", long_rows(runs))
    _write_csv(
        out / "runs.csv",
        [
            {
                "path": str(r.path),
                "env": r.env,
                "task": r.task,
                "method": r.method,
                "variant": r.variant,
                "setting": r.setting,
                "seed": r.seed,
                "bin_rule": figures_rule(r),
                **{m: metric_value(r, m) for m, _, _ in METRICS},
                **{f"visited_{m}": r.metrics.get(f"visited_{m}") for m in CORNER_METRICS},
            }
            for r in runs
        ],
    )
    (out / "report.md").write_text(markdown(runs, skipped, paths, out, broken))
    return {"markdown": out / "report.md", "metrics_csv": out / "metrics.csv", "runs_csv": out / "runs.csv"}


def counted_runs(runs_csv: Path) -> int:
    """How many runs a report counts: runs.csv's rows, one per run."""
    with open(runs_csv, newline="") as f:
        return sum(1 for _ in csv.DictReader(f))


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("roots", nargs="+", help="folders holding run folders (searched recursively)")
    p.add_argument("--out", default=None, help="report folder (default: FIRST_ROOT/report)")
    p.add_argument("--no-figures", action="store_true", help="tables only")
    p.add_argument(
        "--bin-rule",
        choices=BIN_RULES,
        default="corner",
        help="coverage by the reference's corner rule (default, as the paper's tables) or the visited rule",
    )


def run(args: argparse.Namespace) -> int:
    roots = [Path(r) for r in args.roots]
    missing = [str(r) for r in roots if not r.is_dir()]
    if missing:
        print(f"collie report: error: not a folder: {', '.join(missing)}", file=sys.stderr)
        return 2
    empty = [str(r) for r in roots if not run_folders(r)]
    if empty:
        print(f"collie report: error: no run folder (none has summary.json) under {', '.join(empty)}", file=sys.stderr)
        return 2
    for root in roots:  # a run folder given itself: a broken one is an error, not a line in the report
        if (root / "summary.json").exists():
            try:
                checked_run(root)
            except RunFolderError as exc:
                print(f"collie report: error: {exc}", file=sys.stderr)
                return 2
    out = Path(args.out) if args.out else roots[0] / "report"
    if out.exists() and not out.is_dir():
        print(f"collie report: error: --out {out} is a file, not a folder", file=sys.stderr)
        return 2
    held = [name for name in ("summary.json", "config.json") if (out / name).exists()]
    if held:  # its report files would be written into the run, and a run's report.md read as its own
        print(f"collie report: error: --out {out} is a run folder (it holds {held[0]}); give another", file=sys.stderr)
        return 2
    with writing_into(out):
        paths = write_report(roots, out, figures=not args.no_figures, bin_rule=args.bin_rule)
    print((out / "report.md").read_text())
    print(f"written: {', '.join(str(p) for p in paths.values())}")
    if not counted_runs(paths["runs_csv"]):  # tables of dashes: a script must not take them for results
        where = ", ".join(str(r) for r in roots)
        print(
            f"collie report: error: no finished run to report under {where} ({out / 'report.md'} says why)",
            file=sys.stderr,
        )
        return 1
    return 0
