"""Every error uavris raises on bad input, under one base.

Lives here: :class:`UavrisError` and its kinds. The CLI turns any of them into one line
``uavris: error: ...`` and exit code 2. Not here: what is checked (each layer validates
its own input and raises the kind that names the problem).

The kinds that concern values also derive from ``ValueError``, so code that catches a
``ValueError`` (Gymnasium's contract for a bad action, for one) keeps working.
"""

from __future__ import annotations


class UavrisError(Exception):
    """A bad input (argument, file, directory) reported to the user in one line."""


class ConfigError(UavrisError, ValueError):
    """A configuration value outside its allowed range, or an unknown name (scenario, preset, ...)."""


class ActionError(UavrisError, ValueError):
    """An action that cannot be applied (wrong shape, NaN or inf)."""


class DatasetError(UavrisError, ValueError):
    """A dataset that is missing, malformed or was made for a different environment."""


class CheckpointError(UavrisError, ValueError):
    """A checkpoint or model directory that is missing, corrupt or does not fit."""
