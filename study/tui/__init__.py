"""The Textual terminal app the experimenter uses all day (`study tui`)."""
