"""`study bench export`'s study: the samples split over the trials as asked, and each
trial's measures computed from its own samples (checked with one SQL query here, over
the stored chunks decoded with plain pyarrow)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

from db.migrate import open_database
from study.bench.export import TRIALS_PER_PARTICIPANT, build_study
from tests.conftest import expose_samples


def test_bench_study_measures_are_the_peaks_of_its_samples(tmp_path: Path) -> None:
    db = tmp_path / "bench.db"
    engine = open_database(str(db))
    try:
        trials, _ = build_study(engine, 2_003, 2, seed=3)
    finally:
        engine.dispose()
    assert trials == 2 * TRIALS_PER_PARTICIPANT
    conn = sqlite3.connect(db)
    expose_samples(conn)
    rows = conn.execute(
        """
        SELECT t.id, count(*), max(s.t_s), t.completion_time_s, t.success,
               max(s.proximal_force_n), max(s.distal_force_n),
               (SELECT value FROM trial_measures m
                WHERE m.trial_id = t.id AND m.name = 'peak_proximal_force_n'),
               (SELECT value FROM trial_measures m
                WHERE m.trial_id = t.id AND m.name = 'peak_distal_force_n')
        FROM trials t JOIN samples s ON s.trial_id = t.id
        GROUP BY t.id ORDER BY t.id
        """
    ).fetchall()
    conn.close()
    # 2,003 samples over 16 trials: 125 each, the first three one more
    assert [r[1] for r in rows] == [126] * 3 + [125] * 13
    for _, n, last_t, completion, success, prox, distal, peak_prox, peak_distal in rows:
        assert last_t == (n - 1) / 1000.0 == completion
        assert success == 1
        assert (peak_prox, peak_distal) == (prox, distal)
