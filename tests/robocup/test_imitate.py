"""Behaviour cloning from game logs (elevens.robocup.imitate).

``logs/helios_excerpt.*`` are cycles 20-60 of a real helios-base against helios-base match
(rcssserver 19, `elevens robocup match --log-dir`): kick-off, then play_on from cycle 24.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from elevens.cli.app import main
from elevens.env import observe as observe_lib
from elevens.env.state import SELF_FEATURES, Observation
from elevens.nets.policy import AttentionPolicy
from elevens.robocup.actions import ActionScaling, action_to_command
from elevens.robocup.env import RoboCupConfig, robocup_env_params
from elevens.robocup.imitate import (
    Demonstrations,
    GameLog,
    command_kind,
    command_loss,
    demonstrations,
    imitate,
    imitate_from_logs,
    intent_labels,
    label_of_command,
    read_game_log,
    thesis12_label,
    thesis12_loss,
)
from elevens.robocup.play import load_robocup_team
from elevens.robocup.protocol import Dash, Kick, Tackle, Turn

LOGS = Path(__file__).parent / "logs"
RCG, RCL = LOGS / "helios_excerpt.rcg", LOGS / "helios_excerpt.rcl"
PARAMS = robocup_env_params(RoboCupConfig(players_per_team=11))


@pytest.mark.parametrize(
    ("command", "label"),
    [
        (("dash", (100.0, 0.0)), (0.95, 0.0)),  # full power is kept off tanh's end
        (("dash", (50.0,)), (0.5, 0.0)),
        (("dash", (60.0, 180.0)), (-0.6, 0.0)),  # a backward dash moves backwards
        (("dash", (80.0, 90.0)), (0.0, 0.0)),  # sideways: no forward part
        (("turn", (90.0,)), (0.0, 0.5)),
        (("turn", (-36.0,)), (0.0, -0.2)),
        (("kick", (80.0, 30.0)), (0.8, 0.0)),  # the sim rule kicks when move > 0
        (("tackle", (50.0,)), None),
        (("catch", (10.0,)), None),
        (("move", (-10.0, 0.0)), None),
    ],
)
def test_commands_become_sim_actions(command, label):
    found = label_of_command(*command)
    if label is None:
        assert found is None
    else:
        np.testing.assert_allclose(found, label, atol=1e-9)


def test_a_real_log_is_read():
    game = read_game_log(RCG, RCL)
    assert game.team_names == ("HELIOS_a", "HELIOS_b")
    assert game.time[0] == 20 and game.time[-1] == 60
    assert game.play_mode[0] == "kick_off_l" and game.play_mode[-1] == "play_on"
    assert game.play_mode[list(game.time).index(24)] == "play_on"
    assert np.isfinite(game.positions).all()  # all 22 players on the field
    # The goalies stand in front of their own goals.
    assert game.positions[0, 0, 0, 0] < -40 and game.positions[0, 1, 0, 0] > 40
    # A body command from nearly every player every cycle (a few cycles have only a turn_neck).
    assert 0.95 * 2 * 11 * 41 <= len(game.commands) <= 2 * 11 * 41
    assert game.commands[("HELIOS_b", 9, 20)] == ("dash", (60.961,))


def test_a_file_that_is_not_a_game_log_is_refused(tmp_path):
    text = tmp_path / "x.rcg"
    text.write_text("hello\n")
    with pytest.raises(ValueError, match=r"x\.rcg is not a text game log.*ULG"):
        read_game_log(text, RCL)
    broken = tmp_path / "broken.rcg"
    lines = RCG.read_text().splitlines()
    show = next(i for i, line in enumerate(lines) if line.startswith("(show "))
    lines[show] = lines[show].replace("((l 2) 10 0x1 ", "((l 2) 10 0x1 nan ", 1)
    broken.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=r"broken\.rcg:\d+: non-finite number 'nan'"):
        read_game_log(broken, RCL)


def test_demonstrations_match_the_simulator_observation_and_label_play_on_only():
    game = read_game_log(RCG, RCL)
    demo = demonstrations(game, "HELIOS_b", PARAMS, see_period=1)
    steps = len(game.time)
    assert demo.actions.shape == (11, steps, 2)
    assert demo.observations.entities.shape == (11, steps, 22, 11)
    play_on = np.array([mode == "play_on" for mode in game.play_mode])
    labelled = np.array(
        [
            [label_of_command(*game.commands.get(("HELIOS_b", unum, t), ("move", ()))) is not None
             for t in game.time]
            for unum in range(1, 12)
        ]
    )
    np.testing.assert_array_equal(demo.valid, labelled & play_on)
    assert game.commands[("HELIOS_b", 6, 45)] == ("tackle", (108.0, 1.0))  # (tackle 108 on)
    assert not demo.valid[5, list(game.time).index(45)]
    t = list(game.time).index(30)
    # The right team sees itself attacking +x: its own x is the server's x mirrored.
    x_index = SELF_FEATURES.index("x")
    np.testing.assert_allclose(
        demo.observations.self_features[:, t, x_index],
        -game.positions[t, 1, :, 0] / PARAMS.half_length,
        rtol=1e-5,
    )
    # The labels are the logged commands.
    for unum in (2, 9):
        command = game.commands[("HELIOS_b", unum, 30)]
        np.testing.assert_allclose(demo.actions[unum - 1, t], label_of_command(*command))
        # ... and each player's previous label is its last action in the self features.
        before = label_of_command(*game.commands[("HELIOS_b", unum, 29)])
        last = SELF_FEATURES.index("last_move")
        np.testing.assert_allclose(
            demo.observations.self_features[unum - 1, t, last : last + 2], before, atol=1e-6
        )
    # The entity features are the simulator's (field of view included), without last actions.
    ball_distance = demo.observations.self_features[:, t, SELF_FEATURES.index("ball_distance")]
    ball = game.ball[t, :2]
    expected = np.hypot(*(game.positions[t, 1] - ball).T) / PARAMS.field_length
    seen = demo.observations.self_features[:, t, SELF_FEATURES.index("ball_visible")] > 0
    np.testing.assert_allclose(ball_distance[seen], expected[seen], rtol=1e-4)
    assert not demo.observations.entities[..., 7:9].any()
    assert not seen.all()  # some players have their backs to the ball


def test_between_sees_a_player_keeps_its_view_but_its_last_action_is_fresh():
    game = read_game_log(RCG, RCL)
    fresh = demonstrations(game, "HELIOS_a", PARAMS, see_period=1)
    held = demonstrations(game, "HELIOS_a", PARAMS, see_period=3)
    x, last = SELF_FEATURES.index("x"), SELF_FEATURES.index("last_move")
    for i in (0, 4, 8):
        for t in range(3, 30):
            seen_at = t - (t + i) % 3  # player i sees when (t + i) % 3 == 0
            np.testing.assert_array_equal(
                held.observations.self_features[i, t, x],
                fresh.observations.self_features[i, seen_at, x],
            )
            np.testing.assert_array_equal(
                held.observations.entities[i, t], fresh.observations.entities[i, seen_at]
            )
            np.testing.assert_array_equal(
                held.observations.self_features[i, t, last : last + 2],
                fresh.observations.self_features[i, t, last : last + 2],
            )
    np.testing.assert_array_equal(held.actions, fresh.actions)
    with pytest.raises(ValueError, match="see_period=0 is invalid"):
        demonstrations(game, "HELIOS_a", PARAMS, see_period=0)


def _walking_game(body_deg: float, speed: float, steps: int = 30) -> GameLog:
    """Player 1 of the left team walks along the server's +x at ``speed`` m/cycle, its body at
    ``body_deg``; every other player stands; all play_on."""
    positions = np.zeros((steps, 2, 11, 2), np.float32)
    positions[:, :, :, 0] = np.arange(11) * 3.0
    positions[:, 0, 0, 0] = -20.0 + speed * np.arange(steps)
    return GameLog(
        team_names=("A", "B"),
        time=np.arange(1, steps + 1, dtype=np.int32),
        play_mode=["play_on"] * steps,
        positions=positions,
        velocities=np.zeros_like(positions),
        body_deg=np.full((steps, 2, 11), body_deg, np.float32),
        ball=np.zeros((steps, 4), np.float32),
        commands={},
    )


@pytest.mark.parametrize(
    ("body_deg", "speed", "label"),
    [
        (0.0, 0.5, (0.5, 0.0)),  # facing the way it goes: a dash at half of top speed
        (20.0, 0.5, (0.5, 0.0)),  # within the aim: still a dash
        (90.0, 0.5, (0.0, -0.5)),  # its target 90 degrees to the right: turn there first
        (-60.0, 0.5, (0.0, 60.0 / 180.0)),
        (180.0, 0.5, (-0.5, 0.0)),  # the target behind it: a dash backwards
        (0.0, 0.01, (0.0, 0.0)),  # as good as standing: nothing
    ],
)
def test_intent_labels_head_for_where_the_player_will_be(body_deg, speed, label):
    game = _walking_game(body_deg, speed)
    labels = intent_labels(game, 0, 11, lookahead=10)
    assert labels.shape == (11, 30, 2)
    np.testing.assert_allclose(labels[0, :29], np.broadcast_to(label, (29, 2)), atol=1e-5)
    assert not labels[1:].any()  # the others stand
    assert not labels[0, 29].any()  # the end of play: nowhere to go


def test_intent_labels_keep_kicks_and_stop_at_the_end_of_play():
    game = _walking_game(0.0, 0.5)
    game.commands[("A", 1, 5)] = ("kick", (70.0, 30.0))
    game.play_mode[20:] = ["free_kick_l"] * 10
    demo = demonstrations(game, "A", robocup_env_params(RoboCupConfig()), labels="intent")
    np.testing.assert_allclose(demo.actions[0, 4], (0.7, 0.0), atol=1e-6)
    np.testing.assert_allclose(demo.actions[0, 3], (0.5, 0.0), atol=1e-5)
    # Cycle 15 looks to the last cycle of play_on (19), 4 cycles on: the same speed.
    np.testing.assert_allclose(demo.actions[0, 15], (0.5, 0.0), atol=1e-5)
    assert not demo.valid[:, 20:].any() and demo.valid[:, :20].all()
    game.commands[("A", 3, 7)] = ("tackle", (50.0,))
    tackled = demonstrations(game, "A", PARAMS, labels="intent")
    assert not tackled.valid[2, 6] and tackled.valid[2, 5]
    with pytest.raises(ValueError, match="labels='future' is invalid"):
        demonstrations(game, "A", PARAMS, labels="future")


def test_a_team_that_did_not_play_is_named():
    game = read_game_log(RCG, RCL)
    with pytest.raises(ValueError, match="'CYRUS' did not play.*'HELIOS_a' and 'HELIOS_b'"):
        demonstrations(game, "CYRUS", PARAMS)


@functools.cache
def _synthetic(key: int, steps: int = 64, n: int = 3) -> Demonstrations:
    """Players that dash forward when the ball is to their left and back when to their right.

    Built once per key (eager observes, seconds) and shared by the tests, read-only."""
    params = robocup_env_params(RoboCupConfig(players_per_team=n))
    rng = np.random.default_rng(key)
    obs_list = []
    for _ in range(steps):
        state = observe_lib_state(rng, n)
        obs_list.append(jax.tree.map(np.asarray, observe_lib.observe(state, params)))
    obs = jax.tree.map(lambda *leaves: np.stack(leaves, axis=2)[0], *obs_list)  # [n, T]
    sin_bearing = obs.self_features[..., SELF_FEATURES.index("ball_sin_bearing")]
    move = np.where(sin_bearing > 0, 0.8, -0.8).astype(np.float32)
    actions = np.stack([move, np.zeros_like(move)], axis=-1)
    valid = obs.self_features[..., SELF_FEATURES.index("ball_visible")] > 0
    demo = Demonstrations(
        observations=Observation(
            self_features=obs.self_features, entities=obs.entities, entity_mask=obs.entity_mask
        ),
        actions=actions, valid=valid, reset=np.zeros(steps, bool),
    )
    for leaf in (*jax.tree.leaves(demo.observations), demo.actions, demo.valid, demo.reset):
        leaf.setflags(write=False)
    return demo


def observe_lib_state(rng: np.random.Generator, n: int):
    from elevens.env.state import State

    return State(
        positions=jnp.asarray(rng.uniform(-30, 30, (2 * n, 2)), jnp.float32),
        headings=jnp.asarray(rng.uniform(-math.pi, math.pi, 2 * n), jnp.float32),
        velocities=jnp.zeros((2 * n, 2)),
        last_actions=jnp.zeros((2 * n, 2)),
        start_positions=jnp.zeros((2 * n, 2)),
        ball_position=jnp.asarray(rng.uniform(-30, 30, 2), jnp.float32),
        ball_velocity=jnp.zeros(2),
        score=jnp.zeros(2, jnp.int32),
        step=jnp.zeros((), jnp.int32),
    )


@pytest.mark.parametrize(
    ("action", "label", "kind"),
    [
        ((0.9, 0.1), (0.9, 0.0), 1),  # a dash
        ((0.2, 0.6), (0.0, 0.5), 2),  # a turn
        ((0.01, -0.02), (0.0, 0.01), 0),  # nothing
    ],
)
def test_the_loss_is_zero_only_for_the_same_command_with_a_margin(action, label, kind):
    action, label = jnp.asarray(action), jnp.asarray(label)
    assert int(command_kind(label)) == kind
    if kind == 0:
        assert float(command_loss(jnp.zeros(2), label)) == 0.0
        assert float(command_loss(action, label)) > 0.0
        return
    assert int(command_kind(action)) == kind
    exact = label.at[1 - (kind - 1)].set(0.0)  # the other part at zero: beyond the margin
    assert float(command_loss(exact, label)) == 0.0
    # The average of a dash and a turn gives neither command: both losses see it.
    blend = jnp.asarray([0.45, 0.25])
    assert float(command_loss(blend, label)) > 0.05


def test_imitation_learns_a_rule_it_is_shown():
    demos = [_synthetic(k) for k in range(4)]
    policy = AttentionPolicy(features=32, lstm_features=16)
    obs0 = jax.tree.map(lambda leaf: jnp.asarray(leaf[:, 0]), demos[0].observations)
    params = policy.init(jax.random.key(0), policy.initial_carry((3,)), obs0, jnp.ones(3, bool))
    fitted, result = imitate(
        policy, params, demos, steps=300, batch_size=8, sequence_length=8, learning_rate=3e-3,
        held_out=0.25,
    )
    assert result.steps == 300 and result.samples == sum(d.labelled for d in demos)
    assert result.last_loss < 0.1 * result.first_loss
    # Held-out sequences: the deterministic move has the label's sign and is close to it.
    assert result.held_out_move_error < 0.2 and result.held_out_agreement > 0.95
    # The same held-out figures of the starting networks: the fit, not the data, made them.
    assert result.held_out_move_error < 0.5 * result.held_out_move_error_before
    assert result.held_out_agreement_before < 0.9


def test_the_last_action_can_be_hidden_from_the_policy():
    """Labels that copy the player's last action: learnable only when it is shown."""
    demos = []
    for k in range(4):
        demo = _synthetic(k)
        rng = np.random.default_rng(k)
        last = SELF_FEATURES.index("last_move")
        features = demo.observations.self_features.copy()
        features[..., last] = rng.choice([-0.8, 0.8], features.shape[:-1])
        features[..., last + 1] = 0.0
        actions = np.stack([features[..., last], features[..., last + 1]], axis=-1)
        obs = Observation(
            self_features=features,
            entities=demo.observations.entities,
            entity_mask=demo.observations.entity_mask,
        )
        demos.append(Demonstrations(obs, actions, np.ones_like(demo.valid), demo.reset))
    policy = AttentionPolicy(features=32, lstm_features=16)
    obs0 = jax.tree.map(lambda leaf: jnp.asarray(leaf[:, 0]), demos[0].observations)
    params = policy.init(jax.random.key(0), policy.initial_carry((3,)), obs0, jnp.ones(3, bool))
    errors = {}
    for hide in (False, True):
        _, result = imitate(
            policy, params, demos, steps=300, batch_size=8, sequence_length=8,
            learning_rate=3e-3, held_out=0.25, hide_last_action=hide,
        )
        errors[hide] = result.held_out_move_error
    assert errors[False] < 0.2 and errors[True] > 0.6


def test_a_learned_team_is_written_and_plays(tmp_path):
    out = tmp_path / "team"
    result = imitate_from_logs(
        [LOGS], ["HELIOS_a"], out, init_from="elevens-2v2", steps=3, batch_size=2,
        sequence_length=8, print_fn=lambda _: None,
    )
    assert result.steps == 3 and result.samples > 0
    assert (out / "networks.npz").is_file() and "HELIOS_a" in (out / "MODEL_CARD.md").read_text()
    team = load_robocup_team(str(out), "sim")
    from elevens.runs.teams import load_team

    assert load_team(str(out)).field == (105.0, 68.0, 14.02)  # the server's field
    obs = jax.tree.map(
        lambda leaf: jnp.asarray(leaf[:, 0]),
        demonstrations(read_game_log(RCG, RCL), "HELIOS_a", PARAMS).observations,
    )
    _, actions = team.act(team.init_carry(11), obs, jax.random.key(0))
    assert np.asarray(actions).shape == (11, 2) and np.isfinite(np.asarray(actions)).all()


def test_the_command_names_a_missing_team_and_missing_logs(tmp_path, capsys):
    with pytest.raises(SystemExit) as exited:
        main(["robocup", "imitate", "--logs", str(LOGS), "--team-name", "CYRUS",
              "--out", str(tmp_path / "t"), "--steps", "1"])
    assert exited.value.code == 2
    assert "'CYRUS'" in capsys.readouterr().err and not (tmp_path / "t").exists()
    with pytest.raises(SystemExit):
        main(["robocup", "imitate", "--logs", str(tmp_path), "--team-name", "X",
              "--out", str(tmp_path / "t")])
    assert "no .rcg/.rcl pair" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("command", "expected"),
    [
        (("dash", (60.0, 0.0)), Dash(60.0, 0.0)),
        (("dash", (60.0, 180.0)), Dash(60.0, 180.0)),  # backwards: a negative power
        (("dash", (80.0, -135.0)), Dash(80.0, -135.0)),
        (("dash", (50.0, 45.0)), Dash(50.0, 45.0)),
        (("kick", (80.0, 30.0)), Kick(80.0, 30.0)),
        (("kick", (40.0, -120.0)), Kick(40.0, -120.0)),
        (("turn", (-72.0,)), Turn(-72.0)),
        (("tackle", (45.0, 1.0)), Tackle(45.0, foul=True)),
        (("tackle", (-30.0, -1.0)), Tackle(-30.0, foul=False)),
    ],
)
def test_a_thesis12_label_maps_back_to_the_command_sent(command, expected):
    label = thesis12_label(*command)
    assert label is not None and label.shape == (12,)
    assert np.argmax(label[:5]) == {Dash: 0, Kick: 1, Turn: 2, Tackle: 3}[type(expected)]
    sent = action_to_command(label)
    assert type(sent) is type(expected)
    for field in ("power", "direction", "moment"):
        if hasattr(expected, field):
            assert getattr(sent, field) == pytest.approx(getattr(expected, field), abs=1e-3)
    if isinstance(expected, Tackle):
        assert sent.foul == expected.foul
    assert thesis12_label("catch", (10.0,)) is None and thesis12_label("move", (1.0, 2.0)) is None


def test_the_thesis12_loss_picks_one_command_and_fits_only_its_parameters():
    dash = jnp.asarray(thesis12_label("dash", (60.0, 0.0)))
    good = jnp.zeros(12).at[:5].set(-10.0).at[0].set(10.0).at[5].set(jnp.arctanh(0.6))
    loss, agree, error = thesis12_loss(good, dash)
    assert float(loss) < 1e-3 and float(agree) == 1.0 and float(error) < 1e-5
    # The kick's parameters are free when the label is a dash.
    assert float(thesis12_loss(good.at[7:9].set(3.0), dash)[0]) == pytest.approx(float(loss))
    wrong = good.at[2].set(20.0)  # a turn wins the scores
    loss_wrong, agree_wrong, _ = thesis12_loss(wrong, dash)
    assert float(agree_wrong) == 0.0 and float(loss_wrong) > 3.0


def test_imitation_of_thesis12_commands_chooses_between_them():
    """Turn when the ball is to the left, dash at 0.6 when it is to the right: a choice a
    (move, rot) regression blends, the selection scores make."""
    demos = []
    for k in range(4):
        demo = _synthetic(k)
        left = demo.observations.self_features[..., SELF_FEATURES.index("ball_sin_bearing")] > 0
        turn, dash = thesis12_label("turn", (90.0,)), thesis12_label("dash", (60.0, 0.0))
        actions = np.where(left[..., None], turn, dash).astype(np.float32)
        demos.append(Demonstrations(demo.observations, actions, demo.valid, demo.reset))
    policy = AttentionPolicy(features=32, lstm_features=16, num_actions=12)
    obs0 = jax.tree.map(lambda leaf: jnp.asarray(leaf[:, 0]), demos[0].observations)
    params = policy.init(jax.random.key(0), policy.initial_carry((3,)), obs0, jnp.ones(3, bool))
    # 400 steps passed or stalled at a loss of 2 by the initial key (3 keys of 4 stalled);
    # 1000 steps learn it from every key tried.
    _, result = imitate(
        policy, params, demos, steps=1000, batch_size=8, sequence_length=8, learning_rate=3e-3,
        held_out=0.25,
    )
    assert result.held_out_agreement > 0.95 and result.held_out_move_error < 0.1


def test_a_thesis12_team_plays_the_server_or_its_bodies_only(tmp_path):
    out = tmp_path / "team12"
    imitate_from_logs(
        [LOGS], ["HELIOS_b"], out, init_from="elevens-2v2", steps=2, batch_size=2,
        sequence_length=8, action="thesis12", print_fn=lambda _: None,
    )
    from elevens.robocup.team import RoboCupTeam
    from elevens.runs.teams import load_team

    team = load_team(str(out))
    assert team.actions == 12
    with pytest.raises(ValueError, match="12-value RoboCup action.*env.physics rcss"):
        team.check_size(11)  # what the simulator's own game checks
    team.check_size(11, actions=12)  # the simulator with the server's bodies takes it
    with pytest.raises(ValueError, match="must be 'thesis12', not 'sim'"):
        load_robocup_team(str(out), "sim")
    player = RoboCupTeam(str(out), team_name="mine")
    action = np.zeros((11, 12), np.float32)
    action[:, 1] = 1.0  # kick
    action[:, 7:9] = (0.5, -0.25)  # power 75, 45 degrees anticlockwise
    last, commands = player._commands(action, np.full(11, 0.5), 1.085, ActionScaling())
    assert commands == [Kick(75.0, -45.0)] * 11
    assert not last.any()  # a kick moves no one: (0, 0) is the last action it observes
    action[:, 1] = -1.0  # a dash at 0.5 wins now
    action[:, 5] = 0.5
    last, commands = player._commands(action, np.full(11, 0.5), 1.085, ActionScaling())
    assert commands == [Dash(50.0, 0.0)] * 11 and np.allclose(last, [0.5, 0.0])
    # elevens robocup train fine-tunes it (--network.actions 12): the run starts from its
    # networks.
    import json

    from elevens.robocup.train import make_robocup_config, train_robocup
    from elevens.runs.teams import load_learner_params
    from tests.robocup.test_train_play import KickScoreEnv

    network = json.loads((out / "config.json").read_text())["learner"]["network"]
    config = make_robocup_config(**{
        "env.players_per_team": 1, "ppo.minibatch_size": 1, "games_per_iteration": 1,
        "env.episode_length": 4, "run.max_minutes": 1e-9, "server.threads": False,
        "run.run_dir": str(tmp_path / "run"), "run.init_from": str(out),
        **{f"network.{name}": value for name, value in network.items()},
    })
    result = train_robocup(config, env_factory=lambda i: KickScoreEnv(1), progress=False)
    assert result.iteration == 0
    _, expected = load_learner_params(str(out))
    _, started = load_learner_params(str(tmp_path / "run"))
    for a, b in zip(jax.tree.leaves(expected), jax.tree.leaves(started), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
