"""Stance-foot contact points from a rigid body's pose: the slope and the hub they fix (no-slip).

While a foot stands on the slope it does not move (no slip): some body point f (the foot, in the body frame)
stays at one world point c. For frames i of one stance, ``T_i + R_i f = c`` (``R_i`` world-from-body, ``T_i``
the tracked body point, m). Every window of half a step (in wheel angle) is fitted with this pivot model
(linear least squares, f in the wheel plane); windows inside one stance fit to the marker noise, windows that
straddle an impact do not. Accepted windows are grouped by their contact point along the travel; each group is
one stance with its contact point ``c_k`` (world) and foot ``f_k`` (body).

* Slope: every ``c_k`` lies on the slope, so the slope is the line of ``c_k`` height against the horizontal
  distance along the travel (two stances suffice); its uncertainty combines each contact point's least-squares
  error, the spread of its windows (leg compression moves the pivot a little) and the scatter about the line.
* Hub: the feet of an n-legged wheel sit at angles alpha apart around the hub, ``f_k = d + Rot(-m_k alpha) u``
  (m_k legs after the first), linear in the hub ``d`` and the first foot ``u``; a Gaussian prior keeps ``d``
  within a few cm of the tracked point. ``d`` is reported undetermined when its standard error is large.
Positions in m, angles in rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["Contact", "ContactFit", "fit_contacts", "hub_from_contacts", "slope_from_contacts", "HUB_PRIOR_SD_M"]

#: Prior standard deviation of the hub offset from the tracked point, per in-plane component, m.
HUB_PRIOR_SD_M = 0.04
#: Hub offsets whose standard error exceeds this (m) are not determined by the data.
HUB_MAX_SE_M = 0.005
#: At most this many stances are used (the first ones of the walk).
MAX_STANCES = 40
#: Contact points closer than this along the travel, m, belong to one stance (a step of any wheel this
#: analysis meets is several times longer: 0.18 m for Table 1).
STANCE_SEPARATION_M = 0.05
#: Least frames in a window.
MIN_WINDOW_FRAMES = 6
#: Floor of a contact point's height uncertainty, m (feet are not points, legs compress).
CONTACT_FLOOR_M = 0.1e-3


@dataclass(frozen=True)
class Contact:
    """One stance: world contact point ``c_m``, body foot point ``f_m`` (in the wheel plane), the wheel angle at
    its middle ``angle_rad``, the standard error of its height ``sd_m`` and the number of windows."""

    c_m: np.ndarray
    f_m: np.ndarray
    angle_rad: float
    sd_m: float
    n_windows: int
    residual_m: float


@dataclass(frozen=True)
class ContactFit:
    contacts: tuple[Contact, ...]
    plane: np.ndarray  # (3, 2) body-frame basis of the wheel plane
    axis_body: np.ndarray  # (3,)
    noise_m: float  # RMS pivot residual of the best windows


def _pivot(r: np.ndarray, t: np.ndarray, plane: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """Least squares ``t_i + r_i (plane @ g) = c``: returns f (body), c (world), RMS residual, covariance of c."""
    n = t.shape[0]
    rp = r @ plane  # (n, 3, 2)
    a = np.zeros((3 * n, 5))
    a[:, :2] = rp.reshape(3 * n, 2)
    a[:, 2:] = -np.tile(np.eye(3), (n, 1))
    b = -t.reshape(3 * n)
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    res = a @ sol - b
    dof = max(3 * n - 5, 1)
    s2 = float(res @ res) / dof
    try:
        cov = np.linalg.inv(a.T @ a) * s2
    except np.linalg.LinAlgError:
        cov = np.full((5, 5), np.inf)
    return plane @ sol[:2], sol[2:], math.sqrt(float(res @ res) / n), cov[2:, 2:]


def fit_contacts(
    rot,
    trans_m: np.ndarray,
    angle_rad: np.ndarray,
    axis: np.ndarray,
    mask: np.ndarray,
    *,
    alpha_rad: float = math.pi / 4,
    travel: np.ndarray | None = None,
) -> ContactFit | None:
    """The stances of the frames in ``mask`` (see the module doc); None when the wheel turns under half a step.

    ``rot`` (n, 3, 3) or a `RotationStack`, ``trans_m`` (n, 3), ``angle_rad`` (n,) the unwrapped wheel angle,
    ``axis`` its world axis, ``travel`` the horizontal travel direction (for ordering the stances).
    """
    ok = mask & np.isfinite(angle_rad) & ~np.isnan(trans_m).any(axis=1)
    idx = np.flatnonzero(ok)
    if idx.size < 2 * MIN_WINDOW_FRAMES:
        return None
    ang = angle_rad[idx]
    lo = float(np.min(ang))
    # the first MAX_STANCES steps of rotation are enough
    keep = ang <= lo + MAX_STANCES * alpha_rad
    idx, ang = idx[keep], ang[keep]
    hi = float(np.max(ang))
    width = alpha_rad / 2
    if hi - lo < width:
        return None
    r_all = rot[idx]
    if not isinstance(r_all, np.ndarray):
        r_all = np.asarray(r_all)
    t_all = trans_m[idx]
    good = ~np.isnan(r_all.reshape(len(idx), 9)).any(axis=1)
    idx, ang, r_all, t_all = idx[good], ang[good], r_all[good], t_all[good]
    a_body = np.einsum("nji,j->ni", r_all, axis).mean(axis=0)
    a_body /= np.linalg.norm(a_body)
    e1 = np.cross(a_body, [1.0, 0.0, 0.0] if abs(a_body[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a_body, e1)
    plane = np.column_stack([e1, e2])
    if travel is None:
        xy = t_all[:, :2] - t_all[0, :2]
        _, _, vt = np.linalg.svd(xy - xy.mean(axis=0), full_matrices=False)
        u = vt[0] if (xy[-1] @ vt[0]) >= 0 else -vt[0]
        travel = np.array([u[0], u[1], 0.0])
    wins = []
    # Windows: half a step of wheel angle, every sixteenth of a step; rocking back revisits angles, so a window
    # takes the frames of one contiguous run inside its angle band.
    step = alpha_rad / 16
    for a0 in np.arange(lo, hi - width + 1e-12, step):
        inside = (ang >= a0) & (ang < a0 + width)
        if inside.sum() < MIN_WINDOW_FRAMES:
            continue
        pos = np.flatnonzero(inside)
        runs = np.split(pos, np.flatnonzero(np.diff(pos) > 1) + 1)
        for run in runs:
            if run.size < MIN_WINDOW_FRAMES or float(np.ptp(ang[run])) < 0.6 * width:
                continue
            f, c, rms, cov = _pivot(r_all[run], t_all[run], plane)
            wins.append((f, c, rms, cov, float(np.mean(ang[run]))))
    if len(wins) < 2:
        return None
    rms_wins = np.array([w[2] for w in wins])
    best = float(np.percentile(rms_wins, 20))
    thr = 3.0 * best + 0.3e-3
    acc = [w for w in wins if w[2] <= thr]
    if not acc:
        return None
    s = np.array([(w[1] - t_all[0]) @ travel for w in acc])
    order = np.argsort(s)
    groups: list[list[int]] = []
    for i in order:
        if groups and s[i] - s[groups[-1][-1]] < STANCE_SEPARATION_M:
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    contacts = []
    for g in groups:
        if len(g) < 2:
            continue
        cs = np.array([acc[i][1] for i in g])
        fs = np.array([acc[i][0] for i in g])
        c = np.median(cs, axis=0)
        f = np.median(fs, axis=0)
        formal = min(math.sqrt(max(acc[i][3][2, 2], 0.0)) for i in g)
        spread = 1.4826 * float(np.median(np.abs(cs[:, 2] - c[2])))
        sd = math.sqrt(formal**2 + spread**2 + CONTACT_FLOOR_M**2)
        contacts.append(
            Contact(
                c, f, float(np.median([acc[i][4] for i in g])), sd, len(g), float(np.median([acc[i][2] for i in g]))
            )
        )
    return ContactFit(tuple(contacts), plane, a_body, best)


def slope_from_contacts(contacts: tuple[Contact, ...], travel: np.ndarray) -> tuple[float, float, float] | None:
    """(slope rad, standard error rad, RMS scatter of the contact heights about the line m) from >= 2 contacts;
    positive slope = the contacts descend along ``travel``."""
    if len(contacts) < 2:
        return None
    c = np.array([k.c_m for k in contacts])
    sd = np.array([k.sd_m for k in contacts])
    s = (c - c[0]) @ travel
    z = c[:, 2]
    w = 1.0 / sd**2
    sw = w.sum()
    sm, zm = (w * s).sum() / sw, (w * z).sum() / sw
    sxx = (w * (s - sm) ** 2).sum()
    if sxx <= 0:
        return None
    b = float((w * (s - sm) * (z - zm)).sum() / sxx)
    var_b = 1.0 / sxx
    res = z - zm - b * (s - sm)
    if len(contacts) > 2:
        chi2 = float((w * res**2).sum()) / (len(contacts) - 2)
        var_b *= max(1.0, chi2)
    se = math.sqrt(var_b) / (1 + b * b)
    return float(math.atan(-b)), se, float(np.sqrt(np.mean(res**2)))


def hub_from_contacts(
    fit: ContactFit, alpha_rad: float = math.pi / 4, prior_sd_m: float = HUB_PRIOR_SD_M
) -> tuple[np.ndarray, float, float] | None:
    """Hub offset in the body frame (in the wheel plane), its standard error (m, largest axis) and the RMS
    residual of the feet about the wheel's star (m), from >= 2 contacts; None with fewer."""
    cs = fit.contacts
    if len(cs) < 2:
        return None
    p = fit.plane
    fp = np.array([k.f_m @ p for k in cs])  # (k, 2) in-plane coordinates
    m = np.round((np.array([k.angle_rad for k in cs]) - cs[0].angle_rad) / alpha_rad)
    # successive feet are found alpha further round, against the wheel's rotation, in the body frame
    rows, rhs, wts = [], [], []
    for j in range(len(cs)):
        ang = -m[j] * alpha_rad
        rr = np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])
        blk = np.zeros((2, 4))
        blk[:, :2] = np.eye(2)
        blk[:, 2:] = rr
        rows.append(blk)
        rhs.append(fp[j])
        wts.append(np.full(2, 1.0 / max(cs[j].sd_m, 0.2e-3)))
    a = np.vstack(rows)
    b = np.concatenate(rhs)
    w = np.concatenate(wts)
    # the prior: d ~ N(0, prior_sd^2) per component
    a = np.vstack([a * w[:, None], np.hstack([np.eye(2), np.zeros((2, 2))]) / prior_sd_m])
    b = np.concatenate([b * w, np.zeros(2)])
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    cov = np.linalg.inv(a.T @ a)
    res = (a @ sol - b)[:-2] / w
    se = float(math.sqrt(max(np.linalg.eigvalsh(cov[:2, :2]).max(), 0.0)))
    return p @ sol[:2], se, float(np.sqrt(np.mean(res**2)))
