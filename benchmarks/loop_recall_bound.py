"""How much stiction recall the control-loop benchmark's records allow: the true
valve and process against the re-fit that `hamjax diagnose` tests every
structural candidate against, by the rule's own two tests.

    python benchmarks/loop_recall_bound.py --seeds 1 2 3 4 --out results/bound

For each seed, the loops of `hamjax blind make --family loops --cases N --seed S`
(`papers.gap.control_loops`, the same draws) are diagnosed without model.json
(hamjax fits its own nominal, as for a real record), the fits captured. For
each sticky loop the true valve (its truth entry) and the true process are
simulated on the validation command, and their residual is compared with that
of the re-fit's best row (`parameter_mismatch`):

- in simulation: `attribute.significant` at `Z_STRUCT`, the truth's noise floor;
- through the loop's noise predictor where one is significant (its one-step
  errors): batch-means $z > z^\\star$ (`Z_STAR`).

A sticky loop that passes both is *detectable*: a diagnosis judged on the
validation record can name it at best. The truth's valve starts either at rest
at 0, as the benchmark ran it, or at the first command with no force, the
contract's convention and the fits' (`--start`, both by default). Written:
`loop_recall_bound.json` (per seed and pooled: sticky loops, detectable ones,
how many of those the diagnosis named stiction-like, the same for a valve
visibility below 1; per seed the detectable loops missed and the loops named
though not detectable, by case). No timing; about 2.5 minutes a seed on 2 cores.
"""

import argparse
import json
from pathlib import Path

import numpy as np
from decision_replay import diagnose_captured, loop_cases
from scipy import signal


def _valve(st: dict, op: np.ndarray, start: str) -> np.ndarray:
    from hamjax.papers.gap import control_loops as cl

    if start == "rest":
        model = cl.make_valve(st)
    elif st["model"] == "choudhury":
        model = cl.ChoudhuryStiction(st["S"], st["J"], x0=float(op[0]))
    else:
        model = cl.HeStiction(st["fs"], st["fd"], x0=float(op[0]))
    return cl.valve_positions(model, op)


def true_process(truth: dict) -> tuple[np.ndarray, np.ndarray]:
    """`(b, a)` of a loop's true process in discrete time, its dead time in."""
    from hamjax.papers.gap import control_loops as cl

    num, den = cl.process_tf(truth["process"], truth["physics"])
    return cl.discrete_process(num, den, truth["dt"], truth["delay_samples"])


def _detectable(truth: dict, prep, fit, start: str) -> bool:
    from hamjax.diagnosis import attribute as at
    from hamjax.diagnosis.layout import finite_sse, validation_sse
    from hamjax.diagnosis.residuals import noise_floor_hf

    b, a = true_process(truth)
    n = prep.n_val
    op = np.asarray(prep.arrays.v_val)[:n]
    y = np.asarray(prep.arrays.y_val)[:n]
    r_true = y - signal.lfilter(b, a, _valve(truth["stiction"], op, start))
    rows = at.best_row_per_class(prep, finite_sse(fit), validation_sse(prep, fit))
    r_pm = y - np.asarray(fit["y_val"][rows["parameter_mismatch"]])[:n]
    floor = min(noise_floor_hf(r_true), at.rms(r_true))
    in_simulation, _ = at.significant(r_pm, r_true, floor**2, z_star=at.Z_STRUCT)
    noise, significant, _ = at.nominal_noise(fit["noise"], at.reference(prep, fit)[2])
    if not significant:
        return in_simulation
    e_pm, e_true = at.one_step_errors(noise, r_pm), at.one_step_errors(noise, r_true)
    if e_pm is None or e_true is None:
        return False
    return in_simulation and at.improvement_z(e_pm, e_true) > at.Z_STAR


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[1])
    parser.add_argument("--cases", type=int, default=80)
    parser.add_argument(
        "--start",
        nargs="+",
        choices=["rest", "first_command"],
        default=["rest", "first_command"],
    )
    parser.add_argument("--out", type=Path, default=Path("results/bound"))
    args = parser.parse_args(argv)

    import hamjax
    from hamjax._runtime import same_rounding_in_every_lane, split_cpu_into_devices
    from hamjax.diagnosis.probabilities import STICTION_LIKE

    split_cpu_into_devices()
    same_rounding_in_every_lane()  # as `hamjax` runs
    hamjax.enable_x64()
    result: dict = {"cases_per_seed": args.cases, "seeds": {}}
    pooled = {s: np.zeros(6, int) for s in args.start}
    for seed in args.seeds:
        cases = loop_cases(seed, args.cases)
        every = zip(cases, diagnose_captured(list(cases.values())), strict=True)
        sticky = [(i, x) for i, x in every if x[0]["effect"] == "backlash"]
        ids, loops = [i for i, _ in sticky], [x for _, x in sticky]
        result["seeds"][str(seed)] = {}
        for start in args.start:
            det = [_detectable(t, prep, fit, start) for t, prep, fit, _ in loops]
            named = [name in STICTION_LIKE for *_, name in loops]
            low = [t["valve_visibility"] < 1 for t, *_ in loops]
            counts = np.array(
                [
                    len(loops),
                    sum(det),
                    sum(d and m for d, m in zip(det, named, strict=True)),
                    sum(named),
                    sum(low),
                    sum(d and lo for d, lo in zip(det, low, strict=True)),
                ]
            )
            pooled[start] += counts
            result["seeds"][str(seed)][start] = _entry(counts) | {
                # the loops that bound recall and are missed, and the reverse
                "detectable_missed": [
                    i for i, d, m in zip(ids, det, named, strict=True) if d and not m
                ],
                "named_not_detectable": [
                    i for i, d, m in zip(ids, det, named, strict=True) if m and not d
                ],
            }
            print(f"seed {seed}, valve from {start}: {_line(counts)}")
    result["pooled"] = {s: _entry(c) for s, c in pooled.items()}
    for start, counts in pooled.items():
        print(f"pooled, valve from {start}: {_line(counts)}")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "loop_recall_bound.json").write_text(json.dumps(result, indent=2))


def _entry(c: np.ndarray) -> dict:
    sticky, det, det_named, named, low, low_det = (int(x) for x in c)
    return {
        "sticky_loops": sticky,
        "detectable": det,
        "bound": det / sticky if sticky else None,
        "detectable_named_stiction_like": det_named,
        "named_stiction_like": named,
        "visibility_below_1": low,
        "visibility_below_1_detectable": low_det,
    }


def _line(c: np.ndarray) -> str:
    e = _entry(c)
    return (
        f"detectable {e['detectable']} of {e['sticky_loops']} (bound "
        f"{e['bound']:.3f}), named stiction-like {e['named_stiction_like']} "
        f"({e['detectable_named_stiction_like']} of them detectable); visibility "
        f"< 1: {e['visibility_below_1_detectable']} of {e['visibility_below_1']}"
    )


if __name__ == "__main__":
    main()
