"""``elevens tournament TEAM... --panel``: each team against every team of the opponent panel.

Instead of a round robin, each team given plays one match against each panel team
(``elevens.teams.registry.PANEL``), and the command prints, per team, its outcome against each
opponent, its mean over the panel and its worst opponent. Files: ``panel.csv`` and
``panel.json`` in ``--out`` (``elevens.eval.panel``). Example::

    elevens tournament elevens-11v11 elevens-2v2 --panel --games 500 --out results/panel
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from elevens.cli.eval import TournamentArgs


def panel_command(args: TournamentArgs) -> list[Any]:
    """Check the flags, load the teams and the panel (all before any game), play, print and
    save. Returns one ``PanelResult`` per team."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

    from elevens.cli.eval import _teams_and_env
    from elevens.eval.panel import play_panel, save_panel
    from elevens.teams.registry import PANEL

    if not args.teams:
        raise ValueError(
            "--panel needs the team(s) to measure: e.g. elevens tournament elevens-11v11 --panel"
        )
    ignored = [flag for flag, given in (
        ("--anchor", args.anchor is not None), ("--stamina", args.stamina),
        ("--goalie", args.goalie), ("--see-period", args.see_period != 1),
    ) if given]
    if ignored:
        raise ValueError(
            f"{', '.join(ignored)} cannot be used with --panel: the panel plays the simulator's "
            "own game and fits no ratings"
        )
    (teams, panel), env, params = _teams_and_env(
        (args.teams, PANEL), args.players, args.steps, args.deterministic
    )
    console = Console()
    began = time.perf_counter()

    def on_match(index: int, total: int, opponent: str, result: Any) -> None:
        import numpy as np

        console.print(
            f"  v {opponent}: {float(np.mean(result.outcome)):.3f} "
            f"({time.perf_counter() - began:.1f} s)", markup=False,
        )

    results = []
    for team in teams:
        console.print(f"{team.name} against the panel ({len(panel)} teams):", markup=False)
        results.append(play_panel(
            team, panel, env, params, num_games=args.games, seed=args.seed,
            chunk_size=args.chunk_size, on_match=on_match,
        ))
    # One column per team measured, one row per opponent: narrow enough for a terminal.
    grid = Table(
        title="Mean outcome ± std of each team against each panel team",
        caption=(f"{args.players} v {args.players}, {args.games} games a pair, sides swapped; "
                 "win 1, draw 0.5, loss 0"),
        title_justify="left", caption_justify="left",
    )
    grid.add_column("opponent", style="bold")
    for result in results:
        grid.add_column(escape(result.team), justify="right")
    for k, name in enumerate(results[0].opponents):
        grid.add_row(escape(name), *(
            f"{result.numbers[k]['mean']:.3f}±{result.numbers[k]['std']:.2f}"
            for result in results
        ))
    grid.add_row("mean", *(f"{result.mean:.3f}" for result in results), style="bold")
    grid.add_row("worst", *(f"{result.worst[1]:.3f}" for result in results), style="bold")
    console.print(grid)
    paths = save_panel(results, args.out, args.players, args.games,
                       int(params.episode_length), args.seed)
    for result in results:
        worst_name, worst_value = result.worst
        console.print(f"{result.team}: mean {result.mean:.3f} over the panel, worst "
                      f"{worst_value:.3f} against {worst_name}", markup=False)
    for kind, path in paths.items():
        console.print(f"  {kind}: {path}", markup=False)
    return results
