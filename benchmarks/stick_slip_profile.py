"""How fast is the stick-slip profile's grid scoring as one scan, against the
same least squares as separate passes on the host?

Both score the same chunks of `layout.PROFILE_CHUNK` grid points (S, J) of the
He et al. play on a random-walk command of `--samples` samples, with a
second-order 1/A, the lags 1..3 and a constant:

- **scan** (what `layout.stick_slip_profile` runs): `layout._profile_sums`, the
  valve, 1/A and the lagged sums in one JAX scan over blocks of time, the normal
  equations solved by `layout._solve_lagged`;
- **host passes** (the reference, what it ran before): the valve positions by a
  JAX scan over a grid x time array (`layout._valve_positions`), then
  `scipy.signal.lfilter` and the lagged products in NumPy
  (`layout._free_numerator_sse`).

Each is timed on one thread and on `--threads` threads (one chunk each, as
`diagnose_many` prepares one case per core), median of `--repeats`, after a
warm-up (compilation excluded).

    python benchmarks/stick_slip_profile.py --out results/profile

Writes `stick_slip_profile.json` (seconds per chunk, the ratio host/scan per
thread count, the largest relative SSE difference, the machine).
"""

import argparse
import json
import os
import platform
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
from _timing import median_time
from scipy.signal import lfilter


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=3000)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--out", type=Path, default=Path("results/profile"))
    args = parser.parse_args(argv)

    import hamjax
    from hamjax._runtime import split_cpu_into_devices

    split_cpu_into_devices()
    hamjax.enable_x64()
    from hamjax.diagnosis.layout import (
        PROFILE_CHUNK,
        _free_numerator_sse,
        _profile_sums,
        _solve_lagged,
        _valve_positions,
    )

    rng = np.random.default_rng([7, 0])
    n = args.samples
    v = np.cumsum(rng.standard_normal(n)) * 0.1
    y = rng.standard_normal(n)
    a = np.array([1.0, -1.6, 0.7])
    lags = np.array([1, 2, 3])
    chunks = [
        (S, S * rng.uniform(0.0, 0.9, PROFILE_CHUNK))
        for S in rng.uniform(0.01, 0.5, (args.threads, PROFILE_CHUNK)) * np.ptp(v)
    ]

    def scan(chunk):
        S, J = chunk
        gram, rhs, total = _profile_sums(
            v, y, S, J, a, np.zeros(6), slide=False, mapped=(False,), depth=4
        )
        return _solve_lagged(gram[0], rhs[0], total[0], y, lags, level=True)[0]

    def host(chunk):
        S, J = chunk
        x = np.asarray(_valve_positions(v, S, J, slide=False))
        u = lfilter([1.0], a, x, axis=-1)
        return _free_numerator_sse(u, y, lags, level=True)[0]

    worst = max(
        float(np.max(np.abs(scan(c) - host(c)) / np.maximum(host(c), 1e-300)))
        for c in chunks
    )
    result = {"samples": n, "grid_points_per_chunk": PROFILE_CHUNK}
    for name, f in (("scan", scan), ("host_passes", host)):
        one = median_time(lambda f=f: f(chunks[0]), args.repeats)
        with ThreadPoolExecutor(args.threads) as pool:
            many = median_time(
                lambda f=f: list(pool.map(f, chunks)), args.repeats
            ) / len(chunks)
        result[name] = {"s_per_chunk_1_thread": one, "s_per_chunk_threads": many}
        print(
            f"{name:12s} {one * 1e3:8.1f} ms/chunk on 1 thread, "
            f"{many * 1e3:8.1f} ms/chunk on {args.threads}"
        )
    result["ratio_host_over_scan_1_thread"] = (
        result["host_passes"]["s_per_chunk_1_thread"]
        / result["scan"]["s_per_chunk_1_thread"]
    )
    result["ratio_host_over_scan_threads"] = (
        result["host_passes"]["s_per_chunk_threads"]
        / result["scan"]["s_per_chunk_threads"]
    )
    result["max_relative_sse_difference"] = worst
    result["threads"] = args.threads
    result["machine"] = {
        "platform": platform.platform(),
        "cores": len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
    }
    print(
        f"host/scan: {result['ratio_host_over_scan_1_thread']:.2f} on 1 thread, "
        f"{result['ratio_host_over_scan_threads']:.2f} on {args.threads}; "
        f"largest relative SSE difference {worst:.1e}"
    )
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "stick_slip_profile.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
