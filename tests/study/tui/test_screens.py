"""Each screen's main path with Pilot: overview, participants, NASA-TLX, analysis, calibration."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from sqlalchemy import select
from sqlalchemy.orm import Session
from textual.widgets import DataTable, Input, Select, Static

from db.models.audit import AuditEntry
from db.models.calibration import Calibration
from db.models.study import Participant
from db.models.tlx import TLX_SUBSCALES
from study.protocol.tlx import load_tlx, store_tlx
from study.tui.confirm import Confirm
from study.tui.services import calibrate_recording
from study.tui.tlx_pane import PairChoice, TlxPane
from tests.study.tui.conftest import (
    analysed,
    complete_block,
    loaded,
    on_screen,
    store_trials,
    wait_for,
)


def _text(app, selector: str) -> str:
    return str(app.query_one(selector, Static).render())


async def test_overview_shows_groups_sessions_and_what_is_next(make_test_app) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        await loaded(pilot)
        table = app.query_one("#groups", DataTable)
        # DESIGN: novice 2, expert 2; one of each enrolled
        assert [table.get_row(g)[:3] for g in ("novice", "expert")] == [
            ["novice", "1", "2"],
            ["expert", "1", "2"],
        ]
        progress = _text(app, "#progress")
        assert "Sessions done: 0 of 2 enrolled (4 planned)" in progress
        assert "Trials:        0 of 4" in progress
        # P002 (expert) is second in the group's AB/BA balance: HV first
        assert _text(app, "#next-up").splitlines()[:2] == [
            "next trial: P001 lcca/VO trial 1",
            "next trial: P002 lcca/HV trial 1",
        ]
        assert app.overview_shown_s is not None


async def test_add_participant_from_the_keyboard(make_test_app, study_engine) -> None:
    app = make_test_app()
    async with on_screen(app, "f2") as pilot:
        await pilot.press("ctrl+a")  # the first group, novice, is preselected
        table = app.query_one("#people", DataTable)
        await wait_for(pilot, lambda: table.row_count == 3)
        assert table.get_row("P003")[:4] == ["P003", "novice", "HV -> VO", "0/2"]
        assert "enrolled P003 (novice)" in app.query_one("#participants-pane").last_message
    with Session(study_engine) as session:
        stored = session.scalars(select(Participant).where(Participant.code == "P003")).one()
        assert (stored.group, stored.condition_order) == ("novice", ["HV", "VO"])


async def _open_form(pilot, code: str = "P001", block: str = "lcca/VO") -> TlxPane:
    await loaded(pilot)
    await pilot.press("f4")
    pane = pilot.app.query_one(TlxPane)
    pane.open_block(code, *block.split("/"))
    await wait_for(pilot, lambda: pane.loaded_block == (code, *block.split("/")))
    return pane


async def _type_ratings(pilot, ratings: dict[str, str], typed: str = "mental") -> None:
    """Fill the ratings: `typed` key by key, the others set (each key press costs a redraw)."""
    for s, value in ratings.items():
        field = pilot.app.query_one(f"#rating-{s}", Input)
        field.value = ""
        if s == typed:
            field.focus()
            await pilot.press(*value)
        else:
            field.value = value


RATINGS = {
    "mental": "55",
    "physical": "10",
    "temporal": "40",
    "performance": "25",
    "effort": "60",
    "frustration": "20",
}


async def test_tlx_entered_on_the_form_is_stored(make_test_app, study_engine) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _open_form(pilot)
        await _type_ratings(pilot, RATINGS)
        pairs = list(app.query(PairChoice))
        for k, pair in enumerate(pairs):  # left, right, left, ...; the first two by key
            if k < 2:
                pair.focus()
                await pilot.press("left" if k % 2 == 0 else "right")
            else:
                pair.action_pick(k % 2)
        shown = [p.pair[k % 2] for k, p in enumerate(pairs)]
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status == "P001 lcca/VO: stored", 10)
    stored = load_tlx(study_engine, "P001", "lcca", "VO")
    assert {s: getattr(stored, s) for s in TLX_SUBSCALES} == {s: int(v) for s, v in RATINGS.items()}
    # weights: how often each subscale was picked on the screen
    assert {s: getattr(stored, f"w_{s}") for s in TLX_SUBSCALES} == {
        s: shown.count(s) for s in TLX_SUBSCALES
    }
    assert [c for _, _, c in stored.pairwise] == shown


async def test_off_scale_tlx_is_refused_and_nothing_stored(make_test_app, study_engine) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _open_form(pilot)
        await _type_ratings(pilot, {**RATINGS, "physical": "103"}, typed="physical")
        await pilot.press("ctrl+s")
        assert pane.status == (
            "refused: physical rating 103 is off the scale; expected 0-100 in steps of 5"
        )
        await _type_ratings(pilot, {**RATINGS, "effort": "52"}, typed="effort")
        await pilot.press("ctrl+s")
        assert pane.status.startswith("refused: effort rating 52 is off the scale")
        # a few pairwise choices but not all 15
        app.query(PairChoice).first().focus()
        await pilot.press("left")
        await _type_ratings(pilot, RATINGS)
        await pilot.press("ctrl+s")
        assert pane.status.startswith("refused: pairwise choices 2, 3, 4")
        await pilot.pause(0.2)
    assert load_tlx(study_engine, "P001", "lcca", "VO") is None


async def test_editing_a_stored_tlx_needs_a_reason_and_is_audited(
    make_test_app,
    study_engine,
) -> None:
    complete_block(study_engine, "P001", "lcca", "VO")
    store_tlx(study_engine, "P001", "lcca", "VO", {s: int(v) for s, v in RATINGS.items()})
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _open_form(pilot)
        assert app.query_one("#rating-mental", Input).value == "55"  # filled in
        await _type_ratings(pilot, {"mental": "70"})
        await pilot.press("ctrl+s")
        assert pane.status == "refused: this block's TLX is stored; an edit needs a reason"
        app.query_one("#reason", Input).focus()
        await pilot.press(*"typo")
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: "updated" in pane.status)
        assert "mental: 55 -> 70 (typo)" in _text(app, "#audit")
    assert load_tlx(study_engine, "P001", "lcca", "VO").mental == 70
    with Session(study_engine) as session:
        entry = session.scalars(select(AuditEntry).where(AuditEntry.field == "mental")).one()
        assert (entry.old_value, entry.new_value, entry.reason) == ("55", "70", "typo")


async def test_analysis_tables_chart_and_figure_export(
    make_test_app, study_engine, tmp_path
) -> None:
    store_trials(study_engine)
    out = tmp_path / "paper"
    app = make_test_app(figures_dir=out, figure_formats=("png",))
    async with app.run_test(size=(100, 30)) as pilot:
        pane = await analysed(pilot)
        table = app.query_one("#comparisons", DataTable)
        rows = [table.get_row_at(k) for k in range(table.row_count)]
        peak = {r[2]: r for r in rows if r[:2] == ["lcca", "peak_proximal\n_force_n"]}
        # means by hand: novice VO (1.0 + 1.2 + 1.4) / 3 = 1.2, HV 0.6; expert 0.9, 0.6
        assert (peak["novice"][3], peak["novice"][4], peak["novice"][5]) == ("3", "1.2", "0.6")
        assert (peak["expert"][4], peak["expert"][5]) == ("0.9", "0.6")
        # simulated trials: the screen says so beside the tables
        status = _text(app, "#analysis-status")
        assert "Simulated participants: all 12 trials simulated, none measured" in status
        # the chart of peak proximal force: bars on one scale, the longest (1.2) full width
        await wait_for(pilot, lambda: "novice" in _text(app, "#chart"))
        chart = _text(app, "#chart").splitlines()
        bars = {line[:12].strip(): line.count("█") for line in chart[:4]}
        width = bars["novice   VO"]
        assert abs(bars["HV"] - width / 2) <= 1  # novice HV 0.6 = half of 1.2 (last HV: expert)
        assert abs(bars["expert   VO"] - width * 0.9 / 1.2) <= 1
        await pilot.press("ctrl+e")
        await wait_for(pilot, lambda: pane.exported != [])
    assert (out / "fig12_groups_lcca.png").is_file()  # one set per task
    assert all(Path(p).is_file() for p in pane.exported)


async def test_calibration_screen_waits_without_the_loop_and_shows_a_report(
    make_test_app, study_engine, tmp_path
) -> None:
    app = make_test_app()
    async with on_screen(app, "f6") as pilot:
        assert _text(app, "#calib-summary").startswith("no calibration loop")
    recording = tmp_path / "rec.csv"
    recording.write_text("t\n0\n")
    calls = []

    def calibrate(path, model, progress):
        calls.append((path, model))
        progress("fitting the base model")
        return {
            "rmse_before": 0.3,
            "rmse_after": 0.1,
            "candidates_rejected": ["delay"],
            "effects_added": [
                {
                    "family": "stribeck",
                    "params": {
                        "v_s_rad_s": 2.0,
                        "f_static_over_coulomb": 1.35,
                        "shape_exponent": 2.0,
                        "coulomb_scale": 0.987654,
                        "viscous_scale": 1.0123,
                    },
                    "ci": {},
                    "rmse_after_step": 0.1,
                }
            ],
        }

    app = make_test_app(calibrate=calibrate)
    async with on_screen(app, "f6") as pilot:
        app.query_one("#recording", Input).value = str(recording)
        await pilot.press("ctrl+r")
        pane = app.query_one("#calibration-pane")
        await wait_for(pilot, lambda: pane.report is not None)
        # (0.3 - 0.1) / 0.3 = 67 % lower
        assert _text(app, "#calib-summary").splitlines() == [
            "held-out RMSE 0.3000 N -> 0.1000 N (67 % lower)",
            "rejected: delay",
        ]
        effects = app.query_one("#effects", DataTable)
        assert effects.get_row_at(0)[1] == "stribeck"
        # five parameters, one per line: the row is five lines tall, no wider than a line
        assert effects.get_row_at(0)[3].split("\n") == [
            "v_s_rad_s 2",
            "f_static_over_coulomb 1.35",
            "shape_exponent 2",
            "coulomb_scale 0.9877",
            "viscous_scale 1.012",
        ]
        assert effects.rows[effects.coordinate_to_cell_key((0, 0)).row_key].height == 5
        assert effects.virtual_size.width <= 80
        # the result is kept: a row in the calibrations table, a report file, the list
        await wait_for(pilot, lambda: pane.stored_path is not None)
        stored = app.query_one("#stored", DataTable)
        assert stored.row_count == 1
        assert stored.get_row_at(0)[2:5] == ["follower", "rec.csv", "0.3 -> 0.1"]
        # an empty path is named as such (it read "recording '.' is not a file")
        app.query_one("#recording", Input).value = "  "
        await pilot.press("ctrl+r")
        assert _text(app, "#calib-summary") == (
            "refused: type the path of a recording first (a CSV or .mat file)"
        )
    assert calls == [(recording, "follower")]
    with Session(study_engine) as session:
        row = session.scalars(select(Calibration)).one()
    assert (row.model, row.recording_name, row.rmse_before, row.rmse_after) == (
        "follower",
        "rec.csv",
        0.3,
        0.1,
    )
    assert row.recording_sha256 == hashlib.sha256(b"t\n0\n").hexdigest()
    assert row.report["effects_added"][0]["family"] == "stribeck"
    written = json.loads(pane.stored_path.read_text())
    assert pane.stored_path == tmp_path / "calibrations" / f"calibration-{row.id:04d}-rec.json"
    assert (written["id"], written["recording_sha256"]) == (row.id, row.recording_sha256)


async def test_calibration_screen_runs_the_loop_on_a_recording(make_test_app, tmp_path) -> None:
    from teleop_core.notes.params import default_params
    from teleop_core.notes.simulate import simulate_recording

    # a clamped ramp of the NOTES rotation: [notes] reports friction hysteresis and a
    # counter-clockwise loss, which the loop must name (`direction_asymmetry`)
    simulate_recording(
        default_params("rotation"), "ramp", "clamped", noise=0.02, seed=4, rate_hz=200.0
    ).to_csv(tmp_path / "ramp.csv", index=False)
    app = make_test_app(calibrate=calibrate_recording)
    async with on_screen(app, "f6") as pilot:
        app.query_one("#recording", Input).value = str(tmp_path / "ramp.csv")
        app.query_one("#model", Select).value = "notes-rotation"
        await pilot.press("ctrl+r")
        pane = app.query_one("#calibration-pane")
        await wait_for(pilot, lambda: pane.report is not None)
        table = app.query_one("#effects", DataTable)
        shown = {table.get_row_at(k)[1] for k in range(table.row_count)}
        summary = _text(app, "#calib-summary").splitlines()[0]
    assert {"hysteresis", "direction_asymmetry"} <= shown
    assert pane.report["rmse_after"] < pane.report["rmse_before"]
    assert summary.startswith("held-out RMSE")
    assert summary.endswith("% lower)")


async def test_a_questionnaire_for_a_block_not_run_needs_a_reason(
    make_test_app, study_engine
) -> None:
    app = make_test_app()
    async with app.run_test(size=(80, 24)) as pilot:
        pane = await _open_form(pilot, "P002", "lcca/HV")  # P002 has run nothing
        await _type_ratings(pilot, RATINGS)
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: isinstance(app.screen, Confirm), 10)
        await pilot.press("y")  # ratings only: the raw score (asked once for the block)
        await wait_for(pilot, lambda: pane.status.startswith("refused"), 30)
        assert "P002 lcca/HV has no completed trial yet" in pane.status
        assert load_tlx(study_engine, "P002", "lcca", "HV") is None
        app.query_one("#reason", Input).value = "paper form, session cut short"
        await pilot.press("ctrl+s")
        await wait_for(pilot, lambda: pane.status == "P002 lcca/HV: stored", 30)
    with Session(study_engine) as session:
        entry = session.scalars(
            select(AuditEntry).where(AuditEntry.field == "stored_before_block_ran")
        ).one()
    assert entry.reason == "paper form, session cut short"
