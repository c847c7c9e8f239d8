"""A lab's own haptic-study task, as a package of its own: a probe pushed into a viscous
medium (`haptic_study_probe.task`). Installed, it is found through the entry point
`haptic_study.tasks`; nothing in haptic-study names it."""
