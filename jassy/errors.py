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
