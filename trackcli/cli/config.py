"""``trackcli config``: show (with every setting explained), list and check configurations."""

from __future__ import annotations

import click


@click.group("config")
def config_group() -> None:
    """Show (with every setting explained), list and check configuration files and presets."""


@config_group.command("show")
@click.argument("file", required=False, type=click.Path(dir_okay=False))
@click.option("--comments", is_flag=True, help="Explain every setting in a comment.")
def config_show(file: str | None, comments: bool) -> None:
    """Print the effective configuration: the defaults, overridden by FILE if given.

    The output is itself a valid configuration file:
    `trackcli config show --comments > my.yaml` starts a new one.
    """
    from trackcli.settings import dump_yaml, load_settings, render_commented

    settings = load_settings(file)
    click.echo(render_commented(settings) if comments else dump_yaml(settings), nl=False)


@config_group.command("list")
def config_list() -> None:
    """List the preset configurations that ship with trackcli, with their purpose.

    Use a preset by name from any folder: `trackcli track -c tight ...`.  A file of the
    same name in the current folder wins over the preset.
    """
    from trackcli.settings import preset_purpose, presets

    found = presets()
    width = max((len(n) for n in found), default=0)
    for name, path in found.items():
        click.echo(f"{name:<{width}}  {preset_purpose(path)}")


@config_group.command("check")
@click.argument("file", type=click.Path(dir_okay=False))
def config_check(file: str) -> None:
    """Validate FILE; exit 0 if it is valid, 3 with the reason if not."""
    from trackcli.settings import load_settings

    load_settings(file)
    click.echo(f"{file}: OK")
