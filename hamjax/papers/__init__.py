"""The papers hamjax implements, and the studies built on them.

One package per paper, each holding the plants of its examples, its reproductions
and its registered Monte Carlo studies (a `studies/` subpackage whose modules
`hamjax study` discovers):

- `seed000/`: Brouri, Giri, Rochdi, Chaoui, frequency identification of
  nonparametric backlash systems (NBBI, Table 1; FGI, Table 2). The procedures
  themselves are `hamjax/identification/seed000/`.
- `seed001/`: Giri, Rochdi, Chaoui, recursive identification of a piecewise-linear
  map with preload and dead zone ((4.1), Section V.C). The procedures are
  `hamjax/identification/seed001/`.
- `gap/`: the withheld-effect cases of the sim-to-real gap diagnosis (the blind
  case generator and scorer) and its studies.
- `engine/`: the Monte Carlo engine's own throughput study (no paper).
"""

# The packages whose modules are registered studies (`hamjax study --list`).
STUDY_PACKAGES = (
    "hamjax.papers.engine.studies",
    "hamjax.papers.gap.studies",
    "hamjax.papers.seed000.studies",
    "hamjax.papers.seed001.studies",
)
