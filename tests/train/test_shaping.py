"""The shaping schedule: off only after more than 75% scoring games in a full window, for good."""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

import elevens
from elevens.env import EnvParams
from elevens.train.shaping import (
    ShapingState,
    shaping_init,
    shaping_scoring_rate,
    shaping_update,
    shaping_weights,
)

update = jax.jit(shaping_update)


def test_switches_off_only_above_75_percent_of_a_full_window() -> None:
    state = shaping_init(window=4)
    state = update(state, jnp.array([True, True, True]))
    assert bool(state.active)  # 3 of 3 scored, but the window of 4 is not full yet
    state = update(state, jnp.array([False]))
    np.testing.assert_allclose(shaping_scoring_rate(state), 0.75)
    assert bool(state.active)  # exactly 75% is not "more than 75%"
    state = update(state, jnp.array([True]))  # ring: T T T F -> T T T F with slot 0 rewritten
    assert bool(state.active)
    state = update(state, jnp.array([True, True]))  # slots 1, 2 rewritten; the F at 3 stays
    np.testing.assert_allclose(shaping_scoring_rate(state), 0.75)
    assert bool(state.active)
    state = update(state, jnp.array([True]))  # slot 3's F is overwritten: 4 of 4
    np.testing.assert_allclose(shaping_scoring_rate(state), 1.0)
    assert not bool(state.active)
    assert int(state.count) == 8


def test_never_comes_back_on() -> None:
    state = update(shaping_init(window=4), jnp.ones(4, bool))
    assert not bool(state.active)
    for _ in range(3):
        state = update(state, jnp.zeros(4, bool))
    np.testing.assert_allclose(shaping_scoring_rate(state), 0.0)
    assert not bool(state.active)
    weights = shaping_weights(state, 0.1, 0.05)
    assert float(weights.ball) == 0.0 and float(weights.approach) == 0.0


def test_default_window_of_100_games() -> None:
    state = shaping_init()
    assert state.window == 100
    flags_75 = np.arange(100) < 75
    assert bool(update(state, flags_75).active)  # 75 of 100
    flags_76 = np.arange(100) < 76
    assert not bool(update(state, flags_76).active)  # 76 of 100
    # a batch longer than the window keeps only its last 100 games: 50 misses then 76 of 100
    long_batch = np.concatenate([np.zeros(50, bool), flags_76])
    assert not bool(update(state, long_batch).active)
    long_batch = np.concatenate([np.ones(50, bool), flags_75])
    assert bool(update(state, long_batch).active)


def test_mask_ignores_games() -> None:
    state = shaping_init(window=4)
    flags = jnp.array([True, True, True, True, False, False])
    mask = jnp.array([True, True, True, True, False, False])
    state = update(state, flags, 0.75, mask)
    assert int(state.count) == 4 and not bool(state.active)


def test_weights_go_into_env_params() -> None:
    state = shaping_init(window=4)
    weights = shaping_weights(state, 0.1, 0.05)
    np.testing.assert_allclose([weights.ball, weights.approach], [0.1, 0.05])
    _, params = elevens.make("1v1")

    @jax.jit
    def switch(params: EnvParams, state: ShapingState) -> EnvParams:
        # what a trainer does inside its compiled iteration (EnvParams annotates floats)
        w = shaping_weights(state, params.ball_shaping_weight, params.approach_shaping_weight)
        return dataclasses.replace(
            params,
            ball_shaping_weight=w.ball,  # type: ignore[arg-type]
            approach_shaping_weight=w.approach,  # type: ignore[arg-type]
        )

    still_on = switch(params, state)
    np.testing.assert_allclose(float(still_on.ball_shaping_weight), 0.1, rtol=1e-6)
    off = switch(params, update(state, jnp.ones(4, bool)))
    assert float(off.ball_shaping_weight) == 0.0 and float(off.approach_shaping_weight) == 0.0
