"""skills_naive's host path on varied States of the proxy (partial world models, every mode):
each row is decided as in any batch, which lets the decision server decide each request on
its own as it comes (``runtime.rowwise``), and the trimmed numpy path decides as the plain
one did."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from elevens.robocup.skills import naive
from elevens.robocup.skills.naive import skills_naive
from elevens.robocup.skills.observe import observe
from elevens.robocup.skills.runtime import is_rowwise
from elevens.robocup.skills.space import to_player_actions
from tests.robocup.fake_proxy import varied_cycle


def _cycles(count: int) -> list[list[Any]]:
    rng = np.random.default_rng(35)
    return [varied_cycle(rng, c + 1) for c in range(count)]


def test_each_row_is_decided_as_in_the_whole_batch_and_routines_skip_open_play() -> None:
    assert is_rowwise(skills_naive)
    rng = np.random.default_rng(7)
    kinds = set()
    for states in _cycles(40):
        whole = skills_naive(states)
        alone = [skills_naive([s])[0] for s in states]
        cut = int(rng.integers(1, len(states)))
        split = skills_naive(states[:cut]) + skills_naive(states[cut:])
        assert whole == alone == split
        obs = observe(states)  # the full decision, open play decided for every row
        assert whole == to_player_actions(naive.skills_naive_decisions(obs), obs)
        kinds |= {next(k for k, v in vars(a.actions[0]).items() if v is not None) for a in whole}
    # The scenes reach the with-ball skills, the set plays and the kick-off too.
    assert {"body_smart_kick", "body_dribble", "move", "helios_set_play", "helios_goalie",
            "body_intercept", "body_go_to_point"} <= kinds


def test_the_trimmed_norm_decides_as_numpy_s_norm(monkeypatch: pytest.MonkeyPatch) -> None:
    cycles = _cycles(40)
    trimmed = [naive.naive_choices(observe(states)) for states in cycles]

    def plain(v: Any, xp: Any = np, keepdims: bool = False) -> Any:
        return xp.linalg.norm(v, axis=-1, keepdims=keepdims)

    monkeypatch.setattr(naive, "_norm", plain)
    for states, fast in zip(cycles, trimmed, strict=True):
        for got, want in zip(fast, naive.naive_choices(observe(states)), strict=True):
            assert got.dtype == want.dtype
            np.testing.assert_array_equal(got, want)
