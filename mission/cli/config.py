"""``marsupial config``: the configuration reference (from the schema), or a file's effective values."""
from __future__ import annotations

import click

from mission.config.schema import load_config
from mission.config.reference import effective, json_schema, markdown_table, text_table


@click.command("config")
@click.argument("config", required=False, type=click.Path(dir_okay=False))
@click.option("--schema", "fmt", flag_value="schema", help="Print the JSON schema.")
@click.option("--markdown", "fmt", flag_value="markdown",
              help="Print the reference as a Markdown table (docs/configuration.md's).")
def config_command(config: str | None, fmt: str | None) -> int:
    """Every configuration field with its type, default, rule and meaning [unit].

    With CONFIG: validate the file and print every field's effective value (the file's, else the
    default). Exit code 2 when the file is invalid (the error names the field).
    """
    if config is not None:
        click.echo(effective(load_config(config)))
    elif fmt == "schema":
        click.echo(json_schema())
    elif fmt == "markdown":
        click.echo(markdown_table())
    else:
        click.echo(text_table())
    return 0
