"""Study designs, counterbalancing, schedules, the session runner, simulated participants,
and NASA-TLX."""
