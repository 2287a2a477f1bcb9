"""elevens: a JAX-native 2D robot-soccer simulator and multi-agent RL through self-play."""

from elevens.env import EnvParams, Observation, Soccer, State, make

__all__ = ["EnvParams", "Observation", "Soccer", "State", "make"]
__version__ = "0.1.0"
