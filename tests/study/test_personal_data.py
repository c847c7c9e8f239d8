"""Notes, session notes and reasons that look like contact details: an e-mail address or a
phone number is refused with one line saying why, a text that only looks like one is kept
with `--not-personal`, and measurements, dates and times pass as they are."""

from __future__ import annotations

import re
import sqlite3
from pathlib import Path

import pytest

from study.cli import main
from study.protocol.free_text import PersonalDataError, check_free_text, looks_personal
from tests.study.conftest import init_study

EMAILS = [
    "a.b+c@sub.host.org",
    "x@y.co.uk",
    "ANNA@EXAMPLE.COM",
    "o'brien@host.ie",
    "jürgen.müller@uni-köln.de",
    "用户@例子.广告",
    "anna [at] uni-bern [dot] ch",
    "anna(at)example.org",
]
PHONES = [
    "+41 79 123 45 67",
    "+41-79-123-45-67",
    "+44 20 7946 0958",
    "+1 (555) 123-4567",
    "+1.555.123.4567",
    "+7 912 345-67-89",
    "+358 40 1234567",
    "+41 (0)79 123 45 67",
    "0041 79 123 45 67",
    "(030) 1234567",
    "079 123 45 67",
    "079.123.45.67",
    "555-123-4567",
    "0791234567",
    "\uff10\uff17\uff19 \uff11\uff12\uff13 \uff14\uff15 \uff16\uff17",  # full-width digits
]
NOT_PERSONAL = [
    "force 12.5 N at 3-4 s",
    "forces 1.25 2.50 3.75 N",
    "1,25 N then 2,5 N",
    "size 10.5 x 12.25 x 3.5 mm",
    "trial 3 of 12, block 2, attempt 3",
    "3/4 trials, 50/50 split",
    "1999-12-02 10:30",
    "02.12.2025 10:30:15",
    "recalibrated 2025/12/02 14:05",
    "log 20251202-1030",
    "10:30-11:15",
    "serial AB-1234, firmware v1.2.3",
    "see @P001",
    "user@localhost",
    "a @ b",
    "P001 left-handed grip",
]


@pytest.mark.parametrize("address", EMAILS)
@pytest.mark.parametrize("around", ["{}", "wrote from {} today", "mail: {}."])
def test_an_email_address_is_found_wherever_it_stands(address: str, around: str) -> None:
    found = looks_personal(around.format(address))
    assert found == f"an e-mail address {address!r}"


@pytest.mark.parametrize("number", PHONES)
@pytest.mark.parametrize("around", ["{}", "call {} after 5", "tel. {},"])
def test_a_phone_number_is_found_wherever_it_stands(number: str, around: str) -> None:
    assert looks_personal(around.format(number)) == f"a phone number {number!r}"


@pytest.mark.parametrize("text", NOT_PERSONAL)
def test_measurements_dates_and_times_are_kept(text: str) -> None:
    assert looks_personal(text) is None
    assert check_free_text("note", text) == text


def test_a_phone_number_beside_a_date_is_still_found() -> None:
    assert looks_personal("on 02.12.2025 call 079 123 45 67") == "a phone number '079 123 45 67'"


def test_a_lookalike_is_kept_only_when_asked() -> None:
    text = "amplifier at 192.168.100.17"  # an IP address: a phone number's digits
    with pytest.raises(PersonalDataError, match=re.escape("'192.168.100.17'")):
        check_free_text("note", text)
    assert check_free_text("note", text, keep_lookalike=True) == text


@pytest.fixture(scope="module")
def study(tmp_path_factory: pytest.TempPathFactory) -> str:
    return init_study(tmp_path_factory.mktemp("personal"), None, ("novice",))


def _notes(db: str) -> list[str]:
    with sqlite3.connect(db) as conn:
        return [n for (n,) in conn.execute("SELECT note FROM participants") if n]


@pytest.mark.parametrize(
    "argv",
    [
        ["participant", "note", "P001", "reach at x@y.co.uk"],
        ["participant", "note", "P001", "--session", "call +44 20 7946 0958"],
        ["participant", "withdraw", "P001", "--reason", "moved, new number 079 123 45 67"],
    ],
    ids=["note", "session note", "reason"],
)
def test_the_command_line_refuses_contact_details_in_one_line(
    study: str, capsys: pytest.CaptureFixture[str], argv: list[str]
) -> None:
    before = Path(study).read_bytes()
    assert main([*argv, "--db", study]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1, lines
    assert "looks like an e-mail address" in lines[0] or "looks like a phone number" in lines[0]
    assert "expected no personal data" in lines[0]
    assert "--not-personal" in lines[0]
    assert Path(study).read_bytes() == before


def test_not_personal_keeps_a_lookalike_and_a_measurement_needs_no_flag(study: str) -> None:
    assert main(["participant", "note", "P001", "force 12.5 N at 3-4 s", "--db", study]) == 0
    assert _notes(study) == ["force 12.5 N at 3-4 s"]
    lot = "dial lot 0791234567"
    assert main(["participant", "note", "P001", lot, "--db", study]) == 2
    assert main(["participant", "note", "P001", lot, "--not-personal", "--db", study]) == 0
    assert _notes(study) == [lot]
