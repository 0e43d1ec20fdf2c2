"""`diagnose_gap`: where the sim-to-real gap lies, which effect causes it, how far it
shrinks once that effect is added (the contract `../shared/contracts/gap-case.md`)."""

from collections import defaultdict

import equinox as eqx
import jax
import jax.numpy as jnp
import jax.tree_util as jtu
import numpy as np

from ..models import Hammerstein
from .attribute import Attribution, attribute
from .fit import fit_cases
from .layout import bucket, n_free_parameters, prepare
from .locate import locate


class GapDiagnosis(eqx.Module):
    """The diagnosis of one case (validation-record arrays for the figures)."""

    effect: str
    gap_before: float
    gap_after: float
    noise_floor: float
    shrink: float
    ranking: list
    where: dict
    tests: dict
    gap_definition: str
    t: np.ndarray
    v: np.ndarray
    y: np.ndarray
    y_nominal: np.ndarray
    y_augmented: np.ndarray
    residual_before: np.ndarray
    residual_after: np.ndarray


def _length_group(n: int) -> int:
    # coarse groups (powers of two) so a batch of cases compiles only a few times
    b = bucket(n)
    return int(2 ** np.ceil(np.log2(b)))


def _result(prep, att: Attribution, val: dict) -> GapDiagnosis:
    chosen = att.chosen
    if chosen is None:
        y_aug, r_after = att.y_nominal, att.r_before
    elif chosen.prediction is None:  # noise model: the one-step-ahead predictor
        r_after = chosen.residual
        y_aug = val["y"] - r_after
    else:
        y_aug, r_after = chosen.prediction, chosen.residual
    noise = chosen is not None and chosen.measure == "one_step_prediction"
    definition = (
        "one-step-ahead prediction error (nominal simulation + fitted noise/trend "
        "predictor; gap_before with the white-noise predictor)"
        if noise
        else "simulation error from rest on the validation record"
    )
    ranking = [
        {
            "effect": c.effect,
            "gap_after": c.gap_after,
            "measure": c.measure,
            "params": c.params,
        }
        for c in att.candidates
    ]
    where = locate(
        val["t"],
        val["v"],
        att.r_before,
        r_after,
        prep.u_val,
        att.noise_floor,
        prep.ctx.dt,
    )
    return GapDiagnosis(
        effect=att.effect,
        gap_before=att.gap_before,
        gap_after=att.gap_after,
        noise_floor=att.noise_floor,
        shrink=att.shrink,
        ranking=ranking,
        where=where,
        tests=att.tests,
        gap_definition=definition,
        t=val["t"],
        v=val["v"],
        y=val["y"],
        y_nominal=att.y_nominal,
        y_augmented=np.asarray(y_aug),
        residual_before=att.r_before,
        residual_after=np.asarray(r_after),
    )


REFIT = "parameter_mismatch"
CONTINUE_STEPS = 120


def _continue_stopped(padded: list, rows, cases, fits):
    """Continue, per case, the nominal re-fit row and the best (lowest estimation
    SSE) structural row if they stopped at the step limit.

    The re-fit row is the reference every structural candidate is tested against,
    so an unfinished one lets a structural row look significant, and an unfinished
    best structural row lets the re-fit win. Those rows only are fitted again from
    where they stopped (one `[case, 2]` batch, compiled only when some case needs
    it), with `CONTINUE_STEPS` more steps.
    """
    result = np.asarray(fits.result)
    sse = np.where(np.isfinite(fits.sse_est), fits.sse_est, np.inf)
    pick = []
    for c, p in enumerate(padded):
        names = [name for name, _ in p.rows]
        i_pm = names.index(REFIT)
        others = [k for k, name in enumerate(names) if name != REFIT]
        i_s = min(others, key=lambda k: sse[c, k])
        pick.append([i_pm, i_s if result[c, i_s] else i_pm])
    pick = np.asarray(pick)
    cidx = np.arange(len(padded))[:, None]
    stopped = result[cidx, pick] != 0
    if not np.any(stopped):
        return fits
    sel = jtu.tree_map(lambda x: x[cidx, pick], rows)
    sel = eqx.tree_at(lambda r: r.theta0, sel, jnp.asarray(fits.theta)[cidx, pick])
    more = jax.device_get(fit_cases(sel, cases, CONTINUE_STEPS))

    def merge(old, new):
        old = np.array(old)
        keep = stopped.reshape(stopped.shape + (1,) * (old.ndim - 2))
        old[cidx, pick] = np.where(keep, np.asarray(new), old[cidx, pick])
        return old

    return jtu.tree_map(merge, fits, more)


def diagnose_many(
    items: list[tuple[Hammerstein, float, dict, dict]], *, chunk: int = 8
) -> list[GapDiagnosis]:
    """Diagnose several cases: `(plant, dt, estimation, validation)` each, the records
    being `{"t", "v", "y"}` dicts of NumPy arrays.

    Cases are padded to a few common lengths and fitted together (`vmap` over cases
    and candidate rows), `chunk` cases per call of the one compiled function.
    """
    groups = defaultdict(list)
    for i, (_plant, _dt, est, val) in enumerate(items):
        n = max(est["v"].shape[0], val["v"].shape[0])
        groups[_length_group(n)].append(i)
    n_params = max(n_free_parameters(plant) for plant, *_ in items)
    out: list = [None] * len(items)
    for length, members in groups.items():
        for start in range(0, len(members), chunk):
            part = members[start : start + chunk]
            preps = [
                prepare(
                    items[i][0], items[i][1], items[i][2], items[i][3], length, n_params
                )
                for i in part
            ]
            # pad the chunk to `chunk` cases with copies so the shape never changes
            padded = (
                preps + [preps[-1]] * (chunk - len(preps)) if len(items) > 1 else preps
            )
            rows = jtu.tree_map(
                lambda *x: jnp.stack(x),
                *[
                    jtu.tree_map(lambda *r: jnp.stack(r), *[r for _, r in p.rows])
                    for p in padded
                ],
            )
            cases = jtu.tree_map(lambda *x: jnp.stack(x), *[p.arrays for p in padded])
            fits = jax.device_get(fit_cases(rows, cases))
            fits = _continue_stopped(padded, rows, cases, fits)
            for j, i in enumerate(part):
                fit = {
                    k: np.asarray(getattr(fits, k))[j]
                    for k in fits.__dataclass_fields__
                }
                att = attribute(preps[j], fit)
                out[i] = _result(preps[j], att, items[i][3])
    return out


def diagnose_gap(
    plant: Hammerstein, dt: float, estimation: dict, validation: dict
) -> GapDiagnosis:
    """Diagnose the gap between `plant` (the nominal model) and two records.

    **Arguments:**

    - `plant`: nominal Hammerstein model (identity, piecewise-linear or tabulated
      map; discrete or continuous linear block of order <= 4).
    - `dt`: sampling period (s).
    - `estimation`, `validation`: `{"t", "v", "y"}` dicts of NumPy arrays, two
      separate experiments; effects are fitted on the first, scored on the second.

    **Returns:** a `GapDiagnosis` (the contract's fields and the figure data).
    """
    return diagnose_many([(plant, dt, estimation, validation)])[0]
