"""Shared test helpers."""

import importlib.util
import sys
from pathlib import Path

import jax.tree_util as jtu
import numpy as np
import pytest
from scipy import signal

from hamjax._runtime import has_isa_cap


# Bitwise equality across batch widths and device counts rests on the ISA cap
# (`hamjax._runtime.same_rounding_in_every_lane`, which conftest applies), and the
# cap exists on x86-64 only: other CPUs always fuse multiply-adds.
CAPPED = has_isa_cap()
needs_isa_cap = pytest.mark.skipif(
    not CAPPED, reason="bitwise only under the ISA cap, which is x86-64's"
)


def tree_allclose(x, y, *, rtol=1e-10, atol=1e-12) -> bool:
    """Whether two pytrees have the same structure and allclose leaves."""
    lx, tx = jtu.tree_flatten(x)
    ly, ty = jtu.tree_flatten(y)
    if tx != ty:
        return False
    return all(
        np.allclose(a, b, rtol=rtol, atol=atol) for a, b in zip(lx, ly, strict=True)
    )


def reference_backlash(v, f_a, f_d, u0) -> np.ndarray:
    """The play operator of `../shared/tools/contract_check.py`, in plain NumPy:
    rising `u = max(u, f_a(v))`, falling `u = min(u, f_d(v))` (monotone borders)."""
    v = np.asarray(v, dtype=float)
    out, prev_v, u = np.empty(len(v)), v[0], float(u0)
    for k, x in enumerate(v):
        if x > prev_v:
            u = max(u, float(f_a(x)))
        elif x < prev_v:
            u = min(u, float(f_d(x)))
        out[k], prev_v = u, x
    return out


def reference_zoh(num, den, u, dt) -> np.ndarray:
    """Exact zero-order-hold response from rest by `scipy.signal.cont2discrete` and
    `dlsim` (an implementation independent of hamjax's matrix exponential)."""
    from scipy import signal

    ss = signal.tf2ss(np.asarray(num, float), np.asarray(den, float))
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete(ss, dt, method="zoh")
    y = signal.dlsim((Ad, Bd, Cd, Dd, dt), np.asarray(u, float))[1]
    return np.ravel(y)


def random_stable_poly(rng_values, radius: float = 0.95) -> np.ndarray:
    """Monic polynomial in q^-1 whose roots are `radius * x` for values in [-1, 1]
    taken in pairs (a complex pair per two values, a real root for an odd one)."""
    x = list(rng_values)
    roots = []
    while len(x) >= 2:
        r, phi = abs(x.pop()) * radius, x.pop() * np.pi
        roots += [r * np.exp(1j * phi), r * np.exp(-1j * phi)]
    if x:
        roots.append(x.pop() * radius)
    return np.real(np.poly(roots)) if roots else np.ones(1)


def run_on_two_devices(script: str, tmp_path, *, timeout: float = 600):
    """Run `script` (Python source; `sys.argv[1]` is an output `.npz` path) in a
    child process that sees 2 forced host CPU devices; return the loaded `.npz`."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    repo = Path(__file__).resolve().parents[1]
    path = tmp_path / "child.py"
    path.write_text(script)
    env = {
        **os.environ,
        # the parent's flags too (conftest's ISA cap: the same instructions)
        "XLA_FLAGS": os.environ.get("XLA_FLAGS", "")
        + " --xla_force_host_platform_device_count=2",
        "JAX_PLATFORMS": "cpu",
        "PYTHONPATH": str(repo),
    }
    out = tmp_path / "child_result.npz"
    proc = subprocess.run(
        [sys.executable, str(path), str(out)],
        env=env,
        cwd=repo,
        capture_output=True,
        text=True,
        timeout=timeout,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return np.load(out)


def child_env(devices: int) -> dict:
    """The environment of a `python -m hamjax` child process of this checkout that
    sees `devices` forced host CPU devices (and no GPU, no display)."""
    import os
    from pathlib import Path

    return {
        **os.environ,
        "XLA_FLAGS": f"--xla_force_host_platform_device_count={devices}",
        "JAX_PLATFORMS": "cpu",
        "PYTHONPATH": str(Path(__file__).resolve().parents[1]),
        "MPLBACKEND": "Agg",
    }


def free_port() -> int:
    """A TCP port free on localhost now (for a `--coordinator 127.0.0.1:PORT`)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def tree_hash(folder) -> str:
    """sha256 of every file's relative path and bytes below `folder`, in order."""
    import hashlib
    from pathlib import Path

    h = hashlib.sha256()
    for p in sorted(Path(folder).rglob("*")):
        if p.is_file():
            h.update(str(p.relative_to(folder)).encode())
            h.update(p.read_bytes())
    return h.hexdigest()


def run_hamjax(*args):
    """`python -m hamjax ARGS` from the repository root, in a clean environment."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    return subprocess.run(
        [sys.executable, "-m", "hamjax", *args],
        capture_output=True,
        text=True,
        cwd=root,
        env={
            "PYTHONPATH": str(root),
            "PATH": "/usr/bin:/bin",
            "HAMJAX_CACHE_DIR": os.environ["HAMJAX_CACHE_DIR"],  # the session's
        },
    )


# Seed 000, n = 5 levels where the ascending border rises above f_d(v_m) at V_2 and
# then falls (non-monotone) and the descending border stays above the output: the
# descending path never meets f_d, so from the second period of (24) u stays at
# its V_2 value on the last (inner) segment instead of returning to f_d(v_m).
INNER_LEVELS = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])
INNER_FA = np.array([-2.0, 1.0, 0.6, 0.2, -0.2])
INNER_FD = np.array([0.0, 2.0, 2.0, 2.0, 2.0])


def backlash_periods(backlash, levels, periods=3) -> np.ndarray:
    """The backlash model of hamjax.models on seed 000's (3) then `periods` cycles
    of (24): u on the staircase, one row per period."""
    import jax.numpy as jnp

    import hamjax as hj
    from hamjax.signals.staircase import staircase_cycle_levels

    cyc = np.asarray(staircase_cycle_levels(levels))
    v = np.concatenate([levels[-1:], levels[:1], *[cyc] * periods])
    u = np.asarray(hj.apply_nonlinearity(backlash, jnp.asarray(v)))
    return u[2:].reshape(periods, -1)


def assert_normal_equations_match_differences(theta, row, case, slot, *, h=1e-6):
    """`fit.normal_equations` of `row` at `theta` against central differences of
    the simulated residual (step `h`; rounding ~ eps/h ~ 1e-10 relative, so 1e-6
    is ample where the model is smooth), and slot `slot`'s column not zero."""
    import jax

    from hamjax.diagnosis.augmented import simulate_row
    from hamjax.diagnosis.fit import normal_equations

    # compiled once (op by op, every evaluation compiled the scans again)
    simulate = jax.jit(lambda t: simulate_row(t, row, case.v_est, case))

    def residual(t):
        return np.asarray((simulate(t) - case.y_est) * case.m_est / case.y_scale)

    r0 = residual(theta)
    J = np.stack(
        [
            (residual(theta + h * e) - residual(theta - h * e)) / (2 * h)
            for e in np.eye(theta.shape[0])
        ],
        axis=1,
    )
    sse, H, g = jax.jit(normal_equations)(theta, row, case)
    np.testing.assert_allclose(sse, r0 @ r0, rtol=1e-12)
    np.testing.assert_allclose(H, J.T @ J, rtol=1e-6, atol=1e-8 * np.abs(H).max())
    np.testing.assert_allclose(g, J.T @ r0, rtol=1e-6, atol=1e-8 * np.abs(g).max())
    j = list(np.asarray(row.idx)).index(slot)
    assert np.abs(J[:, j]).max() > 1e-3


def pi_loop(i: int, n: int = 2000):
    """A first-order plant under PI control acting within the sample, setpoint
    steps every 200 samples, a coloured output disturbance."""
    rng = np.random.default_rng([12, i])
    sp = np.repeat(rng.uniform(-1, 1, n // 200 + 1), 200)[:n]
    d = signal.lfilter([1.0], [1.0, -0.95], 0.1 * rng.standard_normal(n))
    v, y = np.zeros(n), np.zeros(n)
    v_prev = e_prev = 0.0
    for k in range(n):
        y[k] = 0.8 * y[k - 1] + 0.2 * v[k - 1] if k else 0.0
        e = sp[k] - (y[k] + d[k])
        v[k] = v_prev + 0.8 * (e - e_prev) + 0.3 * e
        v_prev, e_prev = v[k], e
    return y + d, v


BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def benchmark_module(name: str, *, register: bool = False):
    """The script `benchmarks/<name>.py` imported as a module; `register`: put it
    in `sys.modules` under `name` (a process pool pickles its functions by it)."""
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    if register:
        sys.modules[name] = module
    spec.loader.exec_module(module)
    return module
