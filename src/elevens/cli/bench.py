"""The `elevens bench train` subcommand's arguments (wired into ``elevens.cli``)."""

from __future__ import annotations

import dataclasses
from typing import Any


@dataclasses.dataclass(frozen=True)
class TrainBenchArgs:
    """Training env steps per second with the thesis network, and where the time goes."""

    players: tuple[int, ...] = (2, 11)
    """Players per team to measure."""
    json: bool = False
    """Print one JSON object per team size instead of a line of text."""
    episode_length: int = 100
    """Steps per episode (costs scale linearly with it; the rate barely depends on it)."""
    repeats: int = 3
    """Timed repeats; the median is reported."""
    devices: tuple[int, ...] = ()
    """Device counts to train on, e.g. 1 2 (with 2 host devices: XLA_FLAGS=
    --xla_force_host_platform_device_count=2): steps per second per device and the scaling
    efficiency against the first count. Empty: one run on the default device."""
    games: int | None = None
    """Games per iteration (default 660 / players: table 6.1's batch). Must be a multiple of
    every device count."""
    minibatch_size: int | None = None
    """Player sequences per minibatch (default: about table 6.1's 60, in whole games). A larger
    one means fewer sequential optimiser steps per iteration: what a GPU needs."""
    parts: bool = True
    """Also time the rollout, the update and the env alone (three more compiles)."""



def bench_train_command(args: TrainBenchArgs) -> Any:
    """Run the training benchmark."""
    from elevens.bench.train import run_train_bench

    return run_train_bench(
        players=args.players, json=args.json, episode_length=args.episode_length,
        repeats=args.repeats, devices=args.devices, games=args.games,
        parts=args.parts, minibatch_size=args.minibatch_size,
    )
