"""`elevens bench train`: training env steps per second, and where the time goes.

For each team size the thesis network (table 6.2) trains with table 6.1's PPO numbers (5 epochs,
minibatches of about 60 player sequences in whole games, 55 for 11 a side; a batch of 660
sequences: 660 / n games). One "env step" is
one step of one game with all 2n players acting, as in `elevens bench env`; the figure is env
steps of one whole iteration (both teams' rollout, the critic, advantages, the 5 epochs and the
opponent update) divided by the iteration's wall time, the median over repeats. Compilation is
timed separately (the first call).

Where the time goes is measured on the same data with separately compiled functions:

* env: the rollout's env alone (observe + transition, random actions; ``bench.env``'s runner);
* forward: the rollout with both teams' networks (``Trainer.collect``) minus the env;
* update: advantages and the PPO epochs alone (``Trainer.learn``) on a recorded rollout.

Shares are those times over the full iteration's; they need not sum to exactly 1 (the full
iteration fuses the parts, and the opponent and shaping updates are not in any part).

The same run times a host reference (``host_reference``): the two products of a per-entity
64 x 64 layer on one 11 v 11 minibatch's compact rows (forward, and the weight gradient, which
contracts the 75,776 rows) and a memory-bound pass (a sum over 64 MB). The update is bound by these,
not by peak FLOPs, so they say how fast this machine is at what the update does; figures from
different machines compare only beside them (docs/results/throughput.md).
"""

from __future__ import annotations

import dataclasses
import json as json_lib
import math
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from typing import Any

import jax
import jax.numpy as jnp

from elevens.bench.env import make_scan_runner, reset_games
from elevens.train.config import make_config


@dataclass(frozen=True)
class TrainBenchResult:
    players: int
    """Players per team."""
    games: int
    """Games per iteration (660 / players: table 6.1's batch of 660 sequences)."""
    episode_length: int
    """Steps per episode (= per iteration and game)."""
    epochs: int
    minibatch_size: int
    steps_per_s: float
    """Env steps of a full training iteration per second (median over repeats)."""
    iteration_s: float
    """Median wall time of one iteration."""
    env_s: float
    """Median time of the env alone over the same games and steps (random actions)."""
    rollout_s: float
    """Median time of the rollout with both teams' networks."""
    update_s: float
    """Median time of advantages + PPO epochs alone."""
    env_share: float
    forward_share: float
    update_share: float
    compile_s: float
    """First call of the full iteration (trace, compile, one run)."""
    repeats: int
    backend: str
    host_matmul_gflops: float = float("nan")
    """Host reference: f32 [75,776 x 64] x [64 x 64] (a per-entity layer's forward)."""
    host_weight_gradient_gflops: float = float("nan")
    """Host reference: f32 [64 x 75,776] x [75,776 x 64] (that layer's weight gradient)."""
    host_stream_gbps: float = float("nan")
    """Host reference: bytes read per second by a sum over a 64 MB array."""
    devices: int = 1
    """Devices the games were split over (``run.devices``)."""
    steps_per_s_per_device: float = float("nan")
    """``steps_per_s / devices``."""
    scaling_efficiency: float = float("nan")
    """Steps per second per device against the first device count of the same run (1.0 =
    linear scaling); NaN for that first count."""


REFERENCE_ROWS = 75_776
"""Compact per-entity rows of one 11 v 11 minibatch (55 sequences x 100 steps)."""


@dataclass(frozen=True)
class HostReference:
    matmul_gflops: float
    weight_gradient_gflops: float
    stream_gbps: float


def host_reference(rows: int = REFERENCE_ROWS, repeats: int = 20) -> HostReference:
    """Medians over ``repeats`` of the reference computations (see the module doc)."""
    width = 64
    keys = jax.random.split(jax.random.key(0), 3)
    x = jax.random.normal(keys[0], (rows, width))
    grad = jax.random.normal(keys[1], (rows, width))
    kernel = jax.random.normal(keys[2], (width, width))
    stream = jnp.ones((16 * 1024 * 1024,), jnp.float32)  # 64 MB: beyond any cache
    flops = 2.0 * rows * width * width
    _, forward_s = _median_time(lambda: _forward(x, kernel), repeats)
    _, gradient_s = _median_time(lambda: _weight_gradient(x, grad), repeats)
    _, stream_s = _median_time(lambda: _stream(stream), repeats)
    return HostReference(
        matmul_gflops=flops / forward_s / 1e9,
        weight_gradient_gflops=flops / gradient_s / 1e9,
        stream_gbps=stream.nbytes / stream_s / 1e9,
    )


@jax.jit
def _forward(x: jax.Array, kernel: jax.Array) -> jax.Array:
    return x @ kernel


@jax.jit
def _weight_gradient(x: jax.Array, grad: jax.Array) -> jax.Array:
    return x.T @ grad


@jax.jit
def _stream(x: jax.Array) -> jax.Array:
    # A reduction: a new 64 MB output each call would time the page faults, not the memory.
    return jnp.sum(x)


def _median_time(run: Callable[[], Any], repeats: int) -> tuple[float, float]:
    """(first call's seconds, median seconds of ``repeats`` later calls)."""
    start = time.perf_counter()
    jax.block_until_ready(run())
    first = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run())
        times.append(time.perf_counter() - start)
    return first, statistics.median(times)


def bench_train(
    players: int, episode_length: int = 100, repeats: int = 3, games: int | None = None,
    devices: int = 1, minibatch_games_multiple: int = 1, parts: bool = True,
    minibatch_size: int | None = None,
) -> TrainBenchResult:
    """Time one training iteration of ``players`` a side and its parts (see the module doc).
    With ``devices`` > 1 the games split over that many devices; then, or without ``parts``,
    only the whole iteration is timed (the parts are NaN)."""
    from elevens.train.learner import make_learner

    games = max(1, 660 // players) if games is None else games
    units = games * players
    # Table 6.1's 60 sequences, rounded to whole games that divide the batch (55 for 11 a side),
    # in multiples of minibatch_games_multiple games (each device takes an equal share).
    step = players * minibatch_games_multiple
    fits = [m for m in range(step, units + 1, step) if units % m == 0]
    if not fits:
        raise ValueError(
            f"--games={games} is invalid with devices {minibatch_games_multiple}: the games of "
            f"an iteration must split into minibatches of a multiple of "
            f"{minibatch_games_multiple} games"
        )
    minibatch = min(fits, key=lambda m: abs(m - 60))
    if minibatch_size is not None:
        if minibatch_size not in fits:
            raise ValueError(
                f"--minibatch-size={minibatch_size} is invalid with {games} games of {players} "
                f"players: it must divide the batch of {units} sequences in whole games, a "
                f"multiple of {step} (e.g. {fits[len(fits) // 2]})"
            )
        minibatch = minibatch_size
    config = make_config(
        "11v11" if players == 11 else "2v2",
        **{
            "env.players_per_team": players,
            "env.episode_length": episode_length,
            "games_per_iteration": games,
            "iterations_per_chunk": 1,
            "ppo.minibatch_size": minibatch,
        },
    )
    trainer = make_learner(config.learner, config.learner.make_env(), devices=devices)
    state = trainer.init(jax.random.key(0))

    def full() -> Any:
        nonlocal state
        state, metrics = trainer.update_chunk(state)
        return metrics

    compile_s, iteration_s = _median_time(full, repeats)
    nan = float("nan")
    whole = TrainBenchResult(
        players=players,
        games=games,
        episode_length=episode_length,
        epochs=config.learner.ppo.epochs,
        minibatch_size=minibatch,
        steps_per_s=games * episode_length / iteration_s,
        iteration_s=iteration_s,
        env_s=nan,
        rollout_s=nan,
        update_s=nan,
        env_share=nan,
        forward_share=nan,
        update_share=nan,
        compile_s=compile_s,
        repeats=repeats,
        backend=jax.default_backend(),
        devices=devices,
        steps_per_s_per_device=games * episode_length / iteration_s / devices,
    )
    if devices > 1 or not parts:
        return whole

    collect = jax.jit(trainer.collect)
    learn = jax.jit(trainer.learn)
    rollout_key, shuffle_key = jax.random.split(jax.random.key(1))
    _, rollout_s = _median_time(lambda: collect(state, rollout_key), repeats)
    data = collect(state, rollout_key)
    _, update_s = _median_time(
        lambda: learn(state.params, state.opt_state, data, shuffle_key), repeats
    )

    env, params = trainer.env, trainer.env_params
    runner = make_scan_runner(env, params, games, episode_length)
    states = reset_games(env, params, jax.random.key(2), games)
    _, env_s = _median_time(lambda: runner(states, jax.random.key(3)), repeats)
    reference = host_reference()

    return dataclasses.replace(
        whole,
        env_s=env_s,
        rollout_s=rollout_s,
        update_s=update_s,
        env_share=env_s / iteration_s,
        forward_share=max(rollout_s - env_s, 0.0) / iteration_s,
        update_share=update_s / iteration_s,
        host_matmul_gflops=reference.matmul_gflops,
        host_weight_gradient_gflops=reference.weight_gradient_gflops,
        host_stream_gbps=reference.stream_gbps,
    )


def run_train_bench(
    players: Sequence[int] = (2, 11),
    json: bool = False,
    episode_length: int = 100,
    repeats: int = 3,
    print_fn: Callable[[str], None] = print,
    devices: Sequence[int] = (),
    games: int | None = None,
    parts: bool = True,
    minibatch_size: int | None = None,
) -> list[TrainBenchResult]:
    """Bench each team size; print a line (or, with ``json``, one JSON object) per size.

    The JSON objects hold ``players``, ``steps_per_s``, ``env_share``, ``forward_share`` and
    ``update_share``, with the other fields of ``TrainBenchResult``. ``devices``: train each
    size on each of these device counts in turn (the same games and minibatches), and report
    the scaling efficiency against the first. ``games``: games per iteration (None: 660 / n).
    ``parts``: also time the iteration's parts (see the module doc).
    """
    available = jax.device_count()
    for count in devices:
        if not 1 <= count <= available:
            raise ValueError(
                f"--devices={count} is invalid: this process sees {available} device(s) "
                f"({jax.default_backend()}); on a CPU, XLA_FLAGS="
                "--xla_force_host_platform_device_count=N gives N host devices"
            )
    multiple = math.lcm(*devices) if devices else 1
    results = []
    for n in players:
        baseline: TrainBenchResult | None = None
        for count in devices or (1,):
            result = bench_train(
                n, episode_length=episode_length, repeats=repeats, games=games,
                devices=count, minibatch_games_multiple=multiple, parts=parts,
                minibatch_size=minibatch_size,
            )
            if baseline is None:
                baseline = result
            else:
                result = dataclasses.replace(
                    result,
                    scaling_efficiency=result.steps_per_s_per_device
                    / baseline.steps_per_s_per_device,
                )
            results.append(result)
            _print_result(result, json, print_fn)
    return results


def _print_result(
    result: TrainBenchResult, json: bool, print_fn: Callable[[str], None]
) -> None:
    n = result.players
    if json:
        print_fn(json_lib.dumps(asdict(result)))
    elif result.devices > 1 or math.isnan(result.env_share):
        scaling = (
            "" if math.isnan(result.scaling_efficiency)
            else f", scaling efficiency {result.scaling_efficiency:.2f}"
        )
        print_fn(
            f"{n:>2}v{n:<2} train on {result.devices} device(s): {result.steps_per_s:>9,.0f} "
            f"env steps/s, {result.steps_per_s_per_device:,.0f} per device{scaling} "
            f"({result.games} games x {result.episode_length} steps in "
            f"{result.iteration_s:.2f} s; compile {result.compile_s:.1f} s)"
        )
    else:
        print_fn(
            f"{n:>2}v{n:<2} train: {result.steps_per_s:>9,.0f} env steps/s "
            f"({result.games} games x {result.episode_length} steps in "
            f"{result.iteration_s:.2f} s, {result.epochs} epochs; compile "
            f"{result.compile_s:.1f} s) | env {result.env_share:.1%}, forward "
            f"{result.forward_share:.1%}, update {result.update_share:.1%} | host: "
            f"matmul {result.host_matmul_gflops:.0f} GFLOP/s, weight gradient "
            f"{result.host_weight_gradient_gflops:.0f} GFLOP/s, stream "
            f"{result.host_stream_gbps:.0f} GB/s"
        )
