"""The evaluation subcommands: ``tournament``, ``analyze``, ``curves``, ``render``, ``view``.

Each has a typed args dataclass (tyro builds the flags from its fields and docstrings) and a
command function. ``elevens.cli`` wires them in; heavy imports (JAX, matplotlib) happen inside
the command functions so ``elevens --help`` stays fast. Examples::

    elevens tournament random naive teamwork --games 500 --out results/tournament
    elevens tournament naive teamwork 4p=runs/2v2 22p=runs/11v11@5000 --anchor naive
    elevens analyze naive teamwork 22p=runs/11v11 --against 22p=runs/11v11 --games 500
    elevens curves runs/seed0 runs/seed1 runs/seed2 --against naive --out fig_6_4.png
    elevens render replays/game_0000.npz --out game.mp4 --view 3
    elevens view replays/*.npz

A team is ``random``, ``naive``, ``teamwork`` or a checkpoint ``PATH[@ITERATION]``, optionally
labelled ``LABEL=...`` (``elevens.runs.teams``).
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path
from typing import Annotated, Any

import tyro

import elevens.robocup  # noqa: F401 - registers the RoboCup wing's games, teams and shipped teams
from elevens.cli.checks import (
    PLOT_SUFFIXES,
    VIDEO_SUFFIXES,
    Commands,
    check_output_dir,
    check_output_file,
    run_command,
    subcommand_union,
)


@dataclasses.dataclass(frozen=True)
class TournamentArgs:
    """Round robin between teams (thesis table 6.3, figure 6.7) with Bradley-Terry ratings."""

    teams: tyro.conf.Positional[Annotated[tuple[str, ...], tyro.conf.arg(metavar="TEAM...")]]
    """Teams: random, naive, teamwork, or a checkpoint PATH[@ITERATION], as [LABEL=]SPEC."""
    panel: bool = False
    """Instead of a round robin, play each team against every team of the opponent panel and
    report its mean and worst outcome (panel.csv, panel.json; ``panel_command``)."""
    games: int = 500
    """Games per pair of teams (sides swapped at half time); every team also plays itself."""
    players: int = 11
    """Players per team, 1..11 (a checkpoint trained at any size plays any size)."""
    out: Path = Path("tournament")
    """Directory for table.csv, pairs.csv, ratings.csv, tournament.json and the PNGs."""
    seed: int = 0
    """Seed of the games (match m uses fold_in(key(seed), m)) and of the bootstrap."""
    steps: int | None = None
    """Steps per game (default: the full episode, 400)."""
    anchor: str | None = None
    """Team (label) whose rating is 0; default: the ratings' mean is 0."""
    bootstrap: int = 1000
    """Bootstrap resamples for the ratings' intervals (0: Fisher standard errors only)."""
    deterministic: bool | None = None
    """Checkpoints play tanh(mean) (True) or sample (False); default: each run's setting."""
    chunk_size: int = 128
    """Games vmapped together (memory vs speed)."""
    see_period: int = 1
    """Teams of the 12-value RoboCup action (rcss_naive, runs trained with --env.physics
    rcss) play the simulator with rcssserver's bodies, teams of the 4-value skill action
    (skills_naive, skills_random) its skill game; there, cycles between two sees (1: fresh
    observations; 3: the server's wide view)."""
    stamina: bool = False
    """Teams of the 12-value RoboCup action: their players tire as in rcssserver."""
    goalie: bool = False
    """Teams of the 12-value RoboCup action: each goalie guards its goal and catches as the
    elevens routines play it in rcssserver."""
    randomize: int | None = None
    """SEED: play every match on the 20 held-out randomised game settings of SEED (physics and
    geometry drawn from env.randomize's default ranges on another key than any training draw;
    game g plays setting g % 20). Default: the one game of --players and --steps."""


@dataclasses.dataclass(frozen=True)
class AnalyzeArgs:
    """Gameplay metrics (thesis table 6.4) and per-player position heat maps (figs 6.8, 6.9)."""

    teams: tyro.conf.Positional[Annotated[tuple[str, ...], tyro.conf.arg(metavar="TEAM...")]]
    """Teams to analyse (one column each), all against the same opponent."""
    against: str
    """The opponent: random, naive, teamwork, or a checkpoint [LABEL=]PATH[@ITERATION]."""
    games: int = 500
    """Games per team (sides swapped at half time)."""
    players: int = 11
    """Players per team, 1..11."""
    out: Path = Path("analysis")
    """Directory for metrics.csv, metrics.json and heatmap_<team>_vs_<opponent>.png."""
    seed: int = 0
    """Seed of the games."""
    steps: int | None = None
    """Steps per game (default: the full episode, 400)."""
    heatmaps: bool = True
    """Draw the position heat maps."""
    replays: int = 0
    """Also save the first N games of each match as replays (out/replays/<team>/)."""
    deterministic: bool | None = None
    """Checkpoints play tanh(mean) (True) or sample (False); default: each run's setting."""
    chunk_size: int = 64
    """Games vmapped together (recording keeps every step, so smaller than a tournament's)."""


@dataclasses.dataclass(frozen=True)
class CurvesArgs:
    """Learning curves over seeds (thesis figure 6.4) from training runs' metrics.csv."""

    runs: tyro.conf.Positional[Annotated[tuple[str, ...], tyro.conf.arg(metavar="RUN...")]]
    """Run directories (each with metrics.csv), one per seed; or, to overlay settings (figure
    6.6), LABEL=RUN[,RUN...] groups, one curve per label with its seeds pooled."""
    against: str = "naive"
    """The team whose outcome is plotted."""
    out: Path = Path("learning_curves.png")
    """Output PNG."""
    x: tuple[str, ...] = ("hours", "env_steps")
    """x axes, one panel each: hours, env_steps, iteration, or any logged metric name."""
    metric: str = "eval/{team}/outcome"
    """Metric name; {team} is replaced by each evaluated team (vertical lines) and --against."""
    threshold: float = 0.5
    """A team counts as outperformed where the lower end of the 95% interval of the mean
    outcome against it (from the logged win and draw rates) first rises above this."""
    title: str | None = None
    """Figure title (default: the runs and the team)."""


@dataclasses.dataclass(frozen=True)
class RenderArgs:
    """Draw a saved replay as an MP4 or GIF."""

    replay: tyro.conf.Positional[Annotated[Path, tyro.conf.arg(metavar="REPLAY")]]
    """A replay file (.npz, from analyze --replays or elevens.eval.replay.save_replay)."""
    out: Path = Path("game.mp4")
    """Output video: .mp4 or .gif."""
    view: int | None = None
    """Draw this player's field of view (world row: team 0 is 0..n-1, team 1 is n..2n-1)."""
    fps: int = 20
    """Frames per second."""
    scale: int = 6
    """Pixels per metre."""
    follow_ball: float | None = None
    """Zoom in on a window this many metres wide that follows the ball (e.g. 40)."""


@dataclasses.dataclass(frozen=True)
class ViewArgs:
    """Watch replays in the browser: a local web viewer on 127.0.0.1."""

    replays: tyro.conf.Positional[
        Annotated[tuple[Path, ...], tyro.conf.arg(metavar="REPLAY...")]
    ] = ()
    """Replay files (.npz), or folders (a run, an analyze --out folder): every replay under
    them is listed."""
    port: int = 0
    """Port on 127.0.0.1 (0: any free port; the URL is printed)."""
    open: bool = False
    """Open the page in the default browser."""


# --------------------------------------------------------------------------------------------
# Commands
# --------------------------------------------------------------------------------------------


def _env(
    players: int, steps: int | None, field: dict[str, float] | None = None
) -> tuple[Any, Any]:
    import elevens

    overrides: dict[str, Any] = dict(field or {})
    if steps is not None:
        overrides["episode_length"] = steps
    return elevens.make(f"{players}v{players}", **overrides)


def _load_teams(specs: tuple[str, ...], deterministic: bool | None) -> list[Any]:
    import dataclasses as dc

    from elevens.runs.teams import load_team, unique_names

    teams = [load_team(spec, deterministic=deterministic) for spec in specs]
    names = unique_names(teams)
    return [dc.replace(team, name=name) for team, name in zip(teams, names, strict=True)]


def _teams_and_env(
    groups: tuple[tuple[str, ...], ...], players: int, steps: int | None,
    deterministic: bool | None, see_period: int | None = None, stamina: bool = False,
    goalie: bool = False,
) -> tuple[list[list[Any]], Any, Any]:
    """Load each group of team specs, and the game on the field the checkpoints trained on
    (SPEC.md's when all are handcrafted), with the handcrafted teams told that field. With
    ``see_period`` (the tournament) teams that all give the 12-value action play the simulator
    with rcssserver's bodies, and teams that all give the 4-value skill action its skill game
    (the server's field unless the checkpoints trained on another)."""
    from elevens.robocup.bodies import RcssSoccer
    from elevens.robocup.skills.game import SkillSoccer
    from elevens.robocup.skills.team import DEFER, self_feature_count
    from elevens.runs.teams import check_team_size, common_field, fit_to_field

    games = {12: ("the 12-value RoboCup action", RcssSoccer),
             4: ("the 4-value skill action", SkillSoccer)}
    loaded = [_load_teams(group, deterministic) for group in groups]
    every = [team for group in loaded for team in group]
    kinds = {team.actions for team in every}
    if see_period is not None and len(kinds) > 1:
        described = {2: "the simulator's 2-value one", **{k: v[0] for k, v in games.items()}}
        named = " and ".join(
            f"{', '.join(team.name for team in every if team.actions == kind)}"
            f"{' give' if index == 0 else ''} {described.get(kind, f'{kind} action values')}"
            for index, kind in enumerate(sorted(kinds, reverse=True))
        )
        raise ValueError(
            f"{named}: a tournament plays one game, so give teams of one kind"
        )
    (kind,) = kinds if see_period is not None and len(kinds) == 1 else (2,)
    other_game = kind in games
    for team in every:
        check_team_size(team, players, kind if other_game else 2)
    field = common_field(every)
    if other_game:
        # A skills team trained with the intercept table (env.reach_features) reads it; the
        # others read the features before it.
        wide = max((getattr(team.policy, "self_features", None) or 0 for team in every),
                   default=0)
        # A policy with the DEFER kind needs the game that plays it (the others never give it).
        defer = any(getattr(team.policy, "kinds", 0) == DEFER + 1 for team in every)
        env = (SkillSoccer(players, see_period=see_period or 1, stamina=stamina, goalie=goalie,
                           reach=wide == self_feature_count(True), defer=defer) if kind == 4
               else RcssSoccer(players, see_period=see_period or 1, stamina=stamina,
                               goalie=goalie))
        params = env.default_params(
            **field, **({} if steps is None else {"episode_length": steps})
        )
    else:
        env, params = _env(players, steps, field)
    return [[fit_to_field(team, params) for team in group] for group in loaded], env, params


def panel_command(args: TournamentArgs) -> list[Any]:
    """``elevens tournament TEAM... --panel``: instead of a round robin, each team plays every
    team of the opponent panel (``teams.registry.PANEL``); prints each outcome, the mean and the
    worst, and writes panel.csv and panel.json (``eval.panel``). Checks the flags and loads the
    teams first (before any game). Returns one ``PanelResult`` per team."""
    from rich.console import Console
    from rich.markup import escape
    from rich.table import Table

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


def _check_chunk_fits(args: Any) -> None:
    from elevens.runs.memory import batch_bytes, check_fits

    games = min(args.chunk_size, args.games)
    check_fits("--chunk-size", args.chunk_size, batch_bytes(args.players, games),
               f"{games} {args.players}v{args.players} games at once")


def tournament_command(args: TournamentArgs) -> Any:
    """Play the round robin, print the table and ratings, write the files. Returns the
    ``Tournament``."""
    _check_chunk_fits(args)
    if args.panel:
        return panel_command(args)
    from rich.console import Console

    from elevens.env.soccer import Soccer
    from elevens.eval.tournament import print_tournament, run_tournament, save_tournament

    if not args.teams:
        raise ValueError("no teams given: e.g. elevens tournament random naive teamwork")
    if args.games < 1:
        raise ValueError(f"games={args.games} is invalid: it must be >= 1")
    check_output_dir("--out", args.out)
    console = Console()
    (teams,), env, params = _teams_and_env(
        (args.teams,), args.players, args.steps, args.deterministic, args.see_period,
        args.stamina, args.goalie,
    )
    names = [team.name for team in teams]
    if args.anchor is not None and args.anchor not in names:
        raise ValueError(f"--anchor {args.anchor!r} is not one of the teams: {', '.join(names)}")
    if args.randomize is not None and type(env) is not Soccer:
        raise ValueError(
            f"randomize={args.randomize}: held-out randomised games are the simulator's own "
            "game; teams of the 12-value RoboCup action or the skill action play another"
        )
    began = time.perf_counter()

    def on_match(index: int, total: int, home: str, away: str, result: Any) -> None:
        import numpy as np

        mean = float(np.mean(result.outcome))
        console.print(
            f"match {index + 1}/{total}: {home} v {away}: {mean:.3f} "
            f"({time.perf_counter() - began:.1f} s)", markup=False,
        )

    tournament = run_tournament(
        teams, env, params, num_games=args.games, seed=args.seed,
        chunk_size=args.chunk_size, on_match=on_match, anchor=args.anchor,
        bootstrap_samples=args.bootstrap, randomize=args.randomize,
    )
    print_tournament(tournament, console)
    paths = save_tournament(tournament, args.out)
    console.print(f"{len(teams)} teams, {args.games} games a pair, {args.players} v "
                  f"{args.players}: {tournament.wall_s:.1f} s", markup=False)
    for kind, path in paths.items():
        console.print(f"  {kind}: {path}", markup=False)
    return tournament


def analyze_command(args: AnalyzeArgs) -> Any:
    """Play each team against the opponent with records; print and save the metrics, draw the
    heat maps. Returns the list of ``TeamMetrics``."""
    _check_chunk_fits(args)
    import jax
    from rich.console import Console

    from elevens.eval.heatmap import colour_top, plot_heatmaps, position_histograms
    from elevens.eval.match import play_match
    from elevens.eval.metrics import (
        compute_metrics,
        print_metrics,
        save_metrics,
        team_trajectories,
    )
    from elevens.eval.replay import save_match_replays

    if not args.teams:
        raise ValueError("no teams given: e.g. elevens analyze naive teamwork --against naive")
    if args.games < 1:
        raise ValueError(f"games={args.games} is invalid: it must be >= 1")
    check_output_dir("--out", args.out)
    console = Console()
    (teams, (opponent,)), env, params = _teams_and_env(
        (args.teams, (args.against,)), args.players, args.steps, args.deterministic
    )
    out = Path(args.out)
    rows = []
    trajectories = []
    for index, team in enumerate(teams):
        began = time.perf_counter()
        result = play_match(
            env, params, team.policy, opponent.policy, jax.random.fold_in(jax.random.key(
                args.seed), index), args.games, home_params=team.params,
            away_params=opponent.params, record=True, chunk_size=args.chunk_size,
        )
        result = jax.device_get(result)
        rows.append(compute_metrics(result, params, team_name=team.name,
                                    opponent_name=opponent.name))
        message = f"{team.name} v {opponent.name}: {args.games} games"
        if args.heatmaps:
            own = team_trajectories(result)
            trajectories.append((team.name, own.positions, own.ball))
        if args.replays > 0:
            saved = save_match_replays(
                result, params, out / "replays" / team.name, team.name, opponent.name,
                games=range(min(args.replays, args.games)), source={"seed": args.seed},
            )
            message += f", {len(saved)} replays in {saved[0].parent}"
        console.print(f"{message} ({time.perf_counter() - began:.1f} s)", markup=False)
    if trajectories:
        # One colour scale for every team of the analysis, so their maps compare.
        top = colour_top([position_histograms(p, params)[0] for _, p, _ in trajectories])
        for name, positions, ball in trajectories:
            path = plot_heatmaps(
                positions, params, out / f"heatmap_{name}_vs_{opponent.name}.png",
                title=f"Positions of {name} against {opponent.name} "
                f"({args.players} v {args.players}, {args.games} games, own frame)",
                ball=ball, top=top, shared_with=len(trajectories),
            )
            console.print(f"heat map: {path}", markup=False)
    print_metrics(rows, console)
    paths = save_metrics(rows, out / "metrics")
    for kind, path in paths.items():
        console.print(f"  {kind}: {path}", markup=False)
    return rows


def curves_command(args: CurvesArgs) -> Any:
    """Draw the learning curves; print where each team is first outperformed."""
    from elevens.runs.curves import plot_learning_curves

    if not args.runs:
        raise ValueError("no run directories given: e.g. elevens curves runs/a runs/b")
    check_output_file("--out", args.out, PLOT_SUFFIXES)
    if any("=" in run for run in args.runs):
        from elevens.runs.curves import parse_run_groups, plot_run_groups

        finals = plot_run_groups(
            parse_run_groups(args.runs), args.out, against=args.against, x_axes=args.x,
            metric=args.metric, title=args.title,
        )
        for label, final in finals.items():
            print(f"{label}: last mean {final:.3f} against {args.against}")
        print(f"wrote {args.out}")
        return finals
    summary = plot_learning_curves(
        args.runs, args.out, against=args.against, x_axes=args.x, metric=args.metric,
        threshold=args.threshold, title=args.title,
    )
    for axis, teams in summary.first_outperformed.items():
        for team, x in teams.items():
            where = "never" if x is None else f"{x:.4g}"
            rule = ("95% interval" if team in summary.with_interval else "mean, no win and draw "
                    "rates logged")
            print(f"first beats {team} ({rule} above {args.threshold}) at {axis} = {where}")
    print(f"wrote {summary.path}")
    return summary


def render_command(args: RenderArgs) -> Path:
    """Draw a replay to a video file."""
    from elevens.eval.replay import load_replay, render_replay

    check_output_file("--out", args.out, VIDEO_SUFFIXES)
    replay = load_replay(args.replay)
    path = render_replay(replay, args.out, view=args.view, fps=args.fps, scale=args.scale,
                         progress=True, follow_ball=args.follow_ball)
    print(f"{replay.team_names[0]} {replay.final_score[0]} : {replay.final_score[1]} "
          f"{replay.team_names[1]}; wrote {path} ({replay.num_steps + 1} frames, the last at "
          "full time)")
    return path


def view_command(args: ViewArgs) -> None:
    """Serve the web viewer until Ctrl-C."""
    from elevens.eval.viewer import view

    view(args.replays, port=args.port, open_browser=args.open)


COMMANDS: Commands = {
    "tournament": (TournamentArgs, tournament_command),
    "analyze": (AnalyzeArgs, analyze_command),
    "curves": (CurvesArgs, curves_command),
    "render": (RenderArgs, render_command),
    "view": (ViewArgs, view_command),
}
"""The eval subcommands: name -> (args, command); ``elevens.cli.app`` takes them as they are."""


def main(argv: list[str] | None = None) -> Any:
    """``python -m elevens.cli.eval SUBCOMMAND ...``: the eval subcommands on their own."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = tyro.cli(subcommand_union(COMMANDS), args=argv, prog="elevens")
    return run_command(COMMANDS, args)


if __name__ == "__main__":
    main()
