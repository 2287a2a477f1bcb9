"""Host-side pictures of a game: top-down frames, a player's field of view, GIF and MP4.

Never call these inside ``jit``: they pull arrays to the host and draw with Pillow. The look follows
thesis figures 4.1 and 4.2: a green pitch with white lines, oversized goals beyond the goal lines,
players as discs with a leg bar across and a short yellow heading tick (team 0 blue, team 1 red),
the ball, and a header strip with the step (left), the score (centre) and an optional title (right).

World ``y`` points up on screen. Everything is drawn at ``SUPERSAMPLE`` times the final size and
box-filtered down, which anti-aliases discs and lines at little cost.
"""

from __future__ import annotations

import functools
import math
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any, NamedTuple

import jax
import numpy as np
from PIL import Image, ImageDraw, ImageFont

from elevens.env.observe import entity_layout, observe
from elevens.env.params import EnvParams
from elevens.env.state import State

RGB = tuple[int, int, int]

# --- look -------------------------------------------------------------------------------------
TEAM_COLOURS: tuple[RGB, RGB] = ((40, 95, 235), (225, 40, 40))  # thesis: blue left, red right
LEG_COLOURS: tuple[RGB, RGB] = ((15, 40, 120), (120, 15, 15))  # darker, so the bar reads as legs
HEADING_COLOUR: RGB = (255, 225, 0)  # thesis: "the short yellow line ... direction it is facing"
BALL_COLOUR: RGB = (255, 255, 255)
OUTLINE_COLOUR: RGB = (20, 20, 20)
LINE_COLOUR: RGB = (235, 235, 235)  # a touch below the ball's white, so the two stay apart
GRASS_COLOURS: tuple[RGB, RGB] = ((58, 148, 58), (66, 160, 66))  # mowing stripes show motion
SURROUND_COLOUR: RGB = (38, 105, 42)
HEADER_COLOUR: RGB = (24, 24, 28)
TEXT_COLOUR: RGB = (240, 240, 240)
HIGHLIGHT_COLOUR: RGB = (255, 235, 60)
FOV_COLOUR: RGB = (255, 255, 210)
FOV_ALPHA = 0.22
DIM_TOWARDS_GRASS = 0.55  # unseen entities in the observation view fade this far into the grass
DIM_TOWARDS = (232, 232, 232)  # unseen players pale towards white: blue stays blue, red red
NUMBER_COLOUR: RGB = (255, 255, 255)
NUMBER_OUTLINE: RGB = (10, 10, 10)
NUMBER_MIN_PX = 9  # the smallest legible digit height in the final image

# --- geometry (metres unless named _px) ---------------------------------------------------------
SUPERSAMPLE = 2
MARGIN = 4.0  # surround beyond the lines, room for the goal boxes
GOAL_DEPTH = 2.5
LINE_WIDTH = 0.3
CENTRE_CIRCLE_FRACTION = 0.0915  # 9.15 m on a 100 m field, as on a real pitch
LEG_WIDTH = 0.45
HEADING_TICK = 1.9  # from the centre, so the tick pokes out of the disc
STRIPES = 10  # grass stripes over the field length
SUPPORTED_VIDEO_SUFFIXES = (".gif", ".mp4")


class _Layout(NamedTuple):
    """Pixel geometry of one frame. ``scale`` is pixels per metre in the final image."""

    scale: float
    half_length: float
    half_width: float
    goal_half: float
    header_px: int
    width_px: int
    height_px: int


def _layout(params: EnvParams, scale: float) -> _Layout:
    if not scale > 0:
        raise ValueError(f"scale={scale!r} is invalid: it must be > 0 (pixels per metre)")
    half_length, half_width = float(params.field_length) / 2, float(params.field_width) / 2
    header_px = max(18, round(3.2 * scale))
    width_px = math.ceil((2 * half_length + 2 * MARGIN) * scale)
    height_px = header_px + math.ceil((2 * half_width + 2 * MARGIN) * scale)
    return _Layout(
        scale=float(scale),
        half_length=half_length,
        half_width=half_width,
        goal_half=float(params.goal_width) / 2,
        header_px=header_px,
        width_px=width_px,
        height_px=height_px,
    )


def _to_pixel(layout: _Layout, xy: np.ndarray) -> np.ndarray:
    """World metres ``f[..., 2]`` -> final-image pixels ``f[..., 2]`` as (column, row)."""
    xy = np.asarray(xy, np.float64)
    column = (xy[..., 0] + layout.half_length + MARGIN) * layout.scale
    row = layout.header_px + (layout.half_width + MARGIN - xy[..., 1]) * layout.scale
    return np.stack([column, row], axis=-1)


def world_to_pixel(xy: Any, params: EnvParams, *, scale: float = 8) -> np.ndarray:
    """Where world points land in a frame of ``render_frame(..., scale=scale)``.

    xy: ``f[..., 2]`` metres, world frame -> ``f64[..., 2]`` (column, row); pixel ``[int(row),
    int(column)]`` of the frame array covers the point.
    """
    return _to_pixel(_layout(params, scale), np.asarray(xy))


def frame_size(params: EnvParams, *, scale: float = 8) -> tuple[int, int]:
    """``(height, width)`` in pixels of the frames drawn at this scale."""
    layout = _layout(params, scale)
    return layout.height_px, layout.width_px


# ------------------------------------------------------------------------------------ drawing
class _Canvas:
    """An image at SUPERSAMPLE x the final size, addressed in world metres."""

    def __init__(self, image: Image.Image, layout: _Layout):
        self.image = image
        self.layout = layout
        self.draw = ImageDraw.Draw(image)
        self.k = layout.scale * SUPERSAMPLE  # supersampled pixels per metre

    def px(self, x: float, y: float) -> tuple[float, float]:
        column, row = _to_pixel(self.layout, np.array([x, y])) * SUPERSAMPLE
        return float(column), float(row)

    def width(self, metres: float) -> int:
        return max(1, round(metres * self.k))

    def disc(self, centre: np.ndarray, radius: float, fill: RGB | None, outline: RGB | None,
             outline_metres: float = 0.15) -> None:
        column, row = self.px(centre[0], centre[1])
        r = radius * self.k
        self.draw.ellipse(
            (column - r, row - r, column + r, row + r),
            fill=fill,
            outline=outline,
            width=self.width(outline_metres) if outline is not None else 0,
        )

    def segment(self, start: np.ndarray, end: np.ndarray, colour: RGB, metres: float,
                round_ends: bool = False) -> None:
        width = self.width(metres)
        self.draw.line((self.px(*start), self.px(*end)), fill=colour, width=width)
        if round_ends:  # Pillow lines end square; caps keep the leg bar from looking clipped
            for point in (start, end):
                column, row = self.px(*point)
                self.draw.ellipse(
                    (column - width / 2, row - width / 2, column + width / 2, row + width / 2),
                    fill=colour,
                )


@functools.lru_cache(maxsize=8)
def _font(size_px: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    # DejaVu is on most Linux systems; Pillow's bundled font is the fallback so CI needs nothing.
    for name in ("DejaVuSans-Bold.ttf", "DejaVuSans.ttf"):
        try:
            return ImageFont.truetype(name, size_px)
        except OSError:
            continue
    try:
        return ImageFont.load_default(size=size_px)
    except TypeError:  # Pillow < 10.1 has only the fixed-size bitmap font
        return ImageFont.load_default()


@functools.lru_cache(maxsize=16)
def _pitch(layout: _Layout) -> Image.Image:
    """The static background (surround, grass, lines, goals, empty header), drawn once per size."""
    size = (layout.width_px * SUPERSAMPLE, layout.height_px * SUPERSAMPLE)
    canvas = _Canvas(Image.new("RGB", size, SURROUND_COLOUR), layout)
    draw = canvas.draw
    hl, hw, gh = layout.half_length, layout.half_width, layout.goal_half

    stripe = 2 * hl / STRIPES
    for i in range(STRIPES):
        x0 = -hl + i * stripe
        left, top = canvas.px(x0, hw)
        right, bottom = canvas.px(x0 + stripe, -hw)
        draw.rectangle((left, top, right, bottom), fill=GRASS_COLOURS[i % 2])

    line = canvas.width(LINE_WIDTH)
    # Goal boxes: tinted with the defending team's colour (team 0 defends -x), net outline white.
    for side, team in ((-1.0, 0), (1.0, 1)):
        x_line, x_back = side * hl, side * (hl + GOAL_DEPTH)
        left, top = canvas.px(min(x_line, x_back), gh)
        right, bottom = canvas.px(max(x_line, x_back), -gh)
        net = tuple(int(0.45 * c + 0.55 * w) for c, w in zip(TEAM_COLOURS[team], LINE_COLOUR,
                                                             strict=True))
        draw.rectangle((left, top, right, bottom), fill=net, outline=LINE_COLOUR, width=line)
    left, top = canvas.px(-hl, hw)
    right, bottom = canvas.px(hl, -hw)
    draw.rectangle((left, top, right, bottom), outline=LINE_COLOUR, width=line)
    canvas.segment(np.array([0.0, hw]), np.array([0.0, -hw]), LINE_COLOUR, LINE_WIDTH)
    radius = CENTRE_CIRCLE_FRACTION * 2 * hl * canvas.k
    column, row = canvas.px(0.0, 0.0)
    draw.ellipse((column - radius, row - radius, column + radius, row + radius),
                 outline=LINE_COLOUR, width=line)
    canvas.disc(np.zeros(2), 0.45, LINE_COLOUR, None)
    for side in (-1.0, 1.0):  # posts at the mouth's corners
        for post_y in (-gh, gh):
            canvas.disc(np.array([side * hl, post_y]), 0.5, LINE_COLOUR, OUTLINE_COLOUR, 0.1)

    draw.rectangle((0, 0, size[0], layout.header_px * SUPERSAMPLE), fill=HEADER_COLOUR)
    return canvas.image


def _header(canvas: _Canvas, state: State, params: EnvParams, team_names: Sequence[str],
            title: str | None) -> None:
    """Step at the left (thesis), score at the top centre with the names in team colours."""
    header = canvas.layout.header_px * SUPERSAMPLE
    font = _font(max(8, round(header * 0.58)))
    draw = canvas.draw
    middle = header / 2
    pad = header * 0.4
    step = (
        "full time" if int(state.step) >= int(params.episode_length)
        else f"step {int(state.step)}/{int(params.episode_length)}"
    )
    draw.text((pad, middle), step, fill=TEXT_COLOUR, font=font, anchor="lm")
    score = np.asarray(state.score).astype(int)
    pieces = (
        (str(team_names[0]), TEAM_COLOURS[0]),
        (f"   {score[0]} : {score[1]}   ", TEXT_COLOUR),
        (str(team_names[1]), TEAM_COLOURS[1]),
    )
    lengths = [draw.textlength(text, font=font) for text, _ in pieces]
    # Centre the score itself, not the whole string, so it stays put when names differ in length.
    x = canvas.image.width / 2 - lengths[0] - lengths[1] / 2
    for (text, colour), length in zip(pieces, lengths, strict=True):
        lighter = tuple(int(0.55 * c + 0.45 * 255) for c in colour) if colour != TEXT_COLOUR \
            else colour
        draw.text((x, middle), text, fill=lighter, font=font, anchor="lm")
        x += length
    if title:
        draw.text((canvas.image.width - pad, middle), title, fill=TEXT_COLOUR, font=font,
                  anchor="rm")


def _mix(colour: RGB, towards: RGB, amount: float) -> RGB:
    mixed = [round((1 - amount) * c + amount * t) for c, t in zip(colour, towards, strict=True)]
    return (mixed[0], mixed[1], mixed[2])


def _players_and_ball(canvas: _Canvas, state: State, params: EnvParams,
                      dimmed: np.ndarray | None = None, highlight: Iterable[int] = ()) -> None:
    """Legs under bodies under heading ticks, then the ball on top of everything.

    dimmed: ``bool[2n + 1]`` entities (players in world order, then the ball) to fade out.
    """
    n = params.players_per_team
    radius, reach = float(params.player_radius), float(params.leg_reach)
    positions = np.asarray(state.positions, np.float64)
    headings = np.asarray(state.headings, np.float64)
    faded = np.zeros(2 * n + 1, bool) if dimmed is None else dimmed
    grass = GRASS_COLOURS[0]
    for row in range(2 * n):
        team = row // n
        centre, heading = positions[row], headings[row]
        forward = np.array([math.cos(heading), math.sin(heading)])
        left = np.array([-forward[1], forward[0]])
        fade = DIM_TOWARDS_GRASS if faded[row] else 0.0
        canvas.segment(centre - reach * left, centre + reach * left,
                       _mix(LEG_COLOURS[team], DIM_TOWARDS, fade), LEG_WIDTH, round_ends=True)
        canvas.disc(centre, radius, _mix(TEAM_COLOURS[team], DIM_TOWARDS, fade),
                    _mix(OUTLINE_COLOUR, grass, fade))
        canvas.segment(centre, centre + HEADING_TICK * radius * forward,
                       _mix(HEADING_COLOUR, grass, fade), 0.35)
    for row in range(2 * n):
        # Shirt numbers 1..n per team, above and to the right, readable in a clump.
        _number(canvas, positions[row], radius, str(row % n + 1), TEAM_COLOURS[row // n])
    for row in highlight:
        canvas.disc(positions[row], radius + 0.9, None, HIGHLIGHT_COLOUR, 0.3)
    fade = DIM_TOWARDS_GRASS if faded[2 * n] else 0.0
    canvas.disc(np.asarray(state.ball_position, np.float64), float(params.ball_radius),
                _mix(BALL_COLOUR, grass, fade), _mix(OUTLINE_COLOUR, grass, fade))


def _number(canvas: _Canvas, centre: np.ndarray, radius: float, text: str, team: RGB) -> None:
    size = max(NUMBER_MIN_PX, round(1.7 * canvas.layout.scale)) * SUPERSAMPLE
    x, y = canvas.px(float(centre[0]) + 0.7 * radius, float(centre[1]) + 0.7 * radius)
    canvas.draw.text(
        (x, y), text, fill=NUMBER_COLOUR, font=_font(size), anchor="lb",
        stroke_width=max(1, size // 7), stroke_fill=_mix(team, NUMBER_OUTLINE, 0.6),
    )


def _new_canvas(params: EnvParams, scale: float) -> _Canvas:
    layout = _layout(params, scale)
    return _Canvas(_pitch(layout).copy(), layout)


def _finish(canvas: _Canvas) -> np.ndarray:
    # reduce() is a box filter over SUPERSAMPLE x SUPERSAMPLE blocks: exact pixel mapping, fast.
    return np.asarray(canvas.image.reduce(SUPERSAMPLE), dtype=np.uint8)


def _host_state(state: State) -> State:
    # One transfer per leaf; later indexing is plain NumPy.
    return jax.tree.map(np.asarray, state)


def _highlight_rows(highlight: int | Iterable[int] | None, num_players: int) -> tuple[int, ...]:
    if highlight is None:
        return ()
    rows = (highlight,) if isinstance(highlight, int | np.integer) else tuple(highlight)
    for row in rows:
        if not 0 <= int(row) < num_players:
            raise ValueError(f"highlight={row!r} is not a player row in 0..{num_players - 1}")
    return tuple(int(row) for row in rows)


def render_frame(
    state: State,
    params: EnvParams,
    *,
    scale: float = 8,
    team_names: Sequence[str] = ("team 0", "team 1"),
    title: str | None = None,
    highlight: int | Iterable[int] | None = None,
) -> np.ndarray:
    """A top-down picture of one game (thesis fig. 4.1).

    state: one game's State (no batch axis), JAX or NumPy leaves. scale: pixels per metre.
    highlight: player rows (world order, team 0 first) to ring in yellow.
    Returns ``uint8[H, W, 3]``, ``(H, W) = frame_size(params, scale=scale)``.
    """
    state = _host_state(state)
    canvas = _new_canvas(params, scale)
    _players_and_ball(canvas, state, params,
                      highlight=_highlight_rows(highlight, 2 * params.players_per_team))
    _header(canvas, state, params, team_names, title)
    return _finish(canvas)


# ---------------------------------------------------------------------------- observation view
def _mask_of(state: State, params: EnvParams) -> jax.Array:
    return observe(state, params).entity_mask


# Compiled once per team size; a history is one device call, not one per frame.
_entity_mask = jax.jit(_mask_of)
_entity_masks_over_time = jax.jit(jax.vmap(_mask_of, in_axes=(0, None)))


def _player_row(player: int | tuple[int, int], n: int) -> int:
    if isinstance(player, tuple):
        team, k = player
        row = int(team) * n + int(k)
        if not (0 <= int(team) < 2 and 0 <= int(k) < n):
            raise ValueError(f"player={player!r} is not a (team, index) with index in 0..{n - 1}")
        return row
    if not 0 <= int(player) < 2 * n:
        raise ValueError(f"player={player!r} is not a player row in 0..{2 * n - 1}")
    return int(player)


def visible_entities(entity_mask: np.ndarray, params: EnvParams, player: int) -> np.ndarray:
    """Which entities a player sees, read from the env's own observation.

    entity_mask: ``bool[2, n, 2n]`` (``Observation.entity_mask`` of one game); player: world row.
    Returns ``bool[2n + 1]``: players in world order, then the ball. The player itself is False.
    """
    n = params.players_per_team
    index, _ = entity_layout(n)
    mask = np.asarray(entity_mask).reshape(2 * n, 2 * n)[player]
    seen = np.zeros(2 * n + 1, bool)
    seen[index[player][mask]] = True
    return seen


def _fov_overlay(canvas: _Canvas, centre: np.ndarray, heading: float, half_angle: float) -> None:
    """Lighten the sector ahead of the player, clipped to the pitch (lines included)."""
    layout = canvas.layout
    reach = 2 * math.hypot(layout.half_length, layout.half_width) + 1  # past every corner
    steps = max(2, math.ceil(math.degrees(2 * half_angle) / 2))
    angles = heading + np.linspace(-half_angle, half_angle, steps + 1)
    arc = centre + reach * np.stack([np.cos(angles), np.sin(angles)], axis=-1)
    polygon = [canvas.px(*centre)] + [canvas.px(*p) for p in arc]
    sector = Image.new("L", canvas.image.size, 0)
    sector_draw = ImageDraw.Draw(sector)
    sector_draw.polygon(polygon, fill=255)
    pitch = Image.new("L", canvas.image.size, 0)
    margin = LINE_WIDTH / 2
    left, top = canvas.px(-layout.half_length - margin, layout.half_width + margin)
    right, bottom = canvas.px(layout.half_length + margin, -layout.half_width - margin)
    ImageDraw.Draw(pitch).rectangle((left, top, right, bottom), fill=round(255 * FOV_ALPHA))
    alpha = Image.fromarray(np.minimum(np.asarray(sector), np.asarray(pitch)))
    canvas.image.paste(Image.new("RGB", canvas.image.size, FOV_COLOUR), (0, 0), alpha)


def _draw_observation(canvas: _Canvas, state: State, params: EnvParams, player: int,
                      seen: np.ndarray) -> None:
    n = params.players_per_team
    positions = np.asarray(state.positions, np.float64)
    centre = positions[player]
    _fov_overlay(canvas, centre, float(state.headings[player]), float(params.fov_half_angle))
    targets = np.concatenate([positions, np.asarray(state.ball_position, np.float64)[None]])
    for entity in np.flatnonzero(seen):
        if entity == 2 * n:
            colour = BALL_COLOUR
        else:
            colour = _mix(TEAM_COLOURS[entity // n], (255, 255, 255), 0.35)
        canvas.segment(centre, targets[entity], colour, 0.3)
    dimmed = ~seen
    dimmed[player] = False
    _players_and_ball(canvas, state, params, dimmed=dimmed, highlight=(player,))


def render_observation(
    state: State,
    params: EnvParams,
    player: int | tuple[int, int],
    *,
    scale: float = 8,
    team_names: Sequence[str] = ("team 0", "team 1"),
    title: str | None = None,
    entity_mask: Any = None,
) -> np.ndarray:
    """One player's partial view (thesis fig. 4.2) on top of the frame.

    The player's field of view is lightened, lines run from it to every teammate, opponent and
    ball it sees, and the rest is faded. What counts as seen is the env's own
    ``observe(state, params).entity_mask``, so the picture shows exactly what the player gets.

    player: world row (team 0 first) or ``(team, index)``. entity_mask: optional precomputed
    ``bool[2, n, 2n]`` for this state (``frames_from_states`` passes it to skip a device call).
    Returns ``uint8[H, W, 3]``.
    """
    n = params.players_per_team
    row = _player_row(player, n)
    host = _host_state(state)
    if entity_mask is None:
        entity_mask = _entity_mask(host, params)
    seen = visible_entities(np.asarray(entity_mask), params, row)
    canvas = _new_canvas(params, scale)
    _draw_observation(canvas, host, params, row, seen)
    if title is None:
        title = f"view of {team_names[row // n]} player {row % n}"
    _header(canvas, host, params, team_names, title)
    return _finish(canvas)


def frames_from_states(
    states: State,
    params: EnvParams,
    *,
    player: int | tuple[int, int] | None = None,
    progress: bool = False,
    follow_ball: float | None = None,
    **kwargs: Any,
) -> list[np.ndarray]:
    """Draw every step of a stacked history.

    states: State with a leading time axis ``[T, ...]`` on every leaf (e.g. from ``lax.scan`` or
    ``jax.tree.map(lambda *x: jnp.stack(x), *states)``). player: draw that player's observation
    view instead of the plain frame. progress: show a rich progress bar. follow_ball: zoom in
    on a window this many metres wide that follows the ball (the header stays; the frame keeps
    its size). kwargs go to ``render_frame`` / ``render_observation`` (scale, team_names,
    title, highlight). Returns T arrays ``uint8[H, W, 3]``.
    """
    if follow_ball is not None and not follow_ball > 0:
        raise ValueError(f"follow_ball={follow_ball!r} is invalid: give a window width > 0 m")
    host = _host_state(states)
    if np.ndim(host.step) != 1:
        raise ValueError(
            f"states must have a leading time axis: step has shape {np.shape(host.step)}, "
            "expected [T]"
        )
    steps = int(host.step.shape[0])
    masks = None
    if player is not None:
        masks = np.asarray(_entity_masks_over_time(host, params))
    indices: Iterable[int] = range(steps)
    if progress:
        from rich.progress import track

        indices = track(indices, description="rendering", total=steps)
    frames = []
    for t in indices:
        state_t = jax.tree.map(lambda leaf, t=t: leaf[t], host)
        if player is None or masks is None:
            frame = render_frame(state_t, params, **kwargs)
        else:
            frame = render_observation(state_t, params, player, entity_mask=masks[t], **kwargs)
        if follow_ball is not None:
            frame = _zoom(frame, params, np.asarray(state_t.ball_position), follow_ball,
                          float(kwargs.get("scale", 8)))
        frames.append(frame)
    return frames


def _zoom(frame: np.ndarray, params: EnvParams, centre: np.ndarray, width_m: float,
          scale: float) -> np.ndarray:
    """The part of ``frame`` below its header, ``width_m`` metres wide with the frame's aspect,
    centred on ``centre`` (kept inside the picture), scaled back up to the frame's size."""
    layout = _layout(params, scale)
    header = layout.header_px
    body = frame[header:]
    height, width = body.shape[:2]
    crop_w = min(width, max(8, round(width_m * scale)))
    crop_h = min(height, max(8, round(crop_w * height / width)))
    column, row = _to_pixel(layout, centre)
    row -= header
    left = int(np.clip(round(column - crop_w / 2), 0, width - crop_w))
    top = int(np.clip(round(row - crop_h / 2), 0, height - crop_h))
    window = Image.fromarray(body[top:top + crop_h, left:left + crop_w])
    zoomed = np.asarray(window.resize((width, height), Image.Resampling.BILINEAR))
    return np.concatenate([frame[:header], zoomed], axis=0)


def with_full_time(states: State, final_score: Sequence[int]) -> State:
    """``states`` (leading time axis ``[T]``) and one more entry: the last positions with the
    final score (goals of team 0 and team 1) and a step past the last, which frames label "full
    time". A record holds the state before each step, so a goal in the last step shows only
    here."""
    host = _host_state(states)
    last = jax.tree.map(lambda leaf: leaf[-1:], host)
    last = last.replace(
        score=np.asarray([final_score], dtype=np.asarray(host.score).dtype),
        step=np.asarray(host.step[-1:]) + 1,
    )
    return jax.tree.map(lambda a, b: np.concatenate([a, b]), host, last)


# ------------------------------------------------------------------------------------- videos
def _checked_frames(frames: Sequence[np.ndarray] | np.ndarray) -> list[np.ndarray]:
    frames = [np.asarray(frame) for frame in frames]
    if not frames:
        raise ValueError("no frames to save")
    shape = frames[0].shape
    if len(shape) != 3 or shape[-1] != 3:
        raise ValueError(f"frames must be uint8[H, W, 3], got shape {shape}")
    for i, frame in enumerate(frames):
        if frame.shape != shape:
            raise ValueError(f"frame {i} has shape {frame.shape}, frame 0 has {shape}")
    return [frame.astype(np.uint8, copy=False) for frame in frames]


def _check_fps(fps: float) -> None:
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise ValueError(f"fps={fps!r} is invalid: it must be a positive number")


def save_gif(frames: Sequence[np.ndarray] | np.ndarray, path: str | Path, fps: float = 20) -> Path:
    """Write an endlessly looping GIF. frames: ``uint8[H, W, 3]`` each, all the same size.

    One palette, fitted to a sample of frames, serves every frame: colours stay steady and Pillow
    can store each frame as the small rectangle that changed. GIF delays come in 10 ms steps, so
    fps is rounded to the nearest such delay (at least 20 ms, as browsers slow anything faster).
    """
    _check_fps(fps)
    frames = _checked_frames(frames)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    sample = frames[:: max(1, len(frames) // 8)][:8]
    palette = Image.fromarray(np.concatenate(sample, axis=0)).quantize(
        colors=256, method=Image.Quantize.MEDIANCUT
    )
    images = [
        Image.fromarray(frame).quantize(palette=palette, dither=Image.Dither.NONE)
        for frame in frames
    ]
    delay_ms = max(20, 10 * round(100 / fps))
    images[0].save(
        path, format="GIF", save_all=True, append_images=images[1:], duration=delay_ms, loop=0,
        optimize=False,
    )
    return path


def _pad_to_multiple(frame: np.ndarray, multiple: int) -> np.ndarray:
    height, width = frame.shape[:2]
    pad_rows, pad_columns = -height % multiple, -width % multiple
    if not pad_rows and not pad_columns:
        return frame
    return np.pad(frame, ((0, pad_rows), (0, pad_columns), (0, 0)), mode="edge")


MP4_BLOCK = 16  # H.264 macroblocks; padding here stops imageio-ffmpeg from resizing (blurring)


def save_mp4(frames: Sequence[np.ndarray] | np.ndarray, path: str | Path, fps: float = 20) -> Path:
    """Write an H.264 MP4 (yuv420p, plays everywhere). Frames are padded at the bottom and right
    (repeating the edge) to multiples of 16 pixels, as the codec needs; nothing is scaled."""
    import imageio.v2 as imageio

    _check_fps(fps)
    frames = _checked_frames(frames)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with warnings.catch_warnings():
        # JAX warns on every fork; starting ffmpeg is fork + exec at once, which is safe.
        warnings.filterwarnings(
            "ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning
        )
        writer = imageio.get_writer(
            path, format="FFMPEG", mode="I", fps=fps, codec="libx264", pixelformat="yuv420p",
            quality=8, macro_block_size=MP4_BLOCK, ffmpeg_log_level="error",
        )
        try:
            for frame in frames:
                writer.append_data(_pad_to_multiple(frame, MP4_BLOCK))
        finally:
            writer.close()
    return path


def save_video(frames: Sequence[np.ndarray] | np.ndarray, path: str | Path,
               fps: float = 20) -> Path:
    """Write a GIF or an MP4, chosen by the file suffix (``.gif`` or ``.mp4``)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".gif":
        return save_gif(frames, path, fps)
    if suffix == ".mp4":
        return save_mp4(frames, path, fps)
    raise ValueError(
        f"cannot save video to {str(path)!r}: unknown suffix {suffix!r}; allowed suffixes are "
        f"{', '.join(SUPPORTED_VIDEO_SUFFIXES)}"
    )
