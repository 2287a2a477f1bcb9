"""A skills team's server play recorded for PPO: :class:`Recorder` is the decision server's
``decide`` for the policy being trained, and :func:`pack` turns the cycles it recorded into
the ``Rollout`` the compiled unroll returns, so ``Learner.improve`` runs unchanged.

The recorder decides as ``learned.LearnedSkills`` does (the world model as the skill game's
observation, one policy call for the cycle's players, each player's memory kept by shirt
number, the action decoded and played with the routines outside open play), but it SAMPLES
the action from the policy's distribution with the learner's current params and, while
recording, keeps per cycle and player what PPO needs: the observation, the raw sample and its
log-probability, whether a routine played instead of the policy, and the world model it saw
(for the critic's input and the reward).

A step of the rollout is one server cycle (the proxy's (cycle, stopped cycle)); its reward is
the skill game's (``elevens.env.reward.reward_terms``): the goals scored and conceded between
this cycle and the next, read from the referee's score in the world model, for every player
of the team, plus the shaping terms in force, computed from the team's merged world model.
Where the policy's sample was not what the player did, the step leaves PPO's policy terms
(``Rollout.scripted``): a routine played (kick-off placing, set plays, the goalie, penalties,
the proxy's own perception fallbacks, a player not yet placed), the request missed its
deadline and got the default, or the player did not ask that cycle (its step is then a copy of
its nearest one).
"""

from __future__ import annotations

import dataclasses
import threading
from collections.abc import Callable, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.params import EnvParams
from elevens.env.reward import reward_terms
from elevens.env.state import GlobalState, Observation
from elevens.play import PolicyActor
from elevens.robocup.rules import MATCH_CLOCK
from elevens.robocup.skills.learned import (
    check_defer_to,
    shirt_batches,
    sim_observation,
    skill_decisions,
)
from elevens.robocup.skills.naive import helios_parts, kick_off_points, routine_rows
from elevens.robocup.skills.observe import PLAYERS, observe
from elevens.robocup.skills.observe import Observation as SkillObservation
from elevens.robocup.skills.set_plays import TakerGuard, check_set_plays
from elevens.robocup.skills.space import to_player_actions
from elevens.robocup.skills.team import (
    SKILLS_FIELD,
    SkillsNaiveTeam,
    deferred,
    defers,
    self_feature_count,
)
from elevens.teams.scripted import Field
from elevens.train.rollout import Rollout, StepRecord, Teacher, collected

__all__ = ["Recorder", "Segment", "pack", "routine_played", "teacher_actions"]

# (match, server cycle, the player's request within that cycle): one step of one match. The
# clock stands before a kick-off while each player still asks once a cycle; librcsc's
# stopped-cycle count differs between players that connected at different times, and so does
# this count for a player that joined late (its steps there are filled in; all of them are
# the kick-off placing's, masked anyway). In play every player asks once a cycle: count 0.
Key = tuple[int, int, int]


def routine_played(obs: SkillObservation, set_plays: str = "routine") -> np.ndarray:
    """bool[m]: the rows whose player does not play the policy's decision: outside open play
    (kick-off placing and set plays, ``naive.outside_open_play``; with ``set_plays="decided"``
    not our decided set plays), the goalie (the proxy's goalie behaviour), penalties, and a
    proxy that runs its own perception fallbacks (``need_preprocess``: they replace the
    action)."""
    return routine_rows(obs, set_plays) | np.asarray(obs.need_preprocess)


def _finite(obs: SkillObservation) -> tuple[SkillObservation, np.ndarray]:
    """``obs`` with every value librcsc has not placed yet (its invalid vector, DBL_MAX, is
    inf as float32: a player before its first see) set to 0, and bool[m]: the rows that had
    one (the policy decides on a world it does not know: masked like a routine)."""
    bad = np.zeros(len(obs), bool)
    fields: dict[str, np.ndarray] = {}
    for name, value in vars(obs).items():
        a = np.asarray(value)
        if a.dtype.kind == "f":
            finite = np.isfinite(a)
            bad |= ~finite.reshape(len(obs), -1).all(axis=1)
            a = np.where(finite, a, 0.0).astype(a.dtype)
        fields[name] = a
    return SkillObservation(**fields), bad


@dataclasses.dataclass
class _Row:
    """One player's recorded request."""

    obs: dict[str, np.ndarray]  # its Observation's leaves, no leading axis
    world: dict[str, np.ndarray]  # its row of the runtime's arrays (skills.observe)
    pre_tanh: np.ndarray  # f32[A]
    log_prob: float
    routine: bool  # a routine played instead of the policy
    score: tuple[int, int]  # (ours, theirs) as the referee has announced them


@dataclasses.dataclass
class Segment:
    """What a recorder kept between ``start`` and ``stop``: the rows by cycle and shirt
    number, each shirt's memory before its first recorded decision, and the requests that
    got the default."""

    rows: dict[Key, dict[int, _Row]]
    initial: dict[int, Any]  # shirt -> its carry's leaves (no leading axis)
    defaulted: set[tuple[int, int, int]]  # (match, cycle, shirt)

    @property
    def cycles(self) -> int:
        return len(self.rows)


class Recorder:
    """The runtime's ``decide`` for the policy being trained (module docstring).

    ``policy``: the learner's ``AttentionPolicy`` (4-value skill action); its params are set
    with :meth:`set_params` before the first decision. ``hold_s``: while not recording, each
    decision waits this long first (the match crawls while the learner updates; recording
    resumes it at once). ``on_default`` is :meth:`defaulted`. ``set_plays``: our set plays
    the proxy's routine or the policy's decisions (``set_plays``; a decision the free-kick
    rule changed is masked like a routine).
    """

    def __init__(self, policy: Any, *, seed: int = 0, field: Field = SKILLS_FIELD,
                 episode_length: int = MATCH_CLOCK, hold_s: float = 0.0,
                 set_plays: str = "routine", reach: bool = False, defer: bool = False,
                 defer_to: str = "skills_naive") -> None:
        check_set_plays(set_plays)
        check_defer_to(defer, defer_to)
        self.reach = reach
        self.defer = defer
        self.defer_to = defer_to
        self.set_plays = set_plays
        self.guard = TakerGuard()
        self.policy = policy
        self.field = field
        self.episode_length = episode_length
        self.hold_s = hold_s
        self.params: Any = None
        self.key = jax.random.key(seed)
        self.carry = policy.initial_carry((1, PLAYERS))
        self.match = 0
        self.policy_calls = 0
        self._lock = threading.Lock()
        self._recording = threading.Event()
        self._after: Key = (-1, -1, -1)  # the latest key seen: recording starts after it
        self._latest: Key = (-1, -1, -1)
        self._asked: dict[int, tuple[int, int]] = {}  # shirt -> (its last cycle, requests)
        self._segment = Segment({}, {}, set())
        self._step = jax.jit(self._policy_step)

    # ---- control (the trainer's thread) ----

    def set_params(self, params: Any, key: jax.Array | None = None) -> None:
        """Decide with ``params`` from the next cycle on (and sample with ``key``)."""
        with self._lock:
            self.params = params
            if key is not None:
                self.key = key

    def new_match(self) -> None:
        """A new match starts (a fresh server): every player's memory is zeroed, and its
        cycles are keyed apart from the last match's."""
        with self._lock:
            self.match += 1
            self.carry = self.policy.initial_carry((1, PLAYERS))
            self._asked = {}
            self.guard.reset()

    def start(self) -> None:
        """Record every cycle that begins from now on."""
        with self._lock:
            self._segment = Segment({}, {}, set())
            self._after = self._latest
            self._recording.set()

    def stop(self) -> Segment:
        """Stop recording; the cycles recorded since :meth:`start`."""
        with self._lock:
            self._recording.clear()
            return self._segment

    def recorded(self) -> int:
        """Cycles recorded so far (a cycle counts once any player has asked in it)."""
        with self._lock:
            return self._segment.cycles

    def defaulted(self, state: Any) -> None:
        """The decision server's ``on_default``: this request got the default action."""
        wm = state.world_model
        me = None if wm is None else wm.myself
        if me is None:
            return
        with self._lock:
            if self._recording.is_set():
                self._segment.defaulted.add(
                    (self.match, int(wm.cycle or 0), int(me.uniform_number or 0)))

    # ---- deciding (the decision server's thread) ----

    def _policy_step(self, params: Any, carry: Any, obs: Observation, present: jax.Array,
                     key: jax.Array) -> tuple[Any, jax.Array, jax.Array, jax.Array, jax.Array]:
        reset = jnp.zeros((1, PLAYERS), bool)  # new_match zeroes the memory itself
        new, output = self.policy.apply(params, carry, obs, reset)
        distribution = output.distribution()
        sample = distribution.sample(key)
        log_prob = distribution.log_prob(sample.pre_tanh)
        action = sample.action
        deferring = jnp.zeros(action.shape[:-1], bool)
        if self.defer:  # played as skills_naive's (or helios's), recorded (pre_tanh) as DEFER
            deferring = defers(action)
            one = jax.tree.map(lambda leaf: leaf[0], obs)
            action = deferred(action[0], one, SkillsNaiveTeam(field=self.field))[None]

        def keep(fresh: jax.Array, old: jax.Array) -> jax.Array:
            asked = present.reshape(present.shape + (1,) * (fresh.ndim - 2))
            return jnp.where(asked, fresh, old)

        return jax.tree.map(keep, new, carry), action, sample.pre_tanh, log_prob, deferring

    def warm_up(self) -> None:
        """Compile the policy call before a match (nobody's memory changes)."""
        from elevens.env.state import ENTITY_FEATURES

        leaves: dict[str, Any] = dict(
            self_features=np.zeros((1, PLAYERS, self_feature_count(self.reach)), np.float32),
            entities=np.zeros((1, PLAYERS, 2 * PLAYERS, len(ENTITY_FEATURES)), np.float32),
            entity_mask=np.ones((1, PLAYERS, 2 * PLAYERS), bool),
        )
        present = np.zeros((1, PLAYERS), bool)
        out = self._step(self.params, self.carry, Observation(**leaves), present, self.key)
        jax.block_until_ready(out)

    def __call__(self, states: Sequence[Any]) -> list[Any]:
        """The proxy's States of a cycle to PlayerActions (one policy call per distinct
        shirt number; a batch holding a player twice is decided in order)."""
        if self.hold_s > 0 and not self._recording.is_set():
            self._recording.wait(self.hold_s)
        with np.errstate(over="ignore"):  # librcsc's unplaced values: _finite
            obs, unplaced = _finite(observe(states))
        view = sim_observation(obs, self.field, episode_length=self.episode_length,
                               reach=self.reach)
        with self._lock:
            params, match = self.params, self.match
        m = len(obs.unum)
        actions = np.zeros((m, 4), np.float32)
        pre_tanh = np.zeros((m, 4), np.float32)
        log_prob = np.zeros(m, np.float32)
        deferring = np.zeros(m, bool)
        before: list[Any] = [None] * m
        for rows, slot, fill, asked in shirt_batches(obs.unum):
            padded = jax.tree.map(lambda leaf, fill=fill: leaf[fill][None], view)
            present = asked[None]
            carry = jax.tree.map(np.asarray, self.carry)
            for r, s in zip(rows, slot, strict=True):
                before[r] = jax.tree.map(lambda leaf, s=s: leaf[0, s], carry)
            self.key, key = jax.random.split(self.key)
            self.carry, act, raw, logp, defers = self._step(params, self.carry, padded,
                                                            present, key)
            self.policy_calls += 1
            actions[rows] = np.asarray(act)[0, slot]
            pre_tanh[rows] = np.asarray(raw)[0, slot]
            log_prob[rows] = np.asarray(logp)[0, slot]
            deferring[rows] = np.asarray(defers)[0, slot]
        decisions = skill_decisions(obs, actions, np.asarray(view.entity_mask), self.field,
                                    self.set_plays)
        if self.defer_to == "helios":
            decisions = helios_parts(decisions, obs.kickable, deferring)
        changed = np.zeros(m, bool)
        if self.set_plays == "decided":
            decisions, changed = self.guard.apply(obs, decisions)
        routine = routine_played(obs, self.set_plays) | unplaced | changed
        self._record(states, obs, view, pre_tanh, log_prob, before, match, routine)
        return to_player_actions(decisions, obs)

    def _record(self, states: Sequence[Any], obs: SkillObservation, view: Observation,
                pre_tanh: np.ndarray, log_prob: np.ndarray, before: list[Any],
                match: int, routine: np.ndarray) -> None:
        with self._lock:
            if match != self.match:
                return  # decided for a match that has ended
            keys = []
            for shirt, cycle in zip(obs.unum.tolist(), obs.cycle.tolist(), strict=True):
                last, count = self._asked.get(shirt, (-1, 0))
                count = count + 1 if cycle == last else 0
                self._asked[shirt] = (cycle, count)
                keys.append((match, cycle, count))
            self._latest = max([self._latest, *keys])
            if not self._recording.is_set():
                return
            segment = self._segment
            for i, key in enumerate(keys):
                if key <= self._after:
                    continue  # a cycle that began before recording did
                shirt = int(obs.unum[i])
                wm = states[i].world_model
                segment.initial.setdefault(shirt, before[i])
                segment.rows.setdefault(key, {})[shirt] = _Row(
                    obs={name: np.asarray(leaf)[i] for name, leaf in vars(view).items()},
                    world={name: np.asarray(a)[i] for name, a in vars(obs).items()},
                    pre_tanh=pre_tanh[i], log_prob=float(log_prob[i]),
                    routine=bool(routine[i]),
                    score=(int(wm.our_team_score or 0), int(wm.their_team_score or 0)),
                )


# ------------------------------------------------------------------ packing


@dataclasses.dataclass(frozen=True)
class _World:
    """The team's merged world model at one cycle, our frame (we attack +x)."""

    positions: np.ndarray  # f32[2n, 2] ours by shirt, then theirs by shirt
    velocities: np.ndarray  # f32[2n, 2]
    headings: np.ndarray  # f32[2n] radians
    placed: np.ndarray  # bool[2n] someone places the player
    ball: np.ndarray  # f32[2]
    ball_velocity: np.ndarray  # f32[2]
    score: tuple[int, int]


def _merge(rows: dict[int, _Row]) -> _World:
    """Each of our players where it places itself (else where a teammate places it), each
    opponent where the first teammate that places it does, the ball where the teammate that
    saw it last places it; the highest score any player has heard."""
    n = PLAYERS
    positions = np.zeros((2 * n, 2), np.float32)
    velocities = np.zeros((2 * n, 2), np.float32)
    headings = np.zeros(2 * n, np.float32)
    placed = np.zeros(2 * n, bool)
    for side, (where, valid, vel, body) in enumerate((
        ("mates", "mates_valid", "mates_vel", "mates_body"),
        ("opps", "opps_valid", "opps_vel", "opps_body"),
    )):
        for shirt, row in sorted(rows.items()):
            w = row.world
            for k in np.flatnonzero(w[valid]):
                index = side * n + k
                own = side == 0 and k == shirt - 1
                if placed[index] and not own:
                    continue
                positions[index], velocities[index] = w[where][k], w[vel][k]
                headings[index], placed[index] = np.radians(w[body][k]), True
    freshest = min(rows.values(), key=lambda row: int(row.world["ball_pos_count"]))
    scores = [row.score for row in rows.values()]
    return _World(
        positions=positions, velocities=velocities, headings=headings, placed=placed,
        ball=np.asarray(freshest.world["ball"], np.float32),
        ball_velocity=np.asarray(freshest.world["ball_vel"], np.float32),
        score=(max(s[0] for s in scores), max(s[1] for s in scores)),
    )


def _global_state(world: _World, time_left: float, field: Field) -> GlobalState:
    """The learner's critic input (``env.observe.global_state``'s team-0 view) from the
    merged world model. What the world model does not give: the last commands (0) and the
    starts, our kick-off points and theirs mirrored."""
    n = PLAYERS
    extent = np.array([field.half_length, field.half_width], np.float32)
    starts = kick_off_points(np.arange(1, n + 1))
    start = np.concatenate([starts, -starts]) / extent
    players = np.concatenate([
        world.positions / extent, np.cos(world.headings)[:, None],
        np.sin(world.headings)[:, None], world.velocities, np.zeros((2 * n, 2)), start,
        np.concatenate([np.ones((n, 1)), np.zeros((n, 1))]),
    ], axis=-1).astype(np.float32)
    context = np.concatenate([[time_left], world.ball / extent, world.ball_velocity])
    leaves: dict[str, Any] = dict(context=context.astype(np.float32), players=players)
    return GlobalState(**leaves)  # numpy leaves: stacked over the cycles here


@jax.jit
def _terms(goals: jax.Array, after: dict[str, jax.Array], ball_before: jax.Array,
           params: EnvParams) -> Any:
    """``reward_terms`` over T cycles (leading axis), the team's view as team 0."""
    def one(g: jax.Array, a: dict[str, jax.Array], before: jax.Array) -> Any:
        return reward_terms(g, a["ball"], a["ball_velocity"], a["velocities"], before,
                            a["positions"], params)

    return jax.vmap(one)(goals, after, ball_before)


def _nearest(rows: dict[Key, dict[int, _Row]], keys: Sequence[Key], t: int,
             shirt: int) -> _Row | None:
    """Shirt ``shirt``'s row nearest before cycle ``t`` of ``keys``, else nearest after."""
    for index in (*range(t - 1, -1, -1), *range(t + 1, len(keys))):
        row = rows[keys[index]].get(shirt)
        if row is not None:
            return row
    return None


def _game(segment: Segment, steps: int, params: EnvParams, field: Field,
          shaping: bool) -> tuple[dict[str, Any], dict[str, int]]:
    """One game's StepRecord leaves [T, ...] (no game axis) and its counts."""
    keys = sorted(segment.rows)[: steps + 1]
    if len(keys) < steps + 1:
        raise ValueError(f"a segment of {len(keys)} cycles cannot give {steps} steps (it needs "
                         f"{steps + 1}: the last one's score ends the reward)")
    n = PLAYERS
    obs: dict[str, list[np.ndarray]] = {}
    pre_tanh = np.zeros((steps, n, 4), np.float32)
    log_prob = np.zeros((steps, n), np.float32)
    scripted = np.zeros((steps, n), bool)
    counts = {"routine": 0, "defaulted": 0, "filled": 0}
    for t, key in enumerate(keys[:steps]):
        rows, step_obs = segment.rows[key], []
        for shirt in range(1, n + 1):
            row = rows.get(shirt)
            filled = row is None
            if row is None:  # it did not ask: its nearest step stands in, masked
                row = _nearest(segment.rows, keys[:steps], t, shirt) or next(iter(rows.values()))
            defaulted = (key[0], key[1], shirt) in segment.defaulted
            counts["filled"] += filled
            counts["defaulted"] += defaulted and not filled
            counts["routine"] += row.routine and not (filled or defaulted)
            step_obs.append(row.obs)
            pre_tanh[t, shirt - 1], log_prob[t, shirt - 1] = row.pre_tanh, row.log_prob
            scripted[t, shirt - 1] = filled or defaulted or row.routine
        for name in step_obs[0]:
            obs.setdefault(name, []).append(np.stack([o[name] for o in step_obs]))
    worlds = [_merge(segment.rows[key]) for key in keys]
    same = np.array([a[0] == b[0] for a, b in zip(keys[:-1], keys[1:], strict=True)])
    score = np.array([w.score for w in worlds], np.int32)
    goals = np.maximum(score[1:] - score[:-1], 0) * same[:, None]  # [T, 2] ours, theirs
    after = {name: np.stack([getattr(w, name) for w in worlds[1:]])
             for name in ("positions", "velocities", "ball", "ball_velocity")}
    # Unplaced opponents stand far away: they hold no ball.
    after["positions"] = np.where(np.stack([w.placed for w in worlds[1:]])[..., None],
                                  after["positions"], 1e4).astype(np.float32)
    ball_before = np.stack([w.ball for w in worlds[:-1]])
    terms = jax.tree.map(np.asarray, _terms(goals, after, ball_before, params))
    kept = same[:, None].astype(np.float32)  # a new match between two cycles: no reward
    goal, ball = terms.goal[:, 0] * kept, terms.ball[:, 0] * kept
    approach, possession = terms.approach[:, 0] * kept, terms.possession[:, 0] * kept
    reward = goal + ((ball + approach + possession) if shaping else 0.0)
    index = np.arange(steps)
    states = [_global_state(w, 1.0 - t / steps, field) for t, w in enumerate(worlds[:steps])]
    stacked: dict[str, Any] = {name: np.stack(v) for name, v in obs.items()}
    leaves = dict(
        obs=Observation(**stacked),
        global_state=jax.tree.map(lambda *x: np.stack(x), *states),
        pre_tanh=pre_tanh, log_prob=log_prob, reward=reward.astype(np.float32),
        done=(index == steps - 1) | ~same, truncated=(index == steps - 1) | ~same,
        reset=np.concatenate([[False], ~same[:-1]]),
        goal_reward=goal, ball_shaping=ball, approach_shaping=approach,
        possession_shaping=possession, holder=terms.holder[:, 0] * kept[:, 0],
        scripted=scripted,
    )
    counts.update(goals_for=int(goals[:, 0].sum()), goals_against=int(goals[:, 1].sum()),
                  matches=len({k[0] for k in keys[:steps]}))
    return leaves, counts


def teacher_actions(teacher: Teacher) -> Callable[[Observation, jax.Array], jax.Array]:
    """A jitted ``(obs [T, G, n], key) -> f32[T, G, n, A]``: ``teacher`` (``ppo.teacher``'s
    team) acting on the recorded cycles' observations in turn, as it acts beside the learner
    in the simulator's unroll; a network teacher's memory starts fresh each segment."""
    actor = PolicyActor(teacher.policy, teacher.params)

    @jax.jit
    def act(obs: Observation, key: jax.Array) -> jax.Array:
        steps, games = obs.self_features.shape[:2]

        def step(carry: Any, x: tuple[Observation, jax.Array]) -> tuple[Any, jax.Array]:
            carry, actions, _ = actor.act(carry, x[0], jnp.zeros(games, bool), x[1])
            return carry, jnp.asarray(actions, jnp.float32)

        carry = actor.init_carry(games, PLAYERS)
        return jax.lax.scan(step, carry, (obs, jax.random.split(key, steps)))[1]

    return act


def pack(segments: Sequence[Segment], steps: int, policy: Any, params: EnvParams, *,
         shaping: bool, field: Field = SKILLS_FIELD,
         teacher: Callable[[Observation, jax.Array], jax.Array] | None = None,
         key: jax.Array | None = None) -> tuple[Rollout, list[dict[str, int]]]:
    """The first ``steps`` cycles of every game's segment as the learner's ``Rollout``
    (``G * 11`` player sequences of ``steps``), and each game's counts: goals for and
    against, steps a routine played, requests defaulted, steps filled in, matches.
    ``params``: the skill game's EnvParams (goal reward, shaping weights); ``shaping``:
    whether the shaping is in force (``TrainState.shaping.active``). Each player's memory
    before its first recorded decision starts its sequence (the match goes on across
    segments); a new match within a segment ends one episode and starts the next.
    ``teacher`` (``teacher_actions``) with its ``key``: its actions on every step go into
    ``Transition.teacher_action`` for the teacher loss (which counts only where the policy
    played)."""
    games = [_game(segment, steps, params, field, shaping) for segment in segments]
    history = StepRecord(**jax.tree.map(lambda *x: np.stack(x, axis=1),
                                        *[leaves for leaves, _ in games]))
    zero = jax.tree.map(lambda leaf: np.asarray(leaf)[0, 0], policy.initial_carry((1, 1)))
    initial = [jax.tree.map(lambda *x: np.stack(x),
                            *[segment.initial.get(shirt, zero) for shirt in range(1, PLAYERS + 1)])
               for segment in segments]
    initial_carry = jax.tree.map(lambda *x: jnp.asarray(np.stack(x)), *initial)
    counts = [c for _, c in games]
    goals_for = jnp.asarray([c["goals_for"] for c in counts], jnp.int32)
    goals_against = jnp.asarray([c["goals_against"] for c in counts], jnp.int32)
    side = jnp.zeros(len(segments), jnp.int32)
    history = jax.tree.map(jnp.asarray, history)
    if teacher is not None:
        if key is None:
            raise ValueError("pack: a teacher acts with a key; pass key")
        history = history.replace(teacher_action=teacher(history.obs, key))
    return collected(history, goals_for, goals_against, side, initial_carry, PLAYERS), counts
