"""Where the gap lies: the validation residual decomposed along the axes that point
at a cause (frequency, input amplitude, direction of motion, time and lag), each
with the noise floor beside it and a significance statement, before and after the
named effect is added."""

import math

import numpy as np

from .residuals import (
    Z_95,
    billings_voon,
    cross_correlation,
    feedback_test,
    ljung_box,
    period_of,
)


N_BANDS = 6
N_BINS = 6
# z for the per-bin/per-band statements: Bonferroni over ~6 bins at 1 %
Z_BIN = 3.0


def _power_ratio_significant(ratio: float, n: int) -> bool:
    """A mean of `n` squared noise samples exceeds `ratio * floor^2` by chance rarely
    when `ratio > 1 + Z_BIN * sqrt(2 / n)` (chi-square, normal approximation)."""
    return n > 0 and ratio > 1 + Z_BIN * math.sqrt(2 / n)


def frequency_bands(r, v, floor, dt) -> list[dict]:
    """Residual power by log-spaced band against the flat white-noise floor, and the
    input-residual coherence in each band (frequency-averaged periodograms)."""
    n = r.shape[0]
    R = np.fft.rfft(r - r.mean())
    V = np.fft.rfft(v - v.mean())
    f = np.fft.rfftfreq(n, dt)
    P = np.abs(R) ** 2 / n
    edges = np.geomspace(f[1], f[-1], N_BANDS + 1)
    out = []
    for lo, hi in zip(edges[:-1], edges[1:], strict=False):
        sel = (f >= lo) & (f <= hi)
        m = int(sel.sum())
        if m == 0:
            continue
        ratio = float(P[sel].mean() / max(floor**2, 1e-300))
        num = abs(np.sum(V[sel] * np.conj(R[sel]))) ** 2
        den = np.sum(abs(V[sel]) ** 2) * np.sum(abs(R[sel]) ** 2) or 1.0
        coh = float(num / den)
        coh_thr = 1 - 0.01 ** (1 / max(m - 1, 1))
        out.append(
            {
                "f_low_hz": float(lo),
                "f_high_hz": float(hi),
                "power_over_floor": ratio,
                "significant": _power_ratio_significant(ratio, m),
                "coherence_with_input": coh,
                "coherence_significant": bool(m > 1 and coh > coh_thr),
            }
        )
    return out


def periodic_split(r: np.ndarray, period: int) -> dict:
    """Average over whole periods (seed 000, (20)): the period-mean is the
    deterministic model error, the spread about it the noise."""
    k = r.shape[0] // period
    x = (
        r[period : k * period].reshape(k - 1, period)
        if k > 2
        else r[: k * period].reshape(k, period)
    )
    mean = x.mean(axis=0)
    noise = float(np.sqrt(np.sum((x - mean) ** 2) / max(x.size - period, 1)))
    det = float(np.sqrt(max(np.mean(mean**2) - noise**2 / x.shape[0], 0.0)))
    return {"period_samples": period, "deterministic_rms": det, "noise_rms": noise}


def amplitude_bins(r, x, floor, label) -> list[dict]:
    """Residual mean and RMS in quantile bins of `x` (the input or the nominal u)."""
    edges = np.unique(np.quantile(x, np.linspace(0, 1, N_BINS + 1)))
    out = []
    for i, (lo, hi) in enumerate(zip(edges[:-1], edges[1:], strict=False)):
        sel = (x >= lo) & ((x < hi) if i < len(edges) - 2 else (x <= hi))
        m = int(sel.sum())
        if m == 0:
            continue
        rms = float(np.sqrt(np.mean(r[sel] ** 2)))
        ratio = rms**2 / max(floor**2, 1e-300)
        out.append(
            {
                f"{label}_low": float(lo),
                f"{label}_high": float(hi),
                "n": m,
                "mean": float(r[sel].mean()),
                "rms": rms,
                "rms_over_floor": float(math.sqrt(ratio)),
                "significant": _power_ratio_significant(ratio, m),
            }
        )
    return out


def direction(v: np.ndarray) -> np.ndarray:
    """+1 after a rise, -1 after a fall (the last non-zero step), 0 before any."""
    d = np.sign(np.diff(v, prepend=v[0]))
    idx = np.where(d != 0, np.arange(d.shape[0]), 0)
    np.maximum.accumulate(idx, out=idx)
    return np.where(np.arange(d.shape[0]) >= idx, d[idx], 0)


def by_direction(r, v, floor) -> dict:
    """Residual on rising vs falling input: a difference of means flags memory."""
    d = direction(v)
    out = {}
    for name, s in (("rising", 1), ("falling", -1)):
        sel = d == s
        out[name] = {
            "n": int(sel.sum()),
            "mean": float(r[sel].mean()) if sel.any() else 0.0,
            "rms": float(np.sqrt(np.mean(r[sel] ** 2))) if sel.any() else 0.0,
        }
    n1, n2 = out["rising"]["n"], out["falling"]["n"]
    if n1 > 1 and n2 > 1:
        # effective sample size shrunk by the lag-1 autocorrelation of r (none
        # for a residual without variance, e.g. an exact noise-free fit's)
        a, b = r[:-1], r[1:]
        rho = 0.0
        if np.std(a) > 0 and np.std(b) > 0:
            rho = float(np.clip(np.corrcoef(a, b)[0, 1], 0, 0.999))
        eff = (1 - rho) / (1 + rho)
        se = floor * math.sqrt(1 / (n1 * eff) + 1 / (n2 * eff))
        diff = out["rising"]["mean"] - out["falling"]["mean"]
        out["difference"] = diff
        out["z"] = float(diff / se) if se > 0 else 0.0
        out["significant"] = bool(abs(out["z"]) > Z_BIN)
    return out


def time_axis(t, r, v, floor, dt) -> dict:
    """Transient vs steady state after input steps, residual-input
    cross-correlation with 95 % bands, and a slow linear trend."""
    n = r.shape[0]
    steps = np.flatnonzero(np.abs(np.diff(v)) > 1e-9 * (np.ptp(v) or 1.0)) + 1
    since = np.full(n, n)
    if steps.size:
        last = np.maximum.accumulate(
            np.where(np.isin(np.arange(n), steps), np.arange(n), -1)
        )
        since = np.where(last >= 0, np.arange(n) - last, n)
    window = max(5, int(np.median(np.diff(steps)) // 3) if steps.size > 1 else 5)
    trans = since < window
    out = {"transient_window_samples": window}
    for name, sel in (("transient", trans), ("steady", ~trans)):
        out[name] = {
            "n": int(sel.sum()),
            "rms": float(np.sqrt(np.mean(r[sel] ** 2))) if sel.any() else 0.0,
        }
    lags = np.arange(-10, 41)
    xc = cross_correlation(v, r, lags)
    band = Z_95 / math.sqrt(n)
    out["cross_correlation"] = {
        "lags": lags.tolist(),
        "values": xc.tolist(),
        "band_95": band,
        "max_abs_lag": int(lags[np.argmax(np.abs(xc))]),
        "significant": bool(np.max(np.abs(xc)) > band * 1.6),
    }
    # slope of block means over time (blocks absorb short-range correlation)
    k = 20
    m = n // k * k
    bm = r[:m].reshape(k, -1).mean(axis=1)
    bt = t[:m].reshape(k, -1).mean(axis=1)
    A = np.c_[np.ones(k), bt - bt.mean()]
    coef, res, *_ = np.linalg.lstsq(A, bm, rcond=None)
    s2 = float(np.sum((bm - A @ coef) ** 2) / (k - 2))
    se = math.sqrt(s2 / max(np.sum((bt - bt.mean()) ** 2), 1e-300))
    out["trend"] = {
        "slope_per_s": float(coef[1]),
        "z": float(coef[1] / se) if se > 0 else 0.0,
        "significant": bool(se > 0 and abs(coef[1] / se) > Z_BIN),
    }
    return out


def _axes(t, v, r, u, floor, dt) -> dict:
    out = {
        "rms": float(np.sqrt(np.mean(r**2))),
        "frequency": frequency_bands(r, v, floor, dt),
        "amplitude_v": amplitude_bins(r, v, floor, "v"),
        "amplitude_u": amplitude_bins(r, u, floor, "u"),
        "direction": by_direction(r, v, floor),
        "time": time_axis(t, r, v, floor, dt),
        "whiteness": ljung_box(r),
        "billings_voon": billings_voon(r, v),
    }
    p = period_of(v)
    if p is not None:
        out["periodic"] = periodic_split(r, p)
    return out


# input levels counted up to this many (`input_levels`): past two, a static map
# is seen at more points than a gain and an offset can fit
LEVELS_COUNTED = 3


def input_levels(v: np.ndarray) -> int:
    """How many distinct values the input `v` takes, to rounding ($10^{-9}$ of
    its range), counted up to `LEVELS_COUNTED`. On two levels (a PRBS, a step
    test) a static map of the input is seen at two points, where any map is a
    gain and an offset."""
    v = np.asarray(v, float)
    span = float(np.ptp(v)) if v.size else 0.0
    if span == 0.0:
        return 1
    levels = np.unique(np.round((v - v.min()) / (1e-9 * span)))
    return int(min(levels.size, LEVELS_COUNTED))


def locate(t, v, r_before, r_after, u, floor, dt, *, y=None, v_est=None) -> dict:
    """The `where` block of diagnosis.json: every axis for the residual of the
    nominal model (`before`) and of the augmented model (`after`), and whether
    the record looks closed-loop: `residuals.feedback_test` on the measured
    output `y`, as the gate of the candidate layout tests it
    (`layout.looks_closed_loop`): a model's residual is not a function of past
    inputs alone when the model has a direct feedthrough, and its level would
    depend on the model being right. Without `y` the test is not run.
    `input_levels`: `input_levels` of this (validation) record's input and, given
    `v_est`, of the estimation record's."""
    t, v, u = (np.asarray(x, float) for x in (t, v, u))
    if y is None:
        feedback = {"applicable": False, "why": "the measured output was not given"}
    else:
        feedback = feedback_test(np.asarray(y, float), v)
    levels = {"validation": input_levels(v)}
    if v_est is not None:
        levels = {"estimation": input_levels(v_est)} | levels
    return {
        "noise_floor": float(floor),
        "feedback": feedback,
        "input_levels": levels,
        "before": _axes(t, v, np.asarray(r_before, float), u, floor, dt),
        "after": _axes(t, v, np.asarray(r_after, float), u, floor, dt),
    }
