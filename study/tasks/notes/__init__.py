"""The NOTES endoscopy task (seed 001): see `study.tasks.notes.task`."""
