"""Choosing among helios-base's planner chains (``GetBestPlannerAction``) against a fake proxy:
the candidates as the proxy sends them, helios-base's own choice by default, a team's
``choose_chain`` when it has one, and helios-base's choice in place of a failing chooser."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from elevens.robocup.skills import SKILLS
from elevens.robocup.skills.naive import SkillsPlanner, skills_naive
from elevens.robocup.skills.planner import Candidates, helios_best
from elevens.robocup.skills.runtime import DecisionServer
from tests.robocup.fake_proxy import FAKE, FakePlayer, Scene, state

# (index, parent, category, receiver, evaluation): a hold at the root, a pass to 9 and a
# dribble from it, a shot after the pass (the best chain: its first action is the pass).
_NODES = [(0, -1, 0, -1, 10.0), (1, -1, 2, 9, 20.0), (2, -1, 1, -1, 15.0), (3, 1, 3, -1, 40.0)]


def _pairs() -> dict[int, Any]:
    m = FAKE
    pairs = {}
    for index, parent, category, receiver, evaluation in _NODES:
        action = m.RpcCooperativeAction(
            category=category, index=index, sender_unum=10, target_unum=receiver,
            target_point=m.RpcVector2D(x=10.0 + index, y=-float(index)), first_ball_speed=2.5,
            duration_step=index, parent_index=parent,
        )
        predicted = m.RpcPredictState(
            spend_time=3 * index, ball_holder_unum=9 if index else 10,
            ball_position=m.RpcVector2D(x=float(index), y=1.0),
            ball_velocity=m.RpcVector2D(x=0.0, y=0.0), our_defense_line_x=-30.0,
            our_offense_line_x=5.0,
        )
        pairs[index] = m.RpcActionState(action=action, predict_state=predicted,
                                        evaluation=evaluation)
    return pairs


def _ask(player: FakePlayer) -> int:
    request = FAKE.BestPlannerActionRequest(register_response=player.response, pairs=_pairs())
    return int(player.client.GetBestPlannerAction(request).index)


def test_candidates_read_every_node_and_find_each_chains_first_action() -> None:
    c = Candidates.of(_pairs())
    assert c.index.tolist() == [0, 1, 2, 3] and c.parent.tolist() == [-1, -1, -1, 1]
    assert c.category.tolist() == [0, 2, 1, 3] and c.target_unum.tolist() == [-1, 9, -1, -1]
    assert c.target[3].tolist() == [13.0, -3.0] and c.steps.tolist() == [0, 3, 6, 9]
    assert c.holder.tolist() == [10, 9, 9, 9] and c.evaluation.tolist() == [10, 20, 15, 40]
    assert c.first_actions().tolist() == [0, 1, 2, 1]
    assert helios_best(10, c) == 3
    assert len(Candidates.of({})) == 0 and helios_best(10, Candidates.of(None)) == -1


def test_a_planner_team_asks_for_the_choice_only_when_it_chooses() -> None:
    scene = Scene(ball=(-30.0, 20.0), kickable=2, cycle=5)  # player 2 has the ball
    states = [state(scene, unum) for unum in range(1, 12)]
    for team, asks in ((SKILLS["skills_planner"]("routine"), False),
                       (SKILLS["skills_planner_ours"]("routine"), True)):
        planned = [a.actions[1].helios_offensive_planner for a in team(states)
                   if a.actions[0].helios_shoot is not None]
        assert len(planned) == 1 and planned[0].server_side_decision == asks
    with pytest.raises(ValueError, match="set_plays='decided' \\(allowed: 'routine'\\)"):
        SKILLS["skills_planner"]("decided")


@pytest.mark.parametrize("chooser", ["helios", "ours", "failing", "unknown node"])
def test_the_decision_server_answers_the_choosers_node(chooser: str) -> None:
    seen: list[tuple[int, list[int]]] = []

    def ours(unum: int, c: Candidates) -> int:
        seen.append((unum, c.index.tolist()))
        return int(c.index[np.argmin(c.evaluation)])  # the worst: not helios-base's

    decide = {"helios": skills_naive, "ours": SkillsPlanner(ours),
              "failing": SkillsPlanner(lambda u, c: 1 // 0),
              "unknown node": SkillsPlanner(lambda u, c: 99)}[chooser]
    with DecisionServer(decide) as server:
        player = FakePlayer(server.port, unum=7)
        try:
            index = _ask(player)
        finally:
            player.close()
        stats = server.stats()
    assert index == (0 if chooser == "ours" else 3)
    assert seen == ([(7, [0, 1, 2, 3])] if chooser == "ours" else [])
    assert (stats.chosen, stats.choice_errors) == (1, int(chooser in ("failing", "unknown node")))
