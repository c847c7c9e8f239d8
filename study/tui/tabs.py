"""The terminal app's screens, in the order of their function keys (F1-F6): their ids and
titles, apart from the app so that the command palette can name them without importing
the app that imports it."""

TABS = ("overview", "participants", "run", "tlx", "analysis", "calibration")
TITLES = ("Overview", "Participants", "Run", "NASA-TLX", "Analysis", "Calibration")
