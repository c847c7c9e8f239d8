"""The haptic master: the rotary dial of seed 000, III-B (eqs. 5-10, 14-15)."""
