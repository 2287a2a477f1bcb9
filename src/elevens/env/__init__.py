"""The simulator: pure JAX functions over named containers."""

from elevens.env.params import EnvParams, formation
from elevens.env.soccer import Soccer, make
from elevens.env.state import GlobalState, Observation, State, StepInfo

__all__ = ["EnvParams", "GlobalState", "Observation", "Soccer", "State", "StepInfo", "formation",
           "make"]
