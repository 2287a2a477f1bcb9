"""Ecosystem fronts of the simulator (host-side, NumPy in and out).

Kept import-light: ``import elevens.adapters`` does not import PettingZoo or Gymnasium (an
optional extra, ``pip install elevens[pettingzoo]``). ``SoccerParallelEnv`` is loaded on first
access, so both ``from elevens.adapters import SoccerParallelEnv`` and
``from elevens.adapters.pettingzoo import SoccerParallelEnv`` work.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from elevens.adapters.pettingzoo import SoccerParallelEnv

__all__ = ["SoccerParallelEnv"]

_LAZY = {"SoccerParallelEnv": "elevens.adapters.pettingzoo"}


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
