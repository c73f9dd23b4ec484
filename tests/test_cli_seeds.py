"""``--seeds`` has one spelling in every tool: seeds and ranges A-B, space-separated."""

from __future__ import annotations

import argparse

import pytest

from pectoral_gym.agents.controllers.band_study import build_parser as band_parser
from pectoral_gym.agents.nmpc.compare import build_parser as compare_parser
from pectoral_gym.agents.studies.seeds import build_parser as seeds_parser
from pectoral_gym.tools.cli_common import add_seeds_argument


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser()
    add_seeds_argument(parser, [4, 5], "episode seeds")
    return parser


def test_seeds_and_ranges_flatten_in_order() -> None:
    assert _parser().parse_args(["--seeds", "9-11", "3", "7-7"]).seeds == [9, 10, 11, 3, 7]
    assert _parser().parse_args([]).seeds == [4, 5]


@pytest.mark.parametrize("bad, said", [("1,2", "separated by spaces"), ("5-3", "0 <= A <= B"),
                                       ("x", "not a seed"), ("-2", "not a seed")])
def test_bad_seeds_get_one_line(bad: str, said: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        _parser().parse_args(["--seeds", bad])
    assert exit_info.value.code == 2 and said in capsys.readouterr().err


@pytest.mark.parametrize("parser", [band_parser, compare_parser, seeds_parser])
def test_every_tool_reads_the_same_spelling(parser) -> None:
    extra = ["--variants", "{}"] if parser is compare_parser else []
    assert parser().parse_args([*extra, "--seeds", "100-102", "7"]).seeds == [100, 101, 102, 7]
