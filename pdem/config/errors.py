"""The error a scene file that cannot be used raises: every message names its key path."""

from __future__ import annotations

from ..errors import UserError


class ConfigError(UserError, ValueError):
    """A scene file that cannot be used; ``str()`` is the message shown to the user."""

    def __init__(self, messages: list[str], source: str = "scene"):
        self.messages = messages
        self.source = source
        super().__init__(f"{source}: invalid scene\n" + "\n".join(f"  - {m}" for m in messages))

    def __reduce__(self):  # pickled by its messages (sent between ranks, pdem.mpi)
        return type(self), (self.messages, self.source)
