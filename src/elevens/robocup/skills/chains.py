"""A chooser among helios-base's planner chains that learns from the matches it plays.

``skills_helios_parts`` (helios-base's planner on the ball, its basic move off it) plays the
chain of helios's best evaluation. A :class:`ChainChooser` plays the team the same way but
picks the chain itself, among the ``top_k`` of helios's evaluation, by a linear score of each
chain's features (:data:`FEATURES`); its starting weights (:func:`helios_weights`) give
helios's own choice. With ``explore`` it plays a uniform one of those ``top_k`` instead, that
often, and records every choice (features, the chosen row, its probability) beside the match's
game log, so that a better score can be fitted offline:

- :func:`possession_values`: from game logs, what a moment is worth, the mean of the next goal
  within :data:`GOAL_HORIZON` cycles (+1 ours, -1 theirs, 0 none) by where the ball is and
  which team touched it last;
- :func:`label_records`: what each recorded choice led to, the value :data:`LABEL_HORIZON`
  cycles later less the value when it was made (a goal in between: +1 or -1 less it);
- :func:`fit_chooser`: a ridge regression of those outcomes on the chosen chain's features less
  the mean of its search's top rows (what the choice changed), with that mean beside them (what
  the moment was), each choice weighed by the inverse of its probability so that the chosen row
  is uniform among the top rows; and an inverse-propensity estimate of how the fitted choice
  and helios's would have done on matches it was not fitted on, and of the difference.

A chooser is a JSON file (``format: elevens-chain-chooser``), played as a skills team by its
path: ``elevens robocup match --team0 chooser.json ...``.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from elevens.robocup.skills.planner import CATEGORIES, Candidates

__all__ = [
    "FEATURES",
    "ChainChooser",
    "ChooserSpec",
    "FitReport",
    "chain_features",
    "fit_chooser",
    "helios_weights",
    "is_chooser",
    "label_records",
    "load_chooser",
    "match_records",
    "possession_values",
    "save_chooser",
]

FORMAT = "elevens-chain-chooser"
EVAL_SCALE = 10.0
"""The evaluation feature's divisor (helios's top four of a search lie within about 1.3 of its
best, median of one match; a fitted chooser's weights are on this scale)."""
EVAL_FLOOR = 10.0
"""The evaluation feature's least value (a chain helios rules out: -inf)."""
HALF_LENGTH, HALF_WIDTH = 52.5, 34.0
_KINDS = CATEGORIES[:6]  # hold, dribble, pass, shoot, clear, move ("none" is never a node)

FEATURES: tuple[str, ...] = (
    "evaluation",  # helios's evaluation less the search's best, / EVAL_SCALE
    *(f"first_{k}" for k in _KINDS),  # the chain's first action (what is played now)
    *(f"last_{k}" for k in _KINDS),  # the node's own action
    "depth",  # actions in the chain / 3
    "steps",  # predicted cycles to the chain's end / 20
    "end_x",  # the ball at the chain's end, / 52.5
    "end_abs_y",  # |y| / 34
    "gain_x",  # end x less the ball's x now, / 52.5
    "end_goal_distance",  # from the end ball to their goal's centre, / 52.5
    "end_opponent_distance",  # nearest opponent seen now to the end ball, / 10, at most 2
    "end_opponents_near",  # opponents seen now within 7 m of the end ball, / 3
    "first_opponent_distance",  # nearest opponent to the first action's target, / 10, at most 2
    "ball_speed",  # the first kick's speed / 3
    "passed",  # the ball ends with a teammate other than the asking player
)
GOAL_HORIZON = 300
LABEL_HORIZON = 50
_X_BINS = 12
_GOALS = ("goal_l", "goal_r")  # not goal_kick_l: a play mode, not a goal


def _nearest(points: np.ndarray, others: np.ndarray) -> np.ndarray:
    """[k] distance from each point to the nearest of ``others`` (inf when none)."""
    if not len(others):
        return np.full(len(points), np.inf, np.float32)
    return np.linalg.norm(points[:, None, :] - others[None, :, :], axis=-1).min(axis=1)


def chain_features(c: Candidates, unum: int = 0) -> np.ndarray:
    """f32 [k, len(FEATURES)]: each searched node's features, as :data:`FEATURES` names them.
    Without the request's situation the ball is taken at the centre and no opponent is seen."""
    k = len(c)
    out = np.zeros((k, len(FEATURES)), np.float32)
    if not k:
        return out
    col = {name: i for i, name in enumerate(FEATURES)}
    first = c.first_actions()
    situation = c.situation
    ball_now = np.zeros(2, np.float32) if situation is None else situation.ball
    opponents = np.zeros((0, 2), np.float32) if situation is None else situation.opponents
    # helios rates a chain it rules out -inf (a lone hold of a search, say): far below, not NaN
    finite = np.isfinite(c.evaluation)
    best = c.evaluation[finite].max() if finite.any() else 0.0
    below = np.where(finite, c.evaluation - best, -np.inf) / EVAL_SCALE
    out[:, col["evaluation"]] = np.maximum(below, -EVAL_FLOOR)
    for j, kind in enumerate(_KINDS):
        out[:, col[f"first_{kind}"]] = c.category[first] == j
        out[:, col[f"last_{kind}"]] = c.category == j
    end = c.ball
    out[:, col["depth"]] = c.depths() / 3.0
    out[:, col["steps"]] = c.steps / 20.0
    out[:, col["end_x"]] = end[:, 0] / HALF_LENGTH
    out[:, col["end_abs_y"]] = np.abs(end[:, 1]) / HALF_WIDTH
    out[:, col["gain_x"]] = (end[:, 0] - ball_now[0]) / HALF_LENGTH
    goal = np.array([HALF_LENGTH, 0.0], np.float32)
    out[:, col["end_goal_distance"]] = np.linalg.norm(end - goal, axis=1) / HALF_LENGTH
    out[:, col["end_opponent_distance"]] = np.minimum(_nearest(end, opponents) / 10.0, 2.0)
    if len(opponents):
        near = np.linalg.norm(end[:, None] - opponents[None], axis=-1) < 7.0
        out[:, col["end_opponents_near"]] = near.sum(axis=1) / 3.0
    out[:, col["first_opponent_distance"]] = np.minimum(
        _nearest(c.target[first], opponents) / 10.0, 2.0)
    out[:, col["ball_speed"]] = c.ball_speed[first] / 3.0
    out[:, col["passed"]] = (c.holder > 0) & (c.holder != unum) if unum else c.holder != c.holder[0]
    return out


def helios_weights() -> tuple[float, ...]:
    """The weights that choose as helios-base does: its evaluation, nothing else."""
    return tuple(1.0 if name == "evaluation" else 0.0 for name in FEATURES)


@dataclasses.dataclass(frozen=True)
class ChooserSpec:
    """A chooser's file: ``weights`` (one per :data:`FEATURES`), the ``top_k`` chains of
    helios's evaluation it picks among, by how much another chain's score must exceed that of
    helios's best for it to be played instead (``margin``, in the score's units: for fitted
    weights, the predicted outcome), how often it plays a uniform one of them instead
    (``explore``, with the generator ``seed``), where it records its choices (``record_dir``,
    None: nowhere), and how it was fitted (``fit``: free-form, kept with it)."""

    weights: tuple[float, ...] = dataclasses.field(default_factory=helios_weights)
    top_k: int = 4
    margin: float = 0.0
    explore: float = 0.0
    seed: int = 0
    record_dir: str | None = None
    fit: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        if len(self.weights) != len(FEATURES) or not all(map(math.isfinite, self.weights)):
            raise ValueError(f"weights has {len(self.weights)} values (allowed: "
                             f"{len(FEATURES)} finite numbers, one per feature)")
        if not isinstance(self.top_k, int) or self.top_k < 1:
            raise ValueError(f"top_k {self.top_k!r} is invalid (allowed: an integer >= 1)")
        if not (math.isfinite(self.margin) and self.margin >= 0.0):
            raise ValueError(f"margin {self.margin!r} is invalid (allowed: a number >= 0)")
        if not 0.0 <= self.explore <= 1.0:
            raise ValueError(f"explore {self.explore!r} is invalid (allowed: 0 to 1)")


def save_chooser(path: str | Path, spec: ChooserSpec) -> None:
    """Write ``spec`` to ``path`` atomically (a temporary file renamed over it)."""
    path = Path(path)
    body = {"format": FORMAT, "features": list(FEATURES), **dataclasses.asdict(spec)}
    body["weights"] = list(spec.weights)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(body, indent=1) + "\n")
    os.replace(tmp, path)


def is_chooser(spec: str) -> bool:
    """Whether ``spec`` is the path of a chooser's file (False for anything else)."""
    if not spec.endswith(".json") or not Path(spec).is_file():
        return False
    try:
        return json.loads(Path(spec).read_text()).get("format") == FORMAT
    except (OSError, ValueError, AttributeError):
        return False


def load_chooser(path: str | Path) -> ChooserSpec:
    """The chooser in ``path``; a file that is not one, or whose features are not
    :data:`FEATURES`, is a ValueError in one line naming it."""
    try:
        body = json.loads(Path(path).read_text())
    except (OSError, ValueError) as error:
        raise ValueError(f"chooser {str(path)!r} does not read: {error}") from None
    if not isinstance(body, dict) or body.get("format") != FORMAT:
        raise ValueError(f"{str(path)!r} is not a chain chooser (allowed: a JSON file with "
                         f"format {FORMAT!r}, written by elevens robocup chains-init or -fit)")
    if tuple(body.get("features", ())) != FEATURES:
        raise ValueError(f"chooser {str(path)!r} has other features than this elevens "
                         f"({len(body.get('features', ()))} against {len(FEATURES)}): refit it")
    fields = {f.name for f in dataclasses.fields(ChooserSpec)}
    kwargs = {k: v for k, v in body.items() if k in fields}
    kwargs["weights"] = tuple(float(w) for w in kwargs.get("weights", ()))
    try:
        return ChooserSpec(**kwargs)
    except (TypeError, ValueError) as error:
        raise ValueError(f"chooser {str(path)!r}: {error}") from None


class ChainChooser:
    """``planner.Choose`` by a :class:`ChooserSpec` (thread-safe: the decision server asks
    from one thread per player)."""

    def __init__(self, spec: ChooserSpec) -> None:
        self.spec = spec
        self.weights = np.asarray(spec.weights, np.float32)
        self._rng = np.random.default_rng(spec.seed + os.getpid())
        self._lock = threading.Lock()
        self._out = None
        if spec.record_dir is not None:
            Path(spec.record_dir).mkdir(parents=True, exist_ok=True)
            name = f"chains-{time.strftime('%Y%m%d%H%M%S')}-{os.getpid()}.jsonl"
            self._out = open(Path(spec.record_dir) / name, "a", buffering=1)  # noqa: SIM115

    def __call__(self, unum: int, c: Candidates) -> int:
        if not len(c):
            return -1
        phi = chain_features(c, unum)
        top = np.argsort(-c.evaluation, kind="stable")[: self.spec.top_k]
        greedy = _pick(phi[top], self.weights, self.spec.margin)
        with self._lock:
            explores = self.spec.explore > 0 and self._rng.random() < self.spec.explore
            chosen = int(self._rng.integers(len(top))) if explores else greedy
        p = (1 - self.spec.explore) * (chosen == greedy) + self.spec.explore / len(top)
        if self._out is not None:
            s = c.situation
            line = {
                "cycle": -1 if s is None else s.cycle, "left": None if s is None else s.left,
                "unum": unum, "score": None if s is None else list(s.score),
                "features": np.round(phi[top].astype(np.float64), 4).tolist(), "chosen": chosen,
                "greedy": greedy, "p": round(float(p), 6),
            }
            with self._lock:
                self._out.write(json.dumps(line) + "\n")
        return int(c.index[top[chosen]])


def _pick(features: np.ndarray, weights: np.ndarray, margin: float) -> int:
    """The row of the highest score, or row 0 (helios's best) unless another beats it by
    more than ``margin``."""
    score = features @ weights
    best = int(np.argmax(score))
    return best if score[best] - score[0] > margin else 0


# ---- learning from the records and the game logs ----


def _goals(log: Any, side: int) -> list[tuple[int, float]]:
    """Each goal of ``log``: the shows before it and +1 (``side``'s) or -1."""
    ours = _GOALS[side]
    return [(log.playmode_shows[i], 1.0 if mode == ours else -1.0)
            for i, (_, mode) in enumerate(log.playmodes) if mode in _GOALS]


def _our_view(log: Any, side: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per show of ``log``: the ball's x in ``side``'s frame, who touched it last (0 nobody,
    1 ``side``, 2 the other), and the next goal within GOAL_HORIZON cycles (+1, -1, 0)."""
    sign = 1.0 if side == 0 else -1.0
    x = log.ball[:, 0] * sign
    last = np.zeros(len(x), np.int64)
    for show, team, _ in log.touches:
        last[int(show):] = 1 if int(team) == side else 2
    goal = np.zeros(len(x))
    for show, value in _goals(log, side):
        g_cycle = log.cycle[min(show, len(x) - 1)]
        window = (np.arange(len(x)) < show) & (log.cycle >= g_cycle - GOAL_HORIZON)
        window &= goal == 0
        goal[window] = value
    return x, last, goal


def _bin(x: np.ndarray) -> np.ndarray:
    return np.clip(((x + HALF_LENGTH) / (2 * HALF_LENGTH) * _X_BINS).astype(int), 0, _X_BINS - 1)


def possession_values(logs: Sequence[Any], team: str) -> np.ndarray:
    """f64 [_X_BINS, 3]: the mean next goal within GOAL_HORIZON cycles (+1 ours, -1 theirs)
    by the ball's x (12 bins from our goal line to theirs) and who touched it last (nobody,
    us, them), over every show of ``logs`` seen from ``team``'s side (an empty cell: 0)."""
    total, count = np.zeros((_X_BINS, 3)), np.zeros((_X_BINS, 3))
    for log in logs:
        x, last, goal = _our_view(log, log.side_of(team))
        np.add.at(total, (_bin(x), last), goal)
        np.add.at(count, (_bin(x), last), 1)
    return np.divide(total, count, out=np.zeros_like(total), where=count > 0)


def label_records(records: Sequence[dict[str, Any]], log: Any, team: str,
                  values: np.ndarray) -> np.ndarray:
    """f64 [n]: each record's outcome in ``log`` (``team``'s match): the possession value
    LABEL_HORIZON cycles after its cycle less the value at it, or, when a goal comes in
    between, +1 (ours) or -1 less the value at it. A record whose cycle the log lacks is NaN."""
    side = log.side_of(team)
    x, last, _ = _our_view(log, side)
    v = values[_bin(x), last]
    goals = _goals(log, side)
    goal_show = np.array([show for show, _ in goals], np.int64)
    goal_value = np.array([value for _, value in goals])
    out = np.full(len(records), np.nan)
    for i, r in enumerate(records):
        s0 = int(np.searchsorted(log.cycle, r["cycle"]))
        s1 = int(np.searchsorted(log.cycle, r["cycle"] + LABEL_HORIZON))
        if s0 >= len(x) or log.cycle[s0] != r["cycle"]:
            continue
        s1 = min(s1, len(x) - 1)
        scored = np.flatnonzero((goal_show > s0) & (goal_show <= s1))
        out[i] = (goal_value[scored[0]] if len(scored) else v[s1]) - v[s0]
    return out


def match_records(folders: Sequence[str]) -> list[tuple[list[dict[str, Any]], Path]]:
    """For each folder: its records (every ``chains-*.jsonl`` under it) and its one game
    log; a folder without records, or without exactly one .rcg, is a ValueError naming it."""
    out = []
    for folder in folders:
        base = Path(folder)
        files = sorted(base.rglob("chains-*.jsonl"))
        logs = sorted(base.rglob("*.rcg"))
        if not files or len(logs) != 1:
            raise ValueError(f"{folder!r} holds {len(files)} record files and {len(logs)} game "
                             "logs (allowed: one match's folder, records and exactly one .rcg)")
        records = [json.loads(line) for f in files for line in f.read_text().splitlines()
                   if line.strip()]
        out.append((records, logs[0]))
    return out


@dataclasses.dataclass(frozen=True)
class FitReport:
    """What a fit found: ``weights``; the records used; on the matches held out in turn, the
    inverse-propensity estimate (mean outcome a choice, with its standard error) of the
    fitted choice, of helios's, of their difference on the same choices (``gain``) and of the
    choices played, and how often the fitted choice is helios's."""

    weights: tuple[float, ...]
    records: int
    matches: int
    fitted: tuple[float, float]
    helios: tuple[float, float]
    gain: tuple[float, float]
    played: tuple[float, float]
    agreement: float

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _arrays(records: Sequence[dict[str, Any]]) -> tuple[list[np.ndarray], np.ndarray,
                                                         np.ndarray]:
    feats = [np.asarray(r["features"], np.float64).reshape(-1, len(FEATURES)) for r in records]
    chosen = np.array([r["chosen"] for r in records], np.int64)
    p = np.array([r["p"] for r in records], np.float64)
    return feats, chosen, p


def _ridge(feats: list[np.ndarray], chosen: np.ndarray, p: np.ndarray, y: np.ndarray,
           l2: float) -> np.ndarray:
    """The weights on the chosen row's features less its record's mean row. The mean row
    stands beside them for the moment itself (a choice made where the ball is well placed
    looks good whatever it was), and each record weighs 1 / (rows x p), as if every row had
    been chosen alike: helios's own choice, played most often, is the one most confounded with
    its moment."""
    mean = np.stack([f.mean(axis=0) for f in feats])
    rows = np.array([len(f) for f in feats], np.float64)
    x = np.stack([f[c] for f, c in zip(feats, chosen, strict=True)]) - mean
    d = x.shape[1]
    x = np.concatenate([x, mean, np.ones((len(x), 1))], axis=1)  # a bias, not a score
    sw = 1.0 / (rows * p)
    reg = l2 * np.eye(x.shape[1])
    reg[-1, -1] = 0.0
    xw = x * sw[:, None]
    return np.linalg.solve(xw.T @ x + reg, xw.T @ y)[:d]


def _ips(picks: np.ndarray, chosen: np.ndarray, p: np.ndarray, y: np.ndarray,
         baseline: np.ndarray | None = None) -> tuple[float, float]:
    terms = (picks == chosen) / p * y
    if baseline is not None:  # the difference on the same choices: their noise cancels
        terms = terms - (baseline == chosen) / p * y
    return float(terms.mean()), float(terms.std() / math.sqrt(max(len(terms), 1)))


def fit_chooser(matches: Sequence[tuple[Sequence[dict[str, Any]], np.ndarray]],
                l2: float = 10.0, margin: float = 0.0) -> FitReport:
    """Fit the weights on every match's (records, labels) (records without a label, or with
    a feature that is not finite, are dropped), and estimate the fitted choice (with
    ``margin``) on each match held out in turn from the others' fit. Helios's choice is the
    top row of each record (its best evaluation)."""
    kept = []
    for records, labels in matches:
        ok = np.isfinite(labels) & np.array(
            [bool(np.isfinite(r["features"]).all()) for r in records], bool)
        kept.append(([r for r, k in zip(records, ok, strict=True) if k], labels[ok]))
    kept = [(r, y) for r, y in kept if len(r)]
    if not kept:
        raise ValueError("no labelled record to fit (each record's cycle must be in its log)")
    arrays = [(*_arrays(records), y) for records, y in kept]  # each match converted once
    picks_fit = []
    for m, (feats, _, _, _) in enumerate(arrays):
        others = [a for j, a in enumerate(arrays) if j != m] or [arrays[m]]
        chosen_o, p_o, y_o = (np.concatenate([a[i] for a in others]) for i in (1, 2, 3))
        w = _ridge([f for a in others for f in a[0]], chosen_o, p_o, y_o, l2)
        picks_fit.append(np.array([_pick(f, w, margin) for f in feats], np.int64))
    chosen, p, y = (np.concatenate([a[i] for a in arrays]) for i in (1, 2, 3))
    fitted_picks = np.concatenate(picks_fit)
    helios = np.zeros_like(chosen)
    weights = _ridge([f for a in arrays for f in a[0]], chosen, p, y, l2)
    return FitReport(
        weights=tuple(float(w) for w in weights), records=len(y), matches=len(kept),
        fitted=_ips(fitted_picks, chosen, p, y), helios=_ips(helios, chosen, p, y),
        gain=_ips(fitted_picks, chosen, p, y, baseline=helios),
        played=(float(y.mean()), float(y.std() / math.sqrt(len(y)))),
        agreement=float((fitted_picks == 0).mean()),
    )
