"""skills_naive's host path on varied States of the proxy (partial world models, every mode):
each row is decided as in any batch, which lets the decision server decide each request on
its own as it comes (``runtime.rowwise``), and the trimmed numpy path decides as the plain
one did."""

from __future__ import annotations

import types
from typing import Any

import numpy as np
import pytest

from elevens.robocup.skills import naive
from elevens.robocup.skills.naive import SkillsNaive, skills_naive
from elevens.robocup.skills.observe import observe
from elevens.robocup.skills.runtime import is_rowwise
from elevens.robocup.skills.set_plays import TakerGuard
from elevens.robocup.skills.space import Kind, to_player_actions
from tests.robocup.fake_proxy import varied_cycle


def _cycles(count: int) -> list[list[Any]]:
    rng = np.random.default_rng(35)
    return [varied_cycle(rng, c + 1) for c in range(count)]


def test_each_row_is_decided_as_in_the_whole_batch_and_routines_skip_open_play() -> None:
    assert is_rowwise(skills_naive)
    rng = np.random.default_rng(7)
    kinds: set[int] = set()
    for states in _cycles(40):
        whole = skills_naive(states)
        alone = [skills_naive([s])[0] for s in states]
        cut = int(rng.integers(1, len(states)))
        split = skills_naive(states[:cut]) + skills_naive(states[cut:])
        assert whole == alone == split
        obs = observe(states)  # the full decision, open play decided for every row
        decisions = naive.skills_naive_decisions(obs)
        assert whole == to_player_actions(decisions, obs)
        kinds |= set(decisions.kind.tolist())
    # The scenes reach every kind but the rare SHOOT and HOLD (test_skills_naive's scenes)
    # and a set play's KICK: marking and passing or dribbling among them, the parts one
    # player's decision skips.
    assert kinds == set(Kind) - {Kind.SHOOT, Kind.HOLD, Kind.KICK, Kind.PLANNER, Kind.HELIOS_MOVE}


def test_deciding_our_set_plays_is_rowwise_and_only_our_set_plays_change() -> None:
    whole, alone, split = SkillsNaive(), SkillsNaive(), SkillsNaive()
    assert is_rowwise(whole)
    guard = TakerGuard()  # beside whole's: which rows the free-kick rule binds
    rng = np.random.default_rng(8)
    changed = 0
    for states in _cycles(40):
        answers = whole(states)
        cut = int(rng.integers(1, len(states)))
        parts = split(states[:cut]) + split(states[cut:])
        assert answers == [alone([s])[0] for s in states] == parts
        obs = observe(states)
        routine = to_player_actions(naive.skills_naive_decisions(obs), obs)
        ours = obs.our_set_play & np.isin(obs.mode, (3, 5)) & ~obs.goalie & ~obs.penalty
        bound = guard.takers(obs)
        for i, (got, want) in enumerate(zip(answers, routine, strict=True)):
            if ours[i]:
                assert got.actions[0].helios_set_play is None and got.ignore_doIntention
                changed += 1
            elif not bound[i]:
                assert got == want, i
    assert changed > 10


def test_the_trimmed_numpy_path_decides_as_the_plain_one() -> None:
    """numpy's path (one player at a time, parts without a row skipped, the sum of squares
    for np.linalg.norm) against the plain one: every part for a whole cycle, norms by
    ``np.linalg.norm``, the array code the jnp trace runs, here on numpy."""
    plain_np = types.SimpleNamespace(**{k: getattr(np, k) for k in dir(np) if k.isidentifier()})
    assert plain_np is not np and plain_np.linalg is np.linalg
    skipped = 0
    for states in _cycles(40):
        for s in states:
            s.world_model.game_mode_type = 2  # play on: the open play decision shows
        plain = naive.naive_choices(observe(states), plain_np)
        for i, s in enumerate(states):
            obs = observe([s])
            skipped += not obs.kickable.any()
            for got, want in zip(naive.naive_choices(obs), plain, strict=True):
                assert got.dtype == want.dtype
                np.testing.assert_array_equal(got, want[i:i + 1])
    assert skipped > 300  # most rows skip the ball's part


def test_skills_planner_hands_every_kick_to_helios_planner_and_nothing_else() -> None:
    """``skills_planner`` is ``skills_naive`` but for its open-play kicks: there the proxy gets
    helios-base's shot search, then its planner (helios's own evaluator), then a hold, with the
    proxy's reflexes on as helios's own players have them."""
    assert is_rowwise(naive.skills_planner)
    planned = 0
    for states in _cycles(40):
        decisions = naive.skills_naive_decisions(observe(states))
        for state, row, answer, base in zip(
                states, decisions.kind, naive.skills_planner(states), skills_naive(states),
                strict=True):
            if row not in (Kind.SHOOT, Kind.PASS, Kind.DRIBBLE, Kind.HOLD):
                assert answer == base
                continue
            planned += 1
            assert state.world_model.myself.is_kickable
            first, second, third = answer.actions[:3]
            assert first.helios_shoot is not None
            planner = second.helios_offensive_planner
            assert planner is not None and not planner.server_side_decision
            assert planner.lead_pass and planner.short_dribble and planner.cross
            assert third.body_hold_ball is not None
            assert not (answer.ignore_preprocess or answer.ignore_doforcekick
                        or answer.ignore_doIntention or answer.ignore_shootInPreprocess)
    assert planned > 0


def test_helios_parts_replace_exactly_the_open_play_moves_and_kicks() -> None:
    """``skills_helios_move`` hands every open-play move (INTERCEPT, GO_TO, MARK, TACKLE) to
    helios-base's basic move and keeps ``skills_naive``'s kicks; ``skills_helios_parts`` hands
    over both; the goalie, set plays and the kick-off placing stay the routines."""
    moves = (Kind.INTERCEPT, Kind.GO_TO, Kind.MARK, Kind.TACKLE)
    kicks = (Kind.SHOOT, Kind.PASS, Kind.DRIBBLE, Kind.HOLD)
    counted = {"move": 0, "kick": 0, "routine": 0}
    for states in _cycles(20):
        kinds = naive.skills_naive_decisions(observe(states)).kind
        base = skills_naive(states)
        parts = naive.SkillsPlanner(on_ball=True, off_ball=True)(states)
        moved = naive.SkillsPlanner(on_ball=False, off_ball=True)(states)
        for kind, b, p, m in zip(kinds, base, parts, moved, strict=True):
            if kind in moves:
                counted["move"] += 1
                assert p == m and p.actions[0].helios_basic_move is not None
                assert not p.ignore_doforcekick and not p.ignore_doIntention
            elif kind in kicks:
                counted["kick"] += 1
                assert m == b and p.actions[1].helios_offensive_planner is not None
            else:
                counted["routine"] += 1
                assert b == p == m
    assert min(counted.values()) > 0


def test_helios_parts_follow_librcscs_kickable_not_the_decided_kind() -> None:
    # A deferring learned player's kind comes from the simulator's skills_naive, which may
    # disagree with librcsc on who has the ball: helios-base's part goes by librcsc, as its
    # own players choose; routines and rows not taken stay.
    kinds = [Kind.GO_TO, Kind.PASS, Kind.DRIBBLE, Kind.INTERCEPT, Kind.GOALIE, Kind.GO_TO]
    kickable = np.array([True, False, True, False, True, False])
    rows = np.array([True, True, True, True, True, False])
    out = naive.helios_parts(naive.Decisions.of(np.array(kinds)), kickable, rows).kind
    assert out.tolist() == [Kind.PLANNER, Kind.HELIOS_MOVE, Kind.PLANNER, Kind.HELIOS_MOVE,
                            Kind.GOALIE, Kind.GO_TO]
    only_ball = naive.helios_parts(naive.Decisions.of(np.array(kinds)), kickable, off_ball=False)
    assert only_ball.kind.tolist() == [Kind.PLANNER, Kind.PASS, Kind.PLANNER, Kind.INTERCEPT,
                                       Kind.GOALIE, Kind.GO_TO]


def test_pressing_sends_only_near_players_at_their_ball_and_changes_nothing_else() -> None:
    """``skills_helios_press`` is ``skills_helios_parts`` but where ``pressing`` picks a
    player helios-base's basic move would have moved: there it runs at the ball. Pressing
    needs their ball, no teammate's, and a reach within ``press`` cycles of our fastest."""
    parts = naive.SkillsPlanner(on_ball=True, off_ball=True)
    press = naive.SkillsPlanner(on_ball=True, off_ball=True, press=3)
    assert is_rowwise(press)
    counted = {"pressed": 0, "same": 0}
    for states in _cycles(30):
        obs = observe(states)
        picked = naive.pressing(obs, 3)
        theirs = obs.kickable_opp | (obs.opp_reach < np.minimum(obs.self_reach, obs.mate_reach))
        assert not (picked & ~theirs).any() and not (picked & obs.kickable_mate).any()
        assert (obs.self_reach[picked] <= obs.mate_reach[picked] + 3).all()
        assert not (picked & obs.goalie).any()
        assert (naive.pressing(obs, 1) <= picked).all()  # fewer press with less slack
        for row, (p, q) in enumerate(zip(parts(states), press(states), strict=True)):
            if picked[row] and p.actions[0].helios_basic_move is not None:
                counted["pressed"] += 1
                assert q.actions[0].body_intercept is not None
            else:
                counted["same"] += 1
                assert p == q
    assert min(counted.values()) > 0
    with pytest.raises(ValueError, match="press=-1 is invalid"):
        naive.SkillsPlanner(on_ball=True, off_ball=True, press=-1)
    with pytest.raises(ValueError, match="press=2 is invalid"):
        naive.SkillsPlanner(on_ball=True, off_ball=False, press=2)
