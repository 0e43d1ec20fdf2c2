"""The command line's manners: --version, output safety checked before any work,
unstable models refused, --quiet/--verbose, file permissions, --help examples."""

import json
import os
import stat
import subprocess
import sys
import tomllib
from pathlib import Path

import numpy as np
import pytest

import hamjax
from hamjax.cli.main import main


ROOT = Path(__file__).resolve().parents[1]


def _hamjax(*args, cwd=None):
    """Run `python -m hamjax ARGS` in a child (exit status, stdout, stderr)."""
    env = dict(os.environ, PYTHONPATH=str(ROOT), HAMJAX_CACHE_DIR="off")
    p = subprocess.run(
        [sys.executable, "-m", "hamjax", *map(str, args)],
        capture_output=True,
        text=True,
        env=env,
        cwd=cwd,
    )
    return p.returncode, p.stdout, p.stderr


def _one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("hamjax: error:") and "Traceback" not in err, err
    return lines[0]


def test_version_flag_and_attribute_agree_with_pyproject():
    with open(ROOT / "pyproject.toml", "rb") as f:
        want = tomllib.load(f)["project"]["version"]
    assert hamjax.__version__ == want
    code, out, err = _hamjax("--version")
    assert code == 0 and out.strip() == f"hamjax {want}", (out, err)
