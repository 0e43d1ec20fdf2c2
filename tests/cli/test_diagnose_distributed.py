"""`hamjax diagnose CASE... --coordinator ... --num-processes N --process-id I`:
the sorted case list cut into blocks (`run_blocks`), block b to process b mod N,
every block one call padded as the whole run; 2 processes on localhost write
every case once and exactly the 1-process files."""

import re
import subprocess
import sys
from pathlib import Path

import jax.random as jr
import pytest
from helpers import child_env, free_port

import hamjax.diagnosis.diagnose as diagnose_module
from hamjax.cli import diagnose as cli
from hamjax.cli.diagnose import _fingerprint, _sizes, padding, share
from hamjax.cli.main import build_parser, main
from hamjax.diagnosis.case import read_case
from hamjax.diagnosis.diagnose import run_padding
from hamjax.io import model_to_dict, write_csv, write_json
from hamjax.models import Hammerstein, PiecewiseLinear
from hamjax.papers.gap.demo_cases import tiny_case


REPO = Path(__file__).resolve().parents[2]
EFFECTS = ("saturation", "none", "backlash")
SAMPLES = (200, 200, 600)


def _cases(root: Path) -> list[Path]:
    """Three tiny cases that pad differently alone: the first with an identity
    map, the second with the same plant written with an (identity-valued)
    piecewise-linear map, whose rows are wider, the last longer and without
    model.json (its nominal model is fitted and written by the process that owns
    it). Split over 2 processes (c0, c2 | c1), each process's own padding differs
    from the whole run's."""
    folders = []
    for k, (effect, n) in enumerate(zip(EFFECTS, SAMPLES, strict=True)):
        plant, dt, est, val = tiny_case(jr.key(k), effect, n=n, noise=1e-3)
        folder = root / f"c{k}_{effect}"
        if k == 1:
            plant = Hammerstein(PiecewiseLinear(k1=1.0, k2=1.0), plant.linear)
        _write(folder, plant if k < len(EFFECTS) - 1 else None, dt, est, val)
        folders.append(folder)
    return folders


def _write(folder: Path, plant, dt, est, val) -> None:
    """A case folder; without model.json where `plant` is None."""
    folder.mkdir(parents=True)
    if plant is not None:
        write_json(folder / "model.json", model_to_dict(plant, dt))
    write_csv(folder / "estimation.csv", est)
    write_csv(folder / "validation.csv", val)


# `hamjax diagnose` in blocks of one case (`run_blocks`), so that 3 cases split
# over 2 processes (blocks c0, c2 | c1)
ONE_CASE_BLOCKS = (
    "import sys; import hamjax.diagnosis.diagnose as d; d.CASES_PER_CALL = 1; "
    "from hamjax.cli.main import main; sys.exit(main(sys.argv[1:]))"
)


def _diagnose(cases, out: Path, *extra: str) -> subprocess.Popen:
    # XLA's compiled programs kept in one folder beside the cases, shared by the
    # runs: the 2 processes load what the 1-process run compiled (the same
    # programs, so the same numbers; `_runtime.use_compilation_cache`)
    cache = {"HAMJAX_CACHE_DIR": str(cases[0].parent.parent / "xla")}
    return subprocess.Popen(
        [sys.executable, "-c", ONE_CASE_BLOCKS, "diagnose", *map(str, cases)]
        + ["--out", str(out), *extra],
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
def test_two_processes_write_the_one_process_files(tmp_path, monkeypatch):
    monkeypatch.setattr(diagnose_module, "CASES_PER_CALL", 1)  # as the children
    cases = _cases(tmp_path / "cases")
    ((code, *_),) = _wait([_diagnose(cases, tmp_path / "one")])
    assert code == 0
    two = _two(cases, cases, tmp_path / "two")
    assert [r[0] for r in two] == [0, 0], two[0][2][-3000:] + two[1][2][-3000:]

    one_files, two_files = _files(tmp_path / "one"), _files(tmp_path / "two")
    assert len(one_files) == 2 * len(EFFECTS) + 1  # + nominal_model.json once
    assert two_files == one_files  # every file, byte for byte
    # Each case diagnosed by one process (case k of the sorted list -> k mod 2),
    # whose own padding is not the whole run's: the run's padding was used.
    printed = [_named(out + err) for _, out, err in two]
    owners = [i for b in share(cases, num_processes=2, process_id=0) for i in b]
    assert printed[0] == {cases[i].name for i in owners}
    ((alone,),) = share(cases, num_processes=2, process_id=1)
    assert padding([cases[alone]]) != padding(cases)
    assert printed[0] | printed[1] == {c.name for c in cases}
    assert not printed[0] & printed[1]
    assert f"diagnosed {len(cases)} case(s) over 2 processes" in two[0][2]

    # Processes given different case lists stop at the start, in one line, before
    # anything else (here an OUT holding results, refused otherwise), and leave
    # OUT as it was (one phase, to keep the test short).
    mixed = _two(cases, cases[::-1], tmp_path / "two")
    assert [r[0] for r in mixed] == [2, 2]
    for *_, err in mixed:
        assert "other cases or options than process 0" in err.splitlines()[-1]
    assert _files(tmp_path / "two") == one_files


def test_blocks_cover_every_case_once_whatever_the_process_count(monkeypatch):
    monkeypatch.setattr(diagnose_module, "CASES_PER_CALL", 3)
    cases = [Path(f"data/case{k % 7}") for k in (5, 3, 0, 6, 1, 4, 2, 3, 9, 8)]
    # sorted by path (a path given twice: by position), cut into consecutive blocks
    order = sorted(range(len(cases)), key=lambda i: (str(cases[i]), i))
    blocks = [order[k : k + 3] for k in range(0, len(order), 3)]
    assert share(cases, num_processes=1, process_id=0) == blocks
    for n in (1, 2, 3, 5, 12):
        shares = [share(cases, num_processes=n, process_id=p) for p in range(n)]
        # process p: blocks p, p + n, ...; the blocks themselves do not depend on n
        assert shares == [blocks[p::n] for p in range(n)]
        assert sorted(i for s in shares for b in s for i in b) == list(range(10))
    # a path's block follows from the paths alone, not from the input order
    shuffled = [cases[i] for i in (9, 0, 8, 1, 7, 2, 6, 3, 5, 4)]
    as_paths = lambda cs: [  # noqa: E731
        [str(cs[i]) for i in b] for b in share(cs, num_processes=2, process_id=1)
    ]
    assert as_paths(shuffled) == as_paths(cases)


@pytest.mark.slow
def test_each_process_share_diagnosed_in_process_has_the_one_process_numbers(
    tmp_path, monkeypatch
):
    # 5 cases in blocks of 2 (3 blocks): 2 processes take blocks 0, 2 | 1, each
    # share diagnosed by the function a process of `hamjax diagnose` runs
    monkeypatch.setattr(diagnose_module, "CASES_PER_CALL", 2)
    root = tmp_path / "cases"
    cases = _cases(root)
    for k, effect in enumerate(("dead_zone", "time_delay"), start=len(cases)):
        cases.append(root / f"c{k}_{effect}")
        _write(cases[-1], *tiny_case(jr.key(k), effect, n=200, noise=1e-3))
    parse = build_parser(["diagnose"]).parse_args

    def run(out: Path, n_proc: int) -> dict[str, bytes]:
        args = parse(["diagnose", *map(str, cases), "--out", str(out)])
        outs, _ = cli._plan(args, notes=False)
        for me in range(n_proc):
            blocks = share(cases, num_processes=n_proc, process_id=me)
            read, failed = cli._read_cases(args, outs, [i for b in blocks for i in b])
            assert failed == 0
            assert cli._diagnose(args, read, outs, blocks, True, False) == len(read)
        return _files(out)

    one = run(tmp_path / "one", 1)
    assert len(one) == 2 * len(cases) + 1  # + nominal_model.json once
    assert run(tmp_path / "two", 2) == one  # every file, byte for byte


def test_padding_from_the_case_list_alone(tmp_path):
    cases = _cases(tmp_path / "cases")
    # a comment and a blank line: `_sizes` counts the rows `read_case` reads
    est = cases[0] / "estimation.csv"
    lines = est.read_text().splitlines()
    est.write_text("\n".join([lines[0], "# note", "", *lines[1:]]) + "\n")
    sizes = []
    for c in cases:
        r = read_case(c)
        sizes.append((r.model, max(r.estimation["v"].size, r.validation["v"].size)))
        nominal, n = _sizes(c)
        assert n == sizes[-1][1]
        assert (nominal is None) == (r.model is None)
        if nominal is not None:
            assert model_to_dict(nominal, r.dt) == model_to_dict(r.model, r.dt)
    assert sizes[2] == (None, SAMPLES[2])
    # the nominals as read, the unfitted one bounded (`run_padding`)
    whole = run_padding(sizes)
    assert padding(cases) == whole
    # whatever the order, repeats or an unreadable folder in the list
    assert padding([*cases[::-1], cases[0], tmp_path / "missing"]) == whole


def test_fingerprint_sees_cases_order_and_options(tmp_path):
    parse = build_parser(["diagnose"]).parse_args
    base = ["diagnose", "a", "b", "--out", str(tmp_path)]
    ref = _fingerprint(parse(base))
    assert ref == _fingerprint(parse(base))
    for other in (
        ["diagnose", "b", "a", "--out", str(tmp_path)],
        ["diagnose", "a", "b", "a", "--out", str(tmp_path)],
        [*base, "--rule", "likelihood"],
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
