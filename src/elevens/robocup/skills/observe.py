"""The players' States of one cycle as arrays: one row per deciding player, teammates and
opponents in slots by shirt number, so a policy decides all of them in one vectorised call.

Coordinates are librcsc's (metres; our team attacks towards +x on either side of the field);
angles are degrees. A slot whose player this player's world model does not place is invalid
(``mates_valid`` / ``opps_valid`` false, position, velocity and body zero). The player's own
slot in ``mates`` holds itself and is valid.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ["PLAYERS", "Observation", "observe"]

#: Shirt numbers 1..11.
PLAYERS = 11


@dataclasses.dataclass(frozen=True)
class Observation:
    """Arrays over ``n`` deciding players (the leading axis)."""

    unum: np.ndarray  # int32 [n], 1..11
    goalie: np.ndarray  # bool [n]
    kickable: np.ndarray  # bool [n]
    pos: np.ndarray  # float32 [n, 2]
    vel: np.ndarray  # float32 [n, 2]
    body: np.ndarray  # float32 [n], degrees
    stamina: np.ndarray  # float32 [n]
    tackle_probability: np.ndarray  # float32 [n]
    ball: np.ndarray  # float32 [n, 2]
    ball_vel: np.ndarray  # float32 [n, 2]
    ball_pos_count: np.ndarray  # int32 [n], cycles since the ball was seen
    mates: np.ndarray  # float32 [n, 11, 2], by shirt number
    mates_valid: np.ndarray  # bool [n, 11]
    opps: np.ndarray  # float32 [n, 11, 2]
    opps_valid: np.ndarray  # bool [n, 11]
    mates_vel: np.ndarray  # float32 [n, 11, 2], as the world model estimates it
    opps_vel: np.ndarray  # float32 [n, 11, 2]
    mates_body: np.ndarray  # float32 [n, 11], degrees (librcsc's estimate; 0 if never seen)
    opps_body: np.ndarray  # float32 [n, 11]
    opp_goalie: np.ndarray  # int32 [n], their goalie's shirt number (0: unknown)
    self_reach: np.ndarray  # int32 [n], intercept table: cycles for this player to the ball
    mate_reach: np.ndarray  # int32 [n], for the fastest other teammate
    opp_reach: np.ndarray  # int32 [n], for the fastest opponent
    kickable_mate: np.ndarray  # bool [n], a teammate (not this player) can kick the ball
    kickable_opp: np.ndarray  # bool [n]
    offside_x: np.ndarray  # float32 [n]
    mode: np.ndarray  # int32 [n], the proxy's GameModeType
    our_set_play: np.ndarray  # bool [n]
    last_kicker: np.ndarray  # int32 [n], shirt number if one of ours kicked last, else 0
    penalty: np.ndarray  # bool [n], penalty shoot-out modes
    cycle: np.ndarray  # int32 [n]
    stopped: np.ndarray  # int32 [n], cycles the clock has stood still
    need_preprocess: np.ndarray  # bool [n]

    def __len__(self) -> int:
        return int(self.unum.shape[0])


def _xy(v: Any) -> tuple[float, float]:
    return (0.0, 0.0) if v is None else (float(v.x or 0.0), float(v.y or 0.0))


def _slots(players: Sequence[Any] | None, pos: np.ndarray, valid: np.ndarray, vel: np.ndarray,
           body: np.ndarray) -> None:
    for p in players or ():
        k = int(p.uniform_number or 0)
        if 1 <= k <= PLAYERS:
            pos[k - 1] = _xy(p.position)
            valid[k - 1] = True
            vel[k - 1] = _xy(p.velocity)
            body[k - 1] = p.body_direction or 0.0


def observe(states: Sequence[Any]) -> Observation:
    """Arrays from the proxy's ``State`` messages (one per deciding player). A State with no
    world model or a shirt number outside 1..11 is a ValueError naming it."""
    n = len(states)
    f = np.zeros
    out: dict[str, np.ndarray] = {
        "unum": f(n, np.int32), "goalie": f(n, bool), "kickable": f(n, bool),
        "pos": f((n, 2), np.float32), "vel": f((n, 2), np.float32),
        "body": f(n, np.float32), "stamina": f(n, np.float32),
        "tackle_probability": f(n, np.float32),
        "ball": f((n, 2), np.float32), "ball_vel": f((n, 2), np.float32),
        "ball_pos_count": f(n, np.int32),
        "mates": f((n, PLAYERS, 2), np.float32), "mates_valid": f((n, PLAYERS), bool),
        "opps": f((n, PLAYERS, 2), np.float32), "opps_valid": f((n, PLAYERS), bool),
        "mates_vel": f((n, PLAYERS, 2), np.float32), "opps_vel": f((n, PLAYERS, 2), np.float32),
        "mates_body": f((n, PLAYERS), np.float32), "opps_body": f((n, PLAYERS), np.float32),
        "opp_goalie": f(n, np.int32), "self_reach": f(n, np.int32),
        "mate_reach": f(n, np.int32), "opp_reach": f(n, np.int32),
        "kickable_mate": f(n, bool), "kickable_opp": f(n, bool),
        "offside_x": f(n, np.float32), "mode": f(n, np.int32),
        "our_set_play": f(n, bool), "last_kicker": f(n, np.int32), "penalty": f(n, bool),
        "cycle": f(n, np.int32), "stopped": f(n, np.int32), "need_preprocess": f(n, bool),
    }
    for i, state in enumerate(states):
        wm = state.world_model
        me = None if wm is None else wm.myself
        unum = 0 if me is None else int(me.uniform_number or 0)
        if me is None or not 1 <= unum <= PLAYERS:
            raise ValueError(
                f"a State without a world model or with shirt number {unum} (allowed: 1..11)"
            )
        out["unum"][i] = unum
        out["goalie"][i] = bool(me.is_goalie)
        out["kickable"][i] = bool(me.is_kickable)
        out["pos"][i] = _xy(me.position)
        out["vel"][i] = _xy(me.velocity)
        out["body"][i] = me.body_direction or 0.0
        out["stamina"][i] = me.stamina or 0.0
        out["tackle_probability"][i] = me.tackle_probability or 0.0
        ball = wm.ball
        if ball is not None:
            out["ball"][i] = _xy(ball.position)
            out["ball_vel"][i] = _xy(ball.velocity)
            out["ball_pos_count"][i] = ball.pos_count or 0
        _slots(wm.teammates, out["mates"][i], out["mates_valid"][i], out["mates_vel"][i],
               out["mates_body"][i])
        out["mates"][i, unum - 1] = out["pos"][i]
        out["mates_valid"][i, unum - 1] = True
        out["mates_vel"][i, unum - 1] = out["vel"][i]
        out["mates_body"][i, unum - 1] = out["body"][i]
        _slots(wm.opponents, out["opps"][i], out["opps_valid"][i], out["opps_vel"][i],
               out["opps_body"][i])
        out["opp_goalie"][i] = wm.their_goalie_uniform_number or 0
        table = wm.intercept_table
        if table is not None:
            out["self_reach"][i] = table.self_reach_steps or 0
            out["mate_reach"][i] = table.first_teammate_reach_steps or 0
            out["opp_reach"][i] = table.first_opponent_reach_steps or 0
        out["kickable_mate"][i] = bool(wm.kickable_teammate_existance) and not me.is_kickable
        out["kickable_opp"][i] = bool(wm.kickable_opponent_existance)
        out["offside_x"][i] = wm.offside_line_x or 0.0
        out["mode"][i] = wm.game_mode_type or 0
        out["our_set_play"][i] = bool(wm.is_our_set_play)
        ours = wm.last_kick_side is not None and wm.last_kick_side == wm.our_side
        out["last_kicker"][i] = (wm.last_kicker_uniform_number or 0) if ours else 0
        out["penalty"][i] = bool(wm.is_penalty_kick_mode)
        out["cycle"][i] = wm.cycle or 0
        out["stopped"][i] = wm.stoped_cycle or 0
        out["need_preprocess"][i] = bool(state.need_preprocess)
    return Observation(**out)
