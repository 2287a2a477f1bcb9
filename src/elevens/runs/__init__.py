"""Runs on disk: the run directory's layout, opening and resuming it, the host loop that
drives the compiled learner (``train``), loading trained teams from runs and shipped folders,
and reading learning curves back.

Layers: env -> {teams, nets} -> play -> train -> eval -> runs -> the wings and fronts above (the
official server's bridge, adapters, bench) -> cli; docs/architecture.md draws them.
"""

from __future__ import annotations

import importlib
from typing import Any

_LAZY = {
    "train": "elevens.runs.loop",
    "evaluate": "elevens.runs.loop",
    "TrainResult": "elevens.runs.loop",
    "RunRefusedError": "elevens.runs.errors",
    "RunLayout": "elevens.runs.layout",
    "load_team": "elevens.runs.teams",
    "load_learner_params": "elevens.runs.teams",
}

__all__ = list(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'elevens.runs' has no attribute {name!r}")
