"""Where the NOTES endoscope's tip can be, as the sample rows store it: plain constants
in a module of their own, so that a task's declaration reads them without loading the
tissue's numerics."""

REGIONS = ("canal", "fornix", "cavity", "target", "fold")
"""Region names, stored as the samples' `branch` (the fold last, so older codes keep
their meaning): "fold" is the tip against the fold, the screen's red-out."""
