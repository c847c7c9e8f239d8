"""The tasks a study can run, one package each (`lcca`, `notes`).

A task's package owns its trial (the closed loop and the simulated participant's
driver), its features and measures, its sample columns, its live scene and its figures;
`study.protocol.tasks` defines what a task is and keeps the registry that finds the
packages (built in, or installed under the entry-point group `haptic_study.tasks`).
Nothing outside a task's package names a task.
"""
