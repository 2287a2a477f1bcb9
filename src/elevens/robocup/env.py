"""RoboCupEnv: the simulator's reset/step contract on a real rcssserver, host-side numpy.

One env owns one server process and one client (2n players + the offline trainer, synch mode).
A step sends one command per player, waits for every player's ``(think)`` and returns the
simulator's containers, so a policy trained in elevens plays here unchanged:

* ``State`` (world frame, numpy leaves) from the trainer's ``see_global`` (ground truth), for the
  critic (``global_state``) and the rewards;
* ``Observation`` [2, n] from each player's *own* percepts (``see`` + ``sense_body``; see
  elevens.robocup.observe for frames, normalisation and what is kept between see messages);
* rewards f32[2, n]: the goal reward from the referee (+1 scorers, -1 the others) plus the
  simulator's shaping terms (elevens.env.reward.reward_terms on the State before/after).

The "sim" action rule (actions f32[2, n, 2] = (move, rot) in [-1, 1], clipped; one command a
cycle because the server takes one body command per cycle):

1. kick: the ball is kickable (the player's latest see shows it, identified or as the close
   ``(B)`` behind, within player_size + ball_size + kickable_margin = 1.085 m) and move > 0:
   ``(kick move*100 0)``, along the body, as the simulator's leg kick goes along the heading;
2. turn: else if |rot| > |move|: ``(turn rot*turn_scale)``; rot > 0 turns clockwise in both
   (simulator heading decreases; server direction increases), so no sign change;
3. dash: else ``(dash |move|*100 0)``, or ``(dash |move|*100 180)`` for move < 0 (backwards: the
   server clamps negative power to 0 since protocol v17, as elevens.robocup.actions does);
   move = rot = 0 sends only ``(done)``.

"thesis12" actions f32[2, n, 12] go through elevens.robocup.actions.actions_to_commands (a kick
with the ball out of reach, by the player's latest see, becomes a dash towards it). Either
way ``State.last_actions`` and the observations' ``last_move``/``last_rot`` hold 2 values: the
clipped (move, rot) for "sim"; for "thesis12" a summary of the command sent (dash: the forward
part of its power, power / 100 * cos(direction), -1 = full backwards; turn: moment / 180; kick,
tackle, no-op: 0).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import shutil
import subprocess
import tempfile
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from types import TracebackType
from typing import Any, NamedTuple, Protocol

import jax
import numpy as np

from elevens.env import observe as observe_lib
from elevens.env import physics
from elevens.env.params import BALL_SPAWN_MODES, SPAWN_MODES, EnvParams
from elevens.env.reward import reward_terms
from elevens.env.state import GlobalState, Observation, State
from elevens.robocup.actions import ACTION_SIZES, ActionScaling, actions_to_commands
from elevens.robocup.client import Cycle, RoboCupClient, ServerDied
from elevens.robocup.external import TeamCommandNotFound, start_team, stop_team, wait_connected
from elevens.robocup.observe import (
    FIELD_LENGTH,
    FIELD_WIDTH,
    GOAL_WIDTH,
    PLAYER_DECAY,
    PerceptMemory,
    body_from_world_heading,
    server_from_world,
    state_from_global,
)
from elevens.robocup.protocol import (
    ChangeView,
    Command,
    Dash,
    GlobalView,
    Kick,
    NoOp,
    ServerParams,
    Turn,
)
from elevens.robocup.rules import MATCH_CLOCK, MatchRoutines, kick_off_positions
from elevens.robocup.server import RcssserverNotFound, ServerAddress, ServerProcess

__all__ = [
    "ACTION_MODES",
    "EPISODE_MODES",
    "OUT_OF_PLAY_MODES",
    "VIEW_WIDTHS",
    "RoboCupConfig",
    "RoboCupEnv",
    "command_summary",
    "robocup_env_params",
    "sim_actions_to_commands",
]

log = logging.getLogger(__name__)

ACTION_MODES = tuple(ACTION_SIZES)
EPISODE_MODES = ("drill", "match")
#: Server options of match episodes over the training ones: the referee drops a ball that
#: nobody plays for 100 cycles in a set piece, as in a match (elevens.robocup.match).
MATCH_EPISODE_OPTIONS = {"server::drop_ball_time": "100"}
VIEW_WIDTHS = {"narrow": 60.0, "normal": 120.0, "wide": 180.0}  # degrees, synch-see (v18+)
# Referee modes after the ball left the field over a side line or a goal line outside the goal
# (drop_ball: out with no last toucher, e.g. a trainer-placed ball).
OUT_OF_PLAY_MODES = frozenset(
    f"{mode}_{side}" for mode in ("kick_in", "corner_kick", "goal_kick") for side in "lr"
) | {"drop_ball"}
_BALL_MARGIN = 1.0  # metres inside the lines where keep_ball_in_play puts the ball back
_EMPTY_VIEW = GlobalView(time=-1, ball=None, players=())  # a cycle without see_global


@dataclasses.dataclass(frozen=True)
class RoboCupConfig:
    """What a RoboCupEnv plays. Frozen; checked on construction."""

    players_per_team: int = 11
    """Players per side, 1..11; unum 1 of each side connects as the goalie."""
    episode_length: int = 400
    """Env steps (server cycles) per episode, counted by the env: server time freezes in
    stoppages. The simulator's EnvParams default."""
    spawn: str = "formation"
    """"formation": the simulator's formation slots scaled to 105 x 68 + noise; "random":
    uniform in the own half, random heading (elevens.env.physics.spawn)."""
    ball_spawn: str = "random"
    """"random" (uniform over the central half of the field, the simulator's default) or
    "centre"."""
    episodes: str = "drill"
    """How an episode is played. "drill": the trainer spawns everyone (``spawn``,
    ``ball_spawn``) into play_on and respawns them after a goal; the policies act in every
    cycle (the thesis' training in the server). "match": as a regulation match: each episode
    starts from the kick-off formation with a kick-off (either side, drawn), the referee
    restarts play after a goal and when the ball goes out, and each elevens side plays under
    the routines a team plays matches with (elevens.robocup.rules.MatchRoutines: kick-off
    moves, set pieces, the goalie's catch and guard, no second touch, stamina pacing) and
    observes the match's clock, so what it learns is what ``elevens robocup match`` plays."""
    keep_ball_in_play: bool = False
    """True: a ball about to leave (or that left) over a side line or a goal line outside the goal
    is put back inside by the trainer, bouncing as off the simulator's walls, and play_on goes on
    (the thesis' shaping phase). False: the referee's rules (kick-ins, corners, goal kicks)."""
    shaping: bool = True
    """Add the simulator's shaping terms to the goal reward (False: goal reward only)."""
    goal_reward: float = 1.0
    """EnvParams.goal_reward."""
    ball_shaping_weight: float = 0.1
    """EnvParams.ball_shaping_weight (w_b, ball velocity towards the opponent goal)."""
    approach_shaping_weight: float = 0.05
    """EnvParams.approach_shaping_weight (w_a, player velocity towards the ball)."""
    possession_shaping_weight: float = 0.0
    """EnvParams.possession_shaping_weight (w_p, having the ball; elevens.env.reward), by
    nearness (``possession_by`` "near"): the trainer sees no touches."""
    possession_radius: float = 2.0
    """EnvParams.possession_radius (metres)."""
    action: str = "sim"
    """"sim": f32[2, n, 2] (move, rot) by the rule in the module docstring; "thesis12":
    f32[2, n, 12] (thesis table 4.1, elevens.robocup.actions)."""
    turn_scale: float = 180.0
    """Turn moment in degrees at rot = 1 for "sim" actions (the server's full range; the actual
    turn shrinks with speed). deg(EnvParams.turn_speed) = 22.9 mimics the simulator's turn rate."""
    view: str = "wide"
    """View width sent once per player after connecting: "wide" (180 deg, a see every 3rd
    cycle: the simulator's field of view), "normal" (120, every 2nd), "narrow" (60, every cycle).
    Sets EnvParams.fov_half_angle to half of it."""
    rcssserver: str | None = None
    """Path of the rcssserver binary (None: $ELEVENS_RCSSSERVER, then PATH)."""
    server_options: Mapping[str, str] = dataclasses.field(default_factory=dict)
    """Extra server options over elevens.robocup.server.TRAINING_OPTIONS."""
    think_timeout_s: float = 2.0
    """How long a step waits for a player's (think) before marking it missing."""
    team_names: tuple[str, str] = ("elevens_l", "elevens_r")
    """Team names of the left (team 0) and right (team 1) side."""
    max_restarts: int = 3
    """Failed server restarts in a row before the env gives up and raises."""
    opponent_cmd: str | None = None
    """Team 1 is another program (e.g. helios-base's ``start.sh -p {port} -P {coach_port} -t
    {team}``; elevens.robocup.external): started with each server, named ``team_names[1]``,
    it plays for itself. The env then connects team 0 and the trainer only; team 1's actions
    are ignored, and its rewards and observations (no percepts of its own) mean nothing."""
    opponent_connect_timeout_s: float = 60.0
    """How long the opponent's players may take to connect."""

    def __post_init__(self) -> None:
        n = self.players_per_team
        if isinstance(n, bool) or not isinstance(n, int) or not 1 <= n <= 11:
            raise ValueError(f"players_per_team={n!r} is invalid: it must be an integer 1..11")
        if isinstance(self.episode_length, bool) or not isinstance(self.episode_length, int) or (
            self.episode_length < 1
        ):
            raise ValueError(
                f"episode_length={self.episode_length!r} is invalid: it must be an integer >= 1"
            )
        choices: dict[str, tuple[str, ...]] = {
            "spawn": SPAWN_MODES,
            "ball_spawn": BALL_SPAWN_MODES,
            "action": ACTION_MODES,
            "episodes": EPISODE_MODES,
            "view": tuple(VIEW_WIDTHS),
        }
        for name, allowed in choices.items():
            if getattr(self, name) not in allowed:
                raise ValueError(
                    f"{name}={getattr(self, name)!r} is invalid: allowed values are {allowed}"
                )
        for name in ("turn_scale", "think_timeout_s"):
            value = getattr(self, name)
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r} is invalid: it must be a finite number > 0")
        if self.max_restarts < 0:
            raise ValueError(f"max_restarts={self.max_restarts!r} is invalid: it must be >= 0")
        if len(self.team_names) != 2 or self.team_names[0] == self.team_names[1]:
            raise ValueError(
                f"team_names={self.team_names!r} is invalid: it needs two different names"
            )
        if self.opponent_cmd is not None and not self.opponent_cmd.strip():
            raise ValueError("opponent_cmd='' is invalid: give the opponent's start command")
        if self.episodes == "match" and self.keep_ball_in_play:
            raise ValueError(
                "keep_ball_in_play=True is invalid with episodes='match': a match's referee "
                "restarts play when the ball goes out; use one or the other"
            )

    @property
    def action_size(self) -> int:
        """Values per player action: 2 for "sim", 12 for "thesis12"."""
        return ACTION_SIZES[self.action]


def robocup_env_params(config: RoboCupConfig) -> EnvParams:
    """The simulator's EnvParams for the rcssserver field (105 x 68, 14.02 m goal), so the
    normalisation, spawns and reward terms use the server's geometry."""
    shaping = 1.0 if config.shaping else 0.0
    return EnvParams(
        players_per_team=config.players_per_team,
        spawn=config.spawn,
        ball_spawn=config.ball_spawn,
        field_length=FIELD_LENGTH,
        field_width=FIELD_WIDTH,
        goal_width=GOAL_WIDTH,
        fov_half_angle=math.radians(VIEW_WIDTHS[config.view] / 2),
        episode_length=config.episode_length,
        goal_reward=config.goal_reward,
        ball_shaping_weight=config.ball_shaping_weight * shaping,
        approach_shaping_weight=config.approach_shaping_weight * shaping,
        possession_shaping_weight=config.possession_shaping_weight * shaping,
        # The trainer sees no touches (the server reports no kicker), so possession is by
        # nearness here.
        possession_by="near",
        possession_radius=config.possession_radius,
    )


def kickable_distance(params: ServerParams | None = None) -> float:
    """player_size + ball_size + kickable_margin (1.085 m for the default player type)."""
    p = params if params is not None else ServerParams.defaults()
    return p.get_float("player_size") + p.get_float("ball_size") + p.get_float("kickable_margin")


def ball_bearings(memory: PerceptMemory) -> np.ndarray:
    """Each player's bearing of the ball f[2, n] (radians, + = left of its body) in its latest
    see; NaN where that see did not show the ball in the view cone."""
    ball = memory.entities[..., -1, :]
    return np.where(memory.mask[..., -1], np.arctan2(ball[..., 2], ball[..., 1]), np.nan)


def sim_actions_to_commands(
    actions: np.ndarray,
    ball_distance: np.ndarray,
    *,
    kickable: float,
    turn_scale: float = 180.0,
    scaling: ActionScaling | None = None,
) -> list[Command]:
    """The "sim" rule (module docstring): actions f32[..., 2] (clipped to [-1, 1]),
    ball_distance f[...] metres (inf when unseen) -> one Command per player, C order."""
    s = scaling if scaling is not None else ActionScaling()
    flat = np.clip(np.asarray(actions, np.float64), -1.0, 1.0).reshape(-1, 2)
    dist = np.asarray(ball_distance, np.float64).reshape(-1)
    commands: list[Command] = []
    for (move, rot), d in zip(flat.tolist(), dist.tolist(), strict=True):
        if move > 0 and d <= kickable:
            commands.append(Kick(move * s.max_kick_power, 0.0))
        elif abs(rot) > abs(move):
            moment = rot * turn_scale
            commands.append(Turn(min(max(moment, s.min_moment), s.max_moment)))
        elif move == 0.0:
            commands.append(NoOp())
        elif move > 0 or s.min_dash_power < 0:
            power = move * (s.max_dash_power if move > 0 else -s.min_dash_power)
            commands.append(Dash(power, 0.0))
        else:
            commands.append(Dash(-move * s.max_dash_power, 180.0))
    return commands


def command_summary(command: Command, s: ActionScaling) -> tuple[float, float]:
    """A thesis12 command as the 2-value (move, rot) the observations carry."""
    if isinstance(command, Dash):
        direction = math.radians(command.direction or 0.0)
        return command.power / s.max_dash_power * math.cos(direction), 0.0
    if isinstance(command, Turn):
        return 0.0, command.moment / s.max_moment
    return 0.0, 0.0


# ------------------------------------------------------------------ injectable server parts
class ServerLike(Protocol):
    """What the env needs of a server process (elevens.robocup.server.ServerProcess)."""

    @property
    def address(self) -> ServerAddress: ...
    def restart(self) -> Any: ...
    def stop(self) -> Any: ...


class ClientLike(Protocol):
    """What the env needs of a client (elevens.robocup.client.RoboCupClient)."""

    def connect(self) -> Cycle: ...
    def step(self, commands: Sequence[Command | Sequence[Command] | None]) -> Cycle: ...
    def reset(
        self,
        positions_srv: np.ndarray,
        body_deg: np.ndarray,
        ball_srv: tuple[float, float] = ...,
        ball_vel: tuple[float, float] = ...,
        play_mode: str = ...,
        recover: bool = ...,
    ) -> Cycle: ...
    def move_ball(self, x: float, y: float, vx: float = ..., vy: float = ...) -> None: ...
    def change_mode(self, mode: str) -> None: ...
    def close(self) -> None: ...


def _default_server(config: RoboCupConfig) -> ServerLike:
    extra = MATCH_EPISODE_OPTIONS if config.episodes == "match" else {}
    options = {**extra, **config.server_options}
    return ServerProcess(config.rcssserver, options=options).start()


def _default_client(server: ServerLike, config: RoboCupConfig) -> ClientLike:
    # Given the process itself, the client reports its exit status and log in ServerDied.
    target = server if isinstance(server, ServerProcess) else server.address
    return RoboCupClient(
        target,
        config.players_per_team,
        team_names=config.team_names,
        think_timeout_s=config.think_timeout_s,
        one_team=config.opponent_cmd is not None,
    )


@functools.cache
def _cpu() -> jax.Device:
    """Host-side jax work (spawn, reward, critic state) stays on the CPU next to the sockets."""
    return jax.devices("cpu")[0]


# A server that died shows as ServerDied; a socket error on the way counts the same.
_DEAD = (ServerDied, OSError)


class _Placement(NamedTuple):
    """A spawn (elevens.env.physics.Spawn) as numpy, world frame."""

    positions: np.ndarray  # f64[2n, 2]
    headings: np.ndarray  # f64[2n] radians
    ball_position: np.ndarray  # f64[2]


def _out_of_play_mode(cycle: Cycle) -> str | None:
    """The out-of-play mode the referee announced this cycle, if any (it may already have
    switched on, e.g. drop_ball -> play_on within one cycle)."""
    if cycle.play_mode in OUT_OF_PLAY_MODES:
        return cycle.play_mode
    for player in cycle.players:
        for hear in player.hears:
            if hear.play_mode in OUT_OF_PLAY_MODES:
                return hear.play_mode
    return None


def _replace(state: State, **leaves: Any) -> State:
    """``state.replace`` with numpy leaves (typed as jax arrays on State)."""
    return dataclasses.replace(state, **leaves)


class RoboCupEnv:
    """The simulator's reset/step contract on rcssserver (see the module docstring).

    ``reset(seed)`` -> (State, Observation); ``step(actions)`` -> (State, Observation,
    rewards f32[2, n], done, info). Leaves are numpy. Not thread-safe; one episode at a time. A
    context manager: ``close()`` says bye to the server and stops it.

    info: ``pose_valid`` bool[2, n] and ``stale`` i32[2, n] (PerceptMemory), ``restarted`` (the
    server died and was restarted: the returned state is a fresh episode's first, done is True),
    ``restarts`` (total), ``missed`` (players whose (think) did not arrive this cycle),
    ``malformed`` (messages dropped this cycle), ``play_mode``, ``score`` i32[2] (this episode,
    team 0 first), ``goals`` i32[2] (this step), ``goal_reward``/``ball_shaping``/
    ``approach_shaping``/``possession_shaping`` f32[2, n] (the reward terms), ``holder`` f32[2]
    (who has the ball, elevens.env.reward.ball_holder), ``scripted`` bool[2, n] (a match
    routine played for the player this cycle, not its policy), ``ball_returned``
    (keep_ball_in_play moved the ball back), ``server_time``, ``truncated`` (= done).
    """

    def __init__(
        self,
        config: RoboCupConfig | None = None,
        *,
        server_factory: Callable[[RoboCupConfig], ServerLike] | None = None,
        client_factory: Callable[[ServerLike, RoboCupConfig], ClientLike] | None = None,
    ) -> None:
        self.config = config if config is not None else RoboCupConfig()
        self.params: EnvParams = robocup_env_params(self.config)
        self._server_factory = server_factory or _default_server
        self._client_factory = client_factory or _default_client
        self._server: ServerLike | None = None
        self._client: ClientLike | None = None
        n = self.config.players_per_team
        self._match = self.config.episodes == "match"
        # A match's observations count time as a team in a match does (rules.MATCH_CLOCK).
        observed = (
            dataclasses.replace(self.params, episode_length=MATCH_CLOCK)
            if self._match
            else self.params
        )
        self._memory = PerceptMemory(observed, self.config.team_names, PLAYER_DECAY)
        self._routines: list[MatchRoutines] = []
        self._scaling = ActionScaling()
        self._kickable = kickable_distance()
        self._rng = np.random.default_rng()
        self._state: State | None = None
        self._start_team = np.zeros((2, n, 2))  # spawn points in each team's frame
        self._start_world = np.zeros((2 * n, 2))  # the same in the world frame, [2n, 2]
        self._last_cycle: Cycle | None = None
        self._opponent: subprocess.Popen[bytes] | None = None
        self._opponent_dir: Path | None = None
        self._last_actions = np.zeros((2, n, 2), np.float32)
        self._score = np.zeros(2, np.int32)
        self._step = 0
        self.restarts = 0
        with jax.default_device(_cpu()):
            self._spawn = jax.jit(physics.spawn)
            self._reward_terms = jax.jit(reward_terms)
            self._global_state = jax.jit(observe_lib.global_state)

    # ----------------------------------------------------------------- properties
    @property
    def players_per_team(self) -> int:
        return self.config.players_per_team

    @property
    def num_players(self) -> int:
        return 2 * self.config.players_per_team

    @property
    def action_shape(self) -> tuple[int, int, int]:
        """(2, n, 2) for "sim" actions, (2, n, 12) for "thesis12"."""
        return (2, self.config.players_per_team, self.config.action_size)

    # ---------------------------------------------------------------------- api
    def reset(self, seed: int | None = None) -> tuple[State, Observation]:
        """Start an episode: spawn everyone through the trainer. seed: the spawn draw (the
        server's own noise is not seedable)."""
        if seed is not None:
            self._rng = np.random.default_rng(seed)
        if self._client is None:
            self._connect_with_retries()
        try:
            return self._reset_episode()
        except _DEAD:
            self._recover()
            assert self._state is not None
            return self._state, self._observe()

    def step(
        self, actions: np.ndarray
    ) -> tuple[State, Observation, np.ndarray, bool, dict[str, Any]]:
        """One server cycle. actions f32[2, n, 2] ("sim") or f32[2, n, 12] ("thesis12").

        Returns (state, obs [2, n], rewards f32[2, n], done, info). After a goal the returned
        state and observation are the respawned ones (one more server cycle passes for it).
        """
        commands, applied = self._commands(actions)
        if self._client is None or self._state is None:
            raise RuntimeError("RoboCupEnv.step called before reset()")
        ruled, scripted = self._apply_routines(commands)
        before = self._state
        try:
            cycle = self._client.step(self._own(ruled))
        except _DEAD as error:
            log.warning("rcssserver died (%s); restarting", error)
            self._recover()
            return self._restarted_result()
        self._step += 1
        self._last_cycle = cycle
        self._last_actions = applied
        self._memory.update(cycle.players)
        for routines in self._routines:
            routines.observe_mode(cycle.play_mode)
        goals = np.asarray(cycle.goals, np.int32).reshape(2)
        self._score = self._score + goals
        after = self._build_state(cycle, previous=before)
        with jax.default_device(_cpu()):
            terms = self._reward_terms(
                goals,
                after.ball_position,
                after.ball_velocity,
                after.velocities,
                before.ball_position,
                after.positions,
                self.params,
            )
        goal_r, ball_r, approach_r, possession_r, rewards = (
            np.asarray(t, np.float32)
            for t in (terms.goal, terms.ball, terms.approach, terms.possession, terms.total)
        )
        self._state = after
        play_mode = cycle.play_mode
        ball_returned = False
        try:
            if goals.any() and not self._match:
                play_mode = self._respawn().play_mode
            elif self.config.keep_ball_in_play:
                ball_returned = self._keep_ball_in_play(cycle, before)
                if ball_returned:
                    play_mode = "play_on"
        except _DEAD as error:
            log.warning("rcssserver died (%s); restarting", error)
            self._recover()
            return self._restarted_result()
        done = self._step >= self.config.episode_length
        info = self._info(cycle, restarted=False, done=done)
        info.update(
            play_mode=play_mode,
            goals=goals,
            goal_reward=goal_r,
            ball_shaping=ball_r,
            approach_shaping=approach_r,
            possession_shaping=possession_r,
            holder=np.asarray(terms.holder, np.float32),
            scripted=scripted.reshape(2, -1),
            ball_returned=ball_returned,
        )
        assert self._state is not None
        return self._state, self._observe(), rewards, done, info

    def global_state(self, state: State) -> GlobalState:
        """The critic's state (elevens.env.observe.global_state), numpy leaves."""
        with jax.default_device(_cpu()):
            out = self._global_state(state, self.params)
        return jax.tree.map(np.asarray, out)

    def close(self) -> None:
        """Disconnect and stop the server. Idempotent."""
        client, server = self._client, self._server
        self._client = self._server = None
        self._stop_opponent()
        if client is not None:
            try:
                client.close()
            except Exception as error:  # closing must not hide the reason we are closing
                log.warning("closing the rcssserver client failed: %s", error)
        if server is not None:
            try:
                server.stop()
            except Exception as error:
                log.warning("stopping rcssserver failed: %s", error)

    def __enter__(self) -> RoboCupEnv:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ------------------------------------------------------------------ actions
    def _commands(self, actions: np.ndarray) -> tuple[list[Command], np.ndarray]:
        """Validated actions -> (one Command per player, the 2-value actions applied)."""
        expected = self.action_shape
        arr = np.asarray(actions)
        if arr.shape != expected:
            what = "(move, rot)" if self.config.action == "sim" else "12 thesis values"
            raise ValueError(
                f"actions have shape {arr.shape}, expected {expected} (team, player, {what})"
            )
        if not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)):
            raise ValueError(f"actions have dtype {arr.dtype}, expected a float dtype")
        bad = ~np.isfinite(arr)
        if bad.any():
            where = tuple(int(i) for i in np.argwhere(bad)[0])
            raise ValueError(
                f"actions{list(where)} is {float(arr[where])!r}: actions must be finite numbers "
                f"in [-1, 1] of shape {expected}"
            )
        if self.config.action == "sim":
            applied = np.clip(arr, -1.0, 1.0).astype(np.float32)
            commands = sim_actions_to_commands(
                applied,
                self._memory.ball_distance,
                kickable=self._kickable,
                turn_scale=self.config.turn_scale,
                scaling=self._scaling,
            )
            return commands, applied
        commands = actions_to_commands(
            arr, self._scaling, ball_distance=self._memory.ball_distance,
            ball_bearing=ball_bearings(self._memory), kickable=self._kickable,
        )
        summary = [command_summary(c, self._scaling) for c in commands]
        applied = np.asarray(summary, np.float32).reshape(2, self.players_per_team, 2)
        return commands, applied

    # ------------------------------------------------------------ episode parts
    def _draw_spawn(self) -> _Placement:
        """The simulator's own spawn rule (elevens.env.physics.spawn) on the server's field."""
        key = jax.random.key(int(self._rng.integers(0, 2**31 - 1)))
        with jax.default_device(_cpu()):
            placed = self._spawn(key, self.params)
        return _Placement(*(np.asarray(leaf, np.float64) for leaf in placed))

    def _place(self, placed: _Placement, play_mode: str = "play_on") -> Cycle:
        """Send a spawn (world frame) to the server through the trainer."""
        assert self._client is not None
        n = self.players_per_team
        ball = server_from_world(placed.ball_position)
        return self._client.reset(
            server_from_world(placed.positions).reshape(2, n, 2),
            body_from_world_heading(placed.headings).reshape(2, n),
            ball_srv=(float(ball[0]), float(ball[1])),
            ball_vel=(0.0, 0.0),
            play_mode=play_mode,
        )

    def _kick_off_placement(self, kicker: int) -> _Placement:
        """Both teams in the kick-off formation (``kicker``'s taker at the ball), world frame."""
        n = self.players_per_team
        sign = np.array([1.0, -1.0])[:, None, None]
        team = np.stack([kick_off_positions(n, taker=side == kicker) for side in (0, 1)])
        headings = np.repeat(np.array([0.0, np.pi]), n)
        return _Placement((team * sign).reshape(2 * n, 2), headings, np.zeros(2))

    def _start_play(self, placed: _Placement, play_mode: str = "play_on") -> Cycle:
        """Place everyone and reset the percepts to the spawn (known poses)."""
        n = self.players_per_team
        cycle = self._place(placed, play_mode)
        sign = np.array([1.0, -1.0])[:, None, None]
        self._start_team = placed.positions.reshape(2, n, 2) * sign
        headings = placed.headings.reshape(2, n) + np.array([0.0, np.pi])[:, None]
        self._memory.reset(self._start_team, headings)
        self._memory.update(cycle.players, advance=False)
        self._last_cycle = cycle
        return cycle

    def _reset_episode(self) -> tuple[State, Observation]:
        n = self.players_per_team
        self._step = 0
        self._score = np.zeros(2, np.int32)
        self._last_actions = np.zeros((2, n, 2), np.float32)
        self._state = None
        if self._match:
            kicker = int(self._rng.integers(2))
            placed = self._kick_off_placement(kicker)
            self._start_world = placed.positions
            cycle = self._start_play(placed, ("kick_off_l", "kick_off_r")[kicker])
            # The team's own clock and formation, as RoboCupTeam observes them in a match.
            self._start_team = np.stack([kick_off_positions(n, taker=False)] * 2)
            elevens_sides = (0,) if self.config.opponent_cmd is not None else (0, 1)
            self._routines = [
                MatchRoutines(side, n, kickable=self._kickable) for side in elevens_sides
            ]
            for routines in self._routines:
                routines.observe_mode(cycle.play_mode)
        else:
            placed = self._draw_spawn()
            self._start_world = placed.positions
            cycle = self._start_play(placed)
        self._state = self._build_state(cycle, previous=None, spawn=placed)
        return self._state, self._observe()

    def _respawn(self) -> Cycle:
        """After a goal: everyone back to (new) kick-off positions, as the simulator does."""
        placed = self._draw_spawn()
        self._start_world = placed.positions
        cycle = self._start_play(placed)
        self._state = self._build_state(cycle, previous=None, spawn=placed)
        return cycle

    def _build_state(
        self, cycle: Cycle, previous: State | None, spawn: _Placement | None = None
    ) -> State:
        """State from the cycle's see_global. Right after a spawn velocities are 0 (the
        simulator's respawn) and a missing view falls back to the spawn itself."""
        n = self.players_per_team
        if previous is None and spawn is not None:
            leaves: dict[str, Any] = dict(
                positions=spawn.positions.astype(np.float32),
                headings=spawn.headings.astype(np.float32),
                velocities=np.zeros((2 * n, 2), np.float32),
                last_actions=np.zeros((2 * n, 2), np.float32),
                start_positions=spawn.positions.astype(np.float32),
                ball_position=spawn.ball_position.astype(np.float32),
                ball_velocity=np.zeros(2, np.float32),
                score=self._score,
                step=np.asarray(self._step, np.int32),
            )
            previous = State(**leaves)
        kwargs: dict[str, Any] = dict(
            players_per_team=n,
            team_names=self.config.team_names,
            last_actions=self._last_actions.reshape(2 * n, 2),
            start_positions=self._start_world,
            score=self._score,
            step=self._step,
            previous=previous,
        )
        state = state_from_global(cycle.world or _EMPTY_VIEW, **kwargs)
        if spawn is not None:
            state = _replace(state, velocities=np.zeros_like(state.velocities))
        return state

    def _observe(self) -> Observation:
        step = self._routines[0].clock % MATCH_CLOCK if self._match else self._step
        return self._memory.observation(step, self._last_actions, self._start_team)

    def _apply_routines(
        self, commands: list[Command]
    ) -> tuple[list[Command | None], np.ndarray]:
        """In match episodes, each elevens side's commands with its match routines applied
        (for the cycle last observed); in drills, ``commands`` unchanged. Also bool[2n]: the
        players a routine played for."""
        out: list[Command | None] = list(commands)
        scripted = np.zeros(len(out), bool)
        if not self._match or self._last_cycle is None:
            return out, scripted
        n = self.players_per_team
        for routines in self._routines:
            own = slice(routines.side * n, (routines.side + 1) * n)
            out[own], _ = routines.apply(out[own], self._memory, self._last_cycle)
            scripted[own] = routines.scripted
        return out, scripted

    def _keep_ball_in_play(self, cycle: Cycle, before: State) -> bool:
        """Bounce a ball that left (or is about to leave) over a side line or a goal line outside
        the goal back into play, as off the simulator's walls; True if it acted.

        About to leave (position + velocity is out): the trainer turns the velocity inwards
        now. Left (the referee announced a kick-in, corner, goal kick or drop ball this cycle,
        or the ball lies on or beyond a line): the trainer puts it just inside, where it went
        out, with the velocity it had before (the referee zeroes it) turned inwards, and
        restores play_on. Velocities lose wall_restitution on the bounce, as in the simulator.
        """
        assert self._client is not None and self._state is not None
        p = self.params
        half = np.array([p.half_length, p.half_width], np.float64)
        inside = half - _BALL_MARGIN
        goal_half = float(p.goal_width) / 2
        now = self._state
        now_position = np.asarray(now.ball_position, np.float64)
        announced = _out_of_play_mode(cycle)
        out = announced is not None or bool(np.any(np.abs(now_position) >= half - 1e-3))
        if out:
            velocity = np.asarray(before.ball_velocity, np.float64)
            crossing = np.asarray(before.ball_position, np.float64) + velocity
            moved = announced is not None and announced.startswith(("corner_kick", "goal_kick"))
            # Corners and goal kicks move the ball away from where it went out.
            position = crossing if moved and np.any(np.abs(crossing) > half) else now_position
            side = abs(position[1]) >= p.half_width - 1e-3 or (
                announced is not None and announced.startswith("kick_in")
            )
            end = abs(position[0]) >= p.half_length - 1e-3 or moved
        else:
            velocity = np.asarray(now.ball_velocity, np.float64)
            ahead = now_position + velocity
            side = abs(ahead[1]) > p.half_width
            end = abs(ahead[0]) > p.half_length and abs(ahead[1]) > goal_half
            if not (side or end):
                return False
            position = now_position
        restitution = float(p.wall_restitution)
        for axis, bounced in ((0, end), (1, side)):
            if bounced:  # point the velocity away from the line it crossed
                toward = np.sign(position[axis]) or 1.0
                velocity[axis] = -toward * restitution * abs(velocity[axis])
        position = np.clip(position, -inside, inside)
        ball = server_from_world(position)
        ball_velocity = server_from_world(velocity)
        self._client.move_ball(
            float(ball[0]), float(ball[1]), float(ball_velocity[0]), float(ball_velocity[1])
        )
        if cycle.play_mode != "play_on":
            self._client.change_mode("play_on")
        self._state = _replace(
            now,
            ball_position=position.astype(np.float32),
            ball_velocity=velocity.astype(np.float32),
        )
        return True

    # -------------------------------------------------------------- robustness
    def _connect(self) -> None:
        if self._server is None:
            self._server = self._server_factory(self.config)
        else:
            self._server.restart()
        self._client = self._client_factory(self._server, self.config)
        self._client.connect()
        server_params = getattr(self._client, "server_params", None)
        if isinstance(server_params, ServerParams):
            self._scaling = ActionScaling.from_server_params(server_params)
            self._kickable = kickable_distance(server_params)
        if self.config.opponent_cmd is not None:
            self._start_opponent()
        view = [ChangeView(self.config.view)] * len(self._own(list(range(self.num_players))))
        self._client.step(view)

    def _own(self, commands: list[Any]) -> list[Any]:
        """The commands of the players this env connects: all, or team 0's with an external
        opponent."""
        return commands[: self.players_per_team] if self.config.opponent_cmd else commands

    def _start_opponent(self) -> None:
        """(Re)start the external team 1 and wait until its players are in."""
        assert self._client is not None and self._server is not None
        sides = getattr(self._client, "sides", (0,))
        if tuple(sides) != (0,):
            raise RuntimeError(
                f"our team was given the side {sides!r}, not the left: another team was "
                "connected to this server before us"
            )
        self._stop_opponent()
        log_path = getattr(self._server, "log_path", None)
        self._opponent_dir = Path(tempfile.mkdtemp(prefix="elevens-opponent-"))
        output = self._opponent_dir / "opponent.log"
        assert self.config.opponent_cmd is not None
        self._opponent = start_team(
            self.config.opponent_cmd, self._server.address, self.config.team_names[1], output
        )
        wait_connected(
            log_path, self.config.team_names[1], self.players_per_team, self._opponent, output,
            self.config.opponent_connect_timeout_s,
        )

    def _stop_opponent(self) -> None:
        if self._opponent is not None:
            stop_team(self._opponent)
            self._opponent = None
        if self._opponent_dir is not None:
            shutil.rmtree(self._opponent_dir, ignore_errors=True)
            self._opponent_dir = None

    def _connect_with_retries(self) -> None:
        failures = 0
        while True:
            try:
                self._connect()
                return
            except (RcssserverNotFound, TeamCommandNotFound):
                raise
            except (RuntimeError, OSError) as error:  # ServerDied, a failed start, a socket
                failures += 1
                if failures > self.config.max_restarts:
                    raise RuntimeError(
                        f"rcssserver could not be (re)started after {failures} attempts: {error}"
                    ) from error
                log.warning("connecting to rcssserver failed (%s); retrying", error)
                self._drop_client()

    def _drop_client(self) -> None:
        client, self._client = self._client, None
        if client is not None:
            try:
                client.close()
            except Exception as error:
                log.debug("closing a dead client: %s", error)

    def _recover(self) -> None:
        """Restart the server, reconnect and start a fresh episode; counts the restart."""
        self.restarts += 1
        failures = 0
        while True:
            self._drop_client()
            try:
                self._connect_with_retries()
                self._reset_episode()
                return
            except (RcssserverNotFound, TeamCommandNotFound):
                raise
            except _DEAD as error:
                failures += 1
                if failures > self.config.max_restarts:
                    raise RuntimeError(
                        f"rcssserver keeps dying after a restart ({failures} attempts): {error}"
                    ) from error

    def _restarted_result(
        self,
    ) -> tuple[State, Observation, np.ndarray, bool, dict[str, Any]]:
        n = self.players_per_team
        zeros = np.zeros((2, n), np.float32)
        assert self._last_cycle is not None
        info = self._info(self._last_cycle, restarted=True, done=True)
        info.update(
            goals=np.zeros(2, np.int32),
            goal_reward=zeros,
            ball_shaping=zeros,
            approach_shaping=zeros,
            possession_shaping=zeros,
            holder=np.zeros(2, np.float32),
            scripted=np.zeros((2, n), bool),
            ball_returned=False,
        )
        assert self._state is not None
        return self._state, self._observe(), zeros.copy(), True, info

    def _info(self, cycle: Cycle, *, restarted: bool, done: bool) -> dict[str, Any]:
        return {
            "pose_valid": self._memory.pose_valid.copy(),
            "stale": self._memory.stale.copy(),
            "restarted": restarted,
            "restarts": self.restarts,
            "missed": int(cycle.missed),
            "malformed": int(cycle.malformed),
            "play_mode": cycle.play_mode,
            "score": self._score.copy(),
            "server_time": int(cycle.server_time),
            "truncated": done,
        }
