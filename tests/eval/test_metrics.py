"""Table 6.4's metrics on hand-built trajectories with known answers, the team's own frame, and
the per-player position heat maps."""

from __future__ import annotations

import jax
import numpy as np
import pytest

import elevens
from elevens.eval.heatmap import plot_heatmaps, position_histograms, slot_roles, spawn_points
from elevens.eval.match import MatchRecord, MatchResult, play_match
from elevens.eval.metrics import (
    METRIC_NAMES,
    compute_metrics,
    per_step_values,
    print_metrics,
    save_metrics,
    team_trajectories,
)
from elevens.teams.scripted import NaiveTeam, RandomTeam


def _hand_built() -> MatchResult:
    """Two games of 2 v 2, two steps each. The home team plays side 0 in game 0 and side 1 in
    game 1 (where the world is point-reflected for it). In its own frame, in both games and at
    both steps, its players stand at (-40, 0) and (-40, 6) (world (40, 0), (40, -6) in game 1);
    the ball is at (-40, 3) in game 0 and (-40, -3) in game 1 (own frame). Own goal: (-50, 0).
    The away team stands far off at world (0, +-30)."""
    positions = np.zeros((2, 2, 4, 2), np.float32)
    home_own = np.array([[-40.0, 0.0], [-40.0, 6.0]])
    away_world = np.array([[0.0, 30.0], [0.0, -30.0]])
    positions[0, :, 0:2] = home_own  # side 0: world = own frame
    positions[0, :, 2:4] = away_world
    positions[1, :, 2:4] = -home_own  # side 1: world = -own
    positions[1, :, 0:2] = away_world
    ball = np.zeros((2, 2, 2), np.float32)
    ball[0] = [-40.0, 3.0]
    ball[1] = [40.0, 3.0]  # own frame (-40, -3)
    actions = np.zeros((2, 2, 2, 2, 2), np.float32)  # [G, T, side, player, (move, rot)]
    home_actions = np.array([[0.5, 1.0], [-1.0, -0.25]])
    actions[0, :, 0] = home_actions
    actions[1, :, 1] = home_actions
    actions[0, :, 1] = [[0.1, 0.0], [0.1, 0.0]]  # the away team's, never read for home
    actions[1, :, 0] = [[0.1, 0.0], [0.1, 0.0]]
    record = MatchRecord(
        positions=positions,
        headings=np.zeros((2, 2, 4), np.float32),
        ball_position=ball,
        ball_velocity=np.zeros((2, 2, 2), np.float32),
        score=np.zeros((2, 2, 2), np.int32),
        actions=actions,
    )
    return MatchResult(
        goals_for=np.array([2, 0]), goals_against=np.array([1, 1]),
        outcome=np.array([1.0, 0.0]), home_side=np.array([0, 1]), record=record,
    )


def test_metrics_by_hand() -> None:
    env, params = elevens.make("2v2")
    metrics = compute_metrics(_hand_built(), params, team_name="home", opponent_name="away")
    stats = metrics.stats
    assert set(stats) == set(METRIC_NAMES)
    assert (metrics.games, metrics.players_per_team) == (2, 2)
    # |move| in m/step: 0.5 and 1 each step -> 0.75 +- 0.25, the same in every game.
    assert (stats["move"].mean, stats["move"].std, stats["move"].game_std) == pytest.approx(
        (0.75, 0.25, 0.0))
    # |rot| * 0.4 rad/step: 0.4 and 0.1.
    assert (stats["rotation"].mean, stats["rotation"].std) == pytest.approx((0.25, 0.15))
    # Ball distances: game 0 (3, 3) at each step, game 1 (3, 9): pooled 4.5, std sqrt(6.75);
    # game means 3 and 6 -> game std 1.5.
    ball = stats["ball_distance"]
    assert (ball.mean, ball.std, ball.game_std) == pytest.approx((4.5, np.sqrt(6.75), 1.5))
    assert (stats["team_distance"].mean, stats["team_distance"].std) == pytest.approx((6.0, 0.0))
    assert (stats["closest_to_ball"].mean, stats["closest_to_ball"].std) == pytest.approx(
        (3.0, 0.0))
    # In the team's own frame the nearest player is 10 m from its goal in both games; read in
    # the world frame, game 1 would give 90 m.
    assert (stats["closest_to_goal"].mean, stats["closest_to_goal"].std) == pytest.approx(
        (10.0, 0.0))
    outcome = stats["outcome"]
    assert (outcome.mean, outcome.std, outcome.game_std) == pytest.approx((0.5, 0.5, 0.5))


def test_away_view_and_own_frame() -> None:
    env, params = elevens.make("2v2")
    result = _hand_built()
    home = team_trajectories(result, "home")
    np.testing.assert_allclose(home.positions[1, 0], [[-40.0, 0.0], [-40.0, 6.0]])
    np.testing.assert_allclose(home.ball[1, 0], [-40.0, -3.0])
    away = team_trajectories(result, "away")
    np.testing.assert_allclose(away.outcome, [0.0, 1.0])
    # The away team was on side 1 in game 0: its world (0, +-30) is (0, -+30) in its frame.
    np.testing.assert_allclose(away.positions[0, 0], [[0.0, -30.0], [0.0, 30.0]])
    np.testing.assert_allclose(away.actions[0, 0], [[0.1, 0.0], [0.1, 0.0]])
    stats = compute_metrics(result, params, team="away").stats
    assert stats["team_distance"].mean == pytest.approx(60.0)
    assert stats["move"].mean == pytest.approx(0.1)
    with pytest.raises(ValueError, match="record=True"):
        compute_metrics(MatchResult(*[np.zeros(1)] * 4), params)


def test_team_distance_of_a_team_of_one_is_nan() -> None:
    env, params = elevens.make("1v1")
    result = MatchResult(
        goals_for=np.zeros(1), goals_against=np.zeros(1), outcome=np.full(1, 0.5),
        home_side=np.zeros(1, np.int64),
        record=MatchRecord(
            positions=np.zeros((1, 3, 2, 2)), headings=np.zeros((1, 3, 2)),
            ball_position=np.ones((1, 3, 2)), ball_velocity=np.zeros((1, 3, 2)),
            score=np.zeros((1, 3, 2), np.int32), actions=np.zeros((1, 3, 2, 1, 2)),
        ),
    )
    stats = compute_metrics(result, params).stats
    assert np.isnan(stats["team_distance"].mean)
    assert stats["ball_distance"].mean == pytest.approx(np.sqrt(2))


def test_random_team_matches_the_uniform_distribution(tmp_path, capsys) -> None:
    # The random team's actions are U(-1, 1): |U| has mean 1/2 and std 1/sqrt(12) (thesis table
    # 6.4: move 0.50 +- 0.29, rotation 0.20 +- 0.12 rad/step). Same compile as test_match's
    # record test (2 v 2, 40 steps, 6 games).
    env, params = elevens.make("2v2", episode_length=40)
    result = play_match(env, params, RandomTeam(), NaiveTeam(), jax.random.key(4), 6,
                        record=True)
    rows = [compute_metrics(result, params, team_name="random", opponent_name="naive"),
            compute_metrics(result, params, team="away", team_name="naive",
                            opponent_name="random")]
    move, rotation = rows[0].stats["move"], rows[0].stats["rotation"]
    assert move.mean == pytest.approx(0.5, abs=0.03)
    assert move.std == pytest.approx(1 / np.sqrt(12), abs=0.02)
    assert rotation.mean == pytest.approx(0.2, abs=0.015)
    assert rows[1].stats["outcome"].mean == pytest.approx(1 - rows[0].stats["outcome"].mean)
    values = per_step_values(team_trajectories(result), params)
    assert values["team_distance"].shape == (6, 40, 1)
    assert values["closest_to_ball"].shape == (6, 40, 1)

    print_metrics(rows)
    printed = capsys.readouterr().out
    assert "Closest to goal" in printed and "random" in printed
    paths = save_metrics(rows, tmp_path / "metrics")
    lines = paths["csv"].read_text().splitlines()
    assert lines[0] == "team,opponent,metric,unit,mean,std,game_std,games"
    assert len(lines) == 1 + 2 * len(METRIC_NAMES)


# ------------------------------------------------------------------------------ heat maps


def test_position_histograms_are_probabilities() -> None:
    env, params = elevens.make("2v2")
    positions = np.zeros((3, 5, 2, 2))
    positions[..., 0, :] = [-49.0, 1.0]  # player 0 always in one cell
    positions[..., 1, 0] = np.linspace(-45, 45, 5)  # player 1 walks along the x axis
    histograms, x_edges, y_edges = position_histograms(positions, params, cell=2.0)
    assert histograms.shape == (2, 50, 35)
    np.testing.assert_allclose(histograms.sum(axis=(1, 2)), 1.0)
    assert histograms[0, 0, 18] == 1.0  # x in [-50, -48), y in [1, 3)
    assert np.count_nonzero(histograms[1]) == 5
    assert (x_edges[0], x_edges[-1], y_edges[0], y_edges[-1]) == (-50, 50, -35, 35)


def test_spawn_points_and_roles() -> None:
    _, params = elevens.make("11v11")
    np.testing.assert_allclose(spawn_points(params)[0], [-49.5, 0.0])
    assert slot_roles(11)[:2] == ["keeper", "defender"] and slot_roles(11)[-1] == "attacker"
    _, small = elevens.make("2v2", field_length=50.0, field_width=35.0, goal_width=20.0)
    np.testing.assert_allclose(spawn_points(small), [[-24.75, 0.0], [-5.5, 0.0]])


def test_heatmap_png(tmp_path) -> None:
    _, params = elevens.make("5v5")
    positions = np.random.default_rng(0).normal(scale=10, size=(4, 30, 5, 2))
    path = plot_heatmaps(positions, params, tmp_path / "heat.png", title="test")
    from PIL import Image

    with Image.open(path) as image:
        width, height = image.size
    assert width > 600 and height > 300


def test_teams_of_one_analysis_share_a_colour_scale_with_whole_team_and_ball_panels(
    tmp_path,
) -> None:
    from elevens.eval.heatmap import colour_top, position_histograms

    _, params = elevens.make("2v2")
    rng = np.random.default_rng(1)
    spread = rng.normal(scale=20, size=(4, 50, 2, 2))
    tight = rng.normal(scale=2, size=(4, 50, 2, 2))
    histograms = [position_histograms(p, params)[0] for p in (spread, tight)]
    top = colour_top(histograms)
    # The shared top lies between the two teams' own tops: one scale, not two.
    assert colour_top(histograms[:1]) < top <= colour_top(histograms[1:])
    ball = rng.normal(scale=10, size=(4, 50, 2))
    with_ball = plot_heatmaps(spread, params, tmp_path / "a.png", title="t", ball=ball, top=top,
                              shared_with=2)
    without = plot_heatmaps(spread, params, tmp_path / "b.png", title="t", top=top)
    from PIL import Image

    # 2 slots + whole team + ball fill one row of 4 panels; without the ball, 3.
    with Image.open(with_ball) as a, Image.open(without) as b:
        assert a.size[0] > b.size[0]


def test_analyze_command_writes_metrics_heatmaps_and_replays(tmp_path, capsys) -> None:
    import json

    from elevens.cli.eval import main as eval_main
    from elevens.eval.replay import load_replay

    out = tmp_path / "analysis"
    rows = eval_main(["analyze", "random", "teamwork", "--against", "naive", "--players", "2",
                      "--steps", "40", "--games", "6", "--replays", "2", "--out", str(out)])
    assert [(row.team, row.opponent, row.games) for row in rows] == [
        ("random", "naive", 6), ("teamwork", "naive", 6)
    ]
    assert "Gameplay metrics against naive" in capsys.readouterr().out
    saved = json.loads((out / "metrics.json").read_text())
    assert saved["teams"][0]["metrics"]["move"]["mean"] == pytest.approx(
        rows[0].stats["move"].mean)
    for team in ("random", "teamwork"):  # named by the opponent too
        assert (out / f"heatmap_{team}_vs_naive.png").read_bytes()[:4] == b"\x89PNG"
    replay = load_replay(out / "replays" / "random" / "game_0001.npz")
    assert replay.team_names == ("random", "naive") and replay.num_steps == 40
    assert not (out / "replays" / "random" / "game_0002.npz").exists()


def _touch_game() -> MatchResult:
    """Two 2 v 2 games of 10 steps, home on side 0, with touches placed by hand."""
    g, t, n = 2, 10, 2
    kicks = np.zeros((g, t, 2 * n), bool)
    pushes = np.zeros((g, t, 2 * n), bool)
    ball = np.zeros((g, t, 2), np.float32)
    velocity = np.zeros((g, t, 2), np.float32)
    score = np.zeros((g, t, 2), np.int32)
    # Game 0: home 0 kicks backwards (t 1); home 1 touches it (t 3): a pass. Home 1 kicks at
    # goal from (40, 0) at 3 m/step (t 4): on target. Away 0 touches (t 6); both teams touch
    # (t 8): contested.
    kicks[0, 1, 0] = True
    velocity[0, 2] = [-2.0, 0.0]
    pushes[0, 3, 1] = True
    kicks[0, 4, 1] = True
    ball[0, 5], velocity[0, 5] = [40.0, 0.0], [3.0, 0.0]
    pushes[0, 6, 2] = True
    pushes[0, 8, [0, 3]] = True
    # Game 1: home 0 kicks wide (t 2: aimed past the post), the ball goes in off a wall: the
    # home team scores in step 3 (score from t 4), before anyone else touches it.
    kicks[1, 2, 0] = True
    ball[1, 3], velocity[1, 3] = [45.0, 0.0], [1.0, 5.0]
    score[1, 4:, 0] = 1
    record = MatchRecord(
        positions=np.zeros((g, t, 2 * n, 2), np.float32),
        headings=np.zeros((g, t, 2 * n), np.float32), ball_position=ball,
        ball_velocity=velocity, score=score, actions=np.zeros((g, t, 2, n, 2), np.float32),
        kicks=kicks, pushes=pushes,
    )
    return MatchResult(
        goals_for=np.array([0, 1]), goals_against=np.array([0, 0]),
        outcome=np.array([0.5, 1.0]), home_side=np.array([0, 0]), record=record,
    )


def test_possession_passes_shots_and_goals_on_hand_built_games() -> None:
    _, params = elevens.make("2v2")
    values = per_step_values(team_trajectories(_touch_game()), params)
    # Game 0: the home team holds steps 1-5, the away team 6-7: 5 of 7 possessed steps.
    np.testing.assert_allclose(values["possession"][:, 0], [5 / 7, 1.0])
    np.testing.assert_array_equal(values["passes"][:, 0], [1, 0])
    np.testing.assert_array_equal(values["shots_on_target"][:, 0], [1, 1])
    np.testing.assert_array_equal(values["goals"][:, 0], [0, 1])
    # The away team's view of game 0: 2 of 7 steps, no pass, no shot.
    away = per_step_values(team_trajectories(_touch_game(), "away"), params)
    np.testing.assert_allclose(away["possession"][0, 0], 2 / 7)
    assert away["passes"][0, 0] == 0 and away["shots_on_target"][0, 0] == 0


def test_statistics_of_real_games_add_up() -> None:
    env, params = elevens.make("2v2", episode_length=60)
    result = play_match(env, params, NaiveTeam(), RandomTeam(), jax.random.key(3), 8,
                        record=True)
    home = per_step_values(team_trajectories(result), params)
    away = per_step_values(team_trajectories(result, "away"), params)
    shares = home["possession"][:, 0] + away["possession"][:, 0]
    np.testing.assert_allclose(shares[np.isfinite(shares)], 1.0)  # the two shares complement
    np.testing.assert_array_equal(home["goals"][:, 0], np.asarray(result.goals_for))
    # Nearly every goal the record holds follows a shot on target (the exceptions: the random
    # team's own goals, as in game 0, where its push at step 37 was the last touch).
    score = np.asarray(result.record.score)  # [G, T, 2], the home team on side 0 first
    recorded = np.where(np.asarray(result.home_side) == 0, score[:, -1, 0], score[:, -1, 1])
    assert home["shots_on_target"].sum() >= 0.75 * recorded.sum() > 0
    # The naive team chases the ball: it holds it more than the random team does.
    assert np.nanmean(home["possession"]) > 0.5
