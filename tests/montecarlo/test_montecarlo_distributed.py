"""A registered study run as 2 processes (jax.distributed on localhost, CPU
collectives) gives exactly the 1-process numbers; process 0 alone writes."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import child_env, free_port


REPO = Path(__file__).resolve().parents[2]
STUDY = [
    "simulation-throughput",
    "--realisations",
    "11",
    "--samples",
    "130",
    "--chunk",
    "4",
    "--seed",
    "3",
    "--quiet",
]


def _study(out: Path, *extra: str, devices: int) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-m", "hamjax", "study", *STUDY, "--out", str(out), *extra],
        env=child_env(devices),
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait(procs, timeout=240):
    outs = []
    try:
        for p in procs:
            stdout, stderr = p.communicate(timeout=timeout)
            assert p.returncode == 0, stderr[-3000:]
            outs.append(stdout)
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    return outs


def _chunks(out: Path) -> dict:
    folder = out / "realisations" / "chunks"
    result = {}
    for path in sorted(folder.glob("chunk_*.npz")):
        with np.load(path) as data:
            result[path.name] = {k: data[k] for k in data.files}
    return result


@pytest.mark.slow
def test_two_processes_give_the_one_process_numbers(tmp_path):
    one = tmp_path / "one"
    _wait([_study(one, devices=2)])
    two = tmp_path / "two"
    address = f"127.0.0.1:{free_port()}"
    cluster = ["--coordinator", address, "--num-processes", "2"]
    procs = [_study(two, *cluster, "--process-id", str(i), devices=1) for i in (0, 1)]
    _wait(procs)

    a, b = _chunks(one), _chunks(two)
    assert list(a) == list(b) and len(a) == 3  # 4 + 4 + 3, written once
    for name in a:
        for leaf in a[name]:
            np.testing.assert_array_equal(b[name][leaf], a[name][leaf])
    s1 = json.loads((one / "summary.json").read_text())
    s2 = json.loads((two / "summary.json").read_text())
    assert s2["output_rms"] == s1["output_rms"]
    manifest = json.loads((two / "realisations" / "manifest.json").read_text())
    assert manifest["processes"] == 2 and manifest["devices"] == 2

    # Resume as 2 processes: the finished chunks are read by process 0 and shared.
    (two / "realisations" / "chunks" / next(iter(b))).unlink()
    address = f"127.0.0.1:{free_port()}"
    cluster = ["--coordinator", address, "--num-processes", "2"]
    _wait([_study(two, *cluster, "--process-id", str(i), devices=1) for i in (0, 1)])
    assert (
        json.loads((two / "summary.json").read_text())["output_rms"]
        == (s1["output_rms"])
    )
    for name, leaves in _chunks(two).items():
        for leaf in leaves:
            np.testing.assert_array_equal(leaves[leaf], a[name][leaf])


def test_cluster_options_need_a_coordinator(tmp_path):
    proc = _study(tmp_path, "--num-processes", "2", devices=1)
    _, stderr = proc.communicate(timeout=120)
    assert proc.returncode == 2 and "--coordinator" in stderr
