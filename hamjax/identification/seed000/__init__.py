"""Seed 000 (Brouri, Giri, Rochdi, Chaoui): NBBI (Table 1, `nbbi_table1.py`), FGI
(Table 2, `fgi_table2.py`) and the exact Fourier coefficients (13), (22) they use."""

from .fgi_table2 import FGIResult as FGIResult, identify_fgi as identify_fgi
from .nbbi_table1 import NBBIResult as NBBIResult, identify_nbbi as identify_nbbi
