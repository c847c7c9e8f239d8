"""`study demo --quick` end to end, the figures it writes, and the data-source label.

One quick demo (2/2/2 simulated participants, one trial per block) is run for the
module; the mixed-database test imports measured trials into a copy of its database.
"""

from __future__ import annotations

import json
import shutil
import sqlite3
import subprocess
import sys
from contextlib import closing
from pathlib import Path

import pandas as pd
import pytest
from pypdf import PdfReader

from study.cli import main
from study.protocol.exchange import TRIAL_COLUMNS
from tests.study.conftest import init_study


@pytest.fixture(scope="module")
def demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("quick") / "demo"
    # in a process of its own, as a researcher runs it: the process ends right after,
    # with whatever it left open (in this one, pytest's process lives on)
    argv = ["demo", "--quick", "--out", str(out), "--seed", "2"]
    code = f"from study.cli import main; raise SystemExit(main({argv!r}))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    # the database file alone, as a researcher copies it off the machine
    alone = out.parent / "alone"
    alone.mkdir()
    shutil.copyfile(out / "demo.db", alone / "demo.db")
    return out


def _counts(path: Path) -> tuple[int, ...]:
    with closing(sqlite3.connect(path)) as conn:
        tables = ("trials", "sample_chunks", "tlx_responses")
        return tuple(conn.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in tables)


def test_the_database_file_alone_holds_every_trial(demo: Path) -> None:
    """The demo's workers end without closing their connections; the write-ahead log
    they leave is folded into the file at the end, so a copy of demo.db alone (its -wal
    left behind) holds every trial, sample chunk and questionnaire."""
    full = _counts(demo / "demo.db")
    assert full[0] == 6 * 2  # 2/2/2 people, two blocks of one trial each
    assert _counts(demo.parent / "alone" / "demo.db") == full


def _pdf_text(path: Path) -> str:
    return " ".join(page.extract_text() for page in PdfReader(path).pages)


def test_quick_demo_writes_analysis_and_figures(
    demo: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report = json.loads((demo / "analysis" / "analysis.json").read_text())
    # two per group: too few pairs for a test, and the analysis says so instead of failing
    assert report["comparisons"] == []
    assert any("too few to test" in e for e in report["exclusions"])
    # one set per task (the quick demo has lcca only); write_figures ran the figure check
    for name in ("fig12_groups_lcca", "fig9_forces_lcca", "tlx_profile_lcca"):
        for fmt in ("pdf", "svg", "png"):
            assert (demo / "figures" / f"{name}.{fmt}").stat().st_size > 5_000
            # both IEEE widths: single column beside the double-column figures
            assert (demo / "figures" / "single" / f"{name}.{fmt}").stat().st_size > 5_000
    single_pdf = demo / "figures" / "single" / "fig12_groups_lcca.pdf"
    assert "Holm-corrected" not in _pdf_text(single_pdf)  # the caption is in captions.md
    single = PdfReader(single_pdf).pages[0]
    assert float(single.mediabox.width) == pytest.approx(3.5 * 72)
    assert float(single.mediabox.height) <= 4.0 * 72
    pdf = (demo / "figures" / "fig12_groups_lcca.pdf").read_bytes()
    assert b"/FontFile2" in pdf  # TrueType fonts embedded (pdf.fonttype 42)
    # the figures command redraws them at single-column width, PNG only (checked again)
    figs = tmp_path / "single"
    argv = ["figures", "--db", str(demo / "demo.db"), "--out", str(figs), "--width", "single"]
    assert main([*argv, "--format", "png"]) == 0
    assert sorted(p.suffix for p in figs.iterdir()) == [".md", *[".png"] * 3]
    # the captions beside the figures, not inside them
    for folder in (demo / "figures", demo / "figures" / "single", figs):
        captions = (folder / "captions.md").read_text()
        assert "## fig12_groups_lcca\n" in captions
        assert "Simulated participants" in captions
    capsys.readouterr()
    assert (
        main(["figures", "--db", str(demo / "demo.db"), "--out", str(figs), "--format", "gif"]) == 2
    )
    assert "expected a comma-separated list of pdf,svg,png" in capsys.readouterr().err
    assert main(["demo", "--quick", "--out", str(demo)]) == 2  # never overwrites a demo


def test_every_demo_output_says_simulated(demo: Path) -> None:
    # quick design: 6 participants x 2 conditions x 1 measured trial, all simulated
    report = json.loads((demo / "analysis" / "analysis.json").read_text())
    source = report["data_source"]
    assert source["trials_by_driver"] == {
        "simulated": 12,
        "keyboard": 0,
        "hardware": 0,
        "imported": 0,
    }
    assert source["label"] == "simulated"
    assert "Simulated participants" in source["note"]
    assert "Simulated participants" in (demo / "analysis" / "comparisons.md").read_text()
    assert "Simulated participants" in (demo / "analysis" / "comparisons.tex").read_text()
    for name in ("tests.csv", "descriptives.csv"):
        assert set(pd.read_csv(demo / "analysis" / name)["data_source"]) == {"simulated"}
    pdfs = sorted((demo / "figures").glob("*.pdf"))
    assert len(pdfs) == 3  # Fig. 12, Fig. 9 (VO and HV panels), TLX profile
    for pdf in pdfs:  # the text drawn in the figure itself, read back from the PDF
        assert "simulated" in _pdf_text(pdf).lower(), pdf.name


def _measured_csv(path: Path, codes: list[str]) -> Path:
    rows = []
    for k, code in enumerate(codes):
        group = ("outsider", "novice", "expert")[k % 3]
        for cond, shift in (("VO", 0.0), ("HV", -0.1)):
            rows.append([code, group, "lcca", cond, 1, 30.0 + k, 0.8 + shift, 0.4, "true"])
    pd.DataFrame(rows, columns=TRIAL_COLUMNS).to_csv(path, index=False)
    return path


def test_mixed_database_reports_the_mix_and_driver_restricts(
    demo: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = tmp_path / "mixed.db"
    shutil.copy(demo / "demo.db", db)
    csv = _measured_csv(tmp_path / "t.csv", ["M01", "M02", "M03"])
    assert main(["import", "--enrol-new", "--trials", str(csv), "--db", str(db)]) == 0
    out = tmp_path / "all"
    assert main(["analyze", "--out", str(out), "--db", str(db)]) == 0
    source = json.loads((out / "analysis.json").read_text())["data_source"]
    assert source["trials_by_driver"] == {
        "simulated": 12,
        "keyboard": 0,
        "hardware": 0,
        "imported": 6,
    }
    assert source["label"] == "mixed"
    assert source["note"] == "Mixed data: 12 of 18 trials simulated (6 imported)"
    assert "Mixed data: 12 of 18 trials simulated" in capsys.readouterr().out
    figs = tmp_path / "figs"
    assert main(["figures", "--db", str(db), "--out", str(figs), "--format", "pdf"]) == 0
    assert "12 of 18 trials simulated" in _pdf_text(figs / "fig12_groups_lcca.pdf")
    # --driver imported: the measured trials only, and nothing says simulated
    only = tmp_path / "imported"
    argv = ["analyze", "--out", str(only), "--driver", "imported", "--db", str(db)]
    assert main(argv) == 0
    report = json.loads((only / "analysis.json").read_text())
    assert report["data_source"]["trials_by_driver"]["imported"] == 6
    assert report["data_source"]["trials_by_driver"]["simulated"] == 0
    assert report["data_source"]["note"] == ""
    assert {d["n"] for d in report["descriptives"]} == {1}  # one imported participant a group
    capsys.readouterr()
    argv = ["analyze", "--out", str(only), "--driver", "hardware", "--db", str(db)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "no trials driven by 'hardware'" in err
    assert "simulated (12), imported (6)" in err


def test_imported_database_carries_no_simulated_label(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    db = init_study(tmp_path)
    codes = [f"M{k:02d}" for k in range(9)]
    assert (
        main(
            [
                "import",
                "--enrol-new",
                "--trials",
                str(_measured_csv(tmp_path / "t.csv", codes)),
                "--db",
                db,
            ]
        )
        == 0
    )
    out = tmp_path / "a"
    assert main(["analyze", "--out", str(out), "--db", db]) == 0
    report = json.loads((out / "analysis.json").read_text())
    assert report["data_source"] == {
        "trials_by_driver": {"simulated": 0, "keyboard": 0, "hardware": 0, "imported": 18},
        "label": "imported",
        "note": "",
    }
    for name in ("comparisons.md", "comparisons.tex", "tests.csv"):
        text = (out / name).read_text()
        assert "Simulated participants" not in text, name
        assert "Mixed data" not in text, name
    assert set(pd.read_csv(out / "tests.csv")["data_source"]) == {"imported"}
    figs = tmp_path / "figs"
    assert main(["figures", "--db", db, "--out", str(figs), "--format", "pdf"]) == 0
    for pdf in figs.glob("*.pdf"):
        assert "simulated" not in _pdf_text(pdf).lower(), pdf.name
