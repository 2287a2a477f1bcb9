"""Bit-identical training across a refactor: dump 3 iterations from ``key(0)`` at each commit,
then compare.

    PYTHONPATH=OLD/src python scripts/bit_identical.py dump OUT_OLD [CONFIG ...]
    PYTHONPATH=NEW/src python scripts/bit_identical.py dump OUT_NEW [CONFIG ...]
    python scripts/bit_identical.py compare OUT_OLD OUT_NEW

Each configuration's learner (each game size of a mixed run) runs one chunk of 3 iterations
from ``jax.random.key(0)``; every leaf of (params, opponent, opt_state) and every metric is saved
and compared with ``np.array_equal``. docs/results/training_core.md has the figures.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np

SERVER_FIELD = {"env.field_length": 105.0, "env.field_width": 68.0, "env.goal_width": 14.02,
                "env.ball_friction": 0.94, "env.ball_max_speed": 3.0}
CONFIGS: dict[str, tuple[str, dict[str, Any]]] = {
    "quickstart": ("quickstart", {}),
    "2v2": ("2v2", {}),
    "11v11": ("11v11", {}),
    "mix": ("11v11", {"env.mix": ("2v2",), "env.mix_shares": (0.5,), "games_per_iteration": 16,
                      "ppo.minibatch_size": 44}),
    "oppmix": ("2v2", {"opponent.mix": ("self=0.8", "naive=0.2")}),
    # The 2v2 game with the server's bodies (the RoboCup wing's; env.physics rcss before it).
    "rcss": ("2v2", {**SERVER_FIELD, "env.stamina": True, "env.goalie": True,
                     "env.see_period": 3, "opponent.mix": ("self=0.8", "rcss_naive=0.2"),
                     "run.eval_teams": ("rcss_naive",), "run.write_gif": False}),
}


def config_of(name: str) -> Any:
    from elevens.train.config import apply_overrides, make_config

    preset, overrides = CONFIGS[name]
    overrides = {**overrides, "iterations_per_chunk": 3}
    if name != "rcss":
        return make_config(preset, **overrides)
    try:  # the wing's game
        from elevens.robocup.sim import rcss_game
    except ImportError:  # before the wing: a field of the core's config
        return make_config(preset, **overrides, **{"env.physics": "rcss", "network.actions": 12})
    return apply_overrides(rcss_game(make_config(preset), server_field=False), overrides).validate()


def dump(out: Path, names: list[str]) -> None:
    import jax

    from elevens.runs.loop import game_configs
    from elevens.runs.teams import team_on_field
    from elevens.train.learner import make_learner

    out.mkdir(parents=True, exist_ok=True)
    for name in names:
        for game, learner_config in game_configs(config_of(name).learner).items():
            learner = make_learner(learner_config, learner_config.make_env(), team_on_field)
            state, metrics = learner.update_chunk(learner.init(jax.random.key(0)))
            leaves = jax.tree.leaves((state.params, state.opponent, state.opt_state))
            arrays = {f"s{i}": np.asarray(leaf) for i, leaf in enumerate(leaves)}
            arrays.update({f"m_{k}": np.asarray(v) for k, v in metrics.items()})
            np.savez(out / f"{name}_{game}.npz", **arrays)
            print(name, game, len(arrays), "arrays", flush=True)


def compare(old: Path, new: Path) -> bool:
    same_all = True
    for path in sorted(new.glob("*.npz")):
        a, b = np.load(old / path.name), np.load(path)
        keys = sorted(a.files)
        same = keys == sorted(b.files) and all(
            a[k].dtype == b[k].dtype and np.array_equal(a[k], b[k], equal_nan=True) for k in keys
        )
        same_all &= same
        print(f"{path.stem}: {len(keys)} arrays, {'bit-identical' if same else 'DIFFERENT'}")
    return same_all


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "dump":
        dump(Path(sys.argv[2]), sys.argv[3:] or list(CONFIGS))
    elif len(sys.argv) == 4 and sys.argv[1] == "compare":
        sys.exit(0 if compare(Path(sys.argv[2]), Path(sys.argv[3])) else 1)
    else:
        sys.exit(__doc__)
