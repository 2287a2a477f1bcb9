"""RoboCupEnv (elevens.robocup.env).

Most tests drive the env through a scripted fake client (a tiny world that answers with
see_global and emulated see messages, or with recorded ones), so they need no server. The
integration tests at the end run a real rcssserver and are skipped without one.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import signal
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import jax
import numpy as np
import pytest

from elevens.env.reward import reward_terms
from elevens.env.state import (
    NUM_CONTEXT_FEATURES,
    NUM_ENTITY_FEATURES,
    NUM_PLAYER_FEATURES,
    NUM_SELF_FEATURES,
    SELF_FEATURES,
    GlobalState,
    Observation,
    State,
)
from elevens.nets.policy import AttentionPolicy
from elevens.robocup.actions import ActionIndex, actions_to_commands
from elevens.robocup.client import Cycle, PlayerCycle, ServerDied
from elevens.robocup.env import (
    RoboCupConfig,
    RoboCupEnv,
    robocup_env_params,
    sim_actions_to_commands,
)
from elevens.robocup.localize import LANDMARKS
from elevens.robocup.protocol import (
    BallState,
    ChangeView,
    Command,
    Dash,
    GlobalView,
    Kick,
    NoOp,
    PlayerState,
    SeeMessage,
    Turn,
    parse_message,
)
from elevens.robocup.server import ServerAddress
from elevens.teams.network import NetworkTeam
from tests.robocup.conftest import needs_rcssserver

DATA = Path(__file__).resolve().parents[1] / "data" / "rcss"
S = {name: i for i, name in enumerate(SELF_FEATURES)}


# --------------------------------------------------------------------------- fakes
def emulate_see(
    time: int,
    me: tuple[float, float, float],
    ball: tuple[float, float],
    others: Sequence[tuple[str, int, float, float]] = (),
) -> SeeMessage:
    """A 180-degree see of flags, ball and players (exact distances, whole degrees), server
    frame: me = (x, y, body_deg)."""
    x, y, body = me
    parts = []

    def rel(px: float, py: float) -> tuple[float, float]:
        d = math.hypot(px - x, py - y)
        a = math.degrees(math.atan2(py - y, px - x)) - body
        return d, (a + 180.0) % 360.0 - 180.0

    for name, (fx, fy) in LANDMARKS.items():
        d, a = rel(fx, fy)
        if abs(a) <= 90:
            parts.append(f"(({name}) {d:.1f} {round(a)})")
    d, a = rel(*ball)
    if abs(a) <= 90:
        parts.append(f"((b) {d:.2f} {round(a)})")
    for team, unum, px, py in others:
        d, a = rel(px, py)
        if abs(a) <= 90 and d > 0:
            parts.append(f'((p "{team}" {unum}) {d:.1f} {round(a)})')
    message = parse_message(f"(see {time} {' '.join(parts)})")
    assert isinstance(message, SeeMessage)
    return message


class FakeServer:
    def __init__(self) -> None:
        self.address = ServerAddress.from_port(20000)
        self.restarts = 0
        self.stopped = False

    def restart(self) -> FakeServer:
        self.restarts += 1
        return self

    def stop(self) -> None:
        self.stopped = True


class FakeClient:
    """A scripted server: players stand where the trainer put them, the ball rolls with its
    velocity; ``events`` (one dict per step) add goals, play modes, ball moves or a death."""

    def __init__(self, n: int, names: tuple[str, str], recorded: bool = False) -> None:
        self.n = n
        self.names = names
        self.recorded = recorded
        self.time = 0
        self.positions = np.zeros((2, n, 2))
        self.body = np.zeros((2, n))
        self.velocities = np.zeros((2, n, 2))
        self.ball = np.zeros(2)
        self.ball_vel = np.zeros(2)
        self.play_mode = "before_kick_off"
        self.sent: list[list[Any]] = []
        self.resets: list[dict[str, Any]] = []
        self.trainer: list[tuple[Any, ...]] = []
        self.events: list[dict[str, Any]] = []
        self.closed = False
        self.die_on_step = False

    def connect(self) -> Cycle:
        return self._cycle()

    def step(self, commands: Sequence[Command | Sequence[Command] | None]) -> Cycle:
        assert len(commands) == 2 * self.n
        self.sent.append(list(commands))
        if self.die_on_step:
            raise ServerDied("fake server died")
        event = self.events.pop(0) if self.events else {}
        if event.get("die"):
            raise ServerDied("fake server died")
        self.positions = self.positions + self.velocities
        self.ball = self.ball + self.ball_vel
        for key in ("ball", "ball_vel", "play_mode", "velocities"):
            if key in event:
                setattr(self, key, np.asarray(event[key]) if key != "play_mode" else event[key])
        return self._cycle(goals=event.get("goals", (0, 0)))

    def reset(
        self,
        positions_srv: np.ndarray,
        body_deg: np.ndarray,
        ball_srv: tuple[float, float] = (0.0, 0.0),
        ball_vel: tuple[float, float] = (0.0, 0.0),
        play_mode: str = "play_on",
        recover: bool = True,
    ) -> Cycle:
        assert np.shape(positions_srv) == (2, self.n, 2) and np.shape(body_deg) == (2, self.n)
        self.resets.append(
            dict(positions=np.array(positions_srv), body=np.array(body_deg), ball=ball_srv)
        )
        self.positions = np.array(positions_srv, np.float64)
        self.body = np.array(body_deg, np.float64)
        self.velocities = np.zeros((2, self.n, 2))
        self.ball = np.array(ball_srv, np.float64)
        self.ball_vel = np.array(ball_vel, np.float64)
        self.play_mode = play_mode
        return self._cycle()

    def move_ball(self, x: float, y: float, vx: float = 0.0, vy: float = 0.0) -> None:
        self.trainer.append(("move_ball", x, y, vx, vy))
        self.ball = np.array([x, y])
        self.ball_vel = np.array([vx, vy])

    def change_mode(self, mode: str) -> None:
        self.trainer.append(("change_mode", mode))
        self.play_mode = mode

    def close(self) -> None:
        self.closed = True

    def _cycle(self, goals: tuple[int, int] = (0, 0)) -> Cycle:
        self.time += 1
        if self.recorded:
            return recorded_cycle(self.play_mode, goals)
        players = []
        others = [
            (self.names[t], k + 1, *self.positions[t, k]) for t in range(2) for k in range(self.n)
        ]
        for t in range(2):
            for k in range(self.n):
                me = (*self.positions[t, k], self.body[t, k])
                visible = [o for o in others if (o[0], o[1]) != (self.names[t], k + 1)]
                see = emulate_see(self.time, me, tuple(self.ball), visible)  # type: ignore[arg-type]
                players.append(PlayerCycle(t, k + 1, see, None, (), True))
        world = GlobalView(
            time=self.time,
            ball=BallState(*self.ball, *self.ball_vel),
            players=tuple(
                PlayerState(
                    *self.positions[t, k], *(0.4 * self.velocities[t, k]), self.body[t, k], 0.0,
                    k + 1, team=self.names[t],
                )
                for t in range(2)
                for k in range(self.n)
            ),
        )
        return Cycle(tuple(players), world, self.play_mode, (0, 0), goals, self.time, 0, 0)


def recorded_lines(name: str) -> list[tuple[str, Any]]:
    return [
        (line.split("\t", 1)[0], parse_message(line.split("\t", 1)[1]))
        for line in (DATA / name).read_text().splitlines()
    ]


def recorded_cycle(play_mode: str, goals: tuple[int, int]) -> Cycle:
    """Cycle 452 of the recorded 11 v 11 game: every player's see and the trainer's view."""
    sees = {
        who: m for who, m in recorded_lines("see_midgame.txt") if m.time == 452
    }
    world = next(m for _, m in recorded_lines("see_global_midgame.txt") if m.time == 452)
    players = tuple(
        PlayerCycle(t, k, sees.get(f"{'LR'[t]}{k}"), None, (), True)
        for t in range(2)
        for k in range(1, 12)
    )
    return Cycle(players, world, play_mode, (0, 0), goals, 452, 0, 0)


def make_env(
    n: int = 2, recorded: bool = False, **config: Any
) -> tuple[RoboCupEnv, list[FakeClient], FakeServer]:
    names = ("LeftTeam", "RightTeam") if recorded else ("left", "right")
    clients: list[FakeClient] = []
    server = FakeServer()

    def client_factory(_server: Any, cfg: RoboCupConfig) -> FakeClient:
        clients.append(FakeClient(cfg.players_per_team, cfg.team_names, recorded))
        return clients[-1]

    env = RoboCupEnv(
        RoboCupConfig(players_per_team=n, team_names=names, **config),
        server_factory=lambda cfg: server,
        client_factory=client_factory,
    )
    return env, clients, server


def assert_observation_shapes(obs: Observation, n: int) -> None:
    assert obs.self_features.shape == (2, n, NUM_SELF_FEATURES)
    assert obs.entities.shape == (2, n, 2 * n, NUM_ENTITY_FEATURES)
    assert obs.entity_mask.shape == (2, n, 2 * n)
    assert obs.self_features.dtype == np.float32 and obs.entities.dtype == np.float32
    assert obs.entity_mask.dtype == np.bool_
    assert np.all(np.isfinite(obs.self_features)) and np.all(np.isfinite(obs.entities))


# ---------------------------------------------------------------------- config, params
def test_config_rejects_bad_values_by_name() -> None:
    for field, value in [
        ("players_per_team", 12),
        ("spawn", "grid"),
        ("action", "discrete"),
        ("view", "fisheye"),
        ("turn_scale", 0.0),
        ("episode_length", 0),
    ]:
        with pytest.raises(ValueError, match=field):
            RoboCupConfig(**{field: value})


def test_params_use_the_server_field() -> None:
    params = robocup_env_params(RoboCupConfig(players_per_team=3, view="normal", shaping=False))
    assert (params.field_length, params.field_width, params.goal_width) == (105.0, 68.0, 14.02)
    assert params.fov_half_angle == pytest.approx(math.radians(60))
    assert params.ball_shaping_weight == 0.0 and params.approach_shaping_weight == 0.0
    wide = robocup_env_params(RoboCupConfig())
    assert wide.fov_half_angle == pytest.approx(math.pi / 2)  # the simulator's field of view
    assert wide.ball_shaping_weight == 0.1 and wide.approach_shaping_weight == 0.05
    assert wide.possession_shaping_weight == 0.0  # not in the thesis: off unless asked for
    held = RoboCupConfig(possession_shaping_weight=0.01, possession_radius=1.5)
    assert robocup_env_params(held).possession_shaping_weight == 0.01
    assert robocup_env_params(held).possession_radius == 1.5
    off = robocup_env_params(dataclasses.replace(held, shaping=False))
    assert off.possession_shaping_weight == 0.0 and off.possession_radius == 1.5


def test_robocup_train_passes_the_possession_reward_to_its_servers() -> None:
    from elevens.robocup.train import _default_env_factory, make_robocup_config

    config = make_robocup_config(**{
        "env.possession_shaping_weight": 0.005, "env.possession_radius": 3.0,
        "env.possession_by": "near",
    })
    env = _default_env_factory(config)(0)
    try:
        assert env.params.possession_shaping_weight == 0.005
        assert env.params.possession_radius == 3.0
    finally:
        env.close()
    touch = {"env.possession_shaping_weight": 0.005, "env.possession_by": "touch"}
    with pytest.raises(ValueError, match="env.possession_by='touch' is invalid in elevens robocup"):
        make_robocup_config(**touch).validate()
    make_robocup_config(**{**touch, "env.possession_shaping_weight": 0.0}).validate()  # off


# ----------------------------------------------------------------------- action rule
def test_sim_rule_picks_one_command() -> None:
    actions = np.array(
        [
            [0.8, 0.1],  # ball kickable, move > 0: kick along the body
            [0.8, 0.9],  # not kickable, |rot| > |move|: turn
            [0.5, -0.2],  # dash forwards
            [-0.6, 0.3],  # dash backwards (direction 180; the server clamps negative power)
            [0.0, 0.0],  # nothing: only (done)
            [-0.5, 0.0],  # kickable but move <= 0: no kick, dash backwards
            [2.0, -3.0],  # clipped to (1, -1); tie: dash
        ]
    )
    distance = np.array([0.9, math.inf, 5.0, 5.0, 5.0, 0.5, 5.0])
    commands = sim_actions_to_commands(actions, distance, kickable=1.085, turn_scale=90.0)
    assert isinstance(commands[1], Turn) and commands[1].moment == pytest.approx(81.0)
    assert commands[:1] + commands[2:] == [
        Kick(80.0, 0.0),
        Dash(50.0, 0.0),
        Dash(60.0, 180.0),
        NoOp(),
        Dash(50.0, 180.0),
        Dash(100.0, 0.0),
    ]
    assert sim_actions_to_commands(np.array([[0.0, 1.0]]), np.array([9.0]), kickable=1.0) == [
        Turn(180.0)
    ]


def test_bad_actions_raise_with_the_allowed_shape() -> None:
    env, _, _ = make_env(2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(2, 2, 2\)"):
        env.step(np.zeros((2, 2, 12)))
    bad = np.zeros((2, 2, 2))
    bad[1, 0, 1] = np.nan
    with pytest.raises(ValueError, match=r"actions\[1, 0, 1\] is nan.*\(2, 2, 2\)"):
        env.step(bad)
    env12, _, _ = make_env(2, action="thesis12")
    env12.reset(seed=0)
    with pytest.raises(ValueError, match=r"\(2, 2, 12\)"):
        env12.step(np.zeros((2, 2, 2)))


def test_sim_actions_reach_the_server_and_kick_a_kickable_ball() -> None:
    env, clients, _ = make_env(1, spawn="random")
    env.reset(seed=3)
    fake = clients[0]
    assert fake.sent[0] == [ChangeView("wide")] * 2  # once per player after connecting
    x, y = fake.positions[0, 0]
    body = math.radians(fake.body[0, 0])
    fake.events.append(dict(ball=(x + 0.6 * math.cos(body), y + 0.6 * math.sin(body))))
    env.step(np.zeros((2, 1, 2)))  # the see shows the ball now
    env.step(np.array([[[1.0, 0.0]], [[0.0, 0.5]]]))
    assert fake.sent[-1] == [Kick(100.0, 0.0), Turn(90.0)]


def test_thesis12_actions_use_the_thesis_mapping() -> None:
    env, clients, _ = make_env(2, action="thesis12")
    env.reset(seed=0)
    actions = np.full((2, 2, 12), -1.0, np.float32)
    actions[0, 0, ActionIndex.DASH_SCORE] = 1.0
    actions[0, 0, ActionIndex.DASH_POWER] = -0.5
    actions[0, 0, ActionIndex.DASH_DIR] = 0.0
    actions[0, 1, ActionIndex.TURN_SCORE] = 1.0
    actions[0, 1, ActionIndex.TURN_MOMENT] = 0.25
    actions[1, :, ActionIndex.NOOP_SCORE] = 1.0
    state, obs, *_ = env.step(actions)
    assert clients[0].sent[-1] == actions_to_commands(actions)
    np.testing.assert_allclose(state.last_actions, [[-0.5, 0.0], [0.0, 0.25], [0, 0], [0, 0]])
    np.testing.assert_allclose(obs.self_features[0, :, S["last_move"]], [-0.5, 0.0])


def test_thesis12_kick_out_of_reach_becomes_a_dash_towards_the_ball() -> None:
    """A kick the server would ignore (ball out of reach) costs a cycle without a dash: the
    player runs to the ball instead, by its own latest see."""
    env, clients, _ = make_env(1, action="thesis12", spawn="random")
    env.reset(seed=3)
    fake = clients[0]
    x, y = fake.positions[0, 0]
    body = math.radians(fake.body[0, 0])
    aside = body + math.radians(30.0)  # 30 degrees clockwise of its body, 5 m away
    fake.events.append(dict(ball=(x + 5.0 * math.cos(aside), y + 5.0 * math.sin(aside))))
    kick = np.full((2, 1, 12), -1.0, np.float32)
    kick[:, :, ActionIndex.KICK_SCORE] = 1.0
    env.step(kick)  # the see shows the ball now
    env.step(kick)
    ran = fake.sent[-1][0]
    assert isinstance(ran, Dash) and ran.power == 100.0
    assert ran.direction == pytest.approx(30.0, abs=1.5)  # the see's directions are integers
    fake.events.append(dict(ball=(x + 0.6 * math.cos(body), y + 0.6 * math.sin(body))))
    env.step(kick)
    env.step(kick)
    assert isinstance(fake.sent[-1][0], Kick)  # in reach: the kick goes out


# -------------------------------------------------------------------- reset and state
def test_reset_spawns_in_the_server_frame() -> None:
    env, clients, _ = make_env(3)
    state, obs = env.reset(seed=1)
    placed = clients[0].resets[-1]
    np.testing.assert_allclose(
        placed["positions"].reshape(6, 2), state.start_positions * [1, -1], atol=1e-4
    )
    # Formation: the left side in its half (x_srv <= 0), facing roughly +x (body near 0);
    # the right side in the other half, facing the left goal (body near 180).
    assert np.all(placed["positions"][0, :, 0] <= 0) and np.all(placed["positions"][1, :, 0] >= 0)
    assert np.all(np.abs(placed["body"][0]) <= 45.0 + 1e-6)
    assert np.all(np.abs(placed["body"][1]) >= 135.0 - 1e-6)
    np.testing.assert_allclose(state.headings, -np.radians(placed["body"].reshape(6)), atol=1e-5)
    assert int(state.step) == 0 and state.score.tolist() == [0, 0]
    assert_observation_shapes(obs, 3)
    # Both teams see themselves attacking +x: start points in their own halves.
    assert np.all(obs.self_features[..., S["start_x"]] <= 0)
    np.testing.assert_allclose(obs.self_features[..., S["time_left"]], 1.0)


def test_random_spawn_is_uniform_in_the_own_half() -> None:
    env, clients, _ = make_env(4, spawn="random")
    for seed in range(5):
        env.reset(seed=seed)
        placed = clients[0].resets[-1]["positions"]
        assert np.all(placed[0, :, 0] <= 0) and np.all(placed[1, :, 0] >= 0)
        assert np.all(np.abs(placed[..., 1]) <= 34.0)


def test_observation_follows_the_state_in_the_fake_world() -> None:
    """Emulated sees (exact geometry) give the same self features as the simulator would."""
    env, _, _ = make_env(2, spawn="random")
    state, obs = env.reset(seed=5)
    extent = np.array([52.5, 34.0])
    sign = np.array([1.0, -1.0])[:, None, None]
    truth = state.positions.reshape(2, 2, 2) * sign
    np.testing.assert_allclose(obs.self_features[..., 1:3] * extent, truth, atol=0.3)
    heading = np.arctan2(obs.self_features[..., S["sin_heading"]], obs.self_features[..., 3])
    expected = state.headings.reshape(2, 2) + np.array([0.0, math.pi])[:, None]
    error = np.abs(np.remainder(heading - expected + math.pi, 2 * math.pi) - math.pi)
    assert error.max() < math.radians(1.0)


def test_global_state_has_the_simulator_shapes() -> None:
    env, _, _ = make_env(3)
    state, _ = env.reset(seed=0)
    critic = env.global_state(state)
    assert isinstance(critic, GlobalState)
    assert critic.context.shape == (2, NUM_CONTEXT_FEATURES)
    assert critic.players.shape == (2, 6, NUM_PLAYER_FEATURES)
    assert isinstance(critic.players, np.ndarray) and np.all(np.isfinite(critic.players))


# ----------------------------------------------------------------------------- rewards
def test_goal_rewards_the_scorers_and_respawns() -> None:
    env, clients, _ = make_env(2, shaping=False)
    env.reset(seed=0)
    fake = clients[0]
    first_spawn = fake.resets[-1]["positions"].copy()
    fake.events.append(dict(goals=(0, 1), play_mode="goal_r"))
    state, obs, rewards, done, info = env.step(np.zeros((2, 2, 2)))
    np.testing.assert_array_equal(rewards, [[-1.0, -1.0], [1.0, 1.0]])
    assert info["score"].tolist() == [0, 1] and state.score.tolist() == [0, 1]
    assert info["goals"].tolist() == [0, 1]
    assert len(fake.resets) == 2 and not np.allclose(fake.resets[-1]["positions"], first_spawn)
    np.testing.assert_allclose(
        state.start_positions, fake.resets[-1]["positions"].reshape(4, 2) * [1, -1], atol=1e-4
    )
    assert np.all(state.velocities == 0.0)
    assert info["play_mode"] == "play_on" and not done


def test_shaping_terms_match_the_simulator_reward() -> None:
    env, clients, _ = make_env(2, spawn="random")
    before, _ = env.reset(seed=2)
    fake = clients[0]
    fake.events.append(dict(ball_vel=(1.0, -0.5), velocities=np.full((2, 2, 2), 0.2)))
    fake.events.append({})
    env.step(np.zeros((2, 2, 2)))
    previous = env._state
    assert previous is not None
    after, _, rewards, _, info = env.step(np.zeros((2, 2, 2)))
    params = env.params
    expected = reward_terms(
        np.zeros(2, np.int32), after.ball_position, after.ball_velocity, after.velocities,
        previous.ball_position, after.positions, params,
    )
    np.testing.assert_allclose(rewards, np.asarray(expected.total), rtol=1e-5, atol=1e-7)
    assert np.abs(info["ball_shaping"]).max() > 0 and np.abs(info["approach_shaping"]).max() > 0
    np.testing.assert_allclose(info["goal_reward"], 0.0)
    # The ball rolls towards team 0's target (+x world): team 0 gains, team 1 loses.
    assert info["ball_shaping"][0, 0] > 0 > info["ball_shaping"][1, 0]
    np.testing.assert_allclose(after.velocities, np.full((4, 2), 0.2) * [1, -1], atol=1e-6)


def test_done_at_episode_length() -> None:
    env, _, _ = make_env(1, episode_length=3)
    env.reset(seed=0)
    dones = [env.step(np.zeros((2, 1, 2)))[3] for _ in range(3)]
    assert dones == [False, False, True]


# ---------------------------------------------------------------- keep ball in play
def test_keep_ball_in_play_returns_an_out_ball_and_restores_play_on() -> None:
    env, clients, _ = make_env(2, keep_ball_in_play=True)
    env.reset(seed=0)
    fake = clients[0]
    fake.events.append(dict(ball=(10.0, 33.5), ball_vel=(0.5, 2.0)))
    env.step(np.zeros((2, 2, 2)))  # about to cross the bottom side line (server y = +34)
    kind, x, y, vx, vy = fake.trainer[-1]
    assert kind == "move_ball" and abs(y) < 34.0
    assert vy == pytest.approx(-2.0 * 0.6) and vx == pytest.approx(0.5)  # bounced like a wall
    fake.trainer.clear()
    fake.events.append(dict(ball=(20.0, 34.0), ball_vel=(0.0, 0.0), play_mode="kick_in_r"))
    state, _, _, _, info = env.step(np.zeros((2, 2, 2)))
    assert info["play_mode"] == "play_on" and info["ball_returned"]
    assert ("change_mode", "play_on") in fake.trainer
    kind, x, y, vx, vy = next(t for t in fake.trainer if t[0] == "move_ball")
    assert x == pytest.approx(20.0, abs=1.0) and 32.0 <= y < 34.0
    assert abs(state.ball_position[1]) < 34.0
    # A ball heading into the goal mouth is left alone (it is a goal, not a bounce).
    fake.trainer.clear()
    fake.events.append(dict(ball=(52.0, 1.0), ball_vel=(2.0, 0.0), play_mode="play_on"))
    env.step(np.zeros((2, 2, 2)))
    assert fake.trainer == []


def test_without_keep_ball_in_play_the_referee_rules() -> None:
    env, clients, _ = make_env(2)
    env.reset(seed=0)
    clients[0].events.append(dict(ball=(20.0, 34.0), ball_vel=(0, 0), play_mode="kick_in_r"))
    *_, info = env.step(np.zeros((2, 2, 2)))
    assert info["play_mode"] == "kick_in_r" and not info["ball_returned"]
    assert clients[0].trainer == []


# ------------------------------------------------------------------------ dead server
def test_dead_server_is_restarted_and_the_episode_reset() -> None:
    env, clients, server = make_env(2)
    env.reset(seed=0)
    for _ in range(3):
        env.step(np.zeros((2, 2, 2)))
    clients[0].events.append(dict(die=True))
    state, obs, rewards, done, info = env.step(np.zeros((2, 2, 2)))
    assert info["restarted"] and done and env.restarts == 1 and info["restarts"] == 1
    assert server.restarts == 1 and clients[0].closed and len(clients) == 2
    assert clients[1].sent[0] == [ChangeView("wide")] * 4 and len(clients[1].resets) == 1
    assert int(state.step) == 0 and np.all(rewards == 0.0)
    assert_observation_shapes(obs, 2)
    _, _, _, done, info = env.step(np.zeros((2, 2, 2)))  # and it plays on
    assert not info["restarted"] and not done


def test_a_server_that_keeps_dying_gives_up_with_a_clear_error() -> None:
    env, clients, _ = make_env(1, max_restarts=2)
    env.reset(seed=0)
    original = FakeClient.step

    def always_dead(self: FakeClient, commands: Any) -> Cycle:
        raise ServerDied("fake server died")

    try:
        FakeClient.step = always_dead  # type: ignore[method-assign]
        with pytest.raises(RuntimeError, match="could not be"):
            env.step(np.zeros((2, 1, 2)))
    finally:
        FakeClient.step = original  # type: ignore[method-assign]


# ------------------------------------------------------------ recorded messages, policy
def test_a_trained_policy_acts_on_an_observation_from_recorded_messages() -> None:
    """The recorded 11 v 11 cycle gives observations of the simulator's shapes, which the
    simulator's attention policy (small, random weights) turns into actions for a step."""
    env, _, _ = make_env(11, recorded=True)
    state, obs = env.reset(seed=0)
    assert_observation_shapes(obs, 11)
    assert obs.entity_mask.any() and obs.self_features[..., S["ball_visible"]].any()
    assert isinstance(state, State) and state.positions.shape == (22, 2)
    team = NetworkTeam(AttentionPolicy(features=16, num_heads=2, lstm_features=8, lstm_layers=1))
    carry = team.init_carry(11)
    # Random weights of the network's shapes: a compiled Flax init costs seconds of test time.
    shapes = jax.eval_shape(
        team.policy.init, jax.random.key(0), carry, obs.team(0), np.zeros(11, bool)
    )
    rng = np.random.default_rng(0)
    variables = jax.tree.map(lambda s: 0.1 * rng.standard_normal(s.shape).astype(s.dtype), shapes)
    act = jax.jit(team.act)
    actions = []
    for side in range(2):
        _, side_actions = act(variables, carry, obs.team(side), jax.random.key(side))
        actions.append(np.asarray(side_actions))
    stacked = np.stack(actions)
    assert stacked.shape == (2, 11, 2) and np.all(np.abs(stacked) <= 1.0)
    state, obs, rewards, done, info = env.step(stacked)
    assert rewards.shape == (2, 11) and rewards.dtype == np.float32
    assert_observation_shapes(obs, 11)
    assert info["pose_valid"].shape == (2, 11) and info["stale"].dtype == np.int32


# ------------------------------------------------------------------------ integration
@needs_rcssserver
def test_server_2v2_reset_and_random_steps() -> None:
    rng = np.random.default_rng(0)
    with RoboCupEnv(RoboCupConfig(players_per_team=2, spawn="random")) as env:
        state, obs = env.reset(seed=0)
        assert_observation_shapes(obs, 2)
        for _ in range(30):
            state, obs, rewards, done, info = env.step(rng.uniform(-1, 1, (2, 2, 2)))
            assert_observation_shapes(obs, 2)
            assert rewards.shape == (2, 2) and np.all(np.isfinite(rewards))
            assert not info["restarted"] and info["missed"] == 0
        assert int(state.step) == 30
        # Self-localisation agrees with the trainer's ground truth.
        sign = np.array([1.0, -1.0])[:, None, None]
        truth = state.positions.reshape(2, 2, 2) * sign
        estimate = obs.self_features[..., 1:3] * np.array([52.5, 34.0])
        stale = info["stale"]
        assert np.all(np.abs(estimate - truth)[stale == 0] < 1.5)
        critic = env.global_state(state)
        assert critic.players.shape == (2, 4, NUM_PLAYER_FEATURES)


@needs_rcssserver
def test_server_goal_set_up_by_the_trainer_rewards_and_respawns() -> None:
    with RoboCupEnv(RoboCupConfig(players_per_team=2, shaping=False)) as env:
        env.reset(seed=1)
        assert env._client is not None
        env._client.move_ball(48.0, 0.0, 3.0, 0.0)  # server frame: into the right goal
        for _ in range(10):
            state, _, rewards, _, info = env.step(np.zeros((2, 2, 2)))
            if info["goals"].any():
                break
        assert info["goals"].tolist() == [1, 0]
        np.testing.assert_array_equal(rewards, [[1.0, 1.0], [-1.0, -1.0]])
        assert info["score"].tolist() == [1, 0] and info["play_mode"] == "play_on"
        assert np.abs(state.ball_position).max() < 30.0  # respawned inside the field
        assert np.all(state.positions[:2, 0] <= 0.5)  # back in their own halves
        _, _, rewards, _, info = env.step(np.zeros((2, 2, 2)))
        assert info["play_mode"] == "play_on" and np.all(rewards == 0.0)


@needs_rcssserver
def test_server_keep_ball_in_play_at_the_side_line() -> None:
    config = RoboCupConfig(players_per_team=1, keep_ball_in_play=True, ball_spawn="centre")
    with RoboCupEnv(config) as env:
        env.reset(seed=2)
        assert env._client is not None
        env._client.move_ball(0.0, 33.0, 0.0, 3.0)  # out over the bottom line next cycle
        modes = []
        for _ in range(6):
            state, _, _, _, info = env.step(np.zeros((2, 1, 2)))
            modes.append(info["play_mode"])
        assert modes == ["play_on"] * 6
        assert abs(float(state.ball_position[1])) < 34.0
        # About to cross: bounced before the referee sees it go out.
        env._client.move_ball(10.0, 30.5, 0.0, 2.5)
        for _ in range(6):
            state, _, _, _, info = env.step(np.zeros((2, 1, 2)))
            assert info["play_mode"] == "play_on"
            assert abs(float(state.ball_position[1])) < 34.0
        assert float(state.ball_velocity[1]) > 0.0  # world y up: moving back into the field


@needs_rcssserver
def test_server_death_is_survived() -> None:
    with RoboCupEnv(RoboCupConfig(players_per_team=1, think_timeout_s=0.5)) as env:
        env.reset(seed=0)
        env.step(np.zeros((2, 1, 2)))
        pid = getattr(env._server, "pid", None)
        assert pid is not None
        os.kill(pid, signal.SIGKILL)
        # The guard takes the server down with it a moment later; on a loaded machine a cycle
        # already on its way may still arrive first.
        for _ in range(3):
            _, obs, _, done, info = env.step(np.zeros((2, 1, 2)))
            if info["restarted"]:
                break
        assert info["restarted"] and done and env.restarts == 1
        assert_observation_shapes(obs, 1)
        *_, info = env.step(np.zeros((2, 1, 2)))
        assert not info["restarted"]


def test_robocup_train_refuses_game_fields_the_server_sets() -> None:
    from elevens.robocup.train import make_robocup_config

    for flag, value in (("env.field_length", 105.0), ("env.ball_friction", 0.94),
                        ("env.kick_impulse", 2.0)):
        with pytest.raises(ValueError, match=f"{flag}={value!r} is invalid in elevens robocup"):
            make_robocup_config(**{flag: value})
    # The simulator's game setup beside EnvParams: team-size mixes and its bodies (the server
    # brings its own; the simulator's games with the server's bodies are another config).
    message = re.escape("env.mix=('1v1',) is invalid in elevens robocup")
    with pytest.raises(ValueError, match=message):
        make_robocup_config(**{"env.mix": ("1v1",), "env.mix_shares": (0.5,)})
    with pytest.raises(ValueError, match=re.escape("env.physics='rcss' is invalid")):
        make_robocup_config(**{"env.physics": "rcss"})
    with pytest.raises(ValueError, match="override 'env.stamina': unknown field"):
        make_robocup_config(**{"env.stamina": True})
    # The ones it passes on are fine, and so is the shaping schedule.
    make_robocup_config(**{"env.shaping_schedule": False})
    make_robocup_config(**{"env.episode_length": 50, "env.goal_reward": 2.0,
                           "env.ball_shaping_weight": 0.0, "env.players_per_team": 3,
                           "ppo.minibatch_size": 3})
