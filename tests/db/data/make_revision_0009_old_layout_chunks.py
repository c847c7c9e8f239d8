"""Made with the previous code (haptic-study main, revision 0009) so that revision 0010's
test reads a database as that code wrote it: a study with one LCCA trial run by the
session runner (its chunks in the LCCA schema), and two trials whose chunks a sample
writer given no schema wrote in the old layout (an LCCA and a probe trial)."""

import sys

import numpy as np
from sqlalchemy.orm import Session

from db.migrate import open_database
from db.models.trial import Trial
from db.samples import SampleWriter
from study.cli import main

db = sys.argv[1]
url = f"sqlite:///{db}"
open(db + ".toml", "w").write("""name = "old layout"
seed = 1
conditions = ["VO", "HV"]
tasks = ["lcca"]
trials_per_condition = 1
practice_trials = 0
break_s = 0

[groups]
novice = 1
""")
assert main(["init", "--design", db + ".toml", "--db", url]) == 0
assert main(["participant", "add", "--group", "novice", "--db", url]) == 0
assert main(["run", "--participant", "P001", "--db", url]) == 0
engine = open_database(url)
with Session(engine) as s:
    done = s.query(Trial).order_by(Trial.id).first()
    for task, index in (("lcca", 5), ("probe", 6)):
        t = Trial(
            participant_id=done.participant_id,
            block_id=done.block_id,
            task=task,
            condition="VO",
            block_index=done.block_index,
            trial_index=index,
            practice=True,
            attempt=1,
            driver="simulated",
            status="interrupted",
        )
        s.add(t)
    s.commit()
    ids = {t.task: t.id for t in s.query(Trial).filter(Trial.status == "interrupted")}
for task, trial_id in ids.items():
    n = 150  # two chunks of a second at 100 Hz and a half
    k = np.arange(n)
    with SampleWriter(engine, trial_id) as w:  # no schema: the old layout
        w.extend(
            {
                "t_s": 0.01 * (k + 1),
                "insertion_m": 0.001 * k,
                "rotation_rad": 0.0 * k + 0.25,
                "tip_x_m": 0.001 * k,
                "tip_y_m": 0.0 * k,
                "tip_z_m": 0.002 * k,
                "branch": ["DAo" if task == "lcca" else "medium"] * n,
                "proximal_force_n": 0.5 + 0.001 * k,
                "proximal_force_est_n": 0.4 + 0.001 * k,
                "distal_force_n": 0.1 + 0.001 * k,
                "dial_angle_rad": 0.8 + 0.0 * k,
                "dial_torque_n_m": -0.001 * k,
            }
        )
print(ids)
