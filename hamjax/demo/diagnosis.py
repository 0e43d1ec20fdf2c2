"""Demo section: diagnosis of a built-in case whose saturation is withheld."""

from ..papers.gap.demo_cases import run_demo as run


__all__ = ["run"]
