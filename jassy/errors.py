"""Exception types. Every error a user can cause derives from :class:`JassyError`.

The CLI turns a ``JassyError`` into a one-line message on stderr and exit code 2.
"""


class JassyError(Exception):
    """Bad input: a patch, model, argument or file that cannot be used as given."""


class PatchError(JassyError):
    """A patch (TOML file or Python graph) is invalid. The message names file and key."""


class ModelError(JassyError):
    """A modal model is invalid or cannot be read."""


class RenderError(JassyError):
    """Rendering could not complete (e.g. the output cannot be written)."""


def suggest(name: str, choices) -> str:
    """``"; did you mean 'x'?"`` for the choice closest to ``name`` (difflib's ratio >= 0.6,
    case ignored), or "" when none is close."""
    import difflib

    by_lower = {str(c).lower(): str(c) for c in choices}
    close = difflib.get_close_matches(str(name).lower(), list(by_lower), n=1, cutoff=0.6)
    return f"; did you mean {by_lower[close[0]]!r}?" if close else ""


def one_of(choices) -> str:
    """ "expected one of a, b, c" for an error message."""
    return "expected one of " + ", ".join(str(c) for c in choices)
