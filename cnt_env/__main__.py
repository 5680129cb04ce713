"""``python -m cnt_env``: the same command line as ``cnt-sim``."""

from cnt_env.cli.app import main

raise SystemExit(main())
