"""Scripted probe teams for rcssserver: what changes the score against another team?

A diagnostic, not a team to ship (docs/results/robocup.md, session 17). Each probe is the RoboCup
naive team (`elevens.robocup.naive`) with one behaviour changed, played with the same set-piece,
goalie and stamina rules as every elevens team. It runs as an external team command:

    elevens robocup match --team0-cmd "python scripts/robocup_probe_team.py PROBE \
        --host localhost --port {port} --team-name {team} --players 11" --team0-name PROBE \
        --team1-cmd "$ELEVENS_HELIOS_START -p {port} -P {coach_port} -t {team}" \
        --team1-name HELIOS_base --matches 2 --log-dir DIR

Probes:
  naive12    the naive team with the thesis's 12-value action: it kicks at once in any direction
             instead of turning to face the goal first
  clear12    naive12, kicking at the far corner of the opponents' half instead of the goal
  screen     the 2 players nearest the ball chase it; the other 8 hold two lines between the
             ball and the own goal
  bus        the 8 players not within 4 m of the ball hold two rows across the own penalty area
  intercept  chasers run to where they can meet the rolling ball, not to where it is
  dribble12  naive12 with soft kicks (power 35: the ball rolls about 8 m ahead) towards the goal
  combo12    dribble12 whose chasers run for the rolling ball's course (RoboCupNaiveTeam's
             intercept): the two skills that moved the score, together
  longko     naive; the kick-off goes long to the opponents' wing instead of back to midfield
  tackle     naive; a player with the ball 0-1.7 m ahead (and out of kicking reach) tackles
             it towards the opponent goal
  mark       man-marking: the 2 players nearest the ball chase it as ``intercept`` does; each
             other outfield player stands goal-side of one opponent (the most dangerous first:
             nearest the own goal), 1.5 m from it on its line to the goal, leaning to the ball.
             Pairs are kept from step to step; turns take off the turns commanded since the
             last see and are scaled up by the server's inertia (1 + 5 x speed)

Everything after PROBE goes to ``elevens robocup team``.
"""

from __future__ import annotations

import dataclasses
import math
import sys

import numpy as np

import elevens.robocup.play as play
import elevens.robocup.rules as rules
import elevens.robocup.team as team
from elevens.env.state import ENTITY_FEATURES
from elevens.robocup.actions import ActionIndex
from elevens.robocup.naive import (
    _COS,
    _SIN,
    _X,
    _Y,
    NEVER_SEEN,
    NaiveMemory,
    RoboCupNaiveTeam,
    _wrap,
)
from elevens.robocup.protocol import Kick, Tackle

PROBES = (
    "naive12", "clear12", "screen", "bus", "intercept", "dribble12", "combo12", "longko", "tackle",
    "mark",
)
OWN_GOAL = np.array([-52.5, 0.0])


def _pose(team: RoboCupNaiveTeam, obs) -> tuple[np.ndarray, np.ndarray]:
    f = np.asarray(obs.self_features, np.float64)
    position = f[:, [_X, _Y]] * np.array([team.half_length, team.half_width])
    return position, np.arctan2(f[:, _SIN], f[:, _COS])


INERTIA_MOMENT = 5.0  # server::inertia_moment: a turn is divided by 1 + this x speed
PLAYER_DECAY = 0.4  # server::player_decay


def _steer(team, out, turned, speed, i, target, ball, position, heading, arrive=1.0) -> None:
    """Player i heads for ``target`` and, within ``arrive`` m of it, faces the ball ("sim"
    actions, out[i] and turned[i] set in place). Headings are the last see's (every 3rd
    cycle): the turns commanded since are taken off, or the player turns again on the same
    stale bearing and spins; a turn is scaled up by the server's inertia at ``speed[i]``."""
    rot = out[i][1]
    before = turned[i] - (math.radians(-rot * team.turn_scale) if rot else 0.0)
    offset = target - position[i]
    gap = float(np.hypot(*offset))
    close = gap < arrive
    aim = ball - position[i] if close else offset
    angle = _wrap(math.atan2(aim[1], aim[0]) - heading[i] - before)
    if close and abs(angle) <= 0.5:
        out[i], turned[i] = (0.0, 0.0), before
    elif close or abs(angle) > math.radians(40.0):
        slowdown = 1.0 + INERTIA_MOMENT * speed[i]
        moment = float(np.clip(-math.degrees(angle) * slowdown, -180.0, 180.0))
        out[i] = (0.0, float(np.clip(moment / team.turn_scale, -1, 1)))
        turned[i] = before - math.radians(out[i][1] * team.turn_scale) / slowdown
    else:  # a dash within 40 degrees still closes most of the gap
        out[i], turned[i] = (min(1.0, 0.4 + gap / 3.0), 0.0), before


def _next_speed(out, speed: np.ndarray) -> np.ndarray:
    """Each player's speed after this step's "sim" actions (a dash of |move| x 100 power)."""
    move = np.abs(np.asarray(out, np.float64)[:, 0])
    return PLAYER_DECAY * np.minimum(speed + 0.6 * move, 1.05)


@dataclasses.dataclass
class SteerMemory:
    naive: NaiveMemory
    speed: np.ndarray  # f64[n] m/cycle, estimated from the commands sent (for turns)


class Clear(RoboCupNaiveTeam):
    def act(self, params, carry, obs, key=None):
        carry, out = super().act(params, carry, obs, key)
        position, heading = _pose(self, obs)
        for i in np.flatnonzero(out[:, ActionIndex.KICK_SCORE] > 0.5):
            corner = np.array([52.5, 34.0 if position[i, 1] >= 0 else -34.0])
            offset = corner - position[i]
            angle = _wrap(math.atan2(offset[1], offset[0]) - heading[i])
            out[i, ActionIndex.KICK_DIR] = np.clip(-math.degrees(angle) / 180.0, -1.0, 1.0)
        return carry, out


@dataclasses.dataclass(frozen=True)
class Block(RoboCupNaiveTeam):
    """screen (``bus`` False) or bus (True): naive chasers, the rest hold positions."""

    bus: bool = False
    chasers: int = 2

    def init_carry(self, players_per_team: int) -> SteerMemory:
        return SteerMemory(NaiveMemory.empty(players_per_team), np.zeros(players_per_team))

    def act(self, params, carry, obs, key=None):
        naive_carry, out = super().act(params, carry.naive, obs, key)
        position, heading = _pose(self, obs)
        n = len(position)
        ball = naive_carry.ball.mean(axis=0)
        distance = np.hypot(*(position - ball).T)
        distance[0] = np.inf  # the goalie has its own rule
        if self.bus:
            chasing = {i for i in range(1, n) if distance[i] < 4.0}
        else:
            chasing = set(np.argsort(distance)[: self.chasers].tolist())
        holding = [i for i in range(1, n) if i not in chasing]
        targets = self._targets(ball, len(holding))
        free = list(range(len(targets)))
        turned = naive_carry.turned.copy()
        for i in sorted(holding, key=lambda i: position[i, 0]):
            j = min(free, key=lambda j: np.hypot(*(position[i] - targets[j])))
            free.remove(j)
            _steer(self, out, turned, carry.speed, i, targets[j], ball, position, heading, 1.5)
        naive_carry = dataclasses.replace(naive_carry, turned=turned)
        return SteerMemory(naive_carry, _next_speed(out, carry.speed)), out

    def _targets(self, ball: np.ndarray, m: int) -> list[np.ndarray]:
        to_goal = OWN_GOAL - ball
        length = float(np.hypot(*to_goal)) + 1e-9
        along, across = to_goal / length, np.array([-to_goal[1], to_goal[0]]) / length
        targets = []
        for j in range(m):
            row, k = j % 2, j // 2
            if self.bus:
                y = (k - (m // 2 - 1) / 2) * 5.0 + 2.5 * row + np.clip(0.3 * ball[1], -8, 8)
                target = np.array([-48.0 + 5.0 * row, y])
            elif j < m // 2:
                target = ball + along * min(6.0, 0.3 * length) + across * (j - (m // 2 - 1) / 2) * 8
            else:
                k = j - m // 2
                lateral = (k - (m - m // 2 - 1) / 2) * 10.0
                target = ball + along * (0.5 * length + 4.0) + across * lateral
            targets.append(np.clip(target, [-50.0, -33.0], [52.5, 33.0]))
        return targets


class Intercept(RoboCupNaiveTeam):
    def act(self, params, carry, obs, key=None):
        carry, out = super().act(params, carry, obs, key)
        position, heading = _pose(self, obs)
        turned = carry.turned.copy()
        for i in range(len(out)):
            move, rot = out[i]
            near = np.hypot(*(carry.ball[i] - position[i])) <= self.kickable + 0.3
            if carry.age[i] > self.memory_steps or near:
                continue
            # The ball's course (decaying by ball_decay a cycle); meet it where a player at
            # 0.85 m a cycle gets first.
            ball, velocity = carry.ball[i].copy(), carry.ball_velocity[i].copy()
            for cycles in range(1, 40):
                ball, velocity = ball + velocity, velocity * self.ball_decay
                if np.hypot(*(ball - position[i])) <= 0.85 * cycles + self.kickable:
                    break
            target = np.clip(ball, [-52.5, -34.0], [52.5, 34.0])
            offset = target - position[i]
            # The naive turn bookkeeping (turns since the last see) minus this cycle's turn.
            before = turned[i] - (math.radians(-rot * self.turn_scale) if rot else 0.0)
            angle = _wrap(math.atan2(offset[1], offset[0]) - heading[i] - before)
            if abs(angle) > self.chase_tolerance:
                out[i] = (0.0, np.clip(-math.degrees(angle) / self.turn_scale, -1.0, 1.0))
                limit = math.radians(self.turn_scale)
                turned[i] = before + float(np.clip(angle, -limit, limit))
            else:
                out[i] = (1.0 if np.hypot(*offset) > 2.0 else 0.5, 0.0)
                turned[i] = before
        return dataclasses.replace(carry, turned=turned), out


_ENTITY_DISTANCE = ENTITY_FEATURES.index("distance")
_ENTITY_COS = ENTITY_FEATURES.index("cos_bearing")
_ENTITY_SIN = ENTITY_FEATURES.index("sin_bearing")


@dataclasses.dataclass
class MarkMemory(SteerMemory):
    opponents: np.ndarray  # f64[n, 2] last known position of each opponent slot, team frame
    age: np.ndarray  # i64[n] steps since that slot was seen
    marking: np.ndarray  # i64[n] the opponent slot each player marked last step (-1: none)


class Mark(Intercept):
    """Two chasers for the rolling ball; the rest mark the opponents nearest the own goal."""

    chasers = 2
    forget_steps = 30
    goal_side = 1.5  # m from the marked opponent towards the own goal
    lean = 0.7  # m from the marked opponent towards the ball (cuts the pass)

    def init_carry(self, players_per_team: int) -> MarkMemory:
        n = players_per_team
        return MarkMemory(
            NaiveMemory.empty(n), np.zeros(n), np.zeros((n, 2)),
            np.full(n, NEVER_SEEN, np.int64), np.full(n, -1, np.int64),
        )

    def act(self, params, carry, obs, key=None):
        naive_carry, out = super().act(params, carry.naive, obs, key)
        position, heading = _pose(self, obs)
        n = len(position)
        opponents, age = self._sight_opponents(obs, position, heading, carry)
        carry = MarkMemory(naive_carry, carry.speed, opponents, age, np.full(n, -1, np.int64))
        if naive_carry.age.min() > self.memory_steps:
            return carry, out  # nobody knows where the ball is: the naive search
        ball = naive_carry.ball.mean(axis=0)
        distance = np.hypot(*(position - ball).T)
        distance[0] = np.inf  # the goalie has its own rule
        chasing = set(np.argsort(distance)[: self.chasers].tolist())
        markers = [i for i in range(1, n) if i not in chasing]
        known = [
            j for j in range(1, n)  # not the goalie (unum 1)
            if age[j] <= self.forget_steps and opponents[j, 0] < 36.0
            and np.hypot(*(opponents[j] - ball)) > 3.0
        ]
        known.sort(key=lambda j: np.hypot(*(opponents[j] - OWN_GOAL)))
        wanted = known[: len(markers)]
        # Keep last step's pairs (positions are a few cycles stale: re-pairing each step
        # sends markers back and forth), then pair the rest, most dangerous first.
        marking = np.full(n, -1, np.int64)
        for i in markers:
            if carry.marking[i] in wanted:
                marking[i] = carry.marking[i]
        for j in wanted:
            if j in marking:
                continue
            free = [i for i in markers if marking[i] < 0]
            i = min(free, key=lambda i: np.hypot(*(position[i] - opponents[j])))
            marking[i] = j
        spare = [i for i in markers if marking[i] < 0]
        screen = Block._targets(Block(), ball, len(spare)) if spare else []
        targets = {}
        for i in markers:
            j = int(marking[i])
            if j < 0:
                continue
            to_goal, to_ball = OWN_GOAL - opponents[j], ball - opponents[j]
            target = (
                opponents[j]
                + self.goal_side * to_goal / (np.hypot(*to_goal) + 1e-9)
                + self.lean * to_ball / (np.hypot(*to_ball) + 1e-9)
            )
            targets[i] = np.clip(target, [-51.0, -33.0], [52.0, 33.0])
        for i in sorted(spare, key=lambda i: position[i, 0]):
            k = min(range(len(screen)), key=lambda k: np.hypot(*(position[i] - screen[k])))
            targets[i] = screen.pop(k)
        turned = naive_carry.turned.copy()
        for i, target in targets.items():
            _steer(self, out, turned, carry.speed, i, target, ball, position, heading)
        speed = _next_speed(out, carry.speed)
        carry = MarkMemory(
            dataclasses.replace(naive_carry, turned=turned), speed, opponents, age, marking
        )
        return carry, out

    def _sight_opponents(self, obs, position, heading, carry):
        """Each opponent slot from the teammate that sees it nearest, else from memory."""
        entities = np.asarray(obs.entities, np.float64)
        mask = np.asarray(obs.entity_mask)
        n = len(position)
        opponents, age = carry.opponents.copy(), np.minimum(carry.age + 1, NEVER_SEEN)
        nearest = np.full(n, np.inf)
        for i in range(n):
            for j in range(n):
                slot = n - 1 + j
                if not mask[i, slot]:
                    continue
                d = entities[i, slot, _ENTITY_DISTANCE] * self.field_length
                if d >= nearest[j]:
                    continue
                bearing = math.atan2(entities[i, slot, _ENTITY_SIN], entities[i, slot, _ENTITY_COS])
                direction = heading[i] + bearing
                unit = np.array([math.cos(direction), math.sin(direction)])
                opponents[j] = position[i] + d * unit
                nearest[j], age[j] = d, 0
        return opponents, age


def _long_kick_off(original):
    def kick(view, player, play_mode, n):
        if play_mode.startswith("kick_off"):
            wing = np.array([40.0, 24.0 if view.position[player][1] <= 0 else -24.0])
            return rules._kick_to(view, player, wing, 100.0)
        return original(view, player, play_mode, n)

    return kick


def _tackles(original):
    def commands_with_tackles(commands, view, touch, cycle, *, kickable):
        commands = list(original(commands, view, touch, cycle, kickable=kickable))
        for i in range(1, len(commands)):
            if isinstance(commands[i], Kick) or not view.ball_seen[i] or view.stale[i] > 0:
                continue
            d, bearing = float(view.ball_distance[i]), float(view.ball_bearing[i])
            ahead, side = d * math.cos(bearing), d * math.sin(bearing)
            if d > kickable and 0.0 < ahead < 1.7 and abs(side) < 0.9:
                goal = np.array([52.5, 0.0]) - view.position[i]
                angle = math.atan2(goal[1], goal[0]) - view.heading[i]
                commands[i] = Tackle(rules._degrees_clockwise(angle), False)
        return commands

    return commands_with_tackles


def _player(probe: str, turn_scale: float) -> play._Player:
    teams: dict[str, tuple[RoboCupNaiveTeam, int]] = {
        "naive12": (RoboCupNaiveTeam(action="thesis12"), 12),
        "clear12": (Clear(action="thesis12"), 12),
        "screen": (Block(action="sim", turn_scale=turn_scale), 2),
        "bus": (Block(action="sim", turn_scale=turn_scale, bus=True), 2),
        "intercept": (Intercept(action="sim", turn_scale=turn_scale), 2),
        "dribble12": (RoboCupNaiveTeam(action="thesis12", kick_power=35.0), 12),
        "combo12": (RoboCupNaiveTeam(action="thesis12", kick_power=35.0, intercept=True), 12),
        "mark": (Mark(action="sim", turn_scale=turn_scale), 2),
    }
    naive, actions = teams.get(probe, (RoboCupNaiveTeam(action="sim", turn_scale=turn_scale), 2))

    def act(carry: NaiveMemory, obs, key):
        return naive.act(None, carry, obs, key)

    return play._Player(probe, act, naive.init_carry, actions)


def main() -> None:
    if len(sys.argv) < 2 or sys.argv[1] not in PROBES:
        got = sys.argv[1] if len(sys.argv) > 1 else "nothing"
        sys.exit(f"usage: robocup_probe_team.py PROBE [team options]; PROBE is one of "
                 f"{', '.join(PROBES)}, not {got}")
    probe = sys.argv[1]
    if probe == "longko":
        rules._set_piece_kick = _long_kick_off(rules._set_piece_kick)
    if probe == "tackle":
        rules.no_second_touch = _tackles(rules.no_second_touch)
    team.load_robocup_team = lambda spec, action, **kw: _player(probe, kw.get("turn_scale", 180.0))
    from elevens.cli import main as elevens_main

    sys.argv = ["elevens", "robocup", "team", "--team", "naive", *sys.argv[2:]]
    elevens_main()


if __name__ == "__main__":
    main()
