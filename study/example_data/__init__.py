"""The data the tutorials run on, shipped inside the package so that they run from any folder.

- `emps/`: the estimation recording of the EMPS benchmark, a real electro-mechanical
  positioning axis measured at 1 kHz, with its README and citation (A. Janot,
  M. Gautier, M. Brunot, "Data Set and Reference Models of EMPS", Workshop on Nonlinear
  System Identification Benchmarks, 2019).
- `probe_task/`: the worked example of a lab's own task, a package to `pip install`. In
  the repository it is a link to `examples/probe_task/`, so there is one copy of its
  source; a built wheel holds the files themselves.
- `firmware/`: the dial and drive units' firmware (PlatformIO for the ESP32, and the host
  build that runs it against a simulated motor), linked to `firmware/` the same way.

`copy_to(folder)` writes them into a folder of the user's (`study example-data DIR`);
`path(name)` is a file of them inside the installed package (`importlib.resources`).
The boundary is here, not in the commands, because the benches and the tests read the
same files.
"""

from __future__ import annotations

import shutil
from importlib.resources import as_file, files
from pathlib import Path

from study.errors import StudyInputError

ENTRIES = ("emps", "probe_task", "firmware")
"""What `copy_to` writes, each a folder: the EMPS recording, the worked task and the
units' firmware."""

EMPS_FILE = "emps/DATA_EMPS.mat"
"""The EMPS recording, relative to the example data."""

EMPS_MAT_COLUMNS = "t=t,q=qm,u=gtau*vir"
"""The EMPS file's variables for time, position and force (drive gain times voltage), in
the form `study calibrate --mat-columns` takes: EMPS's names, for this recording only."""

_LEFT_OUT = shutil.ignore_patterns("__pycache__", "*.pyc", "build", "*.egg-info", "dist")
"""What a local install may have left beside the example task's source."""


def path(name: str) -> Path:
    """The file `name` (e.g. `EMPS_FILE`) of the example data, as installed."""
    with as_file(files(__name__).joinpath(name)) as found:
        return Path(found)


def copy_to(folder: Path) -> list[Path]:
    """Copy every entry of `ENTRIES` into `folder` (created if its parent exists).

    Returns
    -------
    list of Path
        The folders written, one per entry.

    Raises
    ------
    StudyInputError
        An entry exists in `folder` already (nothing is written), or the folder's
        parent does not exist.
    """
    folder = Path(folder)
    if not folder.parent.is_dir():
        raise StudyInputError(f"{folder}: folder {folder.parent} does not exist; expected one")
    if folder.exists() and not folder.is_dir():
        raise StudyInputError(f"{folder} is a file; expected a folder")
    targets = [folder / entry for entry in ENTRIES]
    taken = [t for t in targets if t.exists()]
    if taken:
        raise StudyInputError(f"{taken[0]} exists; expected a folder without {taken[0].name}")
    made = not folder.exists()
    try:
        folder.mkdir(exist_ok=True)
        for entry, target in zip(ENTRIES, targets, strict=True):
            with as_file(files(__name__).joinpath(entry)) as source:
                shutil.copytree(source, target, ignore=_LEFT_OUT)
    except OSError as exc:  # a folder that cannot be made there (/proc), a full disk
        for target in targets:
            shutil.rmtree(target, ignore_errors=True)
        if made:
            shutil.rmtree(folder, ignore_errors=True)
        raise StudyInputError(
            f"{folder} cannot be written ({exc.strerror or exc}); expected a folder that "
            "can be made and written (nothing was left there)"
        ) from None
    return targets
