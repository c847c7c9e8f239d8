"""A text field's limit beside it: `n/500` as typed, in the error colour past the limit.

The free-text fields (a note, a reason) store at most `MAX_TEXT_CHARS` characters
(`study.protocol.free_text`); the count shows how much of that is typed, as it will be
stored (runs of spaces as one), so a pasted page is seen to be too long before Enter.
Nothing typed is cut: the refusal on saving names the length.
"""

from __future__ import annotations

from textual.widgets import Label

from study.protocol.free_text import MAX_TEXT_CHARS

__all__ = ["CharCount"]


class CharCount(Label):
    """How many of a text field's `limit` characters are typed."""

    DEFAULT_CSS = """
    CharCount { width: auto; color: $text-muted; }
    CharCount.-over { color: $error; text-style: bold; }
    """

    def __init__(self, text: str = "", limit: int = MAX_TEXT_CHARS, **kwargs: object) -> None:
        super().__init__("", **kwargs)  # type: ignore[arg-type]
        self.limit = limit
        self.count(text)

    def count(self, text: str) -> None:
        """Show the length of `text` as it would be stored."""
        n = len(" ".join(text.split()))
        self.update(f"{n}/{self.limit} characters" + (" (too long)" if n > self.limit else ""))
        self.set_class(n > self.limit, "-over")
