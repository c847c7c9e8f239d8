"""liblsl's configuration: the file `LSLAPICFG` names, and the only way pylsl is loaded.

liblsl reads its configuration once, when the library loads, from the file the
`LSLAPICFG` environment variable names (then `./lsl_api.cfg`, `~/lsl_api/lsl_api.cfg`,
`/etc/lsl_api/lsl_api.cfg`; its defaults send stream discovery to multicast and
broadcast addresses of the site). `load_pylsl` therefore refuses to import pylsl
unless `LSLAPICFG` names a readable file: the lab writes its own network's
configuration; `write_loopback_config` writes one that keeps every packet on this
machine (tests, benches, a laptop demo). The keys are liblsl's (`api_config.cpp`):
`[ports] IPv6`, `[multicast] ResolveScope / MachineAddresses / ListenAddress /
Interfaces`, `[lab] KnownPeers`, `[log] level`.
"""

from __future__ import annotations

import configparser
import os
import sys
from pathlib import Path
from types import ModuleType

from study.errors import StudyInputError

ENV = "LSLAPICFG"
LOOPBACK = "127.0.0.1"
LOOPBACK_CONFIG = f"""\
; liblsl configuration that keeps every LSL packet on this machine's loopback
[ports]
IPv6 = disable

[multicast]
ResolveScope = machine
MachineAddresses = {{{LOOPBACK}}}
ListenAddress = {LOOPBACK}
Interfaces = {{{LOOPBACK}}}

[lab]
KnownPeers = {{{LOOPBACK}}}

[log]
level = -3
"""
"""ResolveScope `machine` sends discovery only to `MachineAddresses` (here loopback
alone, no IPv6 group since IPv6 is off); `KnownPeers` adds unicast queries to loopback;
`ListenAddress` and `Interfaces` keep the responders and any multicast on loopback;
log level -3 prints liblsl's fatal errors only (a lost stream is `study`'s one line, not
liblsl's too)."""


def write_loopback_config(path: Path, session_id: str | None = None) -> Path:
    """Write the loopback-only configuration to `path`; returns it. `session_id` (liblsl's
    `[lab] SessionID`) hides its streams from processes with another one (parallel tests)."""
    text = LOOPBACK_CONFIG
    if session_id is not None:
        text = text.replace("[lab]\n", f"[lab]\nSessionID = {session_id}\n")
    path.write_text(text, encoding="utf-8")
    return path


def use_config(path: Path) -> None:
    """Point liblsl at `path` (sets `LSLAPICFG`); only before pylsl has been loaded,
    since liblsl reads its configuration once."""
    if "pylsl" in sys.modules and os.environ.get(ENV) != str(path):
        raise RuntimeError(
            f"pylsl is already loaded with {ENV}={os.environ.get(ENV)!r}; liblsl reads its "
            "configuration once, so set it before the first import"
        )
    os.environ[ENV] = str(path)


def read_config(path: Path) -> dict[str, dict[str, str]]:
    """A liblsl configuration file as {section: {key: value}} (INI, as liblsl reads it)."""
    parser = configparser.ConfigParser(inline_comment_prefixes=(";",))
    # liblsl's keys are case sensitive (typeshed declares optionxform a method, which
    # configparser's documentation says to replace)
    parser.optionxform = str  # type: ignore[assignment, method-assign]
    parser.read_string(path.read_text(encoding="utf-8"))
    return {s: dict(parser[s]) for s in parser.sections()}


def is_loopback_only(path: Path) -> bool:
    """Whether the configuration at `path` keeps discovery on loopback: machine scope,
    loopback machine addresses and peers, IPv6 off."""
    cfg = read_config(path)
    return (
        cfg.get("ports", {}).get("IPv6") in ("disable", "disabled")
        and cfg.get("multicast", {}).get("ResolveScope") == "machine"
        and cfg.get("multicast", {}).get("MachineAddresses") == f"{{{LOOPBACK}}}"
        and cfg.get("lab", {}).get("KnownPeers") == f"{{{LOOPBACK}}}"
        and "AddressesOverride" not in cfg.get("multicast", {})
    )


def load_pylsl() -> ModuleType:
    """pylsl, once `LSLAPICFG` names a readable liblsl configuration file; else one line."""
    path = os.environ.get(ENV)
    if not path or not Path(path).is_file():
        raise StudyInputError(
            f"{ENV}={path!r}; expected the path of a liblsl configuration file for this "
            "lab's network (`study lsl-config FILE` writes one that stays on this machine)"
        )
    # lazy: pylsl costs 94 ms at start-up
    import pylsl

    return pylsl
