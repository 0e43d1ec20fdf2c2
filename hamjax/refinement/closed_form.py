"""Refinement of the closed-form results written by `hamjax identify`, for
`hamjax identify METHOD DIR --refine` (see `contracts/experiments.md`).

Each function takes the data and the closed-form `result.json` dict and returns
`{"refined": {...same keys...}, "standard_errors": {...}, "converged": bool,
"result": str, "steps": int, "noise_std": float}`, JSON-able.
"""

import jax
import jax.numpy as jnp
import numpy as np

from .._results import RESULTS, result_name
from ..identification.seed000.fgi_table2 import steady_cycle_indices
from ..identification.seed001 import dead_zone_rule, preload_rule, symmetric_rule
from .backlash_path import BacklashPathParametrisation
from .backlash_start import initial_backlash_theta
from .crlb import cramer_rao_bound
from .fgi_frequency import FGIBlock, FGIFrequencyParametrisation
from .impulse_table import ImpulseTableParametrisation
from .options import RefinementOptions
from .prediction_error import refine
from .steiglitz_mcbride import steiglitz_mcbride_table


def _lines(levels, points):
    """Eqs. (3.16)-(3.17): $(K_1, K_2, H_1, H_2)$ from the four points."""
    v1, v2, v3, v4 = levels
    f1, f2, f3, f4 = points
    k1 = (f3 - f4) / (v3 - v4)
    k2 = (f1 - f2) / (v1 - v2)
    h1 = (v3 * f4 - v4 * f3) / (v3 - v4)
    h2 = (v1 * f2 - v2 * f1) / (v1 - v2)
    return jnp.stack([k1, k2, h1, h2])


_RULES = {
    "dead-zone": dead_zone_rule,  # Eq. (3.18a)
    "preload": preload_rule,  # Eq. (3.18b)
    "symmetric": symmetric_rule,  # Eq. (3.18c)
}


def refine_recursive_pl_result(
    v,
    y,
    closed_form: dict,
    *,
    levels,
    order: int,
    structure: str | None = None,
    options: RefinementOptions | None = None,
) -> dict:
    """Output-error refinement of seed 001's closed form (input (5.1)).

    The closed form's $A$ starts 20 Steiglitz-McBride iterations (which remove
    the bias of the equation-error least squares under output noise), then
    `refine` with `ImpulseTableParametrisation`. Standard errors come from the
    Fisher information at the refined estimate with $\\hat\\sigma^2 = \\text{rss}/(N-p)$;
    those of $k_j, h_j$ by the delta method through (3.16)-(3.17).

    `closed_form` needs `"a"` (n values); `structure` (`"dead-zone"`,
    `"preload"`, `"symmetric"`) gives `d1, d2, l1, l2` by (3.18a-c); with `None`
    they are `None`, as in the contract.
    """
    levels = jnp.asarray(np.asarray(levels, dtype=float))
    v = jnp.asarray(np.asarray(v, dtype=float))
    y = jnp.asarray(np.asarray(y, dtype=float))
    a0 = jnp.asarray(np.asarray(closed_form["a"], dtype=float))
    if a0.shape != (order,):
        raise ValueError(
            f"closed form 'a' must hold n = {order} values; got {a0.shape}"
        )
    start = jax.jit(steiglitz_mcbride_table)(v, y, levels, a0)
    p = ImpulseTableParametrisation(levels, start[order : 2 * order])
    res = refine(p, p.from_physical(start), v, y, options=options, throw=False)
    sigma = jnp.sqrt(res.noise_variance)
    n = order

    def physical(theta):
        phys = p.to_physical(theta)
        return jnp.concatenate([phys, _lines(levels, phys[2 * n :])])

    est = np.asarray(physical(res.theta))
    se = np.sqrt(
        np.diag(np.asarray(cramer_rao_bound(p, res.theta, v, sigma, physical=physical)))
    )

    def pack(x):
        out = {
            "a": x[:n].tolist(),
            "b": x[n : 2 * n].tolist(),
            "points": [
                [float(V), float(f)]
                for V, f in zip(levels, x[2 * n : 2 * n + 4], strict=True)
            ],
            "k1": float(x[2 * n + 4]),
            "k2": float(x[2 * n + 5]),
            "h1": float(x[2 * n + 6]),
            "h2": float(x[2 * n + 7]),
        }
        return out

    refined, errors = pack(est), pack(se)
    k1, k2, h1, h2 = est[2 * n + 4 :]
    if structure is not None:
        if structure not in _RULES:
            raise ValueError(f"structure must be one of {sorted(_RULES)} or None")
        rule = _RULES[structure]
        d1, d2, l1, l2 = (
            float(x) for x in rule(*(jnp.asarray(x) for x in (k1, k2, h1, h2)))
        )
    else:
        d1 = d2 = l1 = l2 = None
    refined.update({"d1": d1, "d2": d2, "l1": l1, "l2": l2})
    converged = bool(res.result == RESULTS.successful)
    return {
        "refined": refined,
        "standard_errors": errors,
        "converged": converged,
        "result": result_name(res.result),
        "steps": int(res.steps),
        "noise_std": float(sigma),
    }


def refine_nbbi_result(
    v,
    y,
    closed_form: dict,
    *,
    levels,
    dt: float,
    den_order: int = 2,
    num_order: int = 1,
    options: RefinementOptions | None = None,
) -> dict:
    """Joint output-error fit of NBBI's border points and a parametric $G(s)$
    (orders `den_order`/`num_order`, $G(0) = 1$) to the whole record
    (initialisation (3) + staircase (4a-b)), started from the NBBI `"cycle"` points
    and the best all-pole $G$ on a grid (`initial_backlash_theta`).

    `refined` holds `"ascending"`, `"descending"`, `"cycle"` as the closed form
    does, plus `"transfer_function": {"num": [...], "den": [...]}` (highest power
    first); `standard_errors` the same, with the $U$ errors in place of $U$.
    """
    levels_np = np.asarray(levels, dtype=float)
    v = np.asarray(v, dtype=float)
    y = jnp.asarray(np.asarray(y, dtype=float))
    p = BacklashPathParametrisation.from_design(
        v, levels_np, den_order=den_order, num_order=num_order, dt=dt
    )
    cycle = np.asarray(closed_form["cycle"], dtype=float)
    if cycle.shape != (p.n_cycle, 2):
        raise ValueError(
            f"closed form 'cycle' must hold 2n-2 = {p.n_cycle} [V, U] pairs; got "
            f"shape {cycle.shape}"
        )
    v = jnp.asarray(v)
    theta0 = initial_backlash_theta(p, jnp.asarray(cycle[:, 1]), v, y)
    res = refine(p, theta0, v, y, options=options, throw=False)
    sigma = jnp.sqrt(res.noise_variance)
    se = np.sqrt(np.diag(np.asarray(cramer_rao_bound(p, res.theta, v, sigma))))
    est = np.asarray(res.theta)
    n, c = levels_np.shape[0], p.n_cycle

    def pack(x, *, values):
        u = x[:c]
        asc = u[:n]
        desc = np.concatenate([u[n - 1 :], u[:1]])
        alpha = x[c : c + den_order]
        beta = x[c + den_order : c + den_order + num_order]
        # den[0] = 1 is fixed (standard error 0); num[-1] = den[-1] is G(0) = 1.
        lead = 1.0 if values else 0.0
        tf = {"num": [*beta.tolist(), float(alpha[-1])], "den": [lead, *alpha.tolist()]}
        return {
            "ascending": [
                [float(V), float(U)] for V, U in zip(levels_np, asc, strict=True)
            ],
            "descending": [
                [float(V), float(U)] for V, U in zip(levels_np[::-1], desc, strict=True)
            ],
            "cycle": [
                [float(V), float(U)] for V, U in zip(cycle[:, 0], u, strict=True)
            ],
            "transfer_function": tf,
        }

    return {
        "refined": pack(est, values=True),
        "standard_errors": pack(se, values=False),
        "converged": bool(res.result == RESULTS.successful),
        "result": result_name(res.result),
        "steps": int(res.steps),
        "noise_std": float(sigma),
        "u_initial": float(est[-1]),
    }


def refine_fgi_result(
    y_nbbi,
    y_fgi,
    closed_form: dict,
    *,
    levels,
    cycle_values,
    nbbi_start: int,
    hold_samples: int,
    settle_samples: int,
    blocks: list[dict],
    dt: float,
    z: float = 4.0,
    options: RefinementOptions | None = None,
) -> dict:
    """Joint output-error fit of FGI's $G(jk\\omega)$ (every harmonic of
    `closed_form["frequency_response"]`) and the border points $U_i$ to the NBBI
    and FGI records, started from the closed form (`cycle_values`, the $U_i$ that
    FGI used, and its $G$) or from the settled closed form
    (`FGIFrequencyParametrisation.initial_theta`), whichever fits better; see `FGIFrequencyParametrisation` ($G(0) = 1$
    eliminated). Standard errors come from the Fisher information at the refined
    estimate with $\\hat\\sigma$ from the replicates (`replicate_noise_variance`).

    **Arguments:**

    - `y_nbbi`, `y_fgi`: the two measured records.
    - `closed_form`: FGI's `result.json` dict.
    - `levels`: $V_1..V_n$; `cycle_values`: the $2n-2$ starting $U_i$.
    - `nbbi_start`, `hold_samples`: the NBBI design (initialisation length, hold).
    - `settle_samples`: samples of each NBBI hold left out (its transient).
    - `blocks`: the FGI design's blocks (`period_samples`, `periods`,
      `average_start`, `omega`).
    - `dt`: the FGI sampling period (s).
    - `z`: the periodic $u$ of the FGI record is rebuilt from the settled hold
      means (`FGIFrequencyParametrisation.settled_cycle`) by
      `steady_cycle_indices`, two means within `z` standard errors of a
      difference being equal; the fitted model follows that selection of the
      $U_i$.

    **Raises:** `ValueError` where the periodic $u$ cannot be rebuilt from the
    $U_i$ (`RESULTS.cycle_not_rebuilt`) or the first block's averaged periods
    start before $u$ is periodic.

    `refined` holds `"frequency_response"` (the contract's entries) and
    `"cycle"`, `"ascending"`, `"descending"` (the refined $U_i$, as NBBI writes
    them); `standard_errors` the same with the errors in place of the values.
    """
    levels_np = np.asarray(levels, dtype=float)
    n = levels_np.shape[0]
    entries = closed_form.get("frequency_response", [])
    fgi_blocks, starts = [], []
    for b in blocks:
        w = float(b["omega"])
        mine = [
            e
            for e in entries
            if abs(float(e["base_omega"]) - w) <= 1e-9 * max(1.0, abs(w))
        ]
        if not mine:
            continue
        mine.sort(key=lambda e: int(e["k"]))
        fgi_blocks.append(
            FGIBlock(
                period_samples=int(b["period_samples"]),
                periods=int(b["periods"]),
                start=int(b["average_start"]),
                harmonics=tuple(int(e["k"]) for e in mine),
            )
        )
        starts.append(np.array([complex(float(e["re"]), float(e["im"])) for e in mine]))
    if len(fgi_blocks) == 0:
        raise ValueError("the closed form holds no frequency-response entry to refine")
    if sum(len(b.harmonics) for b in fgi_blocks) != len(entries):
        raise ValueError(
            "some frequency-response entries match no block of the design (omega)"
        )
    y_nbbi = np.asarray(y_nbbi, dtype=float)
    y_fgi = np.asarray(y_fgi, dtype=float)

    def model(fgi_cycle=None):
        return FGIFrequencyParametrisation(
            n_levels=n,
            nbbi_start=nbbi_start,
            hold_samples=hold_samples,
            settle_samples=settle_samples,
            blocks=fgi_blocks,
            dt=dt,
            fgi_cycle=fgi_cycle,
        )

    # The periodic u of the FGI record, rebuilt from the settled hold means (free
    # of the plain average's transient bias, which also inflates NBBI's stderr)
    # with their standard errors sigma / sqrt(N_s).
    p = model()
    settled_u, settled_se = p.settled_cycle(y_nbbi, y_fgi)
    index, rebuilt, first = steady_cycle_indices(
        settled_u, cycle_stderr=settled_se, z=z
    )
    if not bool(rebuilt):
        raise ValueError(RESULTS[RESULTS.cycle_not_rebuilt])
    transient = int(blocks[0].get("transient_periods", first))
    if transient < int(first):
        raise ValueError(
            f"the backlash output is periodic from period {int(first)} of the FGI "
            f"input on; the first block averages from period {transient}: raise the "
            "transient periods"
        )
    p = model(tuple(int(i) for i in np.asarray(index)))
    y = p.select(y_nbbi, y_fgi)
    # The closed form's U_i may carry the plain average's transient bias, which
    # makes a poor start; the settled start (`initial_theta`) is used where its
    # residual is smaller.
    given = p.pack(np.asarray(cycle_values, dtype=float), starts)
    settled = p.initial_theta(y_nbbi, y_fgi)
    rss = [float(jnp.sum((y - p.predict(t, y)) ** 2)) for t in (given, settled)]
    theta0 = given if rss[0] <= rss[1] else settled
    res = refine(p, theta0, y, y, options=options, throw=False)
    sigma = jnp.sqrt(p.replicate_noise_variance(y_nbbi, y_fgi))
    se = np.sqrt(np.diag(np.asarray(cramer_rao_bound(p, res.theta, y, sigma))))
    est = np.asarray(res.theta)
    cycle_levels = np.concatenate([levels_np, levels_np[-2:0:-1]])  # Eq. (4a-b)
    m = p.n_cycle

    def pack(x):
        u = x[:m]
        fr = [
            {
                "omega": k * w,
                "k": k,
                "base_omega": w,
                "re": float(x[m + 2 * j]),
                "im": float(x[m + 2 * j + 1]),
            }
            for j, (_, w, k) in enumerate(p.harmonic_list)
        ]
        desc = np.concatenate([u[n - 1 :], u[:1]])
        return {
            "frequency_response": fr,
            "cycle": [
                [float(V), float(U)] for V, U in zip(cycle_levels, u, strict=True)
            ],
            "ascending": [
                [float(V), float(U)] for V, U in zip(levels_np, u[:n], strict=True)
            ],
            "descending": [
                [float(V), float(U)] for V, U in zip(levels_np[::-1], desc, strict=True)
            ],
        }

    return {
        "refined": pack(est),
        "standard_errors": pack(se),
        "converged": bool(res.result == RESULTS.successful),
        "result": result_name(res.result),
        "steps": int(res.steps),
        "noise_std": float(sigma),
        "fitted_samples": int(p.n_record_samples),
    }
