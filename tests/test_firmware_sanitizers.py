"""The C firmware's own unit tests and fuzzed frames, built with AddressSanitizer and UndefinedBehaviorSanitizer.

The C unit tests (``firmware/tests``) run under the sanitizers; the frame fuzzer feeds 100 000 random and mutated
frames (a million in the slow test) to the core and must report no violation and no sanitizer error. The core
against the Python reference, stream by stream: ``tests/test_firmware_differential.py``.
"""

from __future__ import annotations

import shutil
import subprocess

import pytest

from pectoral_gym.hardware.radio.cfirmware import FIRMWARE_DIR, build

pytestmark = pytest.mark.skipif(shutil.which("make") is None or shutil.which("cc") is None,
                                reason="needs make and a C compiler")


# ---------------------------------------------------------------- C tests and fuzzing
def _make(target: str) -> None:
    build(target)  # one build at a time: pytest-xdist workers share firmware/build


def test_c_unit_tests_pass_under_the_sanitizers():
    _make("build/sanitize/unit_tests")
    done = subprocess.run([str(FIRMWARE_DIR / "build" / "sanitize" / "unit_tests")], capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr


def _fuzz(frames: int, seed: int) -> str:
    _make("build/fuzz_frames")
    done = subprocess.run([str(FIRMWARE_DIR / "build" / "fuzz_frames"), str(frames), str(seed)],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0 and "0 violations" in done.stdout, done.stdout + done.stderr
    assert "ERROR" not in done.stderr and "runtime error" not in done.stderr, done.stderr
    return done.stdout


def test_fuzzed_frames_find_nothing():
    assert f"{100_000} frames" in _fuzz(100_000, 7)


@pytest.mark.slow
def test_a_million_fuzzed_frames_find_nothing():
    assert f"{1_000_000} frames" in _fuzz(1_000_000, 1)
