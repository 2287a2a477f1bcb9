"""`elevens ...` subcommands (tyro). Rendering, matches and training run inside each command."""

from __future__ import annotations

import contextlib
import io
import os
import re
import signal
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

import tyro

from elevens.cli import eval as eval_commands
from elevens.cli import exploit as exploit_commands
from elevens.cli import robocup as robocup_commands
from elevens.cli import robocup_skills as robocup_skills_commands
from elevens.cli.bench import TrainBenchArgs, bench_train_command
from elevens.cli.checks import (
    EXIT_BAD_INPUT,
    EXIT_INTERRUPTED,
    PLOT_SUFFIXES,
    VIDEO_SUFFIXES,
    Commands,
    check_numeric_args,
    check_output_file,
    one_line,
    run_command,
    subcommand_union,
)
from elevens.cli.train import TrainArgs, command_flags_first, train_command


@dataclass(frozen=True)
class PlayArgs:
    """Play one game between two teams and write it as a GIF or MP4."""

    home: str = "naive"
    """Team on side 0 (attacks +x): random, naive, teamwork, a shipped trained team
    (elevens-11v11, elevens-2v2) or a checkpoint PATH[@ITERATION]."""
    away: str = "teamwork"
    """Team on side 1, as --home."""
    players: int = 11
    """Players per team, 1..11."""
    out: Path = Path("game.gif")
    """Output file: .gif or .mp4."""
    seed: int = 0
    """Seed of the game (spawns and random teams)."""
    steps: int | None = None
    """Steps to play (default: a whole episode, 400)."""
    fps: int = 20
    """Frames per second of the video."""
    scale: int = 6
    """Pixels per metre."""
    view: int | None = None
    """Draw this player's field of view (world row: team 0 is 0..n-1, team 1 is n..2n-1)."""
    replay: Path | None = None
    """Also save the game as a replay (.npz) that `elevens view` and `elevens render` open."""
    follow_ball: float | None = None
    """Zoom in on a window this many metres wide that follows the ball (e.g. 40)."""
    deterministic: bool | None = None
    """Trained teams play tanh(mean) (True) or sample (False); default: each team's setting."""


@dataclass(frozen=True)
class ExportTeamArgs:
    """Write a trained team as a compact folder (networks.npz, config.json, MODEL_CARD.md):
    the format of the shipped teams, usable wherever a team or --run.init-from is."""

    team: tyro.conf.Positional[Annotated[str, tyro.conf.arg(metavar="TEAM")]]
    """A checkpoint PATH[@ITERATION] (run, checkpoints or step directory) or a shipped team."""
    out: Path
    """The folder to write (created; files in it are replaced atomically)."""
    card: Path | None = None
    """A Markdown model card to copy in as MODEL_CARD.md."""


@dataclass(frozen=True)
class EnvBenchArgs:
    """Env steps per second with random actions: vmapped scan vs a naive jitted Python loop."""

    players: tuple[int, ...] = (1, 2, 5, 11)
    """Players per team to measure."""
    batch: tuple[int, ...] = (256, 1024)
    """Games per batch for the scan mode."""
    steps: int = 100
    """Steps per timed scan call."""
    repeats: int = 5
    """Timed repeats; the median is reported."""
    loop_steps: int = 200
    """Steps per timed Python-loop call."""
    json: bool = False
    """Print one JSON object per configuration instead of a table."""
    host_devices: int = 1
    """On CPU, split the host into this many XLA devices and shard the batch over them."""
    plot: Path | None = None
    """Also draw the results against players per team, with the thesis' figure 6.1 as
    reference lines (a PNG)."""
    games: tuple[str, ...] = ()
    """Instead, time these games (``env.physics`` names, e.g. thesis rcss skills) side by side
    in scan mode at each --players and --batch (repeats interleaved), each against the first."""


def _set_host_devices(count: int) -> None:
    # XLA reads this once, before JAX initialises its backends.
    if count > 1:
        flag = f"--xla_force_host_platform_device_count={count}"
        os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + flag).strip()


def play(args: PlayArgs) -> Path | None:
    """Play a game and write it to ``args.out`` (and ``args.replay``)."""
    from elevens.runs.memory import check_fits, replay_bytes
    from elevens.runs.play import play_and_render

    # Before the game: a path that cannot be written is refused now, not after it.
    check_output_file("--out", args.out, VIDEO_SUFFIXES)
    steps = 400 if args.steps is None else args.steps
    check_fits("--steps", steps, replay_bytes(args.players, steps), "the recorded game's states")
    if args.replay is not None:
        check_output_file("--replay", args.replay, (".npz",))
    return play_and_render(
        home=args.home, away=args.away, players=args.players, out=args.out,
        seed=args.seed, steps=args.steps, fps=args.fps, scale=args.scale, view=args.view,
        replay=args.replay, deterministic=args.deterministic, follow_ball=args.follow_ball,
    )


def export_team(args: ExportTeamArgs) -> Path:
    """Export ``args.team`` to ``args.out``."""
    from elevens.runs.teams import export_team as export

    card = None if args.card is None else args.card.read_text(encoding="utf-8")
    folder, config = export(args.team, args.out, card)
    print(f"wrote {folder} ({config.learner.env.scenario}, {config.preset} preset)")
    return folder


def bench_env(args: EnvBenchArgs) -> None:
    """Run the env benchmark."""
    if args.plot is not None:
        check_output_file("--plot", args.plot, PLOT_SUFFIXES)
    _set_host_devices(args.host_devices)
    if args.games:
        from elevens.bench.env import run_games_bench

        makers = {name: _bench_game(name) for name in args.games}
        run_games_bench(makers, players=args.players, batch=args.batch, steps=args.steps,
                        repeats=args.repeats, as_json=args.json)
        return
    from elevens.bench.env import run_env_bench

    results = run_env_bench(
        players=args.players, batch=args.batch, steps=args.steps, repeats=args.repeats,
        loop_steps=args.loop_steps, as_json=args.json,
    )
    if args.plot is not None:
        from elevens.bench.env import plot_env_bench

        print(f"wrote {plot_env_bench(results, args.plot)}", file=sys.stderr)


def _bench_game(name: str) -> Any:
    """``players -> (env, params, sample)`` of the registered game ``name`` (``env.physics``);
    random actions from the env's ``sample_actions`` when it has one, else uniform."""
    import elevens.robocup  # noqa: F401 - registers the RoboCup wing's games
    from elevens.bench.env import uniform_actions
    from elevens.train.config import GAMES

    if name not in GAMES:
        raise ValueError(f"--games {name!r} is unknown: known games are {', '.join(sorted(GAMES))}")
    config = GAMES[name]()

    def make(players: int) -> Any:
        env = config.make_env(players)
        own = getattr(env, "sample_actions", None)
        sample = uniform_actions(players, config.actions) if own is None else (
            lambda key, batch: own(key, (batch,)))
        return env, env.default_params(), sample

    return make


COMMANDS: Commands = {
    "play": (PlayArgs, play),
    "export-team": (ExportTeamArgs, export_team),
    "bench-env": (EnvBenchArgs, bench_env),
    "train": (TrainArgs, train_command),
    "bench-train": (TrainBenchArgs, bench_train_command),
    **eval_commands.COMMANDS,
    **exploit_commands.COMMANDS,
    **robocup_commands.COMMANDS,
    **robocup_skills_commands.COMMANDS,
}
"""Every subcommand: name -> (its args dataclass, the function that runs it)."""


def main(argv: list[str] | None = None) -> None:
    """Entry point of the ``elevens`` console script.

    Exit status: 0 done, 2 bad input (one line on stderr), 130 interrupted, 1 anything else
    (with its traceback). ``--debug`` anywhere shows the traceback of bad input too.
    """
    from_command_line = argv is None
    argv = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in argv
    argv = [arg for arg in argv if arg != "--debug"]
    # `elevens bench env ...` reads better than a hyphenated subcommand; accept both.
    if len(argv) >= 2 and argv[0] in ("bench", "robocup") and not argv[1].startswith("-"):
        argv = [f"{argv[0]}-{argv[1]}", *argv[2:]]
    if argv and argv[0] == "train":
        argv = ["train", *command_flags_first(argv[1:])]
    try:  # `robocup train skills-11v11 ...`: the skills fine-tuning's own flags
        argv = robocup_skills_commands.skills_train_argv(argv)
    except ValueError as error:
        print(f"elevens robocup train: error: {one_line(error)}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from None
    name = argv[0] if argv else ""
    if name.startswith(("bench-", "robocup-")):
        name = name.replace("-", " ", 1)
    command = f"elevens {name}".rstrip()
    if argv[:1] == [robocup_skills_commands.TRAIN_COMMAND]:
        command = f"elevens robocup train {robocup_skills_commands.PRESET}"
    args = _parse(argv, command, debug)
    # `robocup team` joins someone else's server: it needs their network.
    starts = (*robocup_commands.STARTS_A_SERVER, *robocup_skills_commands.STARTS_A_SERVER)
    if from_command_line and isinstance(args, starts):
        from elevens.robocup.isolation import enter_private_network

        # rcssserver listens on every interface: the command goes on in a network of its own.
        enter_private_network(command)
    # SIGTERM (kill, a job scheduler) takes Ctrl-C's path: a training run (simulator or
    # RoboCup) writes its checkpoint, and every rcssserver a command started is stopped.
    # SIGKILL cannot be caught.
    previous = signal.signal(signal.SIGTERM, _interrupt)
    try:
        _run(args)
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"{command}: interrupted", file=sys.stderr)
        raise SystemExit(EXIT_INTERRUPTED) from None
    except _expected_errors() as error:
        if debug:
            raise
        print(f"{command}: error: {one_line(error)}", file=sys.stderr)
        raise SystemExit(EXIT_BAD_INPUT) from None
    finally:
        signal.signal(signal.SIGTERM, previous)


def _parse(argv: list[str], command: str, debug: bool) -> object:
    """``tyro.cli`` with its usage errors (an unknown flag, a value that does not parse) as one
    line, like every other bad input (``--debug`` keeps tyro's own box). Help goes through."""
    box = io.StringIO()
    try:
        with contextlib.redirect_stderr(box):
            return tyro.cli(subcommand_union(COMMANDS), args=argv, prog="elevens")
    except SystemExit as stop:
        text = box.getvalue()
        if stop.code == EXIT_BAD_INPUT and text.strip() and not debug:
            print(f"{command}: error: {_tyro_message(text)}", file=sys.stderr)
            raise SystemExit(EXIT_BAD_INPUT) from None
        sys.stderr.write(text)
        raise


def _tyro_message(box: str) -> str:
    """The message inside one of tyro's error boxes, on one line, with a pointer to --help."""
    lines: list[str] = []
    for raw in box.splitlines():
        line = raw.strip().strip("│╭╮╰╯").strip()
        if line.startswith("─") and not line.strip("─ "):
            if lines:
                break  # the message ends where the box's first rule is
            continue
        if line.startswith(("─", "Argument helptext", "For full helptext")) or not line:
            continue
        lines.append(line)
    message = " ".join(lines).replace("__tyro-dummy-inner__.config.", "")
    # A group's own check (EnvParams, PPOHyperparams) is named as its flags are: "env", "ppo".
    message = re.sub(
        r"Error parsing ((?:learner\.)?[\w.]+):",
        lambda match: f"{_flag_group(match.group(1))}:",
        message,
    )
    return message + " (--help lists the options)"


def _flag_group(path: str) -> str:
    from elevens.train.config import short_path

    return short_path(f"{path}.x").rpartition(".")[0]


def _expected_errors() -> tuple[type[BaseException], ...]:
    """What bad input raises: the commands' ValueErrors (ReplayError, RunRefusedError,
    ShippedTeamError ...), missing files (RcssserverNotFound too) and damaged checkpoints."""
    from elevens.train.checkpoint import CheckpointError

    return (ValueError, FileNotFoundError, FileExistsError, NotADirectoryError,
            IsADirectoryError, CheckpointError)


def _interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def _run(args: object) -> None:
    check_numeric_args(args)
    run_command(COMMANDS, args)
