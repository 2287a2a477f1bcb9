"""Who the learning team plays: plain self-play, a Polyak-averaged opponent, or a league.

All functions are pure and jittable; state lives in flax struct dataclasses, and params are plain
pytrees (a league stacks its snapshots on a leading axis). Thesis references (seeds/000):
Algorithm 4 and section 5.2.6 (Polyak averaging with opponent freezing), section 5.2.7 (league
training, eq. 5.2), table 6.1 (alpha_s = 0.01, epsilon_s = 0.55).

Game outcomes are scored as in Algorithm 4's ``average_score``: win 1.0, draw 0.5, loss 0.0.
The LEAGUE stores every outcome from the OPPONENT's point of view (1 = the snapshot beat the
learner), because the thesis' w_i is "the win rate of the opponent over the current policy"
(section 5.2.7). The POLYAK step takes the LEARNER's mean score (Algorithm 4 line 25).
``game_outcome`` gives either view: ``game_outcome(opponent_goals, learner_goals)`` is the
opponent's.
"""

from __future__ import annotations

import dataclasses
from typing import Any, NamedTuple, Protocol

import jax
import jax.numpy as jnp
import optax
from flax import struct
from jax.typing import ArrayLike

Params = Any

POLYAK_TAU = 0.01
"""alpha_s, the Polyak averaging update rate (table 6.1)."""
POLYAK_THRESHOLD = 0.55
"""epsilon_s, the opponent update threshold (table 6.1, Algorithm 4 line 25)."""
LEAGUE_WINDOW = 1000
"""Games per snapshot averaged into its win rate (section 5.2.7: "the past 1000 games")."""
LEAGUE_MIN_GAMES = 100
"""Below this many games a snapshot's win rate is held at 0.5 (section 5.2.7)."""
LEAGUE_EVERY = 10
"""A snapshot of the learner joins the league every this many iterations (section 5.2.7)."""
LEAGUE_PSI = 2.0
"""psi of eq. 5.2: p_i proportional to w_i ** psi (section 5.2.7)."""
OPPONENT_KINDS: tuple[str, ...] = ("polyak", "self", "league")
"""The training opponents ``make_opponent`` builds (``opponent.kind``)."""


def game_outcome(goals_for: ArrayLike, goals_against: ArrayLike) -> jax.Array:
    """1.0 for a win, 0.5 for a draw, 0.0 for a loss, from the side whose goals come first.

    Shapes broadcast; returns ``f32[...]``.
    """
    diff = jnp.asarray(goals_for) - jnp.asarray(goals_against)
    return 0.5 * (jnp.sign(diff).astype(jnp.float32) + 1.0)


# --------------------------------------------------------------------------------------------
# Plain self-play (the ablation's opponent)
# --------------------------------------------------------------------------------------------


def self_play_opponent(learner_params: Params) -> Params:
    """Plain self-play: the opponent is the latest learner (gradients stopped)."""
    return jax.lax.stop_gradient(learner_params)


# --------------------------------------------------------------------------------------------
# Polyak averaging with opponent freezing (section 5.2.6)
# --------------------------------------------------------------------------------------------


def polyak_update(
    opponent_params: Params, learner_params: Params, tau: ArrayLike = POLYAK_TAU
) -> Params:
    """theta_2 <- tau * theta_1 + (1 - tau) * theta_2 (eq. 5.1), leaf by leaf."""
    return optax.incremental_update(
        new_tensors=learner_params, old_tensors=opponent_params, step_size=tau
    )


class PolyakState(struct.PyTreeNode):
    """The slow-moving average opponent of section 5.2.6."""

    params: Params
    """theta_2, the opponent's params (same tree as the learner's)."""
    frozen: jax.Array
    """``bool[]``: True if the last ``polyak_step`` held the opponent still."""
    num_updates: jax.Array
    """``i32[]``: how many ``polyak_step`` calls moved the opponent."""
    num_steps: jax.Array
    """``i32[]``: how many ``polyak_step`` calls were made (updates + freezes)."""


def polyak_init(learner_params: Params) -> PolyakState:
    """theta_2 <- theta_1 (Algorithm 4 line 1); not frozen, no steps yet."""
    return PolyakState(
        params=jax.tree_util.tree_map(jnp.asarray, learner_params),
        frozen=jnp.asarray(False),
        num_updates=jnp.asarray(0, jnp.int32),
        num_steps=jnp.asarray(0, jnp.int32),
    )


def polyak_step(
    state: PolyakState,
    learner_params: Params,
    learner_mean_score: ArrayLike,
    tau: ArrayLike = POLYAK_TAU,
    threshold: ArrayLike = POLYAK_THRESHOLD,
) -> PolyakState:
    """One opponent step after a learner step (Algorithm 4 lines 25-27).

    The opponent moves towards the learner (``polyak_update``) only if the learner's mean score
    against it is ABOVE ``threshold`` (0.55); otherwise it is frozen for this step, so that "the
    slow-moving average strategy waits for the learner if the learner is struggling to beat it
    consistently" (section 5.2.6).

    ``learner_mean_score`` is ``f32[]``, Algorithm 4's ``average_score(r_1)``: the mean outcome
    (win 1, draw 0.5, loss 0) of the learning team over the games of the batch just trained on.

    At exactly 0.55 the thesis disagrees with itself: Algorithm 4 updates only if the score is
    ``> epsilon_s``, while the prose of 5.2.6 freezes "if ... less than 0.55". We follow the
    algorithm: a score of exactly 0.55 freezes.
    """
    update = jnp.asarray(learner_mean_score) > threshold
    averaged = polyak_update(state.params, learner_params, tau)
    params = jax.tree_util.tree_map(
        lambda new, old: jnp.where(update, new, old), averaged, state.params
    )
    return PolyakState(
        params=params,
        frozen=jnp.logical_not(update),
        num_updates=state.num_updates + update.astype(jnp.int32),
        num_steps=state.num_steps + 1,
    )


def self_play_step(state: PolyakState, learner_params: Params) -> PolyakState:
    """Plain self-play's step: the opponent becomes the latest learner (counted as an update
    every step, never frozen)."""
    return state.replace(
        params=self_play_opponent(learner_params),
        num_updates=state.num_updates + 1,
        num_steps=state.num_steps + 1,
    )


def single_opponent_step(
    state: PolyakState,
    kind: str,
    learner_params: Params,
    learner_mean_score: ArrayLike,
    tau: ArrayLike = POLYAK_TAU,
    threshold: ArrayLike = POLYAK_THRESHOLD,
) -> PolyakState:
    """The opponent after a learner step, for the kinds with one opponent: "polyak"
    (``polyak_step``) or "self" (the latest learner; counted as an update every step)."""
    if kind == "polyak":
        return polyak_step(state, learner_params, learner_mean_score, tau, threshold)
    if kind == "self":
        return self_play_step(state, learner_params)
    raise ValueError(f"kind={kind!r} is invalid: a single opponent is 'polyak' or 'self'")


# --------------------------------------------------------------------------------------------
# Ring buffers (league results, and the shaping schedule's recent games)
# --------------------------------------------------------------------------------------------


class RingRecord(NamedTuple):
    """Output of ``ring_record``."""

    buffers: jax.Array
    """``f32[R, K]`` the rings with the new values written."""
    write_index: jax.Array
    """``i32[R]`` the next slot to write in each ring."""
    added: jax.Array
    """``i32[R]`` how many valid values each ring received (including ones at once overwritten)."""


def ring_record(
    buffers: ArrayLike,
    write_index: ArrayLike,
    rows: ArrayLike,
    values: ArrayLike,
    valid: ArrayLike | None = None,
) -> RingRecord:
    """Append a batch of values to R ring buffers of length K, in batch order, by one scatter.

    Args:
        buffers: ``f32[R, K]``.
        write_index: ``i32[R]``, the next slot of each ring.
        rows: ``i32[G]``, which ring each value goes to (rows outside ``[0, R)`` are ignored).
        values: ``f32[G]``.
        valid: optional ``bool[G]``; False entries are ignored.

    Values for the same ring land in consecutive slots in batch order, as if appended one at a
    time; if one ring gets more than K values in a batch, only its last K are kept.
    """
    buffers = jnp.asarray(buffers, jnp.float32)
    num_rings, length = buffers.shape
    write_index = jnp.asarray(write_index, jnp.int32)
    rows = jnp.asarray(rows, jnp.int32)
    values = jnp.asarray(values, jnp.float32)
    ok = (rows >= 0) & (rows < num_rings)
    if valid is not None:
        ok = ok & jnp.asarray(valid, bool)
    one_hot = (rows[:, None] == jnp.arange(num_rings)[None, :]) & ok[:, None]  # [G, R]
    one_hot = one_hot.astype(jnp.int32)
    added = jnp.sum(one_hot, axis=0)  # [R]
    # Rank of each value among the earlier values of the same ring in this batch.
    earlier = jnp.cumsum(one_hot, axis=0) - one_hot
    safe_rows = jnp.clip(rows, 0, num_rings - 1)
    rank = jnp.take_along_axis(earlier, safe_rows[:, None], axis=1)[:, 0]
    # Only the last K values of a ring survive; dropping the rest keeps the scatter free of
    # duplicate targets, whose write order XLA does not define.
    keep = ok & (rank >= added[safe_rows] - length)
    slot = (write_index[safe_rows] + rank) % length
    target_rows = jnp.where(keep, safe_rows, num_rings)  # out of bounds: dropped
    buffers = buffers.at[target_rows, slot].set(values, mode="drop")
    return RingRecord(
        buffers=buffers, write_index=(write_index + added) % length, added=added
    )


# --------------------------------------------------------------------------------------------
# League (section 5.2.7)
# --------------------------------------------------------------------------------------------


class LeagueState(struct.PyTreeNode):
    """A fixed-capacity league of past learner snapshots. C = capacity, W = results window."""

    params: Params
    """Snapshots stacked on a leading axis: every leaf ``[C, ...]``. Slots >= size are unused."""
    size: jax.Array
    """``i32[]`` live snapshots, in slots ``[0, size)``."""
    results: jax.Array
    """``f32[C, W]`` ring of each snapshot's last W outcomes, OPPONENT's view (1 = it won)."""
    result_count: jax.Array
    """``i32[C]`` games recorded for each snapshot since it entered its slot (not capped at W)."""
    write_index: jax.Array
    """``i32[C]`` next slot of each results ring."""
    serial: jax.Array
    """``i32[C]`` order of entry (0 for the first snapshot ever added); -1 for an empty slot."""
    iteration: jax.Array
    """``i32[C]`` the learner iteration each snapshot was taken at; -1 for an empty slot."""
    num_added: jax.Array
    """``i32[]`` snapshots ever added (evicted ones included)."""

    @property
    def capacity(self) -> int:
        return int(self.results.shape[0])

    @property
    def window(self) -> int:
        return int(self.results.shape[1])


def league_init(
    learner_params: Params,
    capacity: int,
    window: int = LEAGUE_WINDOW,
    iteration: ArrayLike = 0,
) -> LeagueState:
    """A league of ``capacity`` slots holding one snapshot, ``learner_params`` (in slot 0).

    Starting non-empty means sampling is always well defined.
    """
    if capacity < 1 or window < 1:
        raise ValueError(
            f"capacity={capacity!r}, window={window!r} are invalid: both must be >= 1"
        )

    def stack(leaf: ArrayLike) -> jax.Array:
        leaf = jnp.asarray(leaf)
        return jnp.zeros((capacity, *leaf.shape), leaf.dtype).at[0].set(leaf)

    first = jnp.arange(capacity) == 0
    return LeagueState(
        params=jax.tree_util.tree_map(stack, learner_params),
        size=jnp.asarray(1, jnp.int32),
        results=jnp.zeros((capacity, window), jnp.float32),
        result_count=jnp.zeros((capacity,), jnp.int32),
        write_index=jnp.zeros((capacity,), jnp.int32),
        serial=jnp.where(first, 0, -1).astype(jnp.int32),
        iteration=jnp.where(first, jnp.asarray(iteration, jnp.int32), -1).astype(jnp.int32),
        num_added=jnp.asarray(1, jnp.int32),
    )


def league_live(state: LeagueState) -> jax.Array:
    """``bool[C]``: which slots hold a snapshot."""
    return jnp.arange(state.capacity) < state.size


def league_win_rates(state: LeagueState, min_games: ArrayLike = LEAGUE_MIN_GAMES) -> jax.Array:
    """w_i, each snapshot's win rate against the learner, ``f32[C]`` (section 5.2.7).

    The mean of its last ``min(result_count, W)`` outcomes, a draw counting 0.5 (the score of
    Algorithm 4's ``average_score``). Held at 0.5 until it has played ``min_games`` (100) games:
    "This prevents a new opponent from never being sampled again if it loses an initial game".
    Empty slots read 0.
    """
    played = jnp.minimum(state.result_count, state.window)
    # Unwritten ring slots are 0 (zeroed on entry), so the row sum is the sum of the played games.
    mean = jnp.sum(state.results, axis=1) / jnp.maximum(played, 1).astype(jnp.float32)
    rates = jnp.where(state.result_count >= min_games, mean, 0.5)
    return jnp.where(league_live(state), rates, 0.0)


def league_probabilities(
    state: LeagueState,
    psi: ArrayLike = LEAGUE_PSI,
    min_games: ArrayLike = LEAGUE_MIN_GAMES,
) -> jax.Array:
    """p_i = w_i^psi / sum_j w_j^psi over the live snapshots (eq. 5.2), ``f32[C]``.

    Empty slots get 0. If every live w_i is 0 (the learner beats all of them), sampling falls
    back to uniform over the live snapshots rather than dividing by 0.
    """
    live = league_live(state)
    weights = jnp.where(live, jnp.power(league_win_rates(state, min_games), psi), 0.0)
    total = jnp.sum(weights)
    uniform = live.astype(jnp.float32) / jnp.maximum(state.size, 1).astype(jnp.float32)
    return jnp.where(total > 0, weights / jnp.where(total > 0, total, 1.0), uniform)


def league_sample(
    state: LeagueState,
    key: jax.Array,
    num: int,
    psi: ArrayLike = LEAGUE_PSI,
    min_games: ArrayLike = LEAGUE_MIN_GAMES,
) -> jax.Array:
    """``i32[num]`` snapshot indices drawn independently with ``league_probabilities``."""
    logits = jnp.log(league_probabilities(state, psi, min_games))  # -inf for empty slots
    return jax.random.categorical(key, logits, shape=(num,)).astype(jnp.int32)


def league_params(state: LeagueState, index: ArrayLike) -> Params:
    """Gather snapshot params: a scalar ``index`` gives one snapshot's tree; ``i32[G]`` gives a
    tree with leading axis ``[G]`` (one opponent per game, for a vmapped rollout)."""
    index = jnp.asarray(index, jnp.int32)
    return jax.tree_util.tree_map(lambda leaf: jnp.take(leaf, index, axis=0), state.params)


def league_record(
    state: LeagueState,
    indices: ArrayLike,
    opponent_outcomes: ArrayLike,
    mask: ArrayLike | None = None,
) -> LeagueState:
    """Record a batch of finished games in the snapshots' result rings.

    Args:
        indices: ``i32[G]``, the snapshot each game was played against.
        opponent_outcomes: ``f32[G]``, each game's outcome from the OPPONENT's view (1 it won,
            0.5 draw, 0 it lost); ``1 - learner_outcome`` if you hold the learner's.
        mask: optional ``bool[G]``: False for games that were not league games (e.g. games
            against the latest learner in a mixed batch), which are ignored.
    """
    ring = ring_record(state.results, state.write_index, indices, opponent_outcomes, mask)
    return state.replace(
        results=ring.buffers,
        write_index=ring.write_index,
        result_count=state.result_count + ring.added,
    )


def league_eviction_slot(
    state: LeagueState, min_games: ArrayLike = LEAGUE_MIN_GAMES
) -> jax.Array:
    """``i32[]`` the slot a new snapshot replaces when the league is full.

    Rule: the WEAKEST evaluated snapshot, that is the one with the lowest win rate against the
    learner among those with at least ``min_games`` games (ties: the oldest of them). If no
    snapshot has been evaluated yet, the oldest.

    Why: with p_i proportional to w_i^2 (eq. 5.2) the weakest snapshot is the one the learner
    almost never meets, so dropping it changes the training distribution least, while old but
    still strong strategies, the ones a league exists to keep (section 3.4.5: "strategy
    collapse"), stay. Snapshots still inside their first ``min_games`` games sit at the
    placeholder 0.5 and are not candidates, so a new snapshot is never evicted before it was
    measured.
    """
    live = league_live(state)
    rates = league_win_rates(state, min_games)
    evaluated = live & (state.result_count >= min_games)
    never = jnp.iinfo(jnp.int32).max
    lowest = jnp.min(jnp.where(evaluated, rates, jnp.inf))
    weakest = jnp.argmin(jnp.where(evaluated & (rates == lowest), state.serial, never))
    oldest = jnp.argmin(jnp.where(live, state.serial, never))
    return jnp.where(jnp.any(evaluated), weakest, oldest).astype(jnp.int32)


def league_add(
    state: LeagueState,
    learner_params: Params,
    iteration: ArrayLike = -1,
    min_games: ArrayLike = LEAGUE_MIN_GAMES,
) -> LeagueState:
    """Add a snapshot of the learner: into the next free slot, or, when the league is full, over
    the slot chosen by ``league_eviction_slot``. The slot's result ring starts empty."""
    slot = jnp.where(
        state.size < state.capacity, state.size, league_eviction_slot(state, min_games)
    ).astype(jnp.int32)
    params = jax.tree_util.tree_map(
        lambda stacked, leaf: stacked.at[slot].set(jnp.asarray(leaf, stacked.dtype)),
        state.params,
        learner_params,
    )
    return state.replace(
        params=params,
        size=jnp.minimum(state.size + 1, state.capacity),
        results=state.results.at[slot].set(0.0),
        result_count=state.result_count.at[slot].set(0),
        write_index=state.write_index.at[slot].set(0),
        serial=state.serial.at[slot].set(state.num_added),
        iteration=state.iteration.at[slot].set(jnp.asarray(iteration, jnp.int32)),
        num_added=state.num_added + 1,
    )


def league_maybe_add(
    state: LeagueState,
    learner_params: Params,
    iteration: ArrayLike,
    every: int = LEAGUE_EVERY,
    min_games: ArrayLike = LEAGUE_MIN_GAMES,
) -> LeagueState:
    """``league_add`` when ``iteration`` is a positive multiple of ``every`` (10), else no-op.

    ``iteration`` counts completed learner iterations; iteration 0's params are the snapshot
    ``league_init`` starts with, so they are not added twice.
    """
    iteration = jnp.asarray(iteration, jnp.int32)
    due = (iteration > 0) & (iteration % every == 0)
    return jax.lax.cond(
        due,
        lambda s: league_add(s, learner_params, iteration, min_games),
        lambda s: s,
        state,
    )


# --------------------------------------------------------------------------------------------
# The training opponent as one strategy per kind (what the learner sees of it)
# --------------------------------------------------------------------------------------------


class OpponentState(struct.PyTreeNode):
    """The training opponent's state, the same tree for every kind (checkpoints keep their
    layout): ``polyak`` holds the one opponent of 'polyak' and 'self', ``league`` the snapshots of
    'league'; the other is None."""

    polyak: PolyakState | None
    """'polyak' and 'self': the opponent's policy params (for 'self', the latest learner's)."""
    league: LeagueState | None
    """'league': past snapshots of the learner's policy and their results."""
    indices: jax.Array
    """i32[G]: the league snapshot each game of the next iteration is played against (0s
    otherwise)."""


class OpponentStrategy(Protocol):
    """One kind of training opponent. The learner calls ``init`` once, ``act_params`` before
    each rollout, ``update`` after each PPO update (with the learner's outcomes in its self-play
    games) and ``metrics`` for the iteration's log."""

    @property
    def per_game(self) -> bool:
        """True: ``act_params`` has a leading [games] axis (one opponent per game)."""
        ...

    def init(self, policy_params: Params) -> OpponentState: ...

    def act_params(self, state: OpponentState) -> Params: ...

    def update(
        self, state: OpponentState, policy_params: Params, outcomes: jax.Array,
        iteration: jax.Array, key: jax.Array,
    ) -> OpponentState: ...

    def metrics(self, state: OpponentState) -> dict[str, jax.Array]: ...


@dataclasses.dataclass(frozen=True)
class PolyakOpponent:
    """Section 5.2.6: a Polyak average of the learner that waits while the learner struggles."""

    tau: float = POLYAK_TAU
    threshold: float = POLYAK_THRESHOLD
    index_count: int = 1
    """Length of ``OpponentState.indices`` (unused by this kind, kept for the shared tree)."""
    per_game: bool = False

    def init(self, policy_params: Params) -> OpponentState:
        return OpponentState(
            polyak=polyak_init(policy_params), league=None,
            indices=jnp.zeros((self.index_count,), jnp.int32),
        )

    def act_params(self, state: OpponentState) -> Params:
        assert state.polyak is not None
        return state.polyak.params

    def update(
        self, state: OpponentState, policy_params: Params, outcomes: jax.Array,
        iteration: jax.Array, key: jax.Array,
    ) -> OpponentState:
        assert state.polyak is not None
        if outcomes.shape[0] == 0:  # no self-play game this iteration: nothing to go on
            return state
        return state.replace(polyak=self.step(state.polyak, policy_params, jnp.mean(outcomes)))

    def step(
        self, polyak: PolyakState, policy_params: Params, mean_outcome: jax.Array
    ) -> PolyakState:
        """Algorithm 4 lines 25-27: move towards the learner unless it is struggling."""
        return polyak_step(polyak, policy_params, mean_outcome, self.tau, self.threshold)

    def metrics(self, state: OpponentState) -> dict[str, jax.Array]:
        assert state.polyak is not None
        return {
            "opponent/frozen": state.polyak.frozen.astype(jnp.float32),
            "opponent/updates": state.polyak.num_updates.astype(jnp.float32),
        }


@dataclasses.dataclass(frozen=True)
class SelfPlayOpponent(PolyakOpponent):
    """Plain self-play (the ablation): the opponent is the latest learner, never frozen."""

    def step(
        self, polyak: PolyakState, policy_params: Params, mean_outcome: jax.Array
    ) -> PolyakState:
        return self_play_step(polyak, policy_params)


@dataclasses.dataclass(frozen=True)
class LeagueOpponent:
    """Section 5.2.7: past snapshots of the learner, each game's drawn by its win rate."""

    capacity: int = 32
    window: int = LEAGUE_WINDOW
    every: int = LEAGUE_EVERY
    psi: float = LEAGUE_PSI
    min_games: int = LEAGUE_MIN_GAMES
    index_count: int = 1
    """Games per iteration that draw a snapshot (the self-play games)."""
    per_game: bool = True

    def init(self, policy_params: Params) -> OpponentState:
        return OpponentState(
            polyak=None, league=league_init(policy_params, self.capacity, self.window),
            indices=jnp.zeros((self.index_count,), jnp.int32),
        )

    def act_params(self, state: OpponentState) -> Params:
        assert state.league is not None
        return league_params(state.league, state.indices)

    def update(
        self, state: OpponentState, policy_params: Params, outcomes: jax.Array,
        iteration: jax.Array, key: jax.Array,
    ) -> OpponentState:
        assert state.league is not None
        league = league_record(state.league, state.indices, 1.0 - outcomes)
        league = league_maybe_add(league, policy_params, iteration + 1, self.every, self.min_games)
        indices = league_sample(league, key, outcomes.shape[0], self.psi, self.min_games)
        return state.replace(league=league, indices=indices)

    def metrics(self, state: OpponentState) -> dict[str, jax.Array]:
        assert state.league is not None
        league = state.league
        live = league_live(league)
        rates = league_win_rates(league, self.min_games)
        return {
            "opponent/league_size": league.size.astype(jnp.float32),
            "opponent/league_mean_win_rate": jnp.sum(jnp.where(live, rates, 0.0))
            / jnp.maximum(league.size, 1).astype(jnp.float32),
            "opponent/league_max_win_rate": jnp.max(jnp.where(live, rates, 0.0)),
        }


def make_opponent(
    kind: str, *, polyak_tau: float = POLYAK_TAU, freeze_threshold: float = POLYAK_THRESHOLD,
    league_capacity: int = 32, league_window: int = LEAGUE_WINDOW,
    league_every: int = LEAGUE_EVERY, league_psi: float = LEAGUE_PSI,
    league_min_games: int = LEAGUE_MIN_GAMES, index_count: int = 1,
) -> OpponentStrategy:
    """The strategy of ``kind`` (one of ``OPPONENT_KINDS``)."""
    if kind == "polyak":
        return PolyakOpponent(polyak_tau, freeze_threshold, index_count)
    if kind == "self":
        return SelfPlayOpponent(index_count=index_count)
    if kind == "league":
        return LeagueOpponent(
            league_capacity, league_window, league_every, league_psi, league_min_games,
            index_count,
        )
    raise ValueError(f"opponent kind={kind!r} is unknown: allowed are {', '.join(OPPONENT_KINDS)}")
