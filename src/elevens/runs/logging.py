"""Run logs: TensorBoard scalars, a CSV of every metric, an events log, and a progress display.

Everything here is host-side Python, called between compiled training chunks.

Files a ``RunLogger`` writes into its run directory:

* ``events.out.tfevents.*``: TensorBoard scalars (tensorboardX), one tag per metric name, plus the
  events as text under the ``events`` tag. Point ``tensorboard --logdir`` at the parent of runs.
* ``metrics.csv``: LONG format, one row per (step, metric): ``step,name,value``. Long format
  because metrics come and go during a run (evaluation every k iterations, a league metric that
  appears later); a wide CSV would need its header rewritten whenever a new key shows up, which is
  neither append-only nor crash-safe. Rows are flushed after every ``log`` call, so a killed run
  loses nothing. ``read_metrics_csv`` turns it back into one curve per metric.
* ``events.log``: one line per notable event (``2025-01-31T12:00:00 step=1200 shaping off``).

Metric names are kept exactly as given; by convention they are namespaced ``train/...``,
``eval/...``, ``env/...``, which TensorBoard groups into sections.
"""

from __future__ import annotations

import csv
import datetime
import io
import math
import os
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any, NamedTuple, TextIO

import numpy as np
from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from elevens.files import write_atomically

METRICS_CSV = "metrics.csv"
EVENTS_LOG = "events.log"
CSV_HEADER = ("step", "name", "value")
EVENTS_TAG = "events"
"""TensorBoard text tag under which ``RunLogger.event`` messages appear."""


def _as_float(name: str, value: Any) -> float:
    """A metric value as a Python float; only scalars (0-d arrays included) are metrics."""
    array = np.asarray(value)
    if array.ndim != 0:
        raise ValueError(f"metric {name!r} must be a scalar, got an array of shape {array.shape}")
    try:
        return float(array)
    except (TypeError, ValueError) as error:
        raise ValueError(f"metric {name!r} is not a number: {value!r}") from error


class RunLogger:
    """Writes metrics to TensorBoard and ``metrics.csv`` and events to ``events.log``.

    Example::

        with RunLogger("runs/a") as logger:
            logger.log(iteration, {"train/loss": loss, "env/sps": sps})
            logger.event(iteration, "shaping switched off")

    Reopening an existing run directory (a resumed run) appends to its files.

    Args:
        run_dir: the run's directory (created if missing).
        use_tensorboard: write TensorBoard event files.
        use_csv: write ``metrics.csv``.
        resumed_at: a resumed run's checkpoint step: rows of ``metrics.csv`` after it were
            logged by iterations that the resumed run plays again, so they are dropped first
            (the file is rewritten atomically) and the CSV keeps one row per step and metric.
    """

    def __init__(
        self, run_dir: str | os.PathLike[str], use_tensorboard: bool = True, use_csv: bool = True,
        resumed_at: int | None = None,
    ) -> None:
        self.run_dir = Path(run_dir)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        self.csv_path = self.run_dir / METRICS_CSV
        self.events_path = self.run_dir / EVENTS_LOG
        self._csv_file: TextIO | None = None
        self._csv_writer: Any = None
        if use_csv:
            if resumed_at is not None:
                _drop_rows_after(self.csv_path, resumed_at)
            self._csv_file = self._open_csv(self.csv_path)
            self._csv_writer = csv.writer(self._csv_file, lineterminator="\n")
        self._writer: Any = None
        if use_tensorboard:
            # Imported here so that reading CSVs (plots, tests) does not pull in protobuf.
            from tensorboardX import SummaryWriter

            self._writer = SummaryWriter(logdir=str(self.run_dir))
        self._closed = False

    @staticmethod
    def _open_csv(path: Path) -> TextIO:
        exists = path.is_file() and path.stat().st_size > 0
        if exists:
            with path.open(newline="", encoding="utf-8") as existing:
                header = next(csv.reader(existing), None)
            if tuple(header or ()) != CSV_HEADER:
                raise ValueError(
                    f"{path} exists but is not a metrics CSV of this format (header {header}, "
                    f"expected {','.join(CSV_HEADER)}); refusing to append to it"
                )
        handle = path.open("a", newline="", encoding="utf-8")
        if not exists:
            handle.write(",".join(CSV_HEADER) + "\n")
            handle.flush()
        return handle

    def log(self, step: int, metrics: Mapping[str, Any]) -> None:
        """Records scalar metrics at ``step``; values may be floats, ints or 0-d arrays."""
        self._check_open()
        step = int(step)
        values = {name: _as_float(name, value) for name, value in metrics.items()}
        if self._csv_writer is not None and self._csv_file is not None:
            # repr(float) is the shortest string that parses back to the same float (nan, inf too).
            self._csv_writer.writerows((step, name, repr(v)) for name, v in values.items())
            self._csv_file.flush()
        if self._writer is not None:
            for name, value in values.items():
                self._writer.add_scalar(name, value, step)
            self._writer.flush()

    def event(self, step: int, message: str) -> None:
        """Records a notable event ("shaping switched off") in ``events.log`` and TensorBoard."""
        self._check_open()
        step = int(step)
        one_line = " ".join(str(message).splitlines())
        stamp = datetime.datetime.now().isoformat(timespec="seconds")
        with self.events_path.open("a", encoding="utf-8") as events:
            events.write(f"{stamp} step={step} {one_line}\n")
        if self._writer is not None:
            self._writer.add_text(EVENTS_TAG, one_line, step)
            self._writer.flush()

    def flush(self) -> None:
        if self._csv_file is not None:
            self._csv_file.flush()
        if self._writer is not None:
            self._writer.flush()

    def close(self) -> None:
        """Flushes and closes the files; calling it again does nothing."""
        if self._closed:
            return
        self._closed = True
        if self._csv_file is not None:
            self._csv_file.close()
        if self._writer is not None:
            self._writer.close()

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError(f"RunLogger for {self.run_dir} is closed")

    def __enter__(self) -> RunLogger:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class Curve(NamedTuple):
    """One metric over a run, sorted by step."""

    steps: np.ndarray  # i64[T]
    values: np.ndarray  # f64[T]


def _drop_rows_after(path: Path, step: int) -> None:
    """Rewrite ``path`` (a metrics CSV) without the rows of steps after ``step``, atomically;
    a missing, empty or foreign file is left to ``_open_csv``."""
    if not path.is_file() or path.stat().st_size == 0:
        return
    with path.open(newline="", encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    if not rows or tuple(rows[0]) != CSV_HEADER:
        return
    kept = [row for row in rows[1:] if not (row and row[0].isdigit() and int(row[0]) > step)]
    if len(kept) == len(rows) - 1:
        return
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(CSV_HEADER)
    writer.writerows(kept)
    write_atomically(path, lambda handle: handle.write(text.getvalue().encode("utf-8")))


def read_metrics_csv(path: str | os.PathLike[str]) -> dict[str, Curve]:
    """Reads a ``metrics.csv`` (or a run directory holding one) into one curve per metric name.

    A resumed run may log some steps twice (those after its last checkpoint); the row written
    last wins, since it belongs to the run that continued.

    Returns:
        ``{name: Curve(steps i64[T], values f64[T])}``, steps ascending and unique per name.
    """
    path = Path(path)
    if path.is_dir():
        path = path / METRICS_CSV
    per_name: dict[str, dict[int, float]] = {}
    allowed = "give a run directory or its metrics.csv"
    with path.open(newline="", encoding="utf-8") as handle:
        reader = csv.reader(handle)
        try:
            header = next(reader, None)
        except UnicodeDecodeError:
            raise ValueError(f"{path} is not a metrics.csv (not text); {allowed}") from None
        if tuple(header or ()) != CSV_HEADER:
            raise ValueError(
                f"{path} is not a metrics.csv (header {header}, expected "
                f"{','.join(CSV_HEADER)}); {allowed}"
            )
        for line_number, row in enumerate(reader, start=2):
            if not row:
                continue
            try:
                step_text, name, value_text = row
                step, value = int(step_text), float(value_text)
            except ValueError as error:
                # A run killed mid-write can leave a partial last line; name it, do not guess.
                raise ValueError(f"{path}, line {line_number}: malformed row {row}") from error
            per_name.setdefault(name, {})[step] = value
    curves = {}
    for name, by_step in per_name.items():
        steps = np.array(sorted(by_step), dtype=np.int64)
        values = np.array([by_step[s] for s in steps.tolist()], dtype=np.float64)
        curves[name] = Curve(steps, values)
    return curves


# --------------------------------------------------------------------------------------------
# Progress display
# --------------------------------------------------------------------------------------------


def _format_metric(value: float) -> str:
    return f"{value:.4g}" if math.isfinite(value) else str(value)


class TrainProgress:
    """A progress bar for training: iteration / total, env steps per second, chosen metrics.

    On a terminal it is a ``rich.progress.Progress`` bar. When the output is not a terminal (CI,
    a log file, ``nohup``), a bar would spray control codes, so it prints one plain line at the
    first update, then every ``plain_every`` updates, and at the last iteration::

        train 120/1000 | 52,310 env steps/s | env steps 1,228,800 | train/score 0.31

    Example::

        with TrainProgress(total=1000, metrics=("train/score", "eval/win_rate_naive")) as bar:
            for it in range(1000):
                ...
                bar.update(it + 1, env_steps, metrics)

    Args:
        total: iterations in the run.
        metrics: metric names to show when present in an update (in this order).
        start: iteration the run starts (or resumes) from.
        start_env_steps: env steps already done at ``start`` (for the steps-per-second rate).
        plain_every: in plain (non-terminal) mode, print every this many updates.
        console: where to draw; by default a ``rich.console.Console`` on stdout.
        plain: force plain lines (True) or the bar (False); ``None`` picks the bar exactly when
            ``console.is_terminal``.
        description: the label in front of the count.
        clock: seconds, monotonic (``time.perf_counter``; injectable for tests).
    """

    def __init__(
        self,
        total: int,
        *,
        metrics: Sequence[str] = (),
        start: int = 0,
        start_env_steps: int = 0,
        plain_every: int = 10,
        console: Console | None = None,
        plain: bool | None = None,
        description: str = "train",
        clock: Callable[[], float] = time.perf_counter,
    ) -> None:
        if plain_every < 1:
            raise ValueError(f"plain_every must be >= 1, got {plain_every}")
        self.total = int(total)
        self.metric_names = tuple(metrics)
        self.plain_every = plain_every
        self.description = description
        self.console = console if console is not None else Console()
        self.plain = (not self.console.is_terminal) if plain is None else plain
        self._clock = clock
        self._last_time = clock()
        self._last_env_steps = int(start_env_steps)
        self._updates = 0
        self._closed = False
        self.last_line = ""
        self._progress: Progress | None = None
        self._task: TaskID | None = None
        if not self.plain:
            self._progress = Progress(
                TextColumn("[bold]{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TimeElapsedColumn(),
                TimeRemainingColumn(),
                TextColumn("{task.fields[info]}"),
                console=self.console,
            )
            self._task = self._progress.add_task(
                description, total=self.total, completed=start, info=""
            )
            self._progress.start()

    def update(
        self, iteration: int, env_steps: int, metrics: Mapping[str, Any] | None = None
    ) -> None:
        """Reports that ``iteration`` iterations and ``env_steps`` env steps are done in total.

        Steps per second is measured since the previous update (the first one includes any
        compilation, so it reads low).
        """
        now = self._clock()
        elapsed = now - self._last_time
        sps = (int(env_steps) - self._last_env_steps) / elapsed if elapsed > 0 else float("nan")
        self._last_time, self._last_env_steps = now, int(env_steps)
        self._updates += 1
        parts = [f"{sps:,.0f} env steps/s", f"env steps {int(env_steps):,}"]
        for name in self.metric_names:
            if metrics is not None and name in metrics:
                parts.append(f"{name} {_format_metric(_as_float(name, metrics[name]))}")
        info = " | ".join(parts)
        if self._progress is not None and self._task is not None:
            self._progress.update(self._task, completed=int(iteration), info=info)
            return
        self.last_line = f"{self.description} {int(iteration)}/{self.total} | {info}"
        due = self._updates == 1 or self._updates % self.plain_every == 0
        if due or int(iteration) >= self.total:
            print(self.last_line, file=self.console.file, flush=True)

    def note(self, message: str) -> None:
        """A line of its own above the bar (or between plain lines): what the run is doing
        while the bar cannot move, such as compiling."""
        if self._progress is not None:
            self._progress.console.print(message, markup=False, highlight=False)
        else:
            print(message, file=self.console.file, flush=True)

    def close(self) -> None:
        """Stops the bar (leaving its last state on screen); calling it again does nothing."""
        if self._closed:
            return
        self._closed = True
        if self._progress is not None:
            self._progress.stop()

    def __enter__(self) -> TrainProgress:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()
