"""The uncertainty of a least-squares calibration from its Jacobian: model-based standard errors with the
per-trial unknowns profiled out, flat directions (not identifiable), and the trial-clustered sandwich.

Pure numpy on the Jacobian J of the scaled residuals and the residuals r; used by
`rimless.analysis.inference.calibrate`.
"""

from __future__ import annotations

import numpy as np

__all__ = ["least_squares_report", "sandwich_se", "NULL_EIGEN"]

NULL_EIGEN = 1e-5  # smallest eigenvalue of the normalised information about the globals


def sandwich_se(
    J: np.ndarray, r: np.ndarray, offs: np.ndarray, n_global: int, scale: np.ndarray, known_rows: bool = False
) -> np.ndarray:
    """Standard errors of the globals (their units) from the trial-clustered sandwich A B A: A = (J^T J)^-1,
    B = sum over trials of (J_i^T r_i)(J_i^T r_i)^T with the rows of trial i between offs[i] and offs[i+1].

    It stays right when the residuals of a trial are correlated or the model misses something the trials
    share with each other only through the parameters (each trial's misfit counts once, not once per sample);
    scaled by n / (n - n_global) for n trials (small-sample correction). NaN with fewer trials than globals + 1.
    With `known_rows`, the rows of J beyond offs[-1] are measurements of known unit variance (prior penalty
    rows): they count in A, and their information J_k^T J_k joins B unscaled."""
    n_t = offs.size - 1
    if n_t <= n_global:
        return np.full(n_global, np.nan)
    A = np.linalg.pinv(J.T @ J)
    B = np.zeros_like(A)
    for i in range(n_t):
        g = J[offs[i] : offs[i + 1]].T @ r[offs[i] : offs[i + 1]]
        B += np.outer(g, g)
    B *= n_t / (n_t - n_global)
    if known_rows:
        Jk = J[int(offs[-1]) :]
        B += Jk.T @ Jk
    cov = A @ B @ A
    return np.sqrt(np.clip(np.diag(cov)[:n_global], 0.0, None)) * scale[:n_global]


def least_squares_report(
    J: np.ndarray, n_global: int, scale: np.ndarray
) -> tuple[np.ndarray, np.ndarray, list[bool], list[str]]:
    """From the Jacobian of the scaled residuals (the first n_global columns are the globals, in units of
    ``scale``): their standard errors (in their units), correlation and identifiability.

    The information about the globals is the Schur complement S = F_gg - F_gl F_ll^-1 F_lg of F = J^T J (the
    per-trial unknowns profiled out). Normalised to unit diagonal, an eigenvalue below `NULL_EIGEN` is a flat
    direction of the cost (a parameter, or a combination, the data do not see: finite differences leave it
    slightly above zero); every global taking part in it, and every global whose column is zero, is not
    identifiable and gets an infinite standard error."""
    F = J.T @ J
    g, l_ = slice(0, n_global), slice(n_global, F.shape[0])
    S = F[g, g].copy()
    if F.shape[0] > n_global:
        S -= F[g, l_] @ np.linalg.pinv(F[l_, l_]) @ F[l_, g]
    dS = np.clip(np.diag(S), 0.0, None)
    col = np.linalg.norm(J[:, :n_global], axis=0)
    zero = (dS <= 1e-12 * max(float(np.max(np.diag(F))), 1e-300)) | (col == 0)
    flat = zero.copy()
    ok_idx = np.nonzero(~zero)[0]
    notes = [""] * n_global
    if ok_idx.size:
        d = np.sqrt(dS[ok_idx])
        R = S[np.ix_(ok_idx, ok_idx)] / np.outer(d, d)
        w, V = np.linalg.eigh(R)
        for k in np.nonzero(w < NULL_EIGEN)[0]:
            vu = V[:, k] / d  # the flat direction in the parameters' own (relative) units
            vu /= np.max(np.abs(vu))
            flat[ok_idx[np.abs(vu) > 0.05]] = True
    cov = np.full((n_global, n_global), np.nan)
    if ok_idx.size:
        good = np.nonzero(~flat)[0]
        if good.size:
            cov[np.ix_(good, good)] = np.linalg.inv(S[np.ix_(good, good)])
    se = np.sqrt(np.clip(np.diag(cov), 0.0, None)) * scale[:n_global]
    se = np.where(flat, np.inf, se)
    dd = np.sqrt(np.diag(cov))
    corr = cov / np.outer(dd, dd)
    ok = []
    for i in range(n_global):
        if zero[i]:
            notes[i] = "flat cost: the data do not change when it changes"
        elif flat[i]:
            notes[i] = "flat cost along a combination with other parameters: only the combination is seen"
        ok.append(not flat[i])
    return se, corr, ok, notes
