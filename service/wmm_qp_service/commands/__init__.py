"""One module per ``wmm-qp`` subcommand: ``HELP``, ``add_arguments(parser)``, ``run(args)``."""
