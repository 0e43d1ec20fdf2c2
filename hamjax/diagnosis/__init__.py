"""The sim-to-real gap diagnosis: where the gap lies, which effect causes it, how far
it shrinks. (The withheld-effect case generator is `hamjax.papers.gap.blind`.)"""

from .case import GapCase as GapCase, read_case as read_case
from .diagnose import (
    GapDiagnosis as GapDiagnosis,
    diagnose_gap as diagnose_gap,
    diagnose_many as diagnose_many,
)
from .nominal_fit import fit_nominal as fit_nominal
