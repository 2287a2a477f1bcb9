"""Learning curves over seeds from synthetic metrics.csv files with known crossings."""

from __future__ import annotations

import numpy as np
import pytest

from elevens.cli.eval import main as eval_main
from elevens.runs.curves import Series, band, first_above, plot_learning_curves, run_series
from elevens.runs.logging import RunLogger, read_metrics_csv


def _write_run(run_dir, seed: int, iterations=range(0, 101, 10)) -> None:
    """Evaluations every 10 iterations, as the trainer logs them: against naive the outcome is
    iteration / 100 + 0.02 * (seed - 1) (seeds 0, 1, 2 average to iteration / 100); against
    random it is twice as fast; against teamwork it never passes 0.5. Hours per iteration
    differ by seed; env steps are 1000 per iteration."""
    with RunLogger(run_dir, use_tensorboard=False) as logger:
        for it in iterations:
            logger.log(it, {"train/loss": 1.0})  # other metrics at other rows are ignored
            logger.log(it, {
                "eval/naive/outcome": it / 100 + 0.02 * (seed - 1),
                "eval/random/outcome": min(1.0, it / 50),
                "eval/teamwork/outcome": 0.4,
                "time/env_steps": 1000.0 * it,
                "time/hours": 0.01 * it * (1 + seed),
            })


def test_series_and_band_on_identical_steps(tmp_path) -> None:
    runs = []
    for seed in range(3):
        _write_run(tmp_path / f"s{seed}", seed)
        runs.append(run_series(read_metrics_csv(tmp_path / f"s{seed}"), "eval/naive/outcome",
                               "time/env_steps", f"s{seed}"))
    np.testing.assert_array_equal(runs[0].x, np.arange(0, 101, 10) * 1000.0)
    curve = band(runs)
    np.testing.assert_allclose(curve.mean, np.arange(0, 101, 10) / 100)
    np.testing.assert_allclose(curve.std, np.std([-0.02, 0.0, 0.02]))
    assert curve.runs == 3
    # The mean is 0.5 at 50 000 steps (not above) and 0.6 at 60 000: first above at 60 000.
    assert first_above(curve) == 60_000.0
    assert first_above(curve, threshold=2.0) is None


def test_band_interpolates_runs_with_different_x() -> None:
    a = Series("a", np.array([0.0, 1.0, 2.0]), np.array([0.0, 1.0, 2.0]))
    b = Series("b", np.array([0.0, 2.0, 4.0]), np.array([0.0, 0.0, 4.0]))
    curve = band([a, b], points=5)
    np.testing.assert_allclose(curve.x, [0.0, 0.5, 1.0, 1.5, 2.0])  # the common range
    np.testing.assert_allclose(curve.mean, [0.0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(curve.std, [0.0, 0.25, 0.5, 0.75, 1.0])
    with pytest.raises(ValueError, match="do not overlap"):
        band([a, Series("c", np.array([5.0, 6.0]), np.array([0.0, 1.0]))])


def test_plot_marks_where_each_team_is_first_outperformed(tmp_path) -> None:
    dirs = []
    for seed in range(3):
        _write_run(tmp_path / f"seed{seed}", seed)
        dirs.append(tmp_path / f"seed{seed}")
    summary = plot_learning_curves(dirs, tmp_path / "curve.png", against="naive",
                                   x_axes=("env_steps", "iteration", "hours"))
    assert summary.path.read_bytes()[:4] == b"\x89PNG"
    assert summary.runs == ("seed0", "seed1", "seed2")
    firsts = summary.first_outperformed
    assert firsts["env_steps"] == {"naive": 60_000.0, "random": 30_000.0, "teamwork": None}
    assert firsts["iteration"]["naive"] == 60.0
    # Hours differ by seed (seed s logs 0.01 (1 + s) h per iteration), so the runs are
    # interpolated over the 0 to 1 h that all cover. Against random, seed s is at
    # h / (0.5 (1 + s)), so the mean is h (2 + 1 + 2/3) / 3 below 0.5 h: above 0.5 past 0.409 h.
    assert firsts["hours"]["random"] == pytest.approx(0.5 * 3 / (2 + 1 + 2 / 3), abs=0.006)
    assert summary.final_mean == pytest.approx(1.0)


def test_curves_command_and_errors(tmp_path, capsys) -> None:
    _write_run(tmp_path / "only", 1)
    eval_main(["curves", str(tmp_path / "only"), "--against", "random", "--out",
               str(tmp_path / "c.png"), "--x", "iteration"])
    printed = capsys.readouterr().out
    rule = "mean, no win and draw rates logged"
    assert f"first beats random ({rule} above 0.5) at iteration = 30" in printed
    assert f"first beats teamwork ({rule} above 0.5) at iteration = never" in printed
    with pytest.raises(KeyError, match="no metric 'eval/wizards/outcome'"):
        plot_learning_curves([tmp_path / "only"], tmp_path / "d.png", against="wizards")
    with pytest.raises(FileNotFoundError, match="metrics.csv"):
        plot_learning_curves([tmp_path / "missing"], tmp_path / "d.png")


def test_labelled_groups_overlay_one_pooled_curve_per_setting(tmp_path, capsys) -> None:
    for seed in range(3):
        _write_run(tmp_path / f"p{seed}", seed)
    _write_run(tmp_path / "league", 1, iterations=range(0, 51, 10))
    out = tmp_path / "overlay.png"
    finals = eval_main(["curves", f"polyak={tmp_path / 'p0'},{tmp_path / 'p1'},{tmp_path / 'p2'}",
                        f"league={tmp_path / 'league'}", "--out", str(out), "--x", "env_steps"])
    # Seeds pooled within a label: the last values 0.98, 1.0, 1.02 average to 1.0.
    assert finals == pytest.approx({"polyak": 1.0, "league": 0.5})
    assert out.stat().st_size > 0
    assert "polyak: last mean 1.000 against naive" in capsys.readouterr().out
    with pytest.raises(ValueError, match="labels repeat"):
        eval_main(["curves", f"a={tmp_path / 'p0'}", f"a={tmp_path / 'p1'}",
                   "--out", str(out)])
    with pytest.raises(ValueError, match="write LABEL=RUN"):
        eval_main(["curves", "a=", "--out", str(out)])


def test_first_beats_needs_the_interval_above_one_half(tmp_path) -> None:
    # 64 evaluation games: 1 win and 63 draws (mean 0.508) is noise; 48 wins 16 draws is not.
    import json

    run = tmp_path / "run"
    with RunLogger(run, use_tensorboard=False) as logger:
        for it, (win, draw) in enumerate([(0, 64), (1, 63), (20, 44), (48, 16)]):
            logger.log(it, {
                "eval/naive/outcome": (win + draw / 2) / 64, "eval/naive/win": win / 64,
                "eval/naive/draw": draw / 64, "time/env_steps": 1000.0 * it,
                "time/hours": 0.1 * it,
            })
    (run / "config.json").write_text(json.dumps({"run": {"eval_games": 64}}))
    summary = plot_learning_curves([run], tmp_path / "c.png", x_axes=("iteration",))
    # Iteration 1: mean 0.508, s.e. 0.008, lower end 0.493. Iteration 2: mean 0.656, s.e. 0.029,
    # lower end 0.60.
    assert summary.first_outperformed["iteration"]["naive"] == 2.0
    assert summary.with_interval == {"naive"}
    # Without the games count the mean alone decides: 0.508 at iteration 1.
    (run / "config.json").unlink()
    summary = plot_learning_curves([run], tmp_path / "c.png", x_axes=("iteration",))
    assert summary.first_outperformed["iteration"]["naive"] == 1.0
