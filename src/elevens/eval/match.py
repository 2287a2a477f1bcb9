"""Matches: G games between any two TeamPolicies, as one compiled program.

``play_match`` runs every game of a match at once: ``lax.map`` over chunks of games, and within a
chunk ``elevens.play.unroll`` (the training rollout's unroll too), batched over the chunk's games.
The home team plays side 0 in the first half of the games and side 1 in the second half
(``swap_sides``), so neither team profits from a side. Each game carries its home side, and the
observation slices and the action order are chosen with ``jnp.where``, so one compile serves all.
Each game draws its keys from its own key, so its result does not depend on the chunk size.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from elevens.env.params import EnvParams
from elevens.env.randomize import game_axis, setting_count
from elevens.env.soccer import Soccer
from elevens.play import PolicyActor, StepView, home_sides, per_game_step_keys, unroll
from elevens.teams.base import TeamPolicy
from elevens.train.opponents import game_outcome as outcome_from_score

DEFAULT_CHUNK_SIZE = 128
"""Games vmapped together. Small batches keep the observations in cache (docs/architecture.md;
the chunk sizes measured are in docs/results/throughput.md)."""


@struct.dataclass
class MatchRecord:
    """What happened at every step of every game, world frame. Entry ``t`` holds the state the
    players saw at step ``t`` and the actions they took there."""

    positions: jax.Array  # f32[G, T, 2n, 2] player centres, team 0 first
    headings: jax.Array  # f32[G, T, 2n] radians
    ball_position: jax.Array  # f32[G, T, 2]
    ball_velocity: jax.Array  # f32[G, T, 2]
    score: jax.Array  # i32[G, T, 2] goals of side 0 and side 1 so far
    actions: jax.Array  # f32[G, T, 2, n, 2] (side, player, (move, rot)) as applied: clipped, NaN 0
    kicks: jax.Array | None = None  # bool[G, T, 2n] who leg-kicked the ball in step t
    pushes: jax.Array | None = None  # bool[G, T, 2n] who body-pushed it (None: not recorded,
    #                                  e.g. a replay)


@struct.dataclass
class MatchResult:
    """A match from the HOME team's point of view."""

    goals_for: jax.Array  # i32[G] goals of the home team
    goals_against: jax.Array  # i32[G] goals of the away team
    outcome: jax.Array  # f32[G] 1 home win, 0.5 draw, 0 home loss
    home_side: jax.Array  # i32[G] the side (0 or 1) the home team played
    record: MatchRecord | None = None  # per-step history when played with record=True


def _match_record(view: StepView) -> MatchRecord:
    """What a recorded match keeps of each step."""
    state = view.state
    return MatchRecord(
        positions=state.positions,
        headings=state.headings,
        ball_position=state.ball_position,
        ball_velocity=state.ball_velocity,
        score=state.score,
        actions=view.actions,
        kicks=view.info.kicks,
        pushes=view.info.pushes,
    )


def _play_chunk(
    env: Soccer,
    home: TeamPolicy,
    away: TeamPolicy,
    num_steps: int,
    record: bool,
    params: EnvParams | None,
    home_params: Any,
    away_params: Any,
    games: tuple[jax.Array, jax.Array, EnvParams | None],
    noisy: bool = False,
) -> tuple[jax.Array, MatchRecord | None]:
    """A chunk of games (keys key[C], home sides i32[C], the games' own EnvParams [C] or None
    for ``params``) -> (final scores i32[C, 2] by side, per-step records [C, T, ...] or None).
    Game ``g`` draws everything from its own key."""
    keys, sides, own = games
    params = own if own is not None else params
    assert params is not None, "a chunk needs the shared params or its games' own"
    axis = game_axis(params)
    reset_keys, play_keys = jnp.moveaxis(jax.vmap(jax.random.split)(keys), 1, 0)
    states, _ = jax.vmap(env.reset, in_axes=(0, axis))(reset_keys, params)
    fields = params if axis is not None else None
    final, history = unroll(
        env, params, PolicyActor(home, home_params, fields), PolicyActor(away, away_params, fields),
        states, sides, per_game_step_keys(play_keys, num_steps),
        _match_record if record else lambda view: None, noisy=noisy,
    )
    if history is not None:
        history = jax.tree.map(lambda leaf: jnp.moveaxis(leaf, 0, 1), history)  # [C, T, ...]
    return final.state.score, history


@functools.partial(
    jax.jit,
    static_argnames=("env", "home", "away", "num_steps", "chunk_size", "record", "noisy"),
)
def _play_games(
    params: EnvParams,
    home_params: Any,
    away_params: Any,
    keys: jax.Array,
    sides: jax.Array,
    *,
    env: Soccer,
    home: TeamPolicy,
    away: TeamPolicy,
    num_steps: int,
    chunk_size: int,
    record: bool,
    noisy: bool = False,
) -> tuple[jax.Array, MatchRecord | None]:
    """keys key[G'], sides i32[G'] (G' a multiple of chunk_size), params one game for all or
    one per game ([G']) -> (scores i32[G', 2], record)."""
    per_game = game_axis(params) is not None
    shared = None if per_game else params
    chunk = functools.partial(
        _play_chunk, env, home, away, num_steps, record, shared, home_params, away_params,
        noisy=noisy,
    )
    chunks = keys.shape[0] // chunk_size
    by_chunk = lambda leaf: leaf.reshape(chunks, chunk_size, *leaf.shape[1:])  # noqa: E731
    own = jax.tree.map(by_chunk, params) if per_game else None
    scores, history = jax.lax.map(chunk, (by_chunk(keys), by_chunk(sides), own))
    unchunk = lambda leaf: leaf.reshape(chunks * chunk_size, *leaf.shape[2:])  # noqa: E731
    return unchunk(scores), jax.tree.map(unchunk, history)


def play_match(
    env: Soccer,
    params: EnvParams,
    home: TeamPolicy,
    away: TeamPolicy,
    key: jax.Array,
    num_games: int,
    home_params: Any = None,
    away_params: Any = None,
    swap_sides: bool = True,
    record: bool = False,
    chunk_size: int = DEFAULT_CHUNK_SIZE,
) -> MatchResult:
    """Play ``num_games`` full episodes of ``home`` against ``away``.

    home/away: TeamPolicies (hashable, e.g. frozen dataclasses: they are static to the compile),
    acting with home_params/away_params. key: a ``jax.random.key``; game ``g`` uses
    ``split(key, G)[g]``, so a key gives bit-identical results for the same chunk size (another
    chunk size plays the same games, up to float rounding of the wider or narrower batch).
    With ``swap_sides`` the home team plays side 0 in the first ceil(G/2) games and side 1 in
    the rest; otherwise always side 0. Episodes last ``params.episode_length`` steps (static: a
    new length recompiles). Games run ``chunk_size`` at a time (vmapped) to bound memory.
    Compiles once per (env, policies, G, episode length, record, chunk size).
    ``params`` is one game for every game, or one per game (every leaf ``[G]``: drawn games,
    ``elevens.env.randomize.tile_games``), where handcrafted teams play on each game's field.
    Players see with ``params.observation_noise`` where it is above 0.
    Returns a MatchResult with ``[G]`` fields (``[G, T, ...]`` in ``record`` when record=True).
    """
    if num_games < 1:
        raise ValueError(f"num_games={num_games!r} is invalid: it must be >= 1")
    if chunk_size < 1:
        raise ValueError(f"chunk_size={chunk_size!r} is invalid: it must be >= 1")
    per_game = game_axis(params) is not None
    if per_game and setting_count(params) != num_games:
        raise ValueError(
            f"params hold {setting_count(params)} games and num_games={num_games}: per-game "
            "params need one entry per game (elevens.env.randomize.tile_games)"
        )
    lengths = np.unique(np.asarray(params.episode_length))
    if lengths.size != 1:
        raise ValueError(f"episode_length={lengths.tolist()}: a match's games last one length")
    num_steps = int(lengths[0])
    noisy = bool(np.any(np.asarray(params.observation_noise) > 0))
    # Equal chunks with the least padding: e.g. 500 games at chunk_size 128 run as 4 x 125.
    num_chunks = math.ceil(num_games / chunk_size)
    chunk = math.ceil(num_games / num_chunks)
    padded = num_chunks * chunk
    sides = home_sides(num_games, swap_sides)
    if not jax.dtypes.issubdtype(key.dtype, jax.dtypes.prng_key):
        key = jax.random.wrap_key_data(key)  # a legacy uint32[2] key: the same stream
    game_keys = jax.random.split(key, num_games)
    if padded > num_games:
        game_keys = jnp.concatenate([game_keys, game_keys[: padded - num_games]])
        sides = np.concatenate([sides, sides[: padded - num_games]])
        if per_game:
            params = jax.tree.map(
                lambda leaf: jnp.concatenate([leaf, leaf[: padded - num_games]]), params
            )
    scores, history = _play_games(
        params,
        home_params,
        away_params,
        game_keys,
        jnp.asarray(sides),
        env=env,
        home=home,
        away=away,
        num_steps=num_steps,
        chunk_size=chunk,
        record=record,
        noisy=noisy,
    )
    scores = scores[:num_games]
    if history is not None:
        history = jax.tree.map(lambda x: x[:num_games], history)
    home_side = jnp.asarray(sides[:num_games])
    goals_for = jnp.where(home_side == 0, scores[:, 0], scores[:, 1])
    goals_against = jnp.where(home_side == 0, scores[:, 1], scores[:, 0])
    return MatchResult(
        goals_for=goals_for,
        goals_against=goals_against,
        outcome=outcome_from_score(goals_for, goals_against),
        home_side=home_side,
        record=history,
    )


def summary(result: MatchResult) -> dict[str, float]:
    """Host-side numbers of a match, home team's view: mean and std of the outcome, win, draw
    and loss fractions, mean goals for and against, and the number of games."""
    outcome = np.asarray(result.outcome, np.float64)
    return {
        "games": float(outcome.size),
        "mean": float(outcome.mean()),
        "std": float(outcome.std()),
        "win": float(np.mean(outcome == 1.0)),
        "draw": float(np.mean(outcome == 0.5)),
        "loss": float(np.mean(outcome == 0.0)),
        "goals_for": float(np.mean(np.asarray(result.goals_for))),
        "goals_against": float(np.mean(np.asarray(result.goals_against))),
    }
