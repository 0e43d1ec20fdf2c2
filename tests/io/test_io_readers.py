"""The readers of hamjax/io and the case folder reader against what spreadsheets,
R and pandas write, and against generated malformed files: every outcome is a
result or a one-line `UserInputError` naming the file, never another exception."""

import json
import tempfile
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from hamjax._errors import UserInputError
from hamjax.diagnosis.case import read_case
from hamjax.io import (
    count_rows,
    load_model,
    read_csv,
    read_data,
    read_design,
    write_csv,
)


T = np.arange(60) * 0.05
ROWS = (
    "\n".join(
        f"{t!r},{v!r},{y!r}"
        for t, v, y in zip(
            T.tolist(), np.sin(T).tolist(), np.cos(T).tolist(), strict=True
        )
    )
    + "\n"
)


def _write(path: Path, text: str, encoding: str = "utf-8") -> Path:
    path.write_text(text, encoding=encoding)
    return path


def _assert_matches_reference(cols: dict) -> None:
    np.testing.assert_allclose(cols["t"], T, rtol=0, atol=1e-15)
    np.testing.assert_allclose(cols["v"], np.sin(T), rtol=1e-15)
    np.testing.assert_allclose(cols["y"], np.cos(T), rtol=1e-15)


@pytest.mark.parametrize(
    "text, encoding",
    [
        ("t,v,y\n" + ROWS, "utf-8-sig"),  # Excel "CSV UTF-8": a byte-order mark
        ('"t","v","y"\n' + ROWS, "utf-8"),  # R write.csv(row.names = FALSE)
        (
            '"","t","v","y"\n'
            + "".join(f'"{i + 1}",{r}\n' for i, r in enumerate(ROWS.splitlines())),
            "utf-8",
        ),  # R write.csv: a quoted, unnamed row-index column
        (
            ",t,v,y\n" + "".join(f"{i},{r}\n" for i, r in enumerate(ROWS.splitlines())),
            "utf-8",
        ),  # pandas to_csv: an unnamed index column
        ("# rig 3, 2024-05-01\n#\n\nt,v,y\n" + ROWS, "utf-8"),  # leading comments
        ("t , v , y\r\n" + ROWS.replace("\n", "\r\n"), "utf-8"),  # CRLF, spaces
    ],
    ids=["bom", "r-quoted", "r-row-index", "pandas-index", "comments", "crlf"],
)
def test_csv_dialects_read_like_the_plain_file(tmp_path, text, encoding):
    path = _write(tmp_path / "d.csv", text, encoding)
    cols = read_csv(path)
    assert "" not in cols  # the unnamed index column is dropped
    _assert_matches_reference(cols)
    # the row count, without parsing: the rows written, whatever the dialect
    assert count_rows(path) == T.size


@pytest.mark.parametrize("offset, dt", [(0.0, 1e-3), (1000.0, 0.01), (5e4, 0.25)])
def test_float32_timestamps_are_uniform_within_the_stated_tolerance(
    tmp_path, offset, dt
):
    n = 20000
    t32 = (np.arange(n, dtype=np.float32) * np.float32(dt) + np.float32(offset)).astype(
        np.float32
    )
    lines = "".join(f"{t},{k % 7},{k % 5}\n" for k, t in enumerate(t32))
    cols = read_csv(_write(tmp_path / "f32.csv", "t,v,y\n" + lines))
    np.testing.assert_allclose(np.diff(cols["t"]).mean(), dt, rtol=1e-5)


def test_float64_jitter_above_float32_resolution_is_still_refused(tmp_path):
    t = np.arange(200) * 0.01
    t[100] += 1e-4  # 1 % of dt; float32 rounding of |t| <= 2 is 2.4e-7
    write_csv(tmp_path / "j.csv", {"t": t, "v": t, "y": t})
    with pytest.raises(UserInputError, match=r"not uniformly sampled.*line 102"):
        read_csv(tmp_path / "j.csv")


def test_header_only_csv_is_one_error_and_no_warning(tmp_path):
    p = _write(tmp_path / "h.csv", "t,v,y\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a NumPy warning would fail here
        with pytest.raises(UserInputError, match=r"h\.csv: needs at least 2 rows"):
            read_csv(p)


@pytest.mark.parametrize(
    "text, match",
    [
        ("# note\nt,v,y\n0,1,2\n\n1,x,3\n2,1,1\n", r"line 5: malformed number 'x'"),
        ("t,v,y\n0,1,2\n1,2\n2,1,1\n", r"line 3 has 2 values but the header has 3"),
        ("# a\n# b\nt,v,y\n0,1,2\n1,nan,3\n", r"column v has NaN \(line 5\)"),
        ("t,v,y\n0,1,2\n1,1,2\n1,1,2\n", r"strictly increasing \(line 4\)"),
        ("t;v;y\n0;1;2\n1;1;2\n", r"delimiter must be a comma"),
        ("t,v,t\n0,1,2\n1,1,2\n", r"column name t appears twice"),
        ('t,v,y\n0,"1,2\n1,1,2\n', r"line 2"),
    ],
)
def test_csv_refusals_name_the_file_and_the_line(tmp_path, text, match):
    p = _write(tmp_path / "bad.csv", text)
    with pytest.raises(UserInputError, match=match) as info:
        read_csv(p)
    assert str(p) in str(info.value) and "\n" not in str(info.value)


def test_binary_and_folder_inputs_are_one_line_errors(tmp_path):
    (tmp_path / "b.csv").write_bytes(b"t,v,y\n\xff\xfe\x00\x01\n")
    with pytest.raises(UserInputError, match=r"b\.csv: not UTF-8 text"):
        read_csv(tmp_path / "b.csv")
    (tmp_path / "d.csv").mkdir()
    with pytest.raises(UserInputError, match=r"d\.csv: is a folder"):
        read_csv(tmp_path / "d.csv")
    (tmp_path / "m.json").write_bytes(b'{"a": "\xff"}')
    with pytest.raises(UserInputError, match=r"m\.json: not UTF-8 text"):
        load_model(tmp_path / "m.json")


# ------------------------------------------------------------------ fuzzing --

FUZZ = settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
)

_cell = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-(10**30), 10**30).map(str),
    st.sampled_from(["", "x", "nan", "-inf", '"1"', '"', '"a,b"', " ", "1e999", "#"]),
)
_name = st.sampled_from(["t", "v", "y", "", '"t"', '""', "z", "\ufefft", "t v"])


@st.composite
def _csv_text(draw) -> str:
    """A CSV that may be right or wrong in any part."""
    head = draw(st.lists(st.sampled_from(["# c", "", "  ", "#,t,v"]), max_size=3))
    names = draw(st.lists(_name, min_size=0, max_size=5))
    n_cols = len(names)
    uniform = draw(st.booleans())
    n_rows = draw(st.integers(0, 8))
    rows = []
    for k in range(n_rows):
        width = n_cols if draw(st.integers(0, 9)) else draw(st.integers(0, 6))
        cells = [draw(_cell) for _ in range(width)]
        if uniform and "t" in names and names.index("t") < width:
            cells[names.index("t")] = repr(0.5 * k)
        rows.append(",".join(cells))
    bom = "\ufeff" if draw(st.booleans()) else ""
    text = bom + "\n".join([*head, ",".join(names), *rows])
    return draw(st.one_of(st.just(text), st.text(max_size=200)))


def _assert_outcome(fn, where: Path):
    """`fn()`'s result, or None after a one-line UserInputError naming `where`."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            return fn()
    except UserInputError as err:
        msg = str(err)
        assert "\n" not in msg, msg
        assert str(where) in msg, msg
        return None


@FUZZ
@given(text=_csv_text(), required=st.sampled_from([("t", "v", "y"), ("t", "v")]))
def test_fuzz_csv_reader(text, required):
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "f.csv"
        p.write_text(text, encoding="utf-8")
        cols = _assert_outcome(lambda: read_csv(p, required), p)
        if cols is not None:
            lengths = {cols[c].shape[0] for c in required}
            assert len(lengths) == 1 and lengths.pop() >= 2
            # `count_rows` counts the rows the reader parsed
            assert count_rows(p) == cols[required[0]].shape[0]
            assert all(np.all(np.isfinite(cols[c])) for c in required)


_json_leaf = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(10**400), 10**400),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["identity", "piecewise_linear", "tabulated", "backlash"]),
    st.sampled_from(["discrete_tf", "continuous_tf", "x"]),
)
_json_value = st.recursive(
    _json_leaf,
    lambda inner: (
        st.lists(inner, max_size=5)
        | st.dictionaries(
            st.sampled_from(["kind", "v", "u", "a", "b"]), inner, max_size=4
        )
    ),
    max_leaves=12,
)
_number_list = st.lists(
    st.one_of(st.floats(-5, 5), st.integers(-3, 3), st.just(float("nan"))),
    max_size=5,
)


@st.composite
def _nl(draw):
    kind = draw(
        st.sampled_from(["identity", "piecewise_linear", "tabulated", "backlash", "?"])
    )
    obj = {"kind": kind}
    for key in ("k1", "k2", "d1", "d2", "l1", "l2"):
        if draw(st.integers(0, 5)):
            obj[key] = draw(st.one_of(st.floats(-3, 3), _json_leaf))
    for key in ("v", "u", "ascending", "descending"):
        if draw(st.integers(0, 4)):
            obj[key] = draw(st.one_of(_number_list, _json_value))
    return obj


@st.composite
def _lin(draw):
    kind = draw(st.sampled_from(["discrete_tf", "continuous_tf", "?"]))
    obj = {"kind": kind}
    for key in ("b", "a", "num", "den"):
        if draw(st.integers(0, 4)):
            obj[key] = draw(st.one_of(_number_list, _json_value))
    if draw(st.booleans()):
        obj["dt"] = draw(st.one_of(st.floats(-1, 1), _json_leaf))
    return obj


_model = st.one_of(
    st.fixed_dictionaries({"nonlinearity": _nl(), "linear": _lin()}),
    _json_value,
)


def _dump(obj) -> str:
    try:
        return json.dumps(obj)
    except ValueError:  # an integer too long for Python's str(); still a JSON text
        return "[" * 10


@FUZZ
@given(model=_model, raw=st.one_of(st.none(), st.binary(max_size=40)))
def test_fuzz_model_json_reader(model, raw):
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "model.json"
        if raw is None:
            p.write_text(_dump(model))
        else:
            p.write_bytes(raw)
        got = _assert_outcome(lambda: load_model(p), p)
        if got is not None:
            plant, dt = got
            assert dt is None or (np.isfinite(dt) and dt > 0)


@FUZZ
@given(
    design=st.one_of(
        st.fixed_dictionaries(
            {"method": st.sampled_from(["nbbi", "fgi"]), "dt": _json_leaf}
        ),
        _json_value,
    ),
    data=_csv_text(),
)
def test_fuzz_experiment_folder_readers(design, data):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        (folder / "experiment.json").write_text(_dump(design))
        (folder / "data.csv").write_text(data)
        got = _assert_outcome(lambda: read_design(folder, "nbbi", ("dt",)), folder)
        if got is not None:
            v = np.sin(np.arange(5) * 0.5)
            y = _assert_outcome(lambda: read_data(folder, got, v), folder)
            assert y is None or y.shape == (5,)


@st.composite
def _record(draw) -> str:
    """A record near a valid one: 40-70 samples, then one possible corruption."""
    n = draw(st.integers(40, 70))
    dt = draw(st.sampled_from([0.1, 0.05, 1e-3]))
    t = np.arange(n) * dt
    v = np.asarray(draw(st.lists(st.floats(-2, 2), min_size=n, max_size=n)))
    y = np.cumsum(v) * 0.1
    fault = draw(st.sampled_from(["none", "const_v", "const_y", "nan", "jitter"]))
    if fault == "const_v":
        v[:] = 1.0
    elif fault == "const_y":
        y[:] = 3.5e-44
    elif fault == "nan":
        y[draw(st.integers(0, n - 1))] = np.nan
    elif fault == "jitter":
        t[n // 2] += dt * draw(st.floats(0, 0.5))
    return "t,v,y\n" + "".join(
        f"{a!r},{b!r},{c!r}\n"
        for a, b, c in zip(t.tolist(), v.tolist(), y.tolist(), strict=True)
    )


@FUZZ
@given(
    est=st.one_of(_record(), _csv_text()),
    val=st.one_of(_record(), _csv_text()),
    model=st.one_of(st.none(), _model),
)
def test_fuzz_gap_case_reader(est, val, model):
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "case"
        folder.mkdir()
        (folder / "estimation.csv").write_text(est)
        (folder / "validation.csv").write_text(val)
        if model is not None:
            (folder / "model.json").write_text(_dump(model))
        case = _assert_outcome(lambda: read_case(folder), folder)
        assert case is None or case.dt > 0


def test_fuzzed_gap_case_reader_accepts_a_good_case(tmp_path):
    """The generator's good corner: a valid case reads (the fuzz above is not vacuous)."""
    rng = np.random.default_rng(0)
    for name in ("estimation", "validation"):
        t = np.arange(100) * 0.1
        write_csv(tmp_path / f"{name}.csv", {"t": t, "v": rng.normal(size=100), "y": t})
    model = {
        "nonlinearity": {"kind": "identity"},
        "linear": {"kind": "discrete_tf", "b": [0.0, 0.3], "a": [1.0, -0.7], "dt": 0.1},
    }
    (tmp_path / "model.json").write_text(json.dumps(model))
    case = read_case(tmp_path)
    assert case.dt == pytest.approx(0.1) and case.model is not None
