"""Plots of the tandem (kept as `jaxstring.tanker_plot`; see `jaxstring.tandem.plot`)."""

from .tandem.plot import *  # noqa: F403
