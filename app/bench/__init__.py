"""Sections of `slscan bench`: each module here defines

    FLAG: str             the command-line flag, e.g. "--speed"
    KEY: str              its key in the --json output, e.g. "speed"
    HELP: str
    def add_arguments(parser) -> None      (optional) extra options of that section
    def run(args) -> list[dict]            measure; one dict per table row
    def format_table(rows) -> str          the human-readable table

Speed, memory and accuracy targets live here, never in timed tests.
"""
