"""The packages import in one direction (docs/architecture.md):
env -> {teams, nets} -> play -> train -> eval -> runs -> {robocup, adapters, bench} -> cli.

Read from the source with ``ast``: every ``import`` and ``from ... import`` counts, those
inside functions (lazy imports) included, so a lower layer cannot reach up even on first use.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

SOURCE = Path(__file__).resolve().parents[1] / "src" / "elevens"

LAYERS: dict[str, int] = {
    "files": 0,  # the atomic writer, used everywhere
    "env": 1,
    "nets": 2,
    "teams": 3,  # teams/network.py plays a network
    "play": 4,  # the one unroll: training rollouts, matches, recorded games
    "train": 5,
    "eval": 6,
    "runs": 7,
    "robocup": 8,
    "adapters": 8,
    "bench": 8,
    "cli": 9,
    "__main__": 10,
}
"""Each top-level module or package of elevens and its layer: an import may only go to a
lower layer or stay inside its own package."""


def _unit(module: str) -> str | None:
    """'elevens.train.ppo' -> 'train'; None for the package root and outside modules."""
    parts = module.split(".")
    if parts[0] != "elevens" or len(parts) < 2:
        return None
    return parts[1]


def _imports(path: Path) -> list[tuple[int, str]]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    package = ".".join(path.relative_to(SOURCE.parent).with_suffix("").parts[:-1])
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:  # relative: resolve against this file's package
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            found.append((node.lineno, base))
    return found


def upward_edges() -> list[str]:
    edges = []
    for path in sorted(SOURCE.rglob("*.py")):
        source_unit = path.relative_to(SOURCE).parts[0].removesuffix(".py")
        if source_unit == "__init__":
            continue
        for line, module in _imports(path):
            target = _unit(module)
            if target is None or target == source_unit:
                continue
            if LAYERS[target] >= LAYERS[source_unit]:
                edges.append(
                    f"{path.relative_to(SOURCE.parent)}:{line} imports {module} "
                    f"({source_unit}, layer {LAYERS[source_unit]} -> {target}, layer "
                    f"{LAYERS[target]})"
                )
    return edges


def test_every_module_has_a_layer() -> None:
    units = {p.relative_to(SOURCE).parts[0].removesuffix(".py") for p in SOURCE.rglob("*.py")}
    assert units - {"__init__"} <= set(LAYERS), sorted(units - {"__init__"} - set(LAYERS))


def test_imports_go_down_the_layers() -> None:
    edges = upward_edges()
    assert not edges, "imports against the layer order:\n" + "\n".join(edges)


def test_the_check_sees_a_lazy_upward_import(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # The check itself: an import inside a function of env reaching train is found.
    root = tmp_path / "elevens"
    (root / "env").mkdir(parents=True)
    (root / "env" / "bad.py").write_text(
        "def f():\n    from elevens.train.learner import make_learner\n    return make_learner\n"
    )
    monkeypatch.setitem(globals(), "SOURCE", root)
    edges = upward_edges()
    assert len(edges) == 1 and "env/bad.py:2 imports elevens.train.learner" in edges[0]


READ_TOP_TO_BOTTOM = ("train", "runs")
"""Packages whose functions stay short enough to read on one screen (issue 16)."""
MAX_FUNCTION_LINES = 80


def test_training_core_functions_fit_on_a_screen() -> None:
    long = []
    for package in READ_TOP_TO_BOTTOM:
        for path in sorted((SOURCE / package).rglob("*.py")):
            tree = ast.parse(path.read_text(encoding="utf-8"))
            for node in ast.walk(tree):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    length = (node.end_lineno or node.lineno) - node.lineno + 1
                    if length > MAX_FUNCTION_LINES:
                        long.append(f"{path.relative_to(SOURCE)}: {node.name} ({length} lines)")
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: {long}"
