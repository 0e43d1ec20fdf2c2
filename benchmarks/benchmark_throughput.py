"""Benchmark: Monte Carlo throughput of hamjax against NumPy and numba (issue 3).

Question: how many realisation-samples per second does hamjax push through

1. a Hammerstein plant with a backlash input (width 0.5; second-order linear part
   $B/A = (q^{-1} - 2 q^{-2}) / (1 - 1.5 q^{-1} + 0.56 q^{-2})$ of seed 001 V.C)
   driven by white Gaussian noise, keeping the mean, RMS and peak of the output, and
2. seed 001's normalised-gradient estimator with projection (4.1) on the plant of
   seed 001 Section V.C (n = 2, input (5.1), output noise of std 1), keeping the
   final estimate,

each over R realisations of T samples, compared in the same script on the same
data with (a) a plain NumPy/Python per-sample loop (timed on a few realisations and
scaled), (b) numba `@njit` per realisation, (c) numba `@njit(parallel=True)` with
`prange` over realisations, and for workload 1 (d) a Python backlash loop followed by
`scipy.signal.lfilter`? And what is hamjax's peak memory at R = 100,000?

Not a paper figure: the engineering benchmark of issue 3. Every method runs in its
own subprocess on the same data (drawn once by hamjax, `fold_in(key, r)` per
realisation, saved as `.npy`), after a warm-up that compiles it. Peak memory is that
process's peak resident set (`VmHWM` on Linux, which is `getrusage().ru_maxrss`
without the parent's peak that ru_maxrss inherits through fork+exec; interpreter,
imports and the data it holds included; the value right after the imports is
reported as `baseline_rss_mb`). hamjax processes see one XLA host device per core
(`--xla_force_host_platform_device_count`), so the engine shards over all cores as
numba's `prange` does.

*Inputs given.* Every method that is handed its inputs reads the same data file
as a read-only memory map (in the page cache after the first pass; each method
keeps the best of its repeats), the immutable host memory that the numba peers
read in place and that hamjax's `device_put` aliases. From a writable NumPy
array JAX must copy every chunk first (array semantics, not the simulation's
work): measured at 75-119 M samples/s on a 2-core VM, where first-touch page
faults dominate, it made the public batch's figure 0.4-0.9x numba prange from
run to run (2026-12-04).

    python benchmarks/benchmark_throughput.py --out results/benchmark        # full
    python benchmarks/benchmark_throughput.py --out /tmp/bench --quick       # ~1 min

Writes `benchmark.json` into `--out`. numba comes from the `bench` extra.
"""

import argparse
import json
import math
import os
import platform
import resource
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np


HERE = Path(__file__).resolve()
LEVELS = (-6.0, -3.0, 3.0, 6.0)
B, A = (0.0, 1.0, -2.0), (1.0, -1.5, 0.56)
WIDTH, INPUT_STD, NOISE_STD = 0.5, 1.0, 1.0
HAMJAX = {
    1: (
        "hamjax-time-major",
        "hamjax-vmap-scan",
        "hamjax-public-api",
        "hamjax-public-batch",
        "hamjax-engine",
    ),
    # For workload 2 the public API (vmap of seed001.normalised_gradient) is the
    # vmap-of-scan form; the public batch is seed001.normalised_gradient_batch.
    2: (
        "hamjax-time-major",
        "hamjax-public-api",
        "hamjax-public-batch",
        "hamjax-engine",
    ),
}
PEERS = {
    # numba-parallel-drawn: prange over realisations, each drawing its own normal
    # inputs inside the loop (np.random seeded per realisation), as the engine does.
    1: (
        "numpy-loop",
        "scipy-lfilter",
        "numba-njit",
        "numba-parallel",
        "numba-parallel-drawn",
    ),
    2: ("numpy-loop", "numba-njit", "numba-parallel"),
}
DRAWN = ("numba-parallel-drawn",)  # peers that draw their inputs (no data file)
LOOPED = ("numpy-loop", "scipy-lfilter")  # timed on a subset, then scaled


# --- workloads in hamjax -----------------------------------------------------------


def _workload1_trial(n_samples: int, unroll: int):
    from hamjax.papers.engine.studies.simulation_throughput import make_trial

    return make_trial(
        n_samples=n_samples, width=WIDTH, input_std=INPUT_STD, unroll=unroll
    )


def _workload2_trial(n_samples: int, unroll: int):
    """Seed 001 V.C: input (5.1), y = w + noise, (4.1) from theta0 = 0; theta*."""
    from hamjax.papers.seed001.studies._normalised_gradient_trial import (
        make_gradient_trial,
    )

    return make_gradient_trial(n_samples=n_samples, noise_std=NOISE_STD, unroll=unroll)


# --- peers: NumPy/Python, scipy, numba (the same algorithms, written per sample) -------


def _backlash_plant_py(v, out):
    """Backlash (hamjax.Backlash.from_width semantics) + DF2T filter; summaries."""
    c = WIDTH
    b0, b1, b2 = B
    a1, a2 = A[1], A[2]
    vp = v[0]
    u = vp  # centre of the play
    on_a = u == vp - c / 2
    on_d = u == vp + c / 2
    z0 = 0.0
    z1 = 0.0
    total = 0.0
    squares = 0.0
    peak = 0.0
    for k in range(v.shape[0]):
        vk = v[k]
        fa = vk - c / 2
        fd = vk + c / 2
        rising = vk > vp
        falling = vk < vp
        take_a = rising and (on_a or fa >= u)
        take_d = falling and (on_d or fd <= u)
        if take_a:
            u_new = fa
        elif take_d:
            u_new = fd
        else:
            u_new = u
        if rising or falling:
            on_a = take_a or u_new == fa
            on_d = take_d or u_new == fd
        u = u_new
        vp = vk
        y = b0 * u + z0
        z0 = (z1 + b1 * u) - a1 * y
        z1 = (0.0 + b2 * u) - a2 * y
        total += y
        squares += y * y
        peak = max(peak, abs(y))
    n = v.shape[0]
    out[0] = total / n
    out[1] = math.sqrt(squares / n)
    out[2] = peak


def _backlash_only_py(v, u_out):
    c = WIDTH
    vp = v[0]
    u = vp
    on_a = u == vp - c / 2
    on_d = u == vp + c / 2
    for k in range(v.shape[0]):
        vk = v[k]
        fa = vk - c / 2
        fd = vk + c / 2
        rising = vk > vp
        falling = vk < vp
        take_a = rising and (on_a or fa >= u)
        take_d = falling and (on_d or fd <= u)
        u_new = fa if take_a else (fd if take_d else u)
        if rising or falling:
            on_a = take_a or u_new == fa
            on_d = take_d or u_new == fd
        u = u_new
        vp = vk
        u_out[k] = u


def _normalised_gradient_numpy(y, g, theta0, rho):
    """(4.1a-b) per sample with NumPy vectors, as a reference implementation reads."""
    import numpy as np

    theta = theta0.copy()
    lags = np.zeros(2)
    for t in range(y.shape[0]):
        phi = np.concatenate([-lags, g[t]])
        e = y[t] - phi @ theta
        candidate = theta + phi * e / (1.0 + phi @ phi)
        norm = np.linalg.norm(candidate)
        theta = candidate * (rho / norm if norm > rho else 1.0)
        lags = np.array([y[t], lags[0]])
    return theta


def _normalised_gradient_scalar(y, g, theta0, rho, theta):
    """(4.1a-b) with scalar loops (for numba); writes the final estimate into theta."""
    p = theta0.shape[0]
    q = g.shape[1]
    for i in range(p):
        theta[i] = theta0[i]
    lag1 = 0.0
    lag2 = 0.0
    cand = np.empty(p)
    for t in range(y.shape[0]):
        e = y[t] + lag1 * theta[0] + lag2 * theta[1]
        nn = 1.0 + lag1 * lag1 + lag2 * lag2
        for j in range(q):
            e -= g[t, j] * theta[2 + j]
            nn += g[t, j] * g[t, j]
        gain = e / nn
        cand[0] = theta[0] - lag1 * gain
        cand[1] = theta[1] - lag2 * gain
        for j in range(q):
            cand[2 + j] = theta[2 + j] + g[t, j] * gain
        s = 0.0
        for i in range(p):
            s += cand[i] * cand[i]
        norm = math.sqrt(s)
        scale = rho / norm if norm > rho else 1.0
        for i in range(p):
            theta[i] = cand[i] * scale
        lag2 = lag1
        lag1 = y[t]


def _numba_kernels():
    import numba

    sim = numba.njit(cache=False)(_backlash_plant_py)
    ng = numba.njit(cache=False)(_normalised_gradient_scalar)

    @numba.njit(parallel=True, cache=False)
    def sim_parallel(V, out):
        for r in numba.prange(V.shape[0]):
            sim(V[r], out[r])

    @numba.njit(parallel=True, cache=False)
    def ng_parallel(Y, g, theta0, rho, out):
        for r in numba.prange(Y.shape[0]):
            ng(Y[r], g, theta0, rho, out[r])

    return sim, sim_parallel, ng, ng_parallel


def _numba_drawn_kernel():
    """Workload 1 in numba, each realisation drawing its own N(0, INPUT_STD^2)
    input sample by sample inside the loop (no input array), over all cores."""
    import numba

    @numba.njit(cache=False)
    def _drawn_plant(n, out):
        # The same algorithm as _backlash_plant_py with v[k] drawn when needed.
        c = WIDTH
        b0, b1, b2 = B
        a1, a2 = A[1], A[2]
        vk = INPUT_STD * np.random.standard_normal()
        vp = vk
        u = vp
        on_a = u == vp - c / 2
        on_d = u == vp + c / 2
        z0 = 0.0
        z1 = 0.0
        total = 0.0
        squares = 0.0
        peak = 0.0
        for k in range(n):
            if k > 0:
                vk = INPUT_STD * np.random.standard_normal()
            fa = vk - c / 2
            fd = vk + c / 2
            rising = vk > vp
            falling = vk < vp
            take_a = rising and (on_a or fa >= u)
            take_d = falling and (on_d or fd <= u)
            u_new = fa if take_a else (fd if take_d else u)
            if rising or falling:
                on_a = take_a or u_new == fa
                on_d = take_d or u_new == fd
            u = u_new
            vp = vk
            y = b0 * u + z0
            z0 = (z1 + b1 * u) - a1 * y
            z1 = (0.0 + b2 * u) - a2 * y
            total += y
            squares += y * y
            peak = max(peak, abs(y))
        out[0] = total / n
        out[1] = math.sqrt(squares / n)
        out[2] = peak

    @numba.njit(parallel=True, cache=False)
    def drawn_parallel(R, n, seed, out):
        for r in numba.prange(R):
            np.random.seed(seed + r)  # per realisation: any thread count
            _drawn_plant(n, out[r])

    return drawn_parallel


# --- worker: one method in its own process ------------------------------------------


def _rss_mb() -> float:
    """Peak resident memory of this process (MiB).

    Linux: `VmHWM` of /proc/self/status, the peak of this address space. It is what
    `getrusage(RUSAGE_SELF).ru_maxrss` reports, except that ru_maxrss survives
    fork+exec and so would include the (larger) parent's peak; elsewhere ru_maxrss.
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    scale = 1024.0 * 1024.0 if sys.platform == "darwin" else 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / scale


def _worker(args) -> None:
    import numpy as np

    baseline = None
    method, workload = args.worker, args.workload
    result: dict = {"method": method, "workload": workload}
    if method.startswith("hamjax"):
        import jax

        import hamjax as hj

        hj.enable_x64()
        result["devices"] = len(jax.devices())
    baseline = _rss_mb()
    if method == "hamjax-engine":
        runs = [_run_engine(args, workload) for _ in range(args.repeats)]
    elif method in DRAWN:
        runs = [_run_numba_drawn(args) for _ in range(args.repeats)]
    elif method == "hamjax-ablation":
        result["ablation"] = _run_ablation(args, workload)
        result["peak_rss_mb"] = _rss_mb()
        Path(args.result).write_text(json.dumps(result, indent=2))
        return
    else:
        # read-only, the same for every method (module docstring, *Inputs given*)
        data = np.load(args.data, mmap_mode="r")
        if method in LOOPED:
            data = np.ascontiguousarray(data[: args.subset])
        aux = np.load(args.aux) if args.aux else None
        runs = [
            _run_on_data(args, method, workload, data, aux) for _ in range(args.repeats)
        ]
    # Steady state: the best of the repeats (the first pass of a process also pays
    # first-touch page faults on freshly allocated buffers).
    outputs, seconds, compile_s, n = min(runs, key=lambda run: run[1])
    result.update(
        realisations_timed=n,
        samples=args.samples,
        seconds=seconds,
        compile_seconds=compile_s,
        throughput=n * args.samples / seconds,
        peak_rss_mb=_rss_mb(),
        baseline_rss_mb=baseline,
        chunk=args.chunk,
        unroll=args.unroll,
    )
    np.save(args.result + ".npy", np.asarray(outputs))
    Path(args.result).write_text(json.dumps(result, indent=2))


def _run_engine(args, workload):
    import jax.random as jr

    from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo

    if workload == 1:
        trial = _workload1_trial(args.samples, args.unroll)
        pick = lambda res: res["rms"]  # noqa: E731
    else:
        trial, _ = _workload2_trial(args.samples, args.unroll)
        pick = lambda res: res  # noqa: E731
    key = jr.fold_in(jr.key(args.seed), workload)
    start = time.perf_counter()
    # Warm-up: the same trial object and chunk shape, so the real run reuses it.
    run_monte_carlo(key, trial, MonteCarloConfig(realisations=1, chunk=args.chunk))
    compile_s = time.perf_counter() - start
    config = MonteCarloConfig(realisations=args.realisations, chunk=args.chunk)
    start = time.perf_counter()
    res = run_monte_carlo(key, trial, config, quiet=True)
    seconds = time.perf_counter() - start
    return pick(res), seconds, compile_s, args.realisations


def _run_numba_drawn(args):
    import numpy as np

    drawn_parallel = _numba_drawn_kernel()
    R = args.realisations
    out = np.empty((R, 3))
    t0 = time.perf_counter()
    drawn_parallel(min(R, 4), 100, args.seed, out)
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    drawn_parallel(R, args.samples, args.seed, out)
    return out[:, 1], time.perf_counter() - t0, compile_s, R


def _hamjax_on_data(data, batched_fn, chunk, devices=None, repeats=1):
    """Run `batched_fn(chunk of data (C, T)) -> (C, ...)` over the rows of `data`,
    sharded over the devices, the last chunk padded; returns outputs, the best of
    `repeats` times, and the compile time."""
    import jax
    import numpy as np

    from hamjax.simulation.sharding import effective_chunk, realisation_sharding

    sharding = realisation_sharding(devices)
    C = effective_chunk(chunk, sharding.mesh.devices.size)
    fn = jax.jit(batched_fn, in_shardings=sharding, out_shardings=sharding)
    R = data.shape[0]

    def block(start):
        x = data[start : start + C]
        if x.shape[0] < C:
            x = np.concatenate([x, np.repeat(x[-1:], C - x.shape[0], axis=0)])
        return jax.device_put(x, sharding)

    t0 = time.perf_counter()
    jax.block_until_ready(fn(block(0)))
    compile_s = time.perf_counter() - t0
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        outs = [fn(block(s)) for s in range(0, R, C)]
        host = np.concatenate([np.asarray(o) for o in outs])[:R]
        best = min(best, time.perf_counter() - t0)
    return host, best, compile_s


def _batched_fns(workload, samples, unroll, aux):
    """hamjax functions of a (C, T) data block for the on-data methods."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    import hamjax as hj
    from hamjax.identification import seed001 as rpl
    from hamjax.identification.seed001.normalised_gradient_4_1 import (
        normalised_gradient_time_major,
    )
    from hamjax.simulation.time_major import output_summary, output_summary_time_major

    if workload == 1:
        plant = _workload1_trial(samples, unroll).plant

        def public(V):
            w = jax.vmap(lambda v: hj.simulate(plant, v))(V)
            return jnp.sqrt(jnp.mean(w**2, axis=1))

        def public_batch(V):
            w = hj.simulate_batch(plant, V, unroll=unroll)
            return jnp.sqrt(jnp.mean(w**2, axis=1))

        return {
            "hamjax-public-batch": public_batch,
            "hamjax-time-major": lambda V: output_summary_time_major(
                plant, V.T, unroll=unroll
            )["rms"],
            "hamjax-vmap-scan": lambda V: eqx.filter_vmap(
                lambda v: output_summary(plant, v, unroll=unroll)["rms"]
            )(V),
            "hamjax-public-api": public,
        }
    v, g, rho = jnp.asarray(aux["v"]), jnp.asarray(aux["g"]), float(aux["rho"])
    levels = jnp.asarray(LEVELS)

    def one(y):
        phi = rpl.regressor(v, y, levels=levels, order=2)
        return rpl.normalised_gradient(phi, y, theta0=jnp.zeros(10), rho=rho)[0]

    return {
        "hamjax-time-major": lambda Y: normalised_gradient_time_major(
            Y.T, g, order=2, theta0=jnp.zeros(10), rho=rho, unroll=unroll
        ),
        "hamjax-vmap-scan": jax.vmap(one),
        "hamjax-public-api": jax.vmap(one),
        "hamjax-public-batch": lambda Y: rpl.normalised_gradient_batch(
            v, Y, levels=levels, order=2, theta0=jnp.zeros(10), rho=rho, unroll=unroll
        ),
    }


def _run_on_data(args, method, workload, data, aux):
    import numpy as np

    R = data.shape[0]
    if method.startswith("hamjax"):
        fn = _batched_fns(workload, args.samples, args.unroll, aux)[method]
        out, seconds, compile_s = _hamjax_on_data(data, fn, args.chunk)
        return out, seconds, compile_s, R
    if method == "numpy-loop":
        if workload == 1:
            out = np.empty((R, 3))
            t0 = time.perf_counter()
            for r in range(R):
                _backlash_plant_py(data[r], out[r])
            return out[:, 1], time.perf_counter() - t0, 0.0, R
        g, rho = aux["g"], float(aux["rho"])
        t0 = time.perf_counter()
        out = [
            _normalised_gradient_numpy(data[r], g, np.zeros(10), rho) for r in range(R)
        ]
        return np.asarray(out), time.perf_counter() - t0, 0.0, R
    if method == "scipy-lfilter":
        import scipy.signal

        t0 = time.perf_counter()
        u = np.empty_like(data)
        for r in range(R):
            _backlash_only_py(data[r], u[r])
        w = scipy.signal.lfilter(B, A, u, axis=1)
        rms = np.sqrt(np.mean(w**2, axis=1))
        return rms, time.perf_counter() - t0, 0.0, R
    sim, sim_parallel, ng, ng_parallel = _numba_kernels()
    if workload == 1:
        out = np.empty((R, 3))
        small = min(R, 4)
        t0 = time.perf_counter()
        if method == "numba-njit":
            sim(data[0], out[0])
        else:
            sim_parallel(data[:small], out[:small])
        compile_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        if method == "numba-njit":
            for r in range(R):
                sim(data[r], out[r])
        else:
            sim_parallel(data, out)
        return out[:, 1], time.perf_counter() - t0, compile_s, R
    g, rho = np.ascontiguousarray(aux["g"]), float(aux["rho"])
    theta0 = np.zeros(10)
    out = np.empty((R, 10))
    t0 = time.perf_counter()
    if method == "numba-njit":
        ng(data[0], g, theta0, rho, out[0])
    else:
        ng_parallel(data[:2], g, theta0, rho, out[:2])
    compile_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    if method == "numba-njit":
        for r in range(R):
            ng(data[r], g, theta0, rho, out[r])
    else:
        ng_parallel(data, g, theta0, rho, out)
    return out, time.perf_counter() - t0, compile_s, R


def _run_ablation(args, workload):
    """Throughput of the hamjax layouts for several unroll / chunk / device counts."""
    import jax
    import numpy as np

    data = np.load(args.data, mmap_mode="r")[: args.subset]
    data = np.ascontiguousarray(data)
    aux = np.load(args.aux) if args.aux else None
    n = data.shape[0] * args.samples
    rows = []
    u0 = args.unroll
    configs = [("hamjax-time-major", u, args.chunk, None) for u in (1, 2, 4, 8)]
    configs += [("hamjax-time-major", u0, c, None) for c in (512, 8192)]
    configs += [("hamjax-time-major", u0, args.chunk, jax.devices()[:1])]
    configs += [("hamjax-vmap-scan", u, args.chunk, None) for u in (1, 4)]
    configs += [("hamjax-vmap-scan", 1, args.chunk, jax.devices()[:1])]
    for method, unroll, chunk, devices in configs:
        fn = _batched_fns(workload, args.samples, unroll, aux)[method]
        _, seconds, _ = _hamjax_on_data(data, fn, chunk, devices, repeats=2)
        rows.append(
            {
                "method": method,
                "unroll": unroll,
                "chunk": chunk,
                "devices": len(devices) if devices else len(jax.devices()),
                "throughput": n / seconds,
            }
        )
        print(json.dumps(rows[-1]), file=sys.stderr, flush=True)
    return rows


# --- orchestration ---------------------------------------------------------------------


def _make_data(out: Path, args) -> dict:
    """Draw the data of both workloads with hamjax keys; save them as .npy."""
    import jax.random as jr
    import numpy as np

    import hamjax as hj
    from hamjax.montecarlo import MonteCarloConfig, run_monte_carlo

    hj.enable_x64()
    paths = {}
    config = MonteCarloConfig(realisations=args.realisations, chunk=args.chunk)
    trial1 = _workload1_trial(args.samples, 1)
    v = run_monte_carlo(jr.fold_in(jr.key(args.seed), 1), trial1._inputs, config)
    paths[1] = (out / "data_w1.npy", None)
    np.save(paths[1][0], v)
    del v
    trial2, theta_star = _workload2_trial(args.samples, 1)
    y = run_monte_carlo(jr.fold_in(jr.key(args.seed), 2), trial2.outputs, config)
    aux = out / "aux_w2.npz"
    np.savez(
        aux,
        v=np.asarray(trial2.v),
        g=np.asarray(trial2.g),
        rho=trial2.rho,
        theta_star=np.asarray(theta_star),
    )
    paths[2] = (out / "data_w2.npy", aux)
    np.save(paths[2][0], y)
    return paths


def _default_unroll(args, workload: int) -> int:
    return args.unroll if args.unroll > 0 else {1: 1, 2: 4}[workload]


def _spawn(args, out: Path, method: str, workload: int, data, aux, **extra) -> dict:
    tag = f"w{workload}_{method}" + "".join(f"_{k}{v}" for k, v in extra.items())
    result = out / f"{tag}.json"
    cmd = [
        sys.executable,
        str(HERE),
        "--worker",
        method,
        "--workload",
        str(workload),
        "--samples",
        str(args.samples),
        "--realisations",
        str(args.realisations),
        "--chunk",
        str(extra.get("chunk", args.chunk)),
        "--unroll",
        str(extra.get("unroll", _default_unroll(args, workload))),
        "--seed",
        str(args.seed),
        "--repeats",
        str(args.repeats),
        "--subset",
        str(extra.get("subset", args.loop_subset)),
        "--result",
        str(result),
        "--out",
        str(out),
    ]
    if "realisations" in extra:
        cmd[cmd.index("--realisations") + 1] = str(extra["realisations"])
    if data is not None:
        cmd += ["--data", str(data)]
    if aux is not None:
        cmd += ["--aux", str(aux)]
    env = dict(os.environ)
    cores = os.cpu_count() or 1
    env["XLA_FLAGS"] = f"--xla_force_host_platform_device_count={cores}"
    env.setdefault("JAX_PLATFORMS", "cpu")
    print(f"[benchmark] {tag} ...", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3600)
    if proc.returncode != 0:
        print(proc.stderr[-4000:], file=sys.stderr)
        return {"method": method, "error": proc.stderr.strip().splitlines()[-1:]}
    res = json.loads(result.read_text())
    res["wall_seconds"] = time.perf_counter() - t0
    print(f"[benchmark]   {json.dumps(_brief(res))}", file=sys.stderr, flush=True)
    return res


def _brief(res: dict) -> dict:
    keys = ("throughput", "seconds", "peak_rss_mb", "realisations_timed")
    return {k: res[k] for k in keys if k in res}


def _agreement(out: Path, tags: dict) -> dict:
    """Max relative difference of each method's outputs from hamjax-time-major."""
    import numpy as np

    ref_path = tags.get("hamjax-time-major")
    if ref_path is None or not Path(ref_path).exists():
        return {}
    ref = np.load(ref_path)
    diffs = {}
    for method, path in tags.items():
        if method == "hamjax-time-major" or not Path(path).exists():
            continue
        got = np.load(path)
        r = ref[: got.shape[0]]
        diffs[method] = float(np.max(np.abs(got - r) / np.maximum(np.abs(r), 1e-300)))
    return diffs


def _orchestrate(args) -> int:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    work = out / "_work"
    work.mkdir(exist_ok=True)
    t_start = time.perf_counter()
    print("[benchmark] drawing the data ...", file=sys.stderr, flush=True)
    paths = _make_data(work, args)
    report: dict = {
        "question": "realisation-samples/s of hamjax vs NumPy loop, numba, scipy",
        "command": " ".join([Path(sys.executable).name, *sys.argv]),
        "config": {
            "realisations": args.realisations,
            "samples": args.samples,
            "chunk": args.chunk,
            "unroll": {w: _default_unroll(args, w) for w in (1, 2)},
            "seed": args.seed,
            "loop_subset": args.loop_subset,
            "repeats": args.repeats,
            "memory_realisations": args.memory_realisations,
            "quick": args.quick,
            "inputs_given": "the data file as a read-only memory map, every method",
        },
        "machine": _machine(),
        "memory_method": "peak RSS (VmHWM, = getrusage ru_maxrss of the worker's own "
        "address space) of each worker process; includes interpreter, imports and "
        "the data it maps (workers on data map all R x T samples, resident as they "
        "are read; hamjax-engine draws them chunk by chunk)",
        "throughput_unit": "realisation-samples per second",
    }
    for workload in (1, 2):
        data, aux = paths[workload]
        methods = {}
        for method in (*HAMJAX[workload], *PEERS[workload]):
            given = (None, None) if method in DRAWN else (data, aux)
            methods[method] = _spawn(args, work, method, workload, *given)
        tags = {m: str(work / f"w{workload}_{m}.json.npy") for m in methods}
        section = {
            "methods": methods,
            "max_rel_diff_vs_hamjax_time_major": _agreement(work, tags),
        }
        section["ratios"] = _ratios(methods)
        if not args.no_ablation:
            abl = _spawn(
                args,
                work,
                "hamjax-ablation",
                workload,
                data,
                aux,
                subset=min(args.realisations, args.ablation_subset),
            )
            section["ablation"] = abl.get("ablation", abl)
        report[f"workload{workload}"] = section
        _write(out, report)
    if args.memory_realisations > 0:
        mem = _spawn(
            args,
            work,
            "hamjax-engine",
            1,
            None,
            None,
            realisations=args.memory_realisations,
        )
        report["memory"] = {
            "workload": 1,
            "realisations": args.memory_realisations,
            "samples": args.samples,
            "chunk": args.chunk,
            "peak_rss_mb": mem.get("peak_rss_mb"),
            "baseline_rss_mb": mem.get("baseline_rss_mb"),
            "throughput": mem.get("throughput"),
            "under_2gb": (mem.get("peak_rss_mb") or 1e9) < 2048,
        }
        small = report.get("workload1", {}).get("methods", {}).get("hamjax-engine", {})
        if small.get("peak_rss_mb") and mem.get("peak_rss_mb"):
            # Flat in R: the engine's peak at R = --realisations vs the probe's R.
            report["memory"]["peak_rss_mb_at_realisations"] = {
                str(args.realisations): small["peak_rss_mb"],
                str(args.memory_realisations): mem["peak_rss_mb"],
            }
            report["memory"]["peak_ratio"] = mem["peak_rss_mb"] / small["peak_rss_mb"]
    report["table"] = {
        f"workload{w}": {
            m: res.get("throughput")
            for m, res in report.get(f"workload{w}", {}).get("methods", {}).items()
        }
        for w in (1, 2)
    }
    report["targets"] = _targets(report)
    report["total_seconds"] = time.perf_counter() - t_start
    _write(out, report)
    if not args.keep_data:
        shutil.rmtree(work, ignore_errors=True)
    print(json.dumps(report["targets"], indent=2))
    print(f"wrote {out / 'benchmark.json'}")
    return 0


def _ratios(methods: dict) -> dict:
    ratios = {}
    for h in (
        "hamjax-time-major",
        "hamjax-engine",
        "hamjax-public-api",
        "hamjax-public-batch",
    ):
        th = methods.get(h, {}).get("throughput")
        for peer, res in methods.items():
            tp = res.get("throughput")
            if th and tp and not peer.startswith("hamjax"):
                ratios[f"{h} / {peer}"] = th / tp
    return ratios


def _targets(report: dict) -> dict:
    out = {}
    r1 = report.get("workload1", {}).get("ratios", {})
    fair = r1.get("hamjax-engine / numba-parallel-drawn")
    out["workload1 hamjax-engine >= 1.5x numba-parallel-drawn (both draw inside)"] = (
        None if fair is None else bool(fair >= 1.5)
    )
    for w in (1, 2):
        r = report.get(f"workload{w}", {}).get("ratios", {})
        for h in ("hamjax-public-batch", "hamjax-time-major", "hamjax-engine"):
            par = r.get(f"{h} / numba-parallel")
            loop = r.get(f"{h} / numpy-loop")
            out[f"workload{w} {h} >= 1.0x numba-parallel"] = (
                None if par is None else bool(par >= 1.0)
            )
            out[f"workload{w} {h} >= 200x numpy-loop"] = (
                None if loop is None else bool(loop >= 200)
            )
    mem = report.get("memory")
    if mem:
        out[f"peak memory at R={mem['realisations']} < 2 GB"] = mem["under_2gb"]
    return out


def _machine() -> dict:
    from importlib import metadata

    versions = {}
    for name in ("jax", "jaxlib", "equinox", "numpy", "numba", "scipy"):
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    try:
        load = os.getloadavg()
    except OSError:
        load = None
    return {
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "python": platform.python_version(),
        "load_average_at_start": load,
        "versions": versions,
    }


def _write(out: Path, report: dict) -> None:
    tmp = out / ".benchmark.json.tmp"
    tmp.write_text(json.dumps(report, indent=2) + "\n")
    os.replace(tmp, out / "benchmark.json")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/benchmark"))
    parser.add_argument("--realisations", type=int, default=10_000)
    parser.add_argument("--samples", type=int, default=10_000)
    parser.add_argument(
        "--chunk",
        type=int,
        default=512,
        help="realisations per compiled call (split over the devices; default 512)",
    )
    parser.add_argument(
        "--unroll",
        type=int,
        default=0,
        help="scan unroll of the hamjax kernels (default: 1 for workload 1, 4 for 2, "
        "the best in our ablation)",
    )
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--loop-subset",
        type=int,
        default=4,
        help="realisations timed for the NumPy/Python and scipy loops (then scaled)",
    )
    parser.add_argument(
        "--repeats",
        type=int,
        default=2,
        help="timed passes per method, the fastest is reported (default 2)",
    )
    parser.add_argument("--ablation-subset", type=int, default=8192)
    parser.add_argument("--memory-realisations", type=int, default=100_000)
    parser.add_argument("--no-ablation", action="store_true")
    parser.add_argument("--keep-data", action="store_true")
    parser.add_argument(
        "--quick",
        action="store_true",
        help="tiny sizes (R=128, T=500, memory probe R=512): a smoke run",
    )
    # worker mode (internal)
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    parser.add_argument("--workload", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--data", help=argparse.SUPPRESS)
    parser.add_argument("--aux", help=argparse.SUPPRESS)
    parser.add_argument("--subset", type=int, default=4, help=argparse.SUPPRESS)
    parser.add_argument("--result", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        _worker(args)
        return 0
    import matplotlib

    matplotlib.use("Agg")  # house rule for studies; this one draws no figure
    if args.quick:
        args.realisations = min(args.realisations, 128)
        args.samples = min(args.samples, 500)
        args.chunk = min(args.chunk, 64)
        args.memory_realisations = min(args.memory_realisations, 512)
        args.loop_subset = min(args.loop_subset, 1)
        args.ablation_subset = min(args.ablation_subset, 128)
    for name in ("realisations", "samples", "chunk", "loop_subset"):
        if getattr(args, name) < 1:
            parser.error(f"--{name.replace('_', '-')} must be >= 1")
    return _orchestrate(args)


if __name__ == "__main__":
    sys.exit(main())
