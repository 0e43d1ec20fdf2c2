"""Demo section: seed 000's NBBI + FGI (Figs. 5, 6 analogues and a Bode plot)."""

from ..papers.seed000.fig6_example import demo_run as run


__all__ = ["run"]
