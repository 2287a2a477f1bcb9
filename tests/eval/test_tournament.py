"""Tournaments: the table's arithmetic (mirrored cells, self-play), the schedule, team specs and
checkpoint teams, and a small real tournament through the command line.

The full bar (3 handcrafted teams, 11 v 11, 500 games a pair, under 10 minutes) is the slow test
at the end; it ran in 36 s on the 2-core CPU.
"""

from __future__ import annotations

import csv
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.cli.eval import main as eval_main
from elevens.eval.match import MatchResult, outcome_from_score, play_match
from elevens.eval.tournament import play_round_robin, schedule, table_from_results
from elevens.runs.teams import (
    Team,
    check_team_size,
    load_checkpoint_team,
    load_team,
    parse_team_spec,
    unique_names,
)
from elevens.teams.scripted import NaiveTeam, RandomTeam


def _result(goals_for: list[int], goals_against: list[int]) -> MatchResult:
    scored, conceded = jnp.array(goals_for), jnp.array(goals_against)
    games = len(goals_for)
    return MatchResult(
        goals_for=scored,
        goals_against=conceded,
        outcome=outcome_from_score(scored, conceded),
        home_side=jnp.array([0] * ((games + 1) // 2) + [1] * (games // 2)),
    )


# ------------------------------------------------------------------------------ arithmetic


def test_table_mirrors_each_match_for_the_away_team() -> None:
    results = {
        (0, 0): _result([1, 0, 2, 0], [0, 0, 2, 1]),  # W D D L: 0.5
        (0, 1): _result([2, 1, 0, 3], [0, 1, 3, 1]),  # W D L W: 0.625
        (0, 2): _result([0, 0], [1, 2]),  # L L: 0
        (1, 1): _result([1, 1], [1, 1]),
        (1, 2): _result([1, 0, 0], [0, 0, 5]),  # W D L
        (2, 2): _result([0], [0]),
    }
    table = table_from_results(("a", "b", "c"), results)
    assert table.mean[0, 1] == pytest.approx(0.625)
    assert table.mean[1, 0] == pytest.approx(0.375)
    assert table.std[0, 1] == table.std[1, 0] == pytest.approx(np.std([1, 0.5, 0, 1]))
    assert (table.wins[0, 1], table.draws[0, 1], table.losses[0, 1]) == (2, 1, 1)
    assert (table.wins[1, 0], table.draws[1, 0], table.losses[1, 0]) == (1, 1, 2)
    assert table.goals_for[1, 0] == pytest.approx(table.goals_against[0, 1]) == pytest.approx(
        1.25
    )
    assert table.mean[2, 0] == 1.0 and table.std[2, 0] == 0.0
    assert (table.wins[2, 0], table.losses[2, 0]) == (2, 0)
    # The diagonal is the home team's view of a team against itself.
    assert table.mean[0, 0] == pytest.approx(0.5)
    assert (table.wins[0, 0], table.draws[0, 0], table.losses[0, 0]) == (1, 2, 1)
    off = ~np.eye(3, dtype=bool)
    np.testing.assert_allclose((table.mean + table.mean.T)[off], 1.0)
    np.testing.assert_array_equal(table.games, [[4, 4, 2], [4, 2, 3], [2, 3, 1]])
    np.testing.assert_array_equal(table.wins + table.draws + table.losses, table.games)
    assert table.cell(0, 1) == "0.62±0.41"
    # Ratings read each match once: the upper triangle.
    counts = table.counts()
    assert counts.games.sum() == 4 + 2 + 3
    assert np.all(np.tril(counts.games) == 0)


def test_table_refuses_bad_keys() -> None:
    with pytest.raises(ValueError, match="result key"):
        table_from_results(("a", "b"), {(1, 0): _result([1], [0])})


def test_schedule_has_every_pair_once_and_self_play() -> None:
    assert schedule(3) == [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)]
    assert len(schedule(10)) == 55


def test_round_robin_plays_the_schedule_with_swapped_sides() -> None:
    calls = []

    def fake_play(env, params, home, away, key, num_games, **kwargs):
        calls.append((home.name, away.name, num_games, kwargs["swap_sides"],
                      kwargs["home_params"], jax.random.key_data(key).tolist()))
        return _result([1] * num_games, [0] * num_games)

    teams = [Team("r", RandomTeam(), params="p0"), Team("n", NaiveTeam(), params="p1")]
    env, params = elevens.make("1v1")
    key = jax.random.key(7)
    results = play_round_robin(teams, env, params, key, 6, play=fake_play)
    assert list(results) == [(0, 0), (0, 1), (1, 1)]
    assert [(h, a) for h, a, *_ in calls] == [("random", "random"), ("random", "naive"),
                                              ("naive", "naive")]
    assert all(c[2] == 6 and c[3] is True for c in calls)
    assert [c[4] for c in calls] == ["p0", "p0", "p1"]
    # Match m uses fold_in(key, m): distinct, reproducible keys.
    expected = [jax.random.key_data(jax.random.fold_in(key, m)).tolist() for m in range(3)]
    assert [c[5] for c in calls] == expected


# ------------------------------------------------------------------------------ team specs


def test_parse_team_specs() -> None:
    assert parse_team_spec("naive").handcrafted == "naive"
    labelled = parse_team_spec("best=teamwork")
    assert (labelled.name, labelled.handcrafted) == ("best", "teamwork")
    spec = parse_team_spec("runs/a@500")
    assert (str(spec.path), spec.iteration, spec.name) == ("runs/a", 500, "a@500")
    spec = parse_team_spec("runs/a/checkpoints")
    assert (spec.iteration, spec.name) == (None, "a")
    spec = parse_team_spec("22p=runs/b@12")
    assert (spec.name, spec.iteration) == ("22p", 12)
    for bad, message in (("", "empty"), ("runs/a@x", "whole number"), ("@3", "no checkpoint"),
                         ("a b=naive", "label")):
        with pytest.raises(ValueError, match=message):
            parse_team_spec(bad)
    with pytest.raises(FileNotFoundError, match="does not exist"):
        load_team("no/such/run")


def test_unique_names_and_size_check() -> None:
    teams = [Team("a", NaiveTeam()), Team("a", NaiveTeam()), Team("b", NaiveTeam())]
    assert unique_names(teams) == ["a", "a#2", "b"]
    feedforward = Team("ff", NaiveTeam(), trained_players=2, size_dependent=True, spec="runs/ff")
    check_team_size(feedforward, 2)
    with pytest.raises(ValueError, match="feedforward network"):
        check_team_size(feedforward, 11)


@pytest.fixture(scope="module")
def checkpoint_2v2(tmp_path_factory):
    """A freshly initialised 2 v 2 learner (a small network), saved as the trainer saves it
    (a TrainState in <run>/checkpoints/<iteration>), plus its bare policy variables."""
    from elevens.train.checkpoint import Checkpointer
    from elevens.train.config import make_config
    from elevens.train.learner import make_learner

    config = make_config(
        "2v2",
        **{
            "network.features": 16, "network.num_heads": 2, "network.lstm_features": 8,
            "network.lstm_layers": 1, "games_per_iteration": 4,
            "ppo.minibatch_size": 4, "run.eval_deterministic": True,
        },
    )
    state = make_learner(config.learner, config.learner.make_env()).init(jax.random.key(0))
    run = tmp_path_factory.mktemp("run")
    with Checkpointer(run / "checkpoints") as checkpointer:
        checkpointer.save(3, state, config.to_dict(), {"iteration": 3})
        checkpointer.save(7, state, config.to_dict(), {"iteration": 7})
    bare = tmp_path_factory.mktemp("bare")
    with Checkpointer(bare) as checkpointer:
        checkpointer.save(0, state.params.policy, config.to_dict())
    return run, bare, state


def test_checkpoint_loads_as_a_team_that_plays_11v11(checkpoint_2v2) -> None:
    run, bare, state = checkpoint_2v2
    policy, params = load_checkpoint_team(run / "checkpoints" / "3")
    leaves = jax.tree.leaves(params)
    for got, want in zip(leaves, jax.tree.leaves(state.params.policy), strict=True):
        np.testing.assert_array_equal(np.asarray(got), np.asarray(want))
    assert policy.deterministic  # the run's eval_deterministic
    assert policy.policy.features == 16

    team = load_team(f"{run}@7")
    assert (team.name, team.trained_players, team.size_dependent) == (f"{run.name}@7", 2, False)
    check_team_size(team, 11)
    # The policy's variables alone (not a TrainState) load too.
    _, bare_params = load_checkpoint_team(bare)
    assert jax.tree.structure(bare_params) == jax.tree.structure(params)
    with pytest.raises(FileNotFoundError, match="iteration 5"):
        load_checkpoint_team(run, 5)

    # Trained with 2 a side, it plays 11 a side: same params, 22 players.
    env, params_11 = elevens.make("11v11", episode_length=8)
    result = play_match(env, params_11, team.policy, NaiveTeam(), jax.random.key(1), 2,
                        home_params=team.params, record=True)
    assert result.record is not None
    assert result.record.actions.shape == (2, 8, 2, 11, 2)
    assert bool(jnp.all(jnp.isfinite(result.record.actions)))


# ------------------------------------------------------------------------------ end to end


def test_tournament_command_prints_and_writes_the_table(tmp_path, capsys) -> None:
    out = tmp_path / "tour"
    tournament = eval_main([
        "tournament", "random", "naive", "--games", "8", "--players", "1", "--steps", "60",
        "--out", str(out), "--bootstrap", "50",
    ])
    table = tournament.table
    assert table.names == ("random", "naive")
    np.testing.assert_array_equal(table.games, np.full((2, 2), 8))
    assert table.mean[0, 1] + table.mean[1, 0] == pytest.approx(1.0)
    printed = capsys.readouterr().out
    assert "Mean outcome" in printed and "Bradley-Terry" in printed
    assert table.cell(1, 0) in printed

    with (out / "table.csv").open() as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["team", "random", "naive"]
    assert rows[2][1] == table.cell(1, 0)
    saved = json.loads((out / "tournament.json").read_text())
    assert (saved["format"], saved["version"]) == ("elevens-tournament", 1)
    np.testing.assert_allclose(saved["mean"], table.mean)
    assert saved["wins"][1][0] == int(table.wins[1, 0])
    assert {row["team"] for row in saved["ratings"]["teams"]} == {"random", "naive"}
    with (out / "pairs.csv").open() as handle:
        pairs = list(csv.DictReader(handle))
    assert len(pairs) == 4
    for name in ("table.png", "outcomes.png", "ratings.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_12_value_teams_play_their_tournament_with_the_servers_bodies(tmp_path) -> None:
    tournament = eval_main([
        "tournament", "rcss_naive", "again=rcss_naive", "--games", "4", "--players", "1",
        "--steps", "60", "--out", str(tmp_path / "rcss"), "--bootstrap", "0",
        "--see-period", "3",
    ])
    assert tournament.table.names == ("rcss_naive", "again")
    # The same team on both sides of a mirrored field: each pair's outcomes sum to one.
    assert tournament.table.mean[0, 1] + tournament.table.mean[1, 0] == pytest.approx(1.0)
    with pytest.raises(ValueError, match="rcss_naive give the 12-value .* and naive the"):
        eval_main(["tournament", "naive", "rcss_naive", "--games", "2", "--players", "1",
                   "--out", str(tmp_path / "mixed")])


@pytest.mark.slow
def test_handcrafted_tournament_bar_11v11() -> None:
    # 3 handcrafted teams, 11 v 11, 500 games a pair (its speed is `elevens bench`'s, not a test's).
    from elevens.eval.tournament import run_tournament

    env, params = elevens.make("11v11")
    teams = [load_team(name) for name in ("random", "naive", "teamwork")]
    tournament = run_tournament(teams, env, params, num_games=500)
    mean = tournament.table.mean
    assert mean[1, 0] >= 0.95  # naive beats random
    assert mean[2, 1] > 0.55  # teamwork beats naive
    assert np.all(np.abs(np.diag(mean) - 0.5) < 0.05)
    assert tournament.ratings.order() == [2, 1, 0]
