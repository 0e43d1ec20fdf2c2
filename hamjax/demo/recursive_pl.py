"""Demo section: seed 001's Section V.C reproduced (Fig. 3a/3b analogues)."""

from pathlib import Path

from ..papers.seed001.section_vc import write_section_vc


def run(key, out: Path) -> list[tuple[str, str]]:
    del key  # noise-free, as in the paper
    return write_section_vc(out, periods=1200, prefix="seed001_", dpi=110)[1]
