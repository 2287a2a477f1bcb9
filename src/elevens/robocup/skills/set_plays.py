"""Our set plays decided by the team itself (``--set-plays decided``) instead of the proxy's
ready behaviour (``routine``, ``HeliosSetPlay``).

With ``decided``, every outfield player decides our kick-offs, free kicks, kick-ins and corners
as it decides open play: the policy's own choice (a trained team), or ``skills_naive``'s open-play
rules. The kick-off placing, goal kicks and the goalie's catch stay with the goalie and the
ready behaviours, and so do their set plays (our players keep their distance as the routine
does).

rcssserver's free-kick rule (``free_kick_faults``, on in regulation matches): the player who
takes the kick must not play the ball again after a dash until another player has touched it,
or they get a free kick. :class:`TakerGuard` keeps that rule. It remembers, for each shirt
number, that the player had the ball in our set play; while librcsc's world model still names
it as the last kicker, its dribble becomes a ``KICK`` to the dribble's target (kicks alone)
and its run at the ball (``INTERCEPT``, ``TACKLE``) a run to its formation slot. The memory
ends when another player kicks, at any other stoppage, or :data:`TAKER_CYCLES` after the set
play.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from elevens.robocup.skills.decode import slot_targets
from elevens.robocup.skills.observe import Observation
from elevens.robocup.skills.space import DRIBBLE_DIRECTIONS, DRIBBLE_LENGTH, Decisions, Kind

__all__ = ["SET_PLAYS", "TAKER_CYCLES", "TakerGuard", "check_set_plays", "decided_set_play"]

#: How a skills team plays our set plays: the proxy's ready behaviour, or its own decisions.
SET_PLAYS = ("routine", "decided")
#: Cycles after the set play after which its taker is free again, whatever the world model says.
TAKER_CYCLES = 150
_PLAY_ON = 2
#: The proxy's GameModeType of the set plays a team decides: kick-off, kick-in, free kick,
#: corner (goal kicks and the goalie's catch are the goalie's).
_DECIDED_MODES = (3, 4, 5, 6)


def check_set_plays(value: str, flag: str = "--set-plays") -> None:
    """ValueError in one line unless ``value`` is one of :data:`SET_PLAYS`."""
    if value not in SET_PLAYS:
        raise ValueError(f"{flag} {value!r} is invalid (allowed: {', '.join(SET_PLAYS)})")


def decided_set_play(obs: Observation, xp: Any = np) -> Any:
    """bool[n]: the rows in one of our set plays that a team deciding its set plays decides."""
    mode = xp.asarray(obs.mode)
    return xp.asarray(obs.our_set_play) & xp.isin(mode, xp.asarray(_DECIDED_MODES))


class TakerGuard:
    """The free-kick rule over a team's decisions (module docstring). One per team and match:
    :meth:`reset` forgets every taker. Each row updates only its own shirt's memory, so a
    decision server that decides each player on its own may call it from the players'
    threads."""

    def __init__(self) -> None:
        self._taken: dict[int, int] = {}  # shirt -> the cycle it had the ball in our set play

    def reset(self) -> None:
        self._taken.clear()

    def takers(self, obs: Observation) -> np.ndarray:
        """bool[n]: the rows bound by the rule this cycle: the player with the ball in our
        set play, or the one who had it while no other player has kicked since."""
        taking = decided_set_play(obs) & np.asarray(obs.kickable)
        bound = np.zeros(len(obs), bool)
        for i in range(len(obs)):
            shirt, cycle = int(obs.unum[i]), int(obs.cycle[i])
            if int(obs.mode[i]) != _PLAY_ON:
                if taking[i]:
                    self._taken[shirt] = cycle
                    bound[i] = True
                else:
                    self._taken.pop(shirt, None)
            elif shirt in self._taken:
                if int(obs.last_kicker[i]) == shirt and cycle - self._taken[shirt] <= TAKER_CYCLES:
                    bound[i] = True
                else:
                    del self._taken[shirt]
        return bound

    def apply(self, obs: Observation, decisions: Decisions) -> tuple[Decisions, np.ndarray]:
        """``decisions`` within the rule, and bool[n]: the rows it changed."""
        bound = self.takers(obs)
        kind, index, point = (decisions.kind.copy(), decisions.index.copy(),
                              decisions.point.copy())
        dribble = bound & (kind == Kind.DRIBBLE)
        if dribble.any():
            ahead = DRIBBLE_LENGTH * DRIBBLE_DIRECTIONS[index[dribble] % len(DRIBBLE_DIRECTIONS)]
            point[dribble] = np.asarray(obs.pos)[dribble] + ahead
            kind[dribble] = Kind.KICK
        chase = bound & ~np.asarray(obs.kickable) & np.isin(kind, (Kind.INTERCEPT, Kind.TACKLE))
        if chase.any():
            point[chase] = slot_targets(np.asarray(obs.unum)[chase], np.asarray(obs.ball)[chase],
                                        np.asarray(obs.offside_x)[chase])
            kind[chase] = Kind.GO_TO
        return Decisions(kind, index, point), dribble | chase
