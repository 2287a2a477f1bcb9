"""The thesis' 12-value continuous RoboCup action mapped to one server command.

Table 4.1 of the thesis (section 4.5, "2D RoboCup simulation environment"): a policy
outputs 12 values in [-1, 1]; the largest of the first five picks the body command,
the others are that command's parameters. Layout (:class:`ActionIndex`):

====  ================  ==================================================================
idx   name              meaning -> server value (defaults of rcssserver 19)
====  ================  ==================================================================
0     DASH_SCORE        selection score of dash
1     KICK_SCORE        selection score of kick
2     TURN_SCORE        selection score of turn
3     TACKLE_SCORE      selection score of tackle
4     NOOP_SCORE        selection score of "no move" (only ``(done)`` is sent)
5     DASH_POWER        -1 full backwards .. +1 full forwards; ``|a| * max_dash_power``
6     DASH_DIR          -1 .. +1 -> -90 .. +90 degrees relative to the body
7     KICK_POWER        -1 .. +1 -> 0 .. maxpower (the thesis' "0 to 1")
8     KICK_DIR          -1 .. +1 -> minmoment .. maxmoment (-180 .. 180 degrees)
9     TURN_MOMENT       -1 .. +1 -> minmoment .. maxmoment (-180 .. 180 degrees)
10    TACKLE_FOUL       > 0 -> foul tackle (``on``), <= 0 -> no foul (``off``)
11    TACKLE_DIR        -1 .. +1 -> -90 .. +90 degrees relative to the body
====  ================  ==================================================================

Details:

* Selection is ``argmax`` over indices 0-4; ties go to the lowest index (dash before
  kick before turn before tackle before no-op), as ``numpy.argmax`` does.
* Backwards dash: since protocol v17 the server clamps dash power to
  [min_dash_power, max_dash_power] = [0, 100], so a negative power would become 0. When
  ``min_dash_power >= 0`` a negative DASH_POWER is sent as power ``|a| * max_dash_power``
  with the direction turned by 180 degrees (same acceleration direction; the server
  applies back_dash_rate); when the server allows negative power
  (``server::min_dash_power=-100``) it is sent as ``a * |min_dash_power|`` with the
  unchanged direction.
* Kick direction and turn moment scale positive values by ``maxmoment`` and negative
  ones by ``-minmoment``, so -1/+1 reach the ends of the server range even if it were
  asymmetric. Directions are finally clipped to the server's ranges.
* Values outside [-1, 1] are clipped. NaN or infinite values raise ``ValueError``
  naming the offending index (a policy emitting them is broken; clipping would hide it).
* A kick with the ball out of reach: the server ignores it (a cycle without a dash; 6.8k-9.4k
  a match from a trained team against helios-base). Given where each player last saw the ball
  (``ball_distance``, ``ball_bearing`` of :func:`actions_to_commands`), a kick chosen with the
  ball beyond ``kickable`` becomes a dash towards the ball when the player saw it in its view
  cone (full power beyond ``REACH_SLOW`` metres, half within), else the policy's own dash or
  turn, whichever scored higher.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

import numpy as np

from elevens.robocup.protocol import (
    Command,
    Dash,
    Kick,
    NoOp,
    ServerParams,
    Tackle,
    Turn,
)

__all__ = [
    "ACTION_SIZE",
    "ACTION_SIZES",
    "KICKABLE",
    "action_mode",
    "ActionIndex",
    "ActionScaling",
    "action_to_command",
    "actions_to_commands",
]

#: Length of the action vector.
ACTION_SIZE = 12
KICKABLE = 1.085
"""player_size + ball_size + kickable_margin of the default player type (metres)."""
REACH_SLOW = 3.0
"""Metres to the ball within which a kick out of reach becomes a half-power dash (as the
set-piece taker's run to the ball: full power there would run into it)."""
ACTION_SIZES = {"sim": 2, "thesis12": ACTION_SIZE}
"""Values per player of each RoboCupEnv action mode: "sim" is the simulator's (move, rot),
"thesis12" the thesis's table 4.1."""


def action_mode(values: int) -> str:
    """The action mode of a policy that gives ``values`` numbers per player."""
    for mode, size in ACTION_SIZES.items():
        if size == values:
            return mode
    raise ValueError(
        f"a policy with {values!r} action values has no RoboCupEnv action mode: allowed are "
        f"{ACTION_SIZES}"
    )


class ActionIndex(IntEnum):
    """Positions in the 12-value action vector (thesis table 4.1)."""

    DASH_SCORE = 0
    KICK_SCORE = 1
    TURN_SCORE = 2
    TACKLE_SCORE = 3
    NOOP_SCORE = 4
    DASH_POWER = 5
    DASH_DIR = 6
    KICK_POWER = 7
    KICK_DIR = 8
    TURN_MOMENT = 9
    TACKLE_FOUL = 10
    TACKLE_DIR = 11


_NAMES = {
    ActionIndex.DASH_SCORE: "dash selection score",
    ActionIndex.KICK_SCORE: "kick selection score",
    ActionIndex.TURN_SCORE: "turn selection score",
    ActionIndex.TACKLE_SCORE: "tackle selection score",
    ActionIndex.NOOP_SCORE: "no-op selection score",
    ActionIndex.DASH_POWER: "dash power",
    ActionIndex.DASH_DIR: "dash direction",
    ActionIndex.KICK_POWER: "kick power",
    ActionIndex.KICK_DIR: "kick direction",
    ActionIndex.TURN_MOMENT: "turn moment",
    ActionIndex.TACKLE_FOUL: "tackle foul flag",
    ActionIndex.TACKLE_DIR: "tackle direction",
}


@dataclass(frozen=True, slots=True)
class ActionScaling:
    """Server ranges the normalised parameters are scaled to.

    Build it with :meth:`from_server_params` from the ``server_param`` message; the
    default instance uses the rcssserver 19 defaults. ``dash_dir_range`` and
    ``tackle_dir_range`` are the thesis' +-90 degree ranges (then clipped to the server's
    limits).
    """

    min_dash_power: float = 0.0
    max_dash_power: float = 100.0
    min_dash_angle: float = -180.0
    max_dash_angle: float = 180.0
    max_kick_power: float = 100.0
    min_moment: float = -180.0
    max_moment: float = 180.0
    dash_dir_range: float = 90.0
    tackle_dir_range: float = 90.0

    @classmethod
    def from_server_params(
        cls,
        params: ServerParams | None = None,
        *,
        dash_dir_range: float = 90.0,
        tackle_dir_range: float = 90.0,
    ) -> ActionScaling:
        """Take the ranges from ``params`` (rcssserver 19 defaults if None)."""
        p = params if params is not None else ServerParams.defaults()
        return cls(
            min_dash_power=p.min_dash_power,
            max_dash_power=p.max_dash_power,
            min_dash_angle=p.min_dash_angle,
            max_dash_angle=p.max_dash_angle,
            max_kick_power=p.max_power,
            min_moment=p.min_moment,
            max_moment=p.max_moment,
            dash_dir_range=dash_dir_range,
            tackle_dir_range=tackle_dir_range,
        )


_DEFAULT_SCALING = ActionScaling()


def _scale(a: float, lo: float, hi: float) -> float:
    # Positive values scale by the upper bound, negative by the lower one.
    return a * hi if a >= 0 else -a * lo


def _clamp(v: float, lo: float, hi: float) -> float:
    return min(max(v, lo), hi)


def _wrap(deg: float) -> float:
    """Wrap to (-180, 180], the range the server's directions use."""
    w = math.remainder(deg, 360.0)
    return 180.0 if w == -180.0 else w


def _command(
    a: list[float], s: ActionScaling, ball: tuple[float, float] | None = None,
    kickable: float = KICKABLE,
) -> Command:
    scores = a[:5]
    choice = scores.index(max(scores))  # first maximum: ties go to the lowest index
    if choice == ActionIndex.KICK_SCORE and ball is not None and not ball[0] <= kickable:
        distance, bearing = ball
        if math.isfinite(bearing):  # towards the ball, as the server's omni-dash allows
            power = s.max_dash_power * (1.0 if distance > REACH_SLOW else 0.5)
            direction = -math.degrees(math.remainder(bearing, 2 * math.pi))
            return Dash(power, _clamp(direction, s.min_dash_angle, s.max_dash_angle))
        dash_first = a[ActionIndex.DASH_SCORE] >= a[ActionIndex.TURN_SCORE]
        choice = ActionIndex.DASH_SCORE if dash_first else ActionIndex.TURN_SCORE
    if choice == ActionIndex.DASH_SCORE:
        power = a[ActionIndex.DASH_POWER]
        direction = a[ActionIndex.DASH_DIR] * s.dash_dir_range
        if power >= 0:
            value = power * s.max_dash_power
        elif s.min_dash_power < 0:
            value = power * -s.min_dash_power
        else:
            value = -power * s.max_dash_power
            direction = _wrap(direction + 180.0)
        return Dash(
            _clamp(value, s.min_dash_power, s.max_dash_power),
            _clamp(direction, s.min_dash_angle, s.max_dash_angle),
        )
    if choice == ActionIndex.KICK_SCORE:
        power = (a[ActionIndex.KICK_POWER] + 1.0) * 0.5 * s.max_kick_power
        direction = _scale(a[ActionIndex.KICK_DIR], s.min_moment, s.max_moment)
        return Kick(power, direction)
    if choice == ActionIndex.TURN_SCORE:
        return Turn(_scale(a[ActionIndex.TURN_MOMENT], s.min_moment, s.max_moment))
    if choice == ActionIndex.TACKLE_SCORE:
        direction = _clamp(
            a[ActionIndex.TACKLE_DIR] * s.tackle_dir_range, s.min_moment, s.max_moment
        )
        return Tackle(direction, foul=a[ActionIndex.TACKLE_FOUL] > 0.0)
    return NoOp()


def _checked(actions: object) -> np.ndarray:
    arr = np.asarray(actions)
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.floating)
        or np.issubdtype(arr.dtype, np.integer)
        or arr.dtype == np.bool_
    ):
        raise ValueError(f"action must be a numeric array, got dtype {arr.dtype}")
    if arr.ndim == 0 or arr.shape[-1] != ACTION_SIZE:
        raise ValueError(f"action must have shape (..., {ACTION_SIZE}), got {arr.shape}")
    arr = arr.astype(np.float64, copy=False)
    bad = ~np.isfinite(arr)
    if bad.any():
        where = tuple(int(i) for i in np.argwhere(bad)[0])
        idx = ActionIndex(where[-1])
        value = float(arr[where])
        batch = f" of action {where[:-1]}" if len(where) > 1 else ""
        raise ValueError(
            f"action[{int(idx)}] ({_NAMES[idx]}, {idx.name}){batch} is {value!r}; "
            "actions must be finite numbers in [-1, 1]"
        )
    return np.clip(arr, -1.0, 1.0)


def action_to_command(
    action: object, scaling: ActionScaling | ServerParams | None = None
) -> Command:
    """Map one action, shape ``(12,)``, to the server command for this cycle.

    ``scaling`` is an :class:`ActionScaling`, a :class:`ServerParams` (converted with
    :meth:`ActionScaling.from_server_params`) or None for the rcssserver 19 defaults.
    Returns :class:`Dash`, :class:`Kick`, :class:`Turn`, :class:`Tackle` or
    :class:`NoOp` (which encodes to nothing: send only ``(done)``).
    """
    arr = _checked(action)
    if arr.ndim != 1:
        raise ValueError(
            f"action_to_command takes one action of shape ({ACTION_SIZE},), "
            f"got {arr.shape}; use actions_to_commands for batches"
        )
    return _command(arr.tolist(), _scaling(scaling))


def actions_to_commands(
    actions: object,
    scaling: ActionScaling | ServerParams | None = None,
    *,
    ball_distance: object = None,
    ball_bearing: object = None,
    kickable: float = KICKABLE,
) -> list[Command]:
    """Map a batch of actions, shape ``(..., 12)``, to a flat list of commands.

    Leading axes are flattened in C order, e.g. ``(teams, players, 12)`` gives
    ``teams * players`` commands, player index fastest. A single ``(12,)`` action gives
    a one-element list.

    ``ball_distance`` (metres, inf: not seen) and ``ball_bearing`` (radians, + = left of the
    body; NaN: not in the view cone), both of the actions' leading shape: where each player
    last saw the ball; with them a kick out of ``kickable`` reach is replaced (module
    docstring). None: every kick goes out as chosen.
    """
    arr = _checked(actions)
    s = _scaling(scaling)
    rows = arr.reshape(-1, ACTION_SIZE).tolist()
    if ball_distance is None:
        return [_command(row, s) for row in rows]
    distance = np.asarray(ball_distance, np.float64).reshape(-1)
    bearing = (
        np.full(len(rows), np.nan) if ball_bearing is None
        else np.asarray(ball_bearing, np.float64).reshape(-1)
    )
    if len(distance) != len(rows) or len(bearing) != len(rows):
        raise ValueError(
            f"ball_distance and ball_bearing must give one value per action ({len(rows)}), "
            f"got {len(distance)} and {len(bearing)}"
        )
    balls = zip(distance.tolist(), bearing.tolist(), strict=True)
    return [_command(row, s, ball, kickable) for row, ball in zip(rows, balls, strict=True)]


def _scaling(scaling: ActionScaling | ServerParams | None) -> ActionScaling:
    if scaling is None:
        return _DEFAULT_SCALING
    if isinstance(scaling, ServerParams):
        return ActionScaling.from_server_params(scaling)
    return scaling
