"""A RoboCup team that decides in librcsc's skills: elevens chooses, the proxy executes.

Each player is a process of CLSFramework's soccer-simulation-proxy (librcsc's world model and
skills, built beside the project) that asks elevens' decision server for its actions every
cycle over Thrift. The modules:

* :mod:`~elevens.robocup.skills.wire` -- elevens' own definition of the messages
  (``proxy.thrift``), loaded with thriftpy2's accelerated binary protocol.
* :mod:`~elevens.robocup.skills.observe` -- a cycle's States as arrays over the players.
* :mod:`~elevens.robocup.skills.space` -- the decision space (kind + argument) and the proxy
  actions that carry it out.
* :mod:`~elevens.robocup.skills.naive` -- ``skills_naive``, the scripted yardstick.
* :mod:`~elevens.robocup.skills.runtime` -- the decision server: one batched decision per
  cycle, a default for a request that misses its deadline.
* :mod:`~elevens.robocup.skills.proxy` -- finding the proxy and starting its players.
"""

from __future__ import annotations

from elevens.robocup.skills.naive import skills_naive
from elevens.robocup.skills.runtime import Decide

__all__ = ["SKILLS", "skills_policy"]

#: The skills teams by name: each is a batched ``decide(states) -> actions``.
SKILLS: dict[str, Decide] = {"skills_naive": skills_naive}


def skills_policy(name: str) -> Decide:
    """The skills team called ``name``; a ValueError naming the allowed ones otherwise."""
    if name not in SKILLS:
        raise ValueError(f"skills team {name!r} is unknown (allowed: {', '.join(sorted(SKILLS))})")
    return SKILLS[name]
