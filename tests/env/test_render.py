"""Pictures of a game: pixels where geometry says, the env's own visibility, video round trips."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any, cast

import imageio.v2 as imageio
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from PIL import Image

import elevens
from elevens.env import EnvParams, State, render
from elevens.env.observe import observe

TEAM0_BLUE, TEAM1_RED = render.TEAM_COLOURS


def hand_state(
    params: EnvParams,
    positions: list[tuple[float, float]],
    headings: list[float],
    ball: tuple[float, float] = (20.0, -15.0),
    score: tuple[int, int] = (0, 0),
    step: int = 0,
) -> State:
    """A still game with NumPy leaves (render must take NumPy as well as JAX)."""
    num_players = params.num_players
    assert len(positions) == len(headings) == num_players
    pos = jnp.asarray(positions, jnp.float32)
    state = State(
        positions=pos,
        headings=jnp.asarray(headings, jnp.float32),
        velocities=jnp.zeros((num_players, 2)),
        last_actions=jnp.zeros((num_players, 2)),
        start_positions=pos,
        ball_position=jnp.asarray(ball, jnp.float32),
        ball_velocity=jnp.zeros(2),
        score=jnp.asarray(score, jnp.int32),
        step=jnp.asarray(step, jnp.int32),
    )
    return jax.tree.map(np.asarray, state)


def pixel(frame: np.ndarray, params: EnvParams, xy: tuple[float, float], scale: float = 8
          ) -> np.ndarray:
    column, row = render.world_to_pixel(np.asarray(xy), params, scale=scale)
    return frame[int(row), int(column)].astype(int)


def is_colour(value: np.ndarray, colour: tuple[int, int, int], tolerance: int = 30) -> bool:
    return bool(np.all(np.abs(value - np.asarray(colour)) <= tolerance))


@pytest.fixture(scope="module")
def params_1v1() -> EnvParams:
    return elevens.make("1v1")[1]


@pytest.fixture(scope="module")
def params_2v2() -> EnvParams:
    return elevens.make("2v2")[1]


def test_frame_shape_dtype_and_size_follow_scale(params_1v1: EnvParams) -> None:
    state = hand_state(params_1v1, [(0.0, 10.0), (20.0, 0.0)], [0.0, math.pi])
    frame = render.render_frame(state, params_1v1)
    assert frame.dtype == np.uint8
    assert frame.ndim == 3 and frame.shape[-1] == 3
    assert frame.shape[:2] == render.frame_size(params_1v1, scale=8)
    small = render.render_frame(state, params_1v1, scale=4)
    assert small.shape[1] < frame.shape[1] and small.shape[0] < frame.shape[0]
    # The field (100 m long) spans 100 * scale pixels between its goal lines.
    left = render.world_to_pixel(np.array([-50.0, 0.0]), params_1v1)
    right = render.world_to_pixel(np.array([50.0, 0.0]), params_1v1)
    assert right[0] - left[0] == pytest.approx(800.0)


def test_players_and_ball_are_drawn_where_they_stand(params_1v1: EnvParams) -> None:
    state = hand_state(params_1v1, [(0.0, 10.0), (25.0, -20.0)], [0.0, math.pi],
                       ball=(20.0, -15.0))
    frame = render.render_frame(state, params_1v1)
    # Half a metre behind the centre is body (the heading tick starts at the centre).
    assert is_colour(pixel(frame, params_1v1, (-0.5, 10.0)), TEAM0_BLUE)
    assert is_colour(pixel(frame, params_1v1, (25.5, -20.0)), TEAM1_RED)
    assert is_colour(pixel(frame, params_1v1, (20.0, -15.0)), render.BALL_COLOUR, tolerance=5)
    # World y points up: the player at y=+10 sits above the ball at y=-15.
    assert render.world_to_pixel(np.array([0.0, 10.0]), params_1v1)[1] < \
        render.world_to_pixel(np.array([0.0, -15.0]), params_1v1)[1]
    # Open grass where nobody stands keeps the grass colour.
    grass = pixel(frame, params_1v1, (-25.0, -25.0))
    assert any(is_colour(grass, colour, 2) for colour in render.GRASS_COLOURS)


def test_heading_turns_tick_and_leg_bar(params_1v1: EnvParams) -> None:
    east = hand_state(params_1v1, [(0.0, 10.0), (25.0, -20.0)], [0.0, math.pi])
    north = hand_state(params_1v1, [(0.0, 10.0), (25.0, -20.0)], [math.pi / 2, math.pi])
    frame_east = render.render_frame(east, params_1v1)
    frame_north = render.render_frame(north, params_1v1)
    assert not np.array_equal(frame_east, frame_north)
    tip = render.HEADING_TICK * 0.8  # inside the tick, outside the disc (radius 1)
    assert is_colour(pixel(frame_east, params_1v1, (tip, 10.0)), render.HEADING_COLOUR, 40)
    assert not is_colour(pixel(frame_north, params_1v1, (tip, 10.0)), render.HEADING_COLOUR, 40)
    assert is_colour(pixel(frame_north, params_1v1, (0.0, 10.0 + tip)), render.HEADING_COLOUR, 40)
    # The leg bar lies across the heading: 2.5 m to the player's left.
    leg = render.LEG_COLOURS[0]
    assert is_colour(pixel(frame_east, params_1v1, (0.0, 12.5)), leg)
    assert is_colour(pixel(frame_north, params_1v1, (-2.5, 10.0)), leg)
    assert not is_colour(pixel(frame_north, params_1v1, (0.0, 12.5)), leg)


def observer_scene(params: EnvParams) -> State:
    # Team 0 player 0 at the centre facing +x; opponent 2 ahead, opponent 3 behind, teammate 1
    # behind, ball ahead to the right.
    return hand_state(
        params,
        [(0.0, 0.0), (-30.0, -20.0), (15.0, 0.0), (-15.0, 10.0)],
        [0.0, 0.0, math.pi, math.pi],
        ball=(10.0, -12.0),
    )


def test_render_is_deterministic_and_takes_jax_or_numpy(params_2v2: EnvParams) -> None:
    state = jax.tree.map(jnp.asarray, observer_scene(params_2v2))
    first = render.render_frame(state, params_2v2, title="t", highlight=1)
    second = render.render_frame(state, params_2v2, title="t", highlight=1)
    from_numpy = render.render_frame(jax.tree.map(np.asarray, state), params_2v2, title="t",
                                     highlight=1)
    np.testing.assert_array_equal(first, second)
    np.testing.assert_array_equal(first, from_numpy)
    assert not np.array_equal(first, render.render_frame(state, params_2v2, title="t"))
    assert not np.array_equal(
        first, render.render_frame(dataclasses.replace(state, score=jnp.array([3, 0])), params_2v2,
                                   title="t", highlight=1)
    )
    with pytest.raises(ValueError, match="highlight"):
        render.render_frame(state, params_2v2, highlight=4)


def test_visible_entities_read_the_env_mask(params_2v2: EnvParams) -> None:
    state = observer_scene(params_2v2)
    mask = np.asarray(jax.jit(observe)(state, params_2v2).entity_mask)
    seen = render.visible_entities(mask, params_2v2, 0)
    # players 0 (self), 1 (mate behind), 2 (opponent ahead), 3 (opponent behind), then the ball
    np.testing.assert_array_equal(seen, [False, False, True, False, True])
    # Player 2 at x=15 faces -x: everything else lies ahead of it; it never sees itself.
    seen_by_2 = render.visible_entities(mask, params_2v2, 2)
    np.testing.assert_array_equal(seen_by_2, [True, True, False, True, True])


def test_visible_entities_match_the_angle_rule_on_random_games() -> None:
    params = elevens.make("3v3")[1]
    rng = np.random.default_rng(0)
    observe_jit = jax.jit(observe)
    for _ in range(3):
        positions = rng.uniform([-50, -35], [50, 35], (params.num_players, 2))
        headings = rng.uniform(-math.pi, math.pi, params.num_players)
        ball = rng.uniform([-50, -35], [50, 35])
        state = hand_state(params, [tuple(p) for p in positions], list(headings), tuple(ball))
        mask = np.asarray(observe_jit(state, params).entity_mask)
        entities = np.concatenate([state.positions, state.ball_position[None]]).astype(np.float64)
        for player in range(params.num_players):
            offset = entities - entities[player]
            bearing = np.arctan2(offset[:, 1], offset[:, 0]) - float(state.headings[player])
            expected = np.cos(bearing) >= math.cos(params.fov_half_angle)
            expected[player] = False
            seen = render.visible_entities(mask, params, player)
            np.testing.assert_array_equal(seen, expected)


def test_observation_view_marks_seen_and_unseen(params_2v2: EnvParams) -> None:
    state = observer_scene(params_2v2)
    frame = render.render_frame(state, params_2v2)
    view = render.render_observation(state, params_2v2, 0)
    assert view.shape == frame.shape and view.dtype == np.uint8
    np.testing.assert_array_equal(view, render.render_observation(state, params_2v2, (0, 0)))
    # The opponent ahead keeps its full colour; the one behind is faded towards the grass.
    assert is_colour(pixel(view, params_2v2, (15.5, 0.0)), TEAM1_RED)
    behind = pixel(view, params_2v2, (-14.5, 10.0))
    assert not is_colour(behind, TEAM1_RED)
    assert np.abs(behind - pixel(frame, params_2v2, (-14.5, 10.0))).sum() > 60
    assert not is_colour(pixel(view, params_2v2, (-29.5, -20.0)), TEAM0_BLUE)
    # A sight line runs to the seen opponent and to the ball, none to the unseen opponent.
    on_line = (7.0, 0.0)
    assert np.abs(pixel(view, params_2v2, on_line) - pixel(frame, params_2v2, on_line)).sum() > 60
    assert is_colour(pixel(view, params_2v2, (5.0, -6.0)), render.BALL_COLOUR, 40)
    np.testing.assert_array_equal(pixel(view, params_2v2, (-7.5, 5.0)),
                                  pixel(frame, params_2v2, (-7.5, 5.0)))
    # The field of view lightens the grass ahead and leaves the grass behind alone.
    ahead = (30.0, 25.0)
    assert pixel(view, params_2v2, ahead).sum() > pixel(frame, params_2v2, ahead).sum() + 30
    np.testing.assert_array_equal(pixel(view, params_2v2, (-30.0, 25.0)),
                                  pixel(frame, params_2v2, (-30.0, 25.0)))
    with pytest.raises(ValueError, match="player"):
        render.render_observation(state, params_2v2, 4)


def stacked_history(steps: int = 4) -> tuple[State, EnvParams]:
    """Everyone walks 2 m per step along its heading, while the ball rolls to the right."""
    params = elevens.make("2v2")[1]
    positions = np.array([(-20.0, 0.0), (-10.0, 15.0), (20.0, 0.0), (10.0, -15.0)])
    headings = np.array([0.0, -0.5, math.pi, 2.5])
    forward = np.stack([np.cos(headings), np.sin(headings)], axis=-1)
    states = [
        hand_state(params, [tuple(p) for p in positions + 2.0 * t * forward], list(headings),
                   ball=(1.5 * t, 0.0), step=t)
        for t in range(steps)
    ]
    return jax.tree.map(lambda *leaves: np.stack(leaves), *states), params


def test_frames_from_states_draw_each_step() -> None:
    states, params = stacked_history()
    frames = render.frames_from_states(states, params, scale=4)
    assert len(frames) == 4
    for t, frame in enumerate(frames):
        state_t = jax.tree.map(lambda leaf, t=t: leaf[t], states)
        np.testing.assert_array_equal(frame, render.render_frame(state_t, params, scale=4))
    assert not np.array_equal(frames[0], frames[-1])
    views = render.frames_from_states(states, params, player=3, scale=4, progress=True)
    last = jax.tree.map(lambda leaf: leaf[-1], states)
    np.testing.assert_array_equal(views[-1], render.render_observation(last, params, 3, scale=4))
    with pytest.raises(ValueError, match="time axis"):
        render.frames_from_states(last, params)


@pytest.fixture(scope="module")
def small_frames() -> list[np.ndarray]:
    states, params = stacked_history(5)
    return render.frames_from_states(states, params, scale=2)


def test_gif_round_trip(small_frames: list[np.ndarray], tmp_path: Path) -> None:
    path = render.save_video(small_frames, tmp_path / "game.gif", fps=20)
    with Image.open(path) as gif:
        assert getattr(gif, "n_frames", 1) == len(small_frames)
        assert gif.size == (small_frames[0].shape[1], small_frames[0].shape[0])
        assert gif.info["loop"] == 0
        assert gif.info["duration"] == 50
        gif.seek(len(small_frames) - 1)
        last = np.asarray(gif.convert("RGB"), dtype=int)
    # The shared palette keeps colours close (quantisation, no dithering).
    assert np.abs(last - small_frames[-1]).mean() < 4


# Reading starts ffmpeg (fork + exec at once), which JAX's fork warning does not concern.
@pytest.mark.filterwarnings("ignore:os.fork:RuntimeWarning")
def test_mp4_round_trip_pads_to_macroblocks(small_frames: list[np.ndarray],
                                            tmp_path: Path) -> None:
    height, width = small_frames[0].shape[:2]
    path = render.save_video(small_frames, tmp_path / "game.mp4", fps=10)
    reader = cast(Any, imageio.get_reader(path))
    try:
        read = [np.asarray(frame) for frame in reader]
    finally:
        reader.close()
    assert len(read) == len(small_frames)
    padded = (-(-height // 16) * 16, -(-width // 16) * 16)
    assert read[0].shape == (*padded, 3)
    # Padding adds rows and columns at the bottom right; the picture itself is not rescaled.
    error = np.abs(read[-1][:height, :width].astype(int) - small_frames[-1]).mean()
    assert error < 4  # measured about 2 (H.264 at quality 8); a rescale gives about 9


def test_video_rejects_unknown_suffix_and_bad_frames(small_frames: list[np.ndarray],
                                                     tmp_path: Path) -> None:
    with pytest.raises(ValueError, match=r"\.gif, \.mp4"):
        render.save_video(small_frames, tmp_path / "game.avi", fps=20)
    with pytest.raises(ValueError, match="frame 1"):
        render.save_gif([small_frames[0], small_frames[0][:-2]], tmp_path / "bad.gif")
    with pytest.raises(ValueError, match="no frames"):
        render.save_mp4([], tmp_path / "empty.mp4")
    with pytest.raises(ValueError, match="fps"):
        render.save_gif(small_frames, tmp_path / "slow.gif", fps=0)


def test_follow_ball_zooms_on_the_ball_and_keeps_the_header() -> None:
    env, params = elevens.make("2v2", episode_length=3)
    state, _ = env.reset(jax.random.key(1), params)
    states = jax.tree.map(lambda leaf: np.stack([np.asarray(leaf)] * 2), state)
    plain = render.frames_from_states(states, params, scale=4)
    zoomed = render.frames_from_states(states, params, scale=4, follow_ball=20.0)
    assert zoomed[0].shape == plain[0].shape
    header = render._layout(params, 4).header_px
    np.testing.assert_array_equal(zoomed[0][:header], plain[0][:header])
    assert not np.array_equal(zoomed[0][header:], plain[0][header:])
    # The ball (white) fills far more of the zoomed picture.
    white = [np.all(frame[header:] > 245, axis=-1).sum() for frame in (plain[0], zoomed[0])]
    assert white[1] > 3 * white[0]
    with pytest.raises(ValueError, match="follow_ball=0"):
        render.frames_from_states(states, params, follow_ball=0)


def test_players_carry_their_numbers_and_unseen_ones_keep_their_hue(
    params_2v2: EnvParams,
) -> None:
    # Players 1 and 2 of each team, far apart; numbers sit above and to the right of a player.
    state = hand_state(params_2v2, [(-30.0, 10.0), (-30.0, -20.0), (20.0, 20.0), (25.0, -10.0)],
                       [0.0, 0.0, math.pi, math.pi], ball=(0.0, 0.0))
    frame = render.render_frame(state, params_2v2)

    def label_box(xy: tuple[float, float]) -> np.ndarray:
        # Pixels 1 to 4 m up and right of the centre: the number, on grass otherwise.
        (c0, r0), (c1, r1) = (render.world_to_pixel(np.asarray(p), params_2v2, scale=8)
                              for p in ((xy[0] + 0.6, xy[1] + 4.0), (xy[0] + 3.5, xy[1] + 0.6)))
        return frame[int(r0):int(r1), int(c0):int(c1)]

    for xy in [(-30.0, 10.0), (-30.0, -20.0), (20.0, 20.0), (25.0, -10.0)]:
        white = np.all(label_box(xy) >= 240, axis=-1).sum()
        assert white >= 6, xy  # the digit's white fill
    # The two players of a team carry different numbers.
    assert not np.array_equal(np.all(label_box((-30.0, 10.0)) >= 240, axis=-1),
                              np.all(label_box((-30.0, -20.0)) >= 240, axis=-1))
    # In player 0's view the red player behind it is unseen: pale, but still red, not green.
    view = render.render_observation(state, params_2v2, (0, 0))
    behind = hand_state(params_2v2, [(0.0, 0.0), (-30.0, -20.0), (-20.0, 0.0), (25.0, -10.0)],
                        [0.0, 0.0, math.pi, math.pi], ball=(10.0, 0.0))
    view = render.render_observation(behind, params_2v2, (0, 0))
    red = pixel(view, params_2v2, (-19.6, 0.4))  # in the disc, off its heading tick
    assert red[0] > red[1] + 40 and red[0] > red[2] + 40
    assert not is_colour(red, TEAM1_RED)  # and faded
