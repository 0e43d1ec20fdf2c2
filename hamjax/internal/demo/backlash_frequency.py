"""Demo section: seed 000's NBBI + FGI (Figs. 5, 6 analogues and a Bode plot)."""

from ...cli.methods.backlash_frequency import run as run
