"""Issue 7's scipy baseline: a plain NumPy/SciPy sim-to-real gap diagnosis, timed
against `hamjax diagnose` on the same case folders in the same script.

Question: on a given set of gap cases, how often does a careful NumPy/SciPy
implementation of the same idea (fit every catalogue effect together with a re-fit
of the nominal parameters, choose by validation error and BIC) name the right
effect class, how many seconds per case does it take on this machine, and what is
the ratio scipy s/case / hamjax s/case (issue 7 asks for >= 2)?

    hamjax study blind-benchmark --realisations 240 --seed 0 --out results/blind
    python benchmarks/scipy_reference_diagnosis.py --cases results/blind/realistic \
        --out results/scipy-reference [--limit N] [--workers W] [--skip-hamjax]

Writes OUT/scipy_reference.json (accuracy, false alarm on `none`, confusion and median
shrink, scored by `hamjax blind score`'s code,
s/case of both methods and their ratio, machine info, command line) and
OUT/scipy/<case>/diagnosis.json. hamjax runs as one fresh process,
`python -m hamjax diagnose CASES... --out OUT/hamjax`, so its time includes
interpreter start-up, the JAX import and all compilation. The reference runs its
cases in a `ProcessPoolExecutor` with one worker per available core; its time is
the wall clock over all cases including the pool start-up. s/case = wall / cases.

The reference is written as a new user would write it from contracts/gap-case.md,
independent of hamjax's code: `model.json` parsed with `json`, the linear block
simulated with `scipy.signal.lfilter` (continuous blocks discretised with
`scipy.signal.cont2discrete`, ZOH), memory effects (backlash, rate limit) as Python
loops, every fit a `scipy.optimize.least_squares` with finite-difference Jacobians.

Per case:
- `none`: the nominal simulation, nothing fitted.
- `parameter_mismatch`: the re-fittable nominal parameters fitted on estimation
  data (linear denominator and static gain; the six piecewise-linear parameters;
  the input scale of a tabulated/backlash map). An output scale of the map is the
  linear static gain again, so it is not a separate parameter; for a piecewise-linear
  map the linear gain is fixed since k1, k2, l1, l2 already scale the output.
- each structural effect: the nominal model plus the effect (neutral parameters
  reproduce the nominal exactly), effect and nominal parameters fitted together,
  started from the nominal parameters and two effect starts (e.g. saturation limits
  at quantiles of the nominal u; time_delay: integer delays 1..40 screened with the
  nominal, the best two re-fitted; output_nonlinearity: the better of a cubic
  polynomial and a clip of w). A fit ending worse than `parameter_mismatch` (a local
  minimum) is replaced by `parameter_mismatch` with neutral effect parameters.
  dead_zone is not tried in front of a piecewise-linear map (there it is a shift of
  d1, d2, i.e. parameter_mismatch).
- `drift` (random-walk trend, one-step predictor = exponential smoothing of the
  residual, gain fitted) and `coloured_noise` (AR(1) fitted by least squares) on the
  nominal residual, scored by the one-step-ahead prediction error (the contract's
  definition for these two).

Decision (simple, fixed before looking at any result):
1. BIC on estimation data, n log(SSE/n) + k log n. `parameter_mismatch` is admitted
   if its BIC beats `none`'s; a structural effect if its BIC beats both. Among `none`
   and the admitted candidates the lowest validation RMS wins (W).
2. AR(1) and drift models are fitted on W's estimation residual; one whose one-step
   BIC beats white noise's is named instead of W if it lowers W's validation mean
   square more (one-step) than W lowered the nominal's (variance explained by the
   input-independent model > variance explained by the deterministic one).
"""

import os


# One BLAS thread per process: the process pool is the parallelism. (Threaded OpenBLAS
# makes least_squares' SVD of a tall Jacobian ~50x slower when the cores are busy.)
# hamjax's subprocess gets the environment as it was.
_ORIGINAL_ENV = dict(os.environ)
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import shlex  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from concurrent.futures import ProcessPoolExecutor  # noqa: E402
from importlib import metadata  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy import optimize, signal  # noqa: E402


STRUCTURAL = (
    "backlash",
    "dead_zone",
    "saturation",
    "preload",
    "rate_limit",
    "time_delay",
    "extra_pole",
    "output_nonlinearity",
)
NOISE = ("drift", "coloured_noise")
EFFECTS = ("none", "parameter_mismatch", *STRUCTURAL, *NOISE)
MAX_DELAY = 40  # samples screened for time_delay
MAX_NFEV = 200  # function evaluations per least_squares start


class StudyError(Exception):
    """A user mistake (missing folder, malformed file): printed as one line."""


# ----------------------------------------------------------------------------- input


def read_record(path: Path) -> tuple[dict, float]:
    if not path.is_file():
        raise StudyError(f"{path}: file not found")
    with open(path) as f:
        header = [h.strip() for h in f.readline().strip().split(",")]
    if header != ["t", "v", "y"]:
        raise StudyError(f"{path}: header must be t,v,y (got {','.join(header)})")
    try:
        data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, dtype=np.float64)
    except ValueError as e:
        raise StudyError(f"{path}: {e}") from None
    if data.shape[1] != 3 or data.shape[0] < 10:
        raise StudyError(f"{path}: need 3 columns and at least 10 rows")
    if not np.all(np.isfinite(data)):
        raise StudyError(f"{path}: NaN or inf values")
    t, v, y = data.T.copy()
    dt = float(t[1] - t[0])
    if dt <= 0 or not np.allclose(np.diff(t), dt, rtol=1e-6, atol=1e-9 * dt):
        raise StudyError(f"{path}: t is not uniformly increasing")
    return {"v": v, "y": y}, dt


def read_case(folder: Path) -> tuple[dict, dict, float, dict]:
    if not folder.is_dir():
        raise StudyError(f"{folder}: case folder not found")
    est, dt = read_record(folder / "estimation.csv")
    val, dt_v = read_record(folder / "validation.csv")
    if not np.isclose(dt, dt_v, rtol=1e-6):
        raise StudyError(f"{folder}: the two records have different sampling periods")
    path = folder / "model.json"
    if not path.is_file():
        raise StudyError(f"{path}: not found (the reference needs a nominal model)")
    try:
        model = json.loads(path.read_text())
    except json.JSONDecodeError as e:
        raise StudyError(f"{path}: invalid JSON ({e})") from None
    return est, val, dt, model


# ----------------------------------------------------------------- model pieces


def play(v: np.ndarray, c: float) -> np.ndarray:
    """Backlash (play operator) of total width c, starting centred at v[0]."""
    out = []
    u = float(v[0])
    half = 0.5 * float(c)
    for vk in v.tolist():  # Python floats: much faster than indexing numpy arrays
        if vk - half > u:
            u = vk - half
        elif vk + half < u:
            u = vk + half
        out.append(u)
    return np.array(out)


def rate_limit(v: np.ndarray, step: float) -> np.ndarray:
    """v' follows v with |v'[k] - v'[k-1]| <= step (= r dt), v'[0] = v[0]."""
    out = []
    x = float(v[0])
    step = float(step)
    for vk in v.tolist():
        if vk - x > step:
            x += step
        elif vk - x < -step:
            x -= step
        else:
            x = vk
        out.append(x)
    return np.array(out)


def delay(v: np.ndarray, d: int) -> np.ndarray:
    if d <= 0:
        return v
    return np.concatenate([np.full(d, v[0]), v[:-d]])


def tabulated_backlash(v, grid, asc, desc):
    """Backlash with tabulated borders (contract kind "backlash"), u0 centred."""
    out = np.empty_like(v)
    fa, fd = np.interp(v, grid, asc).tolist(), np.interp(v, grid, desc).tolist()
    u = 0.5 * (fa[0] + fd[0])
    on_a, on_d = u == fa[0], u == fd[0]
    v = v.tolist()
    v_prev = v[0]
    for k in range(len(v)):
        rising, falling = v[k] > v_prev, v[k] < v_prev
        if rising or falling:
            take_a = rising and (on_a or fa[k] >= u)
            take_d = falling and (on_d or fd[k] <= u)
            if take_a:
                u = fa[k]
            elif take_d:
                u = fd[k]
            on_a, on_d = take_a or u == fa[k], take_d or u == fd[k]
        v_prev = v[k]
        out[k] = u
    return out


class Plant:
    """The nominal model of model.json and its re-fittable parameter vector theta."""

    def __init__(self, model: dict, dt: float):
        try:
            nl, lin = model["nonlinearity"], model["linear"]
            self.nl_kind, self.lin_kind = nl["kind"], lin["kind"]
            self.dt = dt
            lower, upper = [], []
            if self.nl_kind == "identity":
                nl0 = []
            elif self.nl_kind == "piecewise_linear":
                nl0 = [float(nl[k]) for k in ("k1", "k2", "d1", "d2", "l1", "l2")]
                lower = [-np.inf, -np.inf, 0.0, -np.inf, -np.inf, -np.inf]
                upper = [np.inf, np.inf, np.inf, 0.0, np.inf, np.inf]
            elif self.nl_kind in ("tabulated", "backlash"):
                self.grid = np.asarray(nl["v"], dtype=np.float64)
                if self.nl_kind == "tabulated":
                    self.table = np.asarray(nl["u"], dtype=np.float64)
                else:
                    self.asc = np.asarray(nl["ascending"], dtype=np.float64)
                    self.desc = np.asarray(nl["descending"], dtype=np.float64)
                nl0, lower, upper = [1.0], [1e-6], [np.inf]  # input scale
            else:
                raise StudyError(f"unknown nonlinearity kind {self.nl_kind!r}")
            if self.lin_kind == "discrete_tf":
                num = np.asarray(lin["b"], dtype=np.float64)
                den = np.asarray(lin["a"], dtype=np.float64)
                if not np.isclose(float(lin["dt"]), dt, rtol=1e-6):
                    raise StudyError(
                        f"model dt {lin['dt']} differs from the data's {dt}"
                    )
            elif self.lin_kind == "continuous_tf":
                num = np.asarray(lin["num"], dtype=np.float64)
                den = np.asarray(lin["den"], dtype=np.float64)
            else:
                raise StudyError(f"unknown linear kind {self.lin_kind!r}")
        except (KeyError, TypeError, ValueError) as e:
            raise StudyError(f"model.json: malformed ({e!r})") from None
        self.num, self.den = num / den[0], den / den[0]
        self.gain_free = self.nl_kind != "piecewise_linear"
        lin0 = ([1.0] if self.gain_free else []) + list(self.den[1:])
        self.n_nl = len(nl0)
        self.theta0 = np.array(nl0 + lin0, dtype=np.float64)
        n_lin = len(lin0)
        self.lower = np.array(lower + [-np.inf] * n_lin)
        self.upper = np.array(upper + [np.inf] * n_lin)
        self.max_radius = max(1.0, self._radius(self.discrete(self.theta0)[1]))
        self.w_scale = 1.0  # set per case: output_nonlinearity's normalisation

    @staticmethod
    def _radius(a):
        return float(np.max(np.abs(np.roots(a)))) if len(a) > 1 else 0.0

    def static(self, theta: np.ndarray, v: np.ndarray) -> np.ndarray:
        p = theta[: self.n_nl]
        if self.nl_kind == "identity":
            return v
        if self.nl_kind == "piecewise_linear":
            k1, k2, d1, d2, l1, l2 = p
            return np.where(
                v > d1, k1 * (v - d1) + l1, np.where(v < d2, k2 * (v - d2) + l2, 0.0)
            )
        if self.nl_kind == "tabulated":
            return np.interp(p[0] * v, self.grid, self.table)
        return tabulated_backlash(p[0] * v, self.grid, self.asc, self.desc)

    def discrete(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        p = theta[self.n_nl :]
        g = p[0] if self.gain_free else 1.0
        den = np.concatenate([[1.0], p[1:] if self.gain_free else p])
        if self.lin_kind == "discrete_tf":
            return g * self.num, den
        b, a, _ = signal.cont2discrete((g * self.num, den), self.dt, method="zoh")
        return np.ravel(b), np.asarray(a)

    def simulate(self, theta, v, effect="none", p=()):
        """y of nominal(theta) + effect(p); None if the linear block is unstable."""
        if effect == "dead_zone":
            v = np.sign(v) * np.maximum(np.abs(v) - p[0], 0.0)
        elif effect == "backlash":
            v = play(v, p[0])
        elif effect == "rate_limit":
            v = rate_limit(v, p[0] * self.dt)
        elif effect == "time_delay":
            v = delay(v, int(p[0]))
        u = self.static(theta, v)
        if effect == "saturation":
            u = np.minimum(np.maximum(u, p[0]), p[1])
        elif effect == "preload":
            u = u + p[0] * np.sign(v)
        b, a = self.discrete(theta)
        if self._radius(a) > self.max_radius + 1e-9:
            return None
        w = signal.lfilter(b, a, u)
        if effect == "extra_pole":
            w = signal.lfilter([1.0 - p[0]], [1.0, -p[0]], w)
        elif effect == "output_cubic":
            s = self.w_scale
            w = w + p[0] * s * (w / s) ** 2 + p[1] * s * (w / s) ** 3
        elif effect == "output_clip":
            w = np.minimum(np.maximum(w, p[0]), p[1])
        return w


# ---------------------------------------------------------------------- fitting


def fit(plant, v, y, effect, theta0, p_starts, p_lo, p_hi, fixed=()):
    """least_squares of y - simulate over (theta, p) from each start; the best."""
    n_th = len(theta0)
    lo = np.concatenate([plant.lower, p_lo])
    hi = np.concatenate([plant.upper, p_hi])
    big = np.full(len(y), 1e3 * (np.std(y) + 1.0))

    def residual(x):
        try:  # a trial point the simulator cannot take is a bad point, not a crash
            ys = plant.simulate(x[:n_th], v, effect, np.concatenate([x[n_th:], fixed]))
        except (np.linalg.LinAlgError, ValueError):
            ys = None
        if ys is None or not np.all(np.isfinite(ys)):
            return big
        return ys - y

    best = None
    for p0 in p_starts:
        x0 = np.clip(np.concatenate([theta0, p0]), lo, hi)
        r = optimize.least_squares(
            residual, x0, bounds=(lo, hi), x_scale="jac", max_nfev=MAX_NFEV
        )
        if best is None or r.cost < best.cost:
            best = r
    return best.x[:n_th], np.concatenate([best.x[n_th:], fixed]), 2.0 * best.cost


def smoother_error(r, gain):
    """One-step error of the random-walk-trend predictor (exponential smoothing)."""
    return r - signal.lfilter([0.0, gain], [1.0, gain - 1.0], r)


def ar1_error(r, a):
    return np.concatenate([r[:1], r[1:] - a * r[:-1]])


def fit_noise(r_est):
    """Drift and AR(1) models of a residual: {name: (param, estimation error fn)}."""
    a = float(
        np.dot(r_est[1:], r_est[:-1]) / max(np.dot(r_est[:-1], r_est[:-1]), 1e-300)
    )
    res = optimize.minimize_scalar(
        lambda g: np.sum(smoother_error(r_est, g) ** 2),
        bounds=(0.0, 1.0),
        method="bounded",
    )
    return {
        "drift": (
            {"gain": float(res.x)},
            lambda r, g=float(res.x): smoother_error(r, g),
        ),
        "coloured_noise": ({"pole": a}, lambda r, a=a: ar1_error(r, a)),
    }


def bic(sse, n, k):
    return n * np.log(max(sse, 1e-300) / n) + k * np.log(n)


def finite(x):
    """A float for JSON; None for inf/NaN (e.g. a saturation limit at infinity)."""
    return float(x) if np.isfinite(x) else None


def rms(x):
    return float(np.sqrt(np.mean(x**2)))


def effect_setup(effect, v, u, w, dt):
    """Starts and bounds of an effect's parameters (from the estimation data)."""
    inf = np.inf
    if effect == "backlash":
        s = np.ptp(v)
        return [[0.05 * s], [0.2 * s]], [0.0], [s]
    if effect == "dead_zone":
        s = np.max(np.abs(v))
        return [[0.05 * s], [0.2 * s]], [0.0], [s]
    if effect == "saturation":
        q = np.quantile(u, [0.02, 0.98, 0.1, 0.9])
        return [[q[0], q[1]], [q[2], q[3]]], [-inf, -inf], [inf, inf]
    if effect == "preload":
        s = np.std(u)
        return [[0.05 * s], [0.2 * s]], [0.0], [inf]
    if effect == "rate_limit":
        rmax = max(np.max(np.abs(np.diff(v))) / dt, 1e-12)
        return [[0.3 * rmax], [0.05 * rmax]], [1e-6 * rmax], [inf]
    if effect == "extra_pole":
        return [[0.3], [0.8]], [0.0], [0.999]
    if effect == "output_cubic":
        return [[0.0, 0.0]], [-inf, -inf], [inf, inf]
    if effect == "output_clip":
        q = np.quantile(w, [0.02, 0.98])
        return [[q[0], q[1]]], [-inf, -inf], [inf, inf]
    raise ValueError(effect)


def neutral(effect, p):
    """Effect parameters that reproduce the nominal model exactly."""
    if effect in ("saturation", "output_clip"):
        return np.array([-np.inf, np.inf])
    if effect == "rate_limit":
        return np.array([np.inf])
    return np.zeros_like(p)


PARAM_NAMES = {
    "backlash": ["c"],
    "dead_zone": ["w"],
    "saturation": ["u_lo", "u_hi"],
    "preload": ["c"],
    "rate_limit": ["r"],
    "time_delay": ["tau_samples"],
    "extra_pole": ["p"],
    "output_cubic": ["a2", "a3"],
    "output_clip": ["w_lo", "w_hi"],
}


def diagnose(est: dict, val: dict, dt: float, model: dict) -> dict:
    plant = Plant(model, dt)
    ve, ye, vv, yv = est["v"], est["y"], val["v"], val["y"]
    n = len(ye)
    th0 = plant.theta0
    y0e, y0v = plant.simulate(th0, ve), plant.simulate(th0, vv)
    if y0e is None or y0v is None:
        raise StudyError("nominal model is unstable")
    plant.w_scale = max(float(np.max(np.abs(y0e))), 1e-12)
    gap_before = rms(yv - y0v)
    cands = {
        "none": dict(theta=th0, p=np.array([]), sse=float(np.sum((ye - y0e) ** 2)), k=0)
    }
    no_p = (np.zeros(0), np.zeros(0))
    th_pm, _, sse = fit(plant, ve, ye, "none", th0, [[]], *no_p)
    n_th = len(th0)
    cands["parameter_mismatch"] = dict(theta=th_pm, p=np.array([]), sse=sse, k=n_th)
    # structural fits start from the nominal model (neutral effect = nominal)
    u0e = plant.static(th0, ve)
    for eff in STRUCTURAL:
        if eff == "dead_zone" and plant.nl_kind == "piecewise_linear":
            continue
        if eff == "time_delay":
            dmax = max(1, min(MAX_DELAY, n // 20))
            sses = []
            for d in range(1, dmax + 1):
                ys = plant.simulate(th0, ve, "time_delay", [d])
                sses.append(np.sum((ys - ye) ** 2))
            best = None
            for d in np.argsort(sses)[:2] + 1:
                th, p, sse = fit(plant, ve, ye, eff, th0, [[]], *no_p, fixed=[float(d)])
                if best is None or sse < best[2]:
                    best = (th, p, sse, eff)
        elif eff == "output_nonlinearity":
            best = None
            for sub in ("output_cubic", "output_clip"):
                starts, lo, hi = effect_setup(sub, ve, u0e, y0e, dt)
                th, p, sse = fit(plant, ve, ye, sub, th0, starts, lo, hi)
                if best is None or sse < best[2]:
                    best = (th, p, sse, sub)
        else:
            starts, lo, hi = effect_setup(eff, ve, u0e, y0e, dt)
            best = (*fit(plant, ve, ye, eff, th0, starts, lo, hi), eff)
        th, p, sse, sim_as = best
        if sse > cands["parameter_mismatch"]["sse"]:  # stuck in a worse local minimum
            th, p, sse = th_pm, neutral(sim_as, p), cands["parameter_mismatch"]["sse"]
        cands[eff] = dict(theta=th, p=p, sse=sse, k=n_th + len(p), sim_as=sim_as)

    # validation simulation error and BIC of each deterministic candidate
    for c in cands.values():
        sim_as = c.get("sim_as", "none")
        ys = plant.simulate(c["theta"], vv, sim_as, c["p"])
        c["val"] = rms(yv - ys) if ys is not None else np.inf
        c["bic"] = bic(c["sse"], n, c["k"])
        names = PARAM_NAMES.get(sim_as, [])
        c["params"] = {nm: finite(x) for nm, x in zip(names, c["p"], strict=True)}
        if sim_as.startswith("output_"):
            c["params"]["shape"] = sim_as.removeprefix("output_")
        c["params"]["nominal"] = [float(x) for x in c["theta"]]

    # step 1: BIC gates, then the lowest validation RMS
    bic_none, bic_pm = cands["none"]["bic"], cands["parameter_mismatch"]["bic"]
    cands["none"]["admitted"] = True
    cands["parameter_mismatch"]["admitted"] = bool(bic_pm < bic_none)
    for eff in STRUCTURAL:
        if eff in cands:
            cands[eff]["admitted"] = bool(cands[eff]["bic"] < min(bic_pm, bic_none))
    winner = min(
        (nm for nm, c in cands.items() if c["admitted"]),
        key=lambda nm: cands[nm]["val"],
    )
    wc = cands[winner]

    # noise candidates on the nominal residual (their ranking entries, contract's gap)
    r0e, r0v = ye - y0e, yv - y0v
    for name, (params, err) in fit_noise(r0e).items():
        cands[name] = dict(
            val=rms(err(r0v)), bic=bic(np.sum(err(r0e) ** 2), n, 1), params=params, k=1
        )
    # step 2: input-independent explanation of the winner's residual?
    ys_we = plant.simulate(wc["theta"], ve, wc.get("sim_as", "none"), wc["p"])
    ys_wv = plant.simulate(wc["theta"], vv, wc.get("sim_as", "none"), wc["p"])
    rwe, rwv = ye - ys_we, yv - ys_wv
    det_gain = gap_before**2 - wc["val"] ** 2
    named, best_gain = winner, det_gain
    for name, (_, err) in fit_noise(rwe).items():
        admitted = bic(np.sum(err(rwe) ** 2), n, 1) < bic(np.sum(rwe**2), n, 0)
        gain = wc["val"] ** 2 - rms(err(rwv)) ** 2
        cands[name]["admitted"] = bool(admitted and gain > 0)
        if admitted and gain > best_gain:
            named, best_gain = name, gain

    ranking = sorted(cands, key=lambda nm: (nm != named, cands[nm]["val"]))
    return {
        "effect": named,
        "gap_before": gap_before,
        "gap_after": cands[named]["val"],
        "gap_definition": (
            "one-step-ahead prediction error"
            if named in NOISE
            else "simulation error of the fitted model"
        ),
        "noise_floor": rms(rwe),
        "ranking": [
            {
                "effect": nm,
                "gap_after": finite(cands[nm]["val"]),
                "bic": finite(cands[nm]["bic"]),
                "admitted": cands[nm]["admitted"],
                "params": cands[nm]["params"],
            }
            for nm in ranking
        ],
    }


def run_case(folder: str, out_dir: str) -> tuple[str, dict | None, str | None]:
    """Worker: diagnose one case folder and write OUT/<case>/diagnosis.json;
    returns (case name, diagnosis or None, error or None)."""
    folder = Path(folder)
    try:
        result = diagnose(*read_case(folder))
    except StudyError as e:
        return folder.name, None, f"{folder.name}: {e}"
    dest = Path(out_dir) / folder.name
    dest.mkdir(parents=True, exist_ok=True)
    (dest / "diagnosis.json").write_text(json.dumps(result, indent=1))
    return folder.name, result, None


# ------------------------------------------------------------------------ study


def score(diagnoses: dict, truth: dict) -> dict | None:
    """`hamjax blind score`'s scoring of {case: diagnosis} (None without truth.json).
    Scoring is study plumbing, not part of the reference, so it is hamjax's: both
    methods are scored by the same code as the blind benchmark."""
    if not truth:
        return None
    from hamjax.papers.gap.blind import score as blind_score

    named = {nm: d["effect"] for nm, d in diagnoses.items()}
    gaps = {nm: (d["gap_before"], d["gap_after"]) for nm, d in diagnoses.items()}
    cases = {nm: truth[nm] for nm in named if nm in truth}
    return blind_score({"cases": cases}, named, gaps)


def run_hamjax(folders: list[Path], out: Path) -> tuple[dict, float]:
    cmd = [
        sys.executable,
        "-m",
        "hamjax",
        "diagnose",
        *map(str, folders),
        "--out",
        str(out),
        "--quiet",
    ]
    t0 = time.perf_counter()
    # Compilation always included: hamjax's on-disk compilation cache is switched
    # off, so the figure does not depend on what earlier runs left behind.
    env = {**_ORIGINAL_ENV, "HAMJAX_CACHE_DIR": "off"}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        last = (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
        raise StudyError(f"hamjax diagnose failed (exit {proc.returncode}): {last}")
    single = len(folders) == 1
    return {
        f.name: json.loads(
            (out if single else out / f.name).joinpath("diagnosis.json").read_text()
        )
        for f in folders
    }, wall


def machine_info(workers: int) -> dict:
    from hamjax.montecarlo.storage import package_versions

    cpu = platform.processor()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cores_available": len(os.sched_getaffinity(0)),
        "workers": workers,
        "cpu": cpu,
        "platform": platform.platform(),
        "versions": package_versions() | {"scipy": metadata.version("scipy")},
    }


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", required=True, help="folder with cases/ and truth.json")
    ap.add_argument("--limit", type=int, default=None, help="first N cases only")
    ap.add_argument("--out", default="results/scipy-reference")
    ap.add_argument(
        "--workers", type=int, default=None, help="default: available cores"
    )
    ap.add_argument("--skip-hamjax", action="store_true")
    return ap.parse_args(argv)


def study(args, command: list[str]) -> int:
    root = Path(args.cases)
    case_root = root / "cases"
    if not case_root.is_dir():
        raise StudyError(f"{case_root}: not found (expected DIR/cases/<case>/)")
    folders = sorted(p for p in case_root.iterdir() if p.is_dir())
    if args.limit is not None:
        if args.limit < 1:
            raise StudyError("--limit must be >= 1")
        folders = folders[: args.limit]
    if not folders:
        raise StudyError(f"{case_root}: no case folders")
    for f in folders:
        for name in ("estimation.csv", "validation.csv", "model.json"):
            if not (f / name).is_file():
                raise StudyError(f"{f / name}: not found")
    truth_path = root / "truth.json"
    truth = json.loads(truth_path.read_text())["cases"] if truth_path.is_file() else {}
    workers = args.workers or len(os.sched_getaffinity(0))
    if workers < 1:
        raise StudyError("--workers must be >= 1")
    out = Path(args.out)
    scipy_out = out / "scipy"
    scipy_out.mkdir(parents=True, exist_ok=True)

    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        done = list(
            pool.map(run_case, map(str, folders), [str(scipy_out)] * len(folders))
        )
    wall_scipy = time.perf_counter() - t0
    errors = [e for _, _, e in done if e]
    if errors:
        raise StudyError(
            errors[0] + (f" (and {len(errors) - 1} more)" if len(errors) > 1 else "")
        )
    diagnoses = {name: d for name, d, _ in done}
    n = len(folders)
    summary = {
        "question": "accuracy and s/case of a careful scipy diagnosis vs hamjax diagnose",
        "command": shlex.join(command),
        "cases_dir": str(root.resolve()),
        "n_cases": n,
        "machine": machine_info(workers),
        "scipy": {
            "wall_s": wall_scipy,
            "s_per_case": wall_scipy / n,
            **(score(diagnoses, truth) or {}),
        },
        "hamjax": None,
        "ratio_scipy_over_hamjax_s_per_case": None,
        "timing_note": "hamjax: one fresh process (start-up, JAX import, compilation "
        "included, its compilation cache off); scipy: ProcessPoolExecutor wall clock over all cases",
    }
    if not args.skip_hamjax:
        diagnoses_h, wall_h = run_hamjax(folders, out / "hamjax")
        summary["hamjax"] = {
            "wall_s": wall_h,
            "s_per_case": wall_h / n,
            **(score(diagnoses_h, truth) or {}),
        }
        summary["ratio_scipy_over_hamjax_s_per_case"] = wall_scipy / wall_h
    (out / "scipy_reference.json").write_text(json.dumps(summary, indent=1))

    print(f"{n} cases from {root}, {workers} workers")
    print(f"{'method':<18}{'accuracy':>10}{'false alarm':>13}{'s/case':>9}")
    for label, key in (("scipy reference", "scipy"), ("hamjax diagnose", "hamjax")):
        s = summary[key]
        if s is None:
            continue
        acc, fa = s.get("accuracy"), s.get("false_alarm_none")
        acc = "-" if acc is None else f"{acc:.3f}"
        fa = "-" if fa is None else f"{fa:.3f}"
        print(f"{label:<18}{acc:>10}{fa:>13}{s['s_per_case']:>9.3f}")
    if summary["ratio_scipy_over_hamjax_s_per_case"] is not None:
        print(
            f"ratio scipy/hamjax s/case: {summary['ratio_scipy_over_hamjax_s_per_case']:.2f}"
        )
    print(f"wrote {out / 'scipy_reference.json'}")
    return 0


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    command = [sys.executable, *sys.argv] if argv is None else [__file__, *argv]
    try:
        return study(args, command)
    except StudyError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
