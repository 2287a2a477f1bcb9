"""Run by tests/train/test_parallel.py in subprocesses (not collected by pytest).

``python -m tests.train.parallel_worker devices OUT``: with 2 host devices, one update chunk of
the same config on 1 and on 2 devices; writes both runs' parameters and metrics to OUT (.npz).

``python -m tests.train.parallel_worker process OUT RUN_DIR COORDINATOR PROCESS_ID``: one of two
processes of a loopback ``jax.distributed`` run of ``train``; writes the final parameters and
every file this process wrote or made under RUN_DIR (from Python's audit hooks) to OUT (.npz).
"""

from __future__ import annotations

import os
import sys

# Before JAX starts: two CPU devices for the "devices" mode, one for each process otherwise.
# The "devices" mode compiles two chunks that then run for milliseconds: LLVM at -O0 compiles
# them in about two thirds of the time (both at the same level, so they compare alike).
if __name__ == "__main__" and sys.argv[1] == "devices":
    _flags = [
        flag for flag in os.environ.get("XLA_FLAGS", "").split()
        if not flag.startswith("--xla_backend_optimization_level")
    ]
    _flags += ["--xla_backend_optimization_level=0", "--xla_force_host_platform_device_count=2"]
    os.environ["XLA_FLAGS"] = " ".join(_flags)

import jax
import numpy as np

from elevens.train.config import TrainConfig, make_config

TINY = {
    "env.players_per_team": 1,
    "env.episode_length": 16,
    "env.field_length": 30.0,
    "env.field_width": 21.0,
    "env.goal_width": 14.0,
    "network.features": 16,
    "network.num_heads": 2,
    "network.lstm_features": 8,
    "network.lstm_layers": 1,
    "games_per_iteration": 8,
    "ppo.minibatch_size": 4,  # 2 minibatches of 4 games: 2 games a device
    "ppo.epochs": 2,
    "ppo.learning_rate": 3e-3,
    "iterations_per_chunk": 1,
}


def flat(tree: object, prefix: str) -> dict[str, np.ndarray]:
    leaves = jax.tree_util.tree_leaves_with_path(tree)
    return {prefix + jax.tree_util.keystr(path): np.asarray(leaf) for path, leaf in leaves}


def devices_mode(out: str) -> None:
    from elevens.train.learner import make_learner

    arrays: dict[str, np.ndarray] = {}
    config = make_config("quickstart", **TINY).learner
    for devices in (1, 2):
        trainer = make_learner(config, config.make_env(), devices=devices)
        state = trainer.init(jax.random.key(0))
        state, metrics = trainer.update_chunk(state)
        arrays.update(flat(state.params, f"{devices}/params"))
        arrays.update(flat(state.opponent.polyak, f"{devices}/opponent"))
        arrays.update({f"{devices}/metrics/{k}": np.asarray(v) for k, v in metrics.items()})
        arrays[f"{devices}/shards"] = np.asarray(len(trainer.mesh.devices.flat))
    np.savez(out, **arrays)


def process_config(run_dir: str) -> TrainConfig:
    return make_config(
        "quickstart",
        **TINY,
        **{
            "run.iterations": 2,
            "run.checkpoint_every": 1,
            "run.eval_every": 0,
            "run.eval_games": 2,
            "run.eval_teams": ("random",),
            "run.write_gif": False,
            "run.run_dir": run_dir,
        },
    )


def process_mode(out: str, run_dir: str, coordinator: str, process_id: int) -> None:
    written: list[str] = []
    root = os.path.abspath(run_dir)

    def audit(event: str, args: tuple) -> None:  # what this process writes under run_dir
        if event == "open" and args[0] is not None and not isinstance(args[0], int):
            mode, flags = args[1], args[2]
            writes = (mode and any(c in mode for c in "wax+")) or (
                flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT)
            )
            if writes and os.path.abspath(os.fspath(args[0])).startswith(root):
                written.append(os.fspath(args[0]))
        elif event in ("os.mkdir", "os.rename", "os.remove", "os.rmdir", "shutil.move") and (
            os.path.abspath(os.fspath(args[0])).startswith(root)
        ):
            written.append(f"{event} {args[0]}")

    from elevens.train.parallel import initialize_distributed

    initialize_distributed(coordinator, 2, process_id)
    from elevens.runs.loop import train

    config = process_config(run_dir)
    sys.addaudithook(audit)
    result = train(config, progress=False)
    arrays = flat(result.state.params, "params")
    arrays["iteration"] = np.asarray(result.iteration)
    arrays["devices"] = np.asarray(jax.device_count())
    arrays["written"] = np.asarray(written if written else [""])
    np.savez(out, **arrays)


if __name__ == "__main__":
    if sys.argv[1] == "devices":
        devices_mode(sys.argv[2])
    else:
        process_mode(sys.argv[2], sys.argv[3], sys.argv[4], int(sys.argv[5]))
