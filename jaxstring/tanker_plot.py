"""Plots of the tandem (the name `jaxstring.tandem.plot` had before)."""

from .tandem.plot import *  # noqa: F403
