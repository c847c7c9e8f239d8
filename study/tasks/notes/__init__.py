"""The NOTES endoscopy task ([notes]): see `study.tasks.notes.task`."""
