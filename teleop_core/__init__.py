"""The embedded teleoperation core: devices, estimators, phantoms, loop, identification.

Plain numerics (numpy, scipy; torch for the GRU). It imports no database, no
application and no UI library (an import-linter contract checks it), so it can be
lifted out and run in a lab PC's control loop.
"""
