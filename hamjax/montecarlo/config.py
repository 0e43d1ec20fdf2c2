"""`MonteCarloConfig`: how many realisations, in chunks of which size."""

import equinox as eqx


class MonteCarloConfig(eqx.Module):
    """Size of a Monte Carlo run.

    **Arguments:**

    - `realisations`: number $R$ of realisations; realisation $r$ uses the key
      `jr.fold_in(key, r)`, $r = 0, \\dots, R-1$.
    - `chunk`: number $C$ of realisations computed by one compiled call (the
      memory bound). It is rounded up to a multiple of the device count.
    - `name`: study name, recorded in the output folder's manifest.
    """

    realisations: int = eqx.field(static=True)
    chunk: int = eqx.field(static=True)
    name: str = eqx.field(static=True)

    def __init__(self, *, realisations: int, chunk: int = 1024, name: str = ""):
        self.realisations = realisations
        self.chunk = chunk
        self.name = name

    def __check_init__(self):
        for field in ("realisations", "chunk"):
            value = getattr(self, field)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(
                    f"MonteCarloConfig.{field} must be an integer >= 1; got {value!r}"
                )
        if not isinstance(self.name, str):
            raise ValueError(
                f"MonteCarloConfig.name must be a string; got {self.name!r}"
            )
