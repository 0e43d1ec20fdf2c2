"""Study `refinement-recursive-pl`: seed 001 closed form vs output-error refinement
vs the Cramér-Rao bound.

Plant of seed 001 Section V.C ($A = 1 - 1.5q^{-1} + 0.56q^{-2}$,
$B = q^{-1} - 2q^{-2}$, Fig. 2 map with $K = (1, 2)$, $D = (1, -2)$,
$L = (1, -2)$), input (5.1) with $V = (-6, -3, 3, 6)$, white output noise at
`--snrs` dB, records of `--periods` periods of $7n$ samples. Closed form: batch
least squares on (3.8) + rank-1 SVD (3.11)-(3.12) (`identify_recursive_pl`,
`estimator="batch"`, computed from its parts). Its equation error $A z$ is coloured, so it is biased;
20 Steiglitz-McBride iterations started from it remove the bias, and
Levenberg-Marquardt (`refine`, `ImpulseTableParametrisation`) finishes the
output-error (maximum-likelihood) fit: that is "refined". "refined from closed
form" runs the same `refine` directly from the closed form, to show why the
intermediate step is needed. Parameters $(a, b, F(V_j))$ in the normalisation
(3.10).
"""

from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ...._argtypes import int_list
from ...._results import RESULTS
from ....identification.seed001 import (
    batch_least_squares,
    recover_parameters,
    regressor,
)
from ....models import noise_std_for_snr
from ....montecarlo.config import MonteCarloConfig
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.runner import run_monte_carlo
from ....montecarlo.timing import time_per_call
from ....refinement import (
    ImpulseTableParametrisation,
    RefinementOptions,
    cramer_rao_bound,
    refine,
)
from ....refinement.efficiency import efficiency_summary
from ....refinement.steiglitz_mcbride import steiglitz_mcbride_table
from ....signals import pe_impulse_sequence
from ....simulation import simulate
from ... import _refinement as shared
from ..plants import seed001_plant


NAME = "refinement-recursive-pl"
DESCRIPTION = (
    "seed 001: batch LS closed form vs output-error refinement vs Cramer-Rao bound "
    "(bias/std/RMSE, efficiency, failures, cost) over record length and SNR"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 100


OPTIONS = (
    StudyOption(
        "periods", [10, 30, 100, 300], "record lengths in periods of 7n", int_list
    ),
    shared.snrs_option([10.0, 20.0]),
    *shared.REFINEMENT_OPTIONS,
)


def _closed_form(v, y, levels, n):
    # `identify_recursive_pl(..., estimator="batch")` without its excitation
    # check: a batched eigvalsh under vmap deadlocked jax 0.10.2's CPU thread pool
    # here (see the report); the estimate is the same.
    lv = jnp.asarray(levels)
    theta = batch_least_squares(regressor(v, y, levels=lv, order=n), y)  # (3.8)
    est = recover_parameters(theta, levels=lv, order=n)  # (3.11)-(3.14)
    cf = jnp.concatenate([est.a, est.b, est.points])
    ok = jnp.all(jnp.isfinite(cf))
    return cf, RESULTS.where(ok, RESULTS.successful, RESULTS.nonfinite)


def _refined(v, y, levels, cf, options):
    n = (cf.shape[0] - 4) // 2
    p = ImpulseTableParametrisation(jnp.asarray(levels), cf[n : 2 * n])
    return refine(p, p.from_physical(cf), v, y, options=options, throw=False)


class _Trial(eqx.Module):
    records: list
    levels: tuple[float, ...] = eqx.field(static=True)
    order: int = eqx.field(static=True)
    options: RefinementOptions

    def __call__(self, key):
        rows = []
        levels = jnp.asarray(self.levels)
        for i, (v, w, sigmas) in enumerate(self.records):
            for j in range(sigmas.shape[0]):
                noise = sigmas[j] * jr.normal(jr.fold_in(key, 100 * i + j), w.shape)
                y = w + noise
                cf, cf_result = _closed_form(v, y, self.levels, self.order)
                cf_ok = (cf_result._value == 0) & jnp.all(jnp.isfinite(cf))
                cf_safe = jnp.where(cf_ok, cf, jnp.ones_like(cf))
                sm = steiglitz_mcbride_table(v, y, levels, cf_safe[: self.order])
                r = _refined(v, y, self.levels, sm, self.options)
                direct = _refined(v, y, self.levels, cf_safe, self.options)
                rows.append(
                    {
                        "closed": cf,
                        "sm": sm,
                        "refined": r.estimate,
                        "direct": direct.estimate,
                        "ok_closed": cf_ok,
                        "ok_refined": r.result._value == 0,
                        "ok_direct": cf_ok & (direct.result._value == 0),
                        "steps": r.steps,
                    }
                )
        return shared.stack_rows(rows)


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:

    from ....plotting.refinement import save_refinement_study

    opts = option_values(args, OPTIONS)
    periods, snrs = opts.periods, opts.snrs
    options = shared.refinement_options(opts)
    plant, levels, n = seed001_plant()
    truth_p = ImpulseTableParametrisation(levels, jnp.array([1.0, -2.0]))
    theta_true = truth_p.from_physical(
        jnp.concatenate(
            [
                jnp.array([-1.5, 0.56]),
                jnp.array([1.0, -2.0]),
                plant.nonlinearity(levels),
            ]
        )
    )
    truth = np.asarray(truth_p.to_physical(theta_true))
    records, crlb = [], []
    for P in periods:
        _, v = pe_impulse_sequence(levels, order=n, periods=P)
        w = simulate(plant, v)
        sigmas = jnp.asarray([noise_std_for_snr(w, s) for s in snrs])
        records.append((v, w, sigmas))
        crlb.append(
            [
                np.diag(np.asarray(cramer_rao_bound(truth_p, theta_true, v, s)))
                for s in sigmas
            ]
        )
    levels = tuple(float(x) for x in levels)
    trial = _Trial(records, levels, n, options)
    res = run_monte_carlo(
        key,
        trial,
        MonteCarloConfig(realisations=realisations, chunk=chunk, name=NAME),
        quiet=quiet,
    )
    # Cost: time per estimate of each estimator alone, on the longest record.
    v, w, sigmas = records[-1]
    keys = shared.timing_keys(chunk, 64)
    noisy = lambda k: w + sigmas[0] * jr.normal(k, w.shape)
    lv = jnp.asarray(levels)

    def _full(k):
        y = noisy(k)
        cf = _closed_form(v, y, levels, n)[0]
        return _refined(
            v, y, levels, steiglitz_mcbride_table(v, y, lv, cf[:n]), options
        ).estimate

    t_cf = t_ref = float("nan")
    if opts.timing:
        t_cf = time_per_call(lambda k: _closed_form(v, noisy(k), levels, n)[0], keys)
        t_ref = time_per_call(_full, keys)
    names = list(truth_p.names)
    configs = []
    k = 0
    for i, P in enumerate(periods):
        for j, snr in enumerate(snrs):
            ok_c = np.asarray(res["ok_closed"][:, k])
            configs.append(
                {
                    "periods": P,
                    "samples": int(records[i][0].shape[0]),
                    "snr_db": snr,
                    "noise_std": float(records[i][2][j]),
                    **shared.refinement_columns(res, k, truth, crlb[i][j]),
                    "steiglitz_mcbride": efficiency_summary(
                        res["sm"][:, k], truth, crlb[i][j], ok_c
                    ),
                    "refined_from_closed_form": efficiency_summary(
                        res["direct"][:, k],
                        truth,
                        crlb[i][j],
                        np.asarray(res["ok_direct"][:, k]),
                    ),
                    "refined_from_closed_form_failure_rate": float(
                        1 - np.asarray(res["ok_direct"][:, k]).mean()
                    ),
                }
            )
            k += 1
    summary = {
        "study": NAME,
        "question": "How close do the seed-001 closed form and its output-error "
        "refinement come to the Cramer-Rao bound?",
        "realisations": realisations,
        "parameters": names,
        "truth": truth.tolist(),
        "solver": options.solver,
        "configs": configs,
        "seconds_per_estimate": {
            "closed_form": t_cf,
            "refined_incl_closed_form_and_sm": t_ref,
        },
        "cost_ratio_refined_to_closed_form": t_ref / t_cf,
    }
    largest = [c for c in configs if c["periods"] == max(periods)]
    summary["headline"] = (
        "; ".join(
            f"SNR {c['snr_db']:g} dB, N={c['samples']}: refined efficiency "
            f"min {min(c['refined']['efficiency']):.2f} / mean "
            f"{np.mean(c['refined']['efficiency']):.2f}, closed form min "
            f"{min(c['closed_form']['efficiency']):.3g}, Steiglitz-McBride min "
            f"{min(c['steiglitz_mcbride']['efficiency']):.2f}; refinement failures "
            f"{c['refined_failure_rate']:.1%}"
            for c in largest
        )
        + f"; cost ratio {t_ref / t_cf:.1f}"
    )
    save_refinement_study(summary, out, "refinement_recursive_pl")
    return summary
