"""What a run draws at its end: the learning curve and one game of the learner."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import jax
import numpy as np

from elevens.teams.registry import resolve_team


def write_learning_curve(
    run_dir: str | Path, path: str | Path, title: str = "learning curve"
) -> Path:
    """Eval outcome against each handcrafted team, vs env steps and vs hours (minutes for runs
    under 2 hours), from metrics.csv.

    Two panels side by side share the y axis (mean outcome: win 1, draw 0.5, loss 0); one line
    per team; a dotted line at 0.5 (even).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from elevens.runs.curves import run_series
    from elevens.runs.logging import read_metrics_csv

    curves = read_metrics_csv(run_dir)
    hours_curve = curves.get("time/hours")
    # Short runs read better in minutes.
    longest = float(np.max(hours_curve.values)) if hours_curve is not None else 0.0
    time_scale, time_unit = (1.0, "hours") if longest >= 2.0 else (60.0, "minutes")
    figure, (by_steps, by_hours) = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    teams = sorted(
        name.split("/")[1]
        for name in curves
        if name.startswith("eval/") and name.endswith("/outcome")
    )
    for team in teams:
        for axis, x_name, scale in (
            (by_steps, "time/env_steps", 1e-6), (by_hours, "time/hours", time_scale)
        ):
            if x_name in curves:
                series = run_series(curves, f"eval/{team}/outcome", x_name)
                axis.plot(series.x * scale, series.y, marker="o", markersize=3, label=team)
    for axis in (by_steps, by_hours):
        axis.axhline(0.5, color="grey", linestyle=":", linewidth=1)
        axis.set_ylim(-0.02, 1.02)
        axis.grid(alpha=0.3)
    by_steps.set_xlabel("env steps (millions of game steps)")
    by_hours.set_xlabel(f"training time ({time_unit}, wall clock)")
    by_steps.set_ylabel("mean outcome vs team (win 1, draw 0.5, loss 0)")
    if teams:
        by_steps.legend(title="evaluated against")
    figure.suptitle(title)
    figure.tight_layout()
    path = Path(path)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path


def write_gif(
    learner: Any, state: Any, path: str | Path, seed: int = 0, opponent: str = "naive",
    deterministic: bool = False,
) -> Path:
    """One game of the learner (side 0) against a handcrafted team, drawn as a GIF or MP4
    (``deterministic``: the learner plays its mean action)."""
    from elevens.env.render import frames_from_states, save_video
    from elevens.eval.match import play_match
    from elevens.eval.play import states_from_record
    from elevens.teams.network import NetworkTeam

    team = NetworkTeam(policy=learner.policy, deterministic=deterministic, name="learner")
    result = play_match(
        learner.env, learner.env_params, team, resolve_team(opponent, learner.env_params),
        jax.random.key(seed + 2), 1, home_params=state.params.policy, swap_sides=False,
        record=True,
    )
    assert result.record is not None
    states = states_from_record(result.record, 0, learner.env_params)
    scale = max(2, round(600 / float(learner.env_params.field_length)))
    frames = frames_from_states(
        states, learner.env_params, team_names=("learner", opponent), scale=scale
    )
    return save_video(frames, path, fps=20)
