"""Figures for runs: skill trajectories over the task's regions (like the paper's Fig. 2) and
metric curves over epochs (metrics.jsonl).

Uses matplotlib's object API with an explicit Agg canvas and never imports pyplot: no global
backend switch, no figure registry to leak, safe from trainer threads and headless machines.
"""

from __future__ import annotations

import math
import pathlib
from collections.abc import Sequence
from typing import Any

import numpy as np
from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import LinearSegmentedColormap, ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch
from matplotlib.ticker import MaxNLocator

from collie.class_colours import STRONG
from collie.tasks import BAD, CLASS_NAMES, GOOD, NEUTRAL, Disc, Task
from collie.whole_files import write_whole

CLASS_COLOURS = STRONG  # undesirable red, neutral green, desirable yellow, as in the paper's figures
REGION_ALPHA = 0.22
DPI = 100
LABELLED_MARKER = "x"  # the guidance map's labelled states: crosses over its w-coloured dots
_GRID = 300  # shading resolution per axis
RGBA = tuple[float, float, float, float]
Labelled = list[tuple[np.ndarray, int]]


def skill_colours(skills: np.ndarray | None, n: int) -> list[RGBA]:
    """One RGBA per trajectory: by angle (cyclic map) for continuous skills with ≥ 2 dims, else
    by skill index (qualitative map) for one-hot, integer or missing skills."""
    if skills is None:
        index = np.arange(n)
    else:
        s = np.asarray(skills, dtype=float)
        s = s.reshape(len(s), -1)
        one_hot = s.shape[1] > 1 and np.isin(s, (0.0, 1.0)).all() and (s.sum(axis=1) == 1).all()
        if s.shape[1] >= 2 and not one_hot:
            angle = np.arctan2(s[:, 1], s[:, 0])
            return [(c[0], c[1], c[2], c[3]) for c in colormaps["hsv"]((angle + np.pi) / (2 * np.pi))]
        index = s.argmax(axis=1) if one_hot else s[:, 0].astype(int)
    qualitative = colormaps["tab10" if index.max(initial=0) < 10 else "tab20"]
    return [qualitative(int(i) % qualitative.N) for i in index]


def _save(fig: Figure, path: str | pathlib.Path) -> pathlib.Path:
    """A PNG renamed into place whole: a live run redraws curves.png while a person may look."""
    path = pathlib.Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(fig)
    write_whole(path, lambda f: fig.savefig(f, format="png", dpi=DPI))
    return path


def _extent(points: list[np.ndarray], task: Task | None) -> tuple[float, float, float, float]:
    """Box around the trajectories, the origin and the task's finite shapes, padded."""
    boxes = [np.array([[0.0, 0.0], [0.0, 0.0]])]
    boxes += [np.array([p.min(axis=0), p.max(axis=0)]) for p in points if len(p)]
    for r in task.regions if task is not None else ():
        if isinstance(r, Disc):  # OutsideDisc too: its edge is what matters
            c = np.asarray(r.centre)
            boxes.append(np.array([c - r.radius, c + r.radius]))
    lo = np.min([b[0] for b in boxes], axis=0)
    hi = np.max([b[1] for b in boxes], axis=0)
    pad = 0.08 * (hi - lo).max() + 1.0
    return lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad


def _shade(ax: Axes, task: Task | None, x0: float, x1: float, y0: float, y1: float, one_dim: bool) -> list[int]:
    """Shade each class's area (x only when one_dim); returns the classes shown. No rule: nothing."""
    if task is None or task.uses_pitch:  # no rule, or class is not a function of position: nothing to shade
        return []
    xs = np.linspace(x0, x1, _GRID)
    if one_dim:
        classes = task.classify(np.stack([xs, np.zeros_like(xs)], axis=1))[None, :]
    else:
        gx, gy = np.meshgrid(xs, np.linspace(y0, y1, _GRID))
        classes = task.classify(np.stack([gx.ravel(), gy.ravel()], axis=1)).reshape(gx.shape)
    cmap = ListedColormap([CLASS_COLOURS[c] for c in (BAD, NEUTRAL, GOOD)])
    ax.imshow(
        classes, cmap=cmap, vmin=-0.5, vmax=2.5, alpha=REGION_ALPHA, origin="lower",
        extent=(x0, x1, y0, y1), aspect="auto", interpolation="nearest", zorder=0,
    )  # fmt: skip
    if not one_dim:
        levels = [lv for lv in (0.5, 1.5) if classes.min() < lv < classes.max()]
        if levels:
            ax.contour(gx, gy, classes, levels=levels, colors="k", linewidths=0.6, alpha=0.5, zorder=1)
    return sorted(int(c) for c in np.unique(classes))


def _legend(ax: Axes, shaded: list[int], labels: set[int], marker: str = "o") -> None:
    """The shaded regions and the labelled states, drawn with `marker` (black-edged circles, or
    crosses in the label's colour: "x" has no face)."""
    handles: list[Any] = [Patch(color=CLASS_COLOURS[c], alpha=0.5, label=f"{CLASS_NAMES[c]} region") for c in shaded]
    handles += [
        Line2D(
            [],
            [],
            ls="",
            marker=marker,
            mfc=CLASS_COLOURS[c],
            mec="k" if marker == "o" else CLASS_COLOURS[c],
            label=f"labelled {CLASS_NAMES[c]}",
        )
        for c in sorted(labels)
    ]
    if handles:
        ax.legend(handles=handles, loc="upper right", fontsize=7, framealpha=0.8)


def _draw_xy(
    ax: Axes,
    trajs: list[np.ndarray],
    colours: list[RGBA],
    task: Task | None,
    labelled: Labelled,
    reach: list[np.ndarray],
) -> list[int]:
    points = [t[:, :2] for t in trajs + reach] + [np.asarray(s, dtype=float)[:, :2] for s, _ in labelled]
    x0, x1, y0, y1 = _extent(points, task)
    shaded = _shade(ax, task, x0, x1, y0, y1, one_dim=False)
    for t, colour in zip(trajs, colours, strict=True):
        ax.plot(t[:, 0], t[:, 1], color=colour, lw=1.2, zorder=2)
    for states, label in labelled:
        s = np.asarray(states, dtype=float)
        ax.scatter(s[:, 0], s[:, 1], s=9, c=CLASS_COLOURS[label], edgecolors="k", linewidths=0.3, zorder=3)
    ax.set(xlim=(x0, x1), ylim=(y0, y1), xlabel="x", ylabel="y")
    ax.set_aspect("equal")
    return shaded


def _draw_x_over_time(
    ax: Axes,
    trajs: list[np.ndarray],
    colours: list[RGBA],
    task: Task | None,
    labelled: Labelled,
    reach: list[np.ndarray],
) -> list[int]:
    xs = [t[:, 0] for t in trajs]
    x0, x1, _, _ = _extent([np.stack([x, np.zeros_like(x)], axis=1) for x in xs + [r[:, 0] for r in reach]], task)
    t_max = max((len(x) for x in xs), default=1) - 1 or 1
    shaded = _shade(ax, task, x0, x1, 0.0, float(t_max), one_dim=True)
    for x, colour in zip(xs, colours, strict=True):
        ax.plot(x, np.arange(len(x)), color=colour, lw=1.2, zorder=2)
    for states, label in labelled:  # a rug along t = 0: a labelled segment has no global time
        x = np.asarray(states, dtype=float).reshape(len(states), -1)[:, 0]
        ax.scatter(x, np.zeros_like(x), marker="|", s=60, c=CLASS_COLOURS[label], zorder=3)
    ax.set(xlim=(x0, x1), ylim=(0, t_max), xlabel="x", ylabel="t (step)")
    return shaded


def plot_skill_trajectories(
    xy_trajs: Sequence[np.ndarray],
    task: Task | None,
    path: str | pathlib.Path,
    *,
    skills: np.ndarray | None = None,
    position_dims: int = 2,
    title: str = "",
    labelled: Sequence[tuple[np.ndarray, int]] | None = None,
) -> pathlib.Path:
    """x-y paths coloured by skill over the shaded task regions (none for a run without a rule; x
    over time when position_dims == 1); `labelled` = (states (H, 2), label) pairs drawn as small
    markers coloured by the label given."""
    fig = Figure(figsize=(6, 6) if position_dims == 2 else (7, 4.5))
    draw_skill_panel(
        fig.add_subplot(), xy_trajs, task, skills=skills, position_dims=position_dims, title=title, labelled=labelled
    )
    fig.tight_layout()
    return _save(fig, path)


def draw_skill_panel(
    ax: Axes,
    xy_trajs: Sequence[np.ndarray],
    task: Task | None,
    *,
    skills: np.ndarray | None = None,
    position_dims: int = 2,
    title: str = "",
    labelled: Sequence[tuple[np.ndarray, int]] | None = None,
    legend: bool = True,
    reach: Sequence[np.ndarray] = (),
) -> None:
    """One panel of `plot_skill_trajectories` on a given axes (for grids of runs, `collie report`);
    its extent takes in `reach` too (the other panels' paths: one scale for all, compared by eye)."""
    if position_dims not in (1, 2):
        raise ValueError(f"position_dims must be 1 or 2, got {position_dims}")
    trajs = [np.asarray(t, dtype=float).reshape(len(t), -1) for t in xy_trajs]
    colours = skill_colours(skills, len(trajs))
    labelled = list(labelled or [])
    draw = _draw_xy if position_dims == 2 else _draw_x_over_time
    shaded = draw(ax, trajs, colours, task, labelled, [np.asarray(r, dtype=float).reshape(len(r), -1) for r in reach])
    ax.set_title(title or (task.name if task is not None else "no task rule"), fontsize=10)
    if legend:
        _legend(ax, shaded, {int(label) for _, label in labelled})


def plot_guidance_map(
    xy_trajs: Sequence[np.ndarray],
    w: np.ndarray,
    path: str | pathlib.Path,
    *,
    task: Task | None = None,
    title: str = "",
    labelled: Sequence[tuple[np.ndarray, int]] | None = None,
) -> pathlib.Path:
    """The evaluation paths coloured by the guidance w(s) ∈ [0, 2] at their states (`w`: one row
    per path, at the same points), and the labelled states by the label given: a map that needs
    no rule (the task's regions are shaded under it only when the run has one)."""
    trajs = [np.asarray(t, dtype=float).reshape(len(t), -1)[:, :2] for t in xy_trajs]
    labelled = list(labelled or [])
    fig = Figure(figsize=(6.6, 6))
    ax = fig.add_subplot()
    x0, x1, y0, y1 = _extent(trajs + [np.asarray(s, float)[:, :2] for s, _ in labelled], task)
    _shade(ax, task, x0, x1, y0, y1, one_dim=False)
    cmap = LinearSegmentedColormap.from_list("w", [CLASS_COLOURS[BAD], CLASS_COLOURS[NEUTRAL], CLASS_COLOURS[GOOD]])
    points = None
    for t, wt in zip(trajs, w, strict=True):
        ax.plot(t[:, 0], t[:, 1], color="0.7", lw=0.6, zorder=1)
        points = ax.scatter(t[:, 0], t[:, 1], c=np.asarray(wt)[: len(t)], cmap=cmap, vmin=0, vmax=2, s=6, zorder=2)
    for states, label in labelled:
        st = np.asarray(states, dtype=float)
        ax.scatter(st[:, 0], st[:, 1], s=14, marker=LABELLED_MARKER, c=CLASS_COLOURS[label], linewidths=0.8, zorder=3)
    if points is not None:
        fig.colorbar(points, ax=ax, label="w(s)", shrink=0.8)
    ax.set(xlim=(x0, x1), ylim=(y0, y1), xlabel="x", ylabel="y")
    ax.set_aspect("equal")
    ax.set_title(title or "guidance w(s)", fontsize=10)
    _legend(ax, [], {int(label) for _, label in labelled}, marker=LABELLED_MARKER)
    fig.tight_layout()
    return _save(fig, path)


def plot_curves(records: list[dict], keys: Sequence[str], path: str | pathlib.Path, title: str = "") -> pathlib.Path:
    """One small subplot per key: value over `epoch` (record index where absent), whole epochs on
    the axis; `title` names the run (a folder of several runs' curves.png tells them apart)."""
    if not keys:
        raise ValueError("plot_curves needs at least one key")
    ncols = min(3, len(keys))
    nrows = math.ceil(len(keys) / ncols)
    fig = Figure(figsize=(4 * ncols, 2.8 * nrows))
    for i, key in enumerate(keys):
        ax = fig.add_subplot(nrows, ncols, i + 1)
        pts = [
            (r.get("epoch", j), r[key])
            for j, r in enumerate(records)
            if isinstance(r.get(key), int | float) and math.isfinite(r[key])
        ]
        if pts:
            ex, ey = zip(*pts, strict=True)
            ax.plot(ex, ey, marker="o", ms=3, lw=1.2)
        ax.set_title(key, fontsize=9)
        ax.set_xlabel("epoch", fontsize=8)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))  # a short run showed epochs 0.2, 0.4, …
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return _save(fig, path)
