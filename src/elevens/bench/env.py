"""`elevens bench env`: env steps per second with random actions.

Two modes are timed in the same process, so their ratio is meaningful on a noisy machine:
- ``scan``: a batch of games vmapped inside one compiled ``lax.scan`` (how the trainer runs it);
- ``loop``: a Python loop calling a jitted single-game ``env.step`` (what a naive user writes).
A "step" is one step of one game (all 2n players act). Compile time is reported separately, and
the figure is the median over repeats.

``run_games_bench`` times several games (any env with the simulator's reset/step contract, e.g.
the games registered above the core) in scan mode side by side: their repeats interleaved, so a
load that comes and goes weighs on each alike, and each game's rate over the first's.
"""

from __future__ import annotations

import functools
import json
import statistics
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

import elevens
from elevens.env import EnvParams, Soccer, State
from elevens.runs.memory import available_memory_bytes, gb


@dataclass(frozen=True)
class EnvBenchResult:
    players: int
    """Players per team."""
    batch: int
    """Games stepped together (1 for the Python loop)."""
    mode: str
    """"scan" or "loop"."""
    steps_per_s: float
    """Median game steps per second over the repeats."""
    compile_s: float
    """Time of the first call (tracing + compilation + one run)."""
    repeats: int
    devices: int
    """Devices the batch was sharded over."""
    backend: str
    ratio_to_loop: float | None = None
    """scan only: steps/s over the Python loop's, measured in the same run."""


def _timed(run: Callable[[], Any], repeats: int) -> tuple[float, list[float]]:
    start = time.perf_counter()
    jax.block_until_ready(run())
    compile_s = time.perf_counter() - start
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        jax.block_until_ready(run())
        times.append(time.perf_counter() - start)
    return compile_s, times


def reset_games(env: Soccer, params: EnvParams, key: jax.Array, games: int) -> State:
    """``games`` fresh games (leading axis), reset in one compiled call: run eagerly, the
    reset compiles each of its hundreds of small ops on its own."""
    keys = jax.random.split(key, games)
    states, _ = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    return states


ActionSampler = Callable[[jax.Array, int], jax.Array]
"""``(key, batch) -> actions f32[batch, 2, n, k]``: the random actions of a benchmark."""


def uniform_actions(players_per_team: int, actions: int = 2) -> ActionSampler:
    """Actions uniform in [-1, 1], ``actions`` values a player."""

    def sample(key: jax.Array, batch: int) -> jax.Array:
        shape = (batch, 2, players_per_team, actions)
        return jax.random.uniform(key, shape, minval=-1.0, maxval=1.0)

    return sample


def make_scan_runner(
    env: Soccer, params: EnvParams, batch: int, steps: int, sample: ActionSampler | None = None
) -> Callable[[State, jax.Array], tuple[State, jax.Array]]:
    """A compiled ``(states, key) -> (states, checksum)`` that plays ``steps`` steps of a batch
    with random actions (``sample``; default: the simulator's 2 values, uniform).

    The observation is computed from the carried state at the top of each step (as a policy would
    read it) and folded into a checksum, so XLA cannot drop it.
    """
    n = env.players_per_team
    sample = uniform_actions(n) if sample is None else sample
    observe = jax.vmap(env.observe, in_axes=(0, None))
    transition = jax.vmap(env.transition, in_axes=(0, 0, 0, None))

    def run(states: State, key: jax.Array) -> tuple[State, jax.Array]:
        def body(carry: tuple[State, jax.Array], step_key: jax.Array) -> tuple[Any, None]:
            states, checksum = carry
            obs = observe(states, params)
            checksum = checksum + jnp.sum(obs.entities) + jnp.sum(obs.self_features)
            action_key, env_key = jax.random.split(step_key)
            actions = sample(action_key, batch)
            env_keys = jax.random.split(env_key, batch)
            states, rewards, _, _ = transition(env_keys, states, actions, params)
            return (states, checksum + jnp.sum(rewards)), None

        (states, checksum), _ = jax.lax.scan(
            body, (states, jnp.zeros(())), jax.random.split(key, steps)
        )
        return states, checksum

    return jax.jit(run)


def bench_scan(
    players: int, batch: int, steps: int = 100, repeats: int = 5, devices: int | None = None
) -> EnvBenchResult:
    """Time a vmapped batch inside ``lax.scan``, sharded over ``devices`` (default: all)."""
    env, params = elevens.make(f"{players}v{players}")
    available = jax.devices()
    devices = len(available) if devices is None else devices
    if batch % devices:
        devices = 1
    states = reset_games(env, params, jax.random.key(0), batch)
    if devices > 1:
        mesh = jax.sharding.Mesh(np.array(available[:devices]), ("games",))
        sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("games"))
        states = jax.device_put(states, sharding)
    run = _carried(make_scan_runner(env, params, batch, steps), states)
    compile_s, times = _timed(run, repeats)
    return EnvBenchResult(
        players=players, batch=batch, mode="scan",
        steps_per_s=batch * steps / statistics.median(times), compile_s=compile_s,
        repeats=repeats, devices=devices, backend=jax.default_backend(),
    )


def bench_loop(players: int, steps: int = 200, repeats: int = 5) -> EnvBenchResult:
    """Time a Python loop over a jitted single-game ``env.step`` with random actions."""
    env, params = elevens.make(f"{players}v{players}")
    step = jax.jit(env.step)
    state, _ = jax.jit(env.reset)(jax.random.key(0), params)
    key = jax.random.key(1)

    def run() -> jax.Array:
        nonlocal state, key
        for _ in range(steps):
            key, action_key, env_key = jax.random.split(key, 3)
            actions = jax.random.uniform(action_key, (2, players, 2), minval=-1.0, maxval=1.0)
            state, obs, rewards, _, _ = step(env_key, state, actions, params)
        return rewards

    compile_s, times = _timed(run, repeats)
    return EnvBenchResult(
        players=players, batch=1, mode="loop", steps_per_s=steps / statistics.median(times),
        compile_s=compile_s, repeats=repeats, devices=1, backend=jax.default_backend(),
    )


STATE_COPIES, OBSERVATION_COPIES = 3, 2
"""What a scanned batch holds at once, per game: its state three times (the reset batch, the
scan's carry in and out) and its observation twice (the step's and its intermediates). A lower
bound on what XLA allocates, so a batch refused would not have run."""


def check_batches_fit(
    players: Sequence[int], batch: Sequence[int], available: int | None = None
) -> None:
    """Raise ``ValueError`` (naming --batch, the estimate and the limit) for a batch whose
    games' states cannot fit in memory. Traces one game's reset (``jax.eval_shape``): nothing
    compiles and nothing is allocated."""
    available = available_memory_bytes() if available is None else available
    if available is None:
        return
    for n in players:
        env, params = elevens.make(f"{n}v{n}")
        state, observation = jax.eval_shape(functools.partial(_reset_one, env, params))
        per_game = STATE_COPIES * _bytes(state) + OBSERVATION_COPIES * _bytes(observation)
        for games in batch:
            if games * per_game > available:
                raise ValueError(
                    f"--batch {games} needs about {gb(games * per_game)} for {n}v{n} games "
                    f"({gb(per_game)} a game), more than the {gb(available)} of memory "
                    f"available: at most {available // per_game:,} games fit"
                )


def _reset_one(env: Soccer, params: EnvParams) -> tuple[State, Any]:
    return env.reset(jax.random.key(0), params)


def _bytes(tree: Any) -> int:
    return sum(leaf.size * leaf.dtype.itemsize for leaf in jax.tree.leaves(tree))




def run_env_bench(
    players: Sequence[int] = (1, 2, 5, 11),
    batch: Sequence[int] = (256, 1024),
    steps: int = 100,
    repeats: int = 5,
    loop_steps: int = 200,
    as_json: bool = False,
    devices: int | None = None,
    print_fn: Callable[[str], None] = print,
) -> list[EnvBenchResult]:
    """Run every configuration; print a table (or one JSON object per line) and return results.
    A batch that cannot fit in memory is refused first (``check_batches_fit``)."""
    check_batches_fit(players, batch)
    results: list[EnvBenchResult] = []
    for n in players:
        loop = bench_loop(n, loop_steps, repeats)
        results.append(loop)
        if as_json:
            print_fn(json.dumps(asdict(loop)))
        else:
            print_fn(
                f"{n:>2}v{n:<2} loop  batch {1:>6}: {loop.steps_per_s:>12,.0f} steps/s "
                f"(compile {loop.compile_s:.1f} s)"
            )
        for b in batch:
            scan = bench_scan(n, b, steps, repeats, devices)
            scan = replace(scan, ratio_to_loop=scan.steps_per_s / loop.steps_per_s)
            results.append(scan)
            if as_json:
                print_fn(json.dumps(asdict(scan)))
            else:
                print_fn(
                    f"{n:>2}v{n:<2} scan  batch {b:>6}: {scan.steps_per_s:>12,.0f} steps/s "
                    f"(compile {scan.compile_s:.1f} s, {scan.devices} device(s)) = "
                    f"{scan.ratio_to_loop:,.0f}x the Python loop"
                )
    return results


@dataclass(frozen=True)
class GameBenchResult:
    game: str
    players: int
    """Players per team."""
    batch: int
    """Games stepped together (vmap inside one scan)."""
    steps_per_s: float
    """Median game steps per second over the repeats."""
    steps_per_cpu_s: float
    """Median game steps per second of this process's CPU time (all its threads): what the
    game costs, less shaken than the wall clock by other processes on a busy machine."""
    compile_s: float
    repeats: int
    backend: str
    ratio_to_first: float
    """steps/s over the first game's, measured in the same run (repeats interleaved)."""
    cpu_ratio_to_first: float
    """The same ratio of steps per CPU second."""


GameMaker = Callable[[int], tuple[Any, EnvParams, ActionSampler]]
"""``players_per_team -> (env, params, sample)``: a game to time and its random actions."""


def run_games_bench(
    games: dict[str, GameMaker],
    players: Sequence[int] = (11,),
    batch: Sequence[int] = (256,),
    steps: int = 100,
    repeats: int = 5,
    as_json: bool = False,
    print_fn: Callable[[str], None] = print,
) -> list[GameBenchResult]:
    """Time ``games`` side by side in scan mode at each team size and batch: every game is
    compiled first, then the repeats run in turns (game 1, game 2, ..., game 1, ...), and each
    median is compared with the first game's."""
    results: list[GameBenchResult] = []
    for n in players:
        for b in batch:
            runs: dict[str, Callable[[], jax.Array]] = {}
            compile_s: dict[str, float] = {}
            times: dict[str, list[float]] = {name: [] for name in games}
            cpu: dict[str, list[float]] = {name: [] for name in games}
            for name, make in games.items():
                runs[name] = _game_run(*make(n), b, steps)
                start = time.perf_counter()
                jax.block_until_ready(runs[name]())
                compile_s[name] = time.perf_counter() - start
            for _ in range(repeats):
                for name, run in runs.items():
                    start, start_cpu = time.perf_counter(), time.process_time()
                    jax.block_until_ready(run())
                    times[name].append(time.perf_counter() - start)
                    cpu[name].append(time.process_time() - start_cpu)
            rates = {name: b * steps / statistics.median(times[name]) for name in games}
            cpu_rates = {name: b * steps / statistics.median(cpu[name]) for name in games}
            first = rates[next(iter(games))]
            cpu_first = cpu_rates[next(iter(games))]
            for name in games:
                result = GameBenchResult(
                    game=name, players=n, batch=b, steps_per_s=rates[name],
                    steps_per_cpu_s=cpu_rates[name], compile_s=compile_s[name],
                    repeats=repeats, backend=jax.default_backend(),
                    ratio_to_first=rates[name] / first,
                    cpu_ratio_to_first=cpu_rates[name] / cpu_first,
                )
                results.append(result)
                print_fn(json.dumps(asdict(result)) if as_json else (
                    f"{n:>2}v{n:<2} {name:<10} batch {b:>6}: {result.steps_per_s:>10,.0f} "
                    f"steps/s = {result.ratio_to_first:.2f}x {next(iter(games))}; "
                    f"{result.steps_per_cpu_s:>10,.0f} steps/CPU s = "
                    f"{result.cpu_ratio_to_first:.2f}x (compile {result.compile_s:.1f} s)"
                ))
    return results


def _game_run(
    env: Any, params: EnvParams, sample: ActionSampler, batch: int, steps: int
) -> Callable[[], jax.Array]:
    """A call that plays ``steps`` steps of ``batch`` games of ``env`` (carried between calls)."""
    states = reset_games(env, params, jax.random.key(0), batch)
    return _carried(make_scan_runner(env, params, batch, steps, sample), states)


def _carried(runner: Callable[..., Any], states: Any) -> Callable[[], jax.Array]:
    """A call of ``runner`` that carries its games' states and a fresh key between calls and
    returns its checksum."""
    key = jax.random.key(1)

    def run() -> jax.Array:
        nonlocal states, key
        key, run_key = jax.random.split(key)
        states, checksum = runner(states, run_key)
        return checksum

    return run


THESIS_FIGURE_6_1: dict[str, dict[int, float]] = {
    # Env steps per second with random actions, thesis section 6.2.1 (figure 6.1): its custom
    # environment 4670 (1 a side) and 1533 (11 a side); RoboCup 7.6x and 25x slower, DeepMind's
    # soccer 13.6x and 102x slower than that.
    "thesis custom env": {1: 4670.0, 11: 1533.0},
    "thesis RoboCup wrapper": {1: 4670.0 / 7.6, 11: 1533.0 / 25.0},
    "thesis DeepMind soccer": {1: 4670.0 / 13.6, 11: 1533.0 / 102.0},
}


def plot_env_bench(results: Sequence[EnvBenchResult], path: str | Path) -> Path:
    """Figure 6.1: env steps per second against players per team (log scale), one line per
    batch size and for the single-game Python loop, with the thesis' figures as reference."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure, axis = plt.subplots(figsize=(6.4, 4.4), layout="constrained")
    series: dict[str, list[tuple[int, float]]] = {}
    for result in results:
        label = (
            "elevens, one game (jitted Python loop)" if result.mode == "loop"
            else f"elevens, {result.batch} games (vmap + scan)"
        )
        series.setdefault(label, []).append((result.players, result.steps_per_s))
    for label, points in series.items():
        points.sort()
        axis.plot(*zip(*points, strict=True), marker="o", label=label)
    for label, reference in THESIS_FIGURE_6_1.items():
        players = sorted(reference)
        axis.plot(players, [reference[p] for p in players], linestyle="--", marker="x",
                  color="grey", alpha=0.8, label=label)
        axis.annotate(label.removeprefix("thesis "), (players[-1], reference[players[-1]]),
                      fontsize=7, color="grey", xytext=(4, 0), textcoords="offset points")
    axis.set_yscale("log")
    axis.set_xlabel("players per team")
    axis.set_ylabel("env steps per second (log)")
    axis.set_title("Environment throughput, random actions (thesis figure 6.1)")
    axis.grid(alpha=0.3, which="both")
    axis.legend(fontsize=7)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110)
    plt.close(figure)
    return path
