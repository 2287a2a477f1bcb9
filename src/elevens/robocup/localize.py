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
import threading
from dataclasses import dataclass
from typing import TypeAlias

import numpy as np

from elevens.robocup.protocol import SeeMessage

__all__ = ["LANDMARKS", "LINES", "PoseEstimate", "localize", "normalize_angle"]


def _landmarks() -> dict[str, tuple[float, float]]:
    # Default landmark positions of rcssserver (src/landmarkreader.cpp loadDefaults with
    # PITCH 105 x 68, goal_width 14.02, penalty area 16.5 x 40.32, outer flags 5 m
    # outside the lines); checked on the live server.
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


# Implementation notes (speed). With ~25 landmarks every numpy call costs far more
# than its arithmetic, so the computation is organised to make few of them:
#
# * positions and directions are complex numbers (x + iy), so one complex operation
#   does the work of an x and a y one; the seen directions come as unit vectors from
#   a table of whole degrees (the server rounds them);
# * the Procrustes sums are accumulated in the loop that collects the landmarks;
# * the Jacobian and residuals of all landmark measurements live in one array, so
#   J'J, J'r and r'r come from a single matrix product, and the 3x3 system is solved
#   in closed form in Python. That array and its views are made once per landmark
#   count and thread (_workspace): views cost as much as a small computation;
# * numeric constants that meet arrays are 0-d arrays (numpy handles a Python float
#   operand ~40% slower than an array one);
# * the residuals at the final pose usually come from the last step's linear model
#   (see _fit; error provably below 2e-7 sigma) instead of another evaluation.
#
# The iterations (start, steps, stopping rule, outlier rounds) are those of the
# straightforward formulation (x/y arrays, np.linalg.solve/inv per step), so the
# results agree with it to ~1e-12 (1e-9 where the linear model is used).

#: Landmark name -> complex position x + iy.
_LANDMARK_Z: dict[str, complex] = {name: complex(x, y) for name, (x, y) in LANDMARKS.items()}
#: Direction in whole degrees -> e^(-i direction): turns a seen bearing to 0.
_UNROTATE: dict[float, complex] = {
    float(d): complex(math.cos(math.radians(d)), -math.sin(math.radians(d)))
    for d in range(-180, 181)
}
_LANDMARK_KINDS = frozenset(("flag", "goal"))
_TWO_PI = 2.0 * math.pi
_LINE_W = 1.0 / _DIR_SD  # weight of a line's angle residual
_SD_REL, _SD_ABS, _MIN_RHO = np.array(_DIST_REL), np.array(_DIST_ABS), np.array(1e-6)
_BEAR_MIN_DIST, _BEAR_W = np.array(_MIN_BEARING_DIST), np.array(1.0 / _DIR_SD)
_NEG_ONE, _I = np.array(-1.0), np.array(1j)


def _unrotate(direction: float) -> complex:
    """e^(-i direction) for a direction in degrees (what _UNROTATE holds)."""
    rad = math.radians(direction)
    return complex(math.cos(rad), -math.sin(rad))


def _procrustes(
    wsum: float, wr_sum: complex, wg_sum: complex, cross: complex
) -> tuple[float, float, float]:
    """Weighted rigid alignment glob ~ p + R(theta) rel; returns (x, y, theta rad).

    From the sums over the landmarks of w, w conj(rel), w glob and w conj(rel) glob
    (complex positions; rel as seen, relative to the head). The closed form of the
    weighted 2-D Procrustes problem: theta = arg sum w conj(rel - rc)(glob - gc),
    p = gc - R(theta) rc, with rc/gc the weighted centroids.
    """
    rc = wr_sum.conjugate() / wsum
    gc = wg_sum / wsum
    # sum w conj(rel - rc)(glob - gc) = sum w conj(rel) glob - wsum conj(rc) gc
    acc = cross - wsum * rc.conjugate() * gc
    theta = math.atan2(acc.imag, acc.real)
    p = gc - complex(math.cos(theta), math.sin(theta)) * rc
    return p.real, p.imag, theta


_Workspace: TypeAlias = tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray
]
_THREAD = threading.local()


def _workspace(n: int) -> _Workspace:
    """The arrays of a fit of ``n`` landmarks, made once per size and thread (see
    :func:`_fit`): ``jac`` (2n, 4), ``jac.T``, the range and the bearing rows of the
    complex d/dx + i d/dy column of ``jac``, the residual column, its range and bearing
    halves, and the bearing rows of the d/dtheta column. The d/dtheta column of the
    range rows stays 0; a fit overwrites everything else."""
    spaces: dict[int, _Workspace] | None = getattr(_THREAD, "spaces", None)
    if spaces is None:
        spaces = _THREAD.spaces = {}
    space = spaces.get(n)
    if space is None:
        jac = np.zeros((2 * n, 4))
        jac_xy = jac.view(np.complex128)[:, 0]
        res = jac[:, 3]
        space = spaces[n] = (
            jac,
            jac.T,
            jac_xy[:n],
            jac_xy[n:],
            res,
            res[:n],
            res[n:],
            jac[n:, 2],
        )
    return space


def _line_residuals(
    line_data: list[tuple[int, float, float, float, float]], x: float, y: float, th: float
) -> list[tuple[float, float, float, int]]:
    """Per line (axis, coordinate, sight-to-line angle, perpendicular distance seen, its
    noise): angle residual, distance residual, d(distance residual) / d(own coordinate)
    (all in units of noise), and the axis of that coordinate."""
    out = []
    for axis, coord, s_obs, perp_obs, sd_p in line_data:
        own = x if axis == 0 else y
        # The normal points from the player to the line (sendLine's line_normal).
        sign = 1.0 if coord > own else -1.0
        normal = (0.0 if sign > 0 else math.pi) if axis == 0 else sign * math.pi / 2
        s_pred = math.remainder(normal - th, _TWO_PI)
        out.append(
            (
                math.remainder(s_pred - s_obs, _TWO_PI) / _DIR_SD,
                (sign * (coord - own) - perp_obs) / sd_p,
                -sign / sd_p,
                axis,
            )
        )
    return out


#: Residuals at the final pose may be taken from the last Gauss-Newton step's
#: linearisation when its remainder is provably below this (in units of noise);
#: otherwise they are evaluated anew.
_LINEARISE_MAX_ERROR = 2e-7


def _fit(
    dist: np.ndarray,
    unrot: np.ndarray,
    glob: np.ndarray,
    lines: list[tuple[int, float, float, float]],
    x: float,
    y: float,
    th: float,
) -> tuple[
    float,
    float,
    float,
    tuple[float, float, float] | None,
    np.ndarray,
    np.ndarray,
    float,
    list[float],
]:
    """Gauss-Newton fit of the pose to range / bearing / line measurements.

    The landmarks come as their seen distances ``dist``, seen directions ``unrot``
    (e^(-i direction)) and complex positions ``glob``; ``lines`` as (axis, coordinate,
    sight-to-line angle rad, distance along the sight). Starts at (x, y, th). Returns
    the pose; the diagonal of the covariance of the last
    step's linearisation (None if J'J was singular, and then nothing else is valid);
    the range and the bearing residuals of the landmarks and r'r of all residuals at
    the final pose; and per line the larger of its two residuals. Residuals are in
    units of their noise.

    Landmark rows live in one (2n, 4) array ``jac``: columns 0-2 the Jacobian (d/dx,
    d/dy, d/dtheta) of each residual, column 3 the residual itself; rows 0..n-1 are
    ranges, n..2n-1 bearings. Columns 0-1 are written as one complex column.
    ``jac.T @ jac`` gives J'J and J'r at once; the line rows are added in Python.
    """
    n = len(dist)
    sd_r = dist * _SD_REL
    sd_r += _SD_ABS
    # Bearing weight 1/sd, 0 for landmarks too close for a useful bearing.
    w_b = (dist >= _BEAR_MIN_DIST) * _BEAR_W
    # d/dx + i d/dy (dz = landmark - position): range -dz / (rho sd), bearing
    # -i w_b dz / rho^2 = range * i w_b sd / rho.
    neg_inv_sd_r = _NEG_ONE / sd_r
    k_bear = (w_b * sd_r) * _I
    jac, jac_t, j_range, j_bear, res, r_range, r_bear, theta_col = _workspace(n)
    np.negative(w_b, out=theta_col)
    # lines: (axis, coordinate, sight-to-line angle s rad, perpendicular distance
    # observed, its noise)
    line_data = []
    for axis, coord, s_obs, d in lines:
        sd_p = (
            math.hypot(math.cos(s_obs) * (_DIST_REL * d + _DIST_ABS), d * math.sin(s_obs) * _DIR_SD)
            + _DIST_ABS
        )
        line_data.append((axis, coord, s_obs, d * math.cos(s_obs), sd_p))

    def landmark_residuals(x: float, y: float, th: float) -> tuple[np.ndarray, np.ndarray]:
        """Into r_range and r_bear, the residuals at the pose: range rho - d and the angle of
        dz turned by -(th + seen direction), which is the bearing residual, already in
        [-pi, pi]; both over their noise. Returns dz (landmark - position) and rho."""
        dz = glob - complex(x, y)
        rho = np.abs(dz)
        np.maximum(rho, _MIN_RHO, out=rho)
        np.subtract(rho, dist, out=r_range)
        np.divide(r_range, sd_r, out=r_range)
        turned = dz * (unrot * complex(math.cos(th), -math.sin(th)))
        np.arctan2(turned.imag, turned.real, out=r_bear)
        np.multiply(r_bear, w_b, out=r_bear)
        return dz, rho

    cov = None
    for _ in range(6):
        # The residuals at the pose, then the Jacobian.
        dz, rho = landmark_residuals(x, y, th)
        np.multiply(dz, neg_inv_sd_r / rho, out=j_range)
        np.multiply(j_range, k_bear / rho, out=j_bear)
        # [J'J | J'r], rows 0-2 (row 3 holds J'r and r'r again)
        (a00, a01, a02, g0), (_, a11, a12, g1), (_, _, a22, g2), _ = np.dot(jac_t, jac).tolist()
        for axis, coord, s_obs, perp_obs, sd_p in line_data:  # _line_residuals, inlined
            own = x if axis == 0 else y
            sign = 1.0 if coord > own else -1.0
            normal = (0.0 if sign > 0 else math.pi) if axis == 0 else sign * math.pi / 2
            r_ang = math.remainder(math.remainder(normal - th, _TWO_PI) - s_obs, _TWO_PI) / _DIR_SD
            j_own = -sign / sd_p
            r_dist = (sign * (coord - own) - perp_obs) / sd_p
            a22 += _LINE_W * _LINE_W
            g2 -= _LINE_W * r_ang
            if axis == 0:
                a00 += j_own * j_own
                g0 += j_own * r_dist
            else:
                a11 += j_own * j_own
                g1 += j_own * r_dist
        # Solve J'J step = -J'r in closed form (cofactors). J'J singular to working
        # precision (det below 1e-12 of the product of its diagonal, where LAPACK would
        # meet a zero pivot or round-off) means degenerate geometry; a merely ill-
        # conditioned one goes to numpy, as does nan.
        c00 = a11 * a22 - a12 * a12
        c01 = a02 * a12 - a01 * a22
        c02 = a01 * a12 - a02 * a11
        det = a00 * c00 + a01 * c01 + a02 * c02
        scale = abs(a00 * a11 * a22)
        if abs(det) <= 1e-12 * scale:
            return x, y, th, None, r_range, r_bear, 0.0, []
        if abs(det) > 1e-9 * scale:
            c11 = a00 * a22 - a02 * a02
            c12 = a01 * a02 - a00 * a12
            c22 = a00 * a11 - a01 * a01
            dx = -(c00 * g0 + c01 * g1 + c02 * g2) / det
            dy = -(c01 * g0 + c11 * g1 + c12 * g2) / det
            dth = -(c02 * g0 + c12 * g1 + c22 * g2) / det
            cov = (c00 / det, c11 / det, c22 / det)
        else:  # also for nan
            jtj = np.array(((a00, a01, a02), (a01, a11, a12), (a02, a12, a22)))
            try:
                dx, dy, dth = np.linalg.solve(jtj, -np.array((g0, g1, g2))).tolist()
                inv = np.linalg.inv(jtj)
            except np.linalg.LinAlgError:
                return x, y, th, None, r_range, r_bear, 0.0, []
            cov = (float(inv[0, 0]), float(inv[1, 1]), float(inv[2, 2]))
        x, y, th = x + dx, y + dy, th + dth
        th = math.remainder(th, _TWO_PI)
        if abs(dx) + abs(dy) < 1e-4 and abs(dth) < 1e-6:
            break

    # Landmark residuals at the final pose. The last step was small, so they are
    # usually those of its linear model, r + J step, whose error is at most
    # |step|^2 / 2 times the largest second derivative along the step: 1 / (rho sd)
    # for a range, w_b / rho^2 for a bearing, rho >= (closest landmark) - |step|.
    step = math.hypot(dx, dy)
    near = float(np.minimum.reduce(rho)) - step
    if (
        near > 0.0
        and 0.5 * step * step * (1.0 / (near * _DIST_ABS) + _LINE_W / (near * near))
        < _LINEARISE_MAX_ERROR
    ):
        lin = np.dot(jac, (dx, dy, dth, 1.0))
        lin_range, lin_bear = lin[:n], lin[n:]
    else:  # evaluate anew (as in the loop)
        landmark_residuals(x, y, th)
        lin, lin_range, lin_bear = res, r_range, r_bear
    sq = float(np.dot(lin, lin))
    line_z = []
    for r_ang, r_dist, _, _ in _line_residuals(line_data, x, y, th):
        sq += r_ang * r_ang + r_dist * r_dist
        line_z.append(max(abs(r_ang), abs(r_dist)))
    return x, y, th, cov, lin_range, lin_bear, sq, line_z


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
    glob_l: list[complex] = []
    dist_l: list[float] = []
    unrot_l: list[complex] = []
    lines: list[tuple[int, float, float, float]] = []
    # Procrustes sums: w, w conj(rel), w glob, w conj(rel) glob (rel = d e^(i dir)).
    wsum = 0.0
    wr_sum = wg_sum = cross = 0j
    landmark_z = _LANDMARK_Z.get
    unrotate = _UNROTATE.get
    kinds = _LANDMARK_KINDS
    add_glob, add_dist, add_unrot = glob_l.append, dist_l.append, unrot_l.append
    for obj in see.objects:
        name = obj.name
        g = landmark_z(name)
        if g is not None:
            d = obj.distance
            if d is None or obj.close or obj.kind not in kinds:
                continue
            u = unrotate(obj.direction)
            if u is None:
                u = _unrotate(obj.direction)
            add_glob(g)
            add_dist(d)
            add_unrot(u)
            sd = 0.006 * d + 0.03
            w = 1.0 / (sd * sd)
            wr = w * d * u
            wsum += w
            wr_sum += wr
            wg_sum += w * g
            cross += wr * g
        elif name in LINES:
            direction = obj.direction
            if obj.close or obj.distance is None or obj.kind != "line" or direction == 0:
                continue
            # Reported angle is round(s - 90) for s > 0, round(s + 90) for s <= 0.
            s = direction + 90.0 if direction < 0 else direction - 90.0
            axis, coord = LINES[name]
            lines.append((axis, coord, math.radians(s), obj.distance))
    n_lm, n_ln = len(dist_l), len(lines)
    if n_lm < min_landmarks and not (n_lm >= 1 and n_ln >= 1):
        return PoseEstimate.invalid(
            f"{n_lm} landmark(s) with distance and {n_ln} line(s) seen; need "
            f"{min_landmarks} landmarks or 1 landmark and a line",
            n_lm,
            n_ln,
        )

    if n_lm >= 2:
        x, y, th = _procrustes(wsum, wr_sum, wg_sum, cross)
    else:
        # One landmark: heading from the first line (assuming we are inside the pitch).
        axis, coord, s_obs, _ = lines[0]
        normal = (0.0 if coord > 0 else math.pi) if axis == 0 else math.copysign(math.pi / 2, coord)
        th = normal - s_obs
        rel = dist_l[0] * unrot_l[0].conjugate()
        p = glob_l[0] - complex(math.cos(th), math.sin(th)) * rel
        x, y = p.real, p.imag

    dist_a = np.array(dist_l, dtype=np.float64)
    unrot_a = np.array(unrot_l, dtype=np.complex128)
    glob_a = np.array(glob_l, dtype=np.complex128)
    kept = list(range(n_lm))  # landmarks still in the fit
    keep_lines = list(lines)
    max_refits = 3
    for attempt in range(max_refits + 1):  # fit; drop the worst outlier and refit
        if attempt:
            x, y, th, cov, r_range, r_bear, sq, line_z = _fit(
                dist_a[kept], unrot_a[kept], glob_a[kept], keep_lines, x, y, th
            )
        else:
            x, y, th, cov, r_range, r_bear, sq, line_z = _fit(
                dist_a, unrot_a, glob_a, keep_lines, x, y, th
            )
        if cov is None:
            return PoseEstimate.invalid("degenerate landmark geometry", n_lm, n_ln)
        if attempt == max_refits or sq <= _OUTLIER_Z * _OUTLIER_Z:
            break  # (with r'r <= _OUTLIER_Z^2 no single residual is above _OUTLIER_Z)
        z_lm = np.maximum(np.abs(r_range), np.abs(r_bear))
        worst = int(z_lm.argmax())
        z_worst = float(z_lm[worst])
        if line_z:
            z_line_max = max(line_z)
            if z_line_max > max(_OUTLIER_Z, z_worst):
                keep_lines.pop(line_z.index(z_line_max))
                continue
        if z_worst > _OUTLIER_Z and len(kept) > max(min_landmarks, 2):
            del kept[worst]
            continue
        break
    rms = math.sqrt(sq / (2 * len(kept) + 2 * len(keep_lines)))
    used_lm, used_ln = len(kept), len(keep_lines)
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
        True,  # valid
        x,
        y,
        normalize_angle(head - head_angle),  # body_dir
        head,  # head_dir
        used_lm,  # n_landmarks
        used_ln,  # n_lines
        math.sqrt(max(cov[0] + cov[1], 0.0)),  # position_std
        math.degrees(math.sqrt(max(cov[2], 0.0))),  # heading_std
        rms,  # rms_z
    )
