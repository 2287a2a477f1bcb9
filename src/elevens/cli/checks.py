"""What every subcommand shares: one-line errors, range checks, and the command tables.

Exit status of every ``elevens`` command: 0 done, 2 bad input (one line on stderr), 130
interrupted (a training run after its checkpoint), 1 anything else (with its traceback).
"""

from __future__ import annotations

import math
import sys
import tempfile
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Annotated, Any, NoReturn, Union

import tyro

EXIT_BAD_INPUT = 2
"""A command refused for its input: a bad value, an unknown team, a missing or damaged file, a
missing rcssserver."""
EXIT_INTERRUPTED = 130
"""A command stopped by Ctrl-C or SIGTERM (128 + SIGINT, as a shell reports it)."""
LARGEST_INT = 2**31 - 1
"""The largest whole number a flag takes: JAX counts steps, games and seeds in int32, and a
larger one is an OverflowError deep inside a compile."""
VIDEO_SUFFIXES = (".gif", ".mp4")
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff",
                 ".webp")
"""What matplotlib writes (the plots of curves, bench env --plot, tournament, analyze)."""


def one_line(error: BaseException) -> str:
    """An error's message on one line (the lines of a multi-line message joined by '; ')."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return "; ".join(lines) or type(error).__name__


def exit_with_error(prefix: str, error: BaseException, code: int = EXIT_BAD_INPUT) -> NoReturn:
    """Print ``prefix: error`` to stderr on one line and exit with ``code``, no traceback."""
    print(f"{prefix}: {one_line(error)}", file=sys.stderr)
    raise SystemExit(code) from None


NUMERIC_RANGES: dict[str, tuple[float, float]] = {
    # flag name: (lowest, highest) allowed, for every numeric flag of every subcommand
    "games": (1, math.inf),
    "players": (1, 11),
    "steps": (1, math.inf),
    "episodes": (1, math.inf),
    "servers": (1, math.inf),
    "iterations": (1, math.inf),
    "batch": (1, math.inf),
    "repeats": (1, math.inf),
    "loop_steps": (1, math.inf),
    "host_devices": (1, math.inf),
    "episode_length": (1, math.inf),
    "chunk_size": (1, math.inf),
    "see_period": (1, math.inf),
    "bootstrap": (0, math.inf),
    "replays": (0, math.inf),
    "fps": (1, math.inf),
    "scale": (1, math.inf),
    "cycles": (1, math.inf),
    "checkpoint_every": (1, math.inf),
    "port": (0, 65535),
    "seed": (0, 2**31 - 1),
    "randomize": (0, 2**31 - 1),  # the seed of the held-out randomised games
    "view": (0, math.inf),
    "threshold": (0.0, 1.0),
    "minutes": (1e-9, math.inf),
    "eval_every": (1, math.inf),
    "eval_games": (1, math.inf),
    "learning_rate": (1e-12, math.inf),
    "follow_ball": (1.0, math.inf),
    "num_processes": (0, math.inf),
    "process_id": (-1, math.inf),
    "devices": (1, math.inf),
    "minibatch_size": (1, math.inf),
    "deadline_ms": (1.0, 10_000.0),
    "gather_ms": (0.1, 10_000.0),
    "top_k": (1, math.inf),
    "explore": (0.0, 1.0),
    "l2": (0.0, math.inf),
    "margin": (0.0, math.inf),
}
"""Every numeric field of the subcommands' args, by name (tests/test_cli.py checks that none is
missing). Finer checks that need the game (``--view`` against the players) come later."""


def check_numeric_args(args: object) -> None:
    """Raise ``ValueError`` naming the first numeric flag of ``args`` (a subcommand's args
    dataclass) outside ``NUMERIC_RANGES``: before anything is compiled or started."""
    import dataclasses

    if not dataclasses.is_dataclass(args):
        return
    for field in dataclasses.fields(args):
        value = getattr(args, field.name)
        values = value if isinstance(value, tuple) else (value,)
        numbers = [v for v in values if isinstance(v, int | float) and not isinstance(v, bool)]
        if not numbers or field.name not in NUMERIC_RANGES:
            continue
        low, high = NUMERIC_RANGES[field.name]
        flag = "--" + field.name.replace("_", "-")
        for number in numbers:
            if isinstance(number, int):
                high = min(high, LARGEST_INT)
            if not (math.isfinite(number) and low <= number <= high):
                allowed = (
                    f">= {_number(low)}" if high == math.inf
                    else f"from {_number(low)} to {_number(high)}"
                )
                raise ValueError(f"{flag}={number!r} is invalid: it must be {allowed}")


def _number(value: float) -> str:
    return str(int(value)) if float(value).is_integer() else f"{value:g}"


def check_output_file(flag: str, path: Path, suffixes: Sequence[str]) -> None:
    """Raise ``ValueError`` naming ``flag`` unless ``path`` ends in one of ``suffixes`` and can
    be written (its folder may be missing: the command creates it): before the work whose
    result it holds. Nothing is created."""
    if path.suffix.lower() not in suffixes:
        raise ValueError(
            f"{flag} {str(path)!r} is invalid: the suffix must be {' or '.join(suffixes)}"
        )
    if path.is_dir():
        raise ValueError(f"{flag} {str(path)!r} is a folder; give a file name")
    _check_writable(flag, path, path.parent)


def check_output_dir(flag: str, path: Path) -> None:
    """Raise ``ValueError`` naming ``flag`` unless ``path`` is (or can be made) a folder this
    user can write: before the games whose results go there. Nothing is created."""
    if path.exists() and not path.is_dir():
        raise ValueError(f"{flag} {str(path)!r} is a file; give a folder (created if missing)")
    _check_writable(flag, path, path)


def _check_writable(flag: str, given: Path, folder: Path) -> None:
    """``folder``, or the nearest of its parents that exists (the rest is created later), is
    a folder in which this user can create a file (tried: permissions alone do not tell, e.g.
    in /proc or on a read-only mount)."""
    existing = folder.absolute()
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ValueError(f"{flag} {str(given)!r} cannot be written: {existing} is a file")
    try:
        with tempfile.TemporaryFile(dir=existing):
            pass
    except OSError as error:
        why = error.strerror or type(error).__name__
        raise ValueError(f"{flag} {str(given)!r} cannot be written in {existing}: {why}") from None


Handler = Callable[[Any], Any]
Commands = dict[str, tuple[type, Handler]]
"""Subcommand name -> (its args dataclass, the function that runs it): each CLI module's
table, and ``elevens.cli.app``'s union of them."""


def subcommand_union(commands: Commands) -> Any:
    """The tyro union of ``commands``' args types, each under its subcommand name."""
    members = tuple(
        Annotated[args_type, tyro.conf.subcommand(name)]
        for name, (args_type, _) in commands.items()
    )
    return Union[members]  # noqa: UP007 (built at run time from the table)


def run_command(commands: Commands, args: object) -> Any:
    """Run the handler of ``args``'s type in ``commands``."""
    handlers = {args_type: handler for args_type, handler in commands.values()}
    return handlers[type(args)](args)
