"""Learning curves over seeds (thesis figure 6.4) from training runs' ``metrics.csv``.

The host loop (``elevens.runs.loop``) logs, at the iteration of every evaluation,
``eval/<team>/outcome`` (the learner's mean outcome against a handcrafted team) together with
``time/hours`` (training wall time) and ``time/env_steps`` (game steps played) at the same step;
``elevens.runs.logging.read_metrics_csv`` reads them back as one curve per name.

For one or more runs (seeds) this draws the mean outcome against a chosen team over each x axis
(hours, env steps or iterations), with a band of ± one std over the runs, and a vertical line
where the mean curve against each evaluated team first rises above 0.5 ("first outperformed").
Runs are evaluated at different wall times, so curves are put on a common grid by linear
interpolation over the x range that all runs cover; with a single run, or runs whose x values
agree, the logged points are used as they are.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

DEFAULT_METRIC = "eval/{team}/outcome"
"""Metric name template; ``{team}`` is replaced by the opponent's name."""
X_AXES: dict[str, tuple[str | None, str, float, str]] = {
    # alias: (metric name or None for the logged step, axis label, divisor, short unit)
    "hours": ("time/hours", "training time (hours, wall clock)", 1.0, "h"),
    "env_steps": ("time/env_steps", "env steps (millions of game steps)", 1e6, "M steps"),
    "iteration": (None, "iteration", 1.0, "it."),
}
OUTPERFORM_THRESHOLD = 0.5
GRID_POINTS = 200


@dataclasses.dataclass(frozen=True)
class Series:
    """One run's metric against one x axis, sorted by x."""

    run: str
    x: np.ndarray  # f64[E]
    y: np.ndarray  # f64[E]


@dataclasses.dataclass(frozen=True)
class Band:
    """Mean and std over runs on a common x grid."""

    x: np.ndarray  # f64[K]
    mean: np.ndarray  # f64[K]
    std: np.ndarray  # f64[K] population std over runs (0 for one run)
    runs: int


def x_metric(alias: str) -> tuple[str | None, str, float, str]:
    """(metric name or None for the step, axis label, divisor, short unit) of an x axis alias
    (hours, env_steps, iteration) or of any logged metric name."""
    if alias in X_AXES:
        return X_AXES[alias]
    if alias in ("step", "iter"):
        return X_AXES["iteration"]
    return alias, alias, 1.0, ""


class MissingMetricError(ValueError, KeyError):
    """A run has not logged the metric a curve needs (bad input: the CLI reports it in one
    line); still a ``KeyError`` for callers that look the metric up."""

    __str__ = ValueError.__str__  # the message as written, not KeyError's repr of it


def run_series(
    curves: dict[str, Any], metric: str, x_name: str | None, run: str = ""
) -> Series:
    """``metric`` against ``x_name`` (another metric, read at the same steps, or None: the step).

    curves: ``read_metrics_csv`` output. Raises ``KeyError`` naming the missing metric and the
    metrics the run has.
    """
    if metric not in curves:
        raise MissingMetricError(
            f"run {run or '?'} has no metric {metric!r}; it has: "
            f"{', '.join(sorted(name for name in curves if name.startswith('eval/'))) or 'none'}"
        )
    curve = curves[metric]
    steps, y = np.asarray(curve.steps), np.asarray(curve.values, np.float64)
    if x_name is None:
        x = steps.astype(np.float64)
    else:
        if x_name not in curves:
            raise MissingMetricError(f"run {run or '?'} has no x metric {x_name!r}")
        by_step = dict(zip(curves[x_name].steps.tolist(), curves[x_name].values.tolist(),
                           strict=True))
        x = np.asarray([by_step.get(int(s), math.nan) for s in steps], np.float64)
    keep = np.isfinite(x) & np.isfinite(y)
    order = np.argsort(x[keep], kind="stable")
    return Series(run=run, x=x[keep][order], y=y[keep][order])


def band(series: Sequence[Series], points: int = GRID_POINTS) -> Band:
    """Mean ± std over runs. Identical x values are used as they are; otherwise the runs are
    interpolated onto ``points`` x values spanning the range all of them cover."""
    series = [s for s in series if s.x.size]
    if not series:
        raise ValueError("no run has any point to plot")
    same_x = all(s.x.shape == series[0].x.shape and np.allclose(s.x, series[0].x)
                 for s in series)
    if same_x:
        grid = series[0].x
        values = np.stack([s.y for s in series])
    else:
        low = max(float(s.x[0]) for s in series)
        high = min(float(s.x[-1]) for s in series)
        if not high > low:
            raise ValueError(
                "the runs' x ranges do not overlap: "
                + ", ".join(f"{s.run} [{s.x[0]:g}, {s.x[-1]:g}]" for s in series)
            )
        grid = np.linspace(low, high, points)
        values = np.stack([np.interp(grid, s.x, s.y) for s in series])
    return Band(x=grid, mean=values.mean(axis=0), std=values.std(axis=0), runs=len(series))


def first_above(
    curve: Band, threshold: float = OUTPERFORM_THRESHOLD, stderr: np.ndarray | None = None,
    z: float = 0.0,
) -> float | None:
    """The first x where the mean is above ``threshold`` (None if it never is); with
    ``stderr`` (on the band's grid), where the lower end ``mean - z * stderr`` is."""
    lower = curve.mean if stderr is None else curve.mean - z * stderr
    above = np.flatnonzero(lower > threshold)
    return float(curve.x[above[0]]) if above.size else None


def outcome_stderr_series(
    curves: dict[str, Any], team: str, x_name: str | None, games: int, run: str = ""
) -> Series | None:
    """The standard error of the mean outcome against ``team`` at each evaluation, from its
    win and draw rates over ``games`` games (outcome 1, 0.5 or 0: variance w + d/4 - mean^2);
    None if the run did not log them."""
    names = [f"eval/{team}/{part}" for part in ("outcome", "win", "draw")]
    if any(name not in curves for name in names) or games < 1:
        return None
    mean, win, draw = (run_series(curves, name, x_name, run) for name in names)
    if not (mean.x.shape == win.x.shape == draw.x.shape):
        return None
    variance = np.clip(win.y + draw.y / 4.0 - mean.y**2, 0.0, None)
    return Series(run=run, x=mean.x, y=np.sqrt(variance / games))


def _eval_games(run_dir: Path) -> int:
    """``run.eval_games`` of a run directory's config.json (0 when it cannot be read)."""
    import json

    try:
        config = json.loads((run_dir / "config.json").read_text(encoding="utf-8"))
        return int(config["run"]["eval_games"])
    except (OSError, ValueError, KeyError, TypeError):
        return 0


def _teams_of(curves_per_run: Sequence[dict[str, Any]], template: str) -> list[str]:
    """Teams for which every run has the templated metric."""
    prefix, _, suffix = template.partition("{team}")
    found = None
    for curves in curves_per_run:
        teams = {
            name[len(prefix): len(name) - len(suffix)]
            for name in curves
            if name.startswith(prefix) and name.endswith(suffix)
            and len(name) > len(prefix) + len(suffix)
        }
        found = teams if found is None else found & teams
    return sorted(found or ())


@dataclasses.dataclass(frozen=True)
class CurvesSummary:
    """What ``plot_learning_curves`` found: per x axis, the first x each team is outperformed."""

    path: Path
    runs: tuple[str, ...]
    against: str
    first_outperformed: dict[str, dict[str, float | None]]  # x alias -> team -> x (or None)
    final_mean: float  # mean over runs of the last logged value against ``against``
    with_interval: frozenset[str] = frozenset()  # teams whose crossing used the interval


def plot_learning_curves(
    run_dirs: Sequence[str | Path],
    out: str | Path,
    *,
    against: str = "naive",
    x_axes: Sequence[str] = ("hours", "env_steps"),
    metric: str = DEFAULT_METRIC,
    threshold: float = OUTPERFORM_THRESHOLD,
    title: str | None = None,
    confidence: float = 0.95,
) -> CurvesSummary:
    """Figure 6.4 from runs' ``metrics.csv``: one panel per x axis, PNG at ``out``.

    metric: a name template with ``{team}`` (default ``eval/{team}/outcome``), or a plain
    metric name (then only ``against`` labels it and no vertical lines are drawn).
    A team counts as beaten ("first beats") where the lower end of the ``confidence``
    interval of the mean outcome is above ``threshold``: the standard error comes from the
    logged win and draw rates over each run's ``run.eval_games`` games, pooled over the runs.
    Runs that logged no win and draw rates fall back to the mean itself (said in the legend).
    """
    import statistics

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names, curves_per_run = _read_runs(run_dirs)
    eval_games = [_eval_games(Path(run_dir)) for run_dir in run_dirs]
    z = statistics.NormalDist().inv_cdf(0.5 + confidence / 2.0)
    templated = "{team}" in metric
    main_metric = metric.format(team=against) if templated else metric
    teams = _teams_of(curves_per_run, metric) if templated else []

    figure, axes = plt.subplots(
        1, len(x_axes), figsize=(5.6 * len(x_axes), 4.4), sharey=True, squeeze=False
    )
    firsts: dict[str, dict[str, float | None]] = {}
    interval_teams: set[str] = set()
    final_mean = math.nan
    for axis, alias in zip(axes[0], x_axes, strict=True):
        x_name, label, divisor, unit = x_metric(alias)
        series = [
            run_series(curves, main_metric, x_name, run)
            for curves, run in zip(curves_per_run, names, strict=True)
        ]
        main = band(series)
        final_mean = float(np.mean([s.y[-1] for s in series if s.y.size]))
        if len(series) > 1:
            for s in series:
                axis.plot(s.x / divisor, s.y, color="grey", linewidth=0.7, alpha=0.5)
        axis.plot(main.x / divisor, main.mean, color="#1f4e9c", linewidth=2,
                  label=f"mean over {main.runs} run{'s' if main.runs > 1 else ''}")
        if main.runs > 1:
            axis.fill_between(main.x / divisor, main.mean - main.std, main.mean + main.std,
                              color="#1f4e9c", alpha=0.2, label="± 1 std over runs")
        axis.axhline(threshold, color="grey", linestyle=":", linewidth=1)
        firsts[alias] = _mark_first_beats(
            axis, teams, curves_per_run, names, eval_games, metric, x_metric(alias),
            threshold, z, interval_teams,
        )
        axis.set_xlabel(label)
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
        axis.legend(loc="lower right", fontsize=8)
    axes[0][0].set_ylabel(f"mean outcome against {against}\n(win 1, draw 0.5, loss 0)")
    figure.suptitle(
        title
        or f"Learning curve against {against} ({len(names)} run{'s' if len(names) > 1 else ''}: "
        f"{', '.join(names)})"
    )
    figure.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=110)
    plt.close(figure)
    return CurvesSummary(
        path=out, runs=tuple(names), against=against, first_outperformed=firsts,
        final_mean=final_mean, with_interval=frozenset(interval_teams),
    )


# --------------------------------------------------------------------------------------------
# Several runs side by side (thesis figure 6.6)
# --------------------------------------------------------------------------------------------



def _read_runs(run_dirs: Sequence[str | Path]) -> tuple[list[str], list[dict[str, Any]]]:
    """(run names, metrics.csv curves) of each run directory (or metrics.csv file)."""
    from elevens.runs.logging import read_metrics_csv

    if not run_dirs:
        raise ValueError("no run directory given")
    names, curves_per_run = [], []
    for run_dir in run_dirs:
        path = Path(run_dir)
        csv_path = path if path.is_file() else path / "metrics.csv"
        if not csv_path.is_file():
            raise FileNotFoundError(f"{csv_path} does not exist (is {run_dir} a run directory?)")
        curves_per_run.append(read_metrics_csv(csv_path))
        names.append(path.name if path.is_dir() else path.parent.name)
    return names, curves_per_run


def _mark_first_beats(
    axis: Any, teams: Sequence[str], curves_per_run: list[dict[str, Any]], names: list[str],
    eval_games: list[int], metric: str, x: tuple[str | None, str, float, str],
    threshold: float, z: float, interval_teams: set[str],
) -> dict[str, float | None]:
    """Where the mean over runs first beats each team (a dashed line on ``axis``): the x of
    the first point whose interval's lower end is above ``threshold``."""
    import matplotlib.pyplot as plt

    x_name, _, divisor, unit = x
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    firsts: dict[str, float | None] = {}
    for index, team in enumerate(teams):
        team_band = band([
            run_series(curves, metric.format(team=team), x_name, run)
            for curves, run in zip(curves_per_run, names, strict=True)
        ])
        errors = [
            outcome_stderr_series(curves, team, x_name, games, run)
            for curves, run, games in zip(curves_per_run, names, eval_games, strict=True)
        ]
        stderr = None
        if metric == DEFAULT_METRIC and all(error is not None for error in errors):
            # The mean over R runs: its variance is the mean of the runs' variances / R.
            variances = [dataclasses.replace(e, y=e.y**2) for e in errors if e is not None]
            pooled = band(variances, points=team_band.x.size)
            stderr = np.sqrt(np.interp(team_band.x, pooled.x, pooled.mean) / len(errors))
        if stderr is not None:
            interval_teams.add(team)
        crossing = first_above(team_band, threshold, stderr, z)
        firsts[team] = crossing
        if crossing is not None:
            where = f"{crossing / divisor:.3g} {unit}".rstrip()
            how = "" if stderr is not None else " (mean, no interval)"
            axis.axvline(crossing / divisor, color=colours[(index + 1) % len(colours)],
                         linestyle="--", linewidth=1.2,
                         label=f"first beats {team} at {where}{how}")
    return firsts

def parse_run_groups(specs: Sequence[str]) -> list[tuple[str, list[Path]]]:
    """``LABEL=RUN[,RUN...]`` words as (label, run directories); a bare ``RUN`` is labelled by
    its folder name. The runs of one label are seeds of one setting, pooled into its band."""
    groups: list[tuple[str, list[Path]]] = []
    for spec in specs:
        label, sep, rest = spec.partition("=")
        if not sep:
            label, rest = Path(spec).name, spec
        runs = [Path(part) for part in rest.split(",") if part]
        if not label or not runs:
            raise ValueError(
                f"run group {spec!r} is invalid: write LABEL=RUN[,RUN...] (e.g. "
                "polyak=runs/p0,runs/p1) or a run directory"
            )
        groups.append((label, runs))
    labels = [label for label, _ in groups]
    if len(set(labels)) != len(labels):
        raise ValueError(f"run group labels repeat: {', '.join(labels)}; give each its own")
    return groups


def _read_run(run_dir: Path) -> dict[str, Any]:
    from elevens.runs.logging import read_metrics_csv

    csv_path = run_dir if run_dir.is_file() else run_dir / "metrics.csv"
    if not csv_path.is_file():
        raise FileNotFoundError(f"{csv_path} does not exist (is {run_dir} a run directory?)")
    return read_metrics_csv(csv_path)


def plot_run_groups(
    groups: Sequence[tuple[str, Sequence[Path]]],
    out: str | Path,
    *,
    against: str = "naive",
    x_axes: Sequence[str] = ("hours", "env_steps"),
    metric: str = DEFAULT_METRIC,
    title: str | None = None,
) -> dict[str, float]:
    """One curve per group (its mean over the group's runs, with a ± 1 std band for several),
    overlaid in one panel per x axis, labelled by the group. Returns each group's final mean."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not groups:
        raise ValueError("no runs given")
    name = metric.format(team=against) if "{team}" in metric else metric
    read = [(label, [(run.name, _read_run(run)) for run in runs]) for label, runs in groups]
    figure, axes = plt.subplots(
        1, len(x_axes), figsize=(5.6 * len(x_axes), 4.4), sharey=True, squeeze=False
    )
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    finals: dict[str, float] = {}
    for axis, alias in zip(axes[0], x_axes, strict=True):
        x_name, x_label, divisor, _ = x_metric(alias)
        for index, (label, runs) in enumerate(read):
            series = [run_series(curves, name, x_name, run) for run, curves in runs]
            curve = band(series)
            colour = colours[index % len(colours)]
            count = f"{curve.runs} run{'s' if curve.runs > 1 else ''}"
            axis.plot(curve.x / divisor, curve.mean, color=colour, linewidth=2,
                      label=f"{label} ({count})")
            if curve.runs > 1:
                axis.fill_between(curve.x / divisor, curve.mean - curve.std,
                                  curve.mean + curve.std, color=colour, alpha=0.15)
            finals[label] = float(np.mean([s.y[-1] for s in series if s.y.size]))
        axis.axhline(OUTPERFORM_THRESHOLD, color="grey", linestyle=":", linewidth=1)
        axis.set_xlabel(x_label)
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
        axis.legend(loc="lower right", fontsize=8)
    axes[0][0].set_ylabel(f"mean outcome against {against}\n(win 1, draw 0.5, loss 0)")
    figure.suptitle(title or f"Against {against}: " + ", ".join(label for label, _ in read))
    figure.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=110)
    plt.close(figure)
    return finals
