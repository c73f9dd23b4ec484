"""The calibration benchmark's seeds: single seeds and inclusive ranges, bad ones a usage error."""

import pytest

from pectoral_gym.scaling.calibration.benchmark import build_parser


def _seeds(*argv: str) -> list[int]:
    return build_parser().parse_args(list(argv)).seeds


def test_seeds_and_inclusive_ranges_mix():
    assert _seeds("--seeds", "301-303", "7", "9-9") == [301, 302, 303, 7, 9]
    assert _seeds() == [101, 102, 103, 104, 105]


@pytest.mark.parametrize("bad", ["5-3", "a-b", "-4", "3-", "1.5"])
def test_a_bad_seed_is_a_usage_error(bad, capsys):
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(["--seeds", bad])
    assert exit_info.value.code == 2 and "--seeds" in capsys.readouterr().err
