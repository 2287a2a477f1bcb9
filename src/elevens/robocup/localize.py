"""Self-localisation of an rcssserver player from one ``see`` message.

Frame (the server's global frame, unmirrored for both teams): x from -52.5 (left goal
line) to +52.5 (right goal line), **y grows downward** (``t``op flags have y < 0,
``b``ottom flags y > 0), angles in degrees with positive rotation from +x towards +y
(clockwise on a screen). A player of the right team facing the left goal has body
direction 180.

What a ``see`` message gives (src/visualsenderplayer.cpp, rcssserver 19.0.0):

* flags/goals ``DIST DIR``: DIR is relative to the **head** (body + neck), rounded to
  whole degrees (``Rad2IDegRound`` since protocol v7, ``VisualSenderPlayerV7``; the
  recorded see_at_known_pose.json confirms rounding, not truncation). DIST is
  log-quantised (``quantize_step_l`` 0.01, i.e. about +-0.5 %) and rounded to 0.1 m,
  so near landmarks are more precise.
* lines ``DIST DIR``: DIR is the angle between the line of sight and the line, DIST the
  distance along the line of sight to the line (``sendLine``): DIR = round(s - 90) for
  s > 0 and round(s + 90) otherwise, s being the angle from the line's normal (pointing
  from the player to the line) to the line of sight. This gives the head direction
  directly and the perpendicular distance to the line (DIR 0, sight almost parallel
  to the line, is ambiguous and skipped).

Method: a weighted closed-form 2-D rigid alignment (Procrustes) of the seen landmark
points to their known positions gives a first pose; a few Gauss-Newton steps then
minimise range, bearing and line residuals, each divided by its quantisation noise
(so near flags count more); landmarks whose residual stays above 8 sigma are dropped
as outliers. The estimate is flagged ``valid=False`` (with NaN pose and a reason) when
there are too few landmarks or the fit is inconsistent; nothing is filled in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from elevens.robocup.protocol import SeeMessage

__all__ = ["LANDMARKS", "LINES", "PoseEstimate", "localize", "normalize_angle"]


def _landmarks() -> dict[str, tuple[float, float]]:
    # Default landmark positions of rcssserver (src/landmarkreader.cpp loadDefaults with
    # PITCH 105 x 68, goal_width 14.02, penalty area 16.5 x 40.32, outer flags 5 m
    # outside the lines); checked on the live server, shared/ROBOCUP_NOTES.md section 6.
    half_l, half_w, goal_half, pen_x, pen_half = 52.5, 34.0, 7.01, 36.0, 20.16
    table = {
        "f c": (0.0, 0.0),
        "f c t": (0.0, -half_w),
        "f c b": (0.0, half_w),
        "f l t": (-half_l, -half_w),
        "f l b": (-half_l, half_w),
        "f r t": (half_l, -half_w),
        "f r b": (half_l, half_w),
        "g l": (-half_l, 0.0),
        "g r": (half_l, 0.0),
        "f g l t": (-half_l, -goal_half),
        "f g l b": (-half_l, goal_half),
        "f g r t": (half_l, -goal_half),
        "f g r b": (half_l, goal_half),
        "f p l t": (-pen_x, -pen_half),
        "f p l c": (-pen_x, 0.0),
        "f p l b": (-pen_x, pen_half),
        "f p r t": (pen_x, -pen_half),
        "f p r c": (pen_x, 0.0),
        "f p r b": (pen_x, pen_half),
        "f t 0": (0.0, -half_w - 5.0),
        "f b 0": (0.0, half_w + 5.0),
        "f l 0": (-half_l - 5.0, 0.0),
        "f r 0": (half_l + 5.0, 0.0),
    }
    for d in (10, 20, 30, 40, 50):
        table[f"f t l {d}"] = (-float(d), -half_w - 5.0)
        table[f"f t r {d}"] = (float(d), -half_w - 5.0)
        table[f"f b l {d}"] = (-float(d), half_w + 5.0)
        table[f"f b r {d}"] = (float(d), half_w + 5.0)
    for d in (10, 20, 30):
        table[f"f l t {d}"] = (-half_l - 5.0, -float(d))
        table[f"f l b {d}"] = (-half_l - 5.0, float(d))
        table[f"f r t {d}"] = (half_l + 5.0, -float(d))
        table[f"f r b {d}"] = (half_l + 5.0, float(d))
    return table


#: Global position (x, y) of every default landmark, keyed by its ``see`` name
#: (``SeenObject.name``): 53 flags and the 2 goals.
LANDMARKS: dict[str, tuple[float, float]] = _landmarks()

#: Field lines: name -> (axis, coordinate); axis 0 = vertical line x = c, 1 = horizontal
#: line y = c.
LINES: dict[str, tuple[int, float]] = {
    "l l": (0, -52.5),
    "l r": (0, 52.5),
    "l t": (1, -34.0),
    "l b": (1, 34.0),
}

# Noise model (standard deviations of the quantisation errors, uniform -> width/sqrt(12)).
_DIST_REL = 0.01 / math.sqrt(3.0)  # log step 0.01 -> +-0.5 % relative
_DIST_ABS = 0.1 / math.sqrt(12.0)  # final rounding to 0.1 m
_DIR_SD = math.radians(1.0 / math.sqrt(12.0))  # rounding to whole degrees
_MIN_BEARING_DIST = 1.0  # bearings of landmarks closer than this are too noisy to use
_OUTLIER_Z = 8.0
_MAX_RMS_Z = 5.0
_FIELD_X, _FIELD_Y = 65.0, 50.0  # generous bounds of where a player can be


def normalize_angle(deg: float) -> float:
    """Wrap an angle in degrees to [-180, 180)."""
    return (deg + 180.0) % 360.0 - 180.0


@dataclass(frozen=True, slots=True)
class PoseEstimate:
    """Result of :func:`localize`.

    ``x``, ``y`` (metres), ``body_dir`` and ``head_dir`` (degrees, [-180, 180)) are in
    the server's global frame (y down). When ``valid`` is False they are NaN and
    ``reason`` says why. ``position_std`` (metres, sqrt of the x/y variance sum) and
    ``heading_std`` (degrees) come from the fit's covariance under the quantisation
    noise model; ``rms_z`` is the RMS residual in units of that noise (about 1 for a
    consistent fit). ``n_landmarks``/``n_lines`` count what was used.
    """

    valid: bool
    x: float
    y: float
    body_dir: float
    head_dir: float
    n_landmarks: int
    n_lines: int
    position_std: float = math.nan
    heading_std: float = math.nan
    rms_z: float = math.nan
    reason: str = ""

    @staticmethod
    def invalid(reason: str, n_landmarks: int = 0, n_lines: int = 0) -> PoseEstimate:
        """An estimate that carries no pose (all NaN), only the reason."""
        nan = math.nan
        return PoseEstimate(False, nan, nan, nan, nan, n_landmarks, n_lines, reason=reason)


def _procrustes(rel: np.ndarray, glob: np.ndarray, w: np.ndarray) -> tuple[float, float, float]:
    """Weighted rigid alignment glob ~ p + R(theta) rel; returns (x, y, theta rad)."""
    wsum = w.sum()
    rc = (w[:, None] * rel).sum(0) / wsum
    gc = (w[:, None] * glob).sum(0) / wsum
    a = rel - rc
    b = glob - gc
    cross = float((w * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])).sum())
    dot = float((w * (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])).sum())
    theta = math.atan2(cross, dot)
    c, s = math.cos(theta), math.sin(theta)
    x = gc[0] - (c * rc[0] - s * rc[1])
    y = gc[1] - (s * rc[0] + c * rc[1])
    return float(x), float(y), theta


def _wrap(rad: np.ndarray) -> np.ndarray:
    return (rad + np.pi) % (2.0 * np.pi) - np.pi


class _Problem:
    """Residuals and Jacobian of the range / bearing / line measurements."""

    def __init__(
        self,
        dist: np.ndarray,
        ang: np.ndarray,
        glob: np.ndarray,
        lines: list[tuple[int, float, float, float]],
    ) -> None:
        self.dist = dist
        self.ang = ang
        self.glob = glob
        self.sd_r = _DIST_REL * dist + _DIST_ABS
        self.use_b = dist >= _MIN_BEARING_DIST
        self.sd_b = _DIR_SD
        # lines: (axis, coordinate, sight-to-line angle s rad, distance along sight D)
        self.lines = lines

    def residuals(
        self, x: float, y: float, th: float, jac: bool
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray]:
        dx = self.glob[:, 0] - x
        dy = self.glob[:, 1] - y
        rho = np.maximum(np.hypot(dx, dy), 1e-6)
        r_range = (rho - self.dist) / self.sd_r
        r_bear = _wrap(np.arctan2(dy, dx) - th - self.ang) / self.sd_b
        r_bear = np.where(self.use_b, r_bear, 0.0)
        line_res: list[float] = []
        line_jac: list[tuple[float, float, float]] = []
        for axis, coord, s_obs, dist in self.lines:
            own = x if axis == 0 else y
            # The normal points from the player to the line (sendLine's line_normal).
            sign = 1.0 if coord > own else -1.0
            normal = (0.0 if sign > 0 else math.pi) if axis == 0 else sign * math.pi / 2
            s_pred = math.remainder(normal - th, 2.0 * math.pi)
            line_res.append(math.remainder(s_pred - s_obs, 2.0 * math.pi) / _DIR_SD)
            line_jac.append((0.0, 0.0, -1.0 / _DIR_SD))
            perp_obs = dist * math.cos(s_obs)
            sd_p = (
                math.hypot(
                    math.cos(s_obs) * (_DIST_REL * dist + _DIST_ABS),
                    dist * math.sin(s_obs) * _DIR_SD,
                )
                + _DIST_ABS
            )
            line_res.append((sign * (coord - own) - perp_obs) / sd_p)
            line_jac.append((-sign / sd_p, 0.0, 0.0) if axis == 0 else (0.0, -sign / sd_p, 0.0))
        res = np.concatenate([r_range, r_bear, np.asarray(line_res, dtype=float)])
        if not jac:
            return res, None, r_range, r_bear
        n = len(self.dist)
        jmat = np.zeros((2 * n + len(line_res), 3))
        jmat[:n, 0] = -dx / rho / self.sd_r
        jmat[:n, 1] = -dy / rho / self.sd_r
        rho2 = rho * rho
        jmat[n : 2 * n, 0] = np.where(self.use_b, dy / rho2 / self.sd_b, 0.0)
        jmat[n : 2 * n, 1] = np.where(self.use_b, -dx / rho2 / self.sd_b, 0.0)
        jmat[n : 2 * n, 2] = np.where(self.use_b, -1.0 / self.sd_b, 0.0)
        if line_jac:
            jmat[2 * n :] = np.asarray(line_jac)
        return res, jmat, r_range, r_bear


def _fit(
    prob: _Problem, x: float, y: float, th: float, iters: int = 6
) -> tuple[float, float, float, np.ndarray | None]:
    cov = None
    for _ in range(iters):
        res, jmat, _, _ = prob.residuals(x, y, th, jac=True)
        assert jmat is not None
        jtj = jmat.T @ jmat
        try:
            step = np.linalg.solve(jtj, -(jmat.T @ res))
            cov = np.linalg.inv(jtj)
        except np.linalg.LinAlgError:
            return x, y, th, None
        x, y, th = x + float(step[0]), y + float(step[1]), th + float(step[2])
        th = math.remainder(th, 2.0 * math.pi)
        if abs(step[0]) + abs(step[1]) < 1e-4 and abs(step[2]) < 1e-6:
            break
    return x, y, th, cov


def localize(see: SeeMessage, head_angle: float = 0.0, *, min_landmarks: int = 2) -> PoseEstimate:
    """Estimate the player's global position and body/head direction from ``see``.

    ``head_angle`` is the neck angle relative to the body, from the latest
    ``SenseBody.head_angle`` (see directions are relative to the head). Needs at least
    ``min_landmarks`` identified flags/goals with distances, or one such landmark and a
    line; otherwise (or if the fit is inconsistent) the result has ``valid=False``.
    """
    if not math.isfinite(head_angle):
        raise ValueError(f"head_angle must be finite, got {head_angle!r}")
    if min_landmarks < 2:
        raise ValueError(f"min_landmarks must be at least 2, got {min_landmarks}")
    names: list[str] = []
    dist: list[float] = []
    ang: list[float] = []
    glob: list[tuple[float, float]] = []
    lines: list[tuple[int, float, float, float]] = []
    for obj in see.objects:
        if obj.close or obj.distance is None:
            continue
        if obj.kind in ("flag", "goal"):
            pos = LANDMARKS.get(obj.name)
            if pos is None:
                continue  # custom landmark file: position unknown
            names.append(obj.name)
            dist.append(obj.distance)
            ang.append(math.radians(obj.direction))
            glob.append(pos)
        elif obj.kind == "line" and obj.name in LINES and obj.direction != 0:
            # Reported angle is round(s - 90) for s > 0, round(s + 90) for s <= 0.
            d = obj.direction
            s = d + 90.0 if d < 0 else d - 90.0
            axis, coord = LINES[obj.name]
            lines.append((axis, coord, math.radians(s), obj.distance))
    n_lm, n_ln = len(dist), len(lines)
    if n_lm < min_landmarks and not (n_lm >= 1 and n_ln >= 1):
        return PoseEstimate.invalid(
            f"{n_lm} landmark(s) with distance and {n_ln} line(s) seen; need "
            f"{min_landmarks} landmarks or 1 landmark and a line",
            n_lm,
            n_ln,
        )

    dist_a = np.asarray(dist)
    ang_a = np.asarray(ang)
    glob_a = np.asarray(glob, dtype=float)
    rel = np.stack([dist_a * np.cos(ang_a), dist_a * np.sin(ang_a)], axis=1)
    if n_lm >= 2:
        sd = 0.006 * dist_a + 0.03
        x, y, th = _procrustes(rel, glob_a, 1.0 / (sd * sd))
    else:
        # One landmark: heading from the first line (assuming we are inside the pitch).
        axis, coord, s_obs, _ = lines[0]
        normal = (0.0 if coord > 0 else math.pi) if axis == 0 else math.copysign(math.pi / 2, coord)
        th = normal - s_obs
        x = glob_a[0, 0] - (math.cos(th) * rel[0, 0] - math.sin(th) * rel[0, 1])
        y = glob_a[0, 1] - (math.sin(th) * rel[0, 0] + math.cos(th) * rel[0, 1])

    keep = np.ones(n_lm, dtype=bool)
    keep_lines = list(lines)
    max_refits = 3
    for attempt in range(max_refits + 1):  # fit; drop the worst outlier and refit
        prob = _Problem(dist_a[keep], ang_a[keep], glob_a[keep], keep_lines)
        x, y, th, cov = _fit(prob, x, y, th)
        if cov is None:
            return PoseEstimate.invalid("degenerate landmark geometry", n_lm, n_ln)
        if attempt == max_refits:
            break
        res, _, r_range, r_bear = prob.residuals(x, y, th, jac=False)
        z_lm = np.maximum(np.abs(r_range), np.abs(r_bear))
        worst = int(np.argmax(z_lm))
        if keep_lines:
            z_lines = np.abs(res[2 * len(z_lm) :]).reshape(-1, 2).max(1)
            if z_lines.max() > max(_OUTLIER_Z, z_lm[worst]):
                keep_lines.pop(int(np.argmax(z_lines)))
                continue
        if z_lm[worst] > _OUTLIER_Z and keep.sum() > max(min_landmarks, 2):
            keep[np.flatnonzero(keep)[worst]] = False
            continue
        break
    res, _, _, _ = prob.residuals(x, y, th, jac=False)
    rms = float(np.sqrt(np.mean(res * res)))
    used_lm, used_ln = int(keep.sum()), len(keep_lines)
    if rms > _MAX_RMS_Z:
        return PoseEstimate.invalid(
            f"landmarks inconsistent (RMS residual {rms:.1f} sigma)", used_lm, used_ln
        )
    if not (abs(x) <= _FIELD_X and abs(y) <= _FIELD_Y):
        return PoseEstimate.invalid(
            f"estimate ({x:.1f}, {y:.1f}) is off the field", used_lm, used_ln
        )
    head = normalize_angle(math.degrees(th))
    assert cov is not None
    return PoseEstimate(
        valid=True,
        x=x,
        y=y,
        body_dir=normalize_angle(head - head_angle),
        head_dir=head,
        n_landmarks=used_lm,
        n_lines=used_ln,
        position_std=float(math.sqrt(max(cov[0, 0] + cov[1, 1], 0.0))),
        heading_std=float(math.degrees(math.sqrt(max(cov[2, 2], 0.0)))),
        rms_z=rms,
    )
