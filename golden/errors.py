"""Errors that name what was wrong; the command line prints them as one line."""


class TespikeError(Exception):
    """Base of every refusal the project makes on purpose (bad config, bad input)."""


class ConfigError(TespikeError, ValueError):
    """A configuration key, value or rule of SPEC section 2 was broken."""


class InputError(TespikeError, ValueError):
    """A stimulus, scene, stream or other input file breaks SPEC section 6."""
