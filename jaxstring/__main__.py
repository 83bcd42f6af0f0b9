"""``python -m jaxstring``: the command line (see `jaxstring.cli`)."""

from .cli.main import main


raise SystemExit(main())
