"""``trackcli inspect``: show what a model holds (:mod:`trackcli.run.model_report`)."""

from __future__ import annotations

import click

from trackcli.cli.common import echo_json
from trackcli.cli.options import config_option, fps_option, json_option, model_argument, template_option


@click.command("inspect")
@model_argument()
@template_option("Show the model placed by this template, as `track --model MODEL --template T` uses it "
                 "on the clip where T was drawn.")
@config_option("Configuration whose placement settings apply, as for `track -c` (default: the defaults).")
@fps_option("Frame rate of the clip where T was drawn (default: the model's).")
@json_option("Machine-readable output.")
def inspect_cmd(model_path, template, config, fps, as_json):
    """Show a model: shape-space, dynamics, modes (AC eqs 11.10-11.13), steady-state spread.

    \b
    With --template T: the model placed where (and at the size) T was drawn, as tracking
    that clip uses it: its mean, stability and modes, next to the learned spectral
    radius.  The placement settings (noise factors, coupling) are those of -c CONFIG, as
    for `track`.

    A mixed-state model (kind: trackcli-mixed) is shown label by label: each label's model
    and modes (a hand-written one needs --template for the modes), the transition matrix,
    the mean stay in each label and the initial distribution.
    """
    from trackcli.run.model_report import inspect_model

    report = inspect_model(model_path, template, config, fps)
    if as_json:
        echo_json(report.info)
        return
    for line in report.lines:
        click.echo(line)
