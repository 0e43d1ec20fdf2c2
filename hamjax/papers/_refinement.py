"""What the refinement studies share (`refinement-nbbi`, `refinement-fgi`,
`refinement-recursive-pl`): their options, the way a trial stacks its rows, the
keys the cost is measured on, and the columns every configuration reports."""

import jax
import jax.numpy as jnp
import jax.random as jr
import numpy as np

from .._argtypes import float_list
from ..montecarlo.registry import StudyOption
from ..refinement import RefinementOptions
from ..refinement.efficiency import efficiency_summary


REFINEMENT_OPTIONS = (
    StudyOption("solver", "levenberg-marquardt", "refinement solver"),
    StudyOption(
        "timing",
        True,
        "skip the cost measurement (two extra compilations)",
        negate=True,
    ),
)


def snrs_option(default: list[float]) -> StudyOption:
    """`--snrs`: the output SNRs in dB."""
    return StudyOption("snrs", default, "SNRs in dB (comma-separated)", float_list)


def refinement_options(opts) -> RefinementOptions:
    """The `RefinementOptions` chosen by `--solver`."""
    return RefinementOptions(solver=str(opts.solver))


def stack_rows(rows: list[dict]) -> dict:
    """`{name: stacked values}` of a trial's rows (one dict a configuration, all
    with the same names), in the order of the first row's names."""
    return {k: jnp.stack([row[k] for row in rows]) for k in rows[0]}


def timing_keys(chunk: int, most: int):
    """The keys the cost of an estimator is measured on: `min(chunk, most)` keys
    folded from `key(1)`."""
    return jax.vmap(lambda r: jr.fold_in(jr.key(1), r))(jnp.arange(min(chunk, most)))


def refinement_columns(res, k: int, truth, crlb_var) -> dict:
    """The columns of configuration `k` that every refinement study reports: the
    closed form's and the refinement's `efficiency_summary` against the bound
    `crlb_var`, their failure rates and the refinement's mean number of steps."""
    ok_r = np.asarray(res["ok_refined"][:, k])
    ok_c = np.asarray(res["ok_closed"][:, k])
    return {
        "closed_form": efficiency_summary(res["closed"][:, k], truth, crlb_var, ok_c),
        "refined": efficiency_summary(res["refined"][:, k], truth, crlb_var, ok_r),
        "refined_failure_rate": float(1 - ok_r.mean()),
        "closed_form_failure_rate": float(1 - ok_c.mean()),
        "mean_steps": float(np.asarray(res["steps"][:, k]).mean()),
    }
