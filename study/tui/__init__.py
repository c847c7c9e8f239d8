"""The Textual terminal app the experimenter uses all day (`study tui`).

One screen per module (overview, participants, run session, NASA-TLX, analysis,
calibration), the app that joins them in `app.py`, built by `make_app` from its
dependencies (`services.StudyServices`).
"""

from study.tui.app import StudyApp, TuiSettings, make_app
from study.tui.services import Roster, StudyServices

__all__ = ["Roster", "StudyApp", "StudyServices", "TuiSettings", "make_app"]
