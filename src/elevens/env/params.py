"""EnvParams: every constant of the game (SPEC.md), frozen and validated.

Static structure (team size, spawn modes) is marked ``pytree_node=False``: changing it recompiles.
Every number is a pytree leaf, so changing it costs no recompile and params can even be vmapped.
"""

from __future__ import annotations

import math
from numbers import Real
from typing import Any

import numpy as np
from flax import struct

MAX_PLAYERS_PER_TEAM = 11
SPAWN_MODES = ("formation", "random")
BALL_SPAWN_MODES = ("centre", "random")
POSSESSION_MODES = ("touch", "near")

# The 11-a-side formation of team 0 (SPEC.md), in slot order: keeper, defenders, midfield, attack.
FORMATION_11 = (
    (-49.5, 0.0),
    (-33.0, -24.75),
    (-33.0, -8.25),
    (-33.0, 8.25),
    (-33.0, 24.75),
    (-22.0, -22.0),
    (-22.0, 0.0),
    (-22.0, 22.0),
    (-11.0, -22.0),
    (-11.0, 0.0),
    (-11.0, 22.0),
)

# Which slots of FORMATION_11 a team of n players uses. Every team of 2 or more has a keeper, so
# handcrafted roles (defenders = keeper and back line) exist at every size; the shapes stay
# symmetric in y wherever the slot list allows.
FORMATION_SUBSETS: dict[int, tuple[int, ...]] = {
    1: (9,),
    2: (0, 9),
    3: (0, 6, 9),
    4: (0, 2, 3, 9),
    5: (0, 2, 3, 6, 9),
    6: (0, 2, 3, 5, 7, 9),
    7: (0, 2, 3, 5, 6, 7, 9),
    8: (0, 1, 2, 3, 4, 6, 8, 10),
    9: (0, 1, 2, 3, 4, 6, 8, 9, 10),
    10: (0, 1, 2, 3, 4, 5, 7, 8, 9, 10),
    11: tuple(range(11)),
}


def formation(players_per_team: int) -> np.ndarray:
    """Formation slots of team 0 on the default 100 x 70 field, ``f64[n, 2]``.

    Team 1 uses their negation. On other field sizes the slots scale with the field.
    """
    return np.asarray([FORMATION_11[i] for i in FORMATION_SUBSETS[players_per_team]])


def _is_concrete_number(value: Any) -> bool:
    # Under jit/vmap the leaves are tracers or placeholders; only real numbers are validated.
    scalar_array = isinstance(value, np.ndarray) and value.ndim == 0
    return isinstance(value, Real | np.number) or scalar_array


@struct.dataclass
class EnvParams:
    """Rules and constants of the game. Defaults follow SPEC.md (thesis ch. 4, tables 6.1/6.2)."""

    # --- static structure (changing these recompiles) ---
    players_per_team: int = struct.field(pytree_node=False, default=11)
    """Players per team, 1..11."""
    spawn: str = struct.field(pytree_node=False, default="formation")
    """"formation": slot + noise; "random": uniform in own half, random heading (thesis 2 v 2)."""
    ball_spawn: str = struct.field(pytree_node=False, default="random")
    """"centre" or "random" (uniform over the central ball_spawn_fraction of the field)."""
    possession_by: str = struct.field(pytree_node=False, default="near")
    """Who has the ball for the possession reward (``reward.ball_holder``): "near", the team
    whose nearest player is within ``possession_radius`` and nearer than every opponent (the
    first definition, so older runs keep their meaning); "touch", the team that touched it
    last (``State.last_touch``), which a crowding team cannot win without the ball."""

    # --- field (metres) ---
    field_length: float = 100.0
    """Goal line to goal line; x in [-length/2, length/2]."""
    field_width: float = 70.0
    """Side line to side line; y in [-width/2, width/2]."""
    goal_width: float = 40.0
    """Goal mouth width, oversized on purpose (thesis fig. 4.1)."""

    # --- bodies ---
    player_radius: float = 1.0
    """Players are discs of this radius."""
    ball_radius: float = 1.0
    """The ball is a disc of this radius."""
    leg_reach: float = 3.0
    """Leg bar half length beyond the centre (reach to each side)."""

    # --- motion (per step) ---
    move_speed: float = 1.0
    """Distance per step at move = 1 (the published code moved twice: fixed)."""
    turn_speed: float = 0.4
    """Radians per step at rot = 1."""

    # --- ball contacts ---
    push_impulse: float = 0.6
    """Velocity added when the body touches the ball (dribble)."""
    kick_impulse: float = 4.0
    """Velocity added along the heading by a leg kick."""
    kick_band: float = 1.0
    """A kick needs the ball centre within this distance of the leg line."""
    ball_max_speed: float = 5.0
    """Ball speeds are capped at this (per step)."""
    ball_friction: float = 0.9
    """Velocity multiplier per step."""
    ball_stop_speed: float = 0.01
    """Speeds below this become 0."""
    wall_restitution: float = 0.6
    """Velocity multiplier on a bounce."""

    # --- view ---
    fov_half_angle: float = math.pi / 2
    """Visible if the direction to an object's centre is within this angle of the heading."""
    observation_noise: float = 0.0
    """Std (metres) of the Gaussian error on each axis of where a player sees every other
    object, drawn afresh each step (domain randomisation; 0: exact sight, SPEC.md's game).
    Needs a key: the unrolls (training and matches) observe through ``Soccer.observe_noisy``
    when it is above 0; ``Soccer.observe`` alone sees exactly."""

    # --- episodes and spawning ---
    episode_length: int = 400
    """Steps per episode (a truncation, not a termination)."""
    spawn_noise: float = 5.5
    """Uniform noise on each axis around the formation slot."""
    heading_noise: float = math.pi / 4
    """Uniform noise on the slot heading."""
    ball_spawn_fraction: float = 0.5
    """Random ball spawns are uniform over this fraction of the length and width, centred."""

    # --- rewards ---
    goal_reward: float = 1.0
    """Reward for a goal (its negative for the team that concedes)."""
    ball_shaping_weight: float = 0.1
    """w_b: weight of the ball's velocity towards the opponent goal (0 switches it off)."""
    approach_shaping_weight: float = 0.05
    """w_a: weight of the player's velocity towards the ball (0 switches it off)."""
    possession_shaping_weight: float = 0.0
    """w_p: weight of having the ball, each step: +w_p to every player of the team that has it
    (``possession_by``), -w_p to the other team's. Not in the thesis (0: off). By nearness a
    team that crowds the ball wins it without controlling it. The shaping schedule switches
    it off with the rest."""
    possession_radius: float = 2.0
    """With ``possession_by`` "near": a team has the ball when its nearest player is this near
    it and nearer than every opponent (metres)."""

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first impossible field. Tracer leaves are skipped."""
        n = self.players_per_team
        if not isinstance(n, int) or isinstance(n, bool) or not 1 <= n <= MAX_PLAYERS_PER_TEAM:
            raise ValueError(
                f"players_per_team={n!r} is invalid: it must be an integer from 1 to "
                f"{MAX_PLAYERS_PER_TEAM}"
            )
        if self.spawn not in SPAWN_MODES:
            raise ValueError(f"spawn={self.spawn!r} is invalid: allowed values are {SPAWN_MODES}")
        if self.possession_by not in POSSESSION_MODES:
            raise ValueError(
                f"possession_by={self.possession_by!r} is invalid: allowed values are "
                f"{POSSESSION_MODES}"
            )
        if self.ball_spawn not in BALL_SPAWN_MODES:
            raise ValueError(
                f"ball_spawn={self.ball_spawn!r} is invalid: allowed values are {BALL_SPAWN_MODES}"
            )
        positive = (
            "field_length", "field_width", "goal_width", "player_radius", "ball_radius",
            "move_speed", "turn_speed", "kick_band", "ball_max_speed", "fov_half_angle",
            "possession_radius",
        )
        non_negative = (
            "leg_reach", "push_impulse", "kick_impulse", "ball_stop_speed", "spawn_noise",
            "heading_noise", "goal_reward", "ball_shaping_weight", "approach_shaping_weight",
            "possession_shaping_weight", "observation_noise",
        )
        unit_interval = ("ball_friction", "wall_restitution", "ball_spawn_fraction")
        values = {name: getattr(self, name) for name in (*positive, *non_negative, *unit_interval)}
        for name, value in values.items():
            if not _is_concrete_number(value):
                continue
            if not math.isfinite(float(value)):
                raise ValueError(f"{name}={value!r} is invalid: it must be a finite number")
            if name in positive and not float(value) > 0:
                raise ValueError(f"{name}={value!r} is invalid: it must be > 0")
            if name in non_negative and float(value) < 0:
                raise ValueError(f"{name}={value!r} is invalid: it must be >= 0")
            if name in unit_interval and not 0 <= float(value) <= 1:
                raise ValueError(f"{name}={value!r} is invalid: it must be in [0, 1]")
        if _is_concrete_number(self.fov_half_angle) and float(self.fov_half_angle) > math.pi:
            raise ValueError(
                f"fov_half_angle={self.fov_half_angle!r} is invalid: it must be in (0, pi]"
            )
        if (
            _is_concrete_number(self.goal_width)
            and _is_concrete_number(self.field_width)
            and float(self.goal_width) > float(self.field_width)
        ):
            raise ValueError(
                f"goal_width={self.goal_width!r} is invalid: it must not exceed "
                f"field_width={self.field_width!r}"
            )
        if _is_concrete_number(self.episode_length) and (
            int(self.episode_length) != self.episode_length or int(self.episode_length) < 1
        ):
            raise ValueError(
                f"episode_length={self.episode_length!r} is invalid: it must be an integer >= 1"
            )

    @property
    def half_length(self) -> Any:
        return self.field_length / 2

    @property
    def half_width(self) -> Any:
        return self.field_width / 2

    @property
    def num_players(self) -> int:
        """Players on the field, both teams."""
        return 2 * self.players_per_team
