"""Where each player of a team spends its games (thesis figures 6.8 and 6.9).

One small panel per formation slot: a 2D histogram of that player's centre over every step of
every game, in the team's own frame (so every team defends the left goal and attacks +x, whatever
side it played), normalised to the probability of finding the player in each cell. The slot's
formation point is marked with a black ring. Colours follow the thesis: dark green is likely,
light yellow unlikely; cells it never visited are left blank. Two more panels pool the whole
team (every player's steps) and show the ball. ``elevens analyze`` draws every team of one
analysis on one colour scale (``colour_top``), so their figures compare.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from elevens.env.params import FORMATION_SUBSETS, EnvParams, formation

CELL_METRES = 2.0
"""Histogram cell size (a player is a disc of radius 1)."""
_ROLES = {0: "keeper", 1: "defender", 2: "defender", 3: "defender", 4: "defender",
          5: "midfielder", 6: "midfielder", 7: "midfielder",
          8: "attacker", 9: "attacker", 10: "attacker"}


def slot_roles(players_per_team: int) -> list[str]:
    """The role of each formation slot of a team of ``players_per_team`` (keeper, defender...)."""
    return [_ROLES[index] for index in FORMATION_SUBSETS[players_per_team]]


def spawn_points(params: EnvParams) -> np.ndarray:
    """f64[n, 2]: the formation slots in the team's own frame, scaled to the field."""
    # formation() is laid out on SPEC.md's 100 x 70 field; the slots scale with the field.
    scale = np.array([float(params.half_length) / 50.0, float(params.half_width) / 35.0])
    return formation(params.players_per_team) * scale


def position_histograms(
    positions: np.ndarray, params: EnvParams, cell: float = CELL_METRES
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """positions f[G, T, n, 2] (own frame) -> (probability f64[n, X, Y], x edges, y edges).

    Each player's histogram sums to 1 over the field.
    """
    hl, hw = float(params.half_length), float(params.half_width)
    x_edges = np.linspace(-hl, hl, max(1, round(2 * hl / cell)) + 1)
    y_edges = np.linspace(-hw, hw, max(1, round(2 * hw / cell)) + 1)
    points = np.asarray(positions, np.float64)
    n = points.shape[2]
    histograms = np.empty((n, x_edges.size - 1, y_edges.size - 1))
    for k in range(n):
        xy = points[:, :, k].reshape(-1, 2)
        counts, _, _ = np.histogram2d(xy[:, 0], xy[:, 1], bins=(x_edges, y_edges))
        histograms[k] = counts / max(counts.sum(), 1.0)
    return histograms, x_edges, y_edges


CLIP_PERCENTILE = 99.0
"""The colour scale tops out at this percentile of the visited cells (said on the colour bar):
a keeper's few cells would otherwise wash out every other panel."""


def colour_top(histograms: list[np.ndarray]) -> float:
    """The top of one colour scale for several teams' per-slot histograms: the
    ``CLIP_PERCENTILE`` of all their visited cells together."""
    visited = np.concatenate([np.ravel(h[h > 0]) for h in histograms] or [np.zeros(0)])
    return float(np.percentile(visited, CLIP_PERCENTILE)) if visited.size else 1.0


def _draw_field(axis: Any, params: EnvParams) -> None:
    from matplotlib.patches import Circle

    hl, hw = float(params.half_length), float(params.half_width)
    gh = float(params.goal_width) / 2
    line = {"color": "#555555", "linewidth": 0.8}
    axis.plot([-hl, hl, hl, -hl, -hl], [-hw, -hw, hw, hw, -hw], **line)
    axis.plot([0, 0], [-hw, hw], **line)
    axis.add_patch(Circle((0, 0), 0.0915 * 2 * hl, fill=False, **line))
    # Goals: own (defended) goal in blue on the left, the attacked one in red on the right.
    axis.plot([-hl, -hl], [-gh, gh], color="#1f4e9c", linewidth=3, solid_capstyle="butt")
    axis.plot([hl, hl], [-gh, gh], color="#c62828", linewidth=3, solid_capstyle="butt")


def plot_heatmaps(
    positions: np.ndarray,
    params: EnvParams,
    path: str | Path,
    *,
    title: str,
    cell: float = CELL_METRES,
    ball: np.ndarray | None = None,
    top: float | None = None,
    shared_with: int = 1,
) -> Path:
    """Write the per-slot heat maps of one team as a PNG, then its whole team and the ball.

    positions: f[G, T, n, 2], the team's players in its own frame (``TeamTrajectories``).
    ball: f[G, T, 2] in the same frame (``TeamTrajectories.ball``); None leaves its panel out.
    top: the colour scale's top (``colour_top`` over the teams to compare; default this team's
    own); ``shared_with`` says on the figure how many teams share it.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.colors import PowerNorm

    histograms, x_edges, y_edges = position_histograms(positions, params, cell)
    n = histograms.shape[0]
    points = np.asarray(positions, np.float64)
    pooled, _, _ = position_histograms(
        points.reshape(points.shape[0], -1, 1, 2), params, cell
    )
    extra = [("whole team", pooled[0] / 1.0)]
    if ball is not None:
        ball_points = np.asarray(ball, np.float64)[:, :, None, :]
        extra.append(("ball", position_histograms(ball_points, params, cell)[0][0]))
    spawns = spawn_points(params)
    roles = slot_roles(n)
    panels = n + len(extra)
    columns = min(panels, 4)
    rows = -(-panels // columns)
    hl, hw = float(params.half_length), float(params.half_width)
    panel_width = 3.3
    panel_height = panel_width * hw / hl + 0.3
    figure, axes = plt.subplots(
        rows, columns, figsize=(panel_width * columns + 1.3, panel_height * rows + 0.7),
        squeeze=False, sharex=True, sharey=True, layout="constrained",
    )
    # One colour scale for all panels (and, from elevens analyze, all teams), so they compare.
    # The square-root norm shows the tails of a distribution, where positional play shows.
    if top is None:
        top = colour_top([histograms])
    norm = PowerNorm(gamma=0.5, vmin=0.0, vmax=max(top, 1e-12))
    image = None
    for k in range(rows * columns):
        axis = axes[k // columns][k % columns]
        if k >= panels:
            axis.set_visible(False)
            continue
        values = histograms[k] if k < n else extra[k - n][1]
        masked = np.ma.masked_equal(values.T, 0.0)
        image = axis.pcolormesh(x_edges, y_edges, masked, cmap="YlGn", norm=norm,
                                shading="flat", rasterized=True)
        _draw_field(axis, params)
        if k < n:
            axis.plot(*spawns[k], marker="o", markersize=9, markerfacecolor="none",
                      markeredgecolor="black", markeredgewidth=1.8)
            axis.set_title(f"slot {k}: {roles[k]}", fontsize=9)
        else:
            axis.set_title(extra[k - n][0], fontsize=9)
        axis.set_aspect("equal")
        axis.set_xlim(-hl - 2, hl + 2)
        axis.set_ylim(-hw - 2, hw + 2)
        axis.tick_params(labelsize=7)
        if k // columns == rows - 1 or k + columns >= panels:
            axis.set_xlabel("x (m), attacking →", fontsize=8)
            axis.xaxis.set_tick_params(labelbottom=True)
        if k % columns == 0:
            axis.set_ylabel("y (m)", fontsize=8)
    if image is not None:
        bar = figure.colorbar(image, ax=axes.ravel().tolist(), shrink=0.8, aspect=30)
        shared = f"; one scale for the {shared_with} teams of this analysis" if (
            shared_with > 1) else ""
        bar.set_label(
            f"probability per {cell:g} × {cell:g} m cell (cells above {top:.2g}, the "
            f"{CLIP_PERCENTILE:g}th percentile, at the top colour{shared})", fontsize=8,
        )
        bar.ax.tick_params(labelsize=7)
    figure.suptitle(f"{title}\n(○ formation spawn point; own goal blue, left)", fontsize=10)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(figure)
    return path
