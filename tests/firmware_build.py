"""The firmware's host build, compiled once per test run into a temporary folder."""

from __future__ import annotations

from pathlib import Path

import pytest

from teleop_core.loop.host_unit import build_host_firmware


@pytest.fixture(scope="session")
def host_firmware(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The folder holding `haptic_unit_host` and `haptic_unit_tests`."""
    return build_host_firmware(tmp_path_factory.mktemp("firmware-build"))
