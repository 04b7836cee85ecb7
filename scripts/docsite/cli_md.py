"""The `armfleet` command reference as Markdown, from the Typer app in service/cli.py.

Why from the app: every option's help is the one `--help` prints (serve's come from the
settings fields), so the page and the command cannot disagree.
"""

from __future__ import annotations

import inspect

import typer


def _cell(text: str) -> str:
    return " ".join(text.split()).replace("|", "\\|").replace("[", "\\[")


def render() -> str:
    from service.cli import app

    group = typer.main.get_command(app)
    root = group.make_context("armfleet", [], resilient_parsing=True)
    lines = [
        "Generated from the command's own definition (`armfleet --help` and "
        "`armfleet COMMAND --help` print the same).",
        "",
        _cell(group.help or ""),
        "",
    ]
    for name, command in group.commands.items():  # type: ignore[attr-defined]
        ctx = command.make_context(name, [], parent=root, resilient_parsing=True)
        usage = command.get_usage(ctx).removeprefix("Usage: ")
        lines += [f"## `armfleet {name}`", "", "```text", usage, "```", ""]
        lines += [inspect.cleandoc(command.help or ""), ""]
        records = [(p, p.get_help_record(ctx)) for p in command.params]
        records = [(p, r) for p, r in records if r]
        if records:
            lines += ["| option | what |", "|---|---|"]
            for _, (opts, what) in records:
                code = opts.replace("|", "\\|")
                lines.append(f"| `{code}` | {_cell(what)} |")
            lines.append("")
    return "\n".join(lines)
