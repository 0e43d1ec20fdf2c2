"""Real measurements (issue 7): what does `hamjax diagnose` name on each usable
dataset of ../shared/data/real (cascaded tanks, CED, EMPS, Silverbox, DaISy sets,
stiction loops), against what the literature says? Adapters and splits:
`hamjax.diagnosis.real_data`.

    python studies/real_data_gap.py --realisations 80 --out results/real-data-gap

(realisations = number of stiction loops included).
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("real-data-gap", argv)


if __name__ == "__main__":
    sys.exit(main())
