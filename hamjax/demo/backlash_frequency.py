"""Demo section: seed 000's NBBI + FGI (Figs. 5, 6 analogues and a Bode plot)."""
