"""Plots of the string pendulum (the name `jaxstring.pendulum.plot` had before)."""

from .pendulum.plot import *  # noqa: F403
