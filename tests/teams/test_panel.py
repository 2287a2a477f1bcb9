"""The opponent panel: interface, roles, and that each team plays sensible soccer."""

from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import elevens
from elevens.env import Observation
from elevens.eval.match import play_match
from elevens.teams import TeamPolicy
from elevens.teams.panel import (
    PANEL_TEAMS,
    BallMemory,
    DeepBlockTeam,
    LongBallTeam,
    ManMarkingTeam,
    PanelTeam,
    Roles,
)
from elevens.teams.registry import HANDCRAFTED, PANEL, resolve_team
from elevens.teams.scripted import Field
from tests.teams.test_scripted import hand_state, jitted_act, reflect, reset_fn, simulate

IDS = [team.name for team in PANEL_TEAMS]
GAMES = 64
"""Games per pair in the match tests (11 v 11, sides swapped): two matches of 32 (keys 0 and
1; against random only the first). The 500-game figures are in docs/results/panel.md."""
MATCH_GAMES = 32
OPPONENTS = ("random", "naive")


@dataclasses.dataclass(frozen=True)
class AnyOfPanel:
    """Plays the panel team whose index it gets as params: one compiled match serves every
    team of the panel (lax.switch on an index shared by all games stays a branch)."""

    teams: tuple[PanelTeam, ...] = PANEL_TEAMS
    name: str = "any-of-panel"

    def init_carry(self, players_per_team: int) -> BallMemory:
        return BallMemory.empty(players_per_team)

    def act(
        self, params: jax.Array, carry: BallMemory, obs: Observation, key: jax.Array
    ) -> tuple[BallMemory, jax.Array]:
        branches = [functools.partial(team.act, None) for team in self.teams]
        return jax.lax.switch(params, branches, carry, obs, key)


@dataclasses.dataclass(frozen=True)
class RandomOrNaive:
    """Plays random (index 0) or naive (1), as AnyOfPanel does the panel: both opponents in
    the same compiled match. Random keeps no memory; naive's is the carry."""

    random: TeamPolicy
    naive: TeamPolicy
    name: str = "random-or-naive"

    def init_carry(self, players_per_team: int) -> BallMemory:
        assert self.random.init_carry(players_per_team) == ()
        return self.naive.init_carry(players_per_team)

    def act(
        self, params: jax.Array, carry: BallMemory, obs: Observation, key: jax.Array
    ) -> tuple[BallMemory, jax.Array]:
        def random(carry: BallMemory, obs: Observation, key: jax.Array) -> Any:
            return carry, self.random.act(None, (), obs, key)[1]

        return jax.lax.switch(
            params, [random, functools.partial(self.naive.act, None)], carry, obs, key
        )


@functools.cache
def outcomes_against(opponent: str, games: int) -> np.ndarray:
    """f64[panel]: each panel team's mean outcome against ``opponent``, 11 v 11, in matches
    of MATCH_GAMES: one compile for every panel team and both opponents."""
    env, params = elevens.make("11v11")
    away = RandomOrNaive(resolve_team("random", params), resolve_team("naive", params))
    means = []
    for index in range(len(PANEL_TEAMS)):
        outcomes = [
            np.asarray(play_match(
                env, params, AnyOfPanel(), away, jax.random.key(match), MATCH_GAMES,
                home_params=jnp.int32(index), away_params=jnp.int32(OPPONENTS.index(opponent)),
            ).outcome)
            for match in range(games // MATCH_GAMES)
        ]
        means.append(float(np.mean(np.concatenate(outcomes))))
    return np.asarray(means)


# ----------------------------------------------------------------------------- registry


def test_the_panel_is_registered_by_name_and_is_distinct() -> None:
    assert len(PANEL) >= 6 and len(set(PANEL)) == len(PANEL)
    for name in PANEL:
        assert HANDCRAFTED[name].name == name
        assert isinstance(HANDCRAFTED[name], TeamPolicy)
    assert not {"random", "naive", "teamwork"} & set(PANEL)
    # Distinct styles, not one team under several names.
    assert len({type(HANDCRAFTED[name]) for name in PANEL}) == len(PANEL)


def test_a_panel_team_is_told_its_field() -> None:
    _, params = elevens.make("2v2", field_length=60.0, field_width=40.0, goal_width=20.0)
    team = resolve_team("deep-block", params)
    assert isinstance(team, DeepBlockTeam)
    assert team.field == Field(half_length=30.0, half_width=20.0, goal_half_width=10.0)
    assert resolve_team("deep-block", elevens.make("2v2")[1]) == HANDCRAFTED["deep-block"]


# ---------------------------------------------------------------------------- interface


@pytest.mark.parametrize("team", PANEL_TEAMS, ids=IDS)
def test_actions_are_valid_at_every_size_and_on_garbage(team: PanelTeam) -> None:
    act = jitted_act(team)
    for n in (1, 11):  # a lone player (no keeper) and the full team
        _, params, reset = reset_fn(n)
        _, obs = reset(jax.random.key(n), params)
        for side in (0, 1):
            _, actions = act(None, team.init_carry(n), obs.team(side), jax.random.key(3))
            assert actions.shape == (n, 2)
            assert bool(jnp.all(jnp.isfinite(actions) & (jnp.abs(actions) <= 1.0)))
    noise_key, mask_key = jax.random.split(jax.random.key(4))
    garbage = Observation(
        self_features=3 * jax.random.normal(noise_key, obs.self_features[0].shape),
        entities=3 * jax.random.normal(noise_key, obs.entities[0].shape),
        entity_mask=jax.random.bernoulli(mask_key, 0.5, obs.entity_mask[0].shape),
    )
    _, actions = act(None, team.init_carry(11), garbage, jax.random.key(5))
    assert bool(jnp.all(jnp.isfinite(actions) & (jnp.abs(actions) <= 1.0)))


@pytest.mark.parametrize("team", PANEL_TEAMS, ids=IDS)
def test_jit_equals_eager_on_an_exact_state(team: PanelTeam) -> None:
    # A mid-game 11 v 11 state: the ball in the side's own half, players off their slots.
    env, params, state = hand_state(
        11, {0: (-47.0, 3.0), 3: (-30.0, 10.0), 6: (-15.0, -4.0), 14: (-20.0, 12.0)},
        {3: 0.3, 6: 2.0, 14: math.pi}, (-25.0, 8.0),
    )
    obs = jax.jit(env.observe)(state, params).team(0)
    carry = team.init_carry(11)
    _, eager = team.act(None, carry, obs, jax.random.key(7))
    _, jitted = jitted_act(team)(None, carry, obs, jax.random.key(7))
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), atol=1e-5)
    assert hash(team) == hash(dataclasses.replace(team))  # static to the compiled match


@pytest.mark.parametrize("team", PANEL_TEAMS, ids=IDS)
def test_teams_play_the_same_on_either_side(team: PanelTeam) -> None:
    env, params, reset = reset_fn(11)
    state, _ = reset(jax.random.key(10), params)
    act = jitted_act(team)
    observe = jax.jit(env.observe)

    def actions(state: Any, side: int) -> np.ndarray:
        obs = observe(state, params).team(side)
        return np.asarray(act(None, team.init_carry(11), obs, jax.random.key(1))[1])

    np.testing.assert_allclose(actions(reflect(state, 11), 1), actions(state, 0), atol=1e-4)


# --------------------------------------------------------------------------------- roles


def test_roles_split_the_formation() -> None:
    roles = Roles.of(11)
    assert roles.keeper.sum() == 1 and roles.defender.sum() == 4
    assert roles.midfield.sum() == 3 and roles.forward.sum() == 3
    assert Roles.of(1).keeper.sum() == 0  # a lone player is an outfield player


def test_man_marking_assigns_each_outfield_player_its_own_mark() -> None:
    roles = Roles.of(11)
    marks = ManMarkingTeam().marks(roles)
    outfield = marks[~roles.keeper]
    assert len(set(outfield.tolist())) == 10
    assert 0 not in outfield  # nobody marks the opponents' keeper
    # The back line marks the forwards (slots 8 to 10), who start nearest to it.
    assert set(marks[roles.defender].tolist()) >= {8, 9, 10}


def test_man_marker_goes_goal_side_of_its_mark() -> None:
    team = ManMarkingTeam()
    marks = team.marks(Roles.of(11))
    k = 2  # a back-line player; its mark stands in this team's half, the ball far away
    mark_row = 11 + int(marks[k])
    # Player 9 stands facing the mark and the ball, so the team sees both; players 8 and 10
    # stand nearer the ball, so they are the ones that would go for it.
    env, params, state = hand_state(
        11, {k: (-30.0, -20.0), 9: (-40.0, 0.0), 8: (20.0, -20.0), 10: (25.0, -10.0),
             mark_row: (-20.0, 5.0)},
        {k: 0.0, 9: 0.0, 8: 0.0, 10: 0.0}, (30.0, -20.0),
    )
    active = np.zeros(11, bool)
    active[k] = True
    final = simulate(env, params, state, team, steps=40, active=active)
    mark = np.array([-20.0, 5.0])
    to_goal = np.array([-50.0, 0.0]) - mark
    guard = mark + team.goal_side * to_goal / np.linalg.norm(to_goal)
    assert np.linalg.norm(np.asarray(final.positions[k]) - guard) < 2.0


def test_deep_block_holds_its_lines_while_the_ball_is_far() -> None:
    team = DeepBlockTeam()
    env, params, reset = reset_fn(11)
    state, _ = reset(jax.random.key(3), params)
    state = dataclasses.replace(state, ball_position=jnp.array([35.0, 0.0]))
    outlet, block, _ = team.lines(Roles.of(11))
    assert outlet.sum() == team.outlets and block.sum() == 10 - team.outlets
    # The block alone moves: the outlet would go for the ball.
    final = simulate(env, params, state, team, steps=60, active=block)
    x = np.asarray(final.positions[:11, 0])
    assert np.all(x[block] < team.front_line + 4.0)
    assert np.all(np.abs(np.asarray(final.positions[:11, 1])[block]) < team.width + 4.0)


def test_long_ball_forwards_wait_high() -> None:
    team = LongBallTeam()
    env, params, reset = reset_fn(11)
    state, _ = reset(jax.random.key(4), params)
    state = dataclasses.replace(state, ball_position=jnp.array([-30.0, 0.0]))
    roles = Roles.of(11)
    final = simulate(env, params, state, team, steps=80, active=roles.forward)
    assert np.all(np.asarray(final.positions[:11, 0])[roles.forward] > team.forward_line - 4)


# ---------------------------------------------------------------------- sensible soccer


def test_every_panel_team_beats_random_clearly() -> None:
    means = outcomes_against("random", GAMES // 2)  # far from the bar: fewer games
    assert np.all(means >= 0.85), dict(zip(PANEL, means.round(3), strict=True))


def test_naive_scores_at_most_0_6_against_every_panel_team() -> None:
    means = outcomes_against("naive", GAMES)
    assert np.all(1.0 - means <= 0.6), dict(zip(PANEL, means.round(3), strict=True))


def test_the_switch_plays_each_team_as_itself() -> None:
    # The panel measured through AnyOfPanel is the panel: each index acts as its team. 11 a
    # side, as the interface tests above, whose compiled acts the direct calls reuse.
    _, params, reset = reset_fn(11)
    _, obs = reset(jax.random.key(12), params)
    switch = jax.jit(AnyOfPanel().act)
    carry = BallMemory.empty(11)
    for index, team in enumerate(PANEL_TEAMS):
        _, through = switch(jnp.int32(index), carry, obs.team(1), jax.random.key(2))
        _, direct = jitted_act(team)(None, carry, obs.team(1), jax.random.key(2))
        np.testing.assert_allclose(np.asarray(through), np.asarray(direct), atol=1e-5)
    # And the match tests' opponents through RandomOrNaive are random and naive.
    away = RandomOrNaive(resolve_team("random", params), resolve_team("naive", params))
    switch = jax.jit(away.act)
    for index, team in enumerate((away.random, away.naive)):
        _, through = switch(jnp.int32(index), carry, obs.team(1), jax.random.key(2))
        _, direct = jitted_act(team)(None, team.init_carry(11), obs.team(1), jax.random.key(2))
        np.testing.assert_allclose(np.asarray(through), np.asarray(direct), atol=1e-5)
