"""Percepts -> the simulator's containers (elevens.robocup.observe), on recorded rcssserver 19
messages (tests/data/rcss) and hand-built ones. No server needed."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import jax
import numpy as np
import pytest

from elevens.env.observe import entity_layout, observe
from elevens.env.params import EnvParams
from elevens.env.state import (
    ENTITY_FEATURES,
    NUM_ENTITY_FEATURES,
    NUM_SELF_FEATURES,
    SELF_FEATURES,
    State,
)
from elevens.robocup.observe import (
    FIELD_LENGTH,
    PerceptMemory,
    body_from_world_heading,
    entities_from_see,
    pose_from_see,
    server_from_world,
    state_from_global,
    team_from_server,
    team_heading_from_server,
    world_from_server,
    world_heading_from_server,
)
from elevens.robocup.protocol import GlobalView, SeeMessage, SenseBody, parse_message

DATA = Path(__file__).resolve().parents[1] / "data" / "rcss"
RECORDED_TEAMS = ("LeftTeam", "RightTeam")
E = {name: i for i, name in enumerate(ENTITY_FEATURES)}
S = {name: i for i, name in enumerate(SELF_FEATURES)}
KNOWN_POSE_POS_TOL = 0.5  # metres, as tests/robocup/test_localize.py (measured worst 0.18)
KNOWN_POSE_DIR_TOL = math.radians(1.0)


@dataclass(frozen=True)
class FakePlayerCycle:
    """The fields of elevens.robocup.client.PlayerCycle that the percept code reads."""

    side: int
    unum: int
    see: SeeMessage | None
    sense_body: SenseBody | None = None
    thought: bool = True


def robocup_params(n: int, **overrides: float) -> EnvParams:
    return EnvParams(
        players_per_team=n, field_length=105.0, field_width=68.0, goal_width=14.02, **overrides
    )


def recorded(name: str) -> list[tuple[str, object]]:
    out = []
    for line in (DATA / name).read_text().splitlines():
        who, text = line.split("\t", 1)
        out.append((who, parse_message(text)))
    return out


def see(text: str) -> SeeMessage:
    message = parse_message(text)
    assert isinstance(message, SeeMessage)
    return message


def sense(speed: float = 0.0, direction: float = 0.0) -> SenseBody:
    message = parse_message(
        f"(sense_body 1 (view_mode high wide) (stamina 8000 1 130600) (speed {speed} {direction}) "
        "(head_angle 0) (kick 0) (dash 0) (turn 0) (say 0) (turn_neck 0) (catch 0) (move 0) "
        "(change_view 0))"
    )
    assert isinstance(message, SenseBody)
    return message


def angle_error(a: float, b: float) -> float:
    return abs(math.remainder(a - b, 2 * math.pi))


# ------------------------------------------------------------------------------ frames
def test_frames_follow_the_brief_for_both_teams() -> None:
    np.testing.assert_allclose(world_from_server(np.array([10.0, 5.0])), [10.0, -5.0])
    np.testing.assert_allclose(server_from_world(world_from_server(np.array([3.0, -7.0]))), [3, -7])
    np.testing.assert_allclose(team_from_server(np.array([10.0, 5.0]), 0), [10.0, -5.0])
    np.testing.assert_allclose(team_from_server(np.array([10.0, 5.0]), 1), [-10.0, 5.0])
    # Body 90 (server, clockwise) faces the bottom side line (y_srv > 0): -pi/2 in team 0's frame.
    assert float(world_heading_from_server(90.0)) == pytest.approx(-math.pi / 2)
    assert float(team_heading_from_server(90.0, 0)) == pytest.approx(-math.pi / 2)
    assert float(team_heading_from_server(90.0, 1)) == pytest.approx(math.pi / 2)
    # A right-side player facing the left goal (body 180) attacks +x in its own frame.
    assert angle_error(float(team_heading_from_server(180.0, 1)), 0.0) < 1e-12
    assert angle_error(float(team_heading_from_server(0.0, 1)), math.pi) < 1e-12
    headings = np.linspace(-math.pi, math.pi, 13, endpoint=False)
    body = body_from_world_heading(headings)
    assert np.all((body > -180.0) & (body <= 180.0))
    np.testing.assert_allclose(world_heading_from_server(body), headings, atol=1e-12)


def test_known_pose_converts_for_both_teams() -> None:
    """see_at_known_pose.json: L2 placed at (0, 0) with body 0/90/180/-90 (server frame). The
    same percepts read as a team-1 player give the point-reflected pose."""
    samples = json.loads((DATA / "see_at_known_pose.json").read_text())
    assert len(samples) >= 4
    bodies = set()
    for _, body, text in samples:
        message = see(text)
        bodies.add(body)
        for team in (0, 1):
            pose = pose_from_see(message, 0.0, team)
            assert pose is not None
            x, y, heading = pose
            assert math.hypot(x, y) < KNOWN_POSE_POS_TOL
            expected = -math.radians(body) + (math.pi if team == 1 else 0.0)
            assert angle_error(heading, expected) < KNOWN_POSE_DIR_TOL, (team, body, heading)
        x0, y0, h0 = pose_from_see(message, 0.0, 0)  # type: ignore[misc]
        x1, y1, h1 = pose_from_see(message, 0.0, 1)  # type: ignore[misc]
        assert (x1, y1) == pytest.approx((-x0, -y0))
        assert angle_error(h1, h0 + math.pi) < 1e-9
    assert {0, 90, 180} <= bodies


def test_known_pose_facing_the_bottom_sees_the_bottom_flag_ahead() -> None:
    """Body 90 at (0, 0): the flag (f c b) (0, 34) is straight ahead; in the simulator frame the
    player faces -y (heading -pi/2) and the flag at world (0, -34) is at bearing 0."""
    samples = json.loads((DATA / "see_at_known_pose.json").read_text())
    message = next(see(text) for _, body, text in samples if body == 90)
    flag = next(o for o in message.objects if o.name == "f c b")
    assert flag.direction == 0
    pose = pose_from_see(message, 0.0, 0)
    assert pose is not None
    assert angle_error(pose[2], -math.pi / 2) < KNOWN_POSE_DIR_TOL


# ---------------------------------------------------------------------------- percepts
@pytest.mark.parametrize("team", [0, 1])
@pytest.mark.parametrize(("direction", "bearing_deg"), [(0, 0.0), (30, -30.0), (-45, 45.0)])
def test_ball_bearing_has_the_simulator_sign(team: int, direction: int, bearing_deg: float) -> None:
    """Server direction +30 (clockwise, to the right) is sim bearing -30 (+ = left), either team."""
    seen = entities_from_see(
        see(f"(see 5 ((b) 10 {direction}))"),
        None,
        team=team,
        unum=1,
        players_per_team=2,
        team_names=("a", "b"),
    )
    ball = seen.entities[-1]
    assert seen.mask.tolist() == [False, False, False, True]
    assert ball[E["distance"]] == pytest.approx(10.0 / FIELD_LENGTH)
    assert ball[E["cos_bearing"]] == pytest.approx(math.cos(math.radians(bearing_deg)))
    assert ball[E["sin_bearing"]] == pytest.approx(math.sin(math.radians(bearing_deg)))
    assert ball[E["is_ball"]] == 1.0 and ball[E["is_teammate"]] == 0.0
    assert ball[E["cos_rel_heading"]] == 0.0 and ball[E["sin_rel_heading"]] == 0.0
    assert seen.ball_distance == 10.0


def test_velocities_from_distance_and_direction_changes() -> None:
    """Relative velocity = distchg along the sight line + rad(dirchg) * dist clockwise, plus own
    velocity (sense_body); players' velocities / player_decay (0.4), the ball's as they are."""
    dirchg = math.degrees(0.1)  # 0.1 rad/step clockwise at 10 m: 1 m/step to the right
    message = see(f"(see 5 ((b) 10 0 -0.5 {dirchg}) ((p \"b\" 1) 10 0 0 {dirchg} 0 0))")
    own = sense(speed=0.2, direction=-90)  # moving 0.2 m/step to the left (server dir -90)
    seen = entities_from_see(
        message, own, team=0, unum=1, players_per_team=1, team_names=("a", "b")
    )
    ball, opponent = seen.entities[1], seen.entities[0]
    assert ball[E["vel_forward"]] == pytest.approx(-0.5, abs=1e-6)
    assert ball[E["vel_left"]] == pytest.approx(-1.0 + 0.2, abs=1e-6)
    assert opponent[E["vel_forward"]] == pytest.approx(0.0, abs=1e-6)
    assert opponent[E["vel_left"]] == pytest.approx((-1.0 + 0.2) / 0.4, abs=1e-5)
    # An object at 90 deg to the right moving away: distchg along the sight line = -left.
    side = entities_from_see(
        see("(see 5 ((b) 5 90 1 0))"), None, team=1, unum=1, players_per_team=1,
        team_names=("a", "b"),
    )
    assert side.entities[1, E["vel_forward"]] == pytest.approx(0.0, abs=1e-6)
    assert side.entities[1, E["vel_left"]] == pytest.approx(-1.0, abs=1e-6)


def test_missing_changes_and_body_give_zero_features() -> None:
    seen = entities_from_see(
        see('(see 5 ((b) 30 10) ((p "b" 2) 40 -20))'),
        sense(0.5, 0),
        team=0,
        unum=1,
        players_per_team=2,
        team_names=("a", "b"),
    )
    for row in (seen.entities[-1], seen.entities[2]):
        assert row[E["vel_forward"]] == 0.0 and row[E["vel_left"]] == 0.0
        assert row[E["cos_rel_heading"]] == 0.0 and row[E["sin_rel_heading"]] == 0.0
        assert row[E["last_move"]] == 0.0 and row[E["last_rot"]] == 0.0


def test_relative_heading_of_a_seen_player() -> None:
    seen = entities_from_see(
        see('(see 5 ((p "a" 2) 5 0 0 0 90 90))'), None, team=0, unum=1, players_per_team=2,
        team_names=("a", "b"),
    )
    mate = seen.entities[0]  # body 90 clockwise of ours = facing to our right: -pi/2
    assert mate[E["cos_rel_heading"]] == pytest.approx(0.0, abs=1e-12)
    assert mate[E["sin_rel_heading"]] == pytest.approx(-1.0)
    assert mate[E["is_teammate"]] == 1.0


def test_slots_follow_the_simulator_layout() -> None:
    """Numbered players go to their slot of elevens.env.observe.entity_layout; unnumbered ones to
    the first free slot of their team; close (P)/(B) and unknown teams are left out."""
    n = 4
    message = see(
        '(see 9 ((p "a" 1) 5 0) ((p "a") 30 10) ((p "b" 3) 7 5) ((p "b") 40 -3) ((p "b" 1) 8 1)'
        ' ((p) 60 2) ((P) 1 170) ((B) 0.6 160))'
    )
    seen = entities_from_see(
        message, None, team=1, unum=2, players_per_team=n, team_names=("a", "b")
    )
    index, _ = entity_layout(n)
    observer = 1 * n + 1  # team 1, unum 2 (world order)
    slot_of = {int(entity): slot for slot, entity in enumerate(index[observer])}
    own = lambda unum: 1 * n + unum - 1  # noqa: E731
    other = lambda unum: 0 * n + unum - 1  # noqa: E731
    visible = set(np.flatnonzero(seen.mask).tolist())
    # own team "b": unums 1 and 3 -> their slots; the unnumbered "b" -> the free one (unum 4's)
    assert seen.entities[slot_of[own(1)], E["distance"]] == pytest.approx(8 / FIELD_LENGTH)
    assert seen.entities[slot_of[own(3)], E["distance"]] == pytest.approx(7 / FIELD_LENGTH)
    assert seen.entities[slot_of[own(4)], E["distance"]] == pytest.approx(40 / FIELD_LENGTH)
    assert seen.entities[slot_of[own(4)], E["is_teammate"]] == 1.0
    # team "a": unum 1 -> its slot, the unnumbered one -> the first free opponent slot (unum 2)
    assert seen.entities[slot_of[other(1)], E["distance"]] == pytest.approx(5 / FIELD_LENGTH)
    assert seen.entities[slot_of[other(2)], E["distance"]] == pytest.approx(30 / FIELD_LENGTH)
    assert seen.entities[slot_of[other(2)], E["is_teammate"]] == 0.0
    assert len(visible) == 5  # (p), (P) and the close (B) are not in view
    assert not seen.mask[-1]
    assert seen.ball_distance == pytest.approx(0.6)  # but the close ball can be kicked
    assert seen.dropped == 1  # (p): team unknown
    assert np.all(seen.entities[~seen.mask] == 0.0)


# ------------------------------------------------------------------------------ state
def test_state_from_global_view_frames_units_and_dtypes() -> None:
    views = [m for _, m in recorded("see_global_midgame.txt")]
    view = views[1]
    assert isinstance(view, GlobalView)
    n = 11
    state = state_from_global(
        view,
        players_per_team=n,
        team_names=RECORDED_TEAMS,
        last_actions=np.zeros((2 * n, 2)),
        start_positions=np.zeros((2 * n, 2)),
        score=np.array([1, 0]),
        step=7,
    )
    assert isinstance(state, State)
    for leaf, shape, dtype in [
        (state.positions, (22, 2), np.float32),
        (state.headings, (22,), np.float32),
        (state.velocities, (22, 2), np.float32),
        (state.last_actions, (22, 2), np.float32),
        (state.start_positions, (22, 2), np.float32),
        (state.ball_position, (2,), np.float32),
        (state.ball_velocity, (2,), np.float32),
        (state.score, (2,), np.int32),
        (state.step, (), np.int32),
    ]:
        assert isinstance(leaf, np.ndarray) and leaf.shape == shape and leaf.dtype == dtype
    assert view.ball is not None
    np.testing.assert_allclose(state.ball_position, [view.ball.x, -view.ball.y], rtol=1e-6)
    for player in view.players:
        row = (0 if player.team == "LeftTeam" else 1) * n + player.unum - 1
        np.testing.assert_allclose(state.positions[row], [player.x, -player.y], rtol=1e-6)
        assert angle_error(float(state.headings[row]), -math.radians(player.body)) < 1e-6
        # Reported velocities are after the decay: the displacement is 1 / 0.4 of them.
        np.testing.assert_allclose(
            state.velocities[row], [player.vx / 0.4, -player.vy / 0.4], rtol=1e-5, atol=1e-9
        )
    # ... which the next view confirms for the player that moved most (R8: 0.16, -0.21 m).
    after = state_from_global(
        views[2], players_per_team=n, team_names=RECORDED_TEAMS, last_actions=np.zeros((22, 2)),
        start_positions=np.zeros((22, 2)), score=np.zeros(2), step=8,
    )
    before = state_from_global(
        views[0], players_per_team=n, team_names=RECORDED_TEAMS, last_actions=np.zeros((22, 2)),
        start_positions=np.zeros((22, 2)), score=np.zeros(2), step=6,
    )
    moved = state.positions - before.positions
    row = int(np.argmax(np.linalg.norm(moved, axis=1)))
    assert np.linalg.norm(moved[row]) > 0.2
    np.testing.assert_allclose(state.velocities[row], moved[row], atol=2e-3)
    assert after.step == 8


def test_state_keeps_previous_values_for_players_missing_from_the_view() -> None:
    n = 2
    previous = state_from_global(
        GlobalView(time=0, ball=None, players=()),
        players_per_team=n, team_names=("a", "b"), last_actions=np.zeros((4, 2)),
        start_positions=np.zeros((4, 2)), score=np.zeros(2), step=0,
    )
    previous = previous.replace(positions=np.arange(8, dtype=np.float32).reshape(4, 2))
    view = parse_message('(see_global 3 ((b) 1 2 0 0) ((p "a" 1) 5 6 0 0 0 0))')
    assert isinstance(view, GlobalView)
    state = state_from_global(
        view, players_per_team=n, team_names=("a", "b"), last_actions=np.zeros((4, 2)),
        start_positions=np.zeros((4, 2)), score=np.zeros(2), step=1, previous=previous,
    )
    np.testing.assert_array_equal(state.positions[0], [5.0, -6.0])
    np.testing.assert_array_equal(state.positions[1:], previous.positions[1:])
    np.testing.assert_array_equal(state.ball_position, [1.0, -2.0])


# ----------------------------------------------------------------------- observations
def memory_for(
    n: int, names: tuple[str, str] = RECORDED_TEAMS, **overrides: float
) -> PerceptMemory:
    memory = PerceptMemory(robocup_params(n, **overrides), names)
    memory.reset(np.zeros((2, n, 2)), np.zeros((2, n)))
    return memory


def midgame_cycle() -> list[FakePlayerCycle]:
    players = []
    for who, message in recorded("see_midgame.txt"):
        assert isinstance(message, SeeMessage)
        if message.time == 452:
            players.append(FakePlayerCycle(0 if who[0] == "L" else 1, int(who[1:]), message))
    return players


def test_observation_has_the_simulator_shapes_and_dtypes() -> None:
    n = 11
    memory = memory_for(n)
    players = midgame_cycle()
    assert len(players) == 21
    memory.update(players)
    obs = memory.observation(100, np.full((2, n, 2), 0.5), np.zeros((2, n, 2)))
    assert obs.self_features.shape == (2, n, NUM_SELF_FEATURES)
    assert obs.self_features.dtype == np.float32
    assert obs.entities.shape == (2, n, 2 * n, NUM_ENTITY_FEATURES)
    assert obs.entities.dtype == np.float32
    assert obs.entity_mask.shape == (2, n, 2 * n) and obs.entity_mask.dtype == np.bool_
    for leaf in (obs.self_features, obs.entities):
        assert isinstance(leaf, np.ndarray) and np.all(np.isfinite(leaf))
    assert np.all(obs.entities[~obs.entity_mask] == 0.0)
    assert obs.entity_mask.any(axis=-1).sum() >= 15  # most players see something
    np.testing.assert_allclose(obs.self_features[..., S["time_left"]], 0.75)
    np.testing.assert_allclose(obs.self_features[..., S["last_move"]], 0.5)
    ball = obs.entities[..., -1, :5]
    np.testing.assert_array_equal(obs.self_features[..., S["ball_distance"] :], ball)
    np.testing.assert_array_equal(
        obs.self_features[..., S["ball_visible"]], obs.entity_mask[..., -1].astype(np.float32)
    )
    assert memory.pose_valid.sum() >= 20  # all that had a see localised (L1's see is cycle 451)
    assert np.abs(obs.self_features[..., S["x"] : S["y"] + 1]).max() < 1.3


def test_observation_matches_the_simulator_observe_on_the_same_situation() -> None:
    """Cycle 2 after a reset, recorded twice (players' see and the trainer's see_global, two runs
    that started identically). For every player whose localised pose matches the see_global one
    (the others turned differently in the two runs), the percept-based observation must equal
    elevens.env.observe.observe of the see_global State: the same frames, signs and
    normalisation, up to the server's quantisation. The recording used the normal view (120 deg),
    so the reference uses fov_half_angle = 60 deg."""
    n = 11
    view = next(m for _, m in recorded("see_global.txt") if m.time == 2)  # type: ignore[attr-defined]
    assert isinstance(view, GlobalView)
    state = state_from_global(
        view, players_per_team=n, team_names=RECORDED_TEAMS, last_actions=np.zeros((22, 2)),
        start_positions=np.zeros((22, 2)), score=np.zeros(2), step=0,
    )
    params = robocup_params(n, fov_half_angle=math.radians(60.0))
    reference = jax.jit(observe)(state, params)  # eager runs op by op: slower than compiling
    memory = PerceptMemory(params, RECORDED_TEAMS)
    memory.reset(np.zeros((2, n, 2)), np.zeros((2, n)))
    players = [
        FakePlayerCycle(0 if who[0] == "L" else 1, int(who[1:]), m)  # type: ignore[arg-type]
        for who, m in recorded("see.txt")
        if isinstance(m, SeeMessage) and m.time == 2
    ]
    memory.update(players)
    obs = memory.observation(0, np.zeros((2, n, 2)), np.zeros((2, n, 2)))
    extent = np.array([52.5, 34.0])
    compared = 0
    for player in players:
        t, i = player.side, player.unum - 1
        ref = np.asarray(reference.self_features[t, i])
        got = obs.self_features[t, i]
        position_error = np.abs((ref[1:3] - got[1:3]) * extent).max()
        heading_error = angle_error(math.atan2(ref[4], ref[3]), math.atan2(got[4], got[3]))
        if position_error > 0.5 or heading_error > math.radians(2.0):
            continue  # this player did something else in the other run
        compared += 1
        assert ref[S["ball_visible"]] == got[S["ball_visible"]]
        if got[S["ball_visible"]]:
            ball = slice(S["ball_distance"], S["ball_sin_bearing"] + 1)
            np.testing.assert_allclose(got[ball], ref[ball], atol=0.02)
        both = np.asarray(reference.entity_mask[t, i]) & obs.entity_mask[t, i]
        ref_e = np.asarray(reference.entities[t, i])[both]
        got_e = obs.entities[t, i][both]
        np.testing.assert_allclose(got_e[:, 0], ref_e[:, 0], rtol=0.06)  # log-quantised distance
        np.testing.assert_allclose(got_e[:, 1:3], ref_e[:, 1:3], atol=0.03)  # whole degrees
        np.testing.assert_array_equal(got_e[:, E["is_teammate"]], ref_e[:, E["is_teammate"]])
        np.testing.assert_array_equal(got_e[:, E["is_ball"]], ref_e[:, E["is_ball"]])
    assert compared >= 15


def test_memory_keeps_the_last_see_and_counts_staleness() -> None:
    n = 2
    memory = memory_for(n, ("a", "b"))
    first = see('(see 3 ((f c) 10 0) ((g r) 62.5 0) ((f r t) 72 -28) ((b) 5 10))')
    memory.update([FakePlayerCycle(0, 1, first, sense())])
    assert memory.stale.tolist() == [[0, 1], [1, 1]]
    after_see = memory.observation(1, np.zeros((2, n, 2)), np.zeros((2, n, 2)))
    assert memory.pose_valid[0, 0]
    x = after_see.self_features[0, 0, S["x"]] * 52.5
    assert x == pytest.approx(-10.0, abs=0.5)
    memory.update([FakePlayerCycle(0, 1, None, sense())])
    memory.update([FakePlayerCycle(0, 1, None, sense())])
    assert memory.stale.tolist() == [[2, 3], [3, 3]]
    later = memory.observation(3, np.zeros((2, n, 2)), np.zeros((2, n, 2)))
    np.testing.assert_array_equal(later.entities, after_see.entities)
    np.testing.assert_array_equal(
        later.self_features[..., S["x"] :], after_see.self_features[..., S["x"] :]
    )
    # A see without landmarks cannot be localised: the pose is kept and flagged.
    memory.update([FakePlayerCycle(0, 1, see("(see 6 ((b) 2 0))"), sense())])
    assert not memory.pose_valid[0, 0]
    assert memory.stale[0, 0] == 0
    kept = memory.observation(4, np.zeros((2, n, 2)), np.zeros((2, n, 2)))
    assert kept.self_features[0, 0, S["x"]] == after_see.self_features[0, 0, S["x"]]
    assert kept.self_features[0, 0, S["ball_distance"]] == pytest.approx(2 / FIELD_LENGTH)
    # A reset forgets everything and takes the spawn as a valid pose.
    memory.reset(np.full((2, n, 2), 3.0), np.zeros((2, n)))
    assert memory.pose_valid.all() and not memory.mask.any() and memory.stale.max() == 0
    assert memory.observation(0, np.zeros((2, n, 2)), np.zeros((2, n, 2))).self_features[
        0, 0, S["x"]
    ] == pytest.approx(3.0 / 52.5)


def test_dead_reckoning_moves_the_pose_and_the_ball_on_between_sees() -> None:
    from elevens.robocup.protocol import Kick, Turn

    n = 1
    memory = PerceptMemory(robocup_params(n), ("a", "b"), dead_reckoning=True)
    memory.reset(np.zeros((2, n, 2)), np.zeros((2, n)))
    # At (-10, 0) facing +x; the ball 5 m ahead, coming at us at 0.5 m a cycle.
    memory.update([FakePlayerCycle(0, 1, see(
        "(see 3 ((f c) 10 0) ((g r) 62.5 0) ((f r t) 72 -28) ((b) 5 0 -0.5 0))"), sense())])
    assert memory.position[0, 0] == pytest.approx([-10.0, 0.0], abs=0.3)
    start = memory.position[0, 0].copy()
    np.testing.assert_allclose(memory.ball[0, 0], start + [5.0, 0.0], atol=0.1)
    np.testing.assert_allclose(memory.ball_velocity[0, 0], [-0.5, 0.0], atol=0.01)
    heading = memory.heading[0, 0]
    assert heading == pytest.approx(0.0, abs=0.01)
    # A cycle without a see: sense_body's 0.4 m/cycle is a 1 m step (player_decay 0.4).
    memory.update([FakePlayerCycle(0, 1, None, sense(0.4))])
    np.testing.assert_allclose(memory.position[0, 0], start + [1.0, 0.0], atol=0.01)
    obs = memory.observation(1, np.zeros((2, n, 2)), np.zeros((2, n, 2)))
    distance = obs.self_features[0, 0, S["ball_distance"]] * FIELD_LENGTH
    assert distance == pytest.approx(5.0 - 0.5 - 1.0, abs=0.1)
    assert obs.self_features[0, 0, S["ball_vel_forward"]] == pytest.approx(-0.47, abs=0.01)
    assert obs.self_features[0, 0, S["ball_visible"]] == 1.0
    # A turn of 90 (clockwise) at 0.4 m/cycle turns 90 / (1 + 5 x 0.4) = 30 degrees.
    memory.update([FakePlayerCycle(0, 1, None, sense(0.0))], commands={(0, 0): Turn(90.0)})
    assert memory.heading[0, 0] == pytest.approx(heading - math.pi / 6, abs=1e-9)
    obs = memory.observation(2, np.zeros((2, n, 2)), np.zeros((2, n, 2)))
    bearing = math.atan2(obs.self_features[0, 0, S["ball_sin_bearing"]],
                         obs.self_features[0, 0, S["ball_cos_bearing"]])
    assert math.degrees(bearing) == pytest.approx(30.0, abs=2.0)
    assert memory.stale[0, 0] == 2  # still counted from the see: the routines read it
    # The ball is now within reach: a full kick straight ahead sends it off at the kick rate.
    memory.ball[0, 0] = memory.position[0, 0] + 0.8 * np.array(
        [math.cos(memory.heading[0, 0]), math.sin(memory.heading[0, 0])]
    )
    memory.ball_velocity[0, 0] = 0.0
    memory.update([FakePlayerCycle(0, 1, None, sense(0.0))], commands={(0, 0): Kick(100.0, 0.0)})
    gap = 0.8 - 0.3 - 0.085
    rate = 0.027 * (1.0 - 0.25 * gap / 0.7)
    assert np.linalg.norm(memory.ball_velocity[0, 0]) == pytest.approx(100 * rate * 0.94)
    # A player without dead reckoning holds its see (test above); a see resets the estimates.
    memory.update([FakePlayerCycle(0, 1, see("(see 9 ((f c) 10 0) ((g r) 62.5 0) "
                                             "((f r t) 72 -28))"), sense())])
    assert not memory.ball_known[0, 0] and not memory.mask[0, 0, -1]


def test_start_positions_are_normalised_in_the_team_frame() -> None:
    n = 1
    memory = memory_for(n, ("a", "b"))
    start = np.array([[[-20.0, 10.0]], [[-30.0, -17.0]]])
    obs = memory.observation(0, np.zeros((2, n, 2)), start)
    np.testing.assert_allclose(obs.self_features[:, 0, S["start_x"]], [-20 / 52.5, -30 / 52.5])
    np.testing.assert_allclose(obs.self_features[:, 0, S["start_y"]], [10 / 34, -17 / 34])
    assert obs.self_features[0, 0, S["time_left"]] == 1.0
