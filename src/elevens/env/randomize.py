"""Domain randomisation (thesis 7.4.5): each game draws its physics and geometry from ranges.

A draw gives every game its own ``EnvParams`` for a whole episode: the drawn fields uniform in
their ranges, the rest the base game's, every leaf with a leading ``[G]`` axis (``draw_games``).
The unrolls vmap the env over that axis (``game_axis``), so drawn games cost no recompile.
Training draws each iteration's games from a key folded out of the run's stream
(``TRAINING_DRAWS``); evaluation plays a fixed set of settings drawn from a seed in another
fold (``held_out_games``), which training never draws.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from elevens.env.params import EnvParams

RANDOMIZED = (
    "ball_friction", "kick_impulse", "move_speed", "turn_speed", "field_length", "field_width",
    "goal_width", "fov_half_angle", "observation_noise",
)
"""The EnvParams fields a randomised game draws, in the order of ``Randomize``'s ranges."""
TRAINING_DRAWS = 0x7261_6E64
"""Training draws an iteration's games from ``fold_in(iteration key, TRAINING_DRAWS)``."""
HELD_OUT_DRAWS = 0x6865_6C64
"""Held-out settings come from ``fold_in(key(seed), HELD_OUT_DRAWS)``: another fold than any
training draw, so the same integer seed does not give training's games."""
HELD_OUT_SETTINGS = 20
"""Settings of a held-out evaluation (``elevens tournament --randomize SEED``)."""


@dataclasses.dataclass(frozen=True)
class Randomize:
    """Ranges ``(low, high)`` each game draws its constants from, uniformly, for its whole
    episode (a range with low == high fixes the value). Each range is centred on SPEC.md's
    value and wide enough to change what works (a pass, a shot's range) without changing the
    game; the goal stays narrower than the narrowest field."""

    enabled: bool = False
    """Draw each game's constants from the ranges below (False: every game is ``env``'s)."""
    ball_friction: tuple[float, float] = (0.86, 0.94)
    """Ball velocity multiplier per step (SPEC.md 0.9); each end in [0, 1]."""
    kick_impulse: tuple[float, float] = (3.0, 5.0)
    """Velocity a leg kick adds (SPEC.md 4)."""
    move_speed: tuple[float, float] = (0.8, 1.2)
    """Player speed, metres per step at move = 1 (SPEC.md 1)."""
    turn_speed: tuple[float, float] = (0.3, 0.5)
    """Radians per step at rot = 1 (SPEC.md 0.4)."""
    field_length: tuple[float, float] = (85.0, 115.0)
    """Goal line to goal line, metres (SPEC.md 100)."""
    field_width: tuple[float, float] = (60.0, 80.0)
    """Side line to side line, metres (SPEC.md 70)."""
    goal_width: tuple[float, float] = (30.0, 50.0)
    """Goal mouth, metres (SPEC.md 40); its high end must not exceed field_width's low end."""
    fov_half_angle: tuple[float, float] = (1.2, 1.95)
    """View half angle, radians (SPEC.md pi/2); each end in (0, pi]."""
    observation_noise: tuple[float, float] = (0.0, 1.0)
    """Std of the error on where a player sees each object, metres per axis (SPEC.md 0)."""

    def __post_init__(self) -> None:
        # Checked when built (a flag, an override, a saved config), as EnvParams is.
        self.check()

    def ranges(self) -> dict[str, tuple[float, float]]:
        """``{field: (low, high)}`` in ``RANDOMIZED`` order."""
        return {name: getattr(self, name) for name in RANDOMIZED}

    def check(self, prefix: str = "env.randomize") -> None:
        """Raise ``ValueError`` naming the first bad range and what is allowed (pure Python,
        before anything compiles). Each end must be a value the game allows (EnvParams)."""
        if not isinstance(self.enabled, bool):
            raise ValueError(
                f"{prefix}.enabled={self.enabled!r} is invalid: it must be True or False"
            )
        for name, value in self.ranges().items():
            path = f"{prefix}.{name}"
            numbers = isinstance(value, tuple | list) and len(value) == 2 and all(
                isinstance(v, int | float) and not isinstance(v, bool) for v in value
            )
            if not numbers:
                raise ValueError(
                    f"{path}={value!r} is invalid: it must be two numbers (low, high)"
                )
            low, high = (float(v) for v in value)
            if not (math.isfinite(low) and math.isfinite(high)):
                raise ValueError(f"{path}={value!r} is invalid: both ends must be finite")
            if low > high:
                raise ValueError(f"{path}={value!r} is invalid: low must not exceed high")
            for end in (low, high):
                # The goal and the field are checked against each other below, not against
                # SPEC.md's other one.
                other = {"goal_width": "field_width", "field_width": "goal_width"}.get(name)
                values: dict[str, Any] = {name: end, **({other: end} if other else {})}
                try:
                    EnvParams(**values)
                except ValueError as error:
                    rule = str(error).partition("is invalid: ")[2]
                    raise ValueError(
                        f"{path}={value!r} is invalid: its end {end:g} is not allowed ({rule})"
                    ) from None
        goal_high, width_low = self.goal_width[1], self.field_width[0]
        if goal_high > width_low:
            raise ValueError(
                f"{prefix}.goal_width={self.goal_width!r} is invalid: its high end must not "
                f"exceed the low end of {prefix}.field_width={self.field_width!r}"
            )

    def noisy(self, base: EnvParams) -> bool:
        """Whether games drawn on ``base`` may see with noise (the unroll then draws it)."""
        if self.enabled:
            return float(self.observation_noise[1]) > 0
        return float(base.observation_noise) > 0


def draw_games(
    key: jax.Array, base: EnvParams, randomize: Randomize, num_games: int
) -> EnvParams:
    """``num_games`` games drawn on ``base``: every leaf ``[G]``, the ``RANDOMIZED`` fields
    uniform in ``randomize``'s ranges (one draw per game and field), the rest ``base``'s.
    Jittable; the same key gives the same games."""
    ranges = randomize.ranges()
    low = jnp.asarray([r[0] for r in ranges.values()], jnp.float32)
    high = jnp.asarray([r[1] for r in ranges.values()], jnp.float32)
    unit = jax.random.uniform(key, (num_games, len(ranges)))
    drawn = low + (high - low) * unit  # f32[G, F]
    games = jax.tree.map(lambda leaf: jnp.broadcast_to(jnp.asarray(leaf), (num_games,)), base)
    return dataclasses.replace(
        games, **{name: drawn[:, i] for i, name in enumerate(ranges)}
    )


def training_games(
    key: jax.Array, base: EnvParams, randomize: Randomize, num_games: int
) -> EnvParams:
    """An iteration's drawn games, from its rollout key (``TRAINING_DRAWS``)."""
    return draw_games(jax.random.fold_in(key, TRAINING_DRAWS), base, randomize, num_games)


def held_out_games(
    seed: int, base: EnvParams, randomize: Randomize | None = None,
    count: int = HELD_OUT_SETTINGS,
) -> EnvParams:
    """The ``count`` held-out settings of ``seed`` (leaves ``[count]``), drawn from
    ``randomize``'s ranges (default: ``Randomize()``'s) on ``base``."""
    if count < 1:
        raise ValueError(f"count={count!r} is invalid: it must be >= 1")
    ranges = randomize if randomize is not None else Randomize()
    ranges.check("randomize")
    key = jax.random.fold_in(jax.random.key(seed), HELD_OUT_DRAWS)
    return draw_games(key, base, ranges, count)


def tile_games(settings: EnvParams, num_games: int) -> EnvParams:
    """Per-game params for ``num_games`` games: game ``g`` plays setting ``g % count``."""
    count = setting_count(settings)
    index = np.arange(num_games) % count
    return jax.tree.map(lambda leaf: jnp.asarray(leaf)[index], settings)


def setting_count(params: EnvParams) -> int:
    """The leading ``[G]`` of per-game params (``game_axis`` 0)."""
    shape: tuple[int, ...] = np.shape(params.field_length)
    return int(shape[0])


def game_axis(params: EnvParams) -> int | None:
    """0 when ``params`` holds one game per entry of a leading axis (``draw_games``), None for
    one game shared by all: the ``in_axes`` of a vmap over games."""
    return 0 if any(np.ndim(leaf) > 0 for leaf in jax.tree.leaves(params)) else None


def game_slice(params: EnvParams, begin: int, end: int) -> EnvParams:
    """Games ``begin:end`` of per-game params."""
    return jax.tree.map(lambda leaf: leaf[begin:end], params)


def setting_rows(settings: EnvParams) -> list[dict[str, Any]]:
    """The drawn fields of each setting as plain numbers (for printing and JSON)."""
    values = {name: np.asarray(getattr(settings, name)).tolist() for name in RANDOMIZED}
    return [
        {name: round(float(values[name][i]), 4) for name in RANDOMIZED}
        for i in range(setting_count(settings))
    ]
