"""Study `recursive-pl-convergence`: Proposition 5.2(2) of seed 001, ideal case.

Question: with $z = 0$ and the impulse input (5.1), does the normalised gradient
(4.1) drive $\\hat\\Theta(t) \\to \\Theta^*$ for random stable plants of order
1..3 with random dead-zone or preload maps and random levels (not only the
paper's plant), and how many samples does it take to reach 1e-3 and 1e-6?
Per realisation: a random case (`hamjax.papers.seed001.plants`), $P$
periods of (5.1), $\\hat\\theta(0) = 0$, $\\rho^* = 10^6$; it records the samples
to each tolerance, the final errors of $\\Theta$, $b$, $F(V_j)$, $K$, $D$, $L$
(rule (3.18a) or (3.18b) as the map is), and the excitation level of one period.
"""

from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ...._argtypes import int_list
from ....identification.seed001 import (
    excitation_level,
    normalised_gradient_convergence,
    recover_parameters,
    regressor,
)
from ....montecarlo.registry import StudyOption, option_values
from ....simulation import simulate
from ..plants import pe_input, random_dead_zone_or_preload
from ._common import headless, periods_option, run_trials, write_summary


NAME = "recursive-pl-convergence"
DESCRIPTION = (
    "seed 001 Prop. 5.2(2): noise-free convergence of (4.1) on random plants of "
    "order 1..3 with random dead-zone/preload maps"
)
DEFAULT_REALISATIONS = 1000
DEFAULT_CHUNK = 100
TOLERANCES = (1e-3, 1e-6)


def _max_abs(x, y):
    return jnp.max(jnp.abs(jnp.asarray(x) - jnp.asarray(y)))


class ConvergenceTrial(eqx.Module):
    """One realisation for a fixed order and number of periods."""

    order: int = eqx.field(static=True)
    periods: int = eqx.field(static=True)

    def __call__(self, key):
        n = self.order
        case, is_dead_zone = random_dead_zone_or_preload(key, n)
        v = pe_input(case.levels, n, self.periods)
        y = simulate(case.plant(), v)
        phi = regressor(v, y, levels=case.levels, order=n)
        theta_star = case.theta_star()
        half = phi.shape[0] // 2
        kw = dict(rho=1e6, theta_ref=theta_star, tolerances=jnp.array(TOLERANCES))
        theta_half, _ = normalised_gradient_convergence(
            phi[:half], y[:half], theta0=jnp.zeros(5 * n), **kw
        )
        theta, samples = normalised_gradient_convergence(
            phi, y, theta0=jnp.zeros(5 * n), **kw
        )
        kw = dict(levels=case.levels, order=n)
        dz = recover_parameters(theta, structure="dead-zone", **kw)
        pl = recover_parameters(theta, structure="preload", **kw)
        truth = case.normalised_truth()

        def pick(name):
            return jnp.where(is_dead_zone, getattr(dz, name), getattr(pl, name))

        return {
            "samples_to_tol": samples,
            "theta_error": _max_abs(theta, theta_star),
            "theta_error_half": _max_abs(theta_half, theta_star),
            "b_error": _max_abs(dz.b, truth["b"]),
            "points_error": _max_abs(dz.points, truth["points"]),
            "k_error": _max_abs(
                jnp.stack([dz.k1, dz.k2]), jnp.stack([truth["k1"], truth["k2"]])
            ),
            "d_error": _max_abs(
                jnp.stack([pick("d1"), pick("d2")]),
                jnp.stack([truth["d1"], truth["d2"]]),
            ),
            "l_error": _max_abs(
                jnp.stack([pick("l1"), pick("l2")]),
                jnp.stack([truth["l1"], truth["l2"]]),
            ),
            "consistent": jnp.where(is_dead_zone, dz.consistent, pl.consistent),
            "excitation": excitation_level(phi[-7 * n :]),
            "dead_zone": is_dead_zone,
        }


OPTIONS = (
    periods_option(
        1500, "periods of (5.1) per realisation (7n samples each; default 1500)"
    ),
    StudyOption("orders", [1, 2, 3], "orders n to test (default 1,2,3)", int_list),
)


def run(key, *, realisations: int, chunk: int, out: Path, quiet: bool, args) -> dict:
    import jax.random as jr

    headless()
    from ....plotting.recursive_pl import plot_curves, plot_histogram

    opts = option_values(args, OPTIONS)
    periods, orders = opts.periods, opts.orders
    out = Path(out)
    per_order, samples, excitation = {}, {}, {}
    budget = dict(realisations=realisations, chunk=chunk, quiet=quiet)
    for n in orders:
        res = run_trials(
            jr.fold_in(key, n),
            ConvergenceTrial(order=n, periods=periods),
            f"{NAME}-n{n}",
            out / f"realisations_n{n}",
            args,
            budget,
            periods=periods,
            order=n,
        )
        n_time = 7 * n * periods
        s = np.asarray(res["samples_to_tol"], dtype=float)
        converged = s <= n_time
        s_plot = np.where(converged, s, np.nan)
        samples[f"n={n}"] = s_plot[:, 1]
        excitation[f"n={n}"] = np.asarray(res["excitation"])
        exc = np.asarray(res["excitation"])
        rank_corr = float(
            np.corrcoef(np.argsort(np.argsort(exc)), np.argsort(np.argsort(s[:, 0])))[
                0, 1
            ]
        )
        err, err_half = (
            np.asarray(res["theta_error"]),
            np.asarray(res["theta_error_half"]),
        )
        decreasing = (err < 0.5 * err_half) | (err < 1e-12)
        per_order[f"n={n}"] = {
            "fraction_error_halved_in_second_half_or_at_roundoff": float(
                decreasing.mean()
            ),
            "samples_per_realisation": n_time,
            "fraction_within_1e-3": float(converged[:, 0].mean()),
            "fraction_within_1e-6": float(converged[:, 1].mean()),
            "samples_to_1e-3_quantiles_10_50_90": np.nanquantile(
                np.where(converged[:, 0], s[:, 0], np.nan), [0.1, 0.5, 0.9]
            ).tolist(),
            "samples_to_1e-6_quantiles_10_50_90": np.nanquantile(
                s_plot[:, 1], [0.1, 0.5, 0.9]
            ).tolist(),
            "final_theta_error_median_max": [
                float(np.median(res["theta_error"])),
                float(np.max(res["theta_error"])),
            ],
            "final_error_medians": {
                k: float(np.median(res[k]))
                for k in ("b_error", "points_error", "k_error", "d_error", "l_error")
            },
            "fraction_structure_consistent": float(np.mean(res["consistent"])),
            "fraction_dead_zone": float(np.mean(res["dead_zone"])),
            "excitation_quantiles_0_50_100": np.quantile(exc, [0, 0.5, 1]).tolist(),
            "spearman_excitation_vs_samples_to_1e-3": rank_corr,
        }
    fig = plot_histogram(
        samples,
        xlabel="samples until max|theta - theta*| <= 1e-6",
        title="Prop. 5.2(2): noise-free convergence time, random plants",
    )
    fig.savefig(out / "samples_to_1e-6.png", dpi=120)
    fig = plot_curves(
        excitation,
        samples,
        xlabel="excitation (lambda_min/lambda_max, one period)",
        ylabel="samples to 1e-6",
        title="slow cases are poorly excited",
        logx=True,
        dots=True,
    )
    fig.savefig(out / "excitation_vs_samples.png", dpi=120)
    fractions = {k: v["fraction_within_1e-6"] for k, v in per_order.items()}
    decreasing = {
        k: v["fraction_error_halved_in_second_half_or_at_roundoff"]
        for k, v in per_order.items()
    }
    summary = {
        "study": NAME,
        "seed": getattr(args, "seed", None),
        "realisations_per_order": realisations,
        "periods": periods,
        "per_order": per_order,
        "verdict": (
            "Prop. 5.2(2): fraction within 1e-6 of Theta* at the end of the record: "
            + ", ".join(f"{k}: {v:.3f}" for k, v in fractions.items())
            + "; fraction whose error still halves (or sits at round-off) over the "
            "second half of the record: "
            + ", ".join(f"{k}: {v:.3f}" for k, v in decreasing.items())
            + ". Convergence speed falls with the excitation level (Spearman "
            "correlations in per_order)."
        ),
    }
    return write_summary(out, summary)
