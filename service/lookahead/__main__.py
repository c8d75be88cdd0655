"""`python -m lookahead` is the `lookahead` console script."""

from lookahead.cli import main

raise SystemExit(main())
