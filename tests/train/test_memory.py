"""runs.memory: sizes refused by a lower bound of what they hold, against a given limit."""

from __future__ import annotations

import pytest

from elevens.runs.memory import batch_bytes, check_fits, game_bytes, replay_bytes, rollout_bytes


def test_the_estimates_grow_with_what_they_hold() -> None:
    state, observation = game_bytes(2)
    assert state > 0 and observation > 0
    assert game_bytes(11)[0] > state and game_bytes(11)[1] > observation
    assert rollout_bytes(2, 10, 100) == 10 * 100 * (observation // 2 + state)
    assert replay_bytes(2, 400) == 400 * state
    assert batch_bytes(2, 64) == 64 * (2 * state + observation)


def test_a_size_over_the_limit_is_one_line_naming_it() -> None:
    needed = rollout_bytes(11, 330, 400)
    check_fits("games_per_iteration", 330, needed, "a rollout", available=needed)  # fits
    with pytest.raises(ValueError) as error:
        check_fits("games_per_iteration", 330, needed, "a rollout", available=needed - 1)
    message = str(error.value)
    assert message.startswith("games_per_iteration=330 needs about ") and "\n" not in message
    assert "(a rollout), more than the " in message and "of memory available" in message
