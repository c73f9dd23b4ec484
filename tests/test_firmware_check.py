"""The conformance suite (pectoral-firmware-check): both firmwares pass, each broken C variant fails its rule."""

import json

import pytest

from pectoral_gym.hardware.conformance import judge
from pectoral_gym.hardware.firmware_check import RULES, check, emulated_probe, main
from pectoral_gym.hardware.radio import protocol as pr

# The rule each deliberately broken build of the C core breaks (firmware/Makefile, PFW_BROKEN_*).
VARIANT_RULES = {"ignore_lease": "lease", "ignore_retired_stop": "stop_retired", "skip_crc": "crc",
                 "latch_midstroke": "turning_points"}


def _c_firmware_available() -> None:
    from pectoral_gym.hardware.radio.cfirmware import library_path

    try:
        library_path()
    except RuntimeError as err:  # no compiler on this machine: the C firmware cannot be built
        pytest.skip(str(err))


def _verdicts(**options) -> dict[str, judge.Result]:
    with emulated_probe(**options) as probe:
        _, results = check(probe)
    return {r.rule: r for r in results}


@pytest.mark.parametrize("firmware", ["python", "python-10ms"])
def test_python_reference_passes_every_rule(firmware):
    results = _verdicts(firmware=firmware, seed=3)
    assert list(results) == list(RULES)
    assert {r.rule: r.verdict for r in results.values()} == dict.fromkeys(RULES, "PASS")
    # The brackets are the poll spacing wide and hold the rule's moment (figures on the robot's clock).
    lease = results["lease"].details
    assert lease["last_running_ms"] < lease["expected_ms"] + judge.TOLERANCE_MS
    assert lease["first_halted_ms"] - lease["last_running_ms"] <= 1000 * judge.POLL + 1


def test_c_firmware_passes_every_rule():
    _c_firmware_available()
    results = _verdicts(firmware="c", seed=4)
    failed = {r.rule: r.reason for r in results.values() if r.verdict != "PASS"}
    assert not failed


@pytest.mark.parametrize("variant", sorted(VARIANT_RULES))
def test_each_broken_c_variant_fails_its_rule(variant):
    _c_firmware_available()
    results = _verdicts(firmware="c", variant=variant, seed=5)
    assert results[VARIANT_RULES[variant]].verdict == "FAIL", results[VARIANT_RULES[variant]]
    # The other rules the variant does not touch still pass (a suite that fails everything names nothing).
    assert results["claim"].verdict == results["refused"].verdict == "PASS"


@pytest.mark.parametrize(("latency", "loss"), [(0.15, 0.0), (0.05, 0.1)])
def test_a_slow_or_lossy_radio_does_not_change_the_verdicts(latency, loss):
    # 150 ms each way: every time is judged on the robot's clock. 10 % of the frames lost each way: a scenario
    # that failed while messages were lost runs again (with seed 8, one rule passes at its second attempt).
    results = _verdicts(firmware="python", seed=8, latency=latency, loss=loss)
    assert {r.verdict for r in results.values()} == {"PASS"}, {r.rule: r.reason for r in results.values()}


def test_a_broken_variant_still_fails_over_a_lossy_radio():
    _c_firmware_available()
    results = _verdicts(firmware="c", variant="skip_crc", seed=8, latency=0.05, loss=0.1)
    assert results["crc"].verdict == "FAIL"


def test_bracket_judges_on_the_robot_clock():
    tol = judge.TOLERANCE_MS
    running, halted = int(pr.RobotState.RUNNING), int(pr.RobotState.EXPIRED)
    assert judge.bracket([(350, running), (400, running), (450, halted)], 400.0, "x")["first_halted_ms"] == 450
    with pytest.raises(judge.Broken, match="before its time"):  # halted 50 ms early
        judge.bracket([(300, running), (350, halted)], 400.0, "x")
    with pytest.raises(judge.Broken, match="after its time"):  # still running 30 ms late
        judge.bracket([(400 + tol + 8, running), (480, halted)], 400.0, "x")
    with pytest.raises(judge.Broken, match="never saw"):
        judge.bracket([(300, running)], 400.0, "x")


def test_cli_json_exit_status_and_skip(tmp_path, capsys):
    out = tmp_path / "report.json"
    assert main(["--emulate", "--rules", "crc", "stale_duplicate", "--json", str(out), "--seed", "2"]) == 0
    report = json.loads(out.read_text())
    assert report["passed"] and [r["rule"] for r in report["results"]] == ["crc", "stale_duplicate"]
    assert "2 passed, 0 failed, 0 skipped" in capsys.readouterr().out
    with emulated_probe(seed=2) as probe:  # a transport that cannot power-cycle the robot: the reboot is skipped
        probe.reboot_robot = None
        _, results = check(probe, ["boot_id"])
    assert results[0].verdict == "SKIP" and "power cycle" in results[0].reason


def test_cli_over_a_serial_url_in_real_time():
    # The path a real robot takes: serial_for_url (socket://), real time, the emulator at 4x.
    assert main(["--emulate", "--realtime", "--speed", "4", "--rules", "refused", "crc"]) == 0


@pytest.mark.parametrize("argv", [["--port", "loop://", "--firmware", "c"], ["--emulate", "--variant", "skip_crc"],
                                  ["--emulate", "--speed", "0"]])
def test_cli_rejects_bad_arguments(argv):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2


def test_latch_pairs_skip_lost_reports_and_quiet_intervals():
    from pectoral_gym.hardware.conformance import fins

    def latch(seq, uptime, fin):
        body = pr.Latch(uptime, 9, fin, seq % 2 == 0, 1.5, (1.5, 0.2, 0.8, 1.0))
        return pr.Message(pr.MsgType.LATCH, seq, 1, latch=body)

    reports = [latch(1, 0, 0), latch(2, 10, 1), latch(3, 400, 0), latch(5, 800, 0), latch(6, 1200, 0),
               latch(7, 2500, 0)]
    pairs = fins._pairs(reports, [(1300, 2400)])
    # 1-3 (fin 1's report between them is no gap); 3-5 skips the lost report 4; 6-7 spans the quiet interval.
    assert [(a.uptime_ms, b.uptime_ms) for a, b in pairs] == [(0, 400), (800, 1200)]
