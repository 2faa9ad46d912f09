"""Fig. 2-style figures for `collie report`: per (env, task), one panel per method with the final
evaluation skills of its lowest seed over the task's shaded regions. Paths come from the run's
eval_latest.npz; runs written before that file existed are rolled out again from checkpoint.pt
(deterministic policy, the evaluation skills of `Trainer.evaluate`)."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from trainer.envs import env_class
from trainer.plots import draw_skill_panel
from trainer.report import HEADLINE_MARK, RunResult, has_rule_figure, metric_value, run_task
from trainer.run_files import has_checkpoint, read_arrays

MAX_COLUMNS = 4  # panels per row
TITLE_CHARS = 30  # a title line's characters that fit a 3.4-inch panel at 10 pt beside its neighbours
TITLE_LINE_INCHES = 0.2  # a 10-pt title line's height
FIGURE_DPI = 150  # a 4-panel figure 2000 px wide: readable in a paper's column (90 gave 918 px)


def final_skills(run: RunResult) -> tuple[np.ndarray, np.ndarray]:
    """(xy (n, T+1, 2), skills (n, k)) of the run's last evaluation."""
    saved = run.path / "eval_latest.npz"
    if saved.exists():  # readable: write_report left out the runs whose file is not
        arrays = read_arrays(saved, ("xy", "skill"))
        return arrays["xy"], arrays["skill"]
    from trainer.acting import acting_path
    from trainer.envs import VectorEnv
    from trainer.pretrained import load_skills
    from trainer.rollout import rollout

    skills = load_skills(run.path)
    c = skills.cfg
    env = VectorEnv(c.env, c.eval_trajectories, episode_steps=c.episode_steps, layout_seed=c.seed)
    z = skills.prior.evaluation_skills(c.eval_trajectories, seed=c.seed)
    traj = rollout(
        env,
        skills.agent,
        z,
        [c.seed * 1000 + i for i in range(c.eval_trajectories)],
        skills.normalise,
        deterministic=True,
        acting=acting_path(c.acting),
    )
    env.close()
    return traj.xy, traj.skill


def drawable(run: RunResult) -> bool:
    """Its final skills can be drawn: saved, or to be rolled out again from its checkpoint (a run
    folder that lost both still counts in the tables)."""
    return (run.path / "eval_latest.npz").exists() or has_checkpoint(run.path)


def panel_title(run: RunResult) -> str:
    """The panel's title: its row (wrapped at its settings, which would run into the next panel's
    title), seed and safe coverage (the tables' value: by the report's rule where logged)."""
    mark = "" if has_rule_figure(run, "safe_coverage") else HEADLINE_MARK
    figure = f"safe cov {metric_value(run, 'safe_coverage'):.0f}{mark}"
    return "\n".join([*textwrap.wrap(f"{run.label} (seed {run.seed})", TITLE_CHARS), figure])


def skill_figures(runs: list[RunResult], folder: Path) -> list[Path]:
    """One PNG per (env, task) present in `runs`, its panels on one scale (how far each method's
    skills reach compares by eye, as in the paper's Fig. 2); returns their paths."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for env, task_name in sorted({(r.env, r.task) for r in runs}):
        group = sorted(
            (r for r in runs if (r.env, r.task) == (env, task_name) and drawable(r)), key=lambda r: (r.order(), r.seed)
        )
        if not group:
            continue
        first = list({r.label: r for r in reversed(group)}.values())[::-1]  # lowest seed per method
        first.sort(key=RunResult.order)
        titles = [panel_title(run) for run in first]
        dims = env_class(env).position_dims
        cols = min(len(first), MAX_COLUMNS)
        rows = -(-len(first) // cols)
        lines = max(t.count("\n") + 1 for t in titles)  # a row's panels make room for its longest title
        panel = (3.6 if dims == 2 else 3.0) + TITLE_LINE_INCHES * (lines - 2)
        fig = Figure(figsize=(3.4 * cols, panel * rows + 0.3))  # and the figure for its suptitle
        drawn = [final_skills(run) for run in first]
        every = [t for xy, _ in drawn for t in xy]  # each panel over all panels' extent: one scale
        for i, (run, title, (xy, skill)) in enumerate(zip(first, titles, drawn, strict=True)):
            ax = fig.add_subplot(rows, cols, i + 1)
            draw_skill_panel(
                ax, list(xy), run_task(run), skills=skill, position_dims=dims, legend=False, title=title, reach=every
            )
            ax.tick_params(labelsize=7)
        fig.suptitle(f"{env} {task_name}", fontsize=11)
        fig.tight_layout()
        path = folder / f"skills_{env}_{task_name}.png"
        FigureCanvasAgg(fig)
        fig.savefig(path, dpi=FIGURE_DPI)
        paths.append(path)
    return paths
