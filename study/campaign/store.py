"""A campaign's folder: what is done, the finished units, and the tables built from them.

Layout of DIR:
- `campaign.toml`: the campaign file as first run; a later run into DIR must bring the
  same campaign (compared after parsing, so comments may differ), else it is refused.
- `units/<unit>.parquet`: one finished unit's rows, written to a temporary name and
  renamed (atomic on POSIX), so a killed run leaves whole units or none. Resuming
  skips exactly these. Parquet keeps the floats bit for bit.
- `unit_times.csv`: how long each unit took on its worker (for the benchmark and the
  cluster estimate; not part of the results, which must not depend on timing).
- `results.csv` / `results.parquet`: every unit's rows in grid order (cells, then
  replicates, then the file's groups, then the measures), whatever order they ran in,
  so the same campaign gives the same bytes on one worker or many.
- `summary.csv`: power per cell, group and measure with its Monte-Carlo 95 % interval
  (Wilson score interval, statsmodels' `proportion_confint`), and the mean effect.
- `campaign.json`: the spec, the defaults of the factors not swept, the counts, and
  `data_source: simulated`.

Every table carries `data_source = simulated`: these numbers come from simulated
participants and must never pass for a measured study.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from scipy import stats
from statsmodels.stats.proportion import proportion_confint

from study.campaign.spec import DEFAULTS, CampaignSpec, Cell, parse_campaign, unit_id
from study.campaign.unit import UNIT_COLUMNS
from study.errors import StudyInputError
from teleop_core.files import atomic_path

DATA_SOURCE = "simulated"
PARTICIPANTS = "participants.json"
"""A campaign folder's copy of the fitted participant model its campaign file names."""
SUMMARY_COLUMNS = (
    "group",
    "measure",
    "n",
    "replicates",
    "power",
    "power_ci_low",
    "power_ci_high",
    "power_hv_lower",
    "effect_mean",
    "effect_ci_low",
    "effect_ci_high",
    "data_source",
)
"""summary.csv after the factor columns."""


def _atomic_write(path: Path, write: Callable[[Path], object]) -> None:
    """`write(tmp)` then `tmp` renamed over `path` (`teleop_core.files.atomic_path`)."""
    with atomic_path(path) as tmp:
        write(tmp)


class CampaignDir:
    """The folder of one campaign's results."""

    def __init__(self, root: Path, spec: CampaignSpec, text: str = "") -> None:
        self.root = root
        self.spec = spec
        self.text = text
        """The campaign file's text, kept in DIR by `create`."""
        self.units_dir = root / "units"

    @classmethod
    def open(cls, root: Path, spec: CampaignSpec, text: str) -> CampaignDir:
        """DIR for `spec`: checked, not yet created (`create` does that, once the run can
        start), or reopened if it holds the same campaign."""
        if root.exists() and not root.is_dir():
            raise StudyInputError(f"--out {root} is a file; expected a folder")
        if not root.parent.is_dir():
            raise StudyInputError(f"folder {root.parent} for {root.name} does not exist")
        kept = root / "campaign.toml"
        if kept.is_file():
            if parse_campaign(kept.read_text(), str(kept)) != spec:
                raise StudyInputError(
                    f"--out {root} holds another campaign ({kept}); expected the same "
                    "campaign file to resume it, or a new folder"
                )
        elif root.is_dir() and any(root.iterdir()):
            raise StudyInputError(
                f"--out {root} is not empty and holds no campaign.toml; "
                "expected a new or empty folder"
            )
        return cls(root, spec, text)

    def create(self) -> None:
        """Make DIR and keep the campaign file in it (once), with a copy of its fitted
        participant model (`participants.json`, which the kept file then names)."""
        self.units_dir.mkdir(parents=True, exist_ok=True)
        kept = self.root / "campaign.toml"
        if not kept.is_file():
            text = self.text
            if self.spec.participants_json:
                model = self.root / PARTICIPANTS
                _atomic_write(model, lambda p: p.write_text(self.spec.participants_json))
                text = re.sub(
                    r"^participants\s*=.*$",
                    f'participants = "{PARTICIPANTS}"',
                    text,
                    count=1,
                    flags=re.M,
                )
            _atomic_write(kept, lambda p: p.write_text(text))

    @classmethod
    def existing(cls, root: Path) -> CampaignDir:
        kept = root / "campaign.toml"
        if not kept.is_file():
            raise StudyInputError(
                f"{root} holds no campaign.toml; expected a folder written by `study campaign run`"
            )
        return cls(root, parse_campaign(kept.read_text(), str(kept)))

    def unit_path(self, cell: Cell, replicate: int) -> Path:
        return self.units_dir / f"{unit_id(cell, replicate)}.parquet"

    def pending(self) -> list[tuple[Cell, int]]:
        """Units without a finished file, in grid order."""
        return [(c, r) for c, r in self.spec.units() if not self.unit_path(c, r).is_file()]

    def save_unit(self, cell: Cell, replicate: int, rows: pd.DataFrame, seconds: float) -> None:
        # its time first, then the unit's file: a kill between the two leaves a time for a
        # unit that runs again (the last time of a unit is kept), never a unit without one
        with atomic_path(self.unit_path(cell, replicate)) as tmp:
            rows.to_parquet(tmp, index=False)
            with open(self.root / "unit_times.csv", "a") as f:
                f.write(f"{unit_id(cell, replicate)},{seconds:.4f}\n")

    def results(self) -> pd.DataFrame:
        """Every finished unit's rows, factor columns first, in grid order."""
        frames = []
        for cell, r in self.spec.units():
            path = self.unit_path(cell, r)
            if path.is_file():
                rows = pd.read_parquet(path)
                for k, name in enumerate(self.spec.factors):
                    rows.insert(k, name, cell.values[name])
                frames.append(rows)
        columns = [*self.spec.factors, *UNIT_COLUMNS, "data_source"]
        if not frames:
            return pd.DataFrame(columns=columns)
        out = pd.concat(frames, ignore_index=True)
        out["data_source"] = DATA_SOURCE
        return out[columns]

    def write_tables(self) -> tuple[pd.DataFrame, pd.DataFrame]:
        """results.csv, results.parquet, summary.csv and campaign.json from the units."""
        results = self.results()
        summary = summarise(results, list(self.spec.factors), list(self.spec.groups))
        _atomic_write(self.root / "results.csv", lambda p: results.to_csv(p, index=False))
        _atomic_write(self.root / "results.parquet", lambda p: results.to_parquet(p, index=False))
        _atomic_write(self.root / "summary.csv", lambda p: summary.to_csv(p, index=False))
        total = len(self.spec.units())
        done = total - len(self.pending())
        meta = {
            "campaign": self.spec.to_dict(),
            "factor_defaults": {k: v for k, v in DEFAULTS.items() if k not in self.spec.factors},
            "cells": len(self.spec.cells()),
            "units": total,
            "units_done": done,
            "complete": done == total,
            "data_source": DATA_SOURCE,
            "note": "simulated participants (each task's, study.tasks), not a measured study",
        }
        text = json.dumps(meta, indent=2) + "\n"
        _atomic_write(self.root / "campaign.json", lambda p: p.write_text(text))
        return results, summary

    def unit_times(self) -> pd.Series:
        path = self.root / "unit_times.csv"
        if not path.is_file():
            return pd.Series(dtype=float)
        times = pd.read_csv(path, names=["unit", "seconds"])
        return times.drop_duplicates("unit", keep="last").set_index("unit")["seconds"]


def summarise(results: pd.DataFrame, factors: list[str], groups: list[str]) -> pd.DataFrame:
    """Power per cell, group and measure: the share of replicates with p < alpha, its
    Wilson 95 % interval, the share significant with HV below VO, and the mean effect
    with its t-based 95 % interval over the replicates."""
    rows = []
    keys = [*factors, "group", "measure"]
    if results.empty:
        return pd.DataFrame(columns=[*factors, *SUMMARY_COLUMNS])
    for key, g in results.groupby(keys, sort=False):
        key = key if isinstance(key, tuple) else (key,)
        reps = len(g)
        hits = int(g["significant"].sum())
        low, high = proportion_confint(hits, reps, alpha=0.05, method="wilson")
        lower = int((g["significant"] & (g["mean_hv"] < g["mean_vo"])).sum())
        effect = g["effect"].to_numpy(float)
        effect = effect[np.isfinite(effect)]
        mean = float(effect.mean()) if len(effect) else float("nan")
        half = (
            float(stats.t.ppf(0.975, len(effect) - 1) * effect.std(ddof=1) / np.sqrt(len(effect)))
            if len(effect) > 1
            else float("nan")
        )
        rows.append(
            {
                **dict(zip(keys, key, strict=True)),
                "n": int(g["n"].iloc[0]),
                "replicates": reps,
                "power": hits / reps,
                "power_ci_low": float(low),
                "power_ci_high": float(high),
                "power_hv_lower": lower / reps,
                "effect_mean": mean,
                "effect_ci_low": mean - half,
                "effect_ci_high": mean + half,
                "data_source": DATA_SOURCE,
            }
        )
    out = pd.DataFrame(rows)
    order = {m: k for k, m in enumerate(dict.fromkeys(results["measure"]))}
    rank = {g: k for k, g in enumerate(groups)}
    out["_g"], out["_m"] = out["group"].map(rank), out["measure"].map(order)
    out = out.sort_values([*factors, "_g", "_m"], kind="stable").drop(columns=["_g", "_m"])
    return out[[*factors, *SUMMARY_COLUMNS]].reset_index(drop=True)
