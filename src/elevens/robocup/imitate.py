"""Learn a team's play from its rcssserver game logs (behaviour cloning).

A demonstrating team (helios-base, or any binary) plays matches with logging on
(``elevens robocup match --log-dir``). Each match leaves a ``.rcg`` (every cycle's positions,
velocities and bodies) and a ``.rcl`` (every command each player sent). From them:

* **observations**: the simulator's observation of each demonstrating player, from the logged
  state, as an elevens player would see it in a match (``elevens.env.observe.observe`` on the
  server's field with the wide view's cone; the entities' last actions zeroed and the start
  points set to the kick-off formation, as ``RoboCupTeam`` builds them);
* **labels**: each player's body command in the "sim" action space (``robocup.env``):
  ``(dash p d)`` -> move ``p / 100 * cos d``; ``(turn m)`` -> rot ``m / 180``; ``(kick p d)`` ->
  move ``p / 100`` (the sim rule kicks when move > 0 with the ball kickable); or, with
  ``action="thesis12"``, the thesis's 12-value action of the command (:func:`thesis12_label`,
  tackles included). Catches, moves and every cycle that is not ``play_on`` are left out of the
  loss, as the set-piece and goalie routines play them in a match.

:func:`imitate` fits an elevens policy's deterministic action (``tanh`` of its Gaussian's
mean) to these labels with :func:`command_loss`, on sequences of consecutive cycles through the
LSTM, and writes a team folder that ``elevens robocup match --team0 FOLDER`` plays, and that
``--run.init-from`` fine-tunes with PPO (a 12-value team in ``elevens robocup train
--network.actions 12`` only: the simulator has no such action). The spread of the Gaussian is
not fitted (it is what the starting networks give). Between two see messages a player's view
is held, as in a match (``see_period``).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import re
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import optax

from elevens.env import observe as observe_lib
from elevens.env.params import EnvParams
from elevens.env.state import ENTITY_FEATURES, SELF_FEATURES, Observation, State
from elevens.robocup.bodies import EVERY_CYCLE_FEATURES
from elevens.robocup.observe import PLAYER_DECAY
from elevens.robocup.rules import kick_off_positions

__all__ = [
    "Demonstrations",
    "GameLog",
    "ImitationResult",
    "command_kind",
    "command_loss",
    "demonstrations",
    "imitate",
    "imitate_from_logs",
    "intent_labels",
    "label_of_command",
    "log_pairs",
    "read_game_log",
    "thesis12_label",
    "thesis12_loss",
]

log = logging.getLogger(__name__)

_SHOW = re.compile(r"^\(show (\d+) \(\(b\) (\S+) (\S+) (\S+) (\S+)\)")
# ((l 3) type state x y vx vy body neck ...
_PLAYER = re.compile(
    r"\(\((l|r) (\d+)\) \d+ (0x[0-9a-f]+) (\S+) (\S+) (\S+) (\S+) (\S+) (\S+)"
)
_PLAYMODE = re.compile(r"^\(playmode (\d+) (\S+)\)")
_TEAM = re.compile(r"^\(team \d+ (\S+) (\S+) \d+ \d+")
_RECV = re.compile(r"^(\d+),(\d+)\tRecv (\S+)_(\d+): (.*)$")
_COMMAND = re.compile(r"\((dash|turn|kick|tackle|catch|move)((?: [^()\s]+)*)\)")
_FLAGS = {"on": 1.0, "off": -1.0}  # (tackle DIR on|off): the foul flag
_TURN_SCALE = 180.0  # degrees at rot = 1: RoboCupTeam's default turn_scale
_MAX_POWER = 100.0  # server::maxpower and max_dash_power
_LABEL_LIMIT = 0.95  # keep targets off tanh's ends, where atanh diverges
_KICK_OFF = "kick_off"


@dataclasses.dataclass(frozen=True)
class GameLog:
    """One match as the server logged it: ``T`` shows (one a cycle in synch play), the server's
    frame (x to the right team's goal, y down)."""

    team_names: tuple[str, str]
    time: np.ndarray  # i32[T] the show's cycle
    play_mode: list[str]  # [T]
    positions: np.ndarray  # f32[T, 2, n, 2] (left, right), unum order; NaN when absent
    velocities: np.ndarray  # f32[T, 2, n, 2] server m/cycle
    body_deg: np.ndarray  # f32[T, 2, n]
    ball: np.ndarray  # f32[T, 4] x, y, vx, vy
    commands: dict[tuple[str, int, int], tuple[str, tuple[float, ...]]]
    """(team name, unum, cycle) -> the body command of that cycle (name, arguments), from the
    .rcl lines of play (stopped time 0)."""


def _float(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"non-finite number {text!r}")
    return value


def read_game_log(rcg: str | Path, rcl: str | Path, players_per_team: int = 11) -> GameLog:
    """Parse one match's ``.rcg`` (version 4-6 text) and ``.rcl``. A file that is not such a log
    is a ``ValueError`` naming it and what was expected."""
    rcg, rcl = Path(rcg), Path(rcl)
    n = players_per_team
    times: list[int] = []
    modes: list[str] = []
    rows: list[np.ndarray] = []
    balls: list[tuple[float, ...]] = []
    names: tuple[str, str] | None = None
    mode = "before_kick_off"
    with rcg.open(encoding="utf-8", errors="replace") as lines:
        header = lines.readline()
        if not header.startswith("ULG"):
            raise ValueError(
                f"{rcg} is not a text game log: it starts {header[:20]!r}, expected 'ULG4'-'ULG6'"
            )
        for number, line in enumerate(lines, start=2):
            if line.startswith("(playmode "):
                found = _PLAYMODE.match(line)
                if found:
                    mode = found.group(2)
                continue
            if line.startswith("(team "):
                found = _TEAM.match(line)
                if found:
                    names = (found.group(1), found.group(2))
                continue
            if not line.startswith("(show "):
                continue
            show = _SHOW.match(line)
            if show is None:
                raise ValueError(f"{rcg}:{number}: a show line without the ball: {line[:80]!r}")
            row = np.full((2, n, 5), np.nan, np.float32)
            try:
                ball = tuple(_float(show.group(i)) for i in range(2, 6))
                for player in _PLAYER.finditer(line):
                    side, unum = int(player.group(1) == "r"), int(player.group(2))
                    if 1 <= unum <= n and int(player.group(3), 16) != 0:
                        x, y, vx, vy, body = (_float(player.group(i)) for i in range(4, 9))
                        row[side, unum - 1] = (x, y, vx, vy, body)
            except ValueError as error:
                raise ValueError(f"{rcg}:{number}: {error}") from None
            times.append(int(show.group(1)))
            modes.append(mode)
            rows.append(row)
            balls.append(ball)
    if names is None or not times:
        raise ValueError(f"{rcg} has no (team ...) or (show ...) lines: not a game log")
    states = np.stack(rows)
    return GameLog(
        team_names=names,
        time=np.asarray(times, np.int32),
        play_mode=modes,
        positions=states[..., 0:2],
        velocities=states[..., 2:4],
        body_deg=states[..., 4],
        ball=np.asarray(balls, np.float32),
        commands=_read_commands(rcl, names),
    )


def _read_commands(
    rcl: Path, names: tuple[str, str]
) -> dict[tuple[str, int, int], tuple[str, tuple[float, ...]]]:
    commands: dict[tuple[str, int, int], tuple[str, tuple[float, ...]]] = {}
    with rcl.open(encoding="utf-8", errors="replace") as lines:
        for line in lines:
            found = _RECV.match(line)
            if found is None or found.group(2) != "0" or found.group(3) not in names:
                continue
            body = _COMMAND.search(found.group(5))
            if body is None:
                continue
            try:
                arguments = tuple(_FLAGS.get(a) or float(a) for a in body.group(2).split())
            except ValueError:
                continue  # a malformed argument: no label
            key = (found.group(3), int(found.group(4)), int(found.group(1)))
            commands[key] = (body.group(1), arguments)
    return commands


def label_of_command(name: str, arguments: Sequence[float]) -> tuple[float, float] | None:
    """A body command -> its (move, rot) in the "sim" action space, or None where that space
    has no such command (tackle, catch, move). See the module docstring."""
    if name == "dash":
        power = arguments[0] if arguments else 0.0
        direction = math.radians(arguments[1]) if len(arguments) > 1 else 0.0
        move = power / _MAX_POWER * math.cos(direction)
        return _limit(move), 0.0
    if name == "turn":
        return 0.0, _limit((arguments[0] if arguments else 0.0) / _TURN_SCALE)
    if name == "kick":
        return _limit(max(arguments[0] if arguments else 0.0, 1.0) / _MAX_POWER), 0.0
    return None


_SCORES = 5  # the selection scores at the head of a thesis12 action (ActionIndex 0-4)
# Which of the 12 values each selected command (dash, kick, turn, tackle, no-op) uses.
_PARAMETERS = np.zeros((_SCORES, 12), bool)
for _choice, _used in enumerate(((5, 6), (7, 8), (9,), (10, 11), ())):
    _PARAMETERS[_choice, list(_used)] = True


def thesis12_label(name: str, arguments: Sequence[float]) -> np.ndarray | None:
    """A body command -> its 12-value action (``elevens.robocup.actions``, thesis table 4.1):
    +1 for its selection score, -1 for the others, its parameters in [-1, 1] (the others 0);
    None for catch and move (the goalie's and the set pieces' routines send those)."""
    label = np.zeros(12, np.float32)
    label[:_SCORES] = -1.0
    first = arguments[0] if arguments else 0.0
    second = arguments[1] if len(arguments) > 1 else 0.0
    if name == "dash":
        power, direction = first / _MAX_POWER, second
        if abs(direction) > 90.0:  # the thesis dashes backwards with a negative power
            power, direction = -power, math.remainder(direction + 180.0, 360.0)
        label[[0, 5, 6]] = 1.0, power, direction / 90.0
    elif name == "kick":
        label[[1, 7, 8]] = 1.0, 2.0 * first / _MAX_POWER - 1.0, second / 180.0
    elif name == "turn":
        label[[2, 9]] = 1.0, first / _TURN_SCALE
    elif name == "tackle":
        label[[3, 10, 11]] = 1.0, 1.0 if second > 0 else -1.0, first / 90.0
    else:
        return None
    label[_SCORES:] = np.clip(label[_SCORES:], -_LABEL_LIMIT, _LABEL_LIMIT)
    return label


def _limit(value: float) -> float:
    return float(min(max(value, -_LABEL_LIMIT), _LABEL_LIMIT))


@dataclasses.dataclass(frozen=True)
class Demonstrations:
    """One team's play in one match, per player: observations and labels, ``T`` cycles."""

    observations: Observation  # leading axes [n, T]
    actions: np.ndarray  # f32[n, T, 2] (move, rot), or f32[n, T, 12] the thesis's action
    valid: np.ndarray  # bool[n, T]: a labelled play_on cycle (in the loss)
    reset: np.ndarray  # bool[T]: a jump in the log (restart the memory)

    @property
    def labelled(self) -> int:
        return int(self.valid.sum())


def demonstrations(
    game: GameLog,
    team_name: str,
    params: EnvParams,
    *,
    episode_length: int = 400,
    see_period: int = 3,
    labels: str = "commands",
    lookahead: int = 10,
    action: str = "sim",
) -> Demonstrations:
    """The observations and labels of ``team_name``'s players in ``game`` (see the module
    docstring). ``params``: the server field's EnvParams (``robocup_env_params``);
    ``episode_length``: the period of the time feature, as ``RoboCupTeam`` restarts it;
    ``see_period``: cycles between two see messages (3 for the wide view in synch mode). As in
    ``PerceptMemory``, a player's view of the field (its pose, the ball, the others) is that of
    its latest see, while its last action and the time are fresh every cycle.

    ``labels``: "commands" labels each cycle with the command sent (the module docstring);
    "intent" with the command that takes the player where it will be ``lookahead`` cycles on
    (:func:`intent_labels`).

    ``action``: "sim" labels (move, rot) as above; "thesis12" the 12-value action of each
    command sent (:func:`thesis12_label`; labels must be "commands")."""
    if action not in ACTIONS:
        raise ValueError(f"action={action!r} is invalid: it must be one of {', '.join(ACTIONS)}")
    if action == "thesis12" and labels != "commands":
        raise ValueError(f"labels={labels!r} is for the sim action only: thesis12 labels the "
                         "commands sent")
    if labels not in LABELS:
        raise ValueError(f"labels={labels!r} is invalid: it must be one of {', '.join(LABELS)}")
    if lookahead < 1:
        raise ValueError(f"lookahead={lookahead!r} is invalid: it must be >= 1")
    if see_period < 1:
        raise ValueError(f"see_period={see_period!r} is invalid: it must be >= 1")
    if team_name not in game.team_names:
        raise ValueError(
            f"team {team_name!r} did not play in this match: the teams were "
            f"{game.team_names[0]!r} and {game.team_names[1]!r}"
        )
    side = game.team_names.index(team_name)
    n = params.players_per_team
    steps = len(game.time)
    actions = np.zeros((n, steps, 2), np.float32)
    full = np.zeros((n, steps, 12), np.float32)
    valid = np.zeros((n, steps), bool)
    for i in range(n):
        for t, (cycle, mode) in enumerate(zip(game.time.tolist(), game.play_mode, strict=True)):
            command = game.commands.get((team_name, i + 1, cycle))
            label = label_of_command(*command) if command is not None else None
            if label is not None:
                actions[i, t] = label
                valid[i, t] = mode == "play_on"
            if action == "thesis12" and command is not None:
                twelve = thesis12_label(*command)
                if twelve is not None:
                    full[i, t] = twelve
                    valid[i, t] = mode == "play_on"
    present = np.isfinite(game.positions[:, side, :, 0]).T  # [n, T]
    valid &= present
    if labels == "intent":
        sent = [[game.commands.get((team_name, i + 1, c), ("",))[0] for c in game.time]
                for i in range(n)]
        kicks = np.array([[name == "kick" for name in row] for row in sent])
        unlabelled = np.array([[name in _NO_LABEL for name in row] for row in sent])
        play_on = np.array([mode == "play_on" for mode in game.play_mode])
        valid = play_on[None, :] & present & ~unlabelled
        actions = np.where(kicks[..., None], actions, intent_labels(game, side, n, lookahead))
    # Own previous action in the self features, as RoboCupTeam feeds its last output back.
    previous = np.concatenate([np.zeros((n, 1, 2), np.float32), actions[:, :-1]], axis=1)
    steps_since = _steps_since_kick_off(game) % episode_length
    obs = _stale(_observations(game, side, params, steps_since, previous), see_period)
    reset = np.ones(steps, bool)
    reset[1:] = np.diff(game.time) != 1
    reset[1:] &= np.diff(game.time) != 0  # stopped time repeats a cycle: still continuous
    if action == "thesis12":
        actions = full  # the (move, rot) summary above stays the last action it observes
    return Demonstrations(observations=obs, actions=actions, valid=valid, reset=reset)


LABELS = ("commands", "intent")
ACTIONS = ("sim", "thesis12")
_NO_LABEL = ("tackle", "catch", "move")  # commands the "sim" action space has no label for
_AIM = 30.0  # degrees: a target further off the body direction is turned to first
_STILL = 0.05  # m/cycle: slower than this towards the target is standing still
_TOP_SPEED = 1.0  # m/cycle at full dash, about the default player type's


def intent_labels(game: GameLog, side: int, n: int, lookahead: int) -> np.ndarray:
    """f32[n, T, 2]: for each player and cycle, the (move, rot) that heads for where the
    player will be ``lookahead`` cycles on (or at the end of its stretch of play_on): nothing
    when it will stay within ``_STILL`` m a cycle; else a turn to the target's bearing when that
    is more than ``_AIM`` degrees off the body (a dash backwards when it lies behind), and a
    dash at the needed share of top speed otherwise."""
    steps = len(game.time)
    play_on = np.array([mode == "play_on" for mode in game.play_mode])
    stretch_end = np.arange(steps)
    for t in range(steps - 2, -1, -1):
        if play_on[t] and play_on[t + 1] and game.time[t + 1] - game.time[t] == 1:
            stretch_end[t] = stretch_end[t + 1]
    future = np.minimum(np.arange(steps) + lookahead, stretch_end)
    cycles = np.maximum(future - np.arange(steps), 1)[:, None]
    position = np.nan_to_num(game.positions[:, side])  # [T, n, 2] server frame
    offset = position[future] - position
    speed = np.hypot(offset[..., 0], offset[..., 1]) / cycles
    bearing = np.degrees(np.arctan2(offset[..., 1], offset[..., 0]))  # server frame, like body
    relative = (bearing - np.nan_to_num(game.body_deg[:, side]) + 180.0) % 360.0 - 180.0
    move = np.minimum(speed / _TOP_SPEED, _LABEL_LIMIT)
    behind = np.abs(relative) >= 180.0 - _AIM
    turn = (np.abs(relative) > _AIM) & ~behind
    label = np.zeros((steps, n, 2), np.float32)
    label[..., 0] = np.where(turn, 0.0, np.where(behind, -move, move))
    label[..., 1] = np.where(turn, relative / _TURN_SCALE, 0.0)
    label[speed < _STILL] = 0.0
    return label.transpose(1, 0, 2)


def _steps_since_kick_off(game: GameLog) -> np.ndarray:
    steps = np.zeros(len(game.time), np.int64)
    count = 0
    for t, mode in enumerate(game.play_mode):
        count = 0 if mode.startswith(_KICK_OFF) else count + 1
        steps[t] = count
    return steps


def _world_states(game: GameLog, side: int, params: EnvParams, previous: np.ndarray) -> State:
    """[T]-batched simulator States (world frame: the left team attacks +x, y up)."""
    n = params.players_per_team
    steps = len(game.time)
    positions = np.nan_to_num(game.positions).reshape(steps, 2 * n, 2) * np.array([1.0, -1.0])
    velocities = (
        np.nan_to_num(game.velocities).reshape(steps, 2 * n, 2)
        * np.array([1.0, -1.0])
        / PLAYER_DECAY
    )
    headings = -np.radians(np.nan_to_num(game.body_deg).reshape(steps, 2 * n))
    last_actions = np.zeros((steps, 2, n, 2), np.float32)
    last_actions[:, side] = previous.transpose(1, 0, 2)
    formation = kick_off_positions(n, taker=False)
    start = np.concatenate([formation, -formation])  # team 1's own frame is mirrored
    leaves: dict[str, Any] = dict(  # numpy leaves, [T]-batched
        positions=positions.astype(np.float32),
        headings=headings.astype(np.float32),
        velocities=velocities.astype(np.float32),
        last_actions=last_actions.reshape(steps, 2 * n, 2),
        start_positions=np.broadcast_to(start, (steps, 2 * n, 2)).astype(np.float32),
        ball_position=(game.ball[:, :2] * np.array([1.0, -1.0])).astype(np.float32),
        ball_velocity=(game.ball[:, 2:] * np.array([1.0, -1.0])).astype(np.float32),
        score=np.zeros((steps, 2), np.int32),
        step=np.zeros(steps, np.int32),
    )
    return State(**leaves)


def _observations(
    game: GameLog, side: int, params: EnvParams, steps_since: np.ndarray, previous: np.ndarray
) -> Observation:
    """Observations [n, T] of ``side``'s players (see the module docstring)."""
    states = _world_states(game, side, params, previous)
    chunks = []
    for start in range(0, len(game.time), 1024):
        part = jax.tree.map(lambda leaf, s=start: leaf[s : s + 1024], states)
        chunks.append(jax.device_get(_observe_batch(part, params)))
    obs = jax.tree.map(lambda *leaves: np.concatenate(leaves), *chunks)
    obs = jax.tree.map(lambda leaf: np.swapaxes(leaf[:, side], 0, 1), obs)  # [n, T, ...]
    entities = obs.entities.copy()
    entities[..., ENTITY_LAST_ACTIONS] = 0.0  # a see message shows no one's last action
    features = obs.self_features.copy()
    time_index = SELF_FEATURES.index("time_left")
    features[..., time_index] = np.clip(1.0 - steps_since / params.episode_length, 0.0, 1.0)
    return Observation(self_features=features, entities=entities, entity_mask=obs.entity_mask)


# One compiled batch observation for every match and team (params are static and hashable).
_observe_batch = jax.jit(jax.vmap(observe_lib.observe, in_axes=(0, None)), static_argnums=1)
ENTITY_LAST_ACTIONS = slice(
    ENTITY_FEATURES.index("last_move"), ENTITY_FEATURES.index("last_rot") + 1
)


def _stale(obs: Observation, see_period: int) -> Observation:
    """Each player's view held from its latest see (player i sees when (t + i) % period == 0),
    all but the fresh self features (``EVERY_CYCLE_FEATURES``)."""
    if see_period == 1:
        return obs
    n, steps = obs.entity_mask.shape[:2]
    t = np.arange(steps)[None, :]
    source = np.maximum(t - (t + np.arange(n)[:, None]) % see_period, 0)  # [n, T]
    rows = np.arange(n)[:, None]
    features = obs.self_features[rows, source].copy()
    features[..., EVERY_CYCLE_FEATURES] = obs.self_features[..., EVERY_CYCLE_FEATURES]
    return Observation(
        self_features=features,
        entities=obs.entities[rows, source],
        entity_mask=obs.entity_mask[rows, source],
    )
_IDLE = 0.05  # |move| and |rot| below this: a dash or turn too small to count
_MARGIN = 0.1  # how much the chosen part of an action must exceed the other


def command_kind(action: jax.Array) -> jax.Array:
    """i32[...]: what the "sim" rule makes of (move, rot) f[..., 2] away from the ball: 0
    nothing (both small), 1 a dash (|move| >= |rot|), 2 a turn."""
    move, rot = jnp.abs(action[..., 0]), jnp.abs(action[..., 1])
    kind = jnp.where(rot > move, 2, 1)
    return jnp.where(jnp.maximum(move, rot) < _IDLE, 0, kind)


def thesis12_loss(mean: jax.Array, label: jax.Array) -> tuple[jax.Array, ...]:
    """For 12-value actions (:func:`thesis12_label`), per cycle: (loss, 1.0 where the largest
    selection score is the label's command, the mean |error| of that command's parameters).

    The five scores are fitted to the label's +1 / -1 and the largest picks the command, so
    however uncertain the fit, one command is sent with its own parameters (a (move, rot)
    regression blends a dash and a turn into a weak dash). The parameters of the label's
    command are fitted; the others are free. (A softmax cross-entropy on the scores stayed at
    the class prior on a task this fit learns.)"""
    choice = jnp.argmax(label[..., :_SCORES], axis=-1)
    action = jnp.tanh(mean)
    scores = jnp.sum((action[..., :_SCORES] - label[..., :_SCORES]) ** 2, axis=-1)
    used = jnp.asarray(_PARAMETERS)[choice]
    error = jnp.where(used, action - label, 0.0)
    squared = jnp.sum(error**2, axis=-1)
    agree = (jnp.argmax(mean[..., :_SCORES], axis=-1) == choice).astype(jnp.float32)
    count = jnp.maximum(used.sum(axis=-1), 1)
    return scores + squared, agree, jnp.abs(error).sum(axis=-1) / count


def command_loss(action: jax.Array, label: jax.Array) -> jax.Array:
    """f32[...]: how far (move, rot) ``action`` is from giving ``label``'s command.

    The "sim" rule dashes (or kicks) when |move| >= |rot| and turns otherwise, so a regression
    to the mean of a dash (0.9, 0) and a turn (0, 0.5) would be a dash at half power that never
    turns. Instead: the chosen part is fitted to the label, and the other part must stay at
    least a margin below it (squared hinge); an idle label pulls both to zero."""
    move, rot = action[..., 0], action[..., 1]
    kind = command_kind(label)
    margin_dash = jax.nn.relu(jnp.abs(rot) - jnp.abs(move) + _MARGIN) ** 2
    margin_turn = jax.nn.relu(jnp.abs(move) - jnp.abs(rot) + _MARGIN) ** 2
    dash = (move - label[..., 0]) ** 2 + margin_dash
    turn = (rot - label[..., 1]) ** 2 + margin_turn
    idle = move**2 + rot**2
    return jnp.where(kind == 2, turn, jnp.where(kind == 1, dash, idle))


@dataclasses.dataclass(frozen=True)
class ImitationResult:
    """What :func:`imitate` did."""

    steps: int
    samples: int  # labelled player-cycles in the data
    first_loss: float  # mean training loss over the first 5% of steps
    last_loss: float  # ... and the last 5%
    held_out_agreement: float  # share of held-out labelled cycles where the deterministic
    # action gives the demonstrator's kind of command (dash or kick, turn, nothing; nan without
    # any held-out sequence)
    held_out_move_error: float  # mean |move - label| of the deterministic action, held out
    # (12-value actions: the mean |error| of the label command's parameters)
    wall_s: float
    held_out_agreement_before: float = math.nan  # the two held-out figures of the starting
    held_out_move_error_before: float = math.nan  # networks, before the first step


def _sequences(
    demos: Sequence[Demonstrations], length: int
) -> tuple[Observation, np.ndarray, np.ndarray, np.ndarray]:
    """Cut every player's trajectory into sequences of ``length`` cycles with at least one
    labelled cycle: (obs [S, L], actions [S, L, 2], valid [S, L], reset [S, L])."""
    obs_parts, action_parts, valid_parts, reset_parts = [], [], [], []
    for demo in demos:
        steps = demo.actions.shape[1] // length * length
        if steps == 0:
            continue

        def cut(leaf: np.ndarray, steps: int = steps) -> np.ndarray:
            return leaf[:, :steps].reshape(-1, length, *leaf.shape[2:])

        n = demo.actions.shape[0]
        valid = cut(demo.valid)
        keep = valid.any(axis=1)
        reset = np.broadcast_to(demo.reset[None, :steps], (n, steps)).reshape(-1, length).copy()
        reset[:, 0] = True
        obs_parts.append(
            jax.tree.map(lambda leaf, keep=keep: cut(leaf)[keep], demo.observations)
        )
        action_parts.append(cut(demo.actions)[keep])
        valid_parts.append(valid[keep])
        reset_parts.append(reset[keep])
    if not action_parts:
        raise ValueError(f"no demonstrations of at least {length} cycles")
    obs = jax.tree.map(lambda *leaves: np.concatenate(leaves), *obs_parts)
    return (
        obs,
        np.concatenate(action_parts),
        np.concatenate(valid_parts),
        np.concatenate(reset_parts),
    )


def imitate(
    policy: Any,
    params: Any,
    demos: Sequence[Demonstrations],
    *,
    steps: int = 2000,
    batch_size: int = 32,
    sequence_length: int = 32,
    learning_rate: float = 1e-3,
    held_out: float = 0.1,
    hide_last_action: bool = True,
    seed: int = 0,
    max_minutes: float | None = None,
    progress: Callable[[int, float], None] | None = None,
) -> tuple[Any, ImitationResult]:
    """Fit ``policy`` (an AttentionPolicy) from ``params`` to the demonstrations; returns the new
    params and an :class:`ImitationResult`. ``held_out``: the share of sequences kept out of
    training to measure the fit; ``max_minutes`` stops early.

    ``hide_last_action``: replace the player's own last action in the self features by uniform
    noise, so the policy learns to do without it. In a match ``RoboCupTeam`` feeds back the
    policy's raw (move, rot), which is never a demonstrator's command ((move, 0) or (0, rot)):
    a policy fitted on the demonstrator's last commands met inputs it had never seen, blended
    its outputs and fed the blend back again (it dashed in 99.5% of its commands)."""
    if steps < 1 or batch_size < 1 or sequence_length < 1:
        raise ValueError(
            f"steps={steps}, batch_size={batch_size}, sequence_length={sequence_length}: "
            "each must be >= 1"
        )
    if not 0.0 <= held_out < 1.0:
        raise ValueError(f"held_out={held_out!r} is invalid: it must be in [0, 1)")
    began = time.perf_counter()
    obs, actions, valid, reset = _sequences(demos, sequence_length)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(actions))
    test_count = int(len(order) * held_out)
    test, train = order[:test_count], order[test_count:]
    if len(train) == 0:
        raise ValueError("no training sequences left after holding some out")
    optimizer = optax.chain(optax.clip_by_global_norm(1.0), optax.adam(learning_rate))
    opt_state = optimizer.init(params)

    def losses(p: Any, o: Observation, a: jax.Array, v: jax.Array, r: jax.Array) -> Any:
        carry = policy.initial_carry(a.shape[:1])
        _, output = policy.apply(p, carry, o, r, 1, method=policy.unroll)
        weight = v.astype(jnp.float32)
        count = jnp.maximum(weight.sum(), 1.0)
        if a.shape[-1] == 12:
            fit, agree, move_error = thesis12_loss(output.mean, a)
        else:
            action = output.distribution().mode()
            fit = command_loss(action, a)
            agree = (command_kind(action) == command_kind(a)).astype(jnp.float32)
            move_error = jnp.abs(action[..., 0] - a[..., 0])
        total = (fit * weight).sum() / count
        return total, (
            (agree * weight).sum() / count,
            (move_error * weight).sum() / count,
        )

    @jax.jit
    def update(p: Any, state: Any, o: Observation, a: Any, v: Any, r: Any) -> Any:
        (loss, _), grads = jax.value_and_grad(losses, has_aux=True)(p, o, a, v, r)
        changes, state = optimizer.update(grads, state, p)
        return optax.apply_updates(p, changes), state, loss

    evaluate = jax.jit(losses)

    last = [SELF_FEATURES.index("last_move"), SELF_FEATURES.index("last_rot")]

    def batch(rows: np.ndarray) -> tuple[Any, ...]:
        features = obs.self_features[rows]
        if hide_last_action:
            features[..., last] = rng.uniform(-1.0, 1.0, (*features.shape[:-1], 2))
        shown = Observation(
            self_features=features, entities=obs.entities[rows], entity_mask=obs.entity_mask[rows]
        )
        return (
            jax.tree.map(jnp.asarray, shown),
            jnp.asarray(actions[rows]),
            jnp.asarray(valid[rows]),
            jnp.asarray(reset[rows]),
        )

    def held_out_figures(p: Any) -> tuple[float, float]:
        """(agreement, move error) over the held-out sequences, (nan, nan) without any."""
        if not len(test):
            return math.nan, math.nan
        totals = np.zeros(2)
        for part in np.array_split(test, max(1, len(test) // 256)):
            totals += np.asarray(evaluate(p, *batch(part))[1], np.float64) * len(part)
        agreement, error = (totals / len(test)).tolist()
        return agreement, error

    agreement_before, error_before = held_out_figures(params)
    history = []
    done = 0
    for step in range(steps):
        rows = train[rng.integers(0, len(train), batch_size)]
        params, opt_state, loss = update(params, opt_state, *batch(rows))
        history.append(float(loss))
        done = step + 1
        if progress is not None:
            progress(done, history[-1])
        if max_minutes is not None and time.perf_counter() - began > 60.0 * max_minutes:
            break
    held_agreement, held_error = held_out_figures(params)
    window = max(1, done // 20)
    result = ImitationResult(
        steps=done,
        samples=int(valid.sum()),
        first_loss=float(np.mean(history[:window])),
        last_loss=float(np.mean(history[-window:])),
        held_out_agreement=held_agreement,
        held_out_move_error=held_error,
        wall_s=time.perf_counter() - began,
        held_out_agreement_before=agreement_before,
        held_out_move_error_before=error_before,
    )
    return params, result


def log_pairs(directory: str | Path) -> list[tuple[Path, Path]]:
    """Every (.rcg, .rcl) pair under ``directory`` (``elevens robocup match --log-dir`` writes
    one folder per match); an empty list when there is none."""
    pairs = []
    for rcg in sorted(Path(directory).rglob("*.rcg")):
        rcl = rcg.with_suffix(".rcl")
        if rcl.is_file():
            pairs.append((rcg, rcl))
    return pairs


def imitate_from_logs(
    log_dirs: Sequence[str | Path],
    team_names: Sequence[str],
    out: str | Path,
    *,
    init_from: str = "elevens-11v11",
    players_per_team: int = 11,
    steps: int = 2000,
    batch_size: int = 32,
    sequence_length: int = 32,
    learning_rate: float = 1e-3,
    see_period: int = 3,
    labels: str = "commands",
    lookahead: int = 10,
    action: str = "sim",
    max_minutes: float | None = None,
    seed: int = 0,
    print_fn: Callable[[str], None] = print,
) -> ImitationResult:
    """Read every match under ``log_dirs``, fit the networks of ``init_from`` (a shipped team,
    exported folder or checkpoint) to the play of the teams named ``team_names`` in them, and
    write the result as a team folder ``out`` (networks.npz, config.json, MODEL_CARD.md) on the
    server's field. Raises ``ValueError`` naming what is missing when no log holds such a team."""
    from elevens.robocup.env import RoboCupConfig, robocup_env_params
    from elevens.runs.teams import load_learner_params
    from elevens.teams.trained import save_networks
    from elevens.train.config import apply_overrides

    pairs = [pair for directory in log_dirs for pair in log_pairs(directory)]
    if not pairs:
        raise ValueError(
            f"no .rcg/.rcl pair under {', '.join(map(str, log_dirs))}: write them with "
            "`elevens robocup match --log-dir DIR`"
        )
    config, learner_params = load_learner_params(init_from)
    env_params = robocup_env_params(RoboCupConfig(players_per_team=players_per_team))
    demos: list[Demonstrations] = []
    seen_names: set[str] = set()
    for rcg, rcl in pairs:
        game = read_game_log(rcg, rcl, players_per_team)
        seen_names.update(game.team_names)
        for name in team_names:
            if name in game.team_names:
                demo = demonstrations(
                    game, name, env_params, see_period=see_period, labels=labels,
                    lookahead=lookahead, action=action,
                )
                demos.append(demo)
        print_fn(f"read {rcg.name}: {', '.join(game.team_names)}")
    if not demos:
        raise ValueError(
            f"none of the teams {', '.join(map(repr, team_names))} played in the logs; "
            f"the logs' teams: {', '.join(sorted(seen_names))}"
        )
    actions = 12 if action == "thesis12" else 2
    network = dataclasses.replace(config.learner.network, actions=actions)
    policy = network.policy()
    start = learner_params.policy
    if actions != config.learner.network.actions:
        # A new action head; the encoders, attention and LSTM start from init_from's.
        first = jax.tree.map(lambda leaf: jnp.asarray(leaf[:, 0]), demos[0].observations)
        n = first.self_features.shape[0]
        fresh = policy.init(jax.random.key(seed), policy.initial_carry((n,)), first,
                            jnp.ones(n, bool))
        start = jax.tree.map(
            lambda new, old: old if np.shape(old) == np.shape(new) else new, fresh, start
        )

    def progress(step: int, loss: float) -> None:
        if step % 100 == 0:
            print_fn(f"step {step}: loss {loss:.3f}")

    policy_params, result = imitate(
        policy, start, demos, steps=steps, batch_size=batch_size,
        sequence_length=sequence_length, learning_rate=learning_rate, seed=seed,
        max_minutes=max_minutes, progress=progress,
    )
    overrides: dict[str, Any] = {
        "env.field_length": float(env_params.field_length),
        "env.field_width": float(env_params.field_width),
        "env.goal_width": float(env_params.goal_width),
        "network.actions": actions,
    }
    if players_per_team != config.learner.players_per_team:
        # A valid config for the new team size: one minibatch of whole games.
        overrides["env.players_per_team"] = players_per_team
        overrides["ppo.minibatch_size"] = players_per_team * config.learner.games_per_iteration
    saved = apply_overrides(config, overrides).validate()
    card = _model_card(init_from, team_names, pairs, result)
    networks = {"policy": jax.device_get(policy_params), "critic": learner_params.critic}
    save_networks(out, networks, saved.to_dict(), card)
    return result


def _model_card(
    init_from: str,
    team_names: Sequence[str],
    pairs: Sequence[tuple[Path, Path]],
    result: ImitationResult,
) -> str:
    lines = [
        "# A team learned from game logs (behaviour cloning)",
        "",
        f"- Demonstrators: {', '.join(team_names)}, in {len(pairs)} logged matches.",
        f"- Started from: {init_from}.",
        f"- {result.steps} steps on {result.samples} labelled player-cycles in "
        f"{result.wall_s / 60:.1f} min.",
        f"- Training loss: {result.first_loss:.3f} (first 5% of steps) -> "
        f"{result.last_loss:.3f} (last 5%).",
        f"- Held out: the demonstrator's kind of command (dash or kick, turn, nothing) in "
        f"{result.held_out_agreement:.1%} of labelled cycles "
        f"({result.held_out_agreement_before:.1%} before the first step).",
        f"- Held-out mean |move - label| of the deterministic action (12-value actions: "
        f"|parameter - label| of the label's command): {result.held_out_move_error:.3f} "
        f"({result.held_out_move_error_before:.3f} before the first step).",
        "- Made by `elevens robocup imitate` (elevens.robocup.imitate).",
        "",
    ]
    return "\n".join(lines)
