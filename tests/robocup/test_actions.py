"""The 12-value thesis action -> one rcssserver command (elevens.robocup.actions)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from elevens.robocup.actions import (
    ACTION_SIZE,
    ActionIndex,
    ActionScaling,
    action_to_command,
    actions_to_commands,
)
from elevens.robocup.protocol import (
    Dash,
    Kick,
    NoOp,
    ServerParams,
    Tackle,
    Turn,
    parse_sexp,
)

I = ActionIndex


def act(choice: ActionIndex | None = None, **params: float) -> np.ndarray:
    """An action with ``choice``'s score 1 (others 0) and named parameters set."""
    a = np.zeros(ACTION_SIZE, dtype=np.float32)
    if choice is not None:
        a[int(choice)] = 1.0
    for name, value in params.items():
        a[int(ActionIndex[name.upper()])] = value
    return a


def test_layout_matches_thesis_table_4_1() -> None:
    assert ACTION_SIZE == 12
    assert [i.name for i in ActionIndex] == [
        "DASH_SCORE",
        "KICK_SCORE",
        "TURN_SCORE",
        "TACKLE_SCORE",
        "NOOP_SCORE",
        "DASH_POWER",
        "DASH_DIR",
        "KICK_POWER",
        "KICK_DIR",
        "TURN_MOMENT",
        "TACKLE_FOUL",
        "TACKLE_DIR",
    ]
    assert [int(i) for i in ActionIndex] == list(range(12))


@pytest.mark.parametrize(
    ("power", "direction", "expected"),
    [
        (1.0, 0.0, Dash(100.0, 0.0)),
        (0.0, 0.0, Dash(0.0, 0.0)),
        (0.5, 1.0, Dash(50.0, 90.0)),
        (0.5, -1.0, Dash(50.0, -90.0)),
        # Backwards: power 0..100 only since v17, so turn the direction by 180.
        (-1.0, 0.0, Dash(100.0, 180.0)),
        (-0.5, 0.5, Dash(50.0, -135.0)),
        (-0.5, -0.5, Dash(50.0, 135.0)),
        (-1.0, 1.0, Dash(100.0, -90.0)),
    ],
)
def test_dash(power: float, direction: float, expected: Dash) -> None:
    cmd = action_to_command(act(I.DASH_SCORE, dash_power=power, dash_dir=direction))
    assert isinstance(cmd, Dash)
    assert cmd.power == pytest.approx(expected.power)
    assert cmd.direction == pytest.approx(expected.direction)
    cmd.encode()  # within the server ranges


def test_dash_with_negative_power_server() -> None:
    params = ServerParams({"min_dash_power": -100})
    cmd = action_to_command(act(I.DASH_SCORE, dash_power=-0.5, dash_dir=0.5), params)
    assert cmd == Dash(-50.0, 45.0)
    assert cmd.encode(params) == b"(dash -50 45)"


@pytest.mark.parametrize(
    ("power", "direction", "exp_power", "exp_dir"),
    [
        (-1.0, 0.0, 0.0, 0.0),
        (0.0, 0.5, 50.0, 90.0),
        (1.0, -1.0, 100.0, -180.0),
        (1.0, 1.0, 100.0, 180.0),
        (0.5, -0.25, 75.0, -45.0),
    ],
)
def test_kick(power: float, direction: float, exp_power: float, exp_dir: float) -> None:
    cmd = action_to_command(act(I.KICK_SCORE, kick_power=power, kick_dir=direction))
    assert cmd == Kick(exp_power, exp_dir)
    cmd.encode()


@pytest.mark.parametrize(
    ("moment", "expected"), [(-1.0, -180.0), (0.0, 0.0), (1.0, 180.0), (0.25, 45.0)]
)
def test_turn(moment: float, expected: float) -> None:
    assert action_to_command(act(I.TURN_SCORE, turn_moment=moment)) == Turn(expected)


@pytest.mark.parametrize(
    ("foul", "direction", "expected"),
    [
        (1.0, 0.0, Tackle(0.0, True)),
        (0.0, 1.0, Tackle(90.0, False)),
        (-1.0, -1.0, Tackle(-90.0, False)),
        (0.01, 0.5, Tackle(45.0, True)),
    ],
)
def test_tackle(foul: float, direction: float, expected: Tackle) -> None:
    cmd = action_to_command(act(I.TACKLE_SCORE, tackle_foul=foul, tackle_dir=direction))
    assert cmd == expected
    assert cmd.encode() == expected.encode()


def test_tackle_encoding_carries_the_foul_flag() -> None:
    assert action_to_command(act(I.TACKLE_SCORE, tackle_foul=1, tackle_dir=-1)).encode() == (
        b"(tackle -90 on)"
    )
    assert action_to_command(act(I.TACKLE_SCORE, tackle_foul=0, tackle_dir=1)).encode() == (
        b"(tackle 90 off)"
    )


def test_noop_sends_nothing() -> None:
    cmd = action_to_command(act(I.NOOP_SCORE))
    assert cmd == NoOp()
    assert cmd.encode() == b""


def test_parameters_of_unselected_commands_are_ignored() -> None:
    full = np.ones(ACTION_SIZE)
    full[:5] = (0.0, 0.0, 1.0, 0.0, 0.0)
    assert action_to_command(full) == Turn(180.0)


@pytest.mark.parametrize(
    ("scores", "expected"),
    [
        ((0, 0, 0, 0, 0), Dash),  # all tied -> lowest index
        ((-1, -1, -1, -1, -1), Dash),
        ((0, 1, 1, 0, 0), Kick),
        ((0, 0, 0.5, 0.5, 0.5), Turn),
        ((0, 0, 0, 1, 1), Tackle),
        ((0, 0, 0, 0, 1e-6), NoOp),
        ((1, 1, 1, 1, 1), Dash),
        ((-1, -0.2, -0.5, -1, -0.2), Kick),
    ],
)
def test_selection_argmax_and_ties(scores: tuple[float, ...], expected: type) -> None:
    a = np.zeros(ACTION_SIZE)
    a[:5] = scores
    assert type(action_to_command(a)) is expected


def test_out_of_range_values_are_clipped() -> None:
    big = act(None, dash_power=7.0, dash_dir=-3.0)
    big[int(I.DASH_SCORE)] = 50.0
    assert action_to_command(big) == Dash(100.0, -90.0)
    assert action_to_command(act(I.TURN_SCORE, turn_moment=-9.0)) == Turn(-180.0)
    assert action_to_command(act(I.KICK_SCORE, kick_power=3.0, kick_dir=2.0)) == Kick(100.0, 180.0)
    # Clipping a score above 1 ties it with a score of 1: lowest index wins.
    tie = np.zeros(ACTION_SIZE)
    tie[int(I.KICK_SCORE)] = 1.0
    tie[int(I.TURN_SCORE)] = 5.0
    assert isinstance(action_to_command(tie), Kick)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
@pytest.mark.parametrize("index", list(ActionIndex))
def test_non_finite_values_raise_naming_the_value(bad: float, index: ActionIndex) -> None:
    a = act(I.DASH_SCORE)
    a[int(index)] = bad
    with pytest.raises(ValueError, match=rf"action\[{int(index)}\]") as info:
        action_to_command(a)
    assert index.name in str(info.value)
    assert repr(bad) in str(info.value)


def test_batched_nan_names_the_batch_position() -> None:
    a = np.zeros((2, 3, ACTION_SIZE), dtype=np.float32)
    a[1, 2, 9] = np.nan
    expected = r"action\[9\] \(turn moment, TURN_MOMENT\) of action \(1, 2\)"
    with pytest.raises(ValueError, match=expected):
        actions_to_commands(a)


@pytest.mark.parametrize(
    "shape",
    [(), (11,), (13,), (0,), (4, 11), (12, 3)],
)
def test_wrong_shapes_raise(shape: tuple[int, ...]) -> None:
    with pytest.raises(ValueError, match="shape"):
        actions_to_commands(np.zeros(shape))
    with pytest.raises(ValueError, match="shape"):
        action_to_command(np.zeros(shape))


def test_single_command_rejects_batches_and_non_numeric() -> None:
    with pytest.raises(ValueError, match="actions_to_commands"):
        action_to_command(np.zeros((2, ACTION_SIZE)))
    with pytest.raises(ValueError, match="numeric"):
        action_to_command(np.array(["a"] * ACTION_SIZE))
    with pytest.raises(ValueError, match="numeric"):
        action_to_command([None] * ACTION_SIZE)


def test_batched_order_and_single() -> None:
    batch = np.stack(
        [
            np.stack([act(I.DASH_SCORE, dash_power=1), act(I.KICK_SCORE, kick_power=1)]),
            np.stack([act(I.TURN_SCORE, turn_moment=-1), act(I.NOOP_SCORE)]),
        ]
    ).astype(np.float32)
    assert batch.shape == (2, 2, ACTION_SIZE)
    cmds = actions_to_commands(batch)
    assert cmds == [Dash(100.0, 0.0), Kick(100.0, 0.0), Turn(-180.0), NoOp()]
    assert actions_to_commands(act(I.TURN_SCORE)) == [Turn(0.0)]
    # Lists and float64 arrays work the same as float32 arrays.
    assert action_to_command(act(I.TURN_SCORE, turn_moment=0.5).tolist()) == Turn(90.0)


def test_scaling_from_recorded_server_params_equals_defaults() -> None:
    from pathlib import Path

    from elevens.robocup.protocol import parse_message

    line = (
        (Path(__file__).resolve().parents[1] / "data" / "rcss" / "server_param.txt")
        .read_text()
        .splitlines()[0]
    )
    params = parse_message(line.split("\t", 1)[1])
    assert isinstance(params, ServerParams)
    assert ActionScaling.from_server_params(params) == ActionScaling()
    assert ActionScaling.from_server_params(None) == ActionScaling()
    assert action_to_command(act(I.DASH_SCORE, dash_power=1), params) == Dash(100.0, 0.0)


def test_random_actions_always_give_a_valid_command() -> None:
    rng = np.random.default_rng(0)
    actions = rng.uniform(-1.5, 1.5, size=(2000, ACTION_SIZE)).astype(np.float32)
    kinds = set()
    for cmd in actions_to_commands(actions):
        text = cmd.encode().decode()
        kinds.add(type(cmd).__name__)
        if text:
            tree = parse_sexp(text)
            assert tree[0] in ("dash", "kick", "turn", "tackle")
    assert kinds == {"Dash", "Kick", "Turn", "Tackle", "NoOp"}


def test_a_policy_s_action_count_names_its_mode() -> None:
    from elevens.robocup.actions import ACTION_SIZES, action_mode

    assert action_mode(2) == "sim" and action_mode(12) == "thesis12"
    assert all(action_mode(size) == mode for mode, size in ACTION_SIZES.items())
    with pytest.raises(ValueError, match=r"7 action values has no RoboCupEnv action mode"):
        action_mode(7)


def test_a_kick_out_of_reach_becomes_a_dash_towards_the_ball() -> None:
    """The server ignores a kick with the ball out of reach: a cycle without a dash."""
    kick = act(I.KICK_SCORE, kick_power=1.0, dash_power=-1.0, turn_moment=0.5)
    kicks = np.stack([kick] * 4)
    distance = [0.9, 2.0, 10.0, 1.085]
    bearing = [0.0, 0.5, -1.0, 0.0]  # radians, + = left of the body
    commands = actions_to_commands(kicks, ball_distance=distance, ball_bearing=bearing)
    assert commands[0] == Kick(100.0, 0.0) and commands[3] == Kick(100.0, 0.0)  # in reach
    # Towards the ball (server directions: + = clockwise); half power near it, full far.
    assert commands[1] == Dash(50.0, -math.degrees(0.5))
    assert commands[2] == Dash(100.0, math.degrees(1.0))
    # Reach by the server's kickable area when it is given (a wider player type's).
    wide = actions_to_commands(kicks, ball_distance=distance, ball_bearing=bearing, kickable=2.5)
    assert wide[1] == Kick(100.0, 0.0)
    # Without the ball's whereabouts every kick goes out as chosen.
    assert actions_to_commands(kicks) == [Kick(100.0, 0.0)] * 4


def test_a_kick_with_the_ball_unseen_becomes_the_policys_dash_or_turn() -> None:
    unseen = dict(ball_distance=[math.inf], ball_bearing=[math.nan])
    dash_next = act(I.KICK_SCORE, dash_score=0.5, turn_score=0.2, dash_power=0.5, dash_dir=0.5)
    assert actions_to_commands(dash_next[None], **unseen) == [Dash(50.0, 45.0)]
    turn_next = act(I.KICK_SCORE, dash_score=0.2, turn_score=0.5, turn_moment=-0.5)
    assert actions_to_commands(turn_next[None], **unseen) == [Turn(-90.0)]
    # Felt close behind ((B), outside the cone): its distance is known, its bearing is not.
    felt = dict(ball_distance=[2.0], ball_bearing=[math.nan])
    assert actions_to_commands(turn_next[None], **felt) == [Turn(-90.0)]
    # No bearing array at all: the same.
    assert actions_to_commands(turn_next[None], ball_distance=[2.0]) == [Turn(-90.0)]
    # Other commands are never touched.
    dash = act(I.DASH_SCORE, dash_power=0.5)
    assert actions_to_commands(dash[None], **unseen) == [Dash(50.0, 0.0)]


def test_ball_arrays_must_match_the_actions() -> None:
    with pytest.raises(ValueError, match=r"one value per action \(2\), got 3 and 2"):
        actions_to_commands(np.zeros((2, ACTION_SIZE)), ball_distance=[1, 2, 3],
                            ball_bearing=[0, 0])
