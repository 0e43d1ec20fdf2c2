from .blind import make_case as make_case, make_cases as make_cases, score as score
from .case import GapCase as GapCase, read_case as read_case
from .diagnose import (
    GapDiagnosis as GapDiagnosis,
    diagnose_gap as diagnose_gap,
    diagnose_many as diagnose_many,
)
from .nominal_fit import fit_nominal as fit_nominal
