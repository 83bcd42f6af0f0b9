"""Plots of the tether (kept as `jaxstring.tether_plot`; see `jaxstring.tether.plot`)."""

from .tether.plot import *  # noqa: F403
