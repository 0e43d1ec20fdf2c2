"""Study `refinement-nbbi`: seed 000 NBBI border points vs the output-error
refinement of (border points, $G(s)$) vs the Cramér-Rao bound.

Plant of the demo (`hamjax.papers.seed000.plants.seed000_plant`): seed 000 Fig. 6's
$G(s) = (s - 10)/(s + 1)^2$ normalised to $G(0) = 1$ with a curved backlash,
$n = 4$ levels. Record: initialisation (3) of `hold`/4 then the staircase (4a-b)
with each level held `--holds` seconds, sampled at `--dt`, white output noise at
`--snrs` dB. Closed form: NBBI's plain average (5) (`identify_nbbi`). Refined:
`refine` with `BacklashPathParametrisation` ($G$ of orders 2/1, $G(0) = 1$),
started from the NBBI points and an all-pole $G$ chosen on a grid
(`initial_backlash_theta`). NBBI gives no $G$: its entries are NaN.
"""

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from ...._argtypes import float_list, positive_float
from ....identification.seed000.nbbi_table1 import identify_nbbi
from ....models import apply_nonlinearity, noise_std_for_snr
from ....montecarlo.config import MonteCarloConfig
from ....montecarlo.registry import StudyOption, option_values
from ....montecarlo.runner import run_monte_carlo
from ....montecarlo.timing import time_per_call
from ....refinement import (
    BacklashPathParametrisation,
    RefinementOptions,
    cramer_rao_bound,
    refine,
)
from ....refinement.backlash_start import initial_backlash_theta
from ....signals import initialisation_step, nbbi_staircase
from ....simulation import simulate
from ... import _refinement as shared
from ..plants import seed000_plant


NAME = "refinement-nbbi"
DESCRIPTION = (
    "seed 000: NBBI border points vs output-error refinement of (U_i, G(s)) vs "
    "Cramer-Rao bound over hold length and SNR"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 50


OPTIONS = (
    StudyOption(
        "holds", [5.0, 10.0, 20.0, 40.0], "hold N*Tr (s) per level", float_list
    ),
    shared.snrs_option([20.0, 40.0]),
    StudyOption("dt", 0.05, "sampling period (s)", positive_float),
    *shared.REFINEMENT_OPTIONS,
)


def make_record(plant, levels, hold, dt):
    """`(v, w, start, parametrisation, theta_true)` of one record."""
    t0 = dt * max(1, round(hold / 4 / dt))  # T0 of (3): a quarter hold, whole samples
    _, v0 = initialisation_step(levels, duration=t0, dt=dt)
    _, v1 = nbbi_staircase(levels, hold=hold, dt=dt)
    v = jnp.concatenate([v0, v1])
    w = simulate(plant, v, dt=dt)
    p = BacklashPathParametrisation.from_design(
        v, levels, den_order=2, num_order=1, dt=dt
    )
    u = np.asarray(apply_nonlinearity(plant.nonlinearity, v))
    pos = np.asarray(p.positions)
    table = jnp.asarray([u[pos == k][0] for k in range(p.n_cycle + 1)])
    G = plant.linear
    theta = jnp.concatenate(
        [table[1:], G.den[1:] / G.den[0], G.num[:-1] / G.den[0], table[:1]]
    )
    return v, w, int(v0.shape[0]), p, theta


class _Trial(eqx.Module):
    records: list
    sigmas: jax.Array
    levels: tuple[float, ...] = eqx.field(static=True)
    holds: tuple[float, ...] = eqx.field(static=True)
    starts: tuple[int, ...] = eqx.field(static=True)
    dt: float = eqx.field(static=True)
    options: RefinementOptions

    def __call__(self, key):
        rows = []
        for i, (v, w, p) in enumerate(self.records):
            for j in range(self.sigmas.shape[1]):
                noise = self.sigmas[i, j] * jr.normal(
                    jr.fold_in(key, 100 * i + j), w.shape
                )
                y = w + noise
                cf, cf_ok = _closed_form(
                    y, self.levels, self.holds[i], self.dt, self.starts[i]
                )
                r = refine(
                    p,
                    initial_backlash_theta(p, cf, v, y),
                    v,
                    y,
                    options=self.options,
                    throw=False,
                )
                nan = jnp.full(r.estimate.shape[0] - cf.shape[0], jnp.nan)
                rows.append(
                    {
                        "closed": jnp.concatenate([cf, nan]),
                        "refined": r.estimate,
                        "ok_closed": cf_ok,
                        "ok_refined": r.result._value == 0,
                        "steps": r.steps,
                    }
                )
        return shared.stack_rows(rows)


def _closed_form(y, levels, hold, dt, start):
    res = identify_nbbi(
        y, np.asarray(levels), hold=hold, dt=dt, start=start, throw=False
    )
    ok = (res.result._value == 0) & jnp.all(jnp.isfinite(res.cycle_values))
    return res.cycle_values, ok


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:

    from ....plotting.refinement import save_refinement_study

    opts = option_values(args, OPTIONS)
    holds, snrs, dt = opts.holds, opts.snrs, opts.dt
    options = shared.refinement_options(opts)
    plant, levels, _, _ = seed000_plant()
    records, sigmas, crlb, truths, starts = [], [], [], [], []
    for hold in holds:
        v, w, start, p, theta = make_record(plant, levels, hold, dt)
        s = [float(noise_std_for_snr(w, snr)) for snr in snrs]
        records.append((v, w, p))
        starts.append(start)
        sigmas.append(s)
        truths.append(np.asarray(theta))
        crlb.append([np.diag(np.asarray(cramer_rao_bound(p, theta, v, x))) for x in s])
    trial = _Trial(
        records,
        jnp.asarray(sigmas),
        tuple(float(x) for x in levels),
        tuple(holds),
        tuple(starts),
        dt,
        options,
    )
    res = run_monte_carlo(
        key,
        trial,
        MonteCarloConfig(realisations=realisations, chunk=chunk, name=NAME),
        quiet=quiet,
    )
    v, w, p = records[-1]
    lv = tuple(float(x) for x in levels)
    keys = shared.timing_keys(chunk, 32)
    noisy = lambda k: w + sigmas[-1][0] * jr.normal(k, w.shape)

    def _full(k):
        y = noisy(k)
        cf = _closed_form(y, lv, holds[-1], dt, starts[-1])[0]
        return refine(
            p, initial_backlash_theta(p, cf, v, y), v, y, options=options, throw=False
        ).estimate

    t_cf = t_ref = float("nan")
    if opts.timing:
        t_cf = time_per_call(
            lambda k: _closed_form(noisy(k), lv, holds[-1], dt, starts[-1])[0], keys
        )
        t_ref = time_per_call(_full, keys)
    names = list(records[0][2].names)
    configs = []
    k = 0
    for i, hold in enumerate(holds):
        for j, snr in enumerate(snrs):
            configs.append(
                {
                    "hold_s": hold,
                    "samples": int(records[i][0].shape[0]),
                    "snr_db": snr,
                    "noise_std": sigmas[i][j],
                    **shared.refinement_columns(res, k, truths[i], crlb[i][j]),
                }
            )
            k += 1
    n_cycle = records[0][2].n_cycle
    summary = {
        "study": NAME,
        "question": "How close do NBBI's border points and their output-error "
        "refinement (with a parametric G) come to the Cramer-Rao bound?",
        "realisations": realisations,
        "parameters": names,
        "truth": truths[-1].tolist(),
        "dt": dt,
        "solver": options.solver,
        "configs": configs,
        "seconds_per_estimate": {"closed_form": t_cf, "refined_incl_start": t_ref},
        "cost_ratio_refined_to_closed_form": t_ref / t_cf,
    }
    largest = [c for c in configs if c["hold_s"] == max(holds)]
    summary["headline"] = (
        "; ".join(
            f"SNR {c['snr_db']:g} dB, hold {c['hold_s']:g} s: refined efficiency min "
            f"{np.nanmin(c['refined']['efficiency']):.2f} / mean "
            f"{np.nanmean(c['refined']['efficiency']):.2f}, NBBI on U min "
            f"{np.nanmin(c['closed_form']['efficiency'][:n_cycle]):.3g}; refinement "
            f"failures {c['refined_failure_rate']:.1%}"
            for c in largest
        )
        + f"; cost ratio {t_ref / t_cf:.0f}"
    )
    save_refinement_study(summary, out, "refinement_nbbi")
    return summary
