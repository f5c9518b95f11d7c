"""The error a session command raises when it cannot be carried out."""


class SessionError(ValueError):
    """A command that cannot be carried out in the session's present state."""
