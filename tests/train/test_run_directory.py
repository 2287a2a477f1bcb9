"""Opening a run directory: one process holds it (elevens.runs.lock), a resume needs a run and
says where it continues from, and a damaged checkpoint is one line on stderr."""

from __future__ import annotations

import asyncio
import gc
import logging
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from elevens.cli import main
from elevens.runs.errors import RunRefusedError
from elevens.runs.lock import lock_run_directory
from elevens.runs.loop import train
from elevens.train import checkpoint as checkpoint_module
from elevens.train import learner as learner_module
from elevens.train.checkpoint import Checkpointer

REPO = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(REPO / "src")}
WAIT_S = 600  # an upper bound on a loaded machine; the tests wait on output, not on time


def _holder(run_dir: Path) -> subprocess.Popen[str]:
    """Another process that holds ``run_dir``'s lock until killed (started; waited on until it
    says it holds it)."""
    code = (
        "import sys, time\n"
        "from elevens.runs.lock import lock_run_directory\n"
        "lock = lock_run_directory(sys.argv[1])\n"
        "print('held', flush=True)\n"
        "time.sleep(3600)\n"
    )
    process = subprocess.Popen(
        [sys.executable, "-c", code, str(run_dir)], stdout=subprocess.PIPE, text=True, env=ENV
    )
    assert process.stdout is not None and process.stdout.readline().strip() == "held"
    return process


def _stop(process: subprocess.Popen[str]) -> None:
    process.kill()
    process.wait(WAIT_S)
    if process.stdout is not None:
        process.stdout.close()  # an open pipe warns when collected, in whichever test that is


@pytest.fixture
def held(tmp_path: Path) -> Iterator[tuple[Path, subprocess.Popen[str]]]:
    run_dir = tmp_path / "run"
    process = _holder(run_dir)
    try:
        yield run_dir, process
    finally:
        _stop(process)


def _no_compile(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(*args: Any, **kwargs: Any) -> Any:
        raise AssertionError("a learner was built (compiled) before the refusal")

    monkeypatch.setattr(learner_module, "make_learner", refuse)
    monkeypatch.setattr("elevens.runs.loop.make_learner", refuse)


def test_a_held_run_directory_is_refused_naming_the_holder_and_freed_by_kill_9(
    held: tuple[Path, subprocess.Popen[str]],
) -> None:
    run_dir, process = held
    assert (run_dir / "lock").read_text().strip() == str(process.pid)
    with pytest.raises(RunRefusedError, match=rf"in use by another run \(process {process.pid}\)"):
        lock_run_directory(run_dir)
    process.send_signal(signal.SIGKILL)
    process.wait(WAIT_S)
    lock = lock_run_directory(run_dir)  # the kernel let go of the dead process's lock
    assert lock.held and (run_dir / "lock").read_text().strip() == str(os.getpid())
    lock.release()
    lock_run_directory(run_dir).release()  # released, it can be taken again


def test_a_second_train_command_exits_2_with_one_line_naming_the_holder(
    held: tuple[Path, subprocess.Popen[str]], monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
) -> None:
    run_dir, process = held
    _no_compile(monkeypatch)  # refused before the learner was built
    with pytest.raises(SystemExit) as exit_info:
        main(["train", "quickstart", "--run.run-dir", str(run_dir), "--no-progress"])
    assert exit_info.value.code == 2
    printed = capsys.readouterr()
    lines = printed.err.splitlines()
    assert len(lines) == 1 and f"(process {process.pid})" in lines[0], printed.err
    assert "compiling" not in printed.out


def test_train_and_resume_refuse_a_held_directory_before_building_the_learner(
    held: tuple[Path, subprocess.Popen[str]], monkeypatch: pytest.MonkeyPatch,
) -> None:
    from tests.train.test_trainer import tiny_config

    run_dir, process = held
    _no_compile(monkeypatch)
    for resume in (False, True):
        with pytest.raises(RunRefusedError, match=rf"\(process {process.pid}\)"):
            train(tiny_config(run_dir), resume=resume, progress=False)


def test_robocup_train_refuses_a_held_directory_before_building_the_learner(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from elevens.robocup.train import train_robocup
    from tests.robocup.test_train_play import small_config

    process = _holder(tmp_path / "run")  # small_config's run directory
    try:
        monkeypatch.setattr(learner_module, "make_learner", _refuse)
        with pytest.raises(RunRefusedError, match=rf"\(process {process.pid}\)"):
            train_robocup(small_config(tmp_path), env_factory=_refuse, progress=False)
    finally:
        _stop(process)


def _refuse(*args: Any, **kwargs: Any) -> Any:
    raise AssertionError("called before the refusal")


def test_a_run_directory_that_cannot_be_one_is_refused_naming_the_flag(tmp_path: Path) -> None:
    a_file = tmp_path / "a_file"
    a_file.write_text("x")
    with pytest.raises(RunRefusedError, match=r"--run.run-dir '.*a_file' is not a directory"):
        lock_run_directory(a_file)
    with pytest.raises(RunRefusedError, match=r"--run.run-dir '.*a_file/run' cannot hold a run"):
        lock_run_directory(a_file / "run")


def test_resume_of_a_directory_without_a_run_is_refused_and_creates_nothing(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
) -> None:
    from tests.train.test_trainer import tiny_config

    _no_compile(monkeypatch)
    typo = tmp_path / "tpyo"
    with pytest.raises(RunRefusedError, match=rf"cannot resume: {typo} holds no run"):
        train(tiny_config(typo), resume=True, progress=False)
    assert not typo.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(RunRefusedError, match=rf"cannot resume: {empty} holds no run"):
        train(tiny_config(empty), resume=True, progress=False)
    lock_run_directory(empty).release()  # the refused run let go of the directory


def _flags(overrides: dict[str, Any]) -> list[str]:
    """``elevens train`` flags for make_config overrides."""
    flags: list[str] = []
    for key, value in overrides.items():
        group, _, name = key.rpartition(".")
        prefix = f"--{group}." if group else "--"
        name = name.replace("_", "-")
        if isinstance(value, bool):
            flags.append(f"{prefix}{name}" if value else f"{prefix}no-{name}")
        elif isinstance(value, tuple):
            flags += [f"{prefix}{name}", *map(str, value)]
        else:
            flags += [f"{prefix}{name}", str(value)]
    return flags


def test_a_truncated_checkpoint_is_one_stderr_line_and_a_resume_says_where_it_goes_on(
    tmp_path: Path, capsys: pytest.CaptureFixture[str],
) -> None:
    from tests.train.test_trainer import BASE, tiny_config

    overrides = {"run.iterations": 4, "run.eval_every": 0, "run.checkpoint_every": 2}
    # No evaluation at the end (a resume may change the teams): nothing here reads one.
    unevaluated = {**overrides, "run.eval_teams": ()}
    first = train(tiny_config(tmp_path, **unevaluated), progress=False)
    # Every resume says where it continues from (here: the finished run's last checkpoint).
    assert train(tiny_config(tmp_path, **unevaluated), resume=True, progress=False).iteration == 4
    saved = Checkpointer(tmp_path / "checkpoints").read_metadata(4)
    expected = (
        f"resuming {tmp_path} from iteration 4 ({first.env_steps:,} env steps, "
        f"{saved['train_seconds'] / 60:.1f} min of training)"
    )
    assert expected in capsys.readouterr().out.splitlines()
    # Truncate the array data files of the newest checkpoint: Orbax's first failed read ends
    # its event loop while its other reads are in flight (whose callbacks printed 433 and 727
    # lines of tracebacks in two tries).
    state = tmp_path / "checkpoints" / "4" / "state"
    for data in state.glob("ocdbt.process_0/d/*"):
        os.truncate(data, 100)
    command = [
        sys.executable, "-m", "elevens", "train", "quickstart", "--resume", "--no-progress",
        *_flags({**BASE, **overrides, "run.iterations": 6, "run.run_dir": str(tmp_path)}),
    ]
    for _ in range(3):  # the stray callbacks race the process's exit: not every try has them
        finished = subprocess.run(
            command, capture_output=True, text=True, env=ENV, timeout=WAIT_S
        )
        assert finished.returncode == 2, finished.stderr[-2000:]
        lines = finished.stderr.splitlines()
        assert len(lines) <= 2, f"{len(lines)} stderr lines: {finished.stderr[-2000:]}"
        assert lines[-1].startswith("elevens train: error: corrupt checkpoint")
        assert "pass --resume-from-last-good" in lines[-1]
    # A failed read leaves the filter that drops its sibling reads' late errors (the read fails
    # by hand here: a real one leaves reads in flight after the test).
    config = tiny_config(tmp_path, **overrides)
    target = learner_module.train_state_shape(config.learner, config.learner.make_env(), devices=1)
    checkpointer = Checkpointer(tmp_path / "checkpoints")
    manager = checkpointer._get_manager()

    class Failing:
        def __getattr__(self, name: str) -> Any:
            return getattr(manager, name)

        def restore(self, *_: Any, **__: Any) -> None:
            raise ValueError(f"OUT_OF_RANGE at {tmp_path / 'checkpoints' / '4' / 'state'}")

    checkpointer._get_manager = Failing  # type: ignore[method-assign]
    asyncio_logger = logging.getLogger("asyncio")
    before = list(asyncio_logger.filters)
    for _ in range(2):  # a second failure of the same checkpoint adds no second filter
        with pytest.raises(checkpoint_module.CheckpointError, match="OUT_OF_RANGE"):
            checkpointer.restore(target, 4)
    added = [f for f in asyncio_logger.filters if f not in before]
    for f in added:
        asyncio_logger.removeFilter(f)
    assert [type(f) for f in added] == [checkpoint_module._DropFailedReads]
    assert added[0]._names >= {str(tmp_path / "checkpoints" / "4")}


def test_only_the_closed_event_loops_unraisable_errors_are_dropped(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    reported: list[str] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda args: reported.append(str(args.exc_value)))
    checkpoint_module._quiet_stray_loop_errors()
    checkpoint_module._quiet_stray_loop_errors()  # once: not a hook around a hook
    loop = asyncio.new_event_loop()
    loop.close()

    class Stray:  # raises where Python cannot raise: what a tensorstore callback does
        def __init__(self, action: Any) -> None:
            self.action = action

        def __del__(self) -> None:
            self.action()

    def other() -> None:
        raise KeyError("kept")

    for action in (lambda: loop.call_soon_threadsafe(print), other):
        thread = threading.Thread(target=Stray, args=(action,))
        thread.start()
        thread.join()
    assert reported == ["'kept'"]


def test_only_the_damaged_checkpoints_unretrieved_read_errors_are_dropped(
    tmp_path: Path, caplog: pytest.LogCaptureFixture,
) -> None:
    # A failed restore leaves its other reads' tasks unawaited; asyncio logs each one when it is
    # collected (in CI once: 8 stderr lines after the message). Errors of other paths still show.
    damaged = tmp_path / "checkpoints" / "4"
    filters = logging.getLogger("asyncio").filters
    quiet = checkpoint_module._DropFailedReads(damaged)
    logging.getLogger("asyncio").addFilter(quiet)
    try:
        async def fail(path: Path) -> None:
            raise ValueError(f'OUT_OF_RANGE: reading "leaf_00107" at local file "{path}/state/"')

        loop = asyncio.new_event_loop()
        with caplog.at_level(logging.ERROR, logger="asyncio"):
            for path in (damaged, tmp_path / "elsewhere"):
                task = loop.create_task(fail(path))
                loop.run_until_complete(asyncio.sleep(0))
                assert task.done()
                del task
                gc.collect()
        loop.close()
        logged = [r.exc_info[1] for r in caplog.records if r.name == "asyncio" and r.exc_info]
        assert [str(e).split('"')[-2] for e in logged] == [f"{tmp_path / 'elsewhere'}/state/"]
    finally:
        logging.getLogger("asyncio").removeFilter(quiet)
    assert logging.getLogger("asyncio").filters == filters
