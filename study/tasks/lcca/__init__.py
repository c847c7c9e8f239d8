"""The LCCA guidewire navigation task ([endovascular]): see `study.tasks.lcca.task`."""
