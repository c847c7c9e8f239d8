"""The haptic master: the rotary dial of [endovascular], III-B (eqs. 5-10, 14-15)."""
