"""The chain chooser (``skills/chains.py``): each chain's features, helios-base's choice from
its starting weights, exploring with the probabilities it records, its file, the outcomes read
from a game log, and a fit that finds a planted preference; played through the decision
server against a fake proxy."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from elevens.robocup.rcg import MatchLog
from elevens.robocup.skills import check_skills_policy, skills_policy
from elevens.robocup.skills.chains import (
    FEATURES,
    GOAL_HORIZON,
    LABEL_HORIZON,
    ChainChooser,
    ChooserSpec,
    chain_features,
    fit_chooser,
    is_chooser,
    label_records,
    load_chooser,
    match_records,
    possession_values,
    save_chooser,
)
from elevens.robocup.skills.planner import Candidates, helios_best
from elevens.robocup.skills.runtime import DecisionServer
from tests.robocup.fake_proxy import FAKE, FakePlayer, Scene, state

COL = {name: i for i, name in enumerate(FEATURES)}


def _pairs(nodes: list[tuple[int, int, int, float, tuple[float, float]]]) -> dict[int, Any]:
    """(index, parent, category, evaluation, ball at the node) as the proxy sends them."""
    m = FAKE
    pairs = {}
    for index, parent, category, evaluation, ball in nodes:
        action = m.RpcCooperativeAction(
            category=category, index=index, sender_unum=10, target_unum=9 if category == 2 else -1,
            target_point=m.RpcVector2D(x=ball[0], y=ball[1]), first_ball_speed=1.5,
            duration_step=3, parent_index=parent)
        predicted = m.RpcPredictState(
            spend_time=4 * index, ball_holder_unum=9 if category == 2 else 10,
            ball_position=m.RpcVector2D(x=ball[0], y=ball[1]))
        pairs[index] = m.RpcActionState(action=action, predict_state=predicted,
                                        evaluation=evaluation)
    return pairs


# A dribble, a pass to 9 and, after the pass, a shot (the best evaluation).
_NODES = [(0, -1, 1, 30.0, (5.0, 0.0)), (1, -1, 2, 35.0, (20.0, 10.0)),
          (2, 1, 3, 50.0, (52.5, 0.0))]


def _random_candidates(rng: np.random.Generator, k: int) -> Candidates:
    nodes = [(i, int(rng.integers(-1, i)) if i else -1, int(rng.integers(0, 4)),
              float(rng.normal(0, 5)), (float(rng.uniform(-50, 50)), float(rng.uniform(-30, 30))))
             for i in range(k)]
    return Candidates.of(_pairs(nodes))


def test_features_of_a_search_seen_from_the_asking_player() -> None:
    scene = Scene(ball=(0.0, 0.0), kickable=10, cycle=77)
    scene.theirs[:] = 100.0
    scene.theirs[3] = (20.0, 13.0)  # 3 m from the pass's end
    c = Candidates.of(_pairs(_NODES), state(scene, 10))
    assert c.situation is not None and c.situation.cycle == 77 and c.situation.left
    phi = chain_features(c, unum=10)
    assert phi.shape == (3, len(FEATURES))
    np.testing.assert_allclose(phi[:, COL["evaluation"]], [-2.0, -1.5, 0.0])
    assert phi[:, COL["first_dribble"]].tolist() == [1, 0, 0]
    assert phi[:, COL["first_pass"]].tolist() == [0, 1, 1]  # the shot's chain starts with it
    assert phi[:, COL["last_shoot"]].tolist() == [0, 0, 1]
    np.testing.assert_allclose(phi[:, COL["depth"]] * 3, [1, 1, 2])
    np.testing.assert_allclose(phi[:, COL["gain_x"]] * 52.5, [5.0, 20.0, 52.5], rtol=1e-6)
    np.testing.assert_allclose(phi[1, COL["end_opponent_distance"]], 0.3, rtol=1e-5)
    assert phi[:, COL["end_opponents_near"]].tolist() == pytest.approx([0, 1 / 3, 0])
    assert phi[:, COL["passed"]].tolist() == [0, 1, 0]  # the shot's holder is 10 again here
    # Without the state: the ball at the centre, no opponent seen.
    bare = chain_features(Candidates.of(_pairs(_NODES)), unum=10)
    assert bare[:, COL["end_opponent_distance"]].tolist() == [2.0, 2.0, 2.0]
    # A chain helios rules out (-inf, as a lone hold came in a match) is far below, not NaN.
    ruled_out = [(0, -1, 0, -np.inf, (5.0, 0.0))]
    assert chain_features(Candidates.of(_pairs(ruled_out)))[0, COL["evaluation"]] == -10.0
    mixed = chain_features(Candidates.of(_pairs([*_NODES[:2], (2, 1, 3, -np.inf, (9.0, 0.0))])))
    np.testing.assert_allclose(mixed[:, COL["evaluation"]], [-0.5, 0.0, -10.0])


def test_the_starting_weights_choose_as_helios_base_does() -> None:
    rng = np.random.default_rng(0)
    chooser = ChainChooser(ChooserSpec())
    for _ in range(200):
        c = _random_candidates(rng, int(rng.integers(1, 12)))
        assert chooser(10, c) == helios_best(10, c)
    assert chooser(10, Candidates.of({})) == -1


def test_exploring_plays_the_top_k_uniformly_and_records_each_choice(tmp_path: Path) -> None:
    rng = np.random.default_rng(1)
    searches = [_random_candidates(rng, 8) for _ in range(400)]
    spec = ChooserSpec(explore=0.5, top_k=3, seed=4, record_dir=str(tmp_path))
    chooser = ChainChooser(spec)
    picks = [chooser(10, c) for c in searches]
    again = ChainChooser(ChooserSpec(explore=0.5, top_k=3, seed=4))
    assert [again(10, c) for c in searches] == picks  # a seed replays its choices
    rank = [int(np.flatnonzero(np.argsort(-c.evaluation, kind="stable") ==
                               np.flatnonzero(c.index == pick)[0])[0])
            for c, pick in zip(searches, picks, strict=True)]
    counts = np.bincount(rank, minlength=8)
    assert counts[3:].sum() == 0  # never outside the top 3
    assert 0.5 + 0.5 / 3 - 0.08 < counts[0] / 400 < 0.5 + 0.5 / 3 + 0.08
    records = [json.loads(line) for f in tmp_path.glob("chains-*.jsonl")
               for line in f.read_text().splitlines()]
    assert len(records) == 400
    assert [r["chosen"] for r in records] == rank
    expected_p = [(0.5 + 0.5 / 3) if r["chosen"] == r["greedy"] else 0.5 / 3 for r in records]
    assert [r["p"] for r in records] == pytest.approx(expected_p, abs=1e-6)
    assert all(np.asarray(r["features"]).shape == (3, len(FEATURES)) for r in records)


def test_a_chooser_file_round_trips_and_bad_ones_say_why(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    spec = ChooserSpec(weights=tuple(np.arange(len(FEATURES)) * 0.5), top_k=5, explore=0.2)
    save_chooser(path, spec)
    assert is_chooser(str(path)) and load_chooser(path) == spec
    check_skills_policy(str(path))
    body = json.loads(path.read_text())
    for change, message in (({"format": "x"}, "is not a chain chooser"),
                            ({"features": ["evaluation"]}, "other features"),
                            ({"explore": 2.0}, "explore 2.0 is invalid"),
                            ({"weights": [1.0]}, "weights has 1 values")):
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps({**body, **change}))
        with pytest.raises(ValueError, match=message):
            load_chooser(bad)
    assert not is_chooser(str(tmp_path / "missing.json")) and not is_chooser("skills_naive")


def test_the_decision_server_plays_a_chooser_file(tmp_path: Path) -> None:
    # Weights that prefer the dribble's chain to helios's best (the pass, then the shot).
    weights = np.zeros(len(FEATURES))
    weights[COL["first_dribble"]] = 10.0
    path = tmp_path / "dribble.json"
    save_chooser(path, ChooserSpec(weights=tuple(weights), record_dir=str(tmp_path)))
    decide = skills_policy(str(path))
    scene = Scene(ball=(0.0, 0.0), kickable=10, cycle=9)
    with DecisionServer(decide) as server:
        player = FakePlayer(server.port, unum=10)
        try:
            request = FAKE.BestPlannerActionRequest(
                register_response=player.response, pairs=_pairs(_NODES), state=state(scene, 10))
            index = int(player.client.GetBestPlannerAction(request).index)
        finally:
            player.close()
        assert (server.stats().chosen, server.stats().choice_errors) == (1, 0)
    assert index == 0
    (record,) = [json.loads(line) for line in next(tmp_path.glob("chains-*.jsonl")).open()]
    assert (record["cycle"], record["left"], record["unum"], record["chosen"]) == (9, True, 10, 2)


def _log(goals: list[tuple[int, str]], touches: list[tuple[int, int]], n: int = 1000) -> MatchLog:
    """A game of ``n`` cycles, one show each, the ball at x = cycle / 10 - 50 (left frame)."""
    cycle = np.arange(n)
    ball = np.stack([cycle / 10.0 - 50.0, np.zeros(n)], axis=1)
    modes = [(0, "play_on")] + [(c, m) for c, m in goals]
    return MatchLog(
        path="x.rcg", names=("elevens", "HELIOS_base"), score=(0, 0), cycle=cycle, ball=ball,
        pos=np.zeros((n, 2, 11, 2)), stamina=np.zeros((n, 2, 11)),
        capacity=np.zeros((n, 2, 11)),
        touches=np.array([(s, side, 10) for s, side in touches], np.int64).reshape(-1, 3),
        playmodes=tuple(modes), playmode_shows=(0, *(c for c, _ in goals)),
    )


def test_possession_values_and_outcomes_from_a_game_log() -> None:
    log = _log(goals=[(600, "goal_l"), (900, "goal_kick_r")],
               touches=[(100, 0), (400, 1), (500, 0)])
    values = possession_values([log], "elevens")
    # Shows 300..599 come within GOAL_HORIZON of our goal; x bins of 8.75 m, from -52.5.
    x, last = log.ball[:, 0], np.zeros(1000, int)
    last[100:], last[400:], last[500:] = 1, 2, 1
    goal = ((np.arange(1000) < 600) & (np.arange(1000) >= 600 - GOAL_HORIZON)).astype(float)
    bins = np.clip(((x + 52.5) / 105 * 12).astype(int), 0, 11)
    for b, t in {(int(b), int(t)) for b, t in zip(bins, last, strict=True)}:
        cell = (bins == b) & (last == t)
        assert values[b, t] == pytest.approx(goal[cell].mean())
    # From the right side's view the same goal is theirs, and its x is mirrored.
    assert possession_values([log], "HELIOS_base").min() < 0
    records = [{"cycle": 200}, {"cycle": 580}, {"cycle": 5000}]
    y = label_records(records, log, "elevens", values)
    v = values[bins, last]
    assert y[0] == pytest.approx(v[200 + LABEL_HORIZON] - v[200])
    assert y[1] == pytest.approx(1.0 - v[580])  # the goal at 600 comes first
    assert np.isnan(y[2])


def _explored(rng: np.random.Generator, feats: np.ndarray, explore: float) -> dict[str, Any]:
    """The record of an exploring chooser's choice among ``feats``' rows (helios's: row 0)."""
    chosen = int(rng.integers(len(feats))) if rng.random() < explore else 0
    p = (1 - explore) * (chosen == 0) + explore / len(feats)
    return {"features": feats.tolist(), "chosen": chosen, "greedy": 0, "p": p}


def test_a_fit_finds_a_planted_preference_and_estimates_it_held_out() -> None:
    rng = np.random.default_rng(2)
    explore, k = 0.4, 3
    matches = []
    for _ in range(4):
        records, labels = [], []
        for _ in range(600):
            feats = rng.normal(0, 1, (k, len(FEATURES))) * 0.3
            feats[:, COL["evaluation"]] = -np.arange(k) * 0.1  # helios's order: row 0 first
            feats[:, COL["first_shoot"]] = rng.random(k) < 0.3
            records.append(_explored(rng, feats, explore))
            labels.append(feats[records[-1]["chosen"], COL["first_shoot"]] + rng.normal(0, 0.5))
        # One record of an older chooser, whose ruled-out chain gave a NaN feature: dropped.
        records.append({"features": [[np.nan] * len(FEATURES)], "chosen": 0, "greedy": 0, "p": 1})
        labels.append(0.0)
        matches.append((records, np.asarray(labels)))
    report = fit_chooser(matches)
    assert report.weights[COL["first_shoot"]] > 0.5 and report.records == 2400
    assert report.matches == 4 and report.agreement < 0.9
    assert report.fitted[0] - 2 * report.fitted[1] > report.helios[0] + 2 * report.helios[1]
    assert report.gain[0] > 3 * report.gain[1]
    assert report.gain[0] == pytest.approx(report.fitted[0] - report.helios[0])
    # A margin above every predicted gain plays helios's choice, and gains nothing.
    cautious = fit_chooser(matches, margin=10.0)
    assert cautious.agreement == 1.0 and cautious.gain == (0.0, 0.0)
    with pytest.raises(ValueError, match="no labelled record"):
        fit_chooser([(matches[0][0], np.full(len(matches[0][0]), np.nan))])


def test_a_feature_that_marks_the_moment_not_the_choice_earns_no_weight() -> None:
    # Where the ball is well placed every row's end_x is high and so is the outcome, and
    # helios's choice (row 0, played most) has the highest end_x: a regression on the chosen
    # row's features alone credits end_x; the choice itself changes nothing.
    rng = np.random.default_rng(3)
    explore, k = 0.3, 4
    matches = []
    for _ in range(3):
        records, labels = [], []
        for _ in range(800):
            moment = rng.normal(0, 1)
            feats = np.zeros((k, len(FEATURES)))
            feats[:, COL["evaluation"]] = -np.arange(k) * 0.1
            feats[:, COL["end_x"]] = moment + np.linspace(0.3, 0, k) + rng.normal(0, 0.1, k)
            records.append(_explored(rng, feats, explore))
            labels.append(moment + rng.normal(0, 0.2))
        matches.append((records, np.asarray(labels)))
    report = fit_chooser(matches, l2=1.0)
    assert abs(report.weights[COL["end_x"]]) < 0.15
    assert abs(report.gain[0]) < 3 * report.gain[1] + 0.02


def test_a_margin_keeps_helios_choice_unless_another_scores_that_much_more() -> None:
    c = Candidates.of(_pairs(_NODES))  # evaluations 30, 35, 50: helios plays the shot (2)
    weights = np.zeros(len(FEATURES))
    weights[COL["last_pass"]] = 1.0  # the pass (1) scores 1, the others 0
    assert ChainChooser(ChooserSpec(weights=tuple(weights), top_k=3))(10, c) == 1
    assert ChainChooser(ChooserSpec(weights=tuple(weights), top_k=3, margin=0.5))(10, c) == 1
    assert ChainChooser(ChooserSpec(weights=tuple(weights), top_k=3, margin=1.0))(10, c) == 2
    with pytest.raises(ValueError, match="margin -1.0 is invalid"):
        ChooserSpec(margin=-1.0)


def test_match_folders_need_records_and_one_game_log(tmp_path: Path) -> None:
    (tmp_path / "m1").mkdir()
    (tmp_path / "m1" / "chains-1.jsonl").write_text('{"cycle": 1}\n')
    with pytest.raises(ValueError, match="1 record files and 0 game logs"):
        match_records([str(tmp_path / "m1")])
    (tmp_path / "m1" / "a.rcg").write_text("ULG5\n")
    ((records, log),) = match_records([str(tmp_path / "m1")])
    assert records == [{"cycle": 1}] and log.name == "a.rcg"
