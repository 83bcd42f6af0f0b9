"""Plots of the tether (the name `jaxstring.tether.plot` had before)."""

from .tether.plot import *  # noqa: F403
