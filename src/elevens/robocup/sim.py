"""The simulator with rcssserver's bodies as a game to train in (``elevens train rcss-11v11``).

The core trains in whatever game its ``EnvConfig`` makes (``train.config.register_game``); this
module supplies the one with the server's bodies and the thesis's 12-value action
(``robocup.bodies.RcssSoccer``): its config (``RcssEnvConfig``, with the server's stamina, the
goalie routine and see periods), the ``rcss-2v2`` and ``rcss-11v11`` presets on the server's
field and ball, the handcrafted 12-value team ``rcss_naive`` and the shipped 12-value teams
(``rcss11``, ``rcss-gpu``, folders beside this file). Importing ``elevens.robocup`` registers
them all, so ``elevens train rcss-11v11`` and a saved run of this game resume as any
other.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, ClassVar

from elevens.robocup.bodies import ACTION_SIZE, RcssSoccer, rcss_field
from elevens.robocup.rcss_naive import RcssNaiveTeam
from elevens.teams.registry import register_team
from elevens.teams.trained import add_shipped_folder
from elevens.train.config import (
    EnvConfig,
    LearnerConfig,
    TrainConfig,
    apply_overrides,
    make_config,
    register_game,
    register_preset,
)


@dataclasses.dataclass(frozen=True)
class RcssEnvConfig(EnvConfig):
    """The simulator's game with rcssserver's bodies and the 12-value action; the other fields
    are ``EnvConfig``'s (give the server's field and ball in ``game``: ``rcss_field``)."""

    physics: str = "rcss"
    """The game's bodies: "rcss", rcssserver's (``elevens.robocup.bodies``)."""
    stamina: bool = False
    """Players tire as in rcssserver (stamina, effort, recovery and capacity;
    ``bodies.Stamina``) and pace their dashes by the rule every elevens team plays the server
    with (``elevens.robocup.rules.pace_dashes``)."""
    goalie: bool = False
    """Each team's goalie (player 0) plays as the elevens routines play it in rcssserver
    instead of by the policy: it guards its goal, catches a ball in reach inside its penalty
    area and clears it up the wing (``bodies.goalie_guard``, ``goalie_catch``)."""
    see_period: int = 1
    """Cycles between two sees of a player. 1: a fresh observation every step; 3:
    rcssserver's wide view in synch mode, as ``elevens robocup`` plays (each player acts on its
    last see, with its clock and last command current; the critic sees the state)."""

    PHYSICS: ClassVar[str] = "rcss"
    BODIES: ClassVar[type[RcssSoccer]] = RcssSoccer
    """The game class ``make_env`` builds (a game on these bodies names its own)."""

    def make_env(self, players_per_team: int) -> RcssSoccer:
        return self.BODIES(
            players_per_team, see_period=self.see_period, stamina=self.stamina,
            goalie=self.goalie,
        )

    @property
    def actions(self) -> int:
        return self.BODIES.actions

    def check(self) -> None:
        _require(
            isinstance(self.see_period, int) and not isinstance(self.see_period, bool)
            and self.see_period >= 1,
            f"env.see_period={self.see_period!r} is invalid: cycles between two sees, an "
            "integer of at least 1",
        )
        for name in ("stamina", "goalie"):
            value = getattr(self, name)
            _require(
                isinstance(value, bool),
                f"env.{name}={value!r} is invalid: it must be True or False",
            )
        one_a_side = [s for s in (self.scenario, *self.mix) if s == "1v1"]
        _require(
            not self.goalie or not one_a_side,
            "env.goalie=True is invalid with 1 player a side (the main game or env.mix): the "
            "routine plays each team's goalie (player 0), so the policy would play nobody; use "
            "2 or more players",
        )


def _require(condition: bool, message: str) -> None:
    if not condition:
        raise ValueError(message)


SERVER_FIELD = ("field_length", "field_width", "goal_width", "ball_friction", "ball_max_speed")
"""The EnvParams fields ``rcss_field`` sets to the server's."""


def rcss_game(config: TrainConfig, *, server_field: bool = True) -> TrainConfig:
    """``config`` in the game with rcssserver's bodies: the 12-value action, ``rcss_naive`` in
    place of the simulator's handcrafted teams for evaluation, no GIF (its game is against
    them), and with ``server_field`` the server's field and ball (``SERVER_FIELD``). Not
    validated: give the other fields with ``apply_overrides`` first."""
    learner: LearnerConfig = config.learner
    env = learner.env
    game = env.game
    if server_field:
        server = rcss_field(env.players_per_team)
        game = dataclasses.replace(game, **{name: getattr(server, name) for name in SERVER_FIELD})
    shared = {f.name: getattr(env, f.name) for f in dataclasses.fields(EnvConfig)}
    return dataclasses.replace(
        config,
        learner=dataclasses.replace(
            learner,
            env=RcssEnvConfig(**{**shared, "game": game, "physics": RcssEnvConfig.PHYSICS}),
            network=dataclasses.replace(learner.network, actions=ACTION_SIZE),
        ),
        run=dataclasses.replace(config.run, eval_teams=("rcss_naive",), write_gif=False),
    )


def rcss_config(preset: str, **overrides: Any) -> TrainConfig:
    """The simulator preset ``preset`` in the game with rcssserver's bodies, field and ball,
    with ``overrides`` as ``make_config`` takes them; validated (the ``rcss-PRESET`` preset)."""
    config = rcss_game(make_config(preset))
    config = dataclasses.replace(
        config, preset=f"rcss-{preset}",
        run=dataclasses.replace(config.run, run_dir=f"runs/rcss-{preset}"),
    )
    return apply_overrides(config, overrides).validate()


def register() -> None:
    """Make the game, its presets and ``rcss_naive`` known to the core (idempotent)."""
    register_game(RcssEnvConfig)
    register_team("rcss_naive", RcssNaiveTeam())
    add_shipped_folder(Path(__file__).resolve().parent / "trained")
    for preset in ("2v2", "11v11"):
        register_preset(
            f"rcss-{preset}",
            _preset_factory(preset),
            f"The {preset} preset in the simulator with rcssserver's bodies, field and ball, "
            "and the thesis's 12-value action (elevens robocup match plays the result).",
        )


def _preset_factory(preset: str) -> Any:
    return lambda: rcss_config(preset)
