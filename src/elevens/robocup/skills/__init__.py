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
* :mod:`~elevens.robocup.skills.set_plays` -- our set plays decided by the team itself, within
  the server's free-kick rule (``--set-plays decided``).
* :mod:`~elevens.robocup.skills.learned` -- a trained skills policy (a checkpoint of
  ``elevens train skills-2v2`` / ``skills-11v11``, or a team exported from one): the world
  model as the skill game's observations, the policy's action decoded as the game decodes it.
* :mod:`~elevens.robocup.skills.runtime` -- the decision server: one batched decision per
  cycle, a default for a request that misses its deadline.
* :mod:`~elevens.robocup.skills.proxy` -- finding the proxy and starting its players.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from elevens.robocup.skills.naive import SkillsNaive, SkillsPlanner, skills_naive
from elevens.robocup.skills.planner import helios_best
from elevens.robocup.skills.runtime import Decide
from elevens.robocup.skills.set_plays import check_set_plays

__all__ = ["SKILLS", "check_skills_policy", "skills_policy"]


def _simulator_team(name: str) -> Callable[[str], Decide]:
    """The simulator's handcrafted skills team ``name`` (``skills.team``) in the runtime, through
    the converter a trained team plays through (``learned.LearnedSkills``); built on demand
    (it compiles its policy call)."""

    def build(set_plays: str) -> Decide:
        from elevens.robocup.skills.learned import LearnedSkills
        from elevens.robocup.skills.team import SkillsNaiveTeam, SkillsRandomTeam

        team = {"skills_random": SkillsRandomTeam, "skills_naive_sim": SkillsNaiveTeam}[name]()
        decide = LearnedSkills(team, None, name=name, set_plays=set_plays)
        decide.warm_up()
        return decide

    return build


def _helios(**kwargs: Any) -> Callable[[str], Decide]:
    """A builder of ``SkillsPlanner(**kwargs)``, which plays our set plays by the routine."""

    def build(set_plays: str) -> Decide:
        if set_plays != "routine":
            raise ValueError(f"a team of helios-base's parts with set_plays={set_plays!r} "
                             "(allowed: 'routine')")
        return SkillsPlanner(**kwargs)

    return build


#: The skills teams by name, each a builder of a batched ``decide(states) -> actions`` given
#: how it plays our set plays (``set_plays.SET_PLAYS``):
#: ``skills_naive`` decides on librcsc's world model directly; ``skills_random`` (uniform skill
#: actions) and ``skills_naive_sim`` (the simulator's ``skills_naive``, on the world model
#: turned into the skill game's observation and back) play as a trained team does;
#: ``skills_planner`` is ``skills_naive`` with helios-base's planner taking its kicks, and
#: ``skills_planner_ours`` the same with the choice among the planner's chains made here
#: (helios-base's own choice, through ``GetBestPlannerAction``: the path a learned chooser
#: takes); ``skills_helios_move`` is ``skills_naive`` with helios-base's off-ball play, and
#: ``skills_helios_parts`` takes both (the goalie and set plays are the proxy's routines in all);
#: ``skills_helios_press`` is ``skills_helios_parts`` with a second player pressing their ball
#: (``naive.pressing``), a yardstick of what the off-ball choice of who runs at it is worth.
SKILLS: dict[str, Callable[[str], Decide]] = {
    "skills_naive": lambda set_plays: skills_naive if set_plays == "routine" else SkillsNaive(),
    "skills_planner": _helios(),
    "skills_planner_ours": _helios(choose=helios_best),
    "skills_helios_move": _helios(on_ball=False, off_ball=True),
    "skills_helios_parts": _helios(on_ball=True, off_ball=True),
    "skills_helios_press": _helios(on_ball=True, off_ball=True, press=3),
    "skills_random": _simulator_team("skills_random"),
    "skills_naive_sim": _simulator_team("skills_naive_sim"),
}


def check_skills_policy(spec: str) -> None:
    """ValueError in one line unless ``spec`` is a skills team: a name of :data:`SKILLS`, a
    chain chooser's file (``chains.py``), or a trained skills team (its config is read, not
    its networks)."""
    if spec in SKILLS:
        return
    from elevens.robocup.skills.chains import is_chooser, load_chooser

    if is_chooser(spec):
        load_chooser(spec)
        return
    from elevens.robocup.skills.learned import check_skills_team

    check_skills_team(spec, sorted(SKILLS))


def skills_policy(spec: str, *, deterministic: bool = True,
                  set_plays: str = "routine") -> Decide:
    """The skills team ``spec``: a name of :data:`SKILLS`, or a trained skills team (a
    checkpoint path, ``PATH@ITERATION`` or an exported folder), loaded and compiled, playing
    the mode of its action unless ``deterministic`` is False, our set plays as ``set_plays``
    says (``set_plays.SET_PLAYS``). A spec that is neither, or a bad ``set_plays``, is a
    ValueError naming what is allowed."""
    check_set_plays(set_plays)
    if spec in SKILLS:
        return SKILLS[spec](set_plays)
    from elevens.robocup.skills.chains import ChainChooser, is_chooser, load_chooser

    if is_chooser(spec):  # skills_helios_parts with its chain chosen by the file's weights
        return _helios(choose=ChainChooser(load_chooser(spec)), on_ball=True,
                       off_ball=True)(set_plays)
    from elevens.robocup.skills.learned import load_learned_skills

    return load_learned_skills(spec, deterministic=deterministic, set_plays=set_plays)
