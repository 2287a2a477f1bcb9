"""Sizes bounded by what they cost: a lower bound on the memory a size asks for, checked
against the memory there is, before anything compiles or runs.

Each estimate traces one game's reset (``jax.eval_shape``: nothing compiles, nothing is
allocated) and counts what the work must hold at once at the least, so a size refused here
would not have run; a size allowed may still be too large (XLA needs more than the bound).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any

import jax

from elevens.env.params import EnvParams
from elevens.env.soccer import Soccer


def available_memory_bytes() -> int | None:
    """Memory the work may fill: the accelerator's limit, or the host's MemAvailable (None when
    neither can be read)."""
    stats = jax.devices()[0].memory_stats() if jax.default_backend() != "cpu" else None
    if stats and "bytes_limit" in stats:
        return int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


@functools.lru_cache(maxsize=16)
def game_bytes(players_per_team: int) -> tuple[int, int]:
    """(state, every player's observation) of one game of ``players_per_team`` a side, bytes."""
    env = Soccer(players_per_team)
    params = EnvParams(players_per_team=players_per_team)
    state, observation = jax.eval_shape(lambda: env.reset(jax.random.key(0), params))
    return _bytes(state), _bytes(observation)


def check_fits(
    flag: str, value: int, needed: int, what: str, available: int | None = None
) -> None:
    """Raise ``ValueError`` naming ``flag``, the estimate and the limit when ``needed`` bytes
    (``what`` they hold) exceed the available memory."""
    available = available_memory_bytes() if available is None else available
    if available is not None and needed > available:
        raise ValueError(
            f"{flag}={value} needs about {gb(needed)} ({what}), more than the {gb(available)} "
            "of memory available"
        )


def rollout_bytes(players_per_team: int, games: int, steps: int) -> int:
    """A training iteration's rollout: every step of every game keeps the learner's players'
    observations and the game's state (the critic's input is built from it)."""
    state, observation = game_bytes(players_per_team)
    return games * steps * (observation // 2 + state)


def replay_bytes(players_per_team: int, steps: int) -> int:
    """A recorded game: its state at every step."""
    return steps * game_bytes(players_per_team)[0]


def batch_bytes(players_per_team: int, games: int) -> int:
    """Games played at once: each game's state (in and out of a step) and observation."""
    state, observation = game_bytes(players_per_team)
    return games * (2 * state + observation)


def _bytes(tree: Any) -> int:
    return sum(leaf.size * leaf.dtype.itemsize for leaf in jax.tree.leaves(tree))


def gb(size: float) -> str:
    """Bytes as GB (kB when small)."""
    return f"{size / 1e9:.3g} GB" if size >= 1e6 else f"{size / 1e3:.3g} kB"
