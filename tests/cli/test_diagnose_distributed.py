"""`hamjax diagnose CASE... --coordinator ... --num-processes N --process-id I`:
the cases split over processes by blocks of the sorted case list; 2 processes on
localhost write every case once and exactly the 1-process files."""

import re
import subprocess
import sys
from pathlib import Path

import jax.random as jr
import pytest
from helpers import child_env, free_port

from hamjax.cli.diagnose import _fingerprint, blocks, share
from hamjax.cli.main import build_parser, main
from hamjax.io import model_to_dict, write_csv, write_json
from hamjax.papers.gap.demo_cases import tiny_case


REPO = Path(__file__).resolve().parents[2]
EFFECTS = ("saturation", "none", "backlash")


def _cases(root: Path) -> list[Path]:
    """Three tiny cases; the last without model.json (its nominal model is fitted
    and written by the process that owns it)."""
    folders = []
    for k, effect in enumerate(EFFECTS):
        plant, dt, est, val = tiny_case(jr.key(k), effect, n=300, noise=1e-3)
        folder = root / f"c{k}_{effect}"
        folder.mkdir(parents=True)
        if k < len(EFFECTS) - 1:
            write_json(folder / "model.json", model_to_dict(plant, dt))
        write_csv(folder / "estimation.csv", est)
        write_csv(folder / "validation.csv", val)
        folders.append(folder)
    return folders


def _diagnose(cases, out: Path, *extra: str) -> subprocess.Popen:
    # XLA's compiled programs kept in one folder beside the cases, shared by the
    # runs: the 2 processes load what the 1-process run compiled (the same
    # programs, so the same numbers; `_runtime.use_compilation_cache`)
    cache = {"HAMJAX_CACHE_DIR": str(cases[0].parent.parent / "xla")}
    return subprocess.Popen(
        [sys.executable, "-m", "hamjax", "diagnose", *map(str, cases)]
        + ["--out", str(out), "--block", "2", *extra],
        env=child_env(1) | cache,  # 1 device per process in both runs
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait(procs, timeout=240) -> list[tuple[int, str, str]]:
    results = []
    try:
        for p in procs:
            stdout, stderr = p.communicate(timeout=timeout)
            results.append((p.returncode, stdout, stderr))
    finally:
        for p in procs:
            if p.poll() is None:
                p.kill()
    return results


def _two(cases_0, cases_1, out: Path, *extra: str):
    cluster = ["--coordinator", f"127.0.0.1:{free_port()}", "--num-processes", "2"]
    return _wait(
        [
            _diagnose(cases, out, *cluster, "--process-id", str(i), *extra)
            for i, cases in enumerate((cases_0, cases_1))
        ]
    )


def _files(out: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(out)): p.read_bytes() for p in out.rglob("*") if p.is_file()
    }


def _named(text: str) -> set[str]:
    """The cases a process printed a result line for."""
    return set(re.findall(r"^(c\d_\w+): ", text, flags=re.M))


@pytest.mark.slow
def test_two_processes_write_the_one_process_files(tmp_path):
    cases = _cases(tmp_path / "cases")
    ((code, *_),) = _wait([_diagnose(cases, tmp_path / "one")])
    assert code == 0
    two = _two(cases, cases, tmp_path / "two")
    assert [r[0] for r in two] == [0, 0], two[0][2][-3000:] + two[1][2][-3000:]

    one_files, two_files = _files(tmp_path / "one"), _files(tmp_path / "two")
    assert len(one_files) == 2 * len(EFFECTS) + 1  # + nominal_model.json once
    assert two_files == one_files  # every file, byte for byte
    # Each case diagnosed by one process, that of its block (block b -> b mod 2).
    printed = [_named(out + err) for _, out, err in two]
    owners = share(cases, num_processes=2, process_id=0, block=2)
    assert printed[0] == {cases[i].name for b in owners for i in b}
    assert printed[0] | printed[1] == {c.name for c in cases}
    assert not printed[0] & printed[1]
    assert f"diagnosed {len(cases)} case(s) over 2 processes" in two[0][2]

    # An OUT holding results is refused by every process, as by one.
    again = _two(cases, cases, tmp_path / "two")
    assert [r[0] for r in again] == [2, 2]
    assert all("--force" in err.splitlines()[-1] for *_, err in again)
    # Processes given different case lists stop at the start, in one line.
    mixed = _two(cases, cases[::-1], tmp_path / "mixed")
    assert [r[0] for r in mixed] == [2, 2]
    for *_, err in mixed:
        assert "other cases or options than process 0" in err.splitlines()[-1]
    assert not (tmp_path / "mixed").exists() or not _files(tmp_path / "mixed")


def test_blocks_cover_every_case_once_whatever_the_order_and_count():
    cases = [Path(f"data/case{k % 7}") for k in (5, 3, 0, 6, 1, 4, 2, 3, 9, 8)]
    cut = blocks(cases, block=3)
    # consecutive runs of the sorted paths (a path given twice: by position)
    flat = [i for b in cut for i in b]
    assert flat == sorted(range(len(cases)), key=lambda i: (str(cases[i]), i))
    assert [len(b) for b in cut] == [3, 3, 3, 1]
    for n in (1, 2, 3, 5):
        shares = [
            share(cases, num_processes=n, process_id=p, block=3) for p in range(n)
        ]
        # block b, the same whatever n, goes to process b mod n
        assert shares == [cut[p::n] for p in range(n)]
        assert sorted(i for s in shares for b in s for i in b) == list(range(10))
    # reordering the input moves no path to another block
    shuffled = [cases[i] for i in (9, 0, 8, 1, 7, 2, 6, 3, 5, 4)]
    as_paths = lambda cs, cut: [sorted(map(str, (cs[i] for i in b))) for b in cut]  # noqa: E731
    assert as_paths(shuffled, blocks(shuffled, block=3)) == as_paths(cases, cut)


def test_fingerprint_sees_cases_order_and_options(tmp_path):
    parse = build_parser(["diagnose"]).parse_args
    base = ["diagnose", "a", "b", "--out", str(tmp_path)]
    ref = _fingerprint(parse(base))
    assert ref == _fingerprint(parse(base))
    for other in (
        ["diagnose", "b", "a", "--out", str(tmp_path)],
        ["diagnose", "a", "b", "a", "--out", str(tmp_path)],
        [*base, "--rule", "likelihood"],
        [*base, "--block", "3"],
        [*base, "--nominal-uncertainty", "0.1"],
        ["diagnose", "a", "b", "--out", str(tmp_path / "x")],
    ):
        assert _fingerprint(parse(other)) != ref, other


@pytest.mark.parametrize(
    "flags, says",
    [
        (["--num-processes", "2"], "--coordinator"),
        (["--process-id", "1"], "--coordinator"),
        (["--coordinator", "127.0.0.1:1"], "--num-processes and --process-id"),
        (
            ["--coordinator", "localhost", "--num-processes", "2", "--process-id", "0"],
            "HOST:PORT",
        ),
        (
            [
                "--coordinator",
                "127.0.0.1:1",
                "--num-processes",
                "2",
                "--process-id",
                "2",
            ],
            "--process-id must be in 0..1",
        ),
        (["--num-processes", "0"], "--num-processes"),
    ],
)
def test_bad_cluster_flags_one_line_exit_2(flags, says, tmp_path, capsys):
    case = tmp_path / "case"
    case.mkdir()
    code = _exit_code(["diagnose", str(case), "--out", str(tmp_path / "out"), *flags])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.startswith("hamjax: error:")]
    assert code == 2 and len(lines) == 1 and says in lines[0], err
    assert "Traceback" not in err and not (tmp_path / "out").exists()


def _exit_code(argv) -> int:
    """`main`'s exit status; argparse's own errors exit through SystemExit."""
    try:
        return main(argv)
    except SystemExit as stop:
        return stop.code
