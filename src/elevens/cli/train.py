"""The `elevens train` subcommand (wired into ``elevens.cli``).

``elevens train PRESET [--resume] [--no-progress] [--group.field VALUE ...]``: the preset is a
tyro subcommand whose defaults are that preset's ``TrainConfig``, and every field of the config
is a flag (``--resume`` and ``--no-progress`` may also come before the preset), e.g.::

    elevens train quickstart
    elevens train 2v2 --ppo.learning-rate 3e-4 --run.run-dir runs/a
    elevens train 2v2 --resume --run.run-dir runs/a --run.iterations 8000
    elevens train 2v2 --run.max-minutes 60     # ends like a finished run after an hour

Heavy imports (JAX, the trainer) happen inside the commands, so ``elevens --help`` stays fast.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Annotated, Any, Union

import tyro

import elevens.robocup  # noqa: F401 - registers the games of the RoboCup wing and their presets
from elevens.cli.checks import EXIT_INTERRUPTED, exit_with_error
from elevens.train.config import PRESET_DESCRIPTIONS, PRESETS, TrainConfig, make_config

_PRESET_HELP = {
    "quickstart": "1 v 1 on a small field, 100-step episodes: learns to beat the random team "
    "within minutes on a laptop CPU.",
    "2v2": "The thesis' 4-player setting: random spawns, 400-step episodes, table 6.1.",
    "2v2-gpu": "The 2v2 preset with batches for one GPU (1,024 games an iteration): on an "
    "H200 it beats naive and teamwork at 11 v 11 within 4 minutes.",
    "11v11": "The full game against a Polyak-averaged opponent, table 6.1.",
}

if TYPE_CHECKING:
    PresetConfig = TrainConfig
else:
    # One tyro subcommand per preset, whose defaults are that preset's config.
    PresetConfig = Union[  # noqa: UP007 - a runtime Union built from a generator
        tuple(
            Annotated[
                TrainConfig,
                tyro.conf.subcommand(
                    name, default=make_config(name),
                    description=_PRESET_HELP.get(name) or PRESET_DESCRIPTIONS[name],
                    prefix_name=False,
                ),
            ]
            for name in PRESETS
        )
    ]


@dataclasses.dataclass(frozen=True)
class TrainArgs:
    """Train a team with PPO (thesis Algorithm 4): a preset, then any config field as a flag."""

    config: Annotated[PresetConfig, tyro.conf.arg(name="")] = make_config("quickstart")
    """The run: a preset, with its fields overridden by flags."""
    resume: bool = False
    """Continue from the latest checkpoint in run.run_dir (its config must match)."""
    progress: bool = True
    """Show the progress bar (plain lines when not on a terminal)."""
    resume_from_last_good: bool = False
    """With --resume: if the latest checkpoint is damaged, continue from the newest intact one
    (the damaged ones move to run_dir/damaged_checkpoints; nothing is deleted)."""
    distributed: bool = False
    """One run over several processes (hosts): calls jax.distributed.initialize(). Under SLURM
    or Open MPI nothing else is needed; otherwise give the next three flags on every process."""
    coordinator: str = ""
    """With --distributed: HOST:PORT of process 0."""
    num_processes: int = 0
    """With --distributed: how many processes the run has."""
    process_id: int = -1
    """With --distributed: this process's number, 0 to num_processes - 1."""


def train_command(args: TrainArgs) -> Any:
    """Validate (before anything compiles), train, and print a summary. Returns TrainResult."""
    from elevens.runs.errors import RunRefusedError
    from elevens.runs.loop import train
    from elevens.train.checkpoint import CheckpointError

    try:
        config = args.config.validate()
        given = args.coordinator or args.num_processes or args.process_id >= 0
        if given and not args.distributed:
            raise ValueError(
                "--coordinator, --num-processes and --process-id need --distributed"
            )
        if args.distributed:
            from elevens.train.parallel import initialize_distributed

            # Before anything touches a device: every process joins the run first.
            initialize_distributed(args.coordinator, args.num_processes, args.process_id)
    except ValueError as error:
        # A usage error like the ones tyro reports for a single field: no traceback, exit 2.
        exit_with_error("elevens train: error", error, 2)
    try:
        result = train(
            config, resume=args.resume or args.resume_from_last_good, progress=args.progress,
            resume_from_last_good=args.resume_from_last_good,
        )
    except RunRefusedError as error:  # another run's checkpoints, or a mismatched resume
        exit_with_error("elevens train: error", error, 2)
    except CheckpointError as error:  # a damaged checkpoint: the message names the file
        exit_with_error("elevens train: error", error, 2)
    if result.interrupted:
        state = "interrupted (Ctrl-C or SIGTERM)"
    elif result.out_of_time:
        state = f"time budget of {config.run.max_minutes:g} min reached"
    else:
        state = "done"
    print(
        f"{state}: {result.iteration} iterations, {result.env_steps:,} env steps in "
        f"{result.train_seconds / 60:.1f} min of training (time/hours)"
    )
    outcomes = {k: v for k, v in result.evaluation.items() if k.endswith("/outcome")}
    for name, value in outcomes.items():
        print(f"  {name}: {value:.3f}")
    if result.checkpoint is not None:
        print(f"  checkpoint: {result.checkpoint}")
    for name, path in result.files.items():
        print(f"  {name}: {path}")
    if result.interrupted:
        # 128 + SIGINT, as a shell reports it: a script or scheduler can tell a stopped run
        # (its checkpoint written; --resume continues it) from a finished one.
        raise SystemExit(EXIT_INTERRUPTED)
    return result


COMMAND_FLAGS = (
    "--resume", "--no-resume", "--progress", "--no-progress", "--resume-from-last-good",
    "--no-resume-from-last-good", "--distributed", "--no-distributed",
)
"""TrainArgs' own switches; tyro takes them only before the preset."""
COMMAND_VALUE_FLAGS = ("--coordinator", "--num-processes", "--process-id")
"""TrainArgs' own flags that take a value (``--flag VALUE`` or ``--flag=VALUE``)."""


def command_flags_first(args: Sequence[str]) -> list[str]:
    """The arguments of `elevens train` with its own flags (``COMMAND_FLAGS``,
    ``COMMAND_VALUE_FLAGS`` with their values) moved in front of the preset, so that
    ``elevens train 2v2 --resume`` works like ``elevens train --resume 2v2``. The order of
    everything else is kept."""
    own: list[str] = []
    rest: list[str] = []
    index = 0
    while index < len(args):
        arg = args[index]
        if arg in COMMAND_FLAGS or arg.split("=", 1)[0] in COMMAND_VALUE_FLAGS and "=" in arg:
            own.append(arg)
        elif arg in COMMAND_VALUE_FLAGS:
            own.extend(args[index : index + 2])
            index += 1
        else:
            rest.append(arg)
        index += 1
    return own + rest
