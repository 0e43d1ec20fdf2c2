"""What the stiction fits would gain from the truth: the loop benchmark's sticky
loops diagnosed again with parts of the truth handed to the fits.

    python benchmarks/loop_recall_oracles.py --seeds 1 2 --out results/oracles

For each seed, the sticky loops of `hamjax blind make --family loops --cases N
--seed S` (`papers.gap.control_loops`, the same draws) are diagnosed without
model.json, as `loop_recall_bound.py` does, once per mode (each in its own
process, since a mode replaces functions that the fits compile):

- `base`: the diagnosis as it is;
- `grid`: the stick-slip profile's grid cut to the one true point $(f_s, f_d)$
  of each loop (`layout.STATIC_BAND_GRID`, `KINETIC_RATIOS`);
- `start`: every valve, in the fits and the profile, starts at rest at 0, as the
  benchmark's valves do (`augmented.memory_init`, `layout._valve_init`), not at
  the first command (the contract's convention);
- `start_grid`: both;
- `start_grid_process`: both, and the profile's first start is the true valve
  with the true process as its re-fitted linear block, where the
  `REFIT_LINEAR` row can hold it (its numerator's lags and its order).

Per mode: how many sticky loops are named stiction-like (backlash, dead zone,
preload or friction), and the backlash class's best row (lowest estimation SSE,
as the rule takes it) against the true valve and process: the ratios of their
RMS errors on the estimation and on the validation record (the truth from rest,
as the benchmark ran it). Written: `loop_recall_oracles.json`. No timing;
about 1.5 minutes a seed and mode on 2 cores.

Each mode replaces module attributes of the installed hamjax in its own
process (a what-if, not an API): nothing of it reaches a diagnosis elsewhere.
"""

import argparse
import hashlib
import json
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
from decision_replay import diagnose_captured, loop_cases
from loop_recall_bound import true_process
from scipy import signal


MODES = ("base", "grid", "start", "start_grid", "start_grid_process")


def _key(v) -> str:
    return hashlib.sha1(np.asarray(v, float).tobytes()).hexdigest()


def _valve_truth(st: dict) -> tuple[float, float, float, float, str]:
    """`(f_s, f_d, S, J, slot)`: the valve's bands and hamjax's parameters of it."""
    if st["model"] == "choudhury":
        S, J = st["S"], st["J"]
        return (S + J) / 2, (S - J) / 2, S, J, "slide_jump"
    fs, fd = st["fs"], st["fd"]
    return fs, fd, fs + fd, fs - fd, "slip_jump"


def _patch(mode: str, truths: dict) -> None:
    """Replace the parts of hamjax that `mode` hands the truth to."""
    import jax.numpy as jnp

    from hamjax.diagnosis import augmented, fit, layout
    from hamjax.diagnosis.effects._base import REFIT_LINEAR
    from hamjax.diagnosis.effects.backlash import slide_init

    profile = layout.stick_slip_profile
    lock = threading.Lock()  # the cases are prepared on threads

    def on_true_point(nom, linear, dt, v, y, length, **kw):
        fs, fd, *_ = _valve_truth(truths[_key(v)]["stiction"])
        vr = float(max(np.ptp(v), 1e-12))
        with lock:
            grid = layout.STATIC_BAND_GRID, layout.KINETIC_RATIOS
            layout.STATIC_BAND_GRID, layout.KINETIC_RATIOS = (fs / vr,), (fd / fs,)
            try:
                return profile(nom, linear, dt, v, y, length, **kw)
            finally:
                layout.STATIC_BAND_GRID, layout.KINETIC_RATIOS = grid

    def with_true_process(nom, linear, dt, v, y, length, **kw):
        found = on_true_point(nom, linear, dt, v, y, length, **kw)
        truth = truths[_key(v)]
        b, a = true_process(truth)
        *_, S, J, slot = _valve_truth(truth["stiction"])
        b_nom, _ = layout._discrete_tf(linear, dt)
        order = layout.refit_linear_order(nom)
        lags = layout._numerator_lags(b_nom, order)
        if not (
            set(np.flatnonzero(np.abs(b) > 1e-14)) <= set(lags.tolist())
            and a.shape[0] - 1 <= order
            and kw.get("refit_linear")
        ):
            return found  # the row cannot hold the true process
        full = np.zeros(int(lags[-1]) + 1)
        held = np.zeros_like(full)
        full[: b.shape[0]] = b
        held[: min(b_nom.shape[0], held.shape[0])] = b_nom[: held.shape[0]]
        start = {
            REFIT_LINEAR: 1.0,
            **{f"den{j}": float(a[j]) for j in range(1, a.shape[0])},
            **{f"db{j}": float(full[j] - held[j]) for j in lags},
            "out_off": 0.0,
        }
        return ((float(S), float(J), start, slot), *found[1:])

    if "grid" in mode:
        layout.stick_slip_profile = on_true_point
    if "process" in mode:
        layout.stick_slip_profile = with_true_process
    if "start" in mode:

        def at_rest(v0, p, case):
            zero = jnp.zeros_like(v0)
            nominal = augmented.memory_arguments(p, case)[-1]
            return (v0, zero, slide_init(zero), nominal.init(v0))

        def valve_at_rest(v0, width, start=None):  # the fitted start ignored
            zero = jnp.zeros(width.shape)
            return v0, zero, slide_init(zero)

        augmented.memory_init = fit.memory_init = at_rest
        layout._valve_init = valve_at_rest


def _one(seed: int, n_cases: int, mode: str) -> dict:
    """Diagnose the seed's sticky loops under `mode`; the figures of `main`."""
    import hamjax
    from hamjax._runtime import same_rounding_in_every_lane, split_cpu_into_devices

    split_cpu_into_devices()
    same_rounding_in_every_lane()  # as `hamjax` runs
    hamjax.enable_x64()
    from hamjax.diagnosis import attribute as at
    from hamjax.diagnosis.layout import finite_sse, validation_sse
    from hamjax.diagnosis.probabilities import STICTION_LIKE
    from hamjax.papers.gap import control_loops as cl

    cases = loop_cases(seed, n_cases, sticky_only=True)
    _patch(mode, {_key(c["estimation"]["v"]): c["truth"] for c in cases.values()})
    ratios, names = [], []
    for truth, prep, fit, name in diagnose_captured(list(cases.values())):
        b, a = true_process(truth)
        rows = at.best_row_per_class(prep, finite_sse(fit), validation_sse(prep, fit))
        row = rows["backlash"]
        out = []
        for rec, n in (("est", prep.n_est), ("val", prep.n_val)):
            v = np.asarray(getattr(prep.arrays, f"v_{rec}"))[:n]
            y = np.asarray(getattr(prep.arrays, f"y_{rec}"))[:n]
            x = cl.valve_positions(cl.make_valve(truth["stiction"]), v)
            true = at.rms(y - signal.lfilter(b, a, x))
            fitted = at.rms(y - np.asarray(fit[f"y_{rec}"][row])[:n])
            out.append(fitted / true)
        ratios.append(out)
        names.append(name)
    r = np.array(ratios)
    return {
        "sticky_loops": len(cases),
        "named_stiction_like": sum(n in STICTION_LIKE for n in names),
        "backlash_over_truth_rms_median": {
            "estimation": float(np.median(r[:, 0])),
            "validation": float(np.median(r[:, 1])),
        },
        "backlash_within_10_percent_of_truth": {
            "estimation": int(np.sum(r[:, 0] <= 1.1)),
            "validation": int(np.sum(r[:, 1] <= 1.1)),
        },
        "names": {str(i): n for i, n in zip(cases, names, strict=True)},
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--cases", type=int, default=80)
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument("--out", type=Path, default=Path("results/oracles"))
    parser.add_argument("--one", nargs=2, metavar=("SEED", "MODE"), help="internal")
    args = parser.parse_args(argv)
    if args.one:
        seed, mode = args.one
        print(json.dumps(_one(int(seed), args.cases, mode)))
        return
    result: dict = {"cases_per_seed": args.cases, "seeds": {}}
    for seed in args.seeds:
        result["seeds"][str(seed)] = {}
        for mode in args.modes:
            cmd = [sys.executable, __file__, "--cases", str(args.cases)]
            got = subprocess.run(
                [*cmd, "--one", str(seed), mode],
                check=True,
                capture_output=True,
                text=True,
            )
            entry = json.loads(got.stdout.strip().splitlines()[-1])
            result["seeds"][str(seed)][mode] = entry
            med = entry["backlash_over_truth_rms_median"]
            print(
                f"seed {seed}, {mode}: named stiction-like "
                f"{entry['named_stiction_like']} of {entry['sticky_loops']}; "
                f"backlash fit / truth RMS (median) estimation "
                f"{med['estimation']:.2f}, validation {med['validation']:.2f}",
                flush=True,
            )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "loop_recall_oracles.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
