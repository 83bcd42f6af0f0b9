"""``python -m jaxstring``: the command line (see `jaxstring.cli`)."""

from .cli import main


raise SystemExit(main())
