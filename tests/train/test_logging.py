"""Run logging: CSV contents, TensorBoard scalars read back, events, the progress display."""

from __future__ import annotations

import io
import struct
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
from rich.console import Console
from tensorboardX.proto import event_pb2

from elevens.runs.logging import (
    EVENTS_LOG,
    METRICS_CSV,
    RunLogger,
    TrainProgress,
    read_metrics_csv,
)


def read_tensorboard_events(run_dir: Path) -> list[event_pb2.Event]:
    """All events of a run's TensorBoard files, parsed from the TFRecord framing by hand.

    A record is: u64 length, u32 CRC of the length, ``length`` bytes of Event proto, u32 CRC.
    (The ``tensorboard`` package, whose reader would do this, is not a dependency.)
    """
    events = []
    files = sorted(run_dir.glob("events.out.tfevents.*"))
    assert files, f"no TensorBoard event file in {run_dir}"
    for path in files:
        data = path.read_bytes()
        offset = 0
        while offset < len(data):
            (length,) = struct.unpack_from("<Q", data, offset)
            payload = data[offset + 12 : offset + 12 + length]
            assert len(payload) == length, f"truncated record in {path}"
            events.append(event_pb2.Event.FromString(payload))
            offset += 12 + length + 4
    return events


def scalars(events: list[event_pb2.Event]) -> dict[str, list[tuple[int, float]]]:
    out: dict[str, list[tuple[int, float]]] = {}
    for event in events:
        for value in event.summary.value:
            if value.HasField("simple_value"):
                out.setdefault(value.tag, []).append((event.step, value.simple_value))
    return out


def test_csv_long_format_with_changing_keys(tmp_path: Path) -> None:
    with RunLogger(tmp_path, use_tensorboard=False) as logger:
        logger.log(0, {"train/loss": 1.5})
        logger.log(1, {"train/loss": jnp.float32(0.25), "eval/win_rate_naive": np.float64(0.125)})
        logger.log(2, {"env/sps": 123456, "train/kl": float("nan")})
    lines = (tmp_path / METRICS_CSV).read_text().splitlines()
    assert lines == [
        "step,name,value",
        "0,train/loss,1.5",
        "1,train/loss,0.25",
        "1,eval/win_rate_naive,0.125",
        "2,env/sps,123456.0",
        "2,train/kl,nan",
    ]
    curves = read_metrics_csv(tmp_path / METRICS_CSV)
    assert set(curves) == {"train/loss", "eval/win_rate_naive", "env/sps", "train/kl"}
    steps, values = curves["train/loss"]
    np.testing.assert_array_equal(steps, [0, 1])
    np.testing.assert_array_equal(values, [1.5, 0.25])
    assert steps.dtype == np.int64 and values.dtype == np.float64
    assert np.isnan(curves["train/kl"].values[0])
    assert not list(tmp_path.glob("events.out.tfevents.*"))


def test_resumed_run_appends_and_last_value_wins(tmp_path: Path) -> None:
    with RunLogger(tmp_path, use_tensorboard=False) as logger:
        for step in range(4):
            logger.log(step, {"train/score": step / 10})
    # Resumed from a checkpoint at step 1: steps 2 and 3 are logged again with new values,
    # and the old rows of those steps are gone (one row per step and metric).
    with RunLogger(tmp_path, use_tensorboard=False, resumed_at=1) as logger:
        for step in range(2, 6):
            logger.log(step, {"train/score": 1.0 + step})
    text = (tmp_path / METRICS_CSV).read_text()
    assert text.count("step,name,value") == 1
    assert text.splitlines()[1:] == [f"{step},train/score,{value!r}" for step, value in
                                     [(0, 0.0), (1, 0.1), (2, 3.0), (3, 4.0), (4, 5.0),
                                      (5, 6.0)]]
    steps, values = read_metrics_csv(tmp_path)["train/score"]  # a run directory works too
    np.testing.assert_array_equal(steps, [0, 1, 2, 3, 4, 5])
    np.testing.assert_allclose(values, [0.0, 0.1, 3.0, 4.0, 5.0, 6.0])


def test_refuses_foreign_csv_and_bad_values(tmp_path: Path) -> None:
    (tmp_path / METRICS_CSV).write_text("step,loss\n0,1.0\n")
    with pytest.raises(ValueError, match="header"):
        RunLogger(tmp_path, use_tensorboard=False)
    with (
        RunLogger(tmp_path / "ok", use_tensorboard=False) as logger,
        pytest.raises(ValueError, match="train/loss"),
    ):
        logger.log(0, {"train/loss": np.ones(3)})
    with (tmp_path / "ok" / METRICS_CSV).open("a") as handle:
        handle.write("7,train/loss\n")  # a cut-off last line
    with pytest.raises(ValueError, match="line 2"):
        read_metrics_csv(tmp_path / "ok")


def test_tensorboard_scalars_and_events(tmp_path: Path) -> None:
    with RunLogger(tmp_path, use_csv=False) as logger:
        logger.log(10, {"train/loss": 0.5, "eval/win_rate_naive": 0.75})
        logger.log(20, {"train/loss": 0.25})
        logger.event(20, "shaping switched off")
        logger.event(30, "league snapshot\nadded")
    assert not (tmp_path / METRICS_CSV).exists()

    events = read_tensorboard_events(tmp_path)
    assert scalars(events) == {
        "train/loss": [(10, 0.5), (20, 0.25)],
        "eval/win_rate_naive": [(10, 0.75)],
    }
    texts = [
        (event.step, value.tensor.string_val[0].decode())
        for event in events
        for value in event.summary.value
        if value.tag.startswith("events")
    ]
    assert texts == [(20, "shaping switched off"), (30, "league snapshot added")]

    lines = (tmp_path / EVENTS_LOG).read_text().splitlines()
    assert len(lines) == 2
    assert lines[0].endswith(" step=20 shaping switched off")
    assert lines[1].endswith(" step=30 league snapshot added")


def test_closed_logger_refuses_to_log(tmp_path: Path) -> None:
    logger = RunLogger(tmp_path, use_tensorboard=False)
    logger.close()
    logger.close()  # idempotent
    with pytest.raises(RuntimeError, match="closed"):
        logger.log(0, {"train/loss": 1.0})


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_progress_prints_plain_lines_when_not_a_terminal() -> None:
    stream = io.StringIO()
    console = Console(file=stream)  # a StringIO is not a terminal, like stdout on CI
    clock = FakeClock()
    with TrainProgress(
        25,
        metrics=("train/score", "eval/win_rate_naive"),
        plain_every=10,
        console=console,
        clock=clock,
    ) as progress:
        assert progress.plain
        for iteration in range(1, 26):
            clock.now += 2.0
            metrics = {"train/score": 0.5, "train/loss": 9.0}
            if iteration % 10 == 0:
                metrics["eval/win_rate_naive"] = 0.8
            progress.update(iteration, env_steps=1000 * iteration, metrics=metrics)
    lines = stream.getvalue().splitlines()
    # The first update, every 10th, and the last.
    assert [line.split(" | ")[0] for line in lines] == [
        "train 1/25",
        "train 10/25",
        "train 20/25",
        "train 25/25",
    ]
    assert lines[1] == (
        "train 10/25 | 500 env steps/s | env steps 10,000 | train/score 0.5 "
        "| eval/win_rate_naive 0.8"
    )
    assert "train/loss" not in stream.getvalue()  # only the chosen metrics
    assert "\x1b" not in stream.getvalue()  # no terminal control codes


def test_progress_bar_on_a_terminal() -> None:
    stream = io.StringIO()
    console = Console(file=stream, force_terminal=True, width=160)
    with TrainProgress(4, metrics=("train/score",), console=console) as progress:
        assert not progress.plain
        for iteration in range(1, 5):
            progress.update(iteration, 512 * iteration, {"train/score": 0.25})
    output = stream.getvalue()
    assert "4/4" in output
    assert "train/score 0.25" in output
