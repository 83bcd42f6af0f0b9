"""The `jaxstring` command: run a named scene, print a result, write a figure."""

from .main import main as main
