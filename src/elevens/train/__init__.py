"""Training: config, rollout, PPO, opponents, shaping, checkpoints, logs and the trainer.

The config is imported eagerly; the trainer and rollout (which pull in the networks) load on
first use, so ``from elevens.train import make_config`` stays light for the CLI.
"""

from __future__ import annotations

import importlib
from typing import Any

from elevens.train.config import (
    EnvConfig,
    NetworkConfig,
    OpponentConfig,
    RunConfig,
    TrainConfig,
    make_config,
)

_LAZY = {
    "Trainer": "elevens.train.trainer",
    "TrainState": "elevens.train.trainer",
    "TrainResult": "elevens.train.trainer",
    "make_trainer": "elevens.train.trainer",
    "train": "elevens.train.trainer",
    "evaluate": "elevens.train.trainer",
    "Transition": "elevens.train.rollout",
    "Rollout": "elevens.train.rollout",
    "rollout": "elevens.train.rollout",
}

__all__ = [
    "EnvConfig",
    "NetworkConfig",
    "OpponentConfig",
    "RunConfig",
    "TrainConfig",
    "make_config",
    *_LAZY,
]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'elevens.train' has no attribute {name!r}")
