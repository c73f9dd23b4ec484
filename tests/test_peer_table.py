"""The side-by-side step-rate table runs and prints its shape (tiny sizes; no wall-clock threshold)."""

import json

import pytest

from pectoral_gym.tools import peer_table
from pectoral_gym.tools.peer_table import COLUMNS, SWIMMER_ID, main

TINY = ["--envs", "8", "--swimmer-envs", "2", "--steps", "50", "--vector-steps", "2", "--repeats", "1"]


def _rows(text: str) -> list[list[str]]:
    """The cells of the markdown table's lines (header, rule, rows)."""
    return [[c.strip() for c in line.strip("|").split("|")] for line in text.splitlines() if line.startswith("|")]


def test_table_has_a_row_per_size_and_a_column_per_env(capsys):
    assert main(TINY) == 0
    rows = _rows(capsys.readouterr().out)
    assert rows[0] == ["envs", "CartPole-v1", "Swimmer-v5", "PectoralFish-Averaged-v2", "PectoralFish-Full-v2"]
    assert [r[0] for r in rows[2:]] == ["1", "8 (native vector)"]
    for row in rows[2:]:
        assert len(row) == 5
        assert "x)" not in row[1]  # CartPole is the reference: no ratio
        for cell in row[3:]:  # the fish: always measured, with a ratio
            assert cell.endswith("x)") and ("k/s" in cell or "M/s" in cell)


def test_json_ratios_are_each_rate_over_cartpoles_in_its_row(capsys):
    assert main([*TINY, "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert set(result["rows"]) == {"single", "vector"}
    assert result["num_envs"]["vector"] == {c: 2 if c == SWIMMER_ID else 8 for c in COLUMNS}
    for row, rates in result["rows"].items():
        for column, rate in rates.items():
            if rate is not None:
                assert rate > 0
                assert result["ratios"][row][column] == pytest.approx(rate / rates["CartPole-v1"], rel=1e-12)


def test_without_mujoco_swimmer_reads_n_a_with_a_note(capsys, monkeypatch):
    monkeypatch.setattr(peer_table, "_mujoco_missing", lambda: "mujoco is not installed; Swimmer-v5 skipped")
    assert main(TINY) == 0
    out = capsys.readouterr().out
    rows = _rows(out)
    assert [r[2].split()[0] for r in rows[2:]] == ["n/a", "n/a"]
    assert "Note: Swimmer-v5: mujoco is not installed" in out


def test_bad_size_is_a_one_line_error(capsys):
    assert main([*TINY[:-2], "--repeats", "0"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("peer_table: ") and "\n" not in err
