"""The ``sonibus`` command line, and what a plug-in needs to add a subcommand.

    from sonibus.bus.cli import Command, Environment, Exit, bus_config

    def run(args, env: Environment) -> Exit:
        env.say(f"joining {bus_config(args).mode}")   # the bus options, with bus=True
        return Exit.OK

    HELLO = Command("hello", "say hello", lambda parser: None, run, bus=True)
    # registered in pyproject.toml: [project.entry-points."sonibus.commands"] hello = "pkg.cli:HELLO"

Every command, the built-in ones too (``sonibus.bus.cli.run``, ``.watch``, ``.send``,
``.demo``), is found in that entry-point group; ``main(argv, env)`` runs one in-process.
"""

from .api import COMMAND_GROUP, Command, Environment, Exit, add_bus_arguments, bus_config, joined
from .app import console_main, main

__all__ = ["COMMAND_GROUP", "Command", "Environment", "Exit", "add_bus_arguments", "bus_config", "console_main",
           "joined", "main"]
