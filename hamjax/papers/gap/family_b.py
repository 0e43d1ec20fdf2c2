"""Blind benchmark, family B: gap cases written from physical models.

Family A (`blind.py`) draws the catalogue's own formulas. Family B is a second,
independent, held-out family: each case is a physical plant (a heater, a
two-body thermal plant, a mass-spring-damper, a DC motor, a servo with a
gearbox, a valve feeding a process) simulated in continuous time on a fine grid
(`FINE` steps per sample, input held between samples), with one physical cause
of mismatch (a gear dead band with contact dynamics, valve-stem stiction with a
Karnopp/Stribeck friction state, spool overlap, amplifier rails with a soft knee,
a stroking-speed limit, a slowly varying transport delay, a sensor lag, a sensor
soft limit, thermal creep, 1/f noise, Coulomb/Stribeck friction on the motion, a
hardening or clearance spring, a sign-blind speed sensor, ...). The nominal model (`model.json`) is
what an engineer would write from the data sheet: the same physics with several
parameters off together by 15-20 % in the structural cases, and close to the
truth (output error <= 0.1 noise std) in the `none`, `drift` and
`coloured_noise` cases. Each case is labelled by what the physical plant
contains (docs/family-b.md gives the mapping and its reasons), never by what the
diagnosis says. NumPy/SciPy only: nothing of the diagnosis is imported, and no
constant of the decision rule may ever be chosen on this family.

Sizes: the SNR of the noise-free output is 10-40 dB; a structural effect is
scaled so that its output RMS after a (linearised) best re-fit of the nominal
structure is 0.3-2 x the noise std; records of 1000-4000 samples. Classes are
balanced (each block of 14 cases is a permutation of the 14 classes; `classes="twelve"`
writes the sets of the twelve classes drawn before `friction` and
`feedback_nonlinearity` were added, byte for byte).

Deterministic given the seed: case i uses `numpy.random.default_rng([seed, i])`
only, so case i does not depend on how many cases are made.
"""

import math
from pathlib import Path

import numpy as np
from scipy import linalg, signal

from ...io import write_case, write_json


# The contract's names (shared/contracts/gap-case.md) that family B draws. TWELVE:
# the classes of the first version (no friction, no feedback nonlinearity), kept to
# reproduce its sets exactly.
TWELVE = (
    "none",
    "parameter_mismatch",
    "backlash",
    "dead_zone",
    "saturation",
    "preload",
    "rate_limit",
    "time_delay",
    "extra_pole",
    "output_nonlinearity",
    "drift",
    "coloured_noise",
)
CLASSES = (*TWELVE, "friction", "feedback_nonlinearity")
CLASS_SETS = {"fourteen": CLASSES, "twelve": TWELVE}
STRUCTURAL = (*TWELVE[2:10], "friction", "feedback_nonlinearity")
FINE = 8  # integration steps per sample
SNR_DB = (10.0, 40.0)
RATIO = (0.3, 2.0)  # effect RMS after a re-fit / noise std
NOMINAL_ERROR = (0.15, 0.20)  # relative error of each perturbed physical parameter
N_SAMPLES = (1000, 4000)

# which plants can physically carry each cause
# every plant of the family
ALL_PLANTS = ("heater", "thermal2", "msd", "motor", "servo_gear", "valve_process")
PLANTS_FOR = {
    "none": ALL_PLANTS,
    "parameter_mismatch": ALL_PLANTS,
    "backlash": ("servo_gear", "valve_process"),
    "dead_zone": ("valve_process", "msd", "motor"),
    "saturation": ("heater", "thermal2", "motor", "msd"),
    "preload": ("motor", "msd", "servo_gear"),
    "rate_limit": ("valve_process", "motor", "heater"),
    "time_delay": ("heater", "thermal2", "valve_process"),
    "extra_pole": ("heater", "thermal2", "msd", "motor", "valve_process"),
    "output_nonlinearity": ALL_PLANTS,
    "drift": ALL_PLANTS,
    "coloured_noise": ALL_PLANTS,
    # velocity output (motor speed) or position output (msd: a spring-returned axis)
    "friction": ("motor", "msd"),
    "feedback_nonlinearity": ("msd",),
}
DT = {  # sampling period of each plant, s
    "heater": 1.0,
    "thermal2": 0.5,
    "msd": 0.01,
    "motor": 0.002,
    "servo_gear": 0.001,
    "valve_process": 0.2,
}


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _softplus(z, k):
    """k log(1 + exp(z/k)): a ramp max(z, 0) with a knee of width ~k."""
    k = max(k, 1e-12)
    return k * np.logaddexp(0.0, z / k)


# ------------------------------------------------------------ physics -----


def _draw_physics(rng, kind: str, dt: float) -> dict:
    """True physical parameters (time constants drawn in samples, then in s)."""
    u = rng.uniform
    if kind == "heater":  # C dT/dt = eta P - T/R
        tau = u(6, 40) * dt
        R = u(0.5, 2.0)
        return {"R": R, "C": tau / R, "eta": u(0.7, 1.0)}
    if kind == "thermal2":  # heater body 1, sensor body 2, loss from 2
        t1, t2 = u(3, 15) * dt, u(8, 40) * dt
        R12, R2 = u(0.3, 1.0), u(0.5, 2.0)
        return {"C1": t1 / R12, "C2": t2 / R2, "R12": R12, "R2": R2, "eta": u(0.7, 1.0)}
    if kind == "msd":  # m x'' + c x' + k x = Ka u
        wn = 2 * math.pi / (u(20, 80) * dt)
        m = u(0.5, 2.0)
        k = m * wn**2
        zeta = u(0.15, 0.7)
        return {"m": m, "c": 2 * zeta * math.sqrt(k * m), "k": k, "Ka": k * u(0.5, 2.0)}
    if kind == "motor":  # speed of a DC motor driven by a voltage amplifier
        tm = u(8, 40) * dt  # mechanical time constant J R / (Kt^2 + R b)
        R, Kt = u(0.5, 3.0), u(0.05, 0.3)
        b = Kt**2 / R * u(0.05, 0.3)
        J = tm * (Kt**2 + R * b) / R
        return {
            "R": R,
            "Kt": Kt,
            "J": J,
            "b": b,
            "Kamp": u(0.5, 2.0) * (Kt**2 + R * b) / Kt,
        }
    if kind == "servo_gear":  # motor position servo, gear contact, load inertia
        ts = u(3, 12) * dt
        wc = u(0.25, 0.8) / dt  # contact mode
        zc = u(0.05, 0.3)
        J = u(0.5, 2.0)
        return {
            "ts": ts,
            "J": J,
            "ks": J * wc**2,
            "ds": 2 * zc * wc * J,
            "b": J / (u(5, 30) * dt),
            "N": u(0.5, 2.0),  # gear ratio: load angle per servo angle
        }
    # valve_process: valve characteristic (tabulated) then a 1st/2nd-order process
    tau1 = u(5, 40) * dt
    tau2 = u(1, 8) * dt if rng.uniform() < 0.6 else 0.0
    return {
        "K": u(0.5, 2.0),
        "tau1": tau1,
        "tau2": tau2,
        "beta": u(0.5, 1.5),
        "char": "quick_opening" if rng.uniform() < 0.5 else "equal_percentage",
        "in_scale": 1.0,
    }


UNCERTAIN = {  # the physical parameters a data sheet gets wrong
    "heater": ("R", "C", "eta"),
    "thermal2": ("C1", "C2", "R12", "R2", "eta"),
    "msd": ("m", "c", "k", "Ka"),
    "motor": ("R", "Kt", "J", "b", "Kamp"),
    "servo_gear": ("ts", "J", "ks", "ds", "b", "N"),
    "valve_process": ("K", "tau1", "tau2", "in_scale"),
}


def _tf(kind: str, ph: dict) -> tuple[np.ndarray, np.ndarray]:
    """The linear block (num, den) in s of the plant, from input u to output w."""
    if kind == "heater":
        return np.array([ph["eta"] * ph["R"]]), np.array([ph["R"] * ph["C"], 1.0])
    if kind == "thermal2":
        C1, C2, R12, R2 = ph["C1"], ph["C2"], ph["R12"], ph["R2"]
        A = np.array(
            [
                [-1 / (R12 * C1), 1 / (R12 * C1)],
                [1 / (R12 * C2), -1 / (R12 * C2) - 1 / (R2 * C2)],
            ]
        )
        B = np.array([[ph["eta"] / C1], [0.0]])
        num, den = signal.ss2tf(A, B, np.array([[0.0, 1.0]]), np.zeros((1, 1)))
        return np.trim_zeros(np.real(num[0]), "f"), np.real(den)
    if kind == "msd":
        return np.array([ph["Ka"]]), np.array([ph["m"], ph["c"], ph["k"]])
    if kind == "motor":
        L = ph.get("L", 0.0)
        den = np.polymul([L, ph["R"]], [ph["J"], ph["b"]])
        den = np.polyadd(den, [ph["Kt"] ** 2])
        return np.array([ph["Kamp"] * ph["Kt"]]), np.trim_zeros(den, "f")
    if kind == "servo_gear":
        num = ph["N"] * np.array([ph["ds"], ph["ks"]])
        den = np.polymul([ph["ts"], 1.0], [ph["J"], ph["b"] + ph["ds"], ph["ks"]])
        return num, den
    den = np.array([ph["tau1"], 1.0])
    if ph["tau2"] > 0:
        den = np.polymul(den, [ph["tau2"], 1.0])
    return np.array([ph["K"]]), den


VALVE_GRID = 27  # points of the valve's table, over +-1.3 x the largest command


def _valve_grid(vs: float) -> np.ndarray:
    return np.linspace(-1.3 * vs, 1.3 * vs, VALVE_GRID)


def _valve_table(ph: dict, grid, vs: float):
    """Installed valve characteristic around the operating point (odd, slope 1 at 0),
    at the points `grid`: the vendor's curve."""
    b, z = ph["beta"], np.asarray(grid) / vs
    if ph["char"] == "quick_opening":
        return vs * np.tanh(b * z) / b
    return vs * np.sinh(b * z) / b


def _valve_char(ph: dict, x, vs: float):
    """The characteristic as the valve's table (linear between its points, constant
    beyond its ends), the command scaled by `in_scale` (the valve's sizing): the plant
    and its nominal share this form (the nominal's table points at grid / in_scale),
    so a nominal with the true parameters is the plant exactly and an input-scale
    error is exactly what the contract's re-fit may change."""
    grid = _valve_grid(vs)
    return np.interp(
        ph["in_scale"] * np.asarray(x, float), grid, _valve_table(ph, grid, vs)
    )


# -------------------------------------------------------- linear sims -----


def _lsim(num, den, u, h):
    """Response from rest of num/den (in s) to u held over steps h (exact ZOH).

    Modal form (each pole a first-order recursion, `lfilter`); a state-space loop
    when two poles nearly coincide.
    """
    num = np.atleast_1d(np.asarray(num, float))
    den = np.asarray(den, float)
    num, den = num / den[0], den / den[0]
    u = np.asarray(u, float)
    p = np.roots(den)
    sep = min(
        (abs(p[i] - p[j]) for i in range(len(p)) for j in range(i + 1, len(p))),
        default=np.inf,
    )
    if sep > 1e-3 * max(np.max(np.abs(p)), 1e-300):
        r, p, k = signal.residue(num, den)
        y = np.zeros(u.shape[0])
        for ri, pi in zip(r, p, strict=True):
            a = np.exp(pi * h)
            beta = (a - 1) / pi
            x = signal.lfilter([0.0, beta], [1.0, -a], u.astype(complex))
            y = y + np.real(ri * x)
        if len(k) and k[0] != 0:
            y = y + np.real(k[0]) * u
        return y
    A, B, C, D = signal.tf2ss(num, den)  # pragma: no cover (near-repeated poles)
    n = A.shape[0]
    M = linalg.expm(np.block([[A, B], [np.zeros((1, n + 1))]]) * h)
    Ad, Bd = M[:n, :n], M[:n, n]
    x, y = np.zeros(n), np.empty(u.shape[0])
    for i, ui in enumerate(u):
        y[i] = C[0] @ x + D[0, 0] * ui
        x = Ad @ x + Bd * ui
    return y


# ------------------------------------------------------- excitations -----

_LFSR_TAPS = {7: (7, 6), 8: (8, 6, 5, 4), 9: (9, 5), 10: (10, 7), 11: (11, 9)}


def _excitation(rng, n: int) -> tuple[str, np.ndarray]:
    kind = ("prbs", "multisine", "random_steps", "filtered_noise")[rng.integers(4)]
    amp = rng.uniform(0.5, 2.0)
    if kind == "prbs":  # maximum-length sequence, clock of 3-40 samples
        order = int(rng.integers(7, 12))
        taps = _LFSR_TAPS[order]
        state = [int(b) for b in rng.integers(0, 2, order)]
        if not any(state):
            state[0] = 1
        clock = int(rng.integers(3, 41))
        bits = []
        while len(bits) * clock < n:
            new = 0
            for t in taps:
                new ^= state[t - 1]
            bits.append(state[-1])
            state = [new] + state[:-1]
        v = np.repeat(2.0 * np.array(bits) - 1.0, clock)[:n]
        return kind, amp * v
    if kind == "multisine":  # random-phase, band 1..k_max of the record's lines
        k_max = int(rng.integers(5, max(6, n // 20)))
        lines = np.arange(1, k_max + 1)
        if rng.uniform() < 0.5:  # pink amplitudes
            ampl = 1 / np.sqrt(lines)
        else:
            ampl = np.ones(k_max)
        ph = rng.uniform(0, 2 * np.pi, k_max)
        t = np.arange(n) / n
        v = np.sum(
            ampl[:, None] * np.cos(2 * np.pi * lines[:, None] * t + ph[:, None]), 0
        )
        return kind, amp * v / np.max(np.abs(v))
    if kind == "random_steps":  # levels held for random durations
        lo, hi = int(rng.integers(5, 40)), int(rng.integers(60, 300))
        v, filled = [], 0
        while filled < n:
            hold = int(rng.integers(lo, hi + 1))
            v.append(np.full(hold, rng.uniform(-1, 1)))
            filled += hold
        return kind, amp * np.concatenate(v)[:n]
    order = int(rng.integers(2, 5))
    wc = rng.uniform(0.01, 0.2)
    sos = signal.butter(order, wc, output="sos")
    v = signal.sosfilt(sos, rng.standard_normal(n + 500))[500:]
    return kind, amp * v / np.max(np.abs(v))


# ----------------------------------------------------- physical causes ---


def _delay(vf, h, tau0, a, period, phase):
    """v held at the samples, seen through a transport delay tau(t) (seconds)."""
    t = np.arange(vf.shape[0]) * h
    tau = tau0 * (1 + a * np.sin(2 * np.pi * t / period + phase))
    src = t - tau
    idx = np.floor(src / (h * FINE) + 1e-9).astype(int)
    v = vf[::FINE]
    return v[np.clip(idx, 0, v.shape[0] - 1)]


def _stem_stiction(vf, h, fs, fc, vs, w, zeta):
    """Valve stem: m x'' = k (v - x) - c x' - friction (Karnopp stick band, Stribeck).

    Normalised by the actuator stiffness: friction in input units; w, zeta the
    stem's natural frequency and damping. Semi-implicit Euler on sub-steps.
    """
    sub = 4
    hs = h / sub
    x, xd = float(vf[0]), 0.0
    eta = 1e-6 * max(float(np.max(np.abs(vf))), 1e-12) / hs  # stick band on velocity
    out = np.empty(vf.shape[0])
    w2, c = w * w, 2 * zeta * w
    for j, vj in enumerate(vf.tolist()):
        for _ in range(sub):
            force = vj - x  # spring force / k
            if abs(xd) < eta and abs(force) <= fs:
                xd = 0.0
                continue
            s = math.copysign(1.0, xd) if abs(xd) >= eta else math.copysign(1.0, force)
            fr = (fc + (fs - fc) * math.exp(-((xd / vs) ** 2))) * s
            acc = w2 * (force - fr) - c * xd
            xd_new = xd + hs * acc
            if xd != 0.0 and xd_new * xd < 0:  # velocity reverses: it sticks
                xd_new = 0.0
            xd = xd_new
            x += hs * xd
        out[j] = x
    return out


def _slew(vf, h, r, tp):
    """Valve actuator / amplifier: x' = (v - x)/tp with |x'| <= r."""
    x, out = float(vf[0]), np.empty(vf.shape[0])
    decay = math.exp(-h / tp)
    step = r * h
    for j, vj in enumerate(vf.tolist()):
        target = vj + (x - vj) * decay
        dx = target - x
        if dx > step:
            dx = step
        elif dx < -step:
            dx = -step
        x += dx
        out[j] = x
    return out


def _gear(uf, h, ph, c):
    """Servo angle (first-order lag of u) driving a load through a gear with a dead
    band of total width c (in servo angle): contact spring/damper, load inertia
    with viscous friction; the contact only pushes. RK4 on the fine grid.
    """
    ts, J, ks, ds, b = ph["ts"], ph["J"], ph["ks"], ph["ds"], ph["b"]
    half = c / 2

    def f(th, tl, wl, u):
        thd = (u - th) / ts
        d = th - tl
        if d > half:
            T = max(ks * (d - half) + ds * (thd - wl), 0.0)
        elif d < -half:
            T = min(ks * (d + half) + ds * (thd - wl), 0.0)
        else:
            T = 0.0
        return thd, wl, (T - b * wl) / J

    th, tl, wl = 0.0, 0.0, 0.0
    out = np.empty(uf.shape[0])
    for j, u in enumerate(uf.tolist()):
        out[j] = tl
        k1 = f(th, tl, wl, u)
        k2 = f(th + h / 2 * k1[0], tl + h / 2 * k1[1], wl + h / 2 * k1[2], u)
        k3 = f(th + h / 2 * k2[0], tl + h / 2 * k2[1], wl + h / 2 * k2[2], u)
        k4 = f(th + h * k3[0], tl + h * k3[1], wl + h * k3[2], u)
        th += h / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        tl += h / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        wl += h / 6 * (k1[2] + 2 * k2[2] + 2 * k3[2] + k4[2])
    return ph["N"] * out


class _Plant:
    """One physical plant, its input map and (at most) one physical cause."""

    def __init__(self, kind, ph, vs, cause, shape, eff):
        self.kind, self.ph, self.vs = kind, ph, vs
        self.cause, self.shape, self.eff = cause, shape, eff  # eff: shape constants
        self.dt = DT[kind]

    def F(self, x, ph=None):
        ph = ph or self.ph
        if self.kind == "valve_process":
            return _valve_char(ph, x, self.vs)
        return np.asarray(x, float).copy()

    def output(self, v, m: float | None):
        """Noise-free output at the samples; m the cause's magnitude (None: no cause)."""
        h = self.dt / FINE
        vf = np.repeat(np.asarray(v, float), FINE)
        cause = self.cause if m is not None else None
        e, p = self.eff, self.shape
        x = vf
        if cause == "time_delay":
            period = e["period"] * v.shape[0] * self.dt
            x = _delay(vf, h, m * self.dt, e["a"], period, e["phase"])
        elif cause == "dead_zone":
            x = _softplus(vf - m, e["knee"] * m) - _softplus(
                -vf - m * e["asym"], e["knee"] * m * e["asym"]
            )
        elif cause == "backlash" and p == "valve_stiction":
            x = _stem_stiction(
                vf,
                h,
                m,
                m * e["fc_over_fs"],
                e["vs"] * m / self.dt,
                e["w"] / self.dt,
                e["zeta"],
            )
        elif cause == "rate_limit":
            x = _slew(vf, h, e["full_range"] / (m * self.dt), e["tp"] * self.dt)
        u = self.F(x)
        if cause == "saturation":
            hi, lo = e["u_hi"] * (1 - m), e["u_lo"] * (1 - min(m * e["asym"], 0.95))
            k = e["knee"] * (hi - lo)
            u = lo + _softplus(u - lo, k) - _softplus(u - hi, k)
        elif cause == "preload":
            u = u + m * e["u_std"] * np.tanh(x / (e["eps"] * self.vs)) * (
                1 + e["asym"] * np.sign(x)
            )
        ph = self.ph
        if cause == "extra_pole" and p == "armature":
            ph = dict(ph, L=m * self.dt * ph["R"])
        if cause == "backlash" and p == "gear_dead_band":
            w = _gear(u, h, ph, m)
        elif cause in ("friction", "feedback_nonlinearity"):
            num, den = _tf(self.kind, ph)
            if cause == "friction":
                force = _friction_force(m, e)
            else:
                force = _spring_force(m, p, e, den[-1] / num[-1])
            w = _axis(u, h, num, den, force, sticks=cause == "friction")
        else:
            num, den = _tf(self.kind, ph)
            w = _lsim(num, den, u, h)
        if cause == "extra_pole" and p == "sensor_lag":
            w = _lsim([1.0], [m * self.dt, 1.0], w, h)
        w = w[::FINE]
        if cause == "output_nonlinearity":
            W = e["W"]
            if p == "tanh_offset":
                L = W / m
                w = e["wc"] + L * np.tanh((w - e["wc"]) / L)
            elif p == "polynomial":
                w = w + m * (e["b2"] * w**2 / W + e["b3"] * w**3 / W**2)
            elif p == "sign_blind":  # a speed sensor without direction
                w = np.abs(w)
            else:  # one-sided soft limit of the sensor range (top or bottom)
                top, sd = e["top"] * (1 - min(m, 0.95)), e["side"]
                w = w - sd * _softplus(sd * w - top, e["knee"] * W)
        return w

    def linear_output(self, v, ph):
        """Nominal-structure output at the samples for parameters ph (exact ZOH)."""
        num, den = _tf(self.kind, ph)
        return _lsim(num, den, self.F(v, ph), self.dt)


def _sensitivities(plant: _Plant, v) -> np.ndarray:
    """Columns: d w / d(re-fittable parameter) of the nominal structure at the true
    parameters: static gain, each denominator coefficient, the valve's input scale."""
    ph = plant.ph
    num, den = _tf(plant.kind, ph)
    u = plant.F(v)
    w = _lsim(num, den, u, plant.dt)
    cols = [w]
    for i in range(1, len(den)):
        d2 = den.copy()
        eps = 1e-4 * abs(d2[i])
        d2[i] += eps
        cols.append((_lsim(num, d2, u, plant.dt) - w) / eps * abs(d2[i]))
    if plant.kind == "valve_process":
        ph2 = dict(ph, in_scale=ph["in_scale"] * (1 + 1e-4))
        cols.append((plant.linear_output(v, ph2) - w) / 1e-4)
    return np.column_stack(cols)


def _after_refit(S, d) -> float:
    """RMS of d once the best linearised re-fit (least squares on S) is removed."""
    coef, *_ = np.linalg.lstsq(S, d, rcond=None)
    return _rms(d - S @ coef)


# ----------------------------------------------------------- the case ----


def perturbed(ph: dict, errors: dict, scale: float) -> dict:
    """`ph` with each parameter of `errors` off by `scale` x its relative error."""
    out = dict(ph)
    for k, e in errors.items():
        out[k] = ph[k] * (1 + scale * e)
    return out


def _draw_errors(rng, kind: str, ph: dict) -> dict:
    """Relative errors of 2-4 physical parameters, 15-20 % each, signs correlated."""
    names = [k for k in UNCERTAIN[kind] if not (k == "tau2" and ph.get("tau2", 0) == 0)]
    return draw_errors(rng, names)


def draw_errors(rng, names: list[str]) -> dict:
    """Relative errors of 2-4 of the parameters `names` (all when there are two),
    15-20 % each, 70 % of them sharing a common sign (a data sheet's errors)."""
    k = int(rng.integers(2, min(4, len(names)) + 1))
    chosen = [names[i] for i in sorted(rng.choice(len(names), k, replace=False))]
    common = rng.choice((-1.0, 1.0))
    errs = {}
    for name in chosen:
        s = common if rng.uniform() < 0.7 else -common
        errs[name] = s * rng.uniform(*NOMINAL_ERROR)
    return errs


def _shape_for(rng, cause: str, kind: str, extended: bool) -> str:
    options = {
        "backlash": {
            "servo_gear": ("gear_dead_band",),
            "valve_process": ("valve_stiction",),
        },
        "dead_zone": {
            "valve_process": ("spool_overlap",),
            "msd": ("spool_overlap",),
            "motor": ("drive_threshold",),
        },
        "saturation": {
            "heater": ("heater_power_limit",),
            "thermal2": ("heater_power_limit",),
        },
        "extra_pole": {"motor": ("armature", "sensor_lag")},
        "output_nonlinearity": {},
        "drift": {},
        "coloured_noise": {},
        "preload": {},
        "rate_limit": {},
        "time_delay": {},
    }
    default = {
        "saturation": ("amplifier_rails",),
        "preload": ("pwm_dead_time_overcompensation",),
        "rate_limit": {"valve_process": ("stroking_speed",)}.get(kind, ("slew_rate",)),
        "time_delay": ("transport_delay",),
        "extra_pole": ("sensor_lag",),
        "output_nonlinearity": ("tanh_offset", "polynomial", "range_limit"),
        "drift": ("thermal_creep", "random_walk", "ambient_cycle"),
        "coloured_noise": ("arma", "flicker"),
        "parameter_mismatch": ("correlated_parameters",),
        "none": ("none",),
        "friction": ("coulomb_stribeck",),
        "feedback_nonlinearity": ("cubic_stiffness", "spring_clearance"),
    }
    choices = options.get(cause, {}).get(kind) or default[cause]
    if extended and cause == "output_nonlinearity" and kind == "motor":
        choices = (*choices, "sign_blind")  # a motor run in both directions
    return choices[int(rng.integers(len(choices)))]


MAG = {  # initial magnitude, bounds (units in _Plant.output)
    "backlash": (0.05, 0.002, 0.8),  # x range of v
    "dead_zone": (0.1, 0.005, 0.7),  # x max|v|
    "saturation": (0.2, 0.005, 0.9),
    "preload": (0.05, 0.002, 1.5),
    "rate_limit": (5.0, 0.3, 400.0),  # samples for a full-range move
    "time_delay": (2.0, 0.3, 15.0),  # samples
    "extra_pole": (2.0, 0.05, 60.0),  # samples
    "output_nonlinearity": (0.3, 0.005, 0.95),  # the upper bound per shape: m_hi
    "friction": (0.05, 0.002, 0.8),  # static friction, x max|v| (input units)
    # cubic: k3 W^3 / (k W); clearance: share of the stiffness behind it (m_hi)
    "feedback_nonlinearity": (0.2, 0.005, 3.0),
}


def _effect_constants(rng, cause, shape, plant_v, w0, u0, vs, speed):
    e: dict = {}
    if cause == "time_delay":
        e.update(
            a=rng.uniform(0, 0.15),
            period=rng.uniform(0.3, 1.5),
            phase=rng.uniform(0, 6.3),
        )
    elif cause == "dead_zone":
        e.update(knee=rng.uniform(0.05, 0.3), asym=rng.uniform(0.6, 1.5))
    elif cause == "backlash" and shape == "valve_stiction":
        e.update(
            fc_over_fs=rng.uniform(0.5, 0.9),
            vs=rng.uniform(0.5, 3.0),  # Stribeck velocity: band per sample
            w=rng.uniform(3.0, 6.0),  # stem natural frequency, rad per sample
            zeta=rng.uniform(0.5, 1.0),
        )
    elif cause == "rate_limit":
        e.update(full_range=float(np.ptp(plant_v)), tp=rng.uniform(0.05, 0.2))
    elif cause == "saturation":
        e.update(
            u_hi=float(np.max(u0)),
            u_lo=float(np.min(u0)),
            asym=rng.uniform(0.3, 1.2)
            if shape == "amplifier_rails"
            else rng.uniform(1.0, 1.1),
            knee=rng.uniform(0.03, 0.15) if shape == "amplifier_rails" else 1e-4,
        )
    elif cause == "preload":
        e.update(
            u_std=float(np.std(u0)),
            eps=rng.uniform(0.005, 0.03),
            asym=rng.uniform(-0.3, 0.3),
        )
    elif cause == "output_nonlinearity":
        W = float(np.quantile(np.abs(w0), 0.98))
        e.update(
            W=W,
            wc=rng.uniform(-0.3, 0.3) * W,
            b2=rng.uniform(-1, 1),
            b3=rng.uniform(-0.5, 0.5),
            side=1.0 if rng.uniform() < 0.5 else -1.0,
            knee=rng.uniform(0.01, 0.05),
        )
        e["top"] = float(np.max(e["side"] * w0))
        e["m_hi"] = {"tanh_offset": 3.0, "polynomial": 1.0}.get(shape, 0.95)
    elif cause == "friction":
        V = float(np.quantile(np.abs(speed), 0.98))
        e.update(
            V=V,  # speed scale of the motion
            fc_over_fs=rng.uniform(0.5, 0.9),  # Coulomb below static (Stribeck)
            vstr=rng.uniform(0.02, 0.2) * V,  # Stribeck speed
            visc=rng.uniform(0.0, 0.3),  # viscous part at speed V, x static
        )
    elif cause == "feedback_nonlinearity":
        e["W"] = float(np.quantile(np.abs(w0), 0.98))
        if shape == "spring_clearance":
            e.update(gap=rng.uniform(0.2, 0.6) * e["W"], m_hi=0.9)
    return e


def _axis(uf, h, num, den, force, *, sticks: bool):
    """Response from rest of num/den (in s; order 1 or 2, constant numerator) to
    u - f, the force f = force(x, s, drive) fed back from its state (input units; x
    the output, s its velocity, s = x for order 1; drive = u less the spring). Exact
    ZOH of the linear part over each fine step with f held. `sticks`: `force`
    returns None to stick (s held at 0, the friction balancing the drive), and a
    velocity that reverses within a step stops there."""
    den = np.asarray(den, float)
    b0 = float(np.atleast_1d(num)[-1]) / den[0]
    den = den / den[0]
    if den.shape[0] == 2:  # velocity output: s' + a0 s = b0 (u - f)
        a = math.exp(-den[1] * h)
        Ad, Bd = np.array([[a]]), np.array([(1 - a) * b0 / den[1]])
        k_b = 0.0  # no spring
    else:  # position output: x'' + a1 x' + a0 x = b0 (u - f)
        M = linalg.expm(
            np.array([[0.0, 1.0, 0.0], [-den[2], -den[1], b0], [0.0, 0.0, 0.0]]) * h
        )
        Ad, Bd = M[:2, :2], M[:2, 2]
        k_b = den[2] / b0
    x = np.zeros(Ad.shape[0])
    out = np.empty(uf.shape[0])
    for j, u in enumerate(uf.tolist()):
        out[j] = x[0]
        s = x[-1]
        drive = u - k_b * x[0]
        f = force(x[0], s, drive)
        if f is None:  # stuck: the friction balances the drive
            x[-1], f = 0.0, drive
        x_new = Ad @ x + Bd * (u - f)
        if sticks and s != 0.0 and x_new[-1] * s < 0:
            x_new[-1] = 0.0
        x = x_new
    return out


def _friction_force(m, e):
    """Coulomb + Stribeck + viscous friction (static level m), Karnopp sticking:
    stuck at s = 0 while the drive stays within the static level."""
    fc, fs, vstr, visc = m * e["fc_over_fs"], m, e["vstr"], m * e["visc"] / e["V"]

    def force(x, s, drive):
        if s == 0.0:
            if abs(drive) <= fs:
                return None
            return math.copysign(fs, drive)
        return (fc + (fs - fc) * math.exp(-((s / vstr) ** 2))) * math.copysign(
            1.0, s
        ) + visc * s

    return force


def _spring_force(m, shape, e, k_over_b):
    """Spring force beyond the nominal's linear k x (input units): a cubic
    hardening k3 x^3 (k3 W^3 = m k W) or, behind a clearance of half-width `gap`, a
    share m of the stiffness that acts only outside it."""
    W = e["W"]
    if shape == "cubic_stiffness":
        return lambda x, s, drive: m * k_over_b * x**3 / W**2
    g = e["gap"]
    return lambda x, s, drive: -m * k_over_b * min(max(x, -g), g)


def _drift_shape(rng, shape, n, dt):
    t = np.arange(n) * dt
    T = t[-1]
    if shape == "thermal_creep":
        d = 1 - np.exp(-t / (rng.uniform(0.2, 1.0) * T))
    elif shape == "random_walk":
        d = signal.lfilter(
            [1.0], [1.0, -rng.uniform(0.9, 0.99)], np.cumsum(rng.standard_normal(n))
        )
        d = d - d[0]
    else:
        ph = rng.uniform(0, 2 * np.pi)
        d = np.sin(2 * np.pi * t / (rng.uniform(1.0, 4.0) * T) + ph) - np.sin(ph)
    return d * rng.choice((-1.0, 1.0))


def _coloured(rng, shape, n):
    e = rng.standard_normal(n + 1000)
    if shape == "arma":
        if rng.uniform() < 0.5:
            r = rng.uniform(0.7, 0.97)
            th = rng.uniform(0.02, 0.4)
            a = [1.0, -2 * r * math.cos(th), r * r]
        else:
            p1, p2 = rng.uniform(0.7, 0.97), rng.uniform(0.0, 0.8)
            a = np.poly([p1, p2])
        b = [1.0, rng.uniform(-0.5, 0.5)]
        x = signal.lfilter(b, a, e)[1000:]
    else:  # 1/f^alpha, flat below a corner at ~2 cycles per record
        alpha = rng.uniform(0.8, 1.2)
        spec = np.fft.rfft(e[:n])
        f = np.fft.rfftfreq(n)
        f0 = 2.0 / n
        spec = spec / np.maximum(f, f0) ** (alpha / 2)
        spec[0] = 0.0
        x = np.fft.irfft(spec, n)
    return x / _rms(x)


def make_case(seed: int, index: int, cause: str, *, classes: str = "fourteen") -> dict:
    """Case `index` of the seed's family-B benchmark, with the physical cause `cause`.

    A draw whose cause does not show (or that fails a sanity check) is drawn again
    from `default_rng([seed, index, attempt])`. `classes="twelve"`: the draws of the
    twelve-class version (no sign-blind sensor among the output nonlinearities).
    """
    for attempt in range(50):
        rng = np.random.default_rng([seed, index] + ([attempt] if attempt else []))
        case = _draw(rng, cause, extended=classes != "twelve")
        if case is not None:
            return case
    raise RuntimeError(
        f"family B: no valid {cause} case in 50 draws"
    )  # pragma: no cover


def _forward_bias(plant: _Plant, recs: dict, snr: float, ratio: float) -> float:
    """Forward drive b added to both records so that the sign-blind sensor's effect
    |w| - w after the linearised re-fit is `ratio` noise std (the noise std at the
    SNR of the biased record): bisection, the effect falling as b grows. Linear in b:
    w(v + b) = w(v) + b w(1), and so are the sensitivities."""
    parts = {
        r: (plant.output(v, None), plant.output(np.ones_like(v), None))
        for r, v in recs.items()
    }
    sens = {
        r: (_sensitivities(plant, v), _sensitivities(plant, np.ones_like(v)))
        for r, v in recs.items()
    }

    def excess(b):  # effect / noise std - ratio
        E = min(
            _after_refit(sens[r][0] + b * sens[r][1], np.abs(w + b * w1) - w - b * w1)
            for r, (w, w1) in parts.items()
        )
        w_est = parts["estimation"][0] + b * parts["estimation"][1]
        return E / (_rms(w_est) / 10 ** (snr / 20)) - ratio

    lo, hi = 0.0, 3.0 * float(max(np.max(np.abs(v)) for v in recs.values()))
    if excess(lo) <= 0:
        return 0.0
    for _ in range(40):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if excess(mid) > 0 else (lo, mid)
    return 0.5 * (lo + hi)


def _draw(rng, cause: str, extended: bool = True) -> dict | None:
    plants = PLANTS_FOR[cause]
    kind = plants[int(rng.integers(len(plants)))]
    dt = DT[kind]
    ph = _draw_physics(rng, kind, dt)
    shape = _shape_for(rng, cause, kind, extended)
    n = int(rng.integers(N_SAMPLES[0], N_SAMPLES[1] + 1))
    (k_est, v_est), (k_val, v_val) = _excitation(rng, n), _excitation(rng, n)
    vs = float(max(np.max(np.abs(v_est)), np.max(np.abs(v_val))))
    plant = _Plant(kind, ph, vs, None, shape, {})
    recs = {"estimation": v_est, "validation": v_val}
    w0 = {r: plant.output(v, None) for r, v in recs.items()}
    u0 = plant.F(v_est)
    snr = rng.uniform(*SNR_DB)
    sigma = _rms(w0["estimation"]) / 10 ** (snr / 20)
    if not sigma > 0:
        return None
    S = {r: _sensitivities(plant, v) for r, v in recs.items()}
    ratio = math.exp(rng.uniform(math.log(RATIO[0]), math.log(RATIO[1])))
    truth = {"plant": kind, "shape": shape, "dt": dt}
    if shape == "sign_blind":  # run forward, reversing just enough to show
        truth["forward_bias"] = bias = _forward_bias(plant, recs, snr, ratio)
        recs = {r: v + bias for r, v in recs.items()}
        v_est = recs["estimation"]
        plant.vs = vs = float(max(np.max(np.abs(v)) for v in recs.values()))
        w0 = {r: plant.output(v, None) for r, v in recs.items()}
        u0 = plant.F(v_est)
        sigma = _rms(w0["estimation"]) / 10 ** (snr / 20)
        S = {r: _sensitivities(plant, v) for r, v in recs.items()}
    w = dict(w0)
    magnitude = None
    if cause in STRUCTURAL:
        plant.cause = cause
        speed = w0["estimation"]  # the velocity: the output itself, or its derivative
        if kind == "msd":
            speed = np.gradient(speed, dt)
        plant.eff = _effect_constants(
            rng, cause, shape, v_est, w0["estimation"], u0, vs, speed
        )
        m0, lo, hi = MAG[cause]
        hi = plant.eff.pop("m_hi", hi)
        if cause == "backlash":
            m0, lo, hi = m0 * np.ptp(v_est), lo * np.ptp(v_est), hi * np.ptp(v_est)
        elif cause in ("dead_zone", "friction"):
            m0, lo, hi = m0 * vs, lo * vs, hi * vs
        elif shape == "sign_blind":  # sized by the forward drive, not a magnitude
            m0 = lo = hi = 1.0
        target = ratio * sigma
        m, hist = m0, []
        for _ in range(7):
            ws = {r: plant.output(v, m) for r, v in recs.items()}
            E = min(_after_refit(S[r], ws[r] - w0[r]) for r in recs)
            hist.append((m, E))
            if E > 0 and abs(math.log(E / target)) < 0.1:
                break
            if (
                len(hist) >= 2
                and hist[-1][1] > 0
                and hist[-2][1] > 0
                and hist[-1][0] != hist[-2][0]
            ):
                slope = math.log(hist[-1][1] / hist[-2][1]) / math.log(
                    hist[-1][0] / hist[-2][0]
                )
                slope = min(max(slope, 0.3), 4.0)
            else:
                slope = 1.0
            step = math.log(target / E) / slope if E > 0 else math.log(10.0)
            m_new = min(max(m * math.exp(max(min(step, 2.5), -2.5)), lo), hi)
            if m_new == m:
                break
            m = m_new
        m, E = min(hist, key=lambda me: abs(math.log(max(me[1], 1e-300) / target)))
        ws = {r: plant.output(v, m) for r, v in recs.items()}
        if not E > 0:
            return None
        # the noise keeps the SNR range; the ratio follows when the magnitude bound bit
        sigma_hi = _rms(w0["estimation"]) / 10 ** (SNR_DB[0] / 20)
        sigma_lo = _rms(w0["estimation"]) / 10 ** (SNR_DB[1] / 20)
        sigma = min(max(E / ratio, sigma_lo), sigma_hi)
        if not RATIO[0] * 0.8 <= E / sigma <= RATIO[1] * 1.25:
            return None  # the cause cannot show at this size in this plant: draw again
        w, magnitude = ws, m
        truth["effect_after_refit_rms"] = E
        truth["effect_rms"] = min(_rms(ws[r] - w0[r]) for r in recs)
        if not all(np.all(np.isfinite(ws[r])) for r in recs):
            return None
    # the nominal model: the same physics with parameters off
    errors = _draw_errors(rng, kind, ph)

    def nominal_gap(scale):  # the larger of the two records'
        p_nom = perturbed(ph, errors, scale)
        return max(_rms(plant.linear_output(v, p_nom) - w0[r]) for r, v in recs.items())

    if cause in ("none", "drift", "coloured_noise"):
        goal = rng.uniform(0.0, 0.1) * sigma
        scale = min(1.0, goal / max(nominal_gap(1.0), 1e-300))
        for _ in range(30):  # the error is about linear in the scale: check it
            if nominal_gap(scale) <= 0.1 * sigma:
                break
            scale /= 2
        errors = {k: e * scale for k, e in errors.items()}
    ph_nom = perturbed(ph, errors, 1.0)
    gap_nominal = nominal_gap(1.0)
    if cause == "parameter_mismatch" and gap_nominal < 0.3 * sigma:
        sigma = gap_nominal / rng.uniform(
            0.3, 2.0
        )  # keep it visible (SNR may pass 40 dB)
    # noise and noise-model causes
    records = {}
    for r, v in recs.items():
        y = w[r].copy()
        if cause == "coloured_noise":
            y = y + sigma * _coloured(rng, shape, n)
        else:
            y = y + sigma * rng.standard_normal(n)
        if cause == "drift":
            d = _drift_shape(rng, shape, n, dt)
            E = _after_refit(S[r], d)
            y = y + d * (ratio * sigma / max(E, 1e-300))
        records[r] = {"t": np.arange(n) * dt, "v": v, "y": y}
    if cause == "drift":
        truth["effect_after_refit_rms"] = ratio * sigma
    truth.update(
        effect=cause,
        noise_std=float(sigma),
        snr_db=float(20 * math.log10(_rms(w0["estimation"]) / sigma)),
        n_samples=n,
        excitation={"estimation": k_est, "validation": k_val},
        nominal_errors={k: float(e) for k, e in errors.items()},
        nominal_gap_over_noise=float(gap_nominal / sigma),
        physics={k: (v if isinstance(v, str) else float(v)) for k, v in ph.items()},
    )
    if magnitude is not None:
        truth["magnitude"] = float(magnitude)
        truth["effect_constants"] = {k: float(x) for k, x in plant.eff.items()}
    if "effect_after_refit_rms" in truth:
        truth["effect_rms_over_noise"] = float(truth["effect_after_refit_rms"] / sigma)
        truth["effect_after_refit_rms"] = float(truth["effect_after_refit_rms"])
    if "effect_rms" in truth:
        truth["effect_rms"] = float(truth["effect_rms"])
    model = _model_dict(plant, ph_nom)
    return {"model": model, **records, "truth": truth}


def _model_dict(plant: _Plant, ph_nom: dict) -> dict:
    """model.json of the nominal (contract schema): continuous_tf, identity or a
    tabulated valve characteristic covering the inputs."""
    num, den = _tf(plant.kind, ph_nom)
    num, den = num / den[-1], den / den[-1]  # time-constant form: den[-1] = 1
    lin = {
        "kind": "continuous_tf",
        "num": [float(x) for x in num],
        "den": [float(x) for x in den],
    }
    if plant.kind == "valve_process":
        grid = _valve_grid(plant.vs)
        nl = {
            "kind": "tabulated",
            "v": [float(x) for x in grid / ph_nom["in_scale"]],
            "u": [float(x) for x in _valve_table(ph_nom, grid, plant.vs)],
        }
    else:
        nl = {"kind": "identity"}
    return {"nonlinearity": nl, "linear": lin}


def classes_for(seed: int, n_cases: int, *, classes: str = "fourteen") -> list[str]:
    """Balanced labels: block b of K cases is a permutation of the K classes of
    `CLASS_SETS[classes]`."""
    names = CLASS_SETS[classes]
    out: list[str] = []
    for b in range((n_cases + len(names) - 1) // len(names)):
        perm = np.random.default_rng([seed, 1_000_003, b]).permutation(len(names))
        out.extend(names[i] for i in perm)
    return out[:n_cases]


def make_cases(
    seed: int, n_cases: int, out: Path, *, classes: str = "fourteen"
) -> dict:
    """Write `n_cases` family-B case folders under `out/cases/` and `out/truth.json`
    (`classes`: "fourteen", or "twelve" for the sets of the twelve-class version)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    truth = {"family": "B", "seed": int(seed), "realism": "physical", "cases": {}}
    if classes != "twelve":  # the twelve-class sets keep their truth.json exactly
        truth["classes"] = classes
    for i, cause in enumerate(classes_for(seed, n_cases, classes=classes)):
        case = make_case(seed, i, cause, classes=classes)
        truth["cases"][write_case(out, i, case)] = case["truth"]
    write_json(out / "truth.json", truth)
    return truth
