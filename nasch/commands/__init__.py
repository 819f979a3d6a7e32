"""One module per ``nasch`` subcommand, imported when that subcommand runs.

:mod:`nasch.cli` lists them (with their one-line summaries) without importing
them, so ``nasch --help`` loads only click.
"""
