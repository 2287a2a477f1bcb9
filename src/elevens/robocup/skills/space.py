"""The skills decision space: what a policy chooses for each player each cycle, and the proxy
answer (librcsc's skills) that carries it out.

A decision is a kind with its argument, for ``n`` players at once (:class:`Decisions`):

- with the ball: ``SHOOT`` at ``point`` (a point of the goal mouth), ``PASS`` to teammate
  ``index`` (shirt number; the ball goes to where the observation has them, plus ``point`` as
  a lead offset), ``DRIBBLE`` in direction ``index`` (0..7, 45 degree steps from +x,
  counter-clockwise), ``HOLD``;
- without it: ``INTERCEPT``, ``GO_TO`` ``point``, ``MARK`` opponent ``index`` (stand between
  them and our goal), ``TACKLE`` (towards their goal);
- outside open play: ``KICKOFF_MOVE`` to ``point`` (the teleport allowed before a kick-off),
  and the proxy's ready behaviours ``GOALIE``, ``SET_PLAY`` and ``PENALTY``;
- ``KICK`` the ball to ``point`` in kicks alone: a dribble of the player who takes our restart
  (``restarts``: the server's free-kick rule forbids its dash-and-kick).

:func:`to_player_actions` turns decisions into the proxy's ``PlayerActions``: the skill first,
a fallback body skill after it (the proxy tries body entries in order), the neck turned to the
ball or scanning. In open play every reflex the proxy would run before our actions is off
(``ignore_doIntention``, ``ignore_shootInPreprocess``, ``ignore_doforcekick``,
``ignore_doHeardPassRecieve``): the choice is ours. Its perception fallbacks (frozen after a
tackle, self or ball lost: ``need_preprocess``) stay on, except before a kick-off, where
``KICKOFF_MOVE`` places the players instead of the proxy's formation. The ready behaviours run
with every reflex on, as the proxy's own team plays them.
"""

from __future__ import annotations

import dataclasses
import enum
from collections.abc import Sequence
from typing import Any

import numpy as np

from elevens.robocup.skills.observe import PLAYERS, Observation
from elevens.robocup.skills.wire import protocol

__all__ = [
    "DRIBBLE_DIRECTIONS",
    "GOAL",
    "Decisions",
    "Kind",
    "default_actions",
    "paced_dash",
    "pass_speed",
    "to_player_actions",
]


class Kind(enum.IntEnum):
    SHOOT = 0
    PASS = 1
    DRIBBLE = 2
    HOLD = 3
    INTERCEPT = 4
    GO_TO = 5
    MARK = 6
    TACKLE = 7
    KICKOFF_MOVE = 8
    GOALIE = 9
    SET_PLAY = 10
    PENALTY = 11
    KICK = 12
    #: helios-base's on-ball planner decides this player's kick (a yardstick, runtime only).
    PLANNER = 13
    #: helios-base's off-ball play decides this player's move (a yardstick, runtime only).
    HELIOS_MOVE = 14


#: Kinds of open play: elevens' own choice, every proxy reflex off.
OPEN_PLAY = frozenset(range(Kind.SHOOT, Kind.TACKLE + 1))
#: Kinds whose every proxy reflex is off: open play, the kick-off move, a restart's kick.
_OURS = OPEN_PLAY | {Kind.KICKOFF_MOVE, Kind.KICK}
#: Their goal's centre and half width (rcssserver's pitch and goal_width 14.02).
GOAL = np.array([52.5, 0.0], np.float32)
GOAL_HALF_WIDTH = 7.01
_OUR_GOAL = (-52.5, 0.0)
#: Unit vectors of the eight dribble directions.
DRIBBLE_DIRECTIONS = np.stack(
    [np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)], axis=1
).astype(np.float32)
DRIBBLE_LENGTH = 8.0  # metres ahead of the player: Body_Dribble's target
BALL_DECAY = 0.94  # rcssserver's ball_decay
BALL_SPEED_MAX = 3.0
MARK_DISTANCE = 1.5  # metres goal-side of the marked opponent
MAX_DASH = 100.0
#: Pacing of the runs to a point: full power while stamina (rcssserver's stamina_max 8000)
#: is above STAMINA_FULL, down to PACED_DASH at STAMINA_LOW, a little above the 2400 below
#: which the server cuts recovery and effort for good. Unpaced players were spent within a
#: third of a match against helios-base.
STAMINA_FULL, STAMINA_LOW = 5000.0, 3000.0
PACED_DASH = 30.0  # below the ~45 a player recovers a cycle: a spent player recovers


@dataclasses.dataclass(frozen=True)
class Decisions:
    """One decision per player: ``kind`` int [n]; ``index`` int [n] (teammate or opponent
    shirt number 1..11, or dribble direction 0..7, else ignored); ``point`` float [n, 2]
    (shot target, go-to or kick-off point, or a pass's lead offset, else ignored)."""

    kind: np.ndarray
    index: np.ndarray
    point: np.ndarray

    @staticmethod
    def of(kind: np.ndarray, index: np.ndarray | None = None,
           point: np.ndarray | None = None) -> Decisions:
        n = len(kind)
        return Decisions(
            np.asarray(kind, np.int32),
            np.zeros(n, np.int32) if index is None else np.asarray(index, np.int32),
            np.zeros((n, 2), np.float32) if point is None else np.asarray(point, np.float32),
        )

    def check(self, n: int) -> None:
        """ValueError, naming the first bad value and what is allowed, unless these are
        ``n`` well-formed decisions."""
        if self.kind.shape != (n,) or self.index.shape != (n,) or self.point.shape != (n, 2):
            raise ValueError(
                f"decisions of shapes kind {self.kind.shape}, index {self.index.shape}, "
                f"point {self.point.shape} for {n} players (allowed: ({n},), ({n},), ({n}, 2))"
            )
        for i in range(n):
            kind, index = int(self.kind[i]), int(self.index[i])
            if kind not in Kind._value2member_map_:
                raise ValueError(f"player row {i}: kind {kind} (allowed: 0..{len(Kind) - 1})")
            if kind in (Kind.PASS, Kind.MARK) and not 1 <= index <= PLAYERS:
                raise ValueError(
                    f"player row {i}: {Kind(kind).name} index {index} (allowed: 1..{PLAYERS})"
                )
            if kind == Kind.DRIBBLE and not 0 <= index < len(DRIBBLE_DIRECTIONS):
                raise ValueError(f"player row {i}: DRIBBLE direction {index} (allowed: 0..7)")
        if not np.isfinite(self.point).all():
            raise ValueError("decisions with a non-finite point (allowed: finite metres)")


def paced_dash(stamina: Any) -> np.ndarray:
    """The dash power of a run to a point for a player with ``stamina``."""
    share = np.clip((np.asarray(stamina) - STAMINA_LOW) / (STAMINA_FULL - STAMINA_LOW), 0.0, 1.0)
    return PACED_DASH + (MAX_DASH - PACED_DASH) * share


def pass_speed(distance: Any, arrival: float = 1.5) -> np.ndarray:
    """First ball speed so that the ball still moves at about ``arrival`` m/s after
    ``distance`` metres (a decaying ball loses ``1 - decay`` of its speed per metre
    travelled), at most the server's maximum."""
    return np.clip(arrival + (1.0 - BALL_DECAY) * np.asarray(distance), 1.0, BALL_SPEED_MAX)


def _v(m: Any, xy: Sequence[float] | np.ndarray) -> Any:
    return m.RpcVector2D(x=float(xy[0]), y=float(xy[1]))


def _neck(m: Any) -> Any:
    return m.PlayerAction(neck_turn_to_ball_or_scan=m.Neck_TurnToBallOrScan(count_threshold=0))


def _hold(m: Any, obs: Observation, i: int) -> Any:
    """Keep the ball away from the nearest opponent (our goal when none is seen), facing
    their goal."""
    valid = obs.opps_valid[i]
    away: Sequence[float] | np.ndarray = _OUR_GOAL
    if valid.any():
        d = np.where(valid, np.linalg.norm(obs.opps[i] - obs.pos[i], axis=1), np.inf)
        away = obs.opps[i, int(np.argmin(d))]
    return m.PlayerAction(body_hold_ball=m.Body_HoldBall(
        do_turn=True, turn_target_point=_v(m, GOAL), kick_target_point=_v(m, away)
    ))


def _kick(m: Any, target: np.ndarray, speed: float) -> Any:
    return m.PlayerAction(body_smart_kick=m.Body_SmartKick(
        target_point=_v(m, target), first_speed=float(speed),
        first_speed_threshold=float(0.8 * speed), max_steps=3,
    ))


def _turn_to_ball(m: Any) -> Any:
    return m.PlayerAction(body_turn_to_ball=m.Body_TurnToBall(cycle=1))


def _go_to(m: Any, target: np.ndarray, power: float, threshold: float = 1.0) -> Any:
    return m.PlayerAction(body_go_to_point=m.Body_GoToPoint(
        target_point=_v(m, target), distance_threshold=threshold, max_dash_power=power
    ))


def _intercept(m: Any) -> Any:
    return m.PlayerAction(
        body_intercept=m.Body_Intercept(save_recovery=True, face_point=_v(m, GOAL))
    )


def _one(m: Any, obs: Observation, dec: Decisions, i: int, ours_chooses: bool) -> list[Any]:
    kind, index, point, pos = Kind(int(dec.kind[i])), int(dec.index[i]), dec.point[i], obs.pos[i]
    if kind == Kind.SHOOT:
        return [_kick(m, point, BALL_SPEED_MAX), _hold(m, obs, i), _neck(m)]
    if kind == Kind.PASS:
        target = obs.mates[i, index - 1] + point
        speed = float(pass_speed(np.linalg.norm(target - pos)))
        return [_kick(m, target, speed), _hold(m, obs, i), _neck(m)]
    if kind == Kind.DRIBBLE:
        target = pos + DRIBBLE_LENGTH * DRIBBLE_DIRECTIONS[index]
        dribble = m.Body_Dribble(target_point=_v(m, target), distance_threshold=1.0,
                                 dash_power=MAX_DASH, dash_count=2, dodge=True)
        return [m.PlayerAction(body_dribble=dribble), _hold(m, obs, i), _neck(m)]
    if kind == Kind.HOLD:
        return [_hold(m, obs, i), _neck(m)]
    if kind == Kind.INTERCEPT:
        return [_intercept(m), _turn_to_ball(m), _neck(m)]
    if kind == Kind.GO_TO:
        return [_go_to(m, point, float(paced_dash(obs.stamina[i]))), _turn_to_ball(m), _neck(m)]
    if kind == Kind.MARK:
        opp = obs.opps[i, index - 1]
        side = np.asarray(_OUR_GOAL, np.float32) - opp
        target = opp + MARK_DISTANCE * side / max(float(np.linalg.norm(side)), 1e-6)
        power = float(paced_dash(obs.stamina[i]))
        return [_go_to(m, target, power, 0.5), _turn_to_ball(m), _neck(m)]
    if kind == Kind.TACKLE:
        tackle = m.Body_TackleToPoint(target_point=_v(m, GOAL), min_probability=0.5,
                                      min_speed=0.0)
        return [m.PlayerAction(body_tackle_to_point=tackle), _intercept(m), _neck(m)]
    if kind == Kind.KICKOFF_MOVE:
        return [
            m.PlayerAction(move=m.Move(x=float(point[0]), y=float(point[1]))),
            _turn_to_ball(m), m.PlayerAction(view_wide=m.View_Wide()), _neck(m),
        ]
    if kind == Kind.GOALIE:
        return [m.PlayerAction(helios_goalie=m.HeliosGoalie())]
    if kind == Kind.SET_PLAY:
        return [m.PlayerAction(helios_set_play=m.HeliosSetPlay())]
    if kind == Kind.KICK:
        speed = float(pass_speed(np.linalg.norm(point - pos)))
        return [_kick(m, point, speed), _hold(m, obs, i), _neck(m)]
    if kind == Kind.PLANNER:
        planner = m.HeliosOffensivePlanner(
            direct_pass=True, lead_pass=True, through_pass=True, short_dribble=True,
            long_dribble=True, cross=True, simple_pass=False, simple_dribble=False,
            simple_shoot=True, server_side_decision=ours_chooses, max_depth=0, max_nodes=0,
        )
        return [m.PlayerAction(helios_shoot=m.HeliosShoot()),
                m.PlayerAction(helios_offensive_planner=planner), _hold(m, obs, i), _neck(m)]
    if kind == Kind.HELIOS_MOVE:  # it turns the neck itself
        return [m.PlayerAction(helios_basic_move=m.HeliosBasicMove()), _turn_to_ball(m)]
    return [m.PlayerAction(helios_penalty=m.HeliosPenalty())]


def to_player_actions(decisions: Decisions, obs: Observation,
                      chooses_chains: bool = False) -> list[Any]:
    """The proxy's ``PlayerActions`` for each row of ``obs``; with ``chooses_chains`` a
    ``PLANNER`` row asks the decision server which of the planner's chains to play."""
    n = len(obs)
    decisions.check(n)
    m = protocol()
    out = []
    for i in range(n):
        kind = int(decisions.kind[i])
        ours = kind in _OURS
        out.append(m.PlayerActions(
            actions=_one(m, obs, decisions, i, chooses_chains),
            ignore_preprocess=kind == Kind.KICKOFF_MOVE,
            ignore_doforcekick=ours,
            ignore_doHeardPassRecieve=ours,
            ignore_doIntention=ours,
            ignore_shootInPreprocess=ours,
        ))
    return out


def default_actions(state: Any) -> Any:
    """The answer for a request whose decision missed its deadline: the proxy's reflexes on
    (its own kick-off positions, ball search, shoot check), the ball held when kickable, else
    the body turned to the ball."""
    m = protocol()
    wm = state.world_model
    me = None if wm is None else wm.myself
    if me is not None and me.is_kickable:
        body = m.PlayerAction(body_hold_ball=m.Body_HoldBall(
            do_turn=True, turn_target_point=_v(m, GOAL), kick_target_point=_v(m, _OUR_GOAL)
        ))
    else:
        body = _turn_to_ball(m)
    return m.PlayerActions(
        actions=[body, _neck(m)], ignore_preprocess=False, ignore_doforcekick=False,
        ignore_doHeardPassRecieve=False, ignore_doIntention=False,
        ignore_shootInPreprocess=False,
    )
