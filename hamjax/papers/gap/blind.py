"""Blind benchmark: withheld-effect gap cases (generation) and their scoring.

A case draws a nominal plant (discrete or continuous linear block of order 1-3;
identity, piecewise-linear or tabulated map), two excitations (random staircase,
multisine or filtered noise) and one effect of the catalogue with a random
magnitude; the measured output is simulated from the *true* plant (nominal +
effect) and noise, independently of the diagnosis code (NumPy recursions, the
linear block by its exact ZOH state space). The truth goes to `DIR/truth.json`,
never into a case folder.

Modes:

- `exact`: the nominal model is the true plant without the effect; effects in the
  textbook form of the contract; effect RMS 1.5-20 x the noise std; 2000 samples.
- `realistic`: in every case the nominal parameters are off by an amount whose
  output effect is up to 0.1 x the noise std (what a careful identification
  leaves, below what anyone would call a mismatch); effect shapes outside the
  catalogue forms (soft saturation, asymmetric dead zone, backlash with
  stick-slip, fractional delay, second-order lag, smooth preload, tanh/cubic
  sensors, random-walk drift, Stribeck friction with a viscous part, a quintic
  part on a cubic stiffness, an asymmetric clearance); effect RMS from 0.3 x the
  noise std up; records of 1000-4000 samples.

`estimation="prbs"` replaces every case's estimation input by a +-1 PRBS (a
random clock of 3-40 samples, `_prbs`, from a key of its own, so every other
draw of the case is as in the default set): the records of two levels on which
family B loses most to family A, made on family A to measure that loss apart
from the family (docs/family-b.md, *Two-level records*).

`friction` and `feedback_nonlinearity` (a force fed back from the output to the
input of the linear block, simulated in one loop, `_lsim_loop`) replace a case's
class with probability 2/14 from a key of their own (`FIRST_DRAW`): the other
cases of a seed are those drawn before these two classes existed.
"""

import math
from pathlib import Path

import jax.random as jr
import numpy as np

from ...diagnosis.attribute import DETERMINISTIC_NAMES, NOISE_NAMES
from ...diagnosis.probabilities import CLASSES as CONTRACT_CLASSES, STICTION_LIKE
from ...io import model_to_dict, write_case, write_json
from ...models import (
    ContinuousTransferFunction,
    DiscreteTransferFunction,
    Hammerstein,
    Identity,
    PiecewiseLinear,
    Tabulated,
)
from ...models.nonlinearities.piecewise_linear import (
    PARAMETERS as PL_PARAMETERS,
    piecewise_linear_map,
)
from ...signals import prbs


# The contract's names: none, the deterministic effects, the noise ones.
EFFECTS = ("none", *DETERMINISTIC_NAMES, *NOISE_NAMES)
DETERMINISTIC = DETERMINISTIC_NAMES
# The truth classes a benchmark may hold: every contract name.
TRUTH_CLASSES = tuple(c for c in CONTRACT_CLASSES if c != "unexplained")
# The classes drawn before the feedback effects existed, in the order of the first
# draw (kept, so a seed still makes the same cases), and the feedback effects, which
# replace a case's class with probability 2/14 (every class then 1/14) from a key
# of their own: the cases not replaced are the cases of before, draw for draw.
FEEDBACK_EFFECTS = ("friction", "feedback_nonlinearity")
FIRST_DRAW = tuple(e for e in EFFECTS if e not in FEEDBACK_EFFECTS)
_FEEDBACK_KEY = 611953  # folded into a case's key for the replacement draw
_PRBS_KEY = 524287  # folded into a case's key for `estimation="prbs"`
ESTIMATION_INPUTS = ("default", "prbs")


class _Draw:
    """Named uniform draws from one key (each draw folds in a counter)."""

    def __init__(self, key):
        self.key, self.n = key, 0

    def _next(self):
        self.n += 1
        return jr.fold_in(self.key, self.n)

    def uniform(self, lo: float, hi: float) -> float:
        return float(jr.uniform(self._next(), (), minval=lo, maxval=hi))

    def log_uniform(self, lo: float, hi: float) -> float:
        return math.exp(self.uniform(math.log(lo), math.log(hi)))

    def integer(self, lo: int, hi: int) -> int:  # inclusive
        return int(jr.randint(self._next(), (), lo, hi + 1))

    def choice(self, options):
        return options[self.integer(0, len(options) - 1)]

    def normal(self, shape) -> np.ndarray:
        return np.asarray(jr.normal(self._next(), shape))

    def uniform_array(self, shape, lo, hi) -> np.ndarray:
        return np.asarray(jr.uniform(self._next(), shape, minval=lo, maxval=hi))


# ---------------------------------------------------------------- plants -----


def _draw_linear(d: _Draw, dt: float):
    order = d.integer(1, 3)
    if d.uniform(0, 1) < 0.5:  # continuous: time constants of 6-40 samples
        w = [1 / (dt * d.uniform(6, 40)) for _ in range(order)]
        den = np.array([1.0])
        if order >= 2 and d.uniform(0, 1) < 0.5:
            zeta = d.uniform(0.4, 0.9)
            den = np.polymul(den, [1.0, 2 * zeta * w[0], w[0] ** 2])
            rest = w[2:]
        else:
            den = np.polymul(den, [1.0, w[0]])
            rest = w[1:]
        for wi in rest:
            den = np.polymul(den, [1.0, wi])
        gain = d.uniform(0.5, 2.0)
        return ContinuousTransferFunction([gain * den[-1]], den)
    poles = [d.uniform(0.5, 0.93) for _ in range(order)]
    a = np.real(np.poly(poles))
    b = np.r_[0.0, np.ones(1)]
    if order >= 2 and d.uniform(0, 1) < 0.5:
        b = np.r_[0.0, 1.0, d.uniform(-0.5, 0.5)]
    b = b * d.uniform(0.5, 2.0) * a.sum() / b.sum()
    return DiscreteTransferFunction(b, a, dt)


def _draw_nonlinearity(d: _Draw, kinds=("identity", "piecewise_linear", "tabulated")):
    kind = d.choice(kinds)
    if kind == "identity":
        return Identity()
    if kind == "piecewise_linear":
        d1, d2 = d.uniform(0.1, 0.3), -d.uniform(0.1, 0.3)
        return PiecewiseLinear(
            k1=d.uniform(0.6, 1.6),
            k2=d.uniform(0.6, 1.6),
            d1=d1,
            d2=d2,
            l1=d.uniform(0.0, 0.2),
            l2=-d.uniform(0.0, 0.2),
        )
    grid = np.linspace(-1.2, 1.2, 9)
    slopes = d.uniform_array((8,), 0.4, 1.6)
    u = np.r_[0.0, np.cumsum(slopes * np.diff(grid))]
    u = u - np.interp(0.0, grid, u)
    return Tabulated(grid, u)


def _static(nl, v: np.ndarray) -> np.ndarray:
    if isinstance(nl, Identity):
        return v.copy()
    if isinstance(nl, PiecewiseLinear):
        numbers = (float(getattr(nl, k)) for k in PL_PARAMETERS)
        return piecewise_linear_map(v, *numbers, xp=np)
    return np.interp(v, np.asarray(nl.v), np.asarray(nl.u))


def _lsim(linear, u: np.ndarray, dt: float) -> np.ndarray:
    """Response from rest, NumPy (exact ZOH state space for continuous blocks)."""
    if isinstance(linear, DiscreteTransferFunction):
        return _lfilter(np.asarray(linear.b), np.asarray(linear.a), u)
    ss = linear.discretise(dt)
    A, B, C, D = (np.asarray(x) for x in (ss.A, ss.B, ss.C, ss.D))
    x = np.zeros(A.shape[0])
    y = np.empty_like(u)
    for k, uk in enumerate(u):
        y[k] = C[0] @ x + D[0, 0] * uk
        x = A @ x + B[:, 0] * uk
    return y


def _lsim_loop(linear, s: np.ndarray, dt: float, forces) -> np.ndarray:
    """Response from rest with fed-back forces `(phi, f)`: $u_k = s_k - \\phi(w_k)
    - f(w_{k+1}, (w_{k+1} - w_k)/dt)$, $w_k = C x_k$ (the strictly proper blocks
    drawn here), $w_{k+1} = C(A x_k + B u_k)$: the friction acts on the velocity
    over the step, the implicit equation solved by bisection (60 halvings of
    $s'_k \\pm$ `f`'s bound; for $c\\,\\mathrm{sign}$ this is the stick-slip
    discretisation: the velocity stays 0 while the drive is below $c$)."""
    phi, f, bound = forces
    if isinstance(linear, DiscreteTransferFunction):
        import scipy.signal as sg

        b, a = np.asarray(linear.b, float), np.asarray(linear.a, float)
        b = np.r_[b, np.zeros(max(len(a) - len(b), 0))]  # in q^-1: pad the end
        # highest power of z first, the leading zeros (the delay) stripped
        a = np.r_[a, np.zeros(len(b) - len(a))]
        A, B, C, _ = sg.tf2ss(np.trim_zeros(b, "f"), a)
    else:
        ss = linear.discretise(dt)
        A, B, C = (np.asarray(x) for x in (ss.A, ss.B, ss.C))
    x = np.zeros(A.shape[0])
    y = np.empty_like(s)
    c_ax, c_b = C[0] @ A, float(C[0] @ B[:, 0])
    for k, sk in enumerate(s):
        w = float(C[0] @ x)
        s2 = sk - phi(w)
        alpha = float(c_ax @ x)
        lo, hi = s2 - bound, s2 + bound
        for _ in range(60 if bound > 0 else 0):
            mid = 0.5 * (lo + hi)
            w_next = alpha + c_b * mid
            if mid - s2 + f(w_next, (w_next - w) / dt) > 0:
                hi = mid
            else:
                lo = mid
        y[k] = w
        x = A @ x + B[:, 0] * (0.5 * (lo + hi))
    return y


def _lfilter(b, a, u):
    n = max(len(a), len(b))
    b = np.r_[b, np.zeros(n - len(b))]
    a = np.r_[a, np.zeros(n - len(a))]
    z = np.zeros(n - 1)
    y = np.empty_like(u)
    for k, uk in enumerate(u):
        yk = b[0] * uk + (z[0] if n > 1 else 0.0)
        if n > 1:
            z = np.r_[z[1:], 0.0] + b[1:] * uk - a[1:] * yk
        y[k] = yk
    return y


# ------------------------------------------------------------- excitation ----


def _excitation(d: _Draw, n: int, dt: float) -> np.ndarray:
    kind = d.choice(("staircase", "staircase", "multisine", "filtered_noise"))
    if kind == "staircase":
        hold = d.integer(20, 60)
        levels = d.uniform_array((n // hold + 1,), -1.0, 1.0)
        return np.repeat(levels, hold)[:n]
    t = np.arange(n) * dt
    if kind == "multisine":
        k = np.arange(1, 9)
        f0 = 1 / (n * dt) * d.integer(2, 6)
        ph = d.uniform_array((8,), 0, 2 * np.pi)
        v = np.sum(
            np.sin(2 * np.pi * f0 * k[:, None] * t[None, :] + ph[:, None]), axis=0
        )
    else:
        e = d.normal((n,))
        p = d.uniform(0.8, 0.95)
        v = _lfilter(np.array([1 - p]), np.array([1.0, -p]), e)
    return v / np.max(np.abs(v))


def _prbs(key, n: int) -> np.ndarray:
    """`signals.prbs` of `n` samples, +-1, with a clock of 3-40 samples drawn
    from `key` too."""
    k_clock, k_bits = jr.split(key)
    clock = int(jr.randint(k_clock, (), 3, 41))
    return np.asarray(prbs(k_bits, n_samples=n, hold=clock)[1])


# ---------------------------------------------------------------- effects ----


def _play(v, c):
    x, out = v[0], np.empty_like(v)
    for k, vk in enumerate(v):
        x = min(max(x, vk - c / 2), vk + c / 2)
        out[k] = x
    return out


def _rate(v, step):
    x, out = v[0], np.empty_like(v)
    for k, vk in enumerate(v):
        x = x + min(max(vk - x, -step), step)
        out[k] = x
    return out


def _shift(v, tau):
    whole = int(math.floor(tau))
    frac = tau - whole
    idx = np.maximum(np.arange(v.shape[0]) - whole, 0)
    idx2 = np.maximum(idx - 1, 0)
    return (1 - frac) * v[idx] + frac * v[idx2]


class _Truth:
    """The true plant: nominal + one effect, as NumPy functions of the input."""

    def __init__(self, nominal, effect, params, realistic):
        self.nominal, self.effect, self.params, self.realistic = (
            nominal,
            effect,
            params,
            realistic,
        )

    def output(self, v, dt, linear=None):
        e, p = self.effect, self.params
        lin = linear or self.nominal.linear
        x = v
        if e == "backlash":
            x = _play(v, p["c"])
            if (
                self.realistic
            ):  # stick-slip: the output sticks until the force exceeds a breakaway
                x = x + p["stick"] * np.sign(np.diff(x, prepend=x[0]))
        elif e == "dead_zone":
            x = v - np.clip(v, -p["w_lo"], p["w_hi"])
        elif e == "rate_limit":
            x = _rate(v, p["r"] * dt)
        elif e == "time_delay":
            x = _shift(v, p["tau"])
        u = _static(self.nominal.nonlinearity, x)
        if e == "preload":
            u = u + p["c"] * (np.tanh(x / p["eps"]) if self.realistic else np.sign(x))
        elif e == "saturation":
            if self.realistic:  # soft saturation: a tanh knee of the same limits
                mid, half = (p["hi"] + p["lo"]) / 2, (p["hi"] - p["lo"]) / 2
                u = mid + half * np.tanh((u - mid) / half)
            else:
                u = np.clip(u, p["lo"], p["hi"])
        elif e == "extra_pole":
            u = _lfilter(np.array([1 - p["p"]]), np.array([1.0, -p["p"]]), u)
            if self.realistic:
                u = _lfilter(np.array([1 - p["p2"]]), np.array([1.0, -p["p2"]]), u)
        if e in FEEDBACK_EFFECTS:
            w = _lsim_loop(lin, u, dt, self._force())
        else:
            w = _lsim(lin, u, dt)
        if e == "output_nonlinearity":
            w = self._output_map(w)
        return w

    def _force(self):
        """`(phi, f, bound)` of `_lsim_loop`: `friction` (Coulomb on the output or
        its derivative; realistic: smooth, Stribeck rise and a viscous part) or
        `feedback_nonlinearity` (cubic stiffness or a clearance; realistic: a
        quintic part, an asymmetric clearance)."""
        p = self.params
        none = lambda *_: 0.0  # noqa: E731
        if self.effect == "friction":

            def friction(v_w, v_dw):
                s = v_w if p["velocity"] == "output" else v_dw
                if not self.realistic:
                    return p["c"] * np.sign(s)
                rise = 1 + p["stribeck"] * np.exp(-((s / p["vs"]) ** 2))
                return p["c"] * rise * np.tanh(s / p["eps"]) + p["viscous"] * s

            # a bound on |f| over the velocities a step can reach (viscous part:
            # up to 100 x the velocity scale, far beyond any)
            bound = p["c"] * (1 + p["stribeck"]) + p["viscous"] * 100 * p["v_scale"]
            return none, friction, bound
        W, U = p["scale"], p["u_scale"]

        def feedback(w):
            if p["shape"] == "cubic":
                return U * (p["k"] * (w / W) ** 3 + p["k5"] * (w / W) ** 5)
            return p["k"] * U / W * (w - np.clip(w, -p["b"], p["b_hi"]))

        return feedback, none, 0.0

    def _output_map(self, w):
        p = self.params
        shape, W = p["shape"], p["scale"]
        if shape == "quadratic":
            return w + p["a"] * w**2 / W
        if shape == "cubic":
            return w - p["a"] * w**3 / W**2
        if shape == "saturation":
            return np.clip(w, p["lo"], p["hi"])
        if shape == "tanh":
            return W * np.tanh(w / W) * p["a"] + (1 - p["a"]) * w
        return w - np.clip(w, -p["b"], p["b"])  # dead band


def _perturb_linear(linear, d: _Draw, size: float):
    """The same structure with poles and gain moved by relative amounts ~ `size`."""
    g = 1 + size * d.uniform(-1, 1)
    if isinstance(linear, ContinuousTransferFunction):
        poles = np.roots(np.asarray(linear.den))
        poles = poles * (1 + size * d.uniform(-1, 1))
        den = np.real(np.poly(poles)) * float(linear.den[0])
        num = np.asarray(linear.num) * g * (den[-1] / float(linear.den[-1]))
        return ContinuousTransferFunction(num, den)
    a = np.asarray(linear.a)
    poles = np.roots(a)
    poles = np.clip(np.abs(poles) * (1 + size * d.uniform(-1, 1)), 0, 0.97) * np.exp(
        1j * np.angle(poles)
    )
    a2 = np.real(np.poly(poles))
    b = np.asarray(linear.b) * g * a2.sum() / a.sum()
    return DiscreteTransferFunction(b, a2, linear.dt)


def _perturb_nl(nl, d: _Draw, size: float):
    if isinstance(nl, PiecewiseLinear):
        vals = {k: float(getattr(nl, k)) for k in PL_PARAMETERS}
        vals = {
            k: x + size * d.uniform(-1, 1) * (abs(x) + 0.1) for k, x in vals.items()
        }
        vals["d1"], vals["d2"] = max(vals["d1"], 0.0), min(vals["d2"], 0.0)
        return PiecewiseLinear(**vals)
    return nl


def _rms(x):
    return float(np.sqrt(np.mean(np.square(x))))


def make_case(key, *, realism: str = "exact", estimation: str = "default") -> dict:
    """One withheld-effect case. `estimation`: `"default"`, or `"prbs"` for a
    +-1 PRBS estimation input (module docstring).

    An effect that does not show in both records (say an output saturation the
    validation output never reaches) is no effect at all: it is drawn again, from
    keys folded from `key`, so every case keeps a known, visible effect.

    **Returns:** `{"model": model.json dict, "estimation": {t, v, y},
    "validation": {...}, "truth": {...}}` (NumPy arrays).
    """
    if realism not in ("exact", "realistic"):
        raise ValueError(f"realism must be 'exact' or 'realistic'; got {realism!r}")
    if estimation not in ESTIMATION_INPUTS:
        raise ValueError(
            f"estimation must be one of {ESTIMATION_INPUTS}; got {estimation!r}"
        )
    for attempt in range(100):
        case = _draw_case(
            key if attempt == 0 else jr.fold_in(key, 104729 + attempt),
            realism,
            estimation,
        )
        if case is not None:
            return case
    raise RuntimeError("no visible effect in 100 draws")  # pragma: no cover


def _draw_case(key, realism: str, estimation: str = "default") -> dict | None:
    realistic = realism == "realistic"
    d = _Draw(key)
    dt = 0.05
    effect = d.choice(FIRST_DRAW)
    if float(jr.uniform(jr.fold_in(key, _FEEDBACK_KEY))) < 2 / 14:
        effect = FEEDBACK_EFFECTS[int(jr.bernoulli(jr.fold_in(key, _FEEDBACK_KEY + 1)))]
    n = d.integer(1000, 4000) if realistic else 2000
    kinds = (
        ("identity", "tabulated")
        if effect in ("dead_zone", "preload")
        else (
            "identity",
            "piecewise_linear",
            "tabulated",
        )
    )
    nominal = Hammerstein(_draw_nonlinearity(d, kinds), _draw_linear(d, dt))
    v_est, v_val = _excitation(d, n, dt), _excitation(d, n, dt)
    if effect in ("backlash", "rate_limit"):  # memory needs steps to be seen
        hold = d.integer(20, 60)
        v_est = np.repeat(d.uniform_array((n // hold + 1,), -1, 1), hold)[:n]
        v_val = np.repeat(d.uniform_array((n // hold + 1,), -1, 1), hold)[:n]
    if estimation == "prbs":
        v_est = _prbs(jr.fold_in(key, _PRBS_KEY), n)
    w_nom_est = _lsim(nominal.linear, _static(nominal.nonlinearity, v_est), dt)
    u_est = _static(nominal.nonlinearity, v_est)
    W = max(np.quantile(np.abs(w_nom_est), 0.98), 1e-9)
    params: dict = {}
    truth_plant = nominal
    if effect == "parameter_mismatch":
        size = d.uniform(0.1, 0.3)
        truth_plant = Hammerstein(
            _perturb_nl(nominal.nonlinearity, d, size),
            _perturb_linear(nominal.linear, d, size),
        )
        params["relative_size"] = size
    elif effect == "backlash":
        params["c"] = d.uniform(0.05, 0.3) * np.ptp(v_est)
        params["stick"] = d.uniform(0.0, 0.05) * params["c"] if realistic else 0.0
    elif effect == "dead_zone":
        w = d.uniform(0.05, 0.3)
        params["w_lo"] = w
        params["w_hi"] = w * (d.uniform(0.5, 1.5) if realistic else 1.0)
    elif effect == "saturation":
        lo = float(np.quantile(u_est, d.uniform(0.03, 0.3)))
        hi = float(np.quantile(u_est, d.uniform(0.7, 0.97)))
        # a map with a wide flat part (a dead band of F) can put both quantiles at
        # the same level, i.e. no input left at all: keep a band of 0.2 std(u)
        band = 0.2 * float(np.std(u_est))
        if hi - lo < band:
            lo, hi = (lo + hi - band) / 2, (lo + hi + band) / 2
        params["lo"], params["hi"] = lo, hi
    elif effect == "preload":
        params["c"] = d.uniform(0.05, 0.3) * float(np.std(u_est))
        params["eps"] = d.uniform(0.01, 0.05)
    elif effect == "rate_limit":
        steps = np.abs(np.diff(v_est))
        params["r"] = d.uniform(0.03, 0.3) * float(steps.max()) / dt
    elif effect == "time_delay":
        params["tau"] = d.integer(1, 5) + (d.uniform(-0.3, 0.3) if realistic else 0.0)
    elif effect == "extra_pole":
        params["p"] = d.uniform(0.5, 0.9)
        params["p2"] = d.uniform(0.0, 0.5) if realistic else 0.0
    elif effect == "output_nonlinearity":
        shapes = ("quadratic", "saturation", "dead_band") + (
            ("cubic", "tanh") if realistic else ()
        )
        params["shape"] = d.choice(shapes)
        params["scale"] = W
        params["a"] = d.uniform(0.1, 0.3)
        params["lo"] = float(np.quantile(w_nom_est, d.uniform(0.03, 0.2)))
        params["hi"] = float(np.quantile(w_nom_est, d.uniform(0.8, 0.97)))
        params["b"] = d.uniform(0.05, 0.2) * W
    elif effect == "friction":
        params["velocity"] = d.choice(("output", "derivative"))
        rate = np.abs(np.diff(w_nom_est)) / dt
        V = W if params["velocity"] == "output" else np.quantile(rate, 0.98)
        params["v_scale"] = float(V)
        params["v_scale"] = float(V)
        params["c"] = d.uniform(0.05, 0.3) * float(np.std(u_est))
        params["eps"] = d.uniform(0.005, 0.02) * V
        params["stribeck"] = d.uniform(0.0, 0.5) if realistic else 0.0
        params["vs"] = d.uniform(0.05, 0.2) * V
        params["viscous"] = d.uniform(0.0, 0.1) * float(np.std(u_est)) / V
    elif effect == "feedback_nonlinearity":
        params["shape"] = d.choice(("cubic", "clearance"))
        params["scale"], params["u_scale"] = W, float(np.std(u_est))
        params["k"] = d.uniform(0.1, 0.5)
        params["k5"] = d.uniform(0.0, 0.5) * params["k"] if realistic else 0.0
        params["b"] = d.uniform(0.1, 0.4) * W
        params["b_hi"] = params["b"] * (d.uniform(0.5, 1.5) if realistic else 1.0)
    truth = _Truth(
        truth_plant,
        effect if effect != "parameter_mismatch" else "none",
        params,
        realistic,
    )
    ws = {
        name: truth.output(v, dt)
        for name, v in (("estimation", v_est), ("validation", v_val))
    }
    w_nominal = {
        name: _lsim(nominal.linear, _static(nominal.nonlinearity, v), dt)
        for name, v in (("estimation", v_est), ("validation", v_val))
    }
    # a feedback loop the drawn force drives unstable is no plant: draw again
    if not all(np.all(np.isfinite(w)) for w in ws.values()) or max(
        _rms(ws[k]) for k in ws
    ) > 100 * max(_rms(w_nominal[k]) for k in ws):
        return None
    # the effect must show in both records: the smaller of the two sets the scale
    effect_rms = min(
        _rms(ws[name] - w_nominal[name]) for name in ("estimation", "validation")
    )
    if effect in DETERMINISTIC and not effect_rms > 1e-6 * _rms(
        w_nominal["validation"]
    ):
        return None
    if effect in DETERMINISTIC:
        ratio = d.log_uniform(0.3, 10.0) if realistic else d.log_uniform(1.5, 20.0)
        sigma = effect_rms / ratio
    else:
        sigma = d.uniform(0.01, 0.05) * float(np.std(w_nominal["estimation"]))
    model_plant = nominal
    if realistic:  # nominal error in every case, output effect <= 0.1 sigma
        kp = jr.fold_in(key, 7919)  # the same draws twice: the error scales linearly
        dp = _Draw(kp)
        trial = Hammerstein(
            _perturb_nl(nominal.nonlinearity, dp, 0.01),
            _perturb_linear(nominal.linear, dp, 0.01),
        )
        err = _rms(
            _lsim(trial.linear, _static(trial.nonlinearity, v_est), dt)
            - w_nominal["estimation"]
        )
        target = d.uniform(0.0, 0.1) * sigma
        size = 0.01 * target / max(err, 1e-300)
        d2 = _Draw(kp)
        model_plant = Hammerstein(
            _perturb_nl(nominal.nonlinearity, d2, size),
            _perturb_linear(nominal.linear, d2, size),
        )
    records = {}
    for _i, (name, v) in enumerate((("estimation", v_est), ("validation", v_val))):
        w = ws[name]
        e = sigma * d.normal((n,))
        if effect == "drift":
            t = np.arange(n) * dt
            if realistic:
                walk = np.cumsum(d.normal((n,))) * sigma * d.uniform(0.05, 0.2)
                w = w + walk
            else:
                total = d.uniform(3.0, 10.0) * sigma * d.choice((-1.0, 1.0))
                w = w + total * t / t[-1]
        elif effect == "coloured_noise":
            pole = params.setdefault("pole", d.uniform(0.7, 0.95))
            e = _lfilter(np.array([1.0]), np.array([1.0, -pole]), e) * math.sqrt(
                1 - pole**2
            )
        records[name] = {"t": np.arange(n) * dt, "v": v, "y": w + e}
    return {
        "model": model_to_dict(model_plant, dt),
        "estimation": records["estimation"],
        "validation": records["validation"],
        "truth": {
            "effect": effect,
            "params": {
                k: (v if isinstance(v, str) else float(v)) for k, v in params.items()
            },
            "noise_std": float(sigma),
            "effect_rms_over_noise": float(effect_rms / sigma) if sigma > 0 else 0.0,
            "n_samples": n,
            "realism": realism,
            **({"excitation": {"estimation": "prbs"}} if estimation == "prbs" else {}),
        },
    }


def make_cases(
    key, n_cases: int, out: Path, *, realism: str = "exact", estimation: str = "default"
) -> dict:
    """Write `n_cases` case folders under `out` and `out/truth.json` (`realism`,
    `estimation`: as in `make_case`)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    truth = {"realism": realism, "cases": {}}
    if estimation != "default":
        truth["estimation"] = estimation
    for i in range(n_cases):
        case = make_case(jr.fold_in(key, i), realism=realism, estimation=estimation)
        truth["cases"][write_case(out, i, case)] = case["truth"]
    write_json(out / "truth.json", truth)
    return truth


# ---------------------------------------------------------------- scoring ----


def calibration(confidences: list[float], right: list[bool], bins: int = 10) -> dict:
    """Reliability of stated confidences: per bin of confidence (width 1/bins) the
    cases, their mean confidence and their accuracy, and the expected calibration
    error (ECE, the case-weighted mean |confidence - accuracy| over the bins)."""
    c, r = np.asarray(confidences, float), np.asarray(right, bool)
    table, ece = [], 0.0
    edges = np.linspace(0.0, 1.0, bins + 1)
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        sel = (c > lo) & (c <= hi) if lo > 0 else (c >= lo) & (c <= hi)
        if sel.any():
            gap = abs(c[sel].mean() - r[sel].mean())
            ece += sel.mean() * gap
            table.append(
                {
                    "low": float(lo),
                    "high": float(hi),
                    "cases": int(sel.sum()),
                    "mean_confidence": float(c[sel].mean()),
                    "accuracy": float(r[sel].mean()),
                }
            )
    return {"ece": float(ece), "bins": table}


def score(
    truth: dict,
    named: dict,
    shrinks: dict | None = None,
    confidences: dict | None = None,
) -> dict:
    """Confusion matrix, accuracy, false alarm on `none`, median shrink, and with
    `confidences` the calibration of the probability of the named effect.
    `accuracy_by_excitation`: where the truth records each case's excitations
    (family B's `excitation`), `{record: {kind: [right, cases]}}` for the
    estimation and the validation record; split so because an input of two
    levels (a PRBS) shows a static map at two points only.

    **Arguments:** `truth` as in `truth.json`; `named` maps case name -> effect
    named; `shrinks` maps case name -> `(gap_before, gap_after)` (the shrink is
    computed against the *true* noise std of the case); `confidences` maps case
    name -> the diagnosis's probability of the effect it named.
    """
    labels = list(TRUTH_CLASSES) + ["unexplained"]
    matrix = {t: {p: 0 for p in labels} for t in TRUTH_CLASSES}
    correct, total, none_total, none_alarm = 0, 0, 0, 0
    shrink_values = []
    missing = []
    by_excitation: dict[str, dict[str, list[int]]] = {}
    for name, tr in truth["cases"].items():
        if name not in named:
            missing.append(name)
            continue
        t, p = tr["effect"], named[name]
        matrix[t][p if p in labels else "unexplained"] += 1
        total += 1
        correct += t == p
        for record, kind in (tr.get("excitation") or {}).items():
            _tally(by_excitation.setdefault(record, {}), str(kind), t == p)
        if t == "none":
            none_total += 1
            none_alarm += p != "none"
        if shrinks is not None and t in DETERMINISTIC and name in shrinks:
            gb, ga = shrinks[name]
            s = tr["noise_std"]
            if gb > s:
                shrink_values.append((gb - ga) / (gb - s))
    scored = [n for n in truth["cases"] if n in named and n in (confidences or {})]
    calib = (
        calibration(
            [confidences[n] for n in scored],
            [truth["cases"][n]["effect"] == named[n] for n in scored],
        )
        if scored
        else None
    )
    return {
        "calibration": calib,
        "n_cases": total,
        "missing": missing,
        "accuracy": correct / total if total else float("nan"),
        "false_alarm_none": none_alarm / none_total if none_total else float("nan"),
        "n_none": none_total,
        "median_shrink_deterministic": float(np.median(shrink_values))
        if shrink_values
        else float("nan"),
        "confusion": matrix,
        "accuracy_by_excitation": {
            r: dict(sorted(c.items())) for r, c in by_excitation.items()
        },
        "stiction": stiction_score(truth, named)
        if truth.get("family") == "loops"
        else None,
    }


def _tally(counts: dict[str, list[int]], key: str, hit: bool) -> None:
    """One case more under `key` of `counts` (`{key: [hits, cases]}`)."""
    c = counts.setdefault(key, [0, 0])
    c[0] += hit
    c[1] += 1


def _rates(counts: dict[str, list[int]]) -> str:
    """`counts` (`{key: [hits, cases]}`) as "key rate (hits/cases), ..."."""
    return ", ".join(f"{k} {h / n:.3f} ({h}/{n})" for k, (h, n) in counts.items())


# the bands of a loop's valve visibility (`control_loops.valve_visibility`) its
# recall is split by: a reporting choice, no constant of the diagnosis
VISIBILITY_BANDS = (1.0, 3.0)


def visibility_band(v: float) -> str:
    """`"<1"`, `"1-3"` or `">=3"` (`VISIBILITY_BANDS`)."""
    lo, hi = VISIBILITY_BANDS
    return f"<{lo:g}" if v < lo else (f"{lo:g}-{hi:g}" if v < hi else f">={hi:g}")


def _ordered(field: str, counts: dict) -> dict:
    """`counts` by value: the visibility bands from low to high, others sorted."""
    if field != "valve_visibility":
        return dict(sorted(counts.items()))
    lo, hi = VISIBILITY_BANDS
    order = [visibility_band(b) for b in (lo / 2, lo, hi)]
    return {b: counts[b] for b in order if b in counts}


def stiction_score(truth: dict, named: dict) -> dict:
    """The stiction question on a control-loop benchmark (truth `backlash` = a sticky
    valve), with one answer on both sides: "the valve sticks" is a name in
    STICTION_LIKE. Recall (stiction loops so named), false-alarm rate (loops without
    stiction so named), balanced accuracy (recall + 1 - false alarm) / 2, over the
    cases with a result; `recall_backlash` also counts the stiction loops named the
    contract's class `backlash` itself (the stricter reading). `recall_by` splits
    the recall by the truth's `process`, `disturbance` and `valve_visibility`
    (where the truth has them; the visibility in `VISIBILITY_BANDS`):
    `{field: {value: [named stiction-like, loops]}}`, the value `none` for a
    loop without a disturbance."""
    hit, exact, n_st, alarm, n_free = 0, 0, 0, 0, 0
    by: dict[str, dict[str, list[int]]] = {
        "process": {},
        "disturbance": {},
        "valve_visibility": {},
    }
    for name, tr in truth["cases"].items():
        if name not in named:
            continue
        if tr["effect"] == "backlash":
            n_st += 1
            hit += named[name] in STICTION_LIKE
            exact += named[name] == "backlash"
            for field, counts in by.items():
                if field in tr:
                    value = tr[field]
                    if field == "valve_visibility":
                        value = visibility_band(value)
                    _tally(counts, str(value or "none"), named[name] in STICTION_LIKE)
        else:
            n_free += 1
            alarm += named[name] in STICTION_LIKE
    recall = hit / n_st if n_st else float("nan")
    false_alarm = alarm / n_free if n_free else float("nan")
    return {
        "n_stiction": n_st,
        "n_without": n_free,
        "recall": recall,
        "recall_backlash": exact / n_st if n_st else float("nan"),
        "false_alarm": false_alarm,
        "balanced_accuracy": (recall + 1 - false_alarm) / 2,
        "recall_by": {f: _ordered(f, c) for f, c in by.items() if c},
    }


def format_score(s: dict) -> str:
    """The confusion matrix and the headline numbers as text."""
    labels = list(TRUTH_CLASSES) + ["unexplained"]
    short = [x[:6] for x in labels]
    width = max(len(t) for t in TRUTH_CLASSES) + 1
    lines = ["truth \\ named".ljust(width) + " ".join(f"{x:>6}" for x in short)]
    for t in TRUTH_CLASSES:
        row = s["confusion"][t]
        if sum(row.values()) == 0:
            continue
        lines.append(t.ljust(width) + " ".join(f"{row[p]:>6}" for p in labels))
    lines.append(
        f"cases {s['n_cases']}  accuracy {s['accuracy']:.3f}  false alarm on none "
        f"{s['false_alarm_none']:.3f} (of {s['n_none']})  median shrink (deterministic) "
        f"{s['median_shrink_deterministic']:.3f}"
    )
    if s.get("calibration"):
        lines.append(
            f"calibration of the named effect's probability: ECE "
            f"{s['calibration']['ece']:.3f} ("
            + ", ".join(
                f"{b['mean_confidence']:.2f}->{b['accuracy']:.2f} ({b['cases']})"
                for b in s["calibration"]["bins"]
            )
            + ")"
        )
    for record, counts in s.get("accuracy_by_excitation", {}).items():
        lines.append(f"accuracy by {record} excitation: " + _rates(counts))
    if s.get("stiction"):
        st = s["stiction"]
        lines.append(
            f"stiction: recall {st['recall']:.3f} (of {st['n_stiction']}; named "
            f"backlash itself {st['recall_backlash']:.3f})  false alarm "
            f"{st['false_alarm']:.3f} (of {st['n_without']}; named one of "
            f"{', '.join(STICTION_LIKE)})  balanced accuracy "
            f"{st['balanced_accuracy']:.3f}"
        )
        for field, counts in st.get("recall_by", {}).items():
            lines.append(f"stiction recall by {field}: " + _rates(counts))
    if s["missing"]:
        lines.append(f"missing results: {len(s['missing'])}")
    return "\n".join(lines)
