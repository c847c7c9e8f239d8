"""The LCCA guidewire navigation task (seed 000): see `study.tasks.lcca.task`."""
