"""The Lab Streaming Layer is only ever used with a loopback configuration in the tests."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from study.errors import StudyInputError
from study.lsl.config import ENV, is_loopback_only, read_config, write_loopback_config


def test_the_suite_points_liblsl_at_a_loopback_only_config() -> None:
    from tests.conftest import LSL_CONFIG, PYLSL_LOADED_BEFORE_CONFIG

    assert not PYLSL_LOADED_BEFORE_CONFIG  # liblsl reads its config once, when it loads
    path = Path(os.environ[ENV])
    assert path == LSL_CONFIG
    cfg = read_config(path)
    # the keys as liblsl's api_config.cpp reads them ("ports.IPv6", "multicast.ResolveScope"...)
    assert cfg["ports"]["IPv6"] == "disable"
    assert cfg["multicast"]["ResolveScope"] == "machine"
    assert cfg["multicast"]["MachineAddresses"] == "{127.0.0.1}"
    assert cfg["lab"]["KnownPeers"] == "{127.0.0.1}"
    assert is_loopback_only(path)


def test_liblsl_reads_the_config_the_suite_set(tmp_path: Path) -> None:
    """In a fresh interpreter, pylsl loads with the file LSLAPICFG names and liblsl says
    so when it first opens a stream (its log names the configuration it loaded)."""
    probe = (
        "import os, sys\n"
        "assert 'pylsl' not in sys.modules\n"
        "from study.lsl.config import load_pylsl\n"
        "pylsl = load_pylsl()\n"
        "outlet = pylsl.StreamOutlet(pylsl.StreamInfo('probe', 'Markers', 1, 0, 'string'))\n"
        "print(pylsl.local_clock() > 0)\n"
    )
    # log level 0 (INFO) so liblsl prints which file it loaded
    cfg = write_loopback_config(tmp_path / "cfg")
    cfg.write_text(cfg.read_text().replace("level = -3", "level = 0"))
    env = {**os.environ, ENV: str(cfg)}
    out = subprocess.run(
        [sys.executable, "-c", probe],
        capture_output=True,
        text=True,
        env=env,
        timeout=60,
        check=True,
    )
    assert out.stdout.strip().splitlines()[-1] == "True"
    assert f"Configuration loaded from {cfg}" in out.stderr


def test_pylsl_is_refused_without_a_config(monkeypatch: pytest.MonkeyPatch) -> None:
    from study.lsl.config import load_pylsl

    monkeypatch.delenv(ENV)
    with pytest.raises(StudyInputError, match="LSLAPICFG"):
        load_pylsl()
    monkeypatch.setenv(ENV, "/nonexistent/lsl_api.cfg")
    with pytest.raises(StudyInputError, match="nonexistent"):
        load_pylsl()


def test_a_config_that_reaches_the_network_is_not_loopback_only(tmp_path: Path) -> None:
    path = write_loopback_config(tmp_path / "cfg")
    path.write_text(path.read_text().replace("ResolveScope = machine", "ResolveScope = site"))
    assert not is_loopback_only(path)
