"""Training against fixed teams (opponent.mix): a learner trained against the naive team gets
better against it; self-play and fixed teams share an iteration's games, each reported apart,
with the league learning from its own games only; and bad mixes are clear errors."""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np
import pytest

from elevens.runs.logging import read_metrics_csv
from elevens.runs.loop import train
from elevens.runs.teams import team_on_field
from elevens.train.config import make_config, opponent_mix, self_play_games
from elevens.train.learner import make_learner
from tests.train.test_trainer import tiny_config


@pytest.mark.slow
def test_training_against_naive_beats_naive_more_often(tmp_path: Path) -> None:
    # Every game of every iteration against the naive team (no self-play). The untrained
    # learner gets 0.04 against it over 200 games; 40 iterations (about 20 s) make it 0.195
    # (seeds 1 and 2: 0.02 -> 0.15, 0.035 -> 0.11).
    config = tiny_config(
        tmp_path / "run",
        **{
            "opponent.mix": ("naive=1",),
            "run.iterations": 40,
            "run.eval_every": 40,
            "run.eval_teams": ("naive",),
            "run.eval_games": 200,
            "run.checkpoint_every": 0,
        },
    )
    result = train(config, progress=False)
    curves = read_metrics_csv(tmp_path / "run" / "metrics.csv")
    evaluation = dict(zip(curves["eval/naive/outcome"].steps.tolist(),
                          curves["eval/naive/outcome"].values.tolist(), strict=True))
    assert evaluation[40] >= evaluation[0] + 0.08, evaluation
    # Training saw only the naive team: its outcome there is train/mean_score.
    np.testing.assert_array_equal(
        curves["opponent/naive/outcome"].values, curves["train/mean_score"].values
    )
    assert result.iteration == 40


def test_self_play_and_fixed_teams_share_the_games_and_are_reported_apart() -> None:
    # A trained team in the mix too, and a run's shorter last chunk (1 iteration; K is 2),
    # compiled for the learner at hand: the trained team's params must not stop that. One
    # compile for both checks (the shorter scan's; the chunk's iteration is the same).
    config = tiny_config(
        **{
            "opponent.kind": "league",
            "opponent.league_every": 1,
            "opponent.mix": ("self=0.5", "naive=0.25", "elevens-2v2=0.25"),
        }
    )
    assert opponent_mix(config.learner) == [("self", 32), ("naive", 16), ("elevens-2v2", 16)]
    assert config.learner.iterations_per_chunk == 2
    trainer = make_learner(config.learner, config.learner.make_env(), team_on_field)
    state = trainer.init(jax.random.key(0))
    assert state.opponent.indices.shape == (32,)  # league snapshots for self-play games only
    state, metrics = trainer.update(state, 1)
    assert int(state.iteration) == 1
    outcomes = {k: np.asarray(v) for k, v in metrics.items() if k.endswith("/outcome")}
    assert set(outcomes) == {"opponent/self/outcome", "opponent/naive/outcome",
                             "opponent/elevens-2v2/outcome"}
    assert all(outcome.shape == (1,) for outcome in outcomes.values())
    # The mean over all games is the games-weighted mean of the three.
    mean = (2 * outcomes["opponent/self/outcome"] + outcomes["opponent/naive/outcome"]
            + outcomes["opponent/elevens-2v2/outcome"]) / 4
    np.testing.assert_allclose(np.asarray(metrics["train/mean_score"]), mean, rtol=1e-6)
    # Every league record is from self-play: 1 iteration x 32 games (not all 64).
    assert int(np.sum(np.asarray(state.opponent.league.result_count))) == 32


@pytest.mark.parametrize(
    ("mix", "message"),
    [
        (("naive",), "entry 'naive' is invalid: give TEAM=SHARE"),
        (("naive=1.5",), "entry 'naive=1.5' is invalid"),
        (("naive=0.7", "random=0.6"), "the shares sum to 1.3"),
        (("self=0.5", "naive=0.2"), "the shares sum to 0.7; with 'self=...' they must sum to 1"),
        (("naive=0.001",), "gives 0.064 games, round to at least 1"),
        (("naive=0.5", "naive=0.2"), "a team appears twice"),
    ],
)
def test_bad_mixes_are_refused(mix: tuple[str, ...], message: str) -> None:
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        tiny_config(**{"opponent.mix": mix})


def test_a_league_needs_self_play_and_an_unknown_team_is_named() -> None:
    with pytest.raises(ValueError, match="without self-play is invalid with opponent.kind"):
        tiny_config(**{"opponent.kind": "league", "opponent.mix": ("naive=1",)})
    assert self_play_games(tiny_config(**{"opponent.mix": ("naive=0.25",)}).learner) == 48
    nobody = make_config("quickstart", **{"opponent.mix": ("nobody=0.5",)}).learner
    with pytest.raises(ValueError, match="opponent.mix team .nobody.: team spec: nobody does not"):
        make_learner(nobody, nobody.make_env(), team_on_field)
    naive = make_config("quickstart", **{"opponent.mix": ("naive=0.5",)}).learner
    with pytest.raises(ValueError, match="names fixed teams: pass load_team"):
        make_learner(naive, naive.make_env())


def test_evaluation_tracks_a_trained_team_and_refuses_an_unknown_one(tmp_path: Path) -> None:
    from elevens.runs.loop import evaluate

    config = tiny_config()
    trainer = make_learner(config.learner, config.learner.make_env())
    state = trainer.init(jax.random.key(0))
    results = evaluate(trainer, state, jax.random.key(1), teams=("elevens-2v2", "naive"),
                       num_games=4)
    assert {"eval/elevens-2v2/outcome", "eval/naive/outcome"} <= set(results)
    assert 0.0 <= results["eval/elevens-2v2/outcome"] <= 1.0
    # Refused before anything compiles, naming the field and the spec.
    with pytest.raises(ValueError, match="run.eval_teams team 'runs/none': team spec"):
        train(tiny_config(tmp_path / "run", **{"run.eval_teams": ("naive", "runs/none")}))
    assert not (tmp_path / "run").exists()


def test_mix_games_keeps_the_other_sizes_for_self_play() -> None:
    # A 1 v 1 run mixed with 2 v 2 whose fixed team plays in the 2 v 2 iterations only.
    from elevens.train.config import scenario_config

    mixed = {"env.mix": ("2v2",), "env.mix_shares": (0.5,), "opponent.mix": ("naive=0.25",)}
    learner = tiny_config(**mixed, **{"opponent.mix_games": ("2v2",)}).learner
    assert opponent_mix(scenario_config(learner, "1v1")) == [("self", 64)]
    assert opponent_mix(scenario_config(learner, "2v2")) == [("self", 24), ("naive", 8)]
    everywhere = tiny_config(**mixed).learner
    assert opponent_mix(scenario_config(everywhere, "1v1")) == [("self", 48), ("naive", 16)]
    with pytest.raises(ValueError, match=r"entry '3v3' is invalid \(allowed: the run's games "
                                         r"1v1, 2v2\)"):
        tiny_config(**mixed, **{"opponent.mix_games": ("3v3",)})
    with pytest.raises(ValueError, match="is invalid without opponent.mix"):
        tiny_config(**{"opponent.mix_games": ("1v1",)})
