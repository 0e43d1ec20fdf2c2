"""Blind withheld-effect benchmark of `hamjax diagnose` (issue 7): in exact and
realistic modes, how often is the withheld effect named, how often is an effect
named on `none` cases, how far does the gap shrink, how fast?

    python studies/blind_benchmark.py --realisations 240 --seed 100 --out results/blind

(realisations = cases per mode). Equivalent, case folders on disk:
`hamjax blind make --cases 240 --seed 100 --out B && hamjax diagnose B/cases/* --out R
&& hamjax blind score B R`.
"""

import sys

from hamjax.cli.study import study_main


def main(argv: list[str] | None = None) -> int:
    return study_main("blind-benchmark", argv)


if __name__ == "__main__":
    sys.exit(main())
