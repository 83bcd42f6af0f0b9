"""Plots of the string pendulum (kept as `jaxstring.plot`; see `jaxstring.pendulum.plot`)."""

from .pendulum.plot import *  # noqa: F403
