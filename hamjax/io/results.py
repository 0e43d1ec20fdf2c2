"""result.json of the experiments contract from an identification result."""

import numpy as np

from .._results import RESULTS, result_name


def recursive_pl_result_dict(res, *, rho: float, estimator: str) -> dict:
    """result.json of the contract from a `RecursivePLResult`."""
    e = res.estimate
    named = res.structure is not None

    def num(x):
        return float(x) if named else None

    levels = np.asarray(res.levels)
    return {
        "method": "recursive-pl",
        "a": np.asarray(e.a).tolist(),
        "b": np.asarray(e.b).tolist(),
        "points": [
            [float(vj), float(fj)] for vj, fj in zip(levels, e.points, strict=True)
        ],
        "k1": float(e.k1),
        "k2": float(e.k2),
        "h1": float(e.h1),
        "h2": float(e.h2),
        "d1": num(e.d1),
        "d2": num(e.d2),
        "l1": num(e.l1),
        "l2": num(e.l2),
        "structure": res.structure,
        "consistent": bool(e.consistent),
        "result": result_name(res.result),
        "result_message": RESULTS[res.result],
        "theta": np.asarray(res.theta).tolist(),
        "singular_values": np.asarray(e.singular_values).tolist(),
        "excitation": float(res.stats["excitation"]),
        "residual_rms": float(res.stats["residual_rms"]),
        "estimator": estimator,
        "rho": rho,
        "note": "theta ordered as (3.8c): a1..an, mu_11..mu_n1, ..., mu_14..mu_n4; b "
        "normalised by (3.10) (sum b_i^2 = 1, first largest-magnitude entry > 0), "
        "points/k/h/l in that scale; d1, d2 signed (Fig. 2)",
    }
