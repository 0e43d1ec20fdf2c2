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


def test_summary_links_are_relative_to_the_summary(tmp_path, monkeypatch):
    # Sections name their files bare, through a relative OUT, or absolutely: every
    # link in summary.md must resolve from summary.md's own folder.
    from hamjax.cli.demo import _relative

    out = tmp_path / "demo-out"
    (out / "diagnosis").mkdir(parents=True)
    (out / "a.png").write_text("x")
    (out / "diagnosis" / "report.md").write_text("x")
    monkeypatch.chdir(tmp_path)
    rel_out = out.relative_to(tmp_path)
    for name in ("a.png", str(rel_out / "diagnosis" / "report.md"), out / "a.png"):
        link = _relative(name, rel_out)
        assert (out / link).is_file(), (name, link)
