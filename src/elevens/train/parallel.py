"""Data-parallel training over every device of every process (docs/architecture.md, "Scale").

One program for any number of devices: the iteration is written for the whole batch of games,
as on one device, and ``jit`` over a one-axis ``("data",)`` mesh splits it. The games' arrays are
constrained to be sharded on their game axis (rollout, update batch, each minibatch), while
parameters, optimiser state, opponent state and the run's key are replicated. XLA then inserts
the collectives: the gradient of a minibatch is averaged over the devices that hold its games,
and every statistic a decision reads (the score behind the Polyak freeze, the shaping switch,
the league's win rates) is a mean over all games, the same on every device.

Random keys are drawn per game from the run's one key (``jax_threefry_partitionable``), so a
game has the same stream whichever device plays it, and N devices give the same update as one
device over the same games, to float tolerance (tests/test_parallel.py). A mesh of one device is
the same program; there the constraints are left out, so the one-device program is unchanged.

Several hosts: ``initialize_distributed`` wraps ``jax.distributed.initialize``; every process
runs the same host loop on the global mesh, plays its own devices' share of the games, and only
process 0 writes the run directory and evaluates (``is_lead``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

DATA_AXIS = "data"

PyTree = Any
Constrain = Callable[[PyTree], PyTree]


def data_mesh(devices: int = 0) -> Mesh:
    """A ``("data",)`` mesh over the first ``devices`` devices of every process (0: all)."""
    available = jax.devices()
    if devices < 0 or devices > len(available):
        raise ValueError(
            f"run.devices={devices} is invalid: give 0 (every device) or 1 to {len(available)}, "
            f"the devices this run sees ({_describe(available)})"
        )
    chosen = available if devices == 0 else available[:devices]
    return Mesh(np.array(chosen), (DATA_AXIS,))


def _describe(devices: list[Any]) -> str:
    kinds = sorted({device.platform for device in devices})
    processes = len({device.process_index for device in devices})
    return f"{len(devices)} {'/'.join(kinds)} device(s) in {processes} process(es)"


def check_divisible(what: str, count: int, mesh: Mesh, fix: str) -> None:
    """Raise a ValueError naming ``what`` if ``count`` games cannot split evenly over ``mesh``."""
    size = mesh.devices.size
    if count % size:
        raise ValueError(
            f"{what}={count} is invalid on {size} devices: each device plays an equal share, so "
            f"it must be a multiple of {size} ({fix})"
        )


def replicated(mesh: Mesh) -> NamedSharding:
    return NamedSharding(mesh, PartitionSpec())


def game_constraint(mesh: Mesh, game_axis: int = 0) -> Constrain:
    """``tree -> tree`` that shards every leaf's ``game_axis`` over the mesh (identity on one
    device). Used inside jit, on arrays whose ``game_axis`` is the games (or whole games)."""
    if mesh.devices.size == 1:
        return lambda tree: tree
    spec = PartitionSpec(*([None] * game_axis), DATA_AXIS)
    sharding = NamedSharding(mesh, spec)

    def constrain(tree: PyTree) -> PyTree:
        return jax.tree.map(lambda leaf: jax.lax.with_sharding_constraint(leaf, sharding), tree)

    return constrain


def jit_replicated(fn: Callable[..., Any], mesh: Mesh) -> Callable[..., Any]:
    """``jax.jit(fn)`` whose inputs and outputs are replicated on ``mesh`` (plain ``jax.jit`` on
    one device)."""
    if mesh.devices.size == 1:
        return jax.jit(fn)
    return jax.jit(fn, in_shardings=replicated(mesh), out_shardings=replicated(mesh))


def replicate(tree: PyTree, mesh: Mesh) -> PyTree:
    """Every leaf as a global array replicated on ``mesh`` (every process passes the same
    values, as after the same init or restore). A no-op on one device."""
    if mesh.devices.size == 1:
        return tree
    sharding = replicated(mesh)

    def place(leaf: Any) -> Any:
        if jax.dtypes.issubdtype(leaf.dtype, jax.dtypes.prng_key):
            impl = jax.random.key_impl(leaf)
            return jax.random.wrap_key_data(place(jax.random.key_data(leaf)), impl=impl)
        if isinstance(leaf, jax.Array) and leaf.sharding == sharding:
            return leaf
        # Each process supplies the (same) whole array; device_put cannot reach another
        # process's devices.
        data = np.asarray(leaf)
        return jax.make_array_from_callback(data.shape, sharding, lambda index: data[index])

    return jax.tree.map(place, tree)


def to_host(tree: PyTree) -> PyTree:
    """Replicated (or local) arrays as numpy, readable on every process."""
    return jax.tree.map(np.asarray, tree)


# --------------------------------------------------------------------------------------------
# Processes
# --------------------------------------------------------------------------------------------


def is_lead() -> bool:
    """Whether this process writes the run directory and evaluates (process 0)."""
    return jax.process_index() == 0


def agree_any(flag: bool) -> bool:
    """True on every process if ``flag`` is True on any (a stop decision all must take at the
    same iteration: a time budget, an interrupt). Free with one process."""
    if jax.process_count() == 1:
        return flag
    from jax.experimental import multihost_utils

    flags = multihost_utils.process_allgather(np.asarray([flag], np.int32))
    return bool(np.any(flags))


def barrier(name: str) -> None:
    """Wait until every process reaches ``name`` (no-op with one process)."""
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices(name)


def initialize_distributed(
    coordinator: str = "", num_processes: int = 0, process_id: int = -1
) -> None:
    """``jax.distributed.initialize``: with no arguments under SLURM or Open MPI (JAX reads the
    job from the environment), otherwise with all three. On CPU the collectives go over gloo."""
    given = [bool(coordinator), num_processes > 0, process_id >= 0]
    if any(given) and not all(given):
        raise ValueError(
            "--coordinator, --num-processes and --process-id go together (got "
            f"coordinator={coordinator!r}, num_processes={num_processes}, "
            f"process_id={process_id}); give all three, or none under SLURM or Open MPI"
        )
    if all(given) and not 0 <= process_id < num_processes:
        raise ValueError(
            f"--process-id={process_id} is invalid with --num-processes={num_processes}: it must "
            f"be in [0, {num_processes - 1}]"
        )
    if all(given) and ":" not in coordinator:
        raise ValueError(f"--coordinator={coordinator!r} is invalid: give HOST:PORT")
    # CPU devices of several processes talk over gloo (GPUs keep NCCL).
    jax.config.update("jax_cpu_collectives_implementation", "gloo")
    if all(given):
        jax.distributed.initialize(
            coordinator_address=coordinator, num_processes=num_processes, process_id=process_id
        )
    else:
        try:
            jax.distributed.initialize()
        except (ValueError, RuntimeError) as error:
            raise ValueError(
                f"--distributed found no SLURM or Open MPI job to read the processes from "
                f"(jax: {str(error).strip()}); outside such a job give --coordinator HOST:PORT "
                "--num-processes N --process-id I on every process"
            ) from error
