"""The ``marsupial`` command line.

Subcommands are imported lazily so that ``marsupial --help`` is fast and a missing optional
dependency of one subcommand does not break the others. Each subcommand lives next to the code
it drives and exposes a ``click.Command``; this module only maps names to them and turns our
errors into exit codes (library code never exits).

The product's own subcommands are listed here. Other packages (the simulator's ``sim``, the
benchmarks' ``bench``) register theirs under the entry-point group ``marsupial.commands`` in
``pyproject.toml``, each naming a :class:`~mission.cli.subcommands.Subcommand`; the product names
none of their modules.
"""
from __future__ import annotations

import logging
import os
import sys
from functools import cache
from typing import NoReturn

import click

from mission.errors import MarsupialError
from mission.lifetime import end_with_parent
from mission.cli.subcommands import Subcommand, registered

PRODUCT: dict[str, Subcommand] = {
    "carrier": Subcommand("mission.carrier.cli:carrier_cli",
                          "Run the carrier-side controller (built-in robot, PX4 rover, ROS 2 robot)."),
    "run": Subcommand("mission.cli.run:run", "Fly the offboard mission on a PX4 vehicle (mock, SITL or real)."),
    "plot": Subcommand("mission.cli.run:plot", "Draw the paper-style figures from a flight log directory."),
    "config": Subcommand("mission.cli.config:config_command",
                         "Every configuration field: type, default, rule, meaning and unit (--schema: JSON)."),
}


@cache
def subcommands() -> dict[str, Subcommand]:
    """Every subcommand by name: the product's, then the registered ones (:func:`registered`)."""
    return {**PRODUCT, **{name: spec for name, spec in registered().items() if name not in PRODUCT}}


class LazyGroup(click.Group):
    """A click group whose subcommands are imported on first use."""

    def list_commands(self, ctx: click.Context) -> list[str]:
        return list(subcommands())

    def get_command(self, ctx: click.Context, name: str) -> click.Command | None:
        spec = subcommands().get(name)
        return None if spec is None else spec.load()

    def format_commands(self, ctx: click.Context, formatter: click.HelpFormatter) -> None:
        with formatter.section("Commands"):
            formatter.write_dl([(name, spec.summary) for name, spec in subcommands().items()])


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.option("-v", "--verbose", count=True, help="More log output (-v info, -vv debug).")
def cli(verbose: int) -> None:
    """marsupial: offboard mission controller for a carrier robot and its passenger UAV.

    The passenger rides the carrier, separates with no jump in its input when the carrier nears
    the target (Hu, Jayawardhana, Cao: equilibrium-driven separation), and flies to the target,
    while the carrier never reaches it. Velocity setpoints go to a PX4 vehicle over MAVLink 2;
    the carrier's state arrives over Eclipse Zenoh.
    """
    level = [logging.WARNING, logging.INFO, logging.DEBUG][min(verbose, 2)]
    logging.basicConfig(level=level, format="%(asctime)s %(levelname)s %(name)s: %(message)s")


def console() -> NoReturn:
    """The process's entry point (the ``marsupial`` script, ``python -m mission.cli``): exit with
    :func:`main`'s code. When a Zenoh session's close was left still running
    (:func:`mission.bus.session.close_session`), the interpreter's own shutdown would tear that
    thread down inside Zenoh and abort the process ("FATAL: exception not rethrown", exit -6 under
    a slowloris): the logs and streams are flushed and the process ends at once with the code."""
    code = main()
    session = sys.modules.get("mission.bus.session")  # loaded only by commands that opened Zenoh
    if session is not None and session.close_abandoned():
        logging.shutdown()
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)
    sys.exit(code)


def main(argv: list[str] | None = None) -> int:
    """Entry point of the console script; returns the process exit code."""
    end_with_parent()
    try:
        rv = cli.main(args=argv, prog_name="marsupial", standalone_mode=False)
    except click.exceptions.Abort:  # Ctrl-C (click turns KeyboardInterrupt into Abort)
        click.echo("interrupted: stopped (processes this command started are stopped too)", err=True)
        return 130
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except MarsupialError as exc:
        click.echo(f"error: {exc}", err=True)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130
    except OSError as exc:  # a file or socket the user named: say which, never a traceback
        where = f": {exc.filename}" if exc.filename else ""
        click.echo(f"error: {exc.strerror or exc}{where}", err=True)
        return 1
    return rv if isinstance(rv, int) else 0

