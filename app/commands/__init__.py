"""Subcommands of `slscan`: each module here defines `register(subparsers)`.

`app.cli` discovers the modules, so a new subcommand is one new file.
"""
