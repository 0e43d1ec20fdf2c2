"""`hamjax demo`: every section is importable and defines `run(key, out)`."""

import importlib
import inspect

import pytest

from hamjax.cli.demo import SECTIONS


@pytest.mark.parametrize("title, module", SECTIONS, ids=[m for _, m in SECTIONS])
def test_every_demo_section_defines_run(title, module):
    run = getattr(importlib.import_module(module), "run", None)
    assert callable(run), f"{module} ({title}) defines no run(key, out)"
    assert len(inspect.signature(run).parameters) == 2
