"""A trained skills policy in the server runtime: a checkpoint of ``elevens train skills-2v2``
or ``skills-11v11`` (or a team exported from one) decides the proxy's players unchanged.

:func:`sim_observation` is the converse of ``skills.team.skill_observation``: the runtime's
arrays (librcsc's world model, ``skills.observe.Observation``) become the simulator's
``Observation`` the skill game gives its players (``elevens.env.observe.observe``: the features
``SELF_FEATURES`` and ``ENTITY_FEATURES`` in their order and normalisation, the team frame,
slots in ``entity_layout``'s order) in the layout of 11 v 11, the runtime's team. The policy
takes any team size (its entities go through attention, its pointer attends over the slots),
so a 2 v 2 checkpoint plays the eleven.

:class:`LearnedSkills` is the runtime's ``decide``: one policy call per batch, padded to the
eleven shirt numbers so it compiles once; each player's recurrent memory kept by shirt number
from the first cycle on; the action decoded by ``decode.decode`` (the simulator's own decode)
and played as ``skills_naive``'s decisions are (``space.to_player_actions``), with the same
kick-off moves, goalie and set-play behaviours outside open play.
"""

from __future__ import annotations

import os
from collections.abc import Iterator, Sequence
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.state import ENTITY_FEATURES, SELF_FEATURES, Observation
from elevens.robocup.rules import MATCH_CLOCK
from elevens.robocup.skills.decode import (
    DRIBBLE,
    MARK,
    PASS,
    SKILL_ACTION_SIZE,
    SkillContext,
    decode,
)
from elevens.robocup.skills.naive import helios_parts, kick_off_points, outside_open_play
from elevens.robocup.skills.observe import PLAYERS, observe
from elevens.robocup.skills.observe import Observation as SkillObservation
from elevens.robocup.skills.set_plays import TakerGuard, check_set_plays
from elevens.robocup.skills.space import OPEN_PLAY, Decisions, Kind, to_player_actions
from elevens.robocup.skills.team import (
    DEFER,
    SKILLS_FIELD,
    SkillsNaiveTeam,
    deferred,
    defers,
    reach_features,
    self_feature_count,
)
from elevens.teams.scripted import Field

__all__ = [
    "shirt_batches",
    "APPROXIMATED",
    "BALL_SEEN_WITHIN",
    "LearnedSkills",
    "check_skills_team",
    "is_skills_team",
    "load_learned_skills",
    "sim_observation",
    "skill_decisions",
    "trained_game",
]

BALL_SEEN_WITHIN = 10
"""Cycles since the ball was seen within which librcsc counts its estimate valid
(``BallObject::posValid``): the ball is "in view" (``ball_visible``, its slot's mask)."""

#: Features the world model does not give, and so are set to the nearest honest value rather
#: than read back (:func:`sim_observation`).
APPROXIMATED = {
    "self": ("time_left", "last_move", "last_rot", "start_x", "start_y"),
    "entity": ("last_move", "last_rot"),
}

_S = {name: i for i, name in enumerate(SELF_FEATURES)}
_E = {name: i for i, name in enumerate(ENTITY_FEATURES)}
_SLOTS = 2 * PLAYERS  # an observer's entity slots in 11 v 11: 10 teammates, 11 opponents, ball


def _slot_table(unum: np.ndarray) -> np.ndarray:
    """int[m, 22]: for each observer (shirt numbers), the index into its teammates (0..10),
    opponents (11..21) and the ball (22) of each entity slot, ``entity_layout``'s order."""
    rows = []
    for u in unum:
        mates = [k for k in range(PLAYERS) if k != int(u) - 1]
        rows.append(mates + list(range(PLAYERS, 2 * PLAYERS)) + [2 * PLAYERS])
    return np.asarray(rows, np.int64).reshape(len(unum), _SLOTS)


def sim_observation(obs: SkillObservation, field: Field = SKILLS_FIELD, *,
                    episode_length: int = MATCH_CLOCK, reach: bool = False) -> Observation:
    """The runtime's arrays over ``m`` deciding players -> the simulator's ``Observation``
    [m] of each as player ``unum - 1`` of an 11 v 11 team (numpy, team frame; librcsc's
    frame is the team frame: our team attacks +x).

    Read from the world model: own position and body; every teammate, opponent and the ball
    it places (position, velocity, body direction), each slot masked where it places none (a
    ball counts as placed while seen within :data:`BALL_SEEN_WITHIN` cycles); the simulator
    masks every feature of a slot out of view to 0, and so does this. Set to the nearest
    honest value (:data:`APPROXIMATED`):

    - ``time_left``: the server's cycle counted in episodes of ``episode_length`` cycles
      (``MATCH_CLOCK``, about what the policies trained on), not restarted at kick-offs;
    - ``last_move``, ``last_rot`` (own and others'): 0. The runtime sends skills, and which
      dash or turn librcsc's skill then chose is not in the world model;
    - ``start_x``, ``start_y``: the player's kick-off point (``naive.kick_off_points``), where
      the runtime places it before every kick-off, rather than a spawn point of the game.

    With ``reach`` (a team trained with ``env.reach_features``) the self features end with
    librcsc's intercept table (``team.REACH_FEATURES``), as the skill game adds them.
    """
    m = len(obs)
    extent = np.array([field.half_length, field.half_width], np.float32)
    length = 2.0 * field.half_length
    # Before its first see a player's own position is unset in the world model (inf): its
    # kick-off point stands in, where the runtime places it. A NaN feature would poison a
    # recurrent policy's memory for the rest of the match.
    pos = np.asarray(obs.pos, np.float64)
    pos = np.where(np.isfinite(pos).all(axis=-1, keepdims=True), pos,
                   kick_off_points(np.asarray(obs.unum)))
    heading = np.radians(np.nan_to_num(np.asarray(obs.body, np.float64), posinf=0.0, neginf=0.0))
    c, s = np.cos(heading)[:, None], np.sin(heading)[:, None]

    table = _slot_table(np.asarray(obs.unum))
    ball_seen = np.asarray(obs.ball_pos_count) <= BALL_SEEN_WITHIN
    where = np.concatenate([obs.mates, obs.opps, np.asarray(obs.ball)[:, None]], axis=1)
    velocity = np.concatenate([obs.mates_vel, obs.opps_vel, np.asarray(obs.ball_vel)[:, None]],
                              axis=1)
    body = np.radians(np.concatenate([obs.mates_body, obs.opps_body, np.zeros((m, 1))], axis=1))
    placed = np.concatenate([obs.mates_valid, obs.opps_valid, ball_seen[:, None]], axis=1)

    def slotted(a: np.ndarray) -> np.ndarray:
        index = table if a.ndim == 2 else table[..., None]
        return np.take_along_axis(a, index, axis=1)

    where, velocity, body, mask = slotted(where), slotted(velocity), slotted(body), slotted(placed)
    # A slot whose estimate is not a number is out of view (its features 0, not NaN).
    mask = mask & np.isfinite(where).all(axis=-1)
    where = np.where(mask[..., None], where, 0.0)
    velocity = np.where(mask[..., None] & np.isfinite(velocity), velocity, 0.0)
    body = np.where(mask & np.isfinite(body), body, 0.0)
    dx = where[..., 0] - pos[:, 0:1]
    dy = where[..., 1] - pos[:, 1:2]
    distance = np.sqrt(dx * dx + dy * dy)
    safe = distance > 1e-6
    inverse = 1.0 / np.where(safe, distance, 1.0)
    vx, vy = velocity[..., 0], velocity[..., 1]
    is_ball = np.zeros((m, _SLOTS), np.float32)
    is_ball[:, -1] = 1.0
    teammate = np.zeros((m, _SLOTS), np.float32)
    teammate[:, : PLAYERS - 1] = 1.0
    other_cos, other_sin = np.cos(body), np.sin(body)
    columns = {
        "distance": distance / length,
        "cos_bearing": np.where(safe, (dx * c + dy * s) * inverse, 1.0),
        "sin_bearing": np.where(safe, (dy * c - dx * s) * inverse, 0.0),
        "vel_forward": vx * c + vy * s,
        "vel_left": vy * c - vx * s,
        "cos_rel_heading": (other_cos * c + other_sin * s) * (1.0 - is_ball),
        "sin_rel_heading": (other_sin * c - other_cos * s) * (1.0 - is_ball),
        "last_move": np.zeros((m, _SLOTS)),
        "last_rot": np.zeros((m, _SLOTS)),
        "is_teammate": teammate,
        "is_ball": is_ball,
    }
    entities = np.stack([np.where(mask, columns[name], 0.0) for name in ENTITY_FEATURES],
                        axis=-1).astype(np.float32)

    cycle = np.asarray(obs.cycle) % episode_length
    own = {
        "time_left": np.clip(1.0 - cycle / episode_length, 0.0, 1.0),
        "x": pos[:, 0] / extent[0],
        "y": pos[:, 1] / extent[1],
        "cos_heading": c[:, 0],
        "sin_heading": s[:, 0],
        "last_move": np.zeros(m),
        "last_rot": np.zeros(m),
        "ball_visible": mask[:, -1].astype(np.float32),
    }
    start = kick_off_points(np.asarray(obs.unum)) / extent
    own["start_x"], own["start_y"] = start[:, 0], start[:, 1]
    ball = ("distance", "cos_bearing", "sin_bearing", "vel_forward", "vel_left")
    for name in ball:
        own[f"ball_{name}"] = entities[:, -1, _E[name]]
    self_features = np.stack([own[name] for name in SELF_FEATURES], axis=-1).astype(np.float32)
    if reach:
        self_features = np.concatenate([self_features, reach_features(
            np.asarray(obs.self_reach), np.asarray(obs.mate_reach), np.asarray(obs.opp_reach))],
            axis=-1)
    leaves: dict[str, Any] = dict(self_features=self_features, entities=entities,
                                  entity_mask=mask)  # numpy leaves: the padding cuts them here
    return Observation(**leaves)


def skill_decisions(obs: SkillObservation, actions: np.ndarray, seen: np.ndarray,
                    field: Field = SKILLS_FIELD, set_plays: str = "routine") -> Decisions:
    """The policy's actions f32[m, 4] for the rows of ``obs`` as the runtime's decisions:
    decoded as the simulator decodes them (each player as player ``unum - 1`` of 11 v 11;
    ``seen`` bool[m, 22] its observation's mask), then what every skills team plays outside
    open play laid over them (``naive.outside_open_play``; our set plays as ``set_plays``
    says)."""
    unum = np.asarray(obs.unum)
    context = SkillContext(
        observer=unum - 1, unum=unum, position=np.asarray(obs.pos), ball=np.asarray(obs.ball),
        offside_x=np.asarray(obs.offside_x), kickable=np.asarray(obs.kickable),
    )
    choice = decode(np.asarray(actions, np.float32), context, PLAYERS,
                    half=(field.half_length, field.half_width),
                    goal_half_width=field.goal_half_width, seen=seen, xp=np)
    # World index -> shirt number: our players are 0..10, theirs 11..21 (11 v 11 layout).
    index = np.where(choice.kind == PASS, choice.target + 1,
                     np.where(choice.kind == MARK, choice.target - PLAYERS + 1,
                              np.where(choice.kind == DRIBBLE, choice.direction, 0)))
    return Decisions.of(*outside_open_play(obs, choice.kind, index, choice.point,
                                           set_plays=set_plays))


def shirt_batches(
    unum: Any,
) -> Iterator[tuple[list[int], np.ndarray, np.ndarray, np.ndarray]]:
    """The rows of a batch of requests (shirt numbers ``unum``) in policy calls of distinct
    shirts, in order (a player twice: two cycles' requests): each call's ``(rows, slot,
    fill, present)``: the rows and their shirts' slots; for every shirt a row (those that
    did not ask repeat a row that did, their result and memory dropped, so the call has one
    shape); which shirts asked, bool[PLAYERS]."""
    unum = np.asarray(unum)
    left = list(range(len(unum)))
    while left:
        rows: list[int] = []
        later: list[int] = []
        shirts: set[int] = set()
        for r in left:
            (later if int(unum[r]) in shirts else rows).append(r)
            shirts.add(int(unum[r]))
        slot = unum[rows] - 1
        fill = np.full(PLAYERS, rows[0])
        fill[slot] = rows
        present = np.zeros(PLAYERS, bool)
        present[slot] = True
        yield rows, slot, fill, present
        left = later


class LearnedSkills:
    """The runtime's ``decide`` for a trained skills policy (module docstring).

    ``policy``: a ``TeamPolicy`` of the 4-value skill action (a loaded checkpoint's
    ``NetworkTeam``; its ``deterministic`` says whether it plays the mode of its distribution
    or samples from it), ``params`` its variables. ``policy_calls`` counts the compiled calls.
    ``set_plays``: our set plays the proxy's ready behaviour (``routine``) or the policy's
    (``decided``, within the free-kick rule: ``set_plays.TakerGuard``).
    """

    def __init__(self, policy: Any, params: Any, *, name: str = "learned",
                 field: Field = SKILLS_FIELD, episode_length: int = MATCH_CLOCK,
                 seed: int = 0, set_plays: str = "routine", reach: bool = False,
                 defer: bool = False, defer_to: str = "skills_naive") -> None:
        check_set_plays(set_plays)
        check_defer_to(defer, defer_to)
        self.set_plays = set_plays
        self.reach = reach
        self.defer = defer
        self.defer_to = defer_to
        self.deferring = np.zeros(0, bool)  # the last decided rows that deferred
        # What the team decided over its match (``report``): rows in open play, those of
        # them the policy deferred, and each final kind's rows (their sum: all rows).
        self.open_play = self.deferred = 0
        self.kinds = np.zeros(len(Kind), np.int64)
        self.guard = TakerGuard()
        self.policy = policy
        self.params = params
        self.name = name
        self.field = field
        self.episode_length = episode_length
        self.key = jax.random.key(seed)
        self.policy_calls = 0
        self.carry = policy.init_carry(PLAYERS)
        self._act = jax.jit(self._step)

    def reset(self) -> None:
        """Forget every player's memory (a new match)."""
        self.carry = self.policy.init_carry(PLAYERS)
        self.guard.reset()

    def _step(self, params: Any, carry: Any, obs: Observation, present: jax.Array,
              key: jax.Array) -> tuple[Any, tuple[jax.Array, jax.Array]]:
        new, actions = self.policy.act(params, carry, obs, key)
        deferring = jnp.zeros(actions.shape[:-1], bool)
        if self.defer:
            deferring = defers(actions)
            actions = deferred(actions, obs, SkillsNaiveTeam(field=self.field))

        def keep(fresh: jax.Array, old: jax.Array) -> jax.Array:
            asked = present.reshape(present.shape + (1,) * (fresh.ndim - 1))
            return jnp.where(asked, fresh, old)

        return jax.tree.map(keep, new, carry), (actions, deferring)

    def actions(self, obs: SkillObservation) -> tuple[np.ndarray, np.ndarray]:
        """(actions f32[m, 4], the observations' masks bool[m, 22]) for the rows of ``obs``,
        each player's memory carried on. One policy call for players of distinct shirt
        numbers; a batch holding a player twice (two cycles' requests) is decided in order,
        one call for each repeat."""
        view = sim_observation(obs, self.field, episode_length=self.episode_length,
                               reach=self.reach)
        out = np.zeros((len(obs.unum), SKILL_ACTION_SIZE), np.float32)
        self.deferring = np.zeros(len(obs.unum), bool)
        for rows, slot, fill, present in shirt_batches(obs.unum):
            padded = jax.tree.map(lambda leaf, fill=fill: leaf[fill], view)
            self.key, key = jax.random.split(self.key)
            self.carry, (acts, deferring) = self._act(self.params, self.carry, padded,
                                                      present, key)
            self.policy_calls += 1
            out[rows] = np.asarray(acts)[slot]
            self.deferring[rows] = np.asarray(deferring)[slot]
        return out, np.asarray(view.entity_mask)

    def decisions(self, obs: SkillObservation) -> Decisions:
        actions, seen = self.actions(obs)
        decisions = skill_decisions(obs, actions, seen, self.field, self.set_plays)
        open_play = np.isin(decisions.kind, list(OPEN_PLAY))
        if self.defer_to == "helios":
            decisions = helios_parts(decisions, obs.kickable, self.deferring)
        if self.set_plays == "decided":
            decisions, _ = self.guard.apply(obs, decisions)
        self.open_play += int(open_play.sum())
        self.deferred += int((open_play & self.deferring).sum())
        self.kinds += np.bincount(np.asarray(decisions.kind, np.int64), minlength=len(Kind))
        return decisions

    def report(self) -> dict[str, Any]:
        """What the team decided so far: rows, open-play rows, the open-play rows the policy
        deferred (with ``env.defer``), and the rows of each final kind by name."""
        kinds = {kind.name: int(self.kinds[kind]) for kind in Kind if self.kinds[kind]}
        return {"rows": int(self.kinds.sum()), "open_play": self.open_play,
                "deferred": self.deferred, "kinds": kinds}

    def __call__(self, states: Sequence[Any]) -> list[Any]:
        """The decision server's callable: the proxy's States of a cycle to PlayerActions."""
        obs = observe(states)
        return to_player_actions(self.decisions(obs), obs)

    def warm_up(self) -> None:
        """Compile the policy call (one shape for every batch) before a match; nobody's
        memory changes."""
        leaves: dict[str, Any] = dict(
            self_features=np.zeros((PLAYERS, self_feature_count(self.reach)), np.float32),
            entities=np.zeros((PLAYERS, _SLOTS, len(ENTITY_FEATURES)), np.float32),
            entity_mask=np.ones((PLAYERS, _SLOTS), bool),
        )
        view = Observation(**leaves)
        _, key = jax.random.split(self.key)
        _, out = self._act(self.params, self.carry, view, np.zeros(PLAYERS, bool), key)
        jax.block_until_ready(out)


def _trained_actions(spec: str) -> int | None:
    from elevens.runs.teams import trained_config

    config = trained_config(spec)
    return None if config is None else int(config.learner.network.actions)


def check_skills_team(spec: str, names: Sequence[str] = ("skills_naive",)) -> None:
    """ValueError in one line unless ``spec`` is a trained skills team (its config read, not
    its networks): a checkpoint or exported team of the 4-value skill action. ``names``: the
    scripted skills teams, for the message."""
    allowed = (f"allowed: {', '.join(names)}, or a checkpoint or exported team of elevens "
               f"train skills-2v2 / skills-11v11, whose action is the {SKILL_ACTION_SIZE}-value "
               "skill decision")
    try:
        actions = _trained_actions(spec)
    except FileNotFoundError as error:
        path = spec.rpartition("=")[2].rpartition("@")[0] or spec.rpartition("=")[2]
        why = str(error) if os.path.exists(path) else f"{path} does not exist"
        raise ValueError(f"skills team {spec!r} is unknown ({allowed}): {why}") from None
    if actions != SKILL_ACTION_SIZE:
        gives = "a handcrafted team" if actions is None else f"a team of {actions}-value actions"
        raise ValueError(f"team {spec!r} is not a skills team: it is {gives} ({allowed})")


def is_skills_team(spec: str) -> bool:
    """Whether ``spec`` names a trained skills team; False for anything else, a spec that
    does not load included (whoever loads it reports that)."""
    try:
        return _trained_actions(spec) == SKILL_ACTION_SIZE
    except (OSError, ValueError):
        return False


def trained_game(spec: str) -> tuple[bool, bool, str]:
    """What the trained skills team ``spec``'s config says its game is: whether it sees
    librcsc's intercept table (``env.reach_features``), whether it may defer (``env.defer``)
    and to whom in the server (``env.defer_to``); read once."""
    from elevens.runs.teams import trained_config

    config = trained_config(spec)
    if config is None:
        return False, False, "skills_naive"
    env = config.learner.env
    return (env.self_features == self_feature_count(True), env.kinds == DEFER + 1,
            getattr(env, "defer_to", "skills_naive"))


def check_defer_to(defer: bool, defer_to: str) -> None:
    """ValueError in one line unless ``defer_to`` is one of ``game.DEFER_TO``, and
    ``skills_naive`` for a team that does not defer."""
    from elevens.robocup.skills.game import DEFER_TO

    if defer_to not in DEFER_TO or (defer_to != "skills_naive" and not defer):
        raise ValueError(f"defer_to={defer_to!r} is invalid (allowed: {', '.join(DEFER_TO)}; "
                         "other than skills_naive only for a deferring team)")


def load_learned_skills(spec: str, *, deterministic: bool = True, warm: bool = True,
                        set_plays: str = "routine") -> LearnedSkills:
    """The runtime's ``decide`` for the trained skills team ``spec`` (a checkpoint path,
    ``PATH@ITERATION`` or an exported team folder): the mode of its action unless
    ``deterministic`` is False (then sampled), compiled before it returns when ``warm``; our
    set plays as ``set_plays`` says."""
    from elevens.runs.teams import load_team

    check_skills_team(spec)
    team = load_team(spec, deterministic=deterministic)
    team.check_size(PLAYERS, SKILL_ACTION_SIZE)
    reach, defer, defer_to = trained_game(spec)
    decide = LearnedSkills(team.policy, team.params, name=team.name, set_plays=set_plays,
                           reach=reach, defer=defer, defer_to=defer_to)
    if warm:
        decide.warm_up()
    return decide
