"""RoboCupEnv(episodes="match"): training episodes played as a regulation match is, from a
kick-off, with the referee's restarts and the match routines a team plays with."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from elevens.env.state import SELF_FEATURES
from elevens.robocup.env import RoboCupConfig, RoboCupEnv
from elevens.robocup.protocol import Move
from elevens.robocup.rules import MATCH_CLOCK, kick_off_positions, kick_off_taker
from elevens.robocup.train import ServerConfig, _default_env_factory, make_robocup_config
from tests.robocup.conftest import needs_rcssserver
from tests.robocup.test_env import make_env

TIME_LEFT = SELF_FEATURES.index("time_left")


def zeros(n: int) -> np.ndarray:
    return np.zeros((2, n, 12), np.float32)


def test_match_episodes_refuse_the_drills_ball_return_and_unknown_modes() -> None:
    with pytest.raises(ValueError, match="keep_ball_in_play=True is invalid with episodes"):
        RoboCupConfig(episodes="match", keep_ball_in_play=True)
    with pytest.raises(ValueError, match=r"episodes='scrimmage' is invalid.*'drill', 'match'"):
        RoboCupConfig(episodes="scrimmage")
    with pytest.raises(ValueError, match=r"server.episodes='scrimmage' is invalid"):
        ServerConfig(episodes="scrimmage")


def test_training_in_match_episodes_has_the_referee_restart_play() -> None:
    config = make_robocup_config(**{"server.episodes": "match"})
    assert config.server.keep_ball_in_play  # the drills' default stays ...
    env = _default_env_factory(config)(0)
    assert env.config.episodes == "match" and not env.config.keep_ball_in_play  # ... unused


def test_a_match_episode_starts_from_the_kick_off_formation() -> None:
    kickers = set()
    for seed in range(8):
        env, clients, _ = make_env(2, episodes="match", action="thesis12")
        _, obs = env.reset(seed=seed)
        fake = clients[0]
        placed = fake.resets[-1]
        kicker = "lr".index(fake.play_mode[-1])
        assert fake.play_mode == f"kick_off_{'lr'[kicker]}"
        kickers.add(kicker)
        assert placed["ball"] == (0.0, 0.0)
        # Server frame: the left team in x < 0, the right in x > 0, each in its formation.
        for side, sign in ((0, 1.0), (1, -1.0)):
            team_frame = placed["positions"][side] * np.array([sign, -sign])
            expected = kick_off_positions(2, taker=side == kicker)
            np.testing.assert_allclose(team_frame, expected, atol=1e-6)
        taker = kick_off_taker(2)
        assert np.hypot(*placed["positions"][kicker, taker]) < 1.0
        np.testing.assert_allclose(placed["body"], [[0.0, 0.0], [180.0, 180.0]])
        np.testing.assert_allclose(obs.self_features[..., TIME_LEFT], 1.0)
    assert kickers == {0, 1}


def test_a_goal_is_followed_by_the_referees_kick_off_not_a_respawn() -> None:
    env, clients, _ = make_env(2, episodes="match", action="thesis12", shaping=False)
    env.reset(seed=0)
    fake = clients[0]
    fake.events.append(dict(play_mode="play_on"))  # the kick-off was taken
    for _ in range(3):
        _, obs, *_ = env.step(zeros(2))
    assert obs.self_features[0, 0, TIME_LEFT] == pytest.approx(1.0 - 3 / MATCH_CLOCK)
    fake.events.append(dict(goals=(1, 0), play_mode="goal_l"))
    _, _, rewards, done, info = env.step(zeros(2))
    np.testing.assert_array_equal(rewards, [[1.0, 1.0], [-1.0, -1.0]])
    assert len(fake.resets) == 1 and info["play_mode"] == "goal_l" and not done
    # After a goal every player of both elevens sides moves to its kick-off slot, whatever its
    # policy says; the right side (conceded) kicks off, so its taker goes to the centre.
    *_, moved = env.step(np.ones((2, 2, 12), np.float32))
    sent = fake.sent[-1]
    assert all(isinstance(c, Move) for c in sent)
    # Every player's command was the routine's: none of the policies' samples was played, so
    # elevens robocup train keeps them out of PPO's policy terms (Rollout.scripted).
    assert moved["scripted"].shape == (2, 2) and moved["scripted"].all()
    right_taker = sent[2 + kick_off_taker(2)]
    assert isinstance(right_taker, Move) and abs(right_taker.x) < 1.0
    fake.events.append(dict(play_mode="kick_off_r"))
    _, obs, *_ = env.step(zeros(2))
    np.testing.assert_allclose(obs.self_features[..., TIME_LEFT], 1.0)  # the clock restarts


def test_drills_leave_the_policys_commands_alone() -> None:
    env, clients, _ = make_env(2, action="thesis12")
    env.reset(seed=0)
    clients[0].events.append(dict(play_mode="goal_l", goals=(1, 0)))
    *_, first = env.step(zeros(2))
    clients[0].play_mode = "before_kick_off"
    *_, second = env.step(np.ones((2, 2, 12), np.float32))
    assert not any(isinstance(c, Move) for c in clients[0].sent[-1])
    assert not first["scripted"].any() and not second["scripted"].any()


# ------------------------------------------------------------------------ integration
@needs_rcssserver
def test_server_match_episode_kicks_off_restarts_after_a_goal_and_takes_set_pieces() -> None:
    config = RoboCupConfig(players_per_team=11, episodes="match", action="thesis12")
    with RoboCupEnv(config) as env:
        env.reset(seed=3)
        client: Any = env._client
        modes = []
        for cycle in range(300):
            if cycle == 20:
                client.move_ball(48.0, 0.0, 3.0, 0.0)  # server frame: into the right goal
            if cycle == 120:
                client.move_ball(-20.0, 33.5, 0.0, 1.5)  # over the bottom side line
            *_, info = env.step(zeros(11))
            modes.append(info["play_mode"])
            assert info["missed"] == 0 and not info["restarted"]
    # The kick-off was taken by the routine; the goal was followed by the right team's
    # kick-off (the referee's, after its pause) and play went on; the kick-in was taken.
    assert modes[0] == "play_on"
    assert "goal_l" in modes and info["score"].tolist() == [1, 0]
    after_goal = modes[modes.index("goal_l"):]
    assert "kick_off_r" in after_goal
    kick_off = modes.index("kick_off_r")
    assert "play_on" in modes[kick_off:120]
    kick_in = [m for m in modes[120:] if m.startswith("kick_in")]
    assert kick_in and modes[-1] == "play_on" and len(kick_in) < 150


def test_match_episodes_drop_the_ball_as_a_match_does() -> None:
    from elevens.robocup.env import MATCH_EPISODE_OPTIONS
    from elevens.robocup.match import MATCH_OPTIONS

    for name, value in MATCH_EPISODE_OPTIONS.items():
        assert MATCH_OPTIONS[name] == value
