"""A study's own options, declared once as `StudyOption`s: the parser and `run`
(called with or without parsed arguments) see the same defaults."""

import argparse

import pytest

from hamjax._argtypes import float_list, int_list, positive_int, word_list
from hamjax.montecarlo.registry import StudyOption, option_values


OPTIONS = (
    StudyOption("periods", 2000, "periods", positive_int),
    StudyOption("orders", [1, 2, 3], "orders", int_list),
    StudyOption("snrs", [10.0, 20.0], "SNRs", float_list),
    StudyOption("modes", ["exact"], "modes", word_list),
    StudyOption("timing", True, "skip timing", negate=True),
)


def _parser():
    parser = argparse.ArgumentParser()
    for option in OPTIONS:
        option.add_to(parser)
    return parser


def test_parsed_defaults_equal_the_declared_defaults():
    parsed = vars(option_values(_parser().parse_args([]), OPTIONS))
    assert parsed == {o.name: o.default for o in OPTIONS}
    assert vars(option_values(None, OPTIONS)) == parsed


def test_given_values_are_parsed_by_their_type():
    args = _parser().parse_args(
        ["--periods", "7", "--orders", "4,5", "--snrs", "3.5", "--modes", "a,b"]
        + ["--no-timing"]
    )
    got = option_values(args, OPTIONS)
    assert (got.periods, got.orders, got.snrs, got.modes, got.timing) == (
        7,
        [4, 5],
        [3.5],
        ["a", "b"],
        False,
    )


def test_a_namespace_lacking_an_option_gets_its_default():
    got = option_values(argparse.Namespace(periods=3), OPTIONS)
    assert got.periods == 3 and got.orders == [1, 2, 3] and got.timing is True


@pytest.mark.parametrize(
    "parse, text",
    [
        (int_list, "1.5"),
        (int_list, ""),
        (float_list, "a,b"),
        (float_list, "1,inf"),
        (word_list, " , "),
        (positive_int, "0"),
    ],
)
def test_bad_option_text_is_a_one_line_argparse_error(parse, text):
    with pytest.raises(argparse.ArgumentTypeError) as err:
        parse(text)
    assert "\n" not in str(err.value) and str(err.value)
