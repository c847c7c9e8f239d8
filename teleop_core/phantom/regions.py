"""The LCCA phantom's regions, by name and as the sample table stores them: plain
constants in a module of their own, so that a task's declaration reads them without
loading the phantom's numerics."""

REGIONS = (
    "descending aorta",
    "aortic arch",
    "ascending aorta",
    "left subclavian",
    "left common carotid",
    "brachiocephalic",
)
"""Region codes (index) the phantom writes as the tip's branch."""
REGION_ABBREVIATIONS = ("DAo", "arch", "AAo", "LSA", "LCCA", "BCT")
"""Short names of REGIONS, as the sample table stores them (16 characters at most)."""
