"""One elevens team in a real rcssserver match: n players of one side, no trainer.

``RoboCupTeam(spec).play(address)`` connects the team's players (the goalie first) to a server
that someone else runs (``elevens robocup match`` or a competition's), plays until time_over
and returns the score. Each cycle: the players' percepts go into a PerceptMemory (the same
observations as RoboCupEnv), the policy acts, its (move, rot) actions become commands by the
"sim" rule, and elevens.robocup.rules replaces some of them (kick-off formation, set pieces,
the goalie's catch and its guard of the goal, no second touch by a set piece's taker).

Nothing is compiled after the first connection: :meth:`RoboCupTeam.warm_up` runs every jitted
function once before ``(init)`` goes out, so the first cycles of a synch-mode match answer
within the server's 1.25 s and none is skipped. In real-time mode (100 ms cycles) a cycle that
starts before a player's command went out is counted as late (``late_player_cycles``); the
command then acts one cycle later and is never sent twice.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable
from typing import Any

import jax
import numpy as np

from elevens.env.state import Observation
from elevens.robocup.actions import ActionScaling, actions_to_commands
from elevens.robocup.client import Cycle, RoboCupClient, ServerDied
from elevens.robocup.env import (
    RoboCupConfig,
    ball_bearings,
    command_summary,
    kickable_distance,
    robocup_env_params,
    sim_actions_to_commands,
)
from elevens.robocup.observe import PLAYER_DECAY, PerceptMemory
from elevens.robocup.play import load_robocup_team
from elevens.robocup.protocol import ChangeView, Command, ServerParams
from elevens.robocup.rules import MATCH_CLOCK, MatchRoutines, kick_off_positions, mode_kind
from elevens.robocup.server import ServerAddress

__all__ = ["RoboCupTeam", "TeamResult"]

log = logging.getLogger(__name__)



@dataclasses.dataclass(frozen=True)
class TeamResult:
    """One match from one team's side."""

    team: str
    side: int  # 0 left, 1 right
    goals_for: int
    goals_against: int
    cycles: int  # cycles this client answered
    server_time: int  # the server's clock at the end
    late_player_cycles: int  # real time: player-cycles that began before its command went out
    missed: int  # player-cycles without a (think) / sense_body in time
    catches: int  # catch commands sent
    set_piece_cycles: int  # cycles in which a scripted set-piece routine acted
    wall_s: float
    warm_up_s: float
    ended: str  # "time_over", "server_exit" or "stopped"

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


class RoboCupTeam:
    """An elevens team (``spec``: naive, random, a shipped name or a checkpoint) that plays
    one side of a match (see the module docstring)."""

    def __init__(
        self,
        spec: str,
        *,
        players_per_team: int = 11,
        team_name: str = "elevens",
        opponent_name: str = "",
        synch: bool = True,
        rules: bool = True,
        view: str = "wide",
        deterministic: bool = True,
        turn_scale: float = 180.0,
        seed: int = 0,
        dead_reckoning: bool = False,
    ) -> None:
        self.spec = spec
        self.dead_reckoning = dead_reckoning
        self.config = RoboCupConfig(
            players_per_team=players_per_team,
            view=view,
            episode_length=MATCH_CLOCK,
            # An opponent whose name we were not told is any other named team: a made-up name
            # here would hide every opponent from the observations.
            team_names=(team_name, opponent_name),
            turn_scale=turn_scale,
        )
        self.team_name = team_name
        self.opponent_name = opponent_name
        self.synch = synch
        self.rules = rules
        self.params = robocup_env_params(self.config)
        self.player = load_robocup_team(
            spec, "sim", deterministic=deterministic, turn_scale=turn_scale, any_action=True
        )
        self.key = jax.random.key(seed)
        self.warm_up_s = 0.0
        self._warm = False

    @property
    def n(self) -> int:
        return self.config.players_per_team

    def _observation(
        self, memory: PerceptMemory, side: int, step: int, last: np.ndarray
    ) -> Observation:
        n = self.n
        start = np.zeros((2, n, 2))
        start[side] = kick_off_positions(n, taker=False)
        actions = np.zeros((2, n, 2), np.float32)
        actions[side] = last
        obs = memory.observation(step % MATCH_CLOCK, actions, start)
        return jax.tree.map(lambda leaf: leaf[side], obs)

    def _commands(
        self, actions: Any, ball_distance: np.ndarray, kickable: float, scaling: ActionScaling,
        ball_bearing: np.ndarray | None = None,
    ) -> tuple[np.ndarray, list[Command | None]]:
        """The policy's actions -> (the (move, rot) its observations carry next, one command
        per player): the "sim" rule for (move, rot), the thesis's table 4.1 for 12 values
        (a kick out of reach becomes a dash towards the ball; ``ball_bearing`` NaN or None:
        where the player did not see it in its view cone)."""
        values = np.clip(np.asarray(actions, np.float32), -1.0, 1.0)
        if self.player.actions == 12:
            sent = actions_to_commands(
                values, scaling, ball_distance=ball_distance, ball_bearing=ball_bearing,
                kickable=kickable,
            )
            last = np.array([command_summary(c, scaling) for c in sent], np.float32)
            return last, list(sent)
        sent = sim_actions_to_commands(
            values, ball_distance, kickable=kickable, turn_scale=self.config.turn_scale
        )
        return values, list(sent)

    def warm_up(self) -> float:
        """Run the policy (and with it every jitted function) once on an empty observation;
        the seconds it took. Call before connecting."""
        began = time.perf_counter()
        memory = PerceptMemory(self.params, self.config.team_names, PLAYER_DECAY)
        obs = self._observation(memory, 0, 0, np.zeros((self.n, 2), np.float32))
        carry = self.player.init_carry(self.n)
        for _ in range(2):  # the second call checks that nothing compiles again
            carry, actions = self.player.act(carry, obs, self.key)
            np.asarray(actions)
        self.warm_up_s = time.perf_counter() - began
        self._warm = True
        return self.warm_up_s

    def play(
        self,
        address: ServerAddress,
        *,
        on_connect: Callable[[int], None] | None = None,
        max_cycles: int | None = None,
        step_hook: Callable[[int], None] | None = None,
    ) -> TeamResult:
        """Connect, play until time_over (or the server exits, or ``max_cycles``), say bye.

        ``on_connect(side)`` runs once the players are in; ``step_hook(cycle)`` runs before
        each policy call (tests use it to make a call slow on purpose)."""
        if not self._warm:
            self.warm_up()
        client = RoboCupClient(
            address,
            self.n,
            team_names=self.config.team_names,
            one_team=True,
            trainer=False,
            eye=False,
            synch=self.synch,
            think_timeout_s=2.0 if self.synch else 0.5,
            connect_timeout_s=20.0,
        )
        began = time.perf_counter()
        with client:
            cycle = client.connect()
            side = client.sides[0]
            if on_connect is not None:
                on_connect(side)
            return self._loop(client, cycle, side, began, max_cycles, step_hook)

    def _loop(
        self,
        client: RoboCupClient,
        cycle: Cycle,
        side: int,
        began: float,
        max_cycles: int | None,
        step_hook: Callable[[int], None] | None,
    ) -> TeamResult:
        n = self.n
        memory = PerceptMemory(
            self.params, client.team_names, PLAYER_DECAY, dead_reckoning=self.dead_reckoning
        )
        positions = np.zeros((2, n, 2))
        positions[side] = kick_off_positions(n, taker=False)
        memory.reset(positions, np.zeros((2, n)))
        params = client.server_params
        kickable = kickable_distance(params if isinstance(params, ServerParams) else None)
        scaling = ActionScaling.from_server_params(
            params if isinstance(params, ServerParams) else None
        )
        carry = self.player.init_carry(n)
        key = self.key
        last = np.zeros((n, 2), np.float32)
        counts = dict(cycles=0, missed=0)
        routines = MatchRoutines(side, n, kickable=kickable, previous_mode=cycle.play_mode)
        ended = "stopped"
        cycle = client.step([ChangeView(self.config.view)] * n)
        cycle = client.step([None] * n)  # real time: the sensors queued while connecting
        setup_late = client.stats.stale_thinks
        sent: dict[tuple[int, int], Command | None] = {}
        try:
            while max_cycles is None or counts["cycles"] < max_cycles:
                memory.update(cycle.players, commands=sent)
                mode = cycle.play_mode
                if mode_kind(mode, side) == "over":
                    ended = "time_over"
                    break
                clock = routines.observe_mode(mode)
                if step_hook is not None:
                    step_hook(counts["cycles"])
                key, act_key = jax.random.split(key)
                obs = self._observation(memory, side, clock, last)
                carry, actions = self.player.act(carry, obs, act_key)
                last, commands = self._commands(
                    actions, memory.ball_distance[side], kickable, scaling,
                    ball_bearings(memory)[side],
                )
                if self.rules:
                    commands, _ = routines.apply(commands, memory, cycle)
                else:
                    routines.clock += 1
                cycle = client.step(commands)
                sent = {(side, i): command for i, command in enumerate(commands)}
                counts["cycles"] += 1
                counts["missed"] += cycle.missed
        except ServerDied:
            ended = "server_exit"  # auto_mode exits the server after the game
        goals = client.score
        return TeamResult(
            team=self.player.name,
            side=side,
            goals_for=goals[side],
            goals_against=goals[1 - side],
            cycles=counts["cycles"],
            server_time=int(cycle.server_time),
            late_player_cycles=int(client.stats.stale_thinks - setup_late),
            missed=counts["missed"],
            catches=routines.catches,
            set_piece_cycles=routines.set_piece_cycles,
            wall_s=time.perf_counter() - began,
            warm_up_s=self.warm_up_s,
            ended=ended,
        )
