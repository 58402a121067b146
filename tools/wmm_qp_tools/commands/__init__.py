"""One module per tool subcommand of ``wmm-qp``: ``HELP``, ``add_arguments(parser)``, ``run(args)``."""
