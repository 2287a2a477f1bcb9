"""Training: config, rollout, PPO, opponents, shaping, checkpoints and the compiled learner.

The config is imported eagerly; the learner and rollout (which pull in the networks) load on
first use, so ``from elevens.train import make_config`` stays light for the CLI. The host loop
that drives the learner is ``elevens.runs.train``.
"""

from __future__ import annotations

import importlib
from typing import Any

from elevens.train.config import (
    EnvConfig,
    LearnerConfig,
    NetworkConfig,
    OpponentConfig,
    RunConfig,
    TrainConfig,
    make_config,
)

_LAZY = {
    "Learner": "elevens.train.learner",
    "TrainState": "elevens.train.learner",
    "make_learner": "elevens.train.learner",
    "Transition": "elevens.train.rollout",
    "Rollout": "elevens.train.rollout",
    "rollout": "elevens.train.rollout",
}

__all__ = [
    "EnvConfig",
    "LearnerConfig",
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
