"""Fit the constants of `hamjax.diagnosis.probabilities` on one case family and
report their calibration on another that was never used to choose them.

    python benchmarks/fit_probability_calibration.py \\
        --train A0=SETS/realistic_seed0:RESULTS/A0 --train ... \\
        --held-out B0=SETS/B0:RESULTS/B0 --held-out ... --out calibration.json

Each `NAME=SET:RESULTS` pairs a blind set (`hamjax blind make`: `truth.json`,
`cases/`) with the folder `hamjax diagnose SET/cases/* --out RESULTS` wrote.
From each `diagnosis.json` it reads the named effect and, from `tests.evidence`,
every class's validation mean square that `probabilities` read (`mse`; named a
noise model, the deterministic candidates seen through its predictor) and the
evidence's effective sample size, so the features are exactly those of
`probabilities.evidence` and `probabilities.verdict_kind`. (A diagnosis written
before `mse` was recorded gives the ranked gaps and `gap_before` instead.)

Fitted on the training sets only, by maximum likelihood with a 1e-3 ridge:
the slope of the evidence and one offset per verdict kind (whether the named
effect is right), and the temperature of the rivals' shares (the likelihood of
the true class among the rivals of the wrong verdicts, on a grid). Printed: the
constants, and on every set the expected calibration error (10 bins) with the
mean confidence and the accuracy.
"""

import argparse
import json
import math
from pathlib import Path

import numpy as np
from scipy.optimize import minimize

from hamjax.diagnosis.probabilities import KINDS, evidence, verdict_kind
from hamjax.papers.gap.blind import calibration


def _pair(text: str) -> tuple[str, Path, Path]:
    name, _, rest = text.partition("=")
    cases, _, results = rest.partition(":")
    if not (name and cases and results):
        raise argparse.ArgumentTypeError(f"expected NAME=SET:RESULTS, got {text!r}")
    return name, Path(cases), Path(results)


def _square(gap: float) -> float:
    """A gap squared; a diverged candidate (written as 1e308) is infinite."""
    return gap * gap if gap < 1e150 else math.inf


def load(cases: Path, results: Path) -> list[dict]:
    """One row per diagnosed case: truth, named effect, MSE per class, n_eff."""
    truth = json.loads((cases / "truth.json").read_text())["cases"]
    rows = []
    for name, t in sorted(truth.items()):
        path = results / name / "diagnosis.json"
        if not path.is_file():
            continue
        d = json.loads(path.read_text())
        ev = d["tests"]["evidence"]
        if "mse" in ev:  # what `probabilities` read (null: infinite)
            mse = {k: math.inf if v is None else v for k, v in ev["mse"].items()}
        else:  # a diagnosis written before 2026-12-06: the ranked gaps
            mse = {"none": _square(d["gap_before"])}
            for c in d["ranking"]:
                mse[c["effect"]] = min(
                    mse.get(c["effect"], math.inf), _square(c["gap_after"])
                )
        rows.append(
            {
                "truth": t["effect"],
                "named": d["effect"],
                "mse": mse,
                "n": float(ev["effective_samples"]),
                "stated": float(d["probabilities"][d["effect"]]),
            }
        )
    return rows


def _features(rows):
    kept = [r for r in rows if r["named"] in r["mse"] and len(r["mse"]) > 1]
    x = np.array([evidence(r["named"], r["mse"], r["n"]) for r in kept])
    g = np.array([[verdict_kind(r["named"]) == k for k in KINDS] for r in kept], float)
    y = np.array([r["named"] == r["truth"] for r in kept], float)
    return x, g, y


def fit_named(rows) -> np.ndarray:
    """`[slope, offset per KINDS]` by ridge-penalised maximum likelihood."""
    x, g, y = _features(rows)

    def nll(th):
        z = th[0] * x + g @ th[1:]
        return float(np.sum(np.logaddexp(0.0, z) - y * z) + 1e-3 * th @ th)

    return minimize(nll, np.zeros(1 + len(KINDS)), method="BFGS").x


TEMPERATURES = np.geomspace(10.0, 1e5, 41)


def fit_temperature(rows, grid=TEMPERATURES) -> float:
    """The temperature maximising the likelihood of the true class among the
    rivals of the wrong verdicts (shares proportional to exp(-n log m / 2T))."""
    wrong = [r for r in rows if r["named"] != r["truth"] and r["truth"] in r["mse"]]

    def ll(temp):
        total = 0.0
        for r in wrong:
            rivals = [k for k in r["mse"] if k != r["named"]]
            s = np.array(
                [-0.5 * r["n"] * math.log(max(r["mse"][k], 1e-300)) for k in rivals]
            )
            s = s / temp
            total += s[rivals.index(r["truth"])] - np.logaddexp.reduce(s)
        return total

    return float(max(grid, key=ll))


def report(rows, th) -> dict:
    x, g, y = _features(rows)
    c = 1.0 / (1.0 + np.exp(-(th[0] * x + g @ th[1:])))
    cal = calibration(list(c), list(y.astype(bool)))
    stated = calibration(
        [r["stated"] for r in rows], [r["named"] == r["truth"] for r in rows]
    )
    return {
        "cases": len(rows),
        "accuracy": float(y.mean()),
        "mean_confidence": float(c.mean()),
        "ece": cal["ece"],
        "ece_as_diagnosed": stated["ece"],
    }


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--train", type=_pair, action="append", required=True)
    p.add_argument("--held-out", type=_pair, action="append", default=[])
    p.add_argument("--out", type=Path)
    args = p.parse_args(argv)
    train = {n: load(c, r) for n, c, r in args.train}
    held = {n: load(c, r) for n, c, r in args.held_out}
    pooled = [r for rows in train.values() for r in rows]
    th = fit_named(pooled)
    temp = fit_temperature(pooled)
    out = {
        "alpha": float(th[0]),
        "beta": dict(zip(KINDS, map(float, th[1:]), strict=True)),
        "temperature": temp,
        "train": {n: report(rows, th) for n, rows in train.items()}
        | {"pooled": report(pooled, th)},
        "held_out": {n: report(rows, th) for n, rows in held.items()},
    }
    if held:
        out["held_out"]["pooled"] = report([r for v in held.values() for r in v], th)
    print(json.dumps(out, indent=1))
    if args.out is not None:
        args.out.write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
