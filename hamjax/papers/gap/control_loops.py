"""Control-loop benchmark: routine operating data of PI loops, with or without valve
stiction (`hamjax blind make --family loops`, docs/control-loops.md).

A case is one PI loop around a first-order-plus-dead-time, second-order-plus-dead-
time or integrating (level) process, sampled every 1-10 s, recorded as the
contract's closed-loop record (shared/contracts/gap-case.md): v = the controller
output OP, y = the measured PV, two experiments (estimation, validation) on the same
loop. The loop runs on setpoint changes at random times, a load disturbance of
realistic colour through the process lag and white measurement noise. Half the loops
of every block have a sticky valve, by the data-driven model of Choudhury et al.
(2005) or of He et al. (2007), labelled `backlash` (the contract: "a control valve
with stiction is a backlash"); the other half are labelled by what they contain
(`none`, `parameter_mismatch`, `coloured_noise`, `drift`). The nominal `model.json`
is the process an engineer would have: the linear process with 15-20 % parameter
errors (within 0.1 noise std of the truth in the `none`, `coloured_noise` and
`drift` loops, as in family B), identity map, discrete (exact ZOH with the dead time).

NumPy/SciPy only, nothing of the diagnosis: case i draws from
`numpy.random.default_rng([seed, i])` only, so it does not depend on the number of
cases.
"""

import math
from pathlib import Path

import numpy as np
from scipy import linalg, signal

from ...io import write_case, write_json
from .family_b import draw_errors, perturbed


# Every block of len(SLOTS) cases is a permutation of the slots: half stiction.
SLOTS = (
    ("backlash", "choudhury"),
    ("backlash", "choudhury"),
    ("backlash", "he"),
    ("backlash", "he"),
    ("none", None),
    ("parameter_mismatch", None),
    ("coloured_noise", None),
    ("drift", None),
)
LABELS = ("backlash", "none", "parameter_mismatch", "coloured_noise", "drift")
PROCESSES = ("fopdt", "sopdt", "integrating")
DTS = (1.0, 2.0, 5.0, 10.0)  # sampling periods, s
N_SAMPLES = (1000, 4000)
DISTURBANCE_RATIO = (0.5, 3.0)  # load disturbance RMS / noise std (log-uniform)
BAND = (0.5, 5.0)  # dead band + stick band S (He: fs + fd), % of valve travel
# the nominal of an integrator: a lag this many records long (the model reader
# refuses an unstable block); over the record it differs from the integrator by
# under 0.05 %
INTEGRATOR_LAG_RECORDS = 1000.0
# the largest discrete order (poles, or numerator length - 1 with the dead time's
# zeros) `hamjax diagnose` reads today (diagnosis.layout.N_MAX; a test checks it):
# the dead time is drawn within it
MAX_ORDER = 4


def _rms(x) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


# ------------------------------------------------------------- stiction -----


class ChoudhuryStiction:
    """Data-driven stiction model of Choudhury, Thornhill & Shah (2005), "Modelling
    valve stiction", Control Eng. Practice 13, 641-658 (Sec. 4, Fig. 7).

    S: dead band plus stick band, J: slip jump (valve-travel units). The valve sticks
    when its input's velocity changes sign or becomes zero (x_ss: the input then);
    stuck, it stays until the input has moved from x_ss by more than S in the
    opposite direction or by more than J in the same direction (stopped and
    restarting); moving, its position is y = x - sign(dx) (S - J)/2. At rest at the
    start (no direction yet), the first motion must cross S.
    """

    def __init__(self, S: float, J: float, *, x0: float = 0.0):
        self.S, self.J = float(S), float(J)
        self.y, self.x_prev, self.x_ss = float(x0), float(x0), float(x0)
        self.direction, self.stuck = 0.0, True

    def __call__(self, x: float) -> float:
        if not self.stuck:
            dx = x - self.x_prev
            if dx != 0.0 and math.copysign(1.0, dx) == self.direction:
                self.y = x - self.direction * (self.S - self.J) / 2
            else:  # stops or reverses: sticks at the previous input
                self.stuck, self.x_ss = True, self.x_prev
        if self.stuck:
            d = x - self.x_ss
            sd = math.copysign(1.0, d) if d != 0.0 else 0.0
            band = self.J if sd == self.direction else self.S
            if sd != 0.0 and abs(d) > band:  # slips
                self.stuck, self.direction = False, sd
                self.y = x - sd * (self.S - self.J) / 2
        self.x_prev = float(x)
        return self.y


class HeStiction:
    """Two-parameter stiction model of He, Wang, Pottmann & Qin (2007), "A curve
    fitting method for detecting valve stiction in oscillating control loops",
    Ind. Eng. Chem. Res. 46, 4549-4560 (Fig. 3).

    fs: static, fd: kinetic friction band (valve-travel units). The residual force
    u_r accumulates the input's changes, temp = u_r + x_k - x_{k-1}; when
    |temp| > fs the valve slips and u_r = sign(temp) fd, else u_r = temp (stuck); the
    position is y_k = x_k - u_r.
    """

    def __init__(self, fs: float, fd: float, *, x0: float = 0.0):
        self.fs, self.fd = float(fs), float(fd)
        self.u_r, self.x_prev = 0.0, float(x0)

    def __call__(self, x: float) -> float:
        temp = self.u_r + x - self.x_prev
        self.u_r = math.copysign(self.fd, temp) if abs(temp) > self.fs else temp
        self.x_prev = float(x)
        return x - self.u_r


def valve_positions(model, op) -> np.ndarray:
    """The valve positions a stiction `model` gives for the commands `op`, in turn."""
    return np.array([model(float(x)) for x in np.asarray(op, float)])


# -------------------------------------------------------------- process -----


def process_tf(kind: str, p: dict) -> tuple[np.ndarray, np.ndarray]:
    """The process without its dead time, (num, den) in s: K/(tau s + 1),
    K/((t1 s + 1)(t2 s + 1)) or Ki/(s (t s + 1))."""
    if kind == "fopdt":
        return np.array([p["K"]]), np.array([p["tau"], 1.0])
    if kind == "sopdt":
        return np.array([p["K"]]), np.polymul([p["t1"], 1.0], [p["t2"], 1.0])
    return np.array([p["Ki"]]), np.array([p["t"], 1.0, 0.0])


def discrete_process(num, den, dt: float, delay: int) -> tuple[np.ndarray, np.ndarray]:
    """(b, a) in q^-1 of num/den with its input held over each sample (exact ZOH)
    and `delay` whole samples of dead time: y_k = B/A u_k."""
    A, B, C, D = signal.tf2ss(num, den)
    n = A.shape[0]
    M = linalg.expm(np.block([[A, B], [np.zeros((1, n + 1))]]) * dt)
    b, a = signal.ss2tf(M[:n, :n], M[:n, n:], C, D)
    b = np.real(b[0])
    b[0] = 0.0  # strictly proper: the held input acts from the next sample on
    b = np.concatenate([np.zeros(delay), b])
    return b, np.real(a)


def simc_pi(kind: str, p: dict, delay: int, dt: float, *, detune: float) -> dict:
    """PI settings by the SIMC rules (Skogestad 2003, J. Process Control 13, 291-309,
    Eqs. 21-22 and the half rule) from the true process: closed-loop time constant
    tau_c = detune x the effective delay theta (the dead time, the lag of the second
    pole or of the integrating process's lag, and 1.5 samples of sampling and hold).
    """
    theta = (delay + 1.5) * dt
    if kind == "fopdt":
        tau, gain = p["tau"], p["K"]
    elif kind == "sopdt":
        t1, t2 = max(p["t1"], p["t2"]), min(p["t1"], p["t2"])
        tau, theta, gain = t1 + t2 / 2, theta + t2 / 2, p["K"]
    else:
        theta += p["t"]
        tc = detune * theta
        return {"Kc": 1.0 / (p["Ki"] * (tc + theta)), "Ti": 4 * (tc + theta)}
    tc = detune * theta
    return {"Kc": tau / (gain * (tc + theta)), "Ti": min(tau, 4 * (tc + theta))}


def simulate_loop(b, a, pi: dict, dt: float, sp, d, e, *, valve=None) -> dict:
    """The loop, sample by sample from rest: PV_k = B/A x_k + d_k + e_k, the PI in
    velocity form OP_k = OP_{k-1} + Kc (err_k - err_{k-1} + dt/Ti err_k),
    err = SP - PV, and the valve position x_k = valve(OP_k) (OP itself without
    stiction), held until the next sample. Returns op, pv, x (valve) and w = B/A x."""
    b, a = np.asarray(b, float) / a[0], np.asarray(a, float) / a[0]
    n = len(sp)
    op, pv, x, w = (np.zeros(n) for _ in range(4))
    kc, ki = pi["Kc"], pi["Kc"] * dt / pi["Ti"]
    o, err_prev = 0.0, 0.0
    for k in range(n):
        acc = sum(b[j] * x[k - j] for j in range(1, min(len(b), k + 1)))
        acc -= sum(a[j] * w[k - j] for j in range(1, min(len(a), k + 1)))
        w[k] = acc  # b[0] = 0: the valve acts from the next sample on
        pv[k] = acc + d[k] + e[k]
        err = sp[k] - pv[k]
        o = o + kc * (err - err_prev) + ki * err
        err_prev = err
        op[k] = o
        x[k] = valve(o) if valve is not None else o
    return {"op": op, "pv": pv, "x": x, "w": w}


# ----------------------------------------------------------- the record -----


def _setpoint(rng, n: int, step: float) -> np.ndarray:
    """Setpoint changes at random times: holds of 100-600 samples, steps of
    0.5-1.5 x `step` either way (the first hold at the rest value 0)."""
    out, level, filled = [], 0.0, 0
    while filled < n:
        hold = int(rng.integers(100, 601))
        out.append(np.full(hold, level))
        filled += hold
        level += rng.choice((-1.0, 1.0)) * rng.uniform(0.5, 1.5) * step
    return np.concatenate(out)[:n]


def _disturbance(rng, kind: str | None, n: int, lag: float) -> np.ndarray:
    """Unit-RMS load disturbance through the process lag (pole exp(-dt/tau)):
    AR(1) noise (pole 0.8-0.98, `coloured`), integrated white noise (`drift`), or
    none."""
    if kind is None:
        return np.zeros(n)
    white = rng.standard_normal(n)
    if kind == "coloured":
        src = signal.lfilter([1.0], [1.0, -rng.uniform(0.8, 0.98)], white)
    else:
        src = np.cumsum(white)
    dist = signal.lfilter([1.0 - lag], [1.0, -lag], src)
    dist = dist - dist[0]
    return dist / max(_rms(dist), 1e-300)


def _physics(rng, kind: str, dt: float) -> tuple[dict, int]:
    """True process parameters (time constants drawn in samples) and dead time in
    whole samples, 0 up to what keeps the nominal's order within MAX_ORDER."""
    u = rng.uniform
    poles = 1 if kind == "fopdt" else 2
    delay = int(rng.integers(0, MAX_ORDER - poles + 1))
    if kind == "fopdt":
        return {"K": u(0.5, 3.0), "tau": u(10, 60) * dt}, delay
    if kind == "sopdt":
        t1 = u(10, 50) * dt
        return {"K": u(0.5, 3.0), "t1": t1, "t2": u(0.1, 0.5) * t1}, delay
    return {"Ki": u(0.005, 0.05) / dt, "t": u(2, 15) * dt}, delay


def _nominal_tf(kind: str, p: dict, dt: float, delay: int, n: int):
    """The engineer's discrete nominal: the process, an integrator written as a lag
    of INTEGRATOR_LAG_RECORDS records (gain Ki T)."""
    if kind == "integrating":
        T = INTEGRATOR_LAG_RECORDS * n * dt
        p = {"K": p["Ki"] * T, "t1": T, "t2": p["t"]}
        kind = "sopdt"
    return discrete_process(*process_tf(kind, p), dt, delay)


def _stiction(rng, model: str) -> dict:
    """A stiction model's parameters: S in BAND, J 0.1-1 x S (Choudhury); fs and fd
    with the same reversal band fs + fd and fd 0.05-0.45 x it (He)."""
    band = rng.uniform(*BAND)
    if model == "choudhury":
        return {"model": model, "S": band, "J": rng.uniform(0.1, 1.0) * band}
    fd = rng.uniform(0.1, 0.9) * band / 2
    return {"model": model, "fs": band - fd, "fd": fd}


def make_valve(st: dict | None):
    """A fresh stiction model from its truth entry (None: no stiction)."""
    if st is None:
        return None
    if st["model"] == "choudhury":
        return ChoudhuryStiction(st["S"], st["J"])
    return HeStiction(st["fs"], st["fd"])


def make_case(seed: int, index: int, slot: tuple[str, str | None]) -> dict:
    """Case `index` of the seed's loop benchmark for `slot` = (label, stiction
    model or None); a draw whose loop runs away is drawn again from
    `default_rng([seed, index, attempt])`."""
    for attempt in range(50):
        rng = np.random.default_rng([seed, index] + ([attempt] if attempt else []))
        case = _draw(rng, *slot)
        if case is not None:
            return case
    raise RuntimeError(f"loops: no valid {slot} case in 50 draws")  # pragma: no cover


def _draw(rng, label: str, stiction: str | None) -> dict | None:
    kind = PROCESSES[int(rng.integers(len(PROCESSES)))]
    dt = DTS[int(rng.integers(len(DTS)))]
    p, delay = _physics(rng, kind, dt)
    n = int(rng.integers(N_SAMPLES[0], N_SAMPLES[1] + 1))
    b, a = discrete_process(*process_tf(kind, p), dt, delay)
    pi = simc_pi(kind, p, delay, dt, detune=rng.uniform(1.0, 3.0))
    pi["Kc"] *= rng.uniform(0.8, 1.25)  # the detuning an engineer leaves
    step = rng.uniform(1.0, 5.0)  # setpoint step, % of the PV span
    sigma = rng.uniform(0.01, 0.1) * step
    dist = {"coloured_noise": "coloured", "drift": "drift"}.get(label)
    if label == "backlash":
        dist = (None, "coloured", "drift")[int(rng.integers(3))]
    ratio = math.exp(rng.uniform(*np.log(DISTURBANCE_RATIO)))
    lag = math.exp(-dt / (p["tau"] if kind == "fopdt" else p.get("t1", p.get("t"))))
    valve_truth = _stiction(rng, stiction) if stiction is not None else None
    streams = {
        r: (
            _setpoint(rng, n, step),
            _disturbance(rng, dist, n, lag),
            rng.standard_normal(n),
        )
        for r in ("estimation", "validation")
    }

    def run(noise_std):
        out = {}
        for r, (sp, d, e) in streams.items():
            out[r] = simulate_loop(
                b,
                a,
                pi,
                dt,
                sp,
                ratio * noise_std * d,
                noise_std * e,
                valve=make_valve(valve_truth),
            )
        return out

    loops = run(sigma)
    if not all(np.all(np.isfinite(lp["pv"])) for lp in loops.values()):
        return None  # pragma: no cover (SIMC loops are stable)
    if max(np.max(np.abs(lp["op"])) for lp in loops.values()) > 200 * step:
        return None  # a loop that runs away is no routine operating data
    names = list(p)
    errors = draw_errors(rng, names)

    def nominal_gap(scale):  # the nominal against the process, both from the valve
        bn, an = _nominal_tf(kind, perturbed(p, errors, scale), dt, delay, n)
        return max(
            _rms(signal.lfilter(bn, an, lp["x"]) - lp["w"]) for lp in loops.values()
        )

    if label in ("none", "coloured_noise", "drift"):
        scale = min(1.0, rng.uniform(0.0, 0.1) * sigma / max(nominal_gap(1.0), 1e-300))
        for _ in range(30):
            if nominal_gap(scale) <= 0.1 * sigma:
                break
            scale /= 2
        errors = {k: x * scale for k, x in errors.items()}
    gap = nominal_gap(1.0)
    if label == "parameter_mismatch" and gap < 0.3 * sigma:
        sigma = gap / rng.uniform(0.3, 2.0)  # keep the mismatch visible
        loops = run(sigma)
        gap = nominal_gap(1.0)
    bn, an = _nominal_tf(kind, perturbed(p, errors, 1.0), dt, delay, n)
    model = {
        "nonlinearity": {"kind": "identity"},
        "linear": {
            "kind": "discrete_tf",
            "b": [float(x) for x in bn],
            "a": [float(x) for x in an],
            "dt": dt,
        },
    }
    t = np.arange(n) * dt
    records = {r: {"t": t, "v": lp["op"], "y": lp["pv"]} for r, lp in loops.items()}
    truth = {
        "effect": label,
        "stiction": valve_truth,
        "noise_std": float(sigma),
        "process": kind,
        "physics": {k: float(x) for k, x in p.items()},
        "delay_samples": delay,
        "dt": dt,
        "n_samples": n,
        "pi": {k: float(x) for k, x in pi.items()},
        "setpoint_step": float(step),
        "disturbance": dist,
        "disturbance_rms_over_noise": float(ratio) if dist else 0.0,
        "nominal_errors": {k: float(x) for k, x in errors.items()},
        "nominal_gap_over_noise": float(gap / sigma),
        "valve_gap_rms": float(min(_rms(lp["x"] - lp["op"]) for lp in loops.values())),
        "valve_visibility": float(
            min(valve_visibility(b, a, lp) for lp in loops.values())
        ),
    }
    return {"model": model, **records, "truth": truth}


def valve_visibility(b, a, loop: dict) -> float:
    r"""What the valve adds to the PV over all else the process leaves: the RMS of
    $B/A\,x - B/A\,\mathrm{OP}$ (the process driven by the valve position against
    it driven by the command) over that of $\mathrm{PV} - B/A\,x$ (noise and
    disturbance); 0 without stiction. Where it is well below 1 the valve is a
    small part of what even the true process leaves on this record."""
    rest = _rms(loop["pv"] - loop["w"])
    added = _rms(loop["w"] - signal.lfilter(b, a, loop["op"]))
    return added / rest if rest > 0 else math.inf


def slots_for(seed: int, n_cases: int) -> list[tuple[str, str | None]]:
    """Balanced slots: block b of len(SLOTS) cases is a permutation of SLOTS."""
    out: list = []
    for blk in range((n_cases + len(SLOTS) - 1) // len(SLOTS)):
        perm = np.random.default_rng([seed, 2_000_003, blk]).permutation(len(SLOTS))
        out.extend(SLOTS[i] for i in perm)
    return out[:n_cases]


def make_cases(seed: int, n_cases: int, out: Path) -> dict:
    """Write `n_cases` loop case folders under `out/cases/` and `out/truth.json`."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    truth = {
        "family": "loops",
        "seed": int(seed),
        "realism": "closed_loop",
        "cases": {},
    }
    for i, slot in enumerate(slots_for(seed, n_cases)):
        case = make_case(seed, i, slot)
        truth["cases"][write_case(out, i, case)] = case["truth"]
    write_json(out / "truth.json", truth)
    return truth
