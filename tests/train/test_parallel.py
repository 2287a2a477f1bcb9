"""Data-parallel training (elevens.train.parallel): one update on 2 devices equals the same
update on 1 device; two processes on loopback (jax.distributed, gloo) train one run with
identical parameters while only process 0 writes the run directory; and the clear errors of
device counts, process counts and the --distributed flags."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from elevens.cli.train import command_flags_first
from elevens.runs.errors import RunRefusedError
from elevens.runs.loop import train
from elevens.train import parallel
from elevens.train.config import make_config
from elevens.train.learner import make_learner
from tests.refusal import refused
from tests.train.parallel_worker import TINY, process_config

ROOT = Path(__file__).resolve().parents[2]
WAIT_S = 1800.0
"""How long a worker may take on a loaded machine: a bound for a hung one, not a speed."""


def run_worker(*args: str, timeout: float = WAIT_S) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": f"{ROOT}{os.pathsep}{ROOT / 'src'}"}
    # The suite's compile flags pass on; a device count is the worker's own to set.
    flags = os.environ.get("XLA_FLAGS", "").split()
    env["XLA_FLAGS"] = " ".join(f for f in flags if "device_count" not in f)
    return subprocess.Popen(
        [sys.executable, "-m", "tests.train.parallel_worker", *args],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )


def finish(process: subprocess.Popen[str], timeout: float = WAIT_S) -> str:
    output, _ = process.communicate(timeout=timeout)
    assert process.returncode == 0, output[-3000:]
    return output


@pytest.mark.slow
def test_an_update_on_two_devices_equals_the_update_on_one(tmp_path: Path) -> None:
    out = tmp_path / "devices.npz"
    finish(run_worker("devices", str(out)))
    saved = np.load(out)
    assert int(saved["1/shards"]) == 1 and int(saved["2/shards"]) == 2
    names = [key[2:] for key in saved.files if key.startswith("1/") and key != "1/shards"]
    assert any(name.startswith("params") for name in names)
    assert any(name.startswith("metrics/train/mean_score") for name in names)
    for name in names:
        one, two = saved[f"1/{name}"], saved[f"2/{name}"]
        # Same games, same minibatches: only the order of float sums differs.
        np.testing.assert_allclose(two, one, rtol=1e-4, atol=1e-5, err_msg=name)
    # The update moved the networks: the comparison is not between two initial states.
    assert float(saved["1/metrics/train/grad_norm"][0]) > 0


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return int(probe.getsockname()[1])


@pytest.mark.slow
def test_two_processes_on_loopback_train_one_run(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    coordinator = f"127.0.0.1:{free_port()}"
    outs = [tmp_path / f"process{i}.npz" for i in range(2)]
    workers = [
        run_worker("process", str(outs[i]), str(run_dir), coordinator, str(i)) for i in range(2)
    ]
    for worker in workers:
        finish(worker)
    first, second = (np.load(out) for out in outs)
    assert int(first["devices"]) == 2  # one CPU device per process, one global mesh
    assert int(first["iteration"]) == int(second["iteration"]) == 2
    params = [key for key in first.files if key.startswith("params")]
    assert params
    for key in params:
        np.testing.assert_array_equal(first[key], second[key], err_msg=key)
    # Process 0 wrote the run directory; process 1 made and wrote nothing under it.
    assert [str(path) for path in second["written"]] == [""]
    written = {str(path) for path in first["written"]}
    assert str(run_dir / "config.json") in written and str(run_dir / "metrics.csv") in written
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == ["1", "2"]
    meta = (run_dir / "checkpoints" / "2" / "metadata" / "metadata.json").read_text()
    assert '"processes": 2' in meta

    # A resume by another number of processes (here one) is refused, naming both numbers.
    with pytest.raises(RunRefusedError, match=r"2 process\(es\) and this run has 1"):
        train(process_config(str(run_dir)), resume=True, progress=False)


def test_device_counts_that_do_not_split_the_games_are_refused() -> None:
    two_devices = types.SimpleNamespace(devices=np.empty(2, object))
    with pytest.raises(ValueError, match=r"run.games_per_iteration=5 is invalid on 2 devices"):
        parallel.check_divisible("run.games_per_iteration", 5, two_devices, "fix")  # type: ignore[arg-type]
    parallel.check_divisible("run.games_per_iteration", 6, two_devices, "fix")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"run.devices=3 is invalid: give 0 .* or 1 to 1"):
        tiny = make_config("quickstart", **TINY).learner
        make_learner(tiny, tiny.make_env(), devices=3)
    with pytest.raises(ValueError, match=r"run.devices=-1 is invalid"):
        make_config("quickstart", **{"run.devices": -1})


def test_distributed_flags_need_each_other() -> None:
    with pytest.raises(ValueError, match="give all three"):
        parallel.initialize_distributed("127.0.0.1:1234", 0, -1)
    with pytest.raises(ValueError, match=r"--process-id=2 is invalid with --num-processes=2"):
        parallel.initialize_distributed("127.0.0.1:1234", 2, 2)
    with pytest.raises(ValueError, match="HOST:PORT"):
        parallel.initialize_distributed("localhost", 2, 0)


def test_elevens_train_refuses_process_flags_without_distributed(
    capsys: pytest.CaptureFixture[str],
) -> None:
    # In this process: the refusal comes before jax.distributed (and anything else) starts.
    assert "need --distributed" in refused(["train", "quickstart", "--num-processes", "2"],
                                           "train", capsys)


def test_train_flags_with_values_move_before_the_preset() -> None:
    args = ["2v2", "--distributed", "--coordinator", "h:1", "--process-id=1", "--run.seed", "3"]
    assert command_flags_first(args) == [
        "--distributed", "--coordinator", "h:1", "--process-id=1", "2v2", "--run.seed", "3",
    ]


def test_distributed_outside_a_cluster_job_says_what_to_give() -> None:
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "OMPI_"))}
    result = subprocess.run(
        [sys.executable, "-m", "elevens", "train", "quickstart", "--distributed"],
        cwd=ROOT, env={**env, "PYTHONPATH": str(ROOT / "src")},
        capture_output=True, text=True, timeout=WAIT_S,
    )
    assert result.returncode == 2, result.stderr
    line = result.stderr.strip()
    assert "\n" not in line and "no SLURM or Open MPI job" in line and "--coordinator" in line
