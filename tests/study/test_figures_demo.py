"""`study demo --quick` end to end, and the figures it writes."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from study.cli import main


def test_quick_demo_writes_analysis_and_figures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "demo"
    assert main(["demo", "--quick", "--out", str(out), "--seed", "2"]) == 0
    report = json.loads((out / "analysis" / "analysis.json").read_text())
    # two per group: too few pairs for a test, and the analysis says so instead of failing
    assert report["comparisons"] == []
    assert any("too few to test" in e for e in report["exclusions"])
    for name in ("fig12_groups", "fig9_forces_vo", "tlx_profile"):
        for fmt in ("pdf", "svg", "png"):
            assert (out / "figures" / f"{name}.{fmt}").stat().st_size > 5_000
    pdf = (out / "figures" / "fig12_groups.pdf").read_bytes()
    assert b"/FontFile2" in pdf  # TrueType fonts embedded (pdf.fonttype 42)
    # the figures command redraws them at single-column width, PNG only
    figs = tmp_path / "single"
    argv = ["figures", "--db", str(out / "demo.db"), "--out", str(figs), "--width", "single"]
    assert main([*argv, "--format", "png"]) == 0
    assert sorted(p.suffix for p in figs.iterdir()) == [".png"] * 4
    capsys.readouterr()
    assert (
        main(["figures", "--db", str(out / "demo.db"), "--out", str(figs), "--format", "gif"]) == 2
    )
    assert "expected some of pdf,svg,png" in capsys.readouterr().err
    assert main(["demo", "--quick", "--out", str(out)]) == 2  # never overwrites a demo
