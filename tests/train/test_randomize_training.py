"""Domain randomisation in a run: its ranges save and resume with the config (old configs read
as no randomisation), bad ranges are refused before compiling, a randomised run trains and logs,
and the held-out tournament plays fixed settings."""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import pytest

import elevens
from elevens.env.randomize import Randomize
from elevens.eval.tournament import run_tournament, tournament_dict
from elevens.runs.logging import read_metrics_csv
from elevens.runs.loop import train
from elevens.runs.teams import load_team
from elevens.train.config import TrainConfig, load_config, make_config, validate
from tests.train.test_trainer import tiny_config

# Ranges around the tiny 30 x 21 field of the trainer tests.
SMALL_FIELD = {
    "env.randomize.enabled": True,
    "env.randomize.field_length": (27.0, 33.0),
    "env.randomize.field_width": (19.0, 23.0),
    "env.randomize.goal_width": (12.0, 16.0),
}


def test_randomize_ranges_round_trip_and_old_configs_read_as_off() -> None:
    config = make_config("2v2", **{"env.randomize.enabled": True,
                                   "env.randomize.kick_impulse": (3.5, 4.5)})
    validate(config)
    again = TrainConfig.from_json(config.to_json())
    assert again == config
    assert again.learner.env.randomize.kick_impulse == (3.5, 4.5)
    # A config written before randomisation existed: no randomize group, no sight noise.
    old = json.loads(make_config("2v2").to_json())
    del old["learner"]["env"]["randomize"]
    del old["learner"]["env"]["game"]["observation_noise"]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # filled silently: the default is what they played
        read = TrainConfig.from_saved(old, "old.json")
    assert read.learner.env.randomize == Randomize()
    assert not read.learner.env.randomize.enabled
    assert read.learner.env.game.observation_noise == 0.0
    assert read == make_config("2v2")


@pytest.mark.parametrize(
    ("override", "message"),
    [
        ({"env.randomize.ball_friction": (0.95, 0.85)}, "env.randomize.ball_friction=(0.95, 0.85)"),
        ({"env.randomize.move_speed": (-1.0, 1.0)}, "env.randomize.move_speed=(-1.0, 1.0)"),
        ({"env.randomize.goal_width": (30.0, 70.0)}, "env.randomize.goal_width=(30.0, 70.0)"),
    ],
)
def test_bad_ranges_are_refused_before_compiling(override, message) -> None:  # type: ignore[no-untyped-def]
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        validate(make_config("quickstart", **{"env.randomize.enabled": True, **override}))


@pytest.mark.slow
def test_a_randomised_run_trains_logs_and_resumes_its_config(tmp_path: Path) -> None:
    config = tiny_config(
        tmp_path / "run", **SMALL_FIELD,
        **{"games_per_iteration": 16, "run.iterations": 2, "run.eval_every": 0,
           "run.eval_teams": (), "opponent.mix": ("self=0.5", "naive=0.5")},
    )
    result = train(config, progress=False)
    assert result.iteration == 2
    curves = read_metrics_csv(tmp_path / "run")
    np.testing.assert_array_equal(curves["train/mean_score"].steps, [1, 2])
    for name in ("train/loss", "train/entropy", "opponent/naive/outcome"):
        assert np.all(np.isfinite(curves[name].values)), name
    saved = load_config(tmp_path / "run" / "config.json")
    assert saved.learner.env.randomize == config.learner.env.randomize
    assert saved.learner.env.randomize.enabled


def test_held_out_tournament_is_fixed_for_a_seed() -> None:
    env, params = elevens.make("1v1", episode_length=30)
    teams = [load_team("naive")]

    def play(seed: int) -> dict:  # type: ignore[type-arg]
        tournament = run_tournament(
            teams, env, params, num_games=8, seed=0, bootstrap_samples=0, randomize=seed
        )
        return tournament_dict(tournament)

    first, again, other = play(4), play(4), play(5)
    assert first["randomize"] == 4 and len(first["settings"]) == 20
    assert first["settings"] == again["settings"] and first["mean"] == again["mean"]
    assert first["settings"] != other["settings"]
    lengths = [row["field_length"] for row in first["settings"]]
    assert min(lengths) >= 85.0 and max(lengths) <= 115.0 and len(set(lengths)) == 20
